//! `microfacet`: the anisotropic Trowbridge-Reitz (GGX) microfacet
//! distribution with height-correlated Smith masking-shadowing and
//! visible-normal sampling. Not a BSDF: `conductor` and `dielectric` share it.
//!
//! - Trowbridge & Reitz 1975; Walter et al. 2007, "Microfacet Models for
//!   Refraction through Rough Surfaces" (GGX).
//! - Heitz 2014, "Understanding the Masking-Shadowing Function in
//!   Microfacet-Based BRDFs": D (eq. 85, anisotropic), Lambda (eq. 86),
//!   G1 = 1 / (1 + Lambda) (eq. 43), height-correlated
//!   G2 = 1 / (1 + Lambda(wo) + Lambda(wi)) (eq. 99; exact for reflection,
//!   and used for transmission too, as pbrt-v4's `DielectricBxDF` uses it:
//!   the height-correlated form of a transmitted pair is the smaller
//!   B(1 + Lambda(wo), 1 + Lambda(wi)), a Beta function, most so at grazing
//!   angles), and the visible normal
//!   distribution D_wo(wm) = G1(wo) max(0, wo.wm) D(wm) / cos theta_o (eq. 38).
//! - Visible normals are sampled with Dupuy & Benyoub 2023, "Sampling Visible
//!   GGX Normals with Spherical Caps" (HPG; listing 3): stretch the view to
//!   the hemisphere configuration (Heitz 2018, "Sampling the GGX Distribution
//!   of Visible Normals", §3.2), draw the halfway vector between the view and
//!   a uniform point of the spherical cap z in (-wo.z, 1], unstretch.
//!
//! Scene parameters of the BSDFs that use it (same names everywhere):
//!
//! | parameter | type  | default | meaning                                          |
//! |-----------|-------|---------|--------------------------------------------------|
//! | roughness | float | 0       | perceptual roughness r; alpha = r^2 (isotropic)  |
//! | alpha     | float | -       | GGX alpha directly (isotropic)                   |
//! | alpha_x   | float | -       | GGX alpha along the tangent (x: the Duff basis of the shading normal, tied to the world axes); needs alpha_y |
//! | alpha_y   | float | -       | GGX alpha along the bitangent (y); needs alpha_x |
//!
//! At most one of `roughness`, `alpha`, (`alpha_x`, `alpha_y`) may be given.
//! When max(alpha_x, alpha_y) < 1e-3 the surface is "effectively smooth" and
//! the BSDF becomes a delta lobe (pbrt-v4's threshold); otherwise each alpha is
//! raised to at least 1e-4 so that D stays finite in f32 (pbrt-v4 does the same).

use glam::{Vec2, Vec3A};
use std::f32::consts::PI;

/// Perceptual roughness to GGX alpha (Burley 2012: alpha = roughness^2).
#[inline]
pub fn roughness_to_alpha(roughness: f32) -> f32 {
    roughness * roughness
}

/// |dwm/dwi| of the generalised half vector wm ~ wo + etap wi of a refraction
/// (Walter et al. 2007 eq. 17, divided through by eta_i^2 as in pbrt-v4):
/// |wi.wm| / (wi.wm + wo.wm / etap)^2, where etap = eta_i / eta_o is the index
/// on wi's side over the index on wo's side. 0 where it degenerates. Walter
/// names the directions the other way round: his i is our wo, and his o, the
/// sampled direction, is our wi.
#[inline]
pub fn refraction_jacobian(wo: Vec3A, wi: Vec3A, wm: Vec3A, etap: f32) -> f32 {
    let s = wi.dot(wm) + wo.dot(wm) / etap;
    let denom = s * s;
    if denom > 0.0 {
        wi.dot(wm).abs() / denom
    } else {
        0.0
    }
}

/// Trowbridge-Reitz (GGX) distribution of microfacet normals. Directions are
/// in the local shading frame (+z normal); microfacet normals `wm` lie in the
/// upper hemisphere (callers face them forward).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrowbridgeReitz {
    pub alpha_x: f32,
    pub alpha_y: f32,
}

#[allow(non_snake_case)]
impl TrowbridgeReitz {
    /// Below this alpha (both axes) the lobe is treated as a delta.
    pub const SMOOTH_ALPHA: f32 = 1e-3;
    /// Smallest alpha of a rough (non-delta) lobe.
    pub const MIN_ALPHA: f32 = 1e-4;

    pub fn new(alpha_x: f32, alpha_y: f32) -> Self {
        let (ax, ay) = (alpha_x.max(0.0), alpha_y.max(0.0));
        let d = Self { alpha_x: ax, alpha_y: ay };
        if d.effectively_smooth() {
            d
        } else {
            Self { alpha_x: ax.max(Self::MIN_ALPHA), alpha_y: ay.max(Self::MIN_ALPHA) }
        }
    }

    /// Whether the distribution is so narrow that it is treated as a delta.
    #[inline]
    pub fn effectively_smooth(&self) -> bool {
        self.alpha_x.max(self.alpha_y) < Self::SMOOTH_ALPHA
    }

    /// Distribution of normals D(wm), per unit projected area (Heitz 2014
    /// eq. 85): 1 / (pi ax ay (x^2/ax^2 + y^2/ay^2 + z^2)^2) for wm.z > 0.
    #[inline]
    pub fn D(&self, wm: Vec3A) -> f32 {
        if wm.z <= 0.0 {
            return 0.0;
        }
        let (sx, sy) = (wm.x / self.alpha_x, wm.y / self.alpha_y);
        let e = sx * sx + sy * sy + wm.z * wm.z;
        1.0 / (PI * self.alpha_x * self.alpha_y * e * e)
    }

