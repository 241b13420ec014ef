//! `fresnel`: the laws of reflection and refraction at a smooth interface and
//! the unpolarised Fresnel reflectance of dielectrics and conductors.
//!
//! Not a BSDF (it has no scene parameters): the dielectric, conductor and
//! microfacet BSDFs share these functions so that each law is written once.
//!
//! - `fr_dielectric`: exact unpolarised reflectance between two dielectrics
//!   (Born & Wolf, "Principles of Optics", §1.5.2; pbrt-v4 §9.3.5 `FrDielectric`);
//!   `fr_dielectric_refracted` the same for a refraction whose transmitted
//!   cosine is known, and `fr_dielectric_reflected` for a reflection whose
//!   pair of directions is known, each exact near the critical angle.
//! - `fr_conductor`: exact unpolarised reflectance of a conductor with complex
//!   index eta + i k, evaluated per wavelength on four lanes at once. It uses the
//!   real-arithmetic form of the complex Fresnel equations (Born & Wolf §14.2;
//!   the form of pbrt-v3 `FrConductor` / Lagarde 2013, "Memo on Fresnel
//!   equations"), algebraically equal to pbrt-v4's complex `FrComplex`; the
//!   tests compare it against complex arithmetic in f64.
//! - `reflect`, `refract`: mirror and Snell directions (pbrt-v4 §9.3, eq. 9.4).
//!
//! Convention: `eta` is the index of the side the normal points away from
//! (inside) relative to the side it points to (outside). A negative cosine
//! means the incident direction is inside, and eta is flipped.

use crate::spectrum::SampledSpectrum;
use glam::{Vec3A, Vec4};

/// Unpolarised Fresnel reflectance of a dielectric interface for light arriving
/// with cosine `cos_theta_i` to the normal (negative: from the inside).
/// Returns 1 under total internal reflection and 0 for a matched index.
#[inline]
pub fn fr_dielectric(cos_theta_i: f32, eta: f32) -> f32 {
    if eta == 1.0 {
        // No interface at all (also avoids 0/0 at grazing incidence).
        return 0.0;
    }
    let (cos_i, etap) = from_incident_side(cos_theta_i, eta);
    let cos2_t = cos2_transmitted((cos_i as f64).powi(2), eta, cos_theta_i < 0.0);
    if cos2_t <= 0.0 {
        return 1.0;
    }
    fr_of_cosines(cos_i, cos2_t.sqrt() as f32, etap)
}

/// `fr_dielectric` for a refraction whose transmitted direction is known
/// (a rough dielectric's f and pdf for a given pair): `cos_t` is its cosine
/// to the normal, by which the reflectance needs no Snell's law. Near the
/// critical angle Snell's cos_t^2 = (cos_i^2 + eta^2 - 1) / eta^2 is a
/// difference of nearly equal numbers: an ulp of cos_i^2 is ~6e-8, and at
/// cos_t = 1e-3 (cos_t^2 = 1e-6) T = 1 - R, proportional to cos_t, was 13 %
/// off in f32; the direction gives cos_t to its own precision.
#[inline]
pub fn fr_dielectric_refracted(cos_theta_i: f32, cos_t: f32, eta: f32) -> f32 {
    if eta == 1.0 {
        return 0.0;
    }
    let (cos_i, eta) = from_incident_side(cos_theta_i, eta);
    fr_of_cosines(cos_i, cos_t.abs().min(1.0), eta)
}

/// `fr_dielectric` for a reflection whose pair of directions is known (a
/// rough dielectric's f and pdf for a given pair, `wo` and `wi` on one
/// side, inside where z < 0): cos_i^2 to their half vector taken in f64
/// from the pair itself. Under the critical angle's cosine R is 1, and
/// above it R leaves 1 like the square root of the cosines' difference, so
/// there the ~1e-7 that an f32 half vector and dot product add to cos_i is
/// magnified: 2.3e-8 above the critical cosine, T = 1 - R read 3.5e-3 for
/// 1.6e-3 and f 0.18 % low (a seed sweep, session 59). This keeps the
/// reflections exact as `fr_dielectric_refracted` keeps the refractions.
#[inline]
pub fn fr_dielectric_reflected(wo: Vec3A, wi: Vec3A, eta: f32) -> f32 {
    if eta == 1.0 {
        return 0.0;
    }
    let (o, i) = (wo.as_dvec3().normalize(), wi.as_dvec3().normalize());
    let h = o + i;
    let c2 = (o.dot(h).powi(2) / h.length_squared()).min(1.0);
    let inside = wo.z < 0.0;
    let cos2_t = cos2_transmitted(c2, eta, inside);
    if cos2_t <= 0.0 {
        return 1.0;
    }
    let etap = if inside { 1.0 / eta } else { eta };
    fr_of_cosines(c2.sqrt() as f32, cos2_t.sqrt() as f32, etap)
}

