//! Four wavelengths per path (hero-wavelength sampling, Wilkie et al. 2014)
//! and the spectral values carried along it, as one SIMD register each.

use glam::Vec4;
use std::ops::{Add, AddAssign, Div, DivAssign, Index, Mul, MulAssign, Sub};

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
/// p(l) = 0.0039398042 / cosh^2(0.0072 (l - 538)) on [360, 830] nm; the three
/// others are rotated by equal steps of 1/4 in the pdf's primary sample space
/// (u_i = u + i/4 mod 1), so each wavelength is marginally distributed by p
/// and the plain average of L(l_i)/p(l_i) is unbiased (Wilkie et al. 2014).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampledWavelengths {
    /// The wavelengths (nm). Only `sample_visible` sets them, as `dense`
    /// must follow them.
    pub lambda: Vec4,
    pub pdf: Vec4,
    /// Each wavelength's index in the 1 nm tables of dense spectra
    /// (`dense_index4`; N_DENSE or more outside them), found once per path
    /// instead of at every `Spectrum::sample`.
    pub(super) dense: [u32; 4],
}

impl SampledWavelengths {
    /// The four wavelengths for primary sample `u`, all lanes at once. With
    /// x = 0.8569106 - 1.827502 u', the inverse CDF is
    /// l = 538 - atanh(x) / 0.0072, so 0.0072 (l - 538) = -atanh(x) and, as
    /// cosh^2(atanh x) = 1 / (1 - x^2), the pdf at l is 0.0039398042 (1 - x^2):
    /// one vector logarithm and no hyperbolic cosine.
    pub fn sample_visible(u: f32) -> Self {
        let up = Vec4::splat(u) + Vec4::new(0.0, 0.25, 0.5, 0.75);
        let up = Vec4::select(up.cmpgt(Vec4::ONE), up - Vec4::ONE, up);
        let x = Vec4::splat(0.856_910_6) - Vec4::splat(1.827_502) * up;
        let atanh = 0.5 * ln(((Vec4::ONE + x) / (Vec4::ONE - x)).max(Vec4::splat(f32::MIN_POSITIVE)));
        let lambda = Vec4::splat(538.0) - Vec4::splat(138.888_89) * atanh;
        let pdf = Vec4::splat(0.003_939_804) * (Vec4::ONE - x * x);
        let dense = super::dense_index4(lambda);
        Self { lambda, pdf, dense }
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

/// Natural logarithm of four positive normal floats, after Cephes' `logf`
/// (Moshier 1992): x = m 2^e with m in [sqrt(1/2), sqrt(2)), then a degree-9
/// polynomial in f = m - 1; about 1 ulp.
#[inline]
fn ln(v: Vec4) -> Vec4 {
    let bits = v.to_array().map(f32::to_bits);
    // m in [0.5, 1) and the matching exponent, as frexp returns them.
    let m = Vec4::from_array(bits.map(|b| f32::from_bits((b & 0x807f_ffff) | 0x3f00_0000)));
    let e = Vec4::from_array(bits.map(|b| ((b >> 23) & 0xff) as i32 as f32 - 126.0));
    let small = m.cmplt(Vec4::splat(std::f32::consts::FRAC_1_SQRT_2));
    let e = Vec4::select(small, e - Vec4::ONE, e);
    let f = Vec4::select(small, m + m, m) - Vec4::ONE;
    let z = f * f;
    let p = [
        -1.151_461e-1,
        1.167_699_84e-1,
        -1.242_014_1e-1,
        1.424_932_3e-1,
        -1.666_805_7e-1,
        2.000_071_4e-1,
        -2.499_999_4e-1,
        3.333_333e-1,
    ]
    .iter()
    .fold(Vec4::splat(7.037_683_6e-2), |acc, &c| acc * f + Vec4::splat(c));
    let y = p * f * z - Vec4::splat(2.121_944_4e-4) * e - 0.5 * z;
    f + y + Vec4::splat(0.693_359_4) * e
}

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

    #[test]
    fn visible_pdf_integrates_to_one() {
        let n = 470_000;
        let h = 470.0 / n as f64;
        let s: f64 =
            (0..n).map(|i| visible_wavelength_pdf(360.0 + (i as f64 + 0.5) as f32 * h as f32) as f64 * h).sum();
        assert!((s - 1.0).abs() < 1e-3, "{s}");
    }

    #[test]
    fn vector_sampling_matches_the_scalar_inverse_cdf_and_pdf() {
        for k in 0..=1000 {
            let l = SampledWavelengths::sample_visible(k as f32 / 1000.0);
            for i in 0..N_LAMBDA {
                let (lambda, pdf) = (l.lambda[i], l.pdf[i]);
                let mut up = k as f32 / 1000.0 + i as f32 / 4.0;
                if up > 1.0 {
                    up -= 1.0;
                }
                assert!((lambda - sample_visible_wavelength(up)).abs() < 1e-3, "{lambda} at {up}");
                let p = visible_wavelength_pdf(lambda.clamp(360.0, 830.0));
                assert!((pdf - p).abs() < 1e-5 * p, "{pdf} vs {p} at {lambda}");
            }
        }
    }

    #[test]
    fn ln_is_accurate() {
        for k in 0..10_000 {
            let x = 0.03 + k as f32 * 0.01;
            let l = ln(Vec4::splat(x)).x;
            assert!((l - x.ln()).abs() <= 2.0 * f32::EPSILON * x.ln().abs().max(1.0), "{x}: {l} vs {}", x.ln());
        }
    }

    #[test]
    fn inverse_cdf_covers_the_range() {
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
