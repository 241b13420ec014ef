//! Spectral core: hero-wavelength sampling (Wilkie et al. 2014) with four
//! wavelengths per path, spectra as scenes name them, and the conversion of a
//! spectral estimate to CIE XYZ and linear sRGB.
//!
//! Every spectrum a scene names is turned, at load time, into either a
//! constant or a dense table at 1 nm over [360, 830] nm, so that evaluating
//! it in the hot loop is four loads (pbrt-v4's `DenselySampledSpectrum`).

mod cie;
mod named;
mod rgb;
mod sampled;

pub use cie::spectrum_to_xyz;
pub use cie::{to_xyz, xyz_to_linear_srgb, SampledCmf, CIE_Y_INTEGRAL, LAMBDA_MAX, LAMBDA_MIN};
pub use named::{
    blackbody, cauchy, glass_ior, illuminant, metal_eta_k, sellmeier, GLASS_NAMES, ILLUMINANT_NAMES, METAL_NAMES,
};
pub use named::{cauchy_ior, planck, sellmeier_ior};
pub use rgb::sigmoid_polynomial;
pub use rgb::{rgb_albedo, rgb_illuminant, RgbToSpectrumTable};
pub use sampled::{SampledSpectrum, SampledWavelengths, N_LAMBDA};

use glam::Vec4;
use std::sync::Arc;

/// Number of 1 nm samples in [LAMBDA_MIN, LAMBDA_MAX].
pub const N_DENSE: usize = (cie::LAMBDA_MAX_I - cie::LAMBDA_MIN_I + 1) as usize;

/// Slots of a `DenseTable` and of the CIE table (cie.rs): a power of two
/// above `N_DENSE`.
const DENSE_SLOTS: usize = (N_DENSE + 1).next_power_of_two();

/// `values` over the visible range (`N_DENSE` of them), then the default
/// (zero) up to `DENSE_SLOTS`: the layout of a `DenseTable` and of the CIE
/// table.
fn padded<T: Copy + Default>(values: &[T]) -> [T; DENSE_SLOTS] {
    let mut slots = [T::default(); DENSE_SLOTS];
    slots[..N_DENSE].copy_from_slice(values);
    slots
}

/// The slot of a `dense_index4` index in a padded table: within the table
/// for every u32 (no bounds test), a zero slot for N_DENSE.
#[inline(always)]
fn slot(i: u32) -> usize {
    i as usize & (DENSE_SLOTS - 1)
}

/// A dense spectrum's values at 360..=830 nm (`N_DENSE`), then zeros up to
/// `DENSE_SLOTS`, so that a lookup masks its index into the table rather
/// than testing it: `dense_index4` clamps an index out of range to
/// `N_DENSE`, a zero slot. A bounds check and a select per wavelength
/// cost `bdpt` 1.3 % of its instructions (docs/performance-log.md,
/// "Session 45"). Built only by `Spectrum::from_dense`, which zeroes the
/// padding.
#[derive(Clone, Debug, PartialEq)]
pub struct DenseTable([f32; DENSE_SLOTS]);

impl DenseTable {
    /// The values over the visible range.
    fn values(&self) -> &[f32] {
        &self.0[..N_DENSE]
    }

    /// The value at a `dense_index4` index (0 out of range).
    #[inline(always)]
    fn at(&self, i: u32) -> f32 {
        self.0[slot(i)]
    }
}

/// A spectral distribution over wavelength (nm).
#[derive(Clone, Debug, PartialEq)]
pub enum Spectrum {
    /// The same value at every wavelength.
    Constant(f32),
    /// One value for each integer wavelength 360..=830 nm, looked up at the
    /// nearest integer (as pbrt-v4 does): the value there, or for a
    /// tabulated spectrum its mean over that nanometre (`piecewise_linear`).
    Dense(Arc<DenseTable>),
}

impl Spectrum {
    /// A piecewise-linear spectrum through (lambda_nm, value) points, sorted by
    /// wavelength. Outside the given range the end values are held (clamped).
    ///
    /// Each entry of the 1 nm table is the spectrum's mean over the
    /// wavelengths a lookup rounds to it (half a nanometre either side,
    /// within [360, 830]), not its value at the whole nanometre. A sampled
    /// wavelength l, whatever its pdf p, then reads in expectation what the
    /// spectrum has: E[table(l) g(l) / p(l)] = integral of S g for any g
    /// constant over each nanometre (the CIE matching functions' table). A
    /// band narrower than a few nanometres keeps its power: point values
    /// lost a 0.4 nm band between two whole nanometres, made one centred on
    /// a whole nanometre 5x as bright and put a 5 nm band up to 4 % off.
    pub fn piecewise_linear(points: &[(f32, f32)]) -> Spectrum {
        assert!(!points.is_empty(), "piecewise_linear needs at least one point");
        let f = |l: f64| piecewise_linear_at(points, l);
        let (min, max) = (LAMBDA_MIN as f64, LAMBDA_MAX as f64);
        let mut table = [0.0f32; N_DENSE];
        for (i, v) in table.iter_mut().enumerate() {
            let centre = min + i as f64;
            let (a, b) = ((centre - 0.5).max(min), (centre + 0.5).min(max));
            // Linear between the points: the midpoint rule is exact on each piece.
            let first = points.partition_point(|p| p.0 as f64 <= a);
            let inside = points[first..].iter().map(|p| p.0 as f64).take_while(|&x| x < b);
            let xs: Vec<f64> = std::iter::once(a).chain(inside).chain(std::iter::once(b)).collect();
            let integral: f64 = xs.windows(2).map(|w| f(0.5 * (w[0] + w[1])) * (w[1] - w[0])).sum();
            *v = (integral / (b - a)) as f32;
        }
        Spectrum::from_dense(table)
    }

