//! `dielectric`: an interface between two dielectrics (glass, water, an air
//! bubble), smooth or rough, reflecting and transmitting.
//!
//! - Smooth (effectively smooth alpha, or eta = 1): a delta reflection and a
//!   delta refraction, one chosen with probability R or T = 1 - R (exact
//!   Fresnel, `fr_dielectric`). eta = 1 is a pure pass-through (R = 0) at any
//!   roughness: a rough interface between equal indices does not exist.
//! - Rough: Walter, Marschner, Li & Torrance 2007, "Microfacet Models for
//!   Refraction through Rough Surfaces": reflection eq. 20, transmission
//!   eq. 21, generalised half vector eq. 16, Jacobians eqs. 14 and 17, with
//!   the Trowbridge-Reitz distribution, G2 (for both lobes, as pbrt-v4)
//!   and visible-normal sampling of `microfacet`. The design follows
//!   pbrt-v4's `DielectricBxDF` (§9.7): a visible normal is drawn, then
//!   reflection or refraction about it with probability R(wo.wm) or
//!   T(wo.wm); microfacets back-facing wo or wi are discarded (the chi+
//!   factors of Walter's G1; pbrt-v4's test).
//! - `eta` is the IOR of the inside (the side the normal points away from)
//!   relative to the outside; wo inside means the relative index is 1/eta.
//! - Transport mode (Veach 1997 §5.2): in `Radiance` mode transmission is
//!   scaled by 1/eta'^2, eta' = eta_t / eta_i the relative index crossed
//!   (`BsdfSample::eta`); `Importance` mode has no such factor. So
//!   f_radiance(wo, wi) = f_importance(wi, wo) for every pair.
//! - Dispersion: directions and every value use eta at the hero wavelength
//!   (`lambda.hero()`). For a non-constant eta (`is_dispersive`) the
//!   integrator keeps only the hero wavelength; f is then returned in the hero
//!   lane with the three secondary lanes set to 0, so a caller that forgot to
//!   terminate the secondaries loses energy visibly instead of smearing the
//!   hero's value over other wavelengths. A constant eta fills all four lanes.
//!
//! | parameter | type                    | default | meaning                                                  |
//! |-----------|-------------------------|---------|----------------------------------------------------------|
//! | ior       | float, spectrum or name | 1.5     | eta inside / outside; a name from `spectrum::GLASS_NAMES` |
//! | roughness | float                   | 0       | perceptual roughness, alpha = roughness^2                |
//! | alpha     | float                   | -       | isotropic GGX alpha (instead of roughness)               |
//! | alpha_x   | float                   | -       | anisotropic GGX alpha along x (with alpha_y)             |
//! | alpha_y   | float                   | -       | anisotropic GGX alpha along y (with alpha_x)             |

use super::fresnel::{fr_dielectric, fr_dielectric_reflected, fr_dielectric_refracted, reflect, reflect_z, refract};
use super::microfacet::{refraction_jacobian, TrowbridgeReitz};
use super::{BsdfFlags, BsdfSample, TransportMode};
use crate::sampling::on_u_grid;
use crate::spectrum::{SampledSpectrum, SampledWavelengths, Spectrum};
use glam::{Vec2, Vec3A};

#[derive(Clone, Debug)]
pub struct Dielectric {
    /// Index of the inside relative to the outside (the struct field behind
    /// the scene's `ior`).
    pub eta: Spectrum,
    pub distrib: TrowbridgeReitz,
}

/// The (generalised) half vector of a direction pair and what it implies.
#[derive(Clone, Copy, Debug)]
struct HalfVector {
    /// Microfacet normal, upper hemisphere.
    wm: Vec3A,
    /// eta_i / eta_o: index on wi's side over index on wo's side (1 for
    /// reflection).
    etap: f32,
    reflect: bool,
}