    /// Smith's Lambda (Heitz 2014 eq. 86): (sqrt(1 + alpha^2 tan^2) - 1) / 2,
    /// with alpha^2 tan^2 = (ax^2 x^2 + ay^2 y^2) / z^2; infinite at grazing.
    #[inline]
    pub fn Lambda(&self, w: Vec3A) -> f32 {
        let (x, y) = (self.alpha_x * w.x, self.alpha_y * w.y);
        let a2_tan2 = (x * x + y * y) / (w.z * w.z);
        if !a2_tan2.is_finite() {
            return f32::INFINITY;
        }
        // Same value as (sqrt(1 + t) - 1) / 2 without cancellation near t = 0.
        0.5 * a2_tan2 / ((1.0 + a2_tan2).sqrt() + 1.0)
    }

    /// Smith masking G1(w) = 1 / (1 + Lambda(w)) (Heitz 2014 eq. 43).
    #[inline]
    pub fn G1(&self, w: Vec3A) -> f32 {
        1.0 / (1.0 + self.Lambda(w))
    }

    /// Height-correlated masking-shadowing (Heitz 2014 eq. 99), for a
    /// reflected pair; dielectrics use it for a transmitted pair as well
    /// (see the module's doc).
    #[inline]
    pub fn G2(&self, wo: Vec3A, wi: Vec3A) -> f32 {
        1.0 / (1.0 + self.Lambda(wo) + self.Lambda(wi))
    }

    /// Distribution of normals visible from `w` (Heitz 2014 eq. 38, with |.|
    /// so that `w` may be below the surface: the profile is point-symmetric).
    #[inline]
    pub fn D_visible(&self, w: Vec3A, wm: Vec3A) -> f32 {
        if w.z == 0.0 {
            return 0.0;
        }
        self.G1(w) / w.z.abs() * self.D(wm) * w.dot(wm).abs()
    }

    /// Solid-angle density of `sample_wm(w, .)` at `wm`: the visible normal
    /// distribution itself.
    #[inline]
    pub fn pdf(&self, w: Vec3A, wm: Vec3A) -> f32 {
        self.D_visible(w, wm)
    }

    /// Solid-angle density of wi = reflect(wo, wm) for wm ~ `pdf(wo, .)`:
    /// D_wo(wm) / (4 |wo.wm|) (Walter et al. 2007 eq. 14), written as
    /// G1(wo) D(wm) / (4 |cos theta_o|) so that no |wo.wm| cancels numerically.
    #[inline]
    pub fn pdf_reflected(&self, wo: Vec3A, wm: Vec3A) -> f32 {
        if wo.z == 0.0 {
            return 0.0;
        }
        self.G1(wo) * self.D(wm) / (4.0 * wo.z.abs())
    }

    /// Solid-angle density of wi = refract(wo, wm) for wm ~ `pdf(wo, .)`:
    /// D_wo(wm) |dwm/dwi| (Walter et al. 2007 eq. 17).
    #[inline]
    pub fn pdf_refracted(&self, wo: Vec3A, wi: Vec3A, wm: Vec3A, etap: f32) -> f32 {
        self.pdf(wo, wm) * refraction_jacobian(wo, wi, wm, etap)
    }

    /// Draw a microfacet normal (upper hemisphere) visible from `w` with
    /// density `pdf(w, wm)` (Dupuy & Benyoub 2023, listing 3). A `w` below the
    /// surface is treated as -w.
    #[inline]
    pub fn sample_wm(&self, w: Vec3A, u: Vec2) -> Vec3A {
        let mut wh = Vec3A::new(self.alpha_x * w.x, self.alpha_y * w.y, w.z).normalize_or(Vec3A::Z);
        if wh.z < 0.0 {
            wh = -wh;
        }
        // Uniform point of the spherical cap z in (-wh.z, 1].
        let phi = 2.0 * PI * u.x;
        let z = (1.0 - u.y) * (1.0 + wh.z) - wh.z;
        let sin_theta = (1.0 - z * z).max(0.0).sqrt();
        let (sin_phi, cos_phi) = phi.sin_cos();
        let h = Vec3A::new(sin_theta * cos_phi, sin_theta * sin_phi, z) + wh;
        Vec3A::new(self.alpha_x * h.x, self.alpha_y * h.y, h.z.max(0.0)).normalize_or(Vec3A::Z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// D is normalised per projected area: integral of D(wm) cos theta_m = 1.
    #[test]
    fn projected_area_of_d_is_one() {
        let d = TrowbridgeReitz::new(0.3, 0.6);
        let (n_t, n_p) = (400, 200);
        let mut sum = 0.0f64;
        for i in 0..n_t {
            let ct = (i as f32 + 0.5) / n_t as f32;
            let st = (1.0 - ct * ct).sqrt();
            for j in 0..n_p {
                let phi = 2.0 * PI * (j as f32 + 0.5) / n_p as f32;
                let wm = Vec3A::new(st * phi.cos(), st * phi.sin(), ct);
                sum += (d.D(wm) * ct) as f64;
            }
        }
        sum *= 2.0 * PI as f64 / (n_t * n_p) as f64;
        assert!((sum - 1.0).abs() < 2e-3, "{sum}");
    }

    #[test]
    fn smooth_threshold_and_clamp() {
        assert!(TrowbridgeReitz::new(0.0, 0.0).effectively_smooth());
        let d = TrowbridgeReitz::new(0.5, 0.0);
        assert!(!d.effectively_smooth());
        assert_eq!(d.alpha_y, TrowbridgeReitz::MIN_ALPHA);
    }
}