    /// A dense table, collapsed to `Constant` when every entry is equal (so
    /// that `is_constant` is exact, which dispersion detection relies on).
    pub fn from_dense(table: [f32; N_DENSE]) -> Spectrum {
        if table.iter().all(|&v| v == table[0]) {
            Spectrum::Constant(table[0])
        } else {
            Spectrum::Dense(Arc::new(DenseTable(padded(&table))))
        }
    }

    /// A dense table from a function of wavelength (nm).
    pub fn from_fn(f: impl Fn(f32) -> f32) -> Spectrum {
        let mut table = [0.0f32; N_DENSE];
        for (i, v) in table.iter_mut().enumerate() {
            *v = f(LAMBDA_MIN + i as f32);
        }
        Spectrum::from_dense(table)
    }

    /// Value at one wavelength (nm); 0 outside [360, 830] for dense spectra.
    #[inline]
    pub fn eval(&self, lambda: f32) -> f32 {
        match self {
            Spectrum::Constant(c) => *c,
            Spectrum::Dense(t) => t.at(dense_index4(Vec4::splat(lambda))[0]),
        }
    }

    /// Values at the four sampled wavelengths.
    #[inline]
    pub fn sample(&self, lambda: &SampledWavelengths) -> SampledSpectrum {
        match self {
            Spectrum::Constant(c) => SampledSpectrum::splat(*c),
            Spectrum::Dense(t) => {
                let [a, b, c, d] = lambda.dense;
                SampledSpectrum::new(t.at(a), t.at(b), t.at(c), t.at(d))
            }
        }
    }

    pub fn is_constant(&self) -> bool {
        matches!(self, Spectrum::Constant(_))
    }

    /// The largest value over the visible range.
    pub fn max_value(&self) -> f32 {
        match self {
            Spectrum::Constant(c) => *c,
            Spectrum::Dense(t) => t.values().iter().copied().fold(f32::NEG_INFINITY, f32::max),
        }
    }

    /// Whether every value over the visible range is finite.
    pub fn is_finite(&self) -> bool {
        match self {
            Spectrum::Constant(c) => c.is_finite(),
            Spectrum::Dense(t) => t.values().iter().all(|v| v.is_finite()),
        }
    }

    /// The smallest value over the visible range.
    pub fn min_value(&self) -> f32 {
        match self {
            Spectrum::Constant(c) => *c,
            Spectrum::Dense(t) => t.values().iter().copied().fold(f32::INFINITY, f32::min),
        }
    }

    /// Luminance Y of this spectrum as radiance: integral of s * ybar divided
    /// by the integral of ybar, so a constant v gives v.
    pub fn luminance(&self) -> f64 {
        cie::luminance(self)
    }

    /// Pointwise product (e.g. an RGB illuminant's shape times D65).
    pub fn scaled_by(&self, other: &Spectrum) -> Spectrum {
        Spectrum::from_fn(|l| self.eval(l) * other.eval(l))
    }

    /// The spectrum times a constant.
    pub fn scale(&self, s: f32) -> Spectrum {
        match self {
            Spectrum::Constant(c) => Spectrum::Constant(c * s),
            Spectrum::Dense(_) => Spectrum::from_fn(|l| self.eval(l) * s),
        }
    }
}

/// The index of each wavelength's nearest integer nanometre in the dense
/// tables, or N_DENSE when out of range (or NaN). Adding 2^23 to a float
/// in [0, 2^22) rounds it to the nearest integer (ties to even) and leaves
/// that integer in the low mantissa bits; the offset of one more nm makes
/// wavelengths just below 360 nm (index -1 + 1 = 0 after rounding) map to
/// 360 nm, and 359.5 nm and below wrap to a huge index, clamped.
#[inline]
pub(crate) fn dense_index4(lambda: Vec4) -> [u32; 4] {
    let r = (lambda - Vec4::splat(LAMBDA_MIN - 1.0)) + Vec4::splat(8_388_608.0);
    r.to_array().map(|x| x.to_bits().wrapping_sub(0x4b00_0001).min(N_DENSE as u32))
}

