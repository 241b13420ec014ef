//! Four wavelengths per path (hero-wavelength sampling, Wilkie et al. 2014)
//! and the spectral values carried along it, as one SIMD register each.

use glam::Vec4;
use std::ops::{Add, AddAssign, Div, DivAssign, Index, Mul, MulAssign, Sub};
use std::sync::LazyLock;

pub const N_LAMBDA: usize = 4;

/// Values of a spectral quantity at the four wavelengths of a path.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SampledSpectrum(pub Vec4);

impl SampledSpectrum {
    pub const ZERO: Self = Self(Vec4::ZERO);
    pub const ONE: Self = Self(Vec4::ONE);

    #[inline]
    pub fn new(a: f32, b: f32, c: f32, d: f32) -> Self {
        Self(Vec4::new(a, b, c, d))
    }
    #[inline]
    pub fn splat(v: f32) -> Self {
        Self(Vec4::splat(v))
    }
    #[inline]
    pub fn is_black(self) -> bool {
        self.0 == Vec4::ZERO
    }
    #[inline]
    pub fn max_component(self) -> f32 {
        self.0.max_element()
    }
    #[inline]
    pub fn min_component(self) -> f32 {
        self.0.min_element()
    }
    #[inline]
    pub fn average(self) -> f32 {
        self.0.element_sum() * 0.25
    }
    #[inline]
    pub fn is_finite(self) -> bool {
        self.0.is_finite()
    }
    #[inline]
    pub fn sqrt(self) -> Self {
        Self(Vec4::from_array(self.0.max(Vec4::ZERO).to_array().map(f32::sqrt)))
    }
    /// Component-wise division that yields 0 where the divisor is 0.
    #[inline]
    pub fn safe_div(self, d: Self) -> Self {
        let q = self.0 / d.0;
        Self(Vec4::select(d.0.cmpeq(Vec4::ZERO), Vec4::ZERO, q))
    }
    #[inline]
    pub fn to_array(self) -> [f32; 4] {
        self.0.to_array()
    }
}

impl Index<usize> for SampledSpectrum {
    type Output = f32;
    #[inline]
    fn index(&self, i: usize) -> &f32 {
        &self.0[i]
    }
}

macro_rules! spectrum_binop {
    ($tr:ident, $f:ident, $tra:ident, $fa:ident, $op:tt) => {
        impl $tr for SampledSpectrum {
            type Output = Self;
            #[inline]
            fn $f(self, o: Self) -> Self {
                Self(self.0 $op o.0)
            }
        }
        impl $tr<f32> for SampledSpectrum {
            type Output = Self;
            #[inline]
            fn $f(self, o: f32) -> Self {
                Self(self.0 $op o)
            }
        }
        impl $tra for SampledSpectrum {
            #[inline]
            fn $fa(&mut self, o: Self) {
                self.0 = self.0 $op o.0;
            }
        }
        impl $tra<f32> for SampledSpectrum {
            #[inline]
            fn $fa(&mut self, o: f32) {
                self.0 = self.0 $op o;
            }
        }
    };
}
spectrum_binop!(Add, add, AddAssign, add_assign, +);
spectrum_binop!(Mul, mul, MulAssign, mul_assign, *);
spectrum_binop!(Div, div, DivAssign, div_assign, /);

impl Sub for SampledSpectrum {
    type Output = Self;
    #[inline]
    fn sub(self, o: Self) -> Self {
        Self(self.0 - o.0)
    }
}

impl Mul<SampledSpectrum> for f32 {
    type Output = SampledSpectrum;
    #[inline]
    fn mul(self, s: SampledSpectrum) -> SampledSpectrum {
        SampledSpectrum(s.0 * self)
    }
}

/// The four wavelengths (nm) of one path and their sampling densities.
///
/// The hero wavelength is drawn from pbrt-v4's visible-importance pdf
/// p(l) = 0.0039398042 / cosh^2(0.0072 (l - 538)) on [360, 830] nm, as
/// tabulated in `VisibleTable`; the three others are rotated by equal steps
/// of 1/4 in the pdf's primary sample space (u_i = u + i/4 mod 1), so each
/// wavelength is marginally distributed by the table's pdf and the plain
/// average of L(l_i)/p(l_i) is unbiased. The hero idea is Wilkie et al.
/// 2014's, who space the wavelengths evenly in nm and combine them by MIS;
/// the rotation in sample space and the plain average are pbrt-v4's
/// (`SampleVisibleWavelengths`, `TerminateSecondary`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampledWavelengths {
    /// The wavelengths (nm). Only `sample_visible` sets them, as `dense`
    /// must follow them.
    pub lambda: Vec4,
    pub pdf: Vec4,
    /// Each wavelength's index in the 1 nm tables of dense spectra and
    /// of the CIE functions (`dense_index4`; N_DENSE outside them), found
    /// once per path instead of at every `Spectrum::sample`.
    pub(super) dense: [u32; 4],
}

