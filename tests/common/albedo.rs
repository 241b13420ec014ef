//! Directional albedo by adaptive cubature on sphere grids refined around a
//! rough BSDF's lobes (used by the BSDF energy checks and the furnace).

use super::chi2::{Accuracy, SphereGrid};
use super::TestBsdf;
use glam::Vec3A;
use prism::materials::fresnel::refract;
use prism::materials::{Bsdf, TransportMode};

/// A rough BSDF with what the quadrature needs to find its lobes.
pub struct Rough {
    pub name: String,
    pub bsdf: Bsdf,
    pub alpha_min: f32,
    /// Relative IOR of a dielectric (None: reflection only).
    pub eta: Option<f32>,
}

pub const Q_T: usize = 32;
pub const Q_PHI: usize = 64;

/// Integral over the sphere of g(wi) (an albedo integrand), by adaptive
/// cubature on grids refined around the reflection and transmission lobes
/// where these are narrow; each side of the surface on its own grid then.
pub fn lobe_quadrature(r: &Rough, wo: Vec3A, g: &dyn Fn(Vec3A) -> f64, split: usize) -> f64 {
    // The cubature's error estimate (coarse vs refined) is far above its
    // error; 1e-3 relative keeps the total well below the checks' 2e-3.
    let acc = Accuracy { abs: 1e-7, rel: 1e-3, sqrt_scale: 0.0 };
    let grid = |axis: Vec3A, width: f64| (width < 0.15).then(|| SphereGrid::for_lobe(axis, width, Q_T, Q_PHI));
    let a = r.alpha_min as f64;
    let reflection = grid(Vec3A::new(-wo.x, -wo.y, wo.z), 2.0 * a);
    let transmission = r.eta.and_then(|eta| match refract(wo, Vec3A::Z, eta) {
        Some((wt, etap)) => grid(wt, 2.0 * a * (1.0 - 1.0 / etap as f64).abs()),
        // Total internal reflection at the macro normal: near eta = 1 the
        // transmitted lobe hugs -wo, otherwise it is spread out.
        None if (eta - 1.0).abs() < 0.05 => grid(-wo, 2.0 * a * (eta as f64 - 1.0).abs()),
        None => None,
    });
    if reflection.is_none() && transmission.is_none() {
        return SphereGrid::equal_area(Q_T, Q_PHI).integrate_split(g, acc, split);
    }
    let or_equal_area = |g: Option<SphereGrid>| g.unwrap_or_else(|| SphereGrid::equal_area(Q_T, Q_PHI));
    let same = |w: Vec3A| if w.z * wo.z > 0.0 { g(w) } else { 0.0 };
    let opposite = |w: Vec3A| if w.z * wo.z < 0.0 { g(w) } else { 0.0 };
    let reflected = or_equal_area(reflection).integrate_split(&same, acc, split);
    if r.eta.is_none() {
        return reflected;
    }
    reflected + or_equal_area(transmission).integrate_split(&opposite, acc, split)
}

/// Directional albedo by quadrature, averaged over the four wavelengths of
/// `lambda()`: the integral of f(wo, wi) |cos theta_i| over wi. In
/// importance mode, the energy leaving per unit energy arriving along wo
/// (Veach 1997 §5.2); in radiance mode, the radiance leaving towards wo
/// under a uniform radiance of 1 (a white furnace).
pub fn albedo_quadrature(r: &Rough, b: &dyn TestBsdf, wo: Vec3A, mode: TransportMode, split: usize) -> f64 {
    lobe_quadrature(r, wo, &|wi| (b.eval(wo, wi, mode).average() * wi.z.abs()) as f64, split)
}