impl HalfVector {
    /// R(wo.wm) from the pair, exact near the critical angle, where Snell's
    /// law from an f32 cosine is not: for a refraction from wi's own cosine
    /// to the microfacet (`fr_dielectric_refracted`), for a reflection from
    /// the half vector in f64 (`fr_dielectric_reflected`). eval and pdf, and
    /// the f and pdf that sample returns, take it from here, so they agree
    /// exactly; sample's choice of lobe, made before wi exists, uses Snell's
    /// law at the sampled normal.
    #[inline]
    fn fresnel(&self, wo: Vec3A, wi: Vec3A, eta: f32) -> f32 {
        if self.reflect {
            fr_dielectric_reflected(wo, wi, eta)
        } else {
            fr_dielectric_refracted(wo.dot(self.wm), wi.dot(self.wm), eta)
        }
    }
}

impl Dielectric {
    /// The least |eta - 1| a rough interface may have (eta = 1 exactly is
    /// a pass-through). Nearer to 1 the generalised half vector eta wi + wo
    /// (Walter et al. eq. 16) is a difference of nearly opposite unit
    /// vectors, of length about |eta - 1|, so f32's rounding of 6e-8 is a
    /// fraction 6e-8 / |eta - 1| of it: at eta = 1 + 2^-23 and alpha 1,
    /// `sample` found a quarter of its refractions facing away from the
    /// recomputed normal and dropped them (an audit, session 36). At 1e-4
    /// the normal is good to 6e-4 and none of 8000 samples was lost
    /// (tests/bsdf_props.rs `rough_interfaces_near_index_one_keep_their_samples`).
    pub const MIN_INDEX_CONTRAST: f32 = 1e-4;

    /// The least alpha |eta - 1| a rough interface may have: about the
    /// width in radians of its refraction lobe, of which the half vector's
    /// rounding (6e-8 / |eta - 1|, above) must stay a small fraction. At
    /// eta 1.0002 and alpha 0.0025 (5e-7) `bdpt` read 28 % dark, 16 % at
    /// alpha 0.01 and 1.3 % at 0.04, while `path` and `light` were right
    /// (an audit, session 44): its connections evaluate the lobe at
    /// directions rounding has moved by a tenth of its width. At 5e-5 the
    /// half vector is good to 1.2e-3 of the lobe (tests/agreement.rs
    /// `bdpt_agrees_through_rough_glass_near_index_one`).
    pub const MIN_LOBE_WIDTH: f32 = 5e-5;

    pub fn new(eta: Spectrum, alpha_x: f32, alpha_y: f32) -> Self {
        Self { eta, distrib: TrowbridgeReitz::new(alpha_x, alpha_y) }
    }

    /// The least |eta - 1| a rough interface of this roughness may have:
    /// `MIN_INDEX_CONTRAST`, and `MIN_LOBE_WIDTH` over its narrower alpha.
    pub fn min_index_contrast(&self) -> f32 {
        Self::MIN_INDEX_CONTRAST.max(Self::MIN_LOBE_WIDTH / self.narrower_alpha())
    }

    pub fn narrower_alpha(&self) -> f32 {
        self.distrib.alpha_x.min(self.distrib.alpha_y)
    }

    /// "at least B at alpha A, its narrower": why `index_unresolved`, for
    /// the loaders' messages, B rounded up to three digits (rounded to
    /// nearest it could read below the index it refuses; f32's last place
    /// is not rounded up: 2e-4 reads 2.00e-4).
    pub fn min_index_contrast_text(&self) -> String {
        let b = self.min_index_contrast() as f64;
        let step = 10f64.powi(b.log10().floor() as i32 - 2);
        let shown = (b / step * (1.0 - 1e-6)).ceil() * step;
        format!("at least {shown:.2e} at alpha {}, its narrower", self.narrower_alpha())
    }

    /// Rough, with eta within `min_index_contrast` of 1 at some wavelength
    /// but not 1 everywhere: an interface f32 cannot resolve, which the
    /// loaders refuse.
    pub fn index_unresolved(&self) -> bool {
        let c = self.min_index_contrast();
        // (A table of 1s is `Constant(1.0)`: `Spectrum::from_dense`.)
        !self.distrib.effectively_smooth()
            && self.eta != Spectrum::Constant(1.0)
            && self.eta.min_value() < 1.0 + c
            && self.eta.max_value() > 1.0 - c
    }

