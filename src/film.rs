//! The film: box-filtered pixel accumulation (camera samples and splats from
//! light tracing and BDPT's t = 1 strategy) in exact fixed point, and the
//! check that keeps NaN, infinite and negative samples out of the image
//! (counted, per reason). `output` writes it to files.
//!
//! Why fixed point: a floating-point sum depends on the order of its terms,
//! so samples 0..64 summed at once differ in the last bits from 0..16 plus
//! 16..64, or from four parts rendered on four machines and merged. Each
//! sample is instead rounded once to a multiple of 2^-FRAC_BITS and the film
//! adds i128 integers, which is exact and associative: chunks, checkpoints,
//! resumed runs and merged parts give the same bits as one uninterrupted
//! render, whatever the split (docs/cluster.md).

use crate::spectrum::{SampledCmf, SampledSpectrum};
use anyhow::{ensure, Result};
use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

/// Samples kept out of the film, by reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DroppedSamples {
    pub nan: u64,
    pub infinite: u64,
    pub negative: u64,
}

impl DroppedSamples {
    /// (Counts saturate at u64::MAX rather than wrap, whatever parts a
    /// merge is given.)
    pub fn total(&self) -> u64 {
        self.nan.saturating_add(self.infinite).saturating_add(self.negative)
    }

    /// "N `what` (a NaN, b infinite, c negative)".
    pub fn describe(&self, what: &str) -> String {
        format!("{} {what} ({} NaN, {} infinite, {} negative)", self.total(), self.nan, self.infinite, self.negative)
    }

    pub fn merge(&mut self, o: &DroppedSamples) {
        self.nan = self.nan.saturating_add(o.nan);
        self.infinite = self.infinite.saturating_add(o.infinite);
        self.negative = self.negative.saturating_add(o.negative);
    }

    /// Converts a spectral sample to linear sRGB with its path's matching
    /// functions `cmf` (`SampledCmf::linear_srgb`), or counts why it is
    /// dropped.
    /// The check is on the spectral values: sRGB itself may legitimately be
    /// negative for saturated spectra. A colour beyond the film's exact range
    /// (|c| > MAX_SAMPLE, some 10^14: no estimator comes near it on a sane
    /// scene) counts as infinite, and so does a colour the conversion itself
    /// overflows (a finite spectrum near f32::MAX sums to infinity, and the
    /// sRGB matrix turns infinities into NaN).
    #[inline]
    pub fn admit(&mut self, l: SampledSpectrum, cmf: &SampledCmf) -> Option<Vec3> {
        if l.0.is_nan_mask().any() {
            self.nan += 1;
            return None;
        }
        if !l.is_finite() {
            self.infinite += 1;
            return None;
        }
        if l.min_component() < 0.0 {
            self.negative += 1;
            return None;
        }
        let rgb = cmf.apply(l);
        // Lane by lane, so that a NaN channel fails too (`max_element`
        // would pass over it).
        if !rgb.abs().cmple(Vec3::splat(MAX_SAMPLE)).all() {
            self.infinite += 1;
            return None;
        }
        Some(rgb)
    }
}

/// "N samples (a NaN, b infinite, c negative)", as the warnings and notes
/// say it (`describe` names other things than samples).
impl std::fmt::Display for DroppedSamples {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.describe("samples"))
    }
}

/// The samples several films kept out (the passes of one render).
impl std::iter::Sum for DroppedSamples {
    fn sum<I: Iterator<Item = Self>>(iter: I) -> Self {
        iter.fold(Self::default(), |mut total, d| {
            total.merge(&d);
            total
        })
    }
}

/// Fractional bits of the film's fixed-point sums: a resolution of 2^-60
/// keeps every f32 sample above 2^-36 exact and truncates smaller ones by less
/// than 2^-60 (8.7e-19) each. An f32 pixel can show far less (down to
/// 1.2e-38), so a scene whose samples are mostly that small reads dark or
/// black (at emission 1e-16, 7 % dark): one whose brightest emitter is
/// below 2^-36 is warned of (`Scene::dim_emission`).
const FRAC_BITS: i32 = 60;
/// The largest sample colour the film accepts: 2^48, so that 2^19 - 1 such
/// samples in one pixel still fit the 127 bits of an i128 sum. Past that a
/// sample that would carry its pixel's sum out of range is dropped and
/// counted as infinite (`add_fixed`).
pub const MAX_SAMPLE: f32 = (1u64 << 48) as f32;

/// A sample's colour in the film's fixed point (`admit` bounds it),
/// truncated toward zero. Colours below 8 in magnitude, nearly all of them,
/// fit an i64 and skip the slower software conversion to i128 (one test
/// for the three channels).
#[inline]
pub fn to_fixed(rgb: Vec3) -> [i128; 3] {
    let x = rgb.as_dvec3() * (FRAC_BITS as f64).exp2();
    if x.abs().cmplt(DVec3::splat(9.2e18)).all() {
        // SAFETY: the test, lane by lane, holds for no NaN or infinity, so
        // every channel is finite and below 2^63 in magnitude: truncation
        // to i64 is defined.
        x.to_array().map(|c| unsafe { c.to_int_unchecked::<i64>() } as i128)
    } else {
        x.to_array().map(|c| c as i128)
    }
}

