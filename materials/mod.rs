//! The spectral BSDF library, shared by every integrator.
//!
//! Conventions (pbrt-v4's):
//! - Directions are unit vectors in the local shading frame, normal along +z,
//!   both `wo` and `wi` pointing away from the surface.
//! - `eval` returns f(wo, wi) WITHOUT the cosine factor; integrators multiply
//!   by |cos theta_i| themselves.
//! - `sample` returns f, the pdf (solid angle) and the flags of the lobe it
//!   chose; for a delta (specular) lobe `pdf` is the discrete probability of
//!   that lobe and `f` is the delta's weight divided by |cos theta_i|, so
//!   f |cos| / pdf is the throughput either way. `eval` and `pdf` return 0 for
//!   delta lobes.
//! - `TransportMode` says which quantity flows along the path: radiance
//!   (camera paths) or importance (light paths). Refraction scales radiance by
//!   1/eta^2 (Veach 1997 §5.2) in radiance mode only. Veach's shading-normal
//!   correction (§5.3) is NOT applied here: it is geometric, so integrators
//!   apply it where they call the BSDF in importance mode (src/path.rs).
//! - Random numbers come in as arguments (`uc` picks a lobe, `u2` the
//!   direction), never an RNG, so tests can drive them.
//! - For non-delta lobes, `sample` returns exactly what `eval` and `pdf`
//!   return at its direction (same arithmetic), so MIS and BDPT's
//!   forward/reverse pdfs agree bit for bit.
//!
//! BSDFs (one per file, JSON `"type"` = file name, parameter table in each
//! file's header): `diffuse`, `conductor`, `dielectric`, `mirror`. Shared
//! math: `fresnel` (Fresnel equations, reflect, refract) and `microfacet`
//! (Trowbridge-Reitz D, Lambda, G1, G2, visible-normal sampling).
//! Tests: tests/bsdf_chi2.rs, tests/bsdf_props.rs; bench: benches/bsdf.rs.

mod conductor;
mod dielectric;
mod diffuse;
pub mod fresnel;
pub mod microfacet;
mod mirror;

pub use conductor::Conductor;
pub use dielectric::Dielectric;
pub use diffuse::Diffuse;
pub use microfacet::{roughness_to_alpha, TrowbridgeReitz};
pub use mirror::Mirror;

use crate::spectrum::{SampledSpectrum, SampledWavelengths};
use glam::{Vec2, Vec3A};

/// Which quantity a path carries (Veach 1997 §5.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TransportMode {
    /// Camera paths: radiance flows towards the camera.
    Radiance,
    /// Light paths: importance flows towards the light (the adjoint BSDF).
    Importance,
}

impl TransportMode {
    pub fn flip(self) -> Self {
        match self {
            TransportMode::Radiance => TransportMode::Importance,
            TransportMode::Importance => TransportMode::Radiance,
        }
    }
}

/// What kind of lobe a BSDF has or a sample came from (bit set).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct BsdfFlags(pub u8);

impl BsdfFlags {
    pub const REFLECTION: Self = Self(1);
    pub const TRANSMISSION: Self = Self(2);
    pub const DIFFUSE: Self = Self(4);
    pub const GLOSSY: Self = Self(8);
    pub const SPECULAR: Self = Self(16);

    pub const DIFFUSE_REFLECTION: Self = Self(1 | 4);
    pub const GLOSSY_REFLECTION: Self = Self(1 | 8);
    pub const GLOSSY_TRANSMISSION: Self = Self(2 | 8);
    pub const SPECULAR_REFLECTION: Self = Self(1 | 16);
    pub const SPECULAR_TRANSMISSION: Self = Self(2 | 16);

    #[inline]
    pub fn contains(self, o: Self) -> bool {
        self.0 & o.0 == o.0
    }
    #[inline]
    pub fn is_specular(self) -> bool {
        self.0 & Self::SPECULAR.0 != 0
    }
    #[inline]
    pub fn is_transmission(self) -> bool {
        self.0 & Self::TRANSMISSION.0 != 0
    }
    #[inline]
    pub fn is_reflection(self) -> bool {
        self.0 & Self::REFLECTION.0 != 0
    }
    /// Has a lobe that a connection (NEE, BDPT) can evaluate.
    #[inline]
    pub fn is_non_specular(self) -> bool {
        self.0 & (Self::DIFFUSE.0 | Self::GLOSSY.0) != 0
    }
}

impl std::ops::BitOr for BsdfFlags {
    type Output = Self;
    fn bitor(self, o: Self) -> Self {
        Self(self.0 | o.0)
    }
}