    /// The relative index that drives directions: the hero wavelength's.
    #[inline]
    fn hero_eta(&self, lambda: &SampledWavelengths) -> f32 {
        self.eta.eval(lambda.hero())
    }

    #[inline]
    fn is_smooth(&self, eta: f32) -> bool {
        eta == 1.0 || self.distrib.effectively_smooth()
    }

    /// A value computed at the hero eta as a spectrum (see the module doc).
    #[inline]
    fn spectral(&self, v: f32) -> SampledSpectrum {
        if self.is_dispersive() {
            SampledSpectrum::new(v, 0.0, 0.0, 0.0)
        } else {
            SampledSpectrum::splat(v)
        }
    }

    #[inline]
    pub fn eval(&self, wo: Vec3A, wi: Vec3A, lambda: &SampledWavelengths, mode: TransportMode) -> SampledSpectrum {
        let eta = self.hero_eta(lambda);
        if self.is_smooth(eta) {
            return SampledSpectrum::ZERO;
        }
        match half_vector(wo, wi, eta) {
            Some(h) => self.spectral(self.f_rough(wo, wi, h, h.fresnel(wo, wi, eta), mode)),
            None => SampledSpectrum::ZERO,
        }
    }

    #[inline]
    pub fn sample(
        &self,
        wo: Vec3A,
        uc: f32,
        u2: Vec2,
        lambda: &SampledWavelengths,
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        let eta = self.hero_eta(lambda);
        if self.is_smooth(eta) {
            self.sample_smooth(wo, uc, eta, mode)
        } else {
            self.sample_rough(wo, uc, u2, eta, mode)
        }
    }

    #[inline]
    pub fn pdf(&self, wo: Vec3A, wi: Vec3A, lambda: &SampledWavelengths, _mode: TransportMode) -> f32 {
        let eta = self.hero_eta(lambda);
        if self.is_smooth(eta) {
            return 0.0;
        }
        match half_vector(wo, wi, eta) {
            Some(h) => self.pdf_rough(wo, wi, h, h.fresnel(wo, wi, eta)),
            None => 0.0,
        }
    }

    pub fn flags(&self) -> BsdfFlags {
        if self.eta == Spectrum::Constant(1.0) {
            BsdfFlags::SPECULAR_TRANSMISSION
        } else if self.distrib.effectively_smooth() {
            BsdfFlags::SPECULAR_REFLECTION | BsdfFlags::SPECULAR_TRANSMISSION
        } else {
            BsdfFlags::GLOSSY_REFLECTION | BsdfFlags::GLOSSY_TRANSMISSION
        }
    }

    pub fn is_dispersive(&self) -> bool {
        !self.eta.is_constant()
    }

    /// Delta reflection with probability R, delta refraction with T = 1 - R
    /// (pbrt-v4 §9.5), R on the sampler's grid (`on_u_grid`): each sample's
    /// weight f |cos| / pdf is 1 (R / p and T / (1 - p) where R is within
    /// 2^-25 of 0 or 1), times 1/eta'^2 for radiance-mode transmission
    /// (§9.5.2).
    fn sample_smooth(&self, wo: Vec3A, uc: f32, eta: f32, mode: TransportMode) -> Option<BsdfSample> {
        let r = fr_dielectric(wo.z, eta);
        let p = on_u_grid(r);
        if uc < p {
            let wi = reflect_z(wo);
            return BsdfSample::specular(wi, self.spectral(r), p, BsdfFlags::SPECULAR_REFLECTION, 1.0);
        }
        let (wi, etap) = refract(wo, Vec3A::Z, eta)?;
        let scale = (1.0 - r) * radiance_scale(mode, etap);
        BsdfSample::specular(wi, self.spectral(scale), 1.0 - p, BsdfFlags::SPECULAR_TRANSMISSION, etap)
    }

