//! Helpers shared by the BSDF test files: the chi-square machinery, fixed
//! wavelengths, directions from angles, the BSDF parameter sets, and the
//! `TestBsdf` trait through which the checks also run on deliberately broken
//! BSDFs (the negative controls).
#![allow(dead_code)]

pub mod albedo;
pub mod chi2;
pub mod seeds;

use glam::{Vec2, Vec3A};
use prism::materials::{Bsdf, BsdfSample, Conductor, Dielectric, Diffuse, Mirror, TransportMode};
use prism::spectrum::{SampledSpectrum, SampledWavelengths, Spectrum};

/// The seed of every statistical test; override with PRISM_TEST_SEED to check
/// that the tests pass for other seeds too (VALIDATION.md §1).
pub fn seed() -> u64 {
    seeds::from_env("PRISM_TEST_SEED", 0x5EED_B5DF)
}

/// Four fixed wavelengths (hero ~ 556 nm).
pub fn lambda() -> SampledWavelengths {
    SampledWavelengths::sample_visible(0.37)
}

/// The unit direction with cos theta = `cos_theta` and azimuth `phi`.
pub fn dir(cos_theta: f32, phi: f32) -> Vec3A {
    let sin = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    Vec3A::new(sin * phi.cos(), sin * phi.sin(), cos_theta)
}

/// Silver-like constant complex IOR (eta, k) at 550 nm.
pub fn conductor(alpha_x: f32, alpha_y: f32) -> Bsdf {
    Bsdf::Conductor(Conductor::new(Spectrum::Constant(0.13), Spectrum::Constant(3.6), alpha_x, alpha_y))
}

/// A wavelength-dependent conductor (gold-like shape) for spectral checks.
pub fn spectral_conductor(alpha: f32) -> Bsdf {
    let eta = Spectrum::piecewise_linear(&[(400.0, 1.5), (550.0, 0.4), (700.0, 0.15)]);
    let k = Spectrum::piecewise_linear(&[(400.0, 1.9), (550.0, 2.3), (700.0, 4.0)]);
    Bsdf::Conductor(Conductor::new(eta, k, alpha, alpha))
}

pub fn dielectric(eta: f32, alpha_x: f32, alpha_y: f32) -> Bsdf {
    Bsdf::Dielectric(Dielectric::new(Spectrum::Constant(eta), alpha_x, alpha_y))
}

/// A dispersive glass (Cauchy-like BK7 shape).
pub fn dispersive_dielectric(alpha: f32) -> Bsdf {
    let eta = Spectrum::from_fn(|l| 1.5046 + 4200.0 / (l * l));
    Bsdf::Dielectric(Dielectric::new(eta, alpha, alpha))
}

pub fn diffuse(r: f32) -> Bsdf {
    Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(r)))
}

pub fn mirror(r: f32) -> Bsdf {
    Bsdf::Mirror(Mirror::new(Spectrum::Constant(r)))
}

/// What the checks need from a BSDF; implemented by `Bsdf` and by the broken
/// wrappers of the negative controls.
pub trait TestBsdf {
    fn eval(&self, wo: Vec3A, wi: Vec3A, mode: TransportMode) -> SampledSpectrum;
    fn sample(&self, wo: Vec3A, uc: f32, u2: Vec2, mode: TransportMode) -> Option<BsdfSample>;
    fn pdf(&self, wo: Vec3A, wi: Vec3A, mode: TransportMode) -> f32;
}

impl TestBsdf for Bsdf {
    fn eval(&self, wo: Vec3A, wi: Vec3A, mode: TransportMode) -> SampledSpectrum {
        Bsdf::eval(self, wo, wi, &lambda(), mode)
    }
    fn sample(&self, wo: Vec3A, uc: f32, u2: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        Bsdf::sample(self, wo, uc, u2, &lambda(), mode)
    }
    fn pdf(&self, wo: Vec3A, wi: Vec3A, mode: TransportMode) -> f32 {
        Bsdf::pdf(self, wo, wi, &lambda(), mode)
    }
}

/// Relative difference |a - b| / max(|a|, |b|, floor).
pub fn rel_diff(a: f32, b: f32, floor: f32) -> f32 {
    (a - b).abs() / a.abs().max(b.abs()).max(floor)
}