/// The piecewise-linear function through `points` (ends held) at `lambda`,
/// in f64: a midpoint rounded to f32 would misplace up to 6e-5 nm of each
/// piece.
fn piecewise_linear_at(points: &[(f32, f32)], lambda: f64) -> f64 {
    let last = points.len() - 1;
    if lambda <= points[0].0 as f64 {
        return points[0].1 as f64;
    }
    if lambda >= points[last].0 as f64 {
        return points[last].1 as f64;
    }
    let i = points.partition_point(|p| p.0 as f64 <= lambda) - 1;
    let (l0, v0) = (points[i].0 as f64, points[i].1 as f64);
    let (l1, v1) = (points[i + 1].0 as f64, points[i + 1].1 as f64);
    let t = (lambda - l0) / (l1 - l0);
    v0 + t * (v1 - v0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Out of range, the index is N_DENSE exactly, a zero slot of every
    /// table: the lookups mask the index rather than test it.
    #[test]
    fn dense_index_rounds_to_the_nearest_nm_inside_the_range() {
        let index = |l: f32| dense_index4(Vec4::new(l, 538.2, l, 360.0));
        assert_eq!(index(360.0), [0, 178, 0, 0]);
        assert_eq!(index(359.6)[0], 0);
        assert_eq!(index(360.4)[0], 0);
        assert_eq!(index(360.6)[0], 1);
        assert_eq!(index(830.4)[0], N_DENSE as u32 - 1);
        assert_eq!(index(830.49994)[0], N_DENSE as u32 - 1);
        for l in [
            359.4,
            359.5,
            830.5,
            830.6,
            1e-40,
            200.0,
            900.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            -1e30,
            1e30,
            0.0,
            -360.0,
        ] {
            assert_eq!(index(l), [N_DENSE as u32, 178, N_DENSE as u32, 0], "{l}");
        }
    }

    /// A dense spectrum reads its table inside [360, 830] nm and 0 outside,
    /// where an index masked without the clamp would land inside the table
    /// (200 nm's wrapped index on slot 193).
    #[test]
    fn a_dense_spectrum_is_zero_outside_the_range() {
        let f = |l: f32| 1.0 + l / 1000.0;
        let s = Spectrum::from_fn(f);
        assert_eq!((s.eval(360.0), s.eval(830.4)), (f(360.0), f(830.0)));
        for l in [359.4, 830.6, 200.0, 900.0, f32::NAN, -1e30, 1e30, 0.0, -360.0] {
            assert_eq!(s.eval(l), 0.0, "{l}");
        }
        assert_eq!((s.max_value(), s.min_value()), (f(830.0), f(360.0)), "the padding is not part of the spectrum");
    }

    /// The table's integral over each nanometre a lookup rounds to is the
    /// spectrum's (from an audit: point values at whole nanometres lost a
    /// 0.4 nm band between two of them, made one centred on one 5x as
    /// bright, and put a 5 nm band up to 4 % off).
    #[test]
    fn narrow_bands_keep_their_power() {
        let integral = |s: &Spectrum| {
            let weight = |i: usize| if i == 0 || i == N_DENSE - 1 { 0.5 } else { 1.0 };
            (0..N_DENSE).map(|i| s.eval(LAMBDA_MIN + i as f32) as f64 * weight(i)).sum::<f64>()
        };
        for (width, centre) in [(0.4f32, 539.5f32), (0.4, 540.0), (1.0, 540.0), (5.0, 540.0), (5.0, 540.3)] {
            let band = [(centre - width / 2.0, 0.0), (centre, 1.0), (centre + width / 2.0, 0.0)];
            let s = Spectrum::piecewise_linear(&band);
            // (The band's ends are f32 and the table's entries too: 1e-5 is
            // their rounding, far below the 4 % to 400 % of point values.)
            let exact = 0.5 * (band[2].0 as f64 - band[0].0 as f64);
            assert!((integral(&s) / exact - 1.0).abs() < 1e-5, "width {width} at {centre}: {}", integral(&s));
        }
    }

    #[test]
    fn piecewise_linear_interpolates_and_clamps() {
        let s = Spectrum::piecewise_linear(&[(400.0, 1.0), (500.0, 3.0)]);
        assert_eq!(s.eval(450.0), 2.0);
        assert_eq!(s.eval(370.0), 1.0);
        assert_eq!(s.eval(800.0), 3.0);
        assert!(Spectrum::piecewise_linear(&[(400.0, 2.0)]).is_constant());
        // A flat table stays a constant (dispersion is detected by it),
        // its knots inside bins included.
        assert!(Spectrum::piecewise_linear(&[(400.3, 1.5), (512.7, 1.5), (700.0, 1.5)]).is_constant());
    }
}