/// A direction drawn by `Bsdf::sample`.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    pub wi: Vec3A,
    pub f: SampledSpectrum,
    /// Solid-angle density of wi (for specular lobes: the lobe's probability).
    pub pdf: f32,
    pub flags: BsdfFlags,
    /// Relative IOR eta_t / eta_i across the boundary for transmission, 1 for
    /// reflection (used to take 1/eta^2 out of roulette's throughput).
    pub eta: f32,
}

impl BsdfSample {
    #[inline]
    pub fn is_specular(&self) -> bool {
        self.flags.is_specular()
    }

    /// A sample of a delta lobe `scale * delta(w - wi) / |cos theta_i|`
    /// chosen with probability `pdf`; None at (numerically) grazing wi or for
    /// an impossible lobe, so no caller ever sees an infinite f or a zero pdf.
    #[inline]
    pub(crate) fn specular(wi: Vec3A, scale: SampledSpectrum, pdf: f32, flags: BsdfFlags, eta: f32) -> Option<Self> {
        let f = scale / wi.z.abs();
        if pdf.is_nan() || pdf <= 0.0 || !f.is_finite() {
            return None;
        }
        Some(Self { wi, f, pdf, flags, eta })
    }
}

/// `Bsdf::eval_with_pdfs`: f(wo, wi), pdf(wo -> wi) and pdf(wi -> wo).
#[derive(Clone, Copy, Debug)]
pub struct BsdfEval {
    pub f: SampledSpectrum,
    pub pdf: f32,
    pub pdf_rev: f32,
}

/// Every BSDF prism knows; matched (not dispatched) in the hot loop.
#[derive(Clone, Debug)]
pub enum Bsdf {
    Diffuse(Diffuse),
    Conductor(Conductor),
    Dielectric(Dielectric),
    Mirror(Mirror),
}

macro_rules! dispatch {
    ($self:ident, $b:ident => $e:expr) => {
        match $self {
            Bsdf::Diffuse($b) => $e,
            Bsdf::Conductor($b) => $e,
            Bsdf::Dielectric($b) => $e,
            Bsdf::Mirror($b) => $e,
        }
    };
}

impl Bsdf {
    #[inline]
    pub fn eval(&self, wo: Vec3A, wi: Vec3A, lambda: &SampledWavelengths, mode: TransportMode) -> SampledSpectrum {
        dispatch!(self, b => b.eval(wo, wi, lambda, mode))
    }

    /// Always inlined into the walks (docs/performance-log.md, "Session 16").
    #[inline(always)]
    pub fn sample(
        &self,
        wo: Vec3A,
        uc: f32,
        u2: Vec2,
        lambda: &SampledWavelengths,
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        dispatch!(self, b => b.sample(wo, uc, u2, lambda, mode))
    }

    #[inline]
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A, lambda: &SampledWavelengths, mode: TransportMode) -> f32 {
        dispatch!(self, b => b.pdf(wo, wi, lambda, mode))
    }

    /// f(wo, wi) with the density of sampling wi from wo and, in the adjoint
    /// mode, of sampling wo from wi: what a BDPT connection needs at each end
    /// (SmallVCM `BSDF::Evaluate` returns the same three).
    #[inline]
    pub fn eval_with_pdfs(&self, wo: Vec3A, wi: Vec3A, lambda: &SampledWavelengths, mode: TransportMode) -> BsdfEval {
        match self {
            Bsdf::Diffuse(b) => b.eval_with_pdfs(wo, wi, lambda),
            _ => BsdfEval {
                f: self.eval(wo, wi, lambda, mode),
                pdf: self.pdf(wo, wi, lambda, mode),
                pdf_rev: self.pdf(wi, wo, lambda, mode.flip()),
            },
        }
    }

    /// The union of the lobes' flags.
    #[inline]
    pub fn flags(&self) -> BsdfFlags {
        dispatch!(self, b => b.flags())
    }

    /// Whether the BSDF's directions depend on wavelength (a dispersive IOR):
    /// a path that meets it keeps only its hero wavelength (pbrt-v4
    /// `TerminateSecondary`, done by the integrators when they hit it).
    #[inline]
    pub fn is_dispersive(&self) -> bool {
        dispatch!(self, b => b.is_dispersive())
    }
}

#[inline]
pub fn abs_cos_theta(w: Vec3A) -> f32 {
    w.z.abs()
}

#[inline]
pub fn same_hemisphere(a: Vec3A, b: Vec3A) -> bool {
    a.z * b.z > 0.0
}