/// |cos_i| (at most 1) and the relative index seen from the incident side:
/// `eta`, or 1 / eta for light arriving from inside (cos_theta_i < 0).
#[inline]
fn from_incident_side(cos_theta_i: f32, eta: f32) -> (f32, f32) {
    if cos_theta_i < 0.0 {
        (-cos_theta_i.max(-1.0), 1.0 / eta)
    } else {
        (cos_theta_i.min(1.0), eta)
    }
}

/// Born & Wolf eq. 1.5.(21a)-(21b), written with the relative index `eta`
/// (transmitted over incident side) and both cosines, not negative.
#[inline]
fn fr_of_cosines(cos_i: f32, cos_t: f32, eta: f32) -> f32 {
    let r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (r_parl * r_parl + r_perp * r_perp)
}

/// Unpolarised Fresnel reflectance of a conductor with complex relative index
/// `eta + i k` (per wavelength), for light arriving from outside with cosine
/// `cos_theta_i` (clamped to [0, 1]).
///
/// With a^2 + b^2 = |eta~^2 - sin^2|, the reflectances for s and p light are
/// Rs = (a^2+b^2 - 2a cos + cos^2) / (a^2+b^2 + 2a cos + cos^2) and
/// Rp = Rs (cos^2 (a^2+b^2) - 2a cos sin^2 + sin^4) / (... + ...).
#[inline]
pub fn fr_conductor(cos_theta_i: f32, eta: SampledSpectrum, k: SampledSpectrum) -> SampledSpectrum {
    let cos_i = cos_theta_i.clamp(0.0, 1.0);
    let cos2 = cos_i * cos_i;
    let sin2 = 1.0 - cos2;
    let (eta2, k2) = (eta.0 * eta.0, k.0 * k.0);
    let t0 = eta2 - k2 - Vec4::splat(sin2);
    let a2_plus_b2 = sqrt4(t0 * t0 + 4.0 * eta2 * k2);
    let a = sqrt4(0.5 * (a2_plus_b2 + t0));
    let t1 = a2_plus_b2 + Vec4::splat(cos2);
    let t2 = 2.0 * cos_i * a;
    // The numerators are (a - cos)^2 + b^2 and (a cos - sin^2)^2 + b^2 cos^2,
    // never negative, but computed as differences they cancel to a few ulps
    // below 0 for an index near 1 + 0i (negative reflectance, whose samples
    // the film drops).
    let rs = ratio_or_one((t1 - t2).max(Vec4::ZERO), t1 + t2);
    let t3 = cos2 * a2_plus_b2 + Vec4::splat(sin2 * sin2);
    let t4 = t2 * sin2;
    let rp = rs * ratio_or_one((t3 - t4).max(Vec4::ZERO), t3 + t4);
    SampledSpectrum(0.5 * (rs + rp))
}

/// Lane-wise square root of the non-negative part (glam's `powf(0.5)` calls
/// `powf` four times; this compiles to one `sqrtps`).
#[inline]
fn sqrt4(v: Vec4) -> Vec4 {
    let v = v.max(Vec4::ZERO);
    Vec4::new(v.x.sqrt(), v.y.sqrt(), v.z.sqrt(), v.w.sqrt())
}

/// n / d, or 1 (total reflection) where the denominator vanishes: that happens
/// only for a vanishing complex index or for grazing light on a matched index.
#[inline]
fn ratio_or_one(n: Vec4, d: Vec4) -> Vec4 {
    Vec4::select(d.cmpgt(Vec4::ZERO), n / d, Vec4::ONE)
}

/// Mirror direction of `wo` about the (unit) normal `n`.
#[inline]
pub fn reflect(wo: Vec3A, n: Vec3A) -> Vec3A {
    -wo + 2.0 * wo.dot(n) * n
}