    /// Visible normal, then reflection (probability R(wo.wm)) or refraction.
    fn sample_rough(&self, wo: Vec3A, uc: f32, u2: Vec2, eta: f32, mode: TransportMode) -> Option<BsdfSample> {
        if wo.z == 0.0 {
            return None;
        }
        let wm = self.distrib.sample_wm(wo, u2);
        let r = fr_dielectric(wo.dot(wm), eta);
        let (wi, flags) = if uc < on_u_grid(r) {
            (reflect(wo, wm), BsdfFlags::GLOSSY_REFLECTION)
        } else {
            (refract(wo, wm, eta)?.0, BsdfFlags::GLOSSY_TRANSMISSION)
        };
        // f and pdf from the half vector of (wo, wi), not the sampled normal:
        // the same arithmetic as eval() and pdf(), so they agree exactly.
        let h = half_vector(wo, wi, eta)?;
        if h.reflect != flags.is_reflection() {
            return None;
        }
        let r = h.fresnel(wo, wi, eta);
        let pdf = self.pdf_rough(wo, wi, h, r);
        if pdf.is_nan() || pdf <= 0.0 {
            return None;
        }
        let f = self.spectral(self.f_rough(wo, wi, h, r, mode));
        Some(BsdfSample { wi, f, pdf, flags, eta: h.etap })
    }

    /// Walter et al. 2007 eq. 20 (reflection) and eq. 21 (transmission, as
    /// D G2 T |wo.wm| |dwm/dwi| / (|cos_o| |cos_i|)), `r` = R(wo.wm).
    fn f_rough(&self, wo: Vec3A, wi: Vec3A, h: HalfVector, r: f32, mode: TransportMode) -> f32 {
        let d = &self.distrib;
        // Divided one cosine at a time: their product can underflow.
        let dg = d.D(h.wm) * d.G2(wo, wi) / wo.z.abs() / wi.z.abs();
        if h.reflect {
            dg * r / 4.0
        } else {
            let jacobian = refraction_jacobian(wo, wi, h.wm, h.etap);
            dg * (1.0 - r) * wo.dot(h.wm).abs() * jacobian * radiance_scale(mode, h.etap)
        }
    }

    /// Visible-normal density times the Jacobian, times the lobe probability
    /// (R on the sampler's grid, as `sample_rough` chooses by it).
    fn pdf_rough(&self, wo: Vec3A, wi: Vec3A, h: HalfVector, r: f32) -> f32 {
        let d = &self.distrib;
        let p = on_u_grid(r);
        if h.reflect {
            d.pdf_reflected(wo, h.wm) * p
        } else {
            d.pdf_refracted(wo, wi, h.wm, h.etap) * (1.0 - p)
        }
    }
}

/// The generalised half vector wm ~ wo + eta' wi (Walter et al. 2007 eq. 16;
/// wo + wi for reflection), faced to +z, or None where the rough lobes vanish:
/// grazing directions, a degenerate pair, or a microfacet that faces away
/// from wo or wi (Walter §5.3).
#[inline]
fn half_vector(wo: Vec3A, wi: Vec3A, eta: f32) -> Option<HalfVector> {
    let (cos_o, cos_i) = (wo.z, wi.z);
    if cos_o == 0.0 || cos_i == 0.0 {
        return None;
    }
    let reflect = (cos_o > 0.0) == (cos_i > 0.0);
    let etap = match (reflect, cos_o > 0.0) {
        (true, _) => 1.0,
        (false, true) => eta,
        (false, false) => 1.0 / eta,
    };
    let wm = (wi * etap + wo).try_normalize()?;
    let wm = if wm.z < 0.0 { -wm } else { wm };
    if wm.dot(wi) * cos_i <= 0.0 || wm.dot(wo) * cos_o <= 0.0 {
        return None;
    }
    Some(HalfVector { wm, etap, reflect })
}

/// Veach 1997 §5.2: light entering a medium of index eta_t from eta_i has its
/// radiance multiplied by (eta_t / eta_i)^2. Here light flows from wi's side
/// to wo's, against the path, so radiance mode takes 1/eta'^2 (eta' = the
/// index on wi's side over wo's); the adjoint, importance, takes none.
#[inline]
fn radiance_scale(mode: TransportMode, etap: f32) -> f32 {
    match mode {
        TransportMode::Radiance => 1.0 / (etap * etap),
        TransportMode::Importance => 1.0,
    }
}
