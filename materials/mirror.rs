//! `mirror`: a perfect specular reflector whose reflectance is the same for
//! every direction (no Fresnel term): a delta lobe wi = (-wo.x, -wo.y, wo.z)
//! carrying `reflectance` (pbrt-v3's `SpecularReflection` with
//! `FresnelNoOp`).
//!
//! Not physical (a real metal is the `conductor`), but its directional albedo
//! is the constant rho, which the white-room and furnace tests need
//! (VALIDATION.md §2: L = Le / (1 - rho) holds only for direction-independent
//! albedos). Kept as its own BSDF rather than a conductor option so that the
//! conductor's parameters stay physical and the mirror has no unused ones.
//! Two-sided, like the conductor.
//!
//! | parameter   | type     | default | meaning                                   |
//! |-------------|----------|---------|-------------------------------------------|
//! | reflectance | spectrum | 1       | rho(lambda) in [0, 1], for every direction |

use super::fresnel::reflect_z;
use super::{BsdfFlags, BsdfSample, TransportMode};
use crate::spectrum::{SampledSpectrum, SampledWavelengths, Spectrum};
use glam::{Vec2, Vec3A};

#[derive(Clone, Debug)]
pub struct Mirror {
    pub reflectance: Spectrum,
}

impl Mirror {
    pub fn new(reflectance: Spectrum) -> Self {
        Self { reflectance }
    }

    #[inline]
    pub fn eval(&self, _wo: Vec3A, _wi: Vec3A, _lambda: &SampledWavelengths, _mode: TransportMode) -> SampledSpectrum {
        SampledSpectrum::ZERO
    }

    #[inline]
    pub fn sample(
        &self,
        wo: Vec3A,
        _uc: f32,
        _u2: Vec2,
        lambda: &SampledWavelengths,
        _mode: TransportMode,
    ) -> Option<BsdfSample> {
        let wi = reflect_z(wo);
        BsdfSample::specular(wi, self.reflectance.sample(lambda), 1.0, BsdfFlags::SPECULAR_REFLECTION, 1.0)
    }

    #[inline]
    pub fn pdf(&self, _wo: Vec3A, _wi: Vec3A, _lambda: &SampledWavelengths, _mode: TransportMode) -> f32 {
        0.0
    }

    pub fn flags(&self) -> BsdfFlags {
        BsdfFlags::SPECULAR_REFLECTION
    }

    pub fn is_dispersive(&self) -> bool {
        false
    }
}