/// Mirror direction of a local `wo` about the shading normal (0, 0, 1):
/// `reflect(wo, Vec3A::Z)` written out.
#[inline]
pub fn reflect_z(wo: Vec3A) -> Vec3A {
    Vec3A::new(-wo.x, -wo.y, wo.z)
}

/// Snell refraction of `wi` (pointing away from the surface) through an
/// interface with normal `n` and relative index `eta` (inside over outside).
/// Returns the transmitted direction and the relative index eta' = eta_t /
/// eta_i actually crossed (eta, or 1/eta when `wi` is inside), or None under
/// total internal reflection (pbrt-v4 eq. 9.4 and `Refract`).
#[inline]
pub fn refract(wi: Vec3A, n: Vec3A, eta: f32) -> Option<(Vec3A, f32)> {
    let cos_wi = n.dot(wi);
    let inside = cos_wi < 0.0;
    let (n, etap, cos_i) = if inside { (-n, 1.0 / eta, -cos_wi) } else { (n, eta, cos_wi) };
    let cos2_t = cos2_transmitted((cos_i as f64).powi(2), eta, inside);
    if cos2_t <= 0.0 {
        return None;
    }
    let cos_t = cos2_t.sqrt() as f32;
    Some((-wi / etap + (cos_i / etap - cos_t) * n, etap))
}