/// Adds fixed-point colour `v` to `sum`, unless a channel would leave the
/// i128 range: then `sum` stays as it was and the result is false.
#[inline]
#[must_use]
pub fn add_fixed(sum: &mut [i128; 3], v: [i128; 3]) -> bool {
    let [(r, o_r), (g, o_g), (b, o_b)] = [0, 1, 2].map(|c| sum[c].overflowing_add(v[c]));
    if o_r | o_g | o_b {
        return false;
    }
    *sum = [r, g, b];
    true
}

pub struct Film {
    pub width: u32,
    pub height: u32,
    /// Exact sum per pixel of every estimate that landed in it, camera
    /// samples and splats alike (linear sRGB in 2^-FRAC_BITS units).
    pub sums: Vec<[i128; 3]>,
    /// Samples per pixel accumulated so far.
    pub spp: u64,
    pub dropped: DroppedSamples,
}

impl Film {
    pub fn new(width: u32, height: u32) -> Self {
        // In usize: width * height in u32 wraps for images of 2^32 pixels or more.
        let n = width as usize * height as usize;
        Self { width, height, sums: vec![[0; 3]; n], spp: 0, dropped: DroppedSamples::default() }
    }

    /// The pixel estimates: sums divided by spp. For camera samples that is
    /// their mean; for splats too, since spp light paths per pixel were
    /// traced (the camera's importance is normalised over the whole image,
    /// see camera.rs).
    pub fn image(&self) -> Vec<[f32; 3]> {
        let scale = if self.spp == 0 { 0.0 } else { (-FRAC_BITS as f64).exp2() / self.spp as f64 };
        self.sums.iter().map(|s| s.map(|c| (c as f64 * scale) as f32)).collect()
    }

    /// Adds another film of the same size (other samples of the same image).
    pub fn add(&mut self, other: &Film) -> Result<()> {
        ensure!(
            (self.width, self.height) == (other.width, other.height),
            "cannot add a {}x{} film to a {}x{} one",
            other.width,
            other.height,
            self.width,
            self.height
        );
        // Checked first, then added: the film is left as it was on failure
        // without a copy of its sums.
        let fits = self.sums.iter().zip(&other.sums).all(|(&a, &b)| add_fixed(&mut { a }, b));
        ensure!(fits, "the summed samples leave the film's exact range (2^67 per pixel and colour channel)");
        for (a, &b) in self.sums.iter_mut().zip(&other.sums) {
            let added = add_fixed(a, b);
            debug_assert!(added, "checked above");
        }
        self.spp += other.spp;
        self.dropped.merge(&other.dropped);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The i64 shortcut truncates as the i128 conversion does, on both sides
    /// of its threshold (8 = 2^63 / 2^60) and with one large channel among
    /// small ones.
    #[test]
    fn fixed_point_is_the_truncated_product() {
        let exact = |c: f32| (c as f64 * 2f64.powi(FRAC_BITS)) as i128;
        let tiny = 1.5 / 2f32.powi(FRAC_BITS); // 1.5 units: truncates to 1
        let values =
            [0.0, -0.0, 1e-30, tiny, -tiny, 0.3, -0.3, 7.999_999, -7.999_999, 8.0, -8.0, 1e6, -3e12, MAX_SAMPLE];
        for &a in &values {
            for &b in &[0.3, 9.5] {
                let rgb = Vec3::new(a, b, -a);
                assert_eq!(to_fixed(rgb), [exact(a), exact(b), exact(-a)], "{rgb}");
            }
        }
        assert_eq!(to_fixed(Vec3::new(0.5, tiny, -tiny)), [1 << (FRAC_BITS - 1), 1, -1]);
    }

    #[test]
    fn adding_films_refuses_to_wrap() {
        let film = |sum: i128| {
            let mut f = Film::new(1, 1);
            f.sums[0] = [sum, 0, 0];
            f.spp = 1;
            f
        };
        let mut a = film(i128::MAX - 1);
        assert!(a.add(&film(2)).is_err(), "a sum past i128::MAX was accepted");
        assert_eq!((a.sums[0][0], a.spp), (i128::MAX - 1, 1), "a refused addition changed the film");
        a.add(&film(1)).unwrap();
        assert_eq!((a.sums[0][0], a.spp), (i128::MAX, 2));
        // Refused at the second pixel: the first is not added either.
        let two = |sums: [i128; 2]| {
            let mut f = Film::new(2, 1);
            f.sums = sums.map(|s| [s, 0, 0]).to_vec();
            f
        };
        let mut b = two([5, i128::MAX]);
        assert!(b.add(&two([1, 1])).is_err());
        assert_eq!(b.sums, two([5, i128::MAX]).sums, "a refused addition changed the film");
    }
}
