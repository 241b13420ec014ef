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
    pub lambda: Vec4,
    pub pdf: Vec4,
    /// Each wavelength's index in the 1 nm tables of dense spectra
    /// (`dense_index`; `u32::MAX` outside them), found once per path instead
    /// of at every `Spectrum::sample`.
    pub(super) dense: [u32; 4],
}

impl SampledWavelengths {
    pub fn sample_visible(u: f32) -> Self {
        let mut lambda = [0.0; 4];
        let mut pdf = [0.0; 4];
        for i in 0..N_LAMBDA {
            let mut up = u + i as f32 / N_LAMBDA as f32;
            if up > 1.0 {
                up -= 1.0;
            }
            lambda[i] = sample_visible_wavelength(up);
            pdf[i] = visible_wavelength_pdf(lambda[i]);
        }
        let dense = lambda.map(|l| super::dense_index(l).map_or(u32::MAX, |i| i as u32));
        Self { lambda: Vec4::from_array(lambda), pdf: Vec4::from_array(pdf), dense }
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

/// Inverse CDF of pbrt-v4's visible-wavelength pdf (util/sampling.h).
#[inline]
pub fn sample_visible_wavelength(u: f32) -> f32 {
    538.0 - 138.888_89 * (0.856_910_6 - 1.827_502 * u).atanh()
}

#[inline]
pub fn visible_wavelength_pdf(lambda: f32) -> f32 {
    if !(360.0..=830.0).contains(&lambda) {
        return 0.0;
    }
    let c = (0.0072 * (lambda - 538.0)).cosh();
    0.003_939_804 / (c * c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn visible_pdf_integrates_to_one() {
        let n = 470_000;
        let h = 470.0 / n as f64;
        let s: f64 =
            (0..n).map(|i| visible_wavelength_pdf(360.0 + (i as f64 + 0.5) as f32 * h as f32) as f64 * h).sum();
        assert!((s - 1.0).abs() < 1e-3, "{s}");
    }

    #[test]
    fn inverse_cdf_covers_the_range() {
        assert!((sample_visible_wavelength(0.0) - 360.0).abs() < 0.5);
        assert!((sample_visible_wavelength(1.0) - 830.0).abs() < 0.5);
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