impl SampledWavelengths {
    /// The four wavelengths for primary sample `u`: lane i takes the
    /// table's segment for u + i/4 (mod 1), at the same position within it.
    #[inline]
    pub fn sample_visible(u: f32) -> Self {
        let t = &*VISIBLE;
        // u has 24 bits, so x = u n and its fraction are exact.
        let x = u * VisibleTable::N as f32;
        let first = (x as usize).min(VisibleTable::N - 1);
        let f = Vec4::splat(x - first as f32);
        // (N is a power of two: the modulo is a mask, and fixed-size
        // tables let the compiler drop the index checks.)
        let segment = [0, 1, 2, 3].map(|i| (first + i * VisibleTable::N / 4) % VisibleTable::N);
        let at = |v: &[f32], d: usize| Vec4::from_array(segment.map(|k| v[k + d]));
        let (lo, hi) = (at(&t.lambda, 0), at(&t.lambda, 1));
        let lambda = lo + (hi - lo) * f;
        Self { lambda, pdf: at(&t.pdf, 0), dense: super::dense_index4(lambda) }
    }

    /// Keep only the hero wavelength (after a dispersive event): the
    /// secondaries get pdf 0 (their terms drop out) and the hero's pdf is
    /// divided by 4 so the average over four lanes stays unbiased (pbrt-v4
    /// `TerminateSecondary`).
    #[inline]
    pub fn terminate_secondary(&mut self) {
        if self.secondary_terminated() {
            return;
        }
        self.pdf = Vec4::new(self.pdf.x / N_LAMBDA as f32, 0.0, 0.0, 0.0);
    }

    #[inline]
    pub fn secondary_terminated(&self) -> bool {
        self.pdf.y == 0.0 && self.pdf.z == 0.0 && self.pdf.w == 0.0
    }

    #[inline]
    pub fn hero(&self) -> f32 {
        self.lambda.x
    }
}

/// pbrt-v4's visible-importance distribution as a table: the wavelengths
/// l_k = F^-1(k / N) of its inverse CDF (k = 0 ..= N; the ends pinned to
/// 360 and 830 nm), with l linear in u within each segment. So a segment is
/// drawn with probability 1/N and l is uniform in it: its density is
/// exactly `pdf[k]` = 1 / (N (l_{k+1} - l_k)), piecewise constant: within
/// 3 % of pbrt's p at N = 1024 (`tabulated_pdf_follows_pbrt`), and within
/// 1.1 % from 370 to 760 nm; the most is in the widest segment, 4.2 nm at
/// 830 nm, where p also changes fastest relative to itself. Drawing
/// from it is three loads per lane; the analytic inverse, a vector logarithm
/// whose polynomial is one chain of dependent multiplies, took ~4 % of
/// `light`'s time (docs/performance-log.md, "Session 18").
struct VisibleTable {
    lambda: [f32; VisibleTable::N + 1],
    pdf: [f32; VisibleTable::N],
}

impl VisibleTable {
    /// Segments: a power of two divisible by 4, so the four rotated lanes
    /// share the position within their segments.
    const N: usize = 1024;

    fn new() -> Self {
        // pbrt-v4 `SampleVisibleWavelengths`: l = 538 - atanh(0.8569106 -
        // 1.827502 u) / 0.0072.
        let inverse_cdf = |u: f64| 538.0 - (0.856_910_6 - 1.827_502 * u).atanh() / 0.0072;
        let lambda: [f32; Self::N + 1] = std::array::from_fn(|k| match k {
            0 => super::LAMBDA_MIN,
            k if k == Self::N => super::LAMBDA_MAX,
            k => inverse_cdf(k as f64 / Self::N as f64) as f32,
        });
        let pdf = std::array::from_fn(|k| (1.0 / (Self::N as f64 * (lambda[k + 1] as f64 - lambda[k] as f64))) as f32);
        Self { lambda, pdf }
    }
}

static VISIBLE: LazyLock<VisibleTable> = LazyLock::new(VisibleTable::new);

#[cfg(test)]
mod tests {
    use super::*;

    /// Inverse CDF of pbrt-v4's visible-wavelength pdf (util/sampling.h).
    fn sample_visible_wavelength(u: f32) -> f32 {
        538.0 - 138.888_89 * (0.856_910_6 - 1.827_502 * u).atanh()
    }