/// cos^2 of the transmitted angle for light arriving with cos_i^2 = `c2`
/// at an interface of index `eta` (inside over outside), from `inside` or
/// outside: 1 - (1 - cos_i^2) / eta'^2 with eta' = eta from outside and
/// 1 / eta from inside, written as (cos_i^2 + (eta - 1)(eta + 1)) / eta^2
/// and eta^2 cos_i^2 - (eta - 1)(eta + 1). Not positive under total
/// internal reflection.
///
/// In f64, from cos_i^2, which a caller may know better than the square of
/// an f32 cosine (`fr_dielectric_reflected`; session 59). The forms date
/// from f32, where each one mattered:
///
/// - at grazing incidence 1 - cos_i^2 rounds to 1 in f32 and lost cos_i
///   (wo.z = 1.5e-4 through an index-matched interface left at -2.4e-4);
///   these forms keep it, exactly so where eta = 1;
/// - near the critical angle their two terms nearly cancel, so each must be
///   good to its own relative precision: in f32, eta^2 - 1 rounded as a
///   whole, or 1 / eta rounded before squaring, was off by ~6e-8 absolute,
///   which at eta 1.0001 and 1.4e-4 in cosine from the critical angle
///   (cos_t^2 = 5e-7) read R 0.831 for 0.826 (a seed sweep, session 45).
///   (eta - 1)(eta + 1) was off by ~1e-11 in f32 (eta - 1 is exact), and
///   is exact in f64 for an f32 eta.
#[inline]
fn cos2_transmitted(c2: f64, eta: f32, inside: bool) -> f64 {
    let eta = eta as f64;
    let d = (eta - 1.0) * (eta + 1.0);
    if inside {
        eta * eta * c2 - d
    } else {
        (c2 + d) / (eta * eta)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dielectric_normal_incidence_and_tir() {
        let r0 = ((1.5f32 - 1.0) / 2.5).powi(2);
        assert!((fr_dielectric(1.0, 1.5) - r0).abs() < 1e-6);
        assert!((fr_dielectric(-1.0, 1.5) - r0).abs() < 1e-6);
        assert_eq!(fr_dielectric(-0.3, 1.5), 1.0);
        assert_eq!(fr_dielectric(0.0, 1.0), 0.0);
    }

    /// Near the matched index 1 + 0i the reflectance is ~0 and must not go
    /// below it (an audit found R < 0 at 11 % of cosines for eta = 1, k = 0).
    #[test]
    fn conductor_near_a_matched_index_is_never_negative() {
        for (eta, k) in [(1.0f32, 0.0f32), (1.0001, 0.0), (0.9999, 0.0), (1.0, 1e-4), (1.0001, 1e-4)] {
            for i in 0..=10_000 {
                let c = i as f32 / 10_000.0;
                let r = fr_conductor(c, SampledSpectrum::splat(eta), SampledSpectrum::splat(k));
                assert!((0.0..=1.0).contains(&r[0]), "eta {eta}, k {k}, cos {c}: R = {}", r[0]);
            }
        }
    }

    /// The reflectance just outside total internal reflection, against f64
    /// from the same f32 inputs, from inside an index near 1 and of glass:
    /// within 2e-5 down to 1e-4 (relative) in cosine from the critical
    /// angle. With eta^2 - 1 rounded as a whole, or 1 / eta rounded before
    /// squaring, R at eta 1.0001 was 5e-3 off at 1.4e-4 (found by
    /// `smooth_dielectric_accounting` at seed offset 57, session 45).
    #[test]
    fn reflectance_near_the_critical_angle() {
        let reference = |cos: f64, eta: f64| {
            let sin_t = (1.0 - cos * cos).sqrt() * eta; // from inside: n_i = eta, n_t = 1
            if sin_t >= 1.0 {
                return 1.0;
            }
            let cos_t = (1.0 - sin_t * sin_t).sqrt();
            let r_s = (eta * cos - cos_t) / (eta * cos + cos_t);
            let r_p = (cos - eta * cos_t) / (cos + eta * cos_t);
            0.5 * (r_s * r_s + r_p * r_p)
        };
        for eta in [1.0001f32, 1.01, 1.5] {
            let critical = (1.0 - 1.0 / (eta as f64 * eta as f64)).sqrt();
            for k in [1e-4, 1e-3, 1e-2, 0.1] {
                let cos = (critical * (1.0 + k)) as f32;
                let (got, want) = (fr_dielectric(-cos, eta), reference(cos as f64, eta as f64));
                assert!(
                    (got as f64 - want).abs() < 2e-5,
                    "eta {eta}, cos {cos} ({k} past critical): R {got} against {want}"
                );
            }
        }
    }

    /// Snell's law in f32 against f64, from normal to grazing incidence
    /// (cos 1e-6), on both sides of indices near 1 and of glass: the
    /// directions agree to 1e-6 (more near the critical angle) and on total
    /// internal reflection, and an
    /// index-matched interface passes every direction straight through.
    /// With sin^2 from 1 - cos^2 (pbrt-v4's form) the matched interface bent
    /// cos 1.5e-4 to 2.4e-4 (found by `smooth_dielectric_accounting` at
    /// another seed).
    #[test]
    fn refraction_keeps_grazing_angles() {
        for eta in [1.0f32, 1.0001, 0.9999, 1.5, 1.0 / 1.5] {
            for cos in [1.0f32, 0.5, 0.02, 1e-3, 1.5e-4, 1e-5, 1e-6] {
                for side in [1.0f32, -1.0] {
                    let sin = (1.0 - cos as f64 * cos as f64).sqrt();
                    let wi = Vec3A::new(sin as f32 * 0.8, sin as f32 * 0.6, side * cos);
                    let got = refract(wi, Vec3A::Z, eta);
                    // (The f32 relative index refract uses.)
                    let etap = if side > 0.0 { eta } else { 1.0 / eta } as f64;
                    let sin_t = sin / etap;
                    if sin_t >= 1.0 {
                        assert!(got.is_none(), "eta {eta}, cos {cos}, side {side}: {got:?} under TIR");
                        continue;
                    }
                    let cos_t = (1.0 - sin_t * sin_t).sqrt();
                    let want = [-0.8 * sin_t, -0.6 * sin_t, -side as f64 * cos_t];
                    let (wt, _) = got.unwrap_or_else(|| panic!("eta {eta}, cos {cos}, side {side}: no refraction"));
                    let err = (0..3).map(|i| (wt[i] as f64 - want[i]).abs()).fold(0.0, f64::max);
                    // Near the critical angle cos_t is ill-conditioned: an
                    // error of ~6e-8 in cos_t^2 (the f32 cosine's square's
                    // rounding) moves it by ~3e-8 / cos_t.
                    let tol = 1e-6 + 1e-7 / cos_t;
                    assert!(err < tol, "eta {eta}, cos {cos}, side {side}: {wt:?} against {want:?}");
                    if eta == 1.0 {
                        assert_eq!(wt, -wi, "cos {cos}, side {side}: bent by a matched interface");
                    }
                }
            }
        }
    }

    #[test]
    fn conductor_with_zero_k_is_a_dielectric() {
        for &c in &[1.0f32, 0.7, 0.3, 0.05] {
            let r = fr_conductor(c, SampledSpectrum::splat(1.5), SampledSpectrum::ZERO);
            assert!((r[0] - fr_dielectric(c, 1.5)).abs() < 1e-5, "{c}: {r:?}");
        }
    }
}
