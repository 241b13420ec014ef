//! `diffuse`: the Lambertian BRDF, f = R / pi, cosine-weighted sampling.
//!
//! | parameter   | type     | default | meaning                              |
//! |-------------|----------|---------|--------------------------------------|
//! | reflectance | spectrum | 0.5     | albedo R(lambda), in [0, 1]          |

use super::{abs_cos_theta, same_hemisphere, BsdfEval, BsdfFlags, BsdfSample, TransportMode};
use crate::sampling::{cosine_hemisphere, cosine_hemisphere_pdf};
use crate::spectrum::{SampledSpectrum, SampledWavelengths, Spectrum};
use glam::{Vec2, Vec3A};
use std::f32::consts::FRAC_1_PI;

#[derive(Clone, Debug)]
pub struct Diffuse {
    pub reflectance: Spectrum,
}

impl Diffuse {
    pub fn new(reflectance: Spectrum) -> Self {
        Self { reflectance }
    }

    #[inline]
    pub fn eval(&self, wo: Vec3A, wi: Vec3A, lambda: &SampledWavelengths, _mode: TransportMode) -> SampledSpectrum {
        if !same_hemisphere(wo, wi) {
            return SampledSpectrum::ZERO;
        }
        self.reflectance.sample(lambda) * FRAC_1_PI
    }

    #[inline]
    pub fn sample(
        &self,
        wo: Vec3A,
        _uc: f32,
        u2: Vec2,
        lambda: &SampledWavelengths,
        _mode: TransportMode,
    ) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let mut wi = cosine_hemisphere(u2);
        if wo.z < 0.0 {
            wi.z = -wi.z;
        }
        let pdf = cosine_hemisphere_pdf(abs_cos_theta(wi));
        if pdf == 0.0 {
            return None;
        }
        Some(BsdfSample {
            wi,
            f: self.reflectance.sample(lambda) * FRAC_1_PI,
            pdf,
            flags: BsdfFlags::DIFFUSE_REFLECTION,
            eta: 1.0,
        })
    }

    #[inline]
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A, _lambda: &SampledWavelengths, _mode: TransportMode) -> f32 {
        if !same_hemisphere(wo, wi) {
            return 0.0;
        }
        cosine_hemisphere_pdf(abs_cos_theta(wi))
    }

    /// `eval` and `pdf` both ways with one hemisphere test.
    #[inline]
    pub fn eval_with_pdfs(&self, wo: Vec3A, wi: Vec3A, lambda: &SampledWavelengths) -> BsdfEval {
        if !same_hemisphere(wo, wi) {
            return BsdfEval { f: SampledSpectrum::ZERO, pdf: 0.0, pdf_rev: 0.0 };
        }
        BsdfEval {
            f: self.reflectance.sample(lambda) * FRAC_1_PI,
            pdf: cosine_hemisphere_pdf(abs_cos_theta(wi)),
            pdf_rev: cosine_hemisphere_pdf(abs_cos_theta(wo)),
        }
    }

    pub fn flags(&self) -> BsdfFlags {
        BsdfFlags::DIFFUSE_REFLECTION
    }

    pub fn is_dispersive(&self) -> bool {
        false
    }
}
