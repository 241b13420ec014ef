//! `conductor`: a metal, smooth (a delta mirror lobe weighted by the conductor
//! Fresnel reflectance) or rough (the Torrance-Sparrow microfacet BRDF with a
//! Trowbridge-Reitz distribution and visible-normal sampling).
//!
//! f(wo, wi) = D(wm) F(wo.wm) G2(wo, wi) / (4 |cos theta_o| |cos theta_i|),
//! wm = normalize(wo + wi) (Torrance & Sparrow 1967; Walter et al. 2007 eq. 20;
//! Heitz 2014 eq. 99 for G2). Sampling draws a visible normal (see
//! `microfacet`) and reflects wo about it: pdf = D_wo(wm) / (4 |wo.wm|)
//! (Walter et al. 2007 eq. 14; Heitz 2018 eq. 17). Fresnel: `fr_conductor`
//! with the complex index eta + i k at each of the four wavelengths. The
//! surface is two-sided: for wo below the surface, both lobes are mirrored.
//! A constant-reflectance mirror without Fresnel is the separate `mirror` BSDF.
//!
//! | parameter | type            | default | meaning                                                   |
//! |-----------|-----------------|---------|-----------------------------------------------------------|
//! | metal     | string          | "Cu"    | named measured metal (`spectrum::METAL_NAMES`): sets eta, k |
//! | eta       | spectrum        | -       | real part of the complex IOR (with `k`, instead of metal)  |
//! | k         | spectrum        | -       | imaginary part (absorption); required with `eta`            |
//! | roughness | float           | 0       | perceptual roughness, alpha = roughness^2                 |
//! | alpha     | float           | -       | isotropic GGX alpha (instead of roughness)                |
//! | alpha_x   | float           | -       | anisotropic GGX alpha along x (with alpha_y)              |
//! | alpha_y   | float           | -       | anisotropic GGX alpha along y (with alpha_x)              |
//!
//! max(alpha_x, alpha_y) < 1e-3 gives the smooth (delta) conductor.

use super::fresnel::{fr_conductor, reflect, reflect_z};
use super::microfacet::TrowbridgeReitz;
use super::{same_hemisphere, BsdfFlags, BsdfSample, TransportMode};
use crate::spectrum::{SampledSpectrum, SampledWavelengths, Spectrum};
use glam::{Vec2, Vec3A};

#[derive(Clone, Debug)]
pub struct Conductor {
    pub eta: Spectrum,
    pub k: Spectrum,
    pub distrib: TrowbridgeReitz,
}

impl Conductor {
    pub fn new(eta: Spectrum, k: Spectrum, alpha_x: f32, alpha_y: f32) -> Self {
        Self { eta, k, distrib: TrowbridgeReitz::new(alpha_x, alpha_y) }
    }

    #[inline]
    fn fresnel(&self, cos_theta: f32, lambda: &SampledWavelengths) -> SampledSpectrum {
        fr_conductor(cos_theta.abs(), self.eta.sample(lambda), self.k.sample(lambda))
    }

    /// The Torrance-Sparrow BRDF at a known half vector `wm` (upper hemisphere).
    #[inline]
    fn f_microfacet(&self, wo: Vec3A, wi: Vec3A, wm: Vec3A, lambda: &SampledWavelengths) -> SampledSpectrum {
        let d = &self.distrib;
        // Divided one cosine at a time: their product can underflow.
        let s = d.D(wm) * d.G2(wo, wi) / (4.0 * wo.z.abs()) / wi.z.abs();
        self.fresnel(wo.dot(wm), lambda) * s
    }

    #[inline]
    pub fn eval(&self, wo: Vec3A, wi: Vec3A, lambda: &SampledWavelengths, _mode: TransportMode) -> SampledSpectrum {
        match self.half_vector(wo, wi) {
            Some(wm) => self.f_microfacet(wo, wi, wm, lambda),
            None => SampledSpectrum::ZERO,
        }
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
        if self.distrib.effectively_smooth() {
            let wi = reflect_z(wo);
            let weight = self.fresnel(wo.z, lambda);
            return BsdfSample::specular(wi, weight, 1.0, BsdfFlags::SPECULAR_REFLECTION, 1.0);
        }
        let wi = reflect(wo, self.distrib.sample_wm(wo, u2));
        // f and pdf from the half vector of (wo, wi), not the sampled normal:
        // the same arithmetic as eval() and pdf(), so they agree exactly
        // (at grazing angles with tiny alpha the two differ by f32 rounding).
        let wm = self.half_vector(wo, wi)?;
        let pdf = self.distrib.pdf_reflected(wo, wm);
        if pdf.is_nan() || pdf <= 0.0 {
            return None;
        }
        let f = self.f_microfacet(wo, wi, wm, lambda);
        Some(BsdfSample { wi, f, pdf, flags: BsdfFlags::GLOSSY_REFLECTION, eta: 1.0 })
    }

    #[inline]
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A, _lambda: &SampledWavelengths, _mode: TransportMode) -> f32 {
        match self.half_vector(wo, wi) {
            Some(wm) => self.distrib.pdf_reflected(wo, wm),
            None => 0.0,
        }
    }

    /// The reflection half vector, faced to +z, or None where the rough lobe
    /// is zero (smooth surface, opposite sides, grazing, or wi = -wo).
    #[inline]
    fn half_vector(&self, wo: Vec3A, wi: Vec3A) -> Option<Vec3A> {
        if self.distrib.effectively_smooth() || !same_hemisphere(wo, wi) {
            return None;
        }
        let wm = (wo + wi).try_normalize()?;
        Some(if wm.z < 0.0 { -wm } else { wm })
    }

    pub fn flags(&self) -> BsdfFlags {
        if self.distrib.effectively_smooth() {
            BsdfFlags::SPECULAR_REFLECTION
        } else {
            BsdfFlags::GLOSSY_REFLECTION
        }
    }

    pub fn is_dispersive(&self) -> bool {
        false
    }
}