    fn visible_wavelength_pdf(lambda: f32) -> f32 {
        if !(360.0..=830.0).contains(&lambda) {
            return 0.0;
        }
        let c = (0.0072 * (lambda - 538.0)).cosh();
        0.003_939_804 / (c * c)
    }

    /// The oracle's own check: pbrt's density, against which
    /// `tabulated_pdf_follows_pbrt` holds the table, integrates to one
    /// (its constant is right); the table's own densities are checked in
    /// `lanes_carry_their_segments_density`.
    #[test]
    fn pbrts_visible_pdf_integrates_to_one() {
        let n = 470_000;
        let h = 470.0 / n as f64;
        let s: f64 =
            (0..n).map(|i| visible_wavelength_pdf(360.0 + (i as f64 + 0.5) as f32 * h as f32) as f64 * h).sum();
        assert!((s - 1.0).abs() < 1e-3, "{s}");
    }

    /// The table's inverse CDF is pbrt's to 0.01 nm, and its density is
    /// pbrt's to 3 % (1.1 % over 370-760 nm): the variance it was chosen for
    /// is kept.
    #[test]
    fn tabulated_pdf_follows_pbrt() {
        for k in 0..1000 {
            let l = SampledWavelengths::sample_visible(k as f32 / 1000.0);
            for i in 0..N_LAMBDA {
                let (lambda, pdf) = (l.lambda[i], l.pdf[i]);
                let mut up = k as f32 / 1000.0 + i as f32 / 4.0;
                if up >= 1.0 {
                    up -= 1.0;
                }
                assert!((lambda - sample_visible_wavelength(up)).abs() < 0.01, "{lambda} at {up}");
                let p = visible_wavelength_pdf(lambda.clamp(360.0, 830.0));
                let tolerance = if (370.0..760.0).contains(&lambda) { 0.015 } else { 0.03 };
                assert!((pdf - p).abs() < tolerance * p, "{pdf} vs {p} at {lambda}");
            }
        }
    }

    /// Each lane's pdf is the density of the wavelengths drawn: the
    /// segment's probability 1/N over its width, with the lane's wavelength
    /// inside the segment; the densities integrate to one over the table.
    #[test]
    fn lanes_carry_their_segments_density() {
        let t = &*VISIBLE;
        let n = VisibleTable::N;
        let total: f64 = (0..n).map(|k| t.pdf[k] as f64 * (t.lambda[k + 1] - t.lambda[k]) as f64).sum();
        assert!((total - 1.0).abs() < 1e-5, "{total}");
        for k in 0..4 * n {
            let u = (k as f32 + 0.5) / (4 * n) as f32;
            let l = SampledWavelengths::sample_visible(u);
            for i in 0..N_LAMBDA {
                let segment = (k / 4 + i * n / 4) % n;
                let (lo, hi) = (t.lambda[segment], t.lambda[segment + 1]);
                assert!((lo..=hi).contains(&l.lambda[i]), "lane {i} at u = {u}: {} outside [{lo}, {hi}]", l.lambda[i]);
                let density = 1.0 / (n as f64 * (hi - lo) as f64);
                assert!((l.pdf[i] as f64 / density - 1.0).abs() < 1e-6, "lane {i} at u = {u}");
            }
        }
    }

    #[test]
    fn inverse_cdf_covers_the_range() {
        // The oracle's range (pbrt's inverse CDF, which
        // `tabulated_pdf_follows_pbrt` holds the table to).
        assert!((sample_visible_wavelength(0.0) - 360.0).abs() < 0.5);
        assert!((sample_visible_wavelength(1.0) - 830.0).abs() < 0.5);
        // The vector sampler: u = 0 gives 360 nm in lane 0, u just below
        // 1 gives 830 nm in lane 0 and lane 3 (u' = u + 3/4 - 1).
        let l = SampledWavelengths::sample_visible(0.0);
        assert!((l.lambda.x - 360.0).abs() < 0.5, "{}", l.lambda);
        let l = SampledWavelengths::sample_visible(1.0 - f32::EPSILON);
        assert!((l.lambda.x - 830.0).abs() < 0.5, "{}", l.lambda);
        assert!(l.lambda.min_element() >= 359.5 && l.lambda.max_element() < 830.5, "{}", l.lambda);
    }

    #[test]
    fn terminate_secondary_keeps_hero_weight() {
        let mut l = SampledWavelengths::sample_visible(0.3);
        let p0 = l.pdf.x;
        l.terminate_secondary();
        assert!(l.secondary_terminated());
        assert_eq!(l.pdf.x, p0 / 4.0);
        l.terminate_secondary();
        assert_eq!(l.pdf.x, p0 / 4.0);
    }
}
