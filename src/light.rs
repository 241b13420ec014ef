//! Light sources: diffuse area emission on triangles, point lights, and a
//! constant environment. Each offers the two sampling routines the
//! estimators need (pbrt-v4's interface):
//! - `sample_li`: a point on the light seen from a reference point, with its
//!   density in solid angle at the reference (next-event estimation);
//! - `sample_le`: an emitted ray (position and direction densities separately,
//!   area and solid angle) for light tracing and BDPT light subpaths.
//!
//! Lights are an enum matched in the hot loop; one light per emissive triangle.

use crate::geometry::{triangle_point, Frame, Ray, Shadow, SurfacePoint, NO_TRIANGLE};
use crate::sampling::{cosine_hemisphere, uniform_sphere, uniform_triangle, UNIFORM_SPHERE_PDF};
use crate::spectrum::{SampledSpectrum, SampledWavelengths, Spectrum};
use glam::{Vec2, Vec3A};
use std::f32::consts::PI;

#[derive(Clone, Debug)]
pub enum Light {
    Area(AreaLight),
    Point(PointLight),
    Environment(EnvironmentLight),
}

/// A triangle emitting radiance `le` from its front side (the side its
/// winding's normal points to), or from both sides.
#[derive(Clone, Debug)]
pub struct AreaLight {
    pub v: [Vec3A; 3],
    pub n: Vec3A,
    pub area: f32,
    pub le: Spectrum,
    pub two_sided: bool,
    /// Index of the scene triangle.
    pub prim: u32,
    /// Its BVH slot (set once the BVH is built).
    pub slot: u32,
    /// Its `geometry::edge_margin`.
    pub margin: f32,
}

impl AreaLight {
    /// A uniform point on the triangle (Heitz 2019), kept off its edges
    /// by its margin (`triangle_point`), with its rounding error bound.
    #[inline(always)]
    fn sample_point(&self, u: Vec2) -> (Vec3A, Vec3A) {
        let (b0, b1) = uniform_triangle(u);
        triangle_point(&self.v, [b0, b1, 1.0 - b0 - b1], self.margin)
    }

    /// Whether a point of the light with normal `n` emits in direction `w`:
    /// from its front side, or from both.
    #[inline]
    pub fn emits_toward(&self, n: Vec3A, w: Vec3A) -> bool {
        self.two_sided || n.dot(w) > 0.0
    }

    /// Radiance leaving a point of the light with normal `n` in direction `w`.
    #[inline]
    pub fn radiance(&self, n: Vec3A, w: Vec3A, lambda: &SampledWavelengths) -> SampledSpectrum {
        if self.emits_toward(n, w) {
            self.le.sample(lambda)
        } else {
            SampledSpectrum::ZERO
        }
    }
}

/// An isotropic point light of radiant intensity `intensity` (W/sr per nm).
#[derive(Clone, Debug)]
pub struct PointLight {
    pub p: Vec3A,
    pub intensity: Spectrum,
}

/// Constant radiance from every direction at infinity. `center`/`radius`
/// bound the scene (set by the scene builder) for emitted rays.
#[derive(Clone, Debug)]
pub struct EnvironmentLight {
    pub le: Spectrum,
    pub center: Vec3A,
    pub radius: f32,
}

/// A light point chosen for next-event estimation.
#[derive(Clone, Copy, Debug)]
pub struct LightLiSample {
    pub l: SampledSpectrum,
    /// Unit direction from the reference point towards the light.
    pub wi: Vec3A,
    pub p: Vec3A,
    /// Bound on the rounding error of `p` (`barycentric_error`).
    pub p_error: Vec3A,
    /// Surface normal at the light point (zero for point/environment).
    pub n: Vec3A,
    /// Solid-angle density at the reference point (for a delta light: 1).
    pub pdf_w: f32,
    /// BVH slot of the light's triangle (`NO_TRIANGLE` for the others).
    pub slot: u32,
}

impl LightLiSample {
    #[inline]
    pub fn point(&self) -> SurfacePoint {
        SurfacePoint { p: self.p, p_error: self.p_error, n: self.n, slot: self.slot }
    }
}

/// An emitted ray for light subpaths.
#[derive(Clone, Copy, Debug)]
pub struct LightLeSample {
    /// The ray's origin is on the emitter (not offset).
    pub ray: Ray,
    /// Bound on the rounding error of the origin (`barycentric_error`).
    pub p_error: Vec3A,
    pub n: Vec3A,
    pub l: SampledSpectrum,
    /// Area density of the origin (delta lights: 1).
    pub pdf_pos: f32,
    /// Solid-angle density of the direction.
    pub pdf_dir: f32,
    /// BVH slot of the emitting triangle (`NO_TRIANGLE` for the others).
    pub slot: u32,
}

impl Light {
    /// The light's radiance (a point light's intensity) at its brightest
    /// wavelength.
    pub fn max_emitted(&self) -> f32 {
        match self {
            Light::Area(a) => a.le.max_value(),
            Light::Point(p) => p.intensity.max_value(),
            Light::Environment(e) => e.le.max_value(),
        }
    }

    /// Whether the light's position is a delta distribution (cannot be hit).
    #[inline]
    pub fn is_delta_position(&self) -> bool {
        matches!(self, Light::Point(_))
    }

    #[inline]
    pub fn is_infinite(&self) -> bool {
        matches!(self, Light::Environment(_))
    }

    /// The shadow ray that decides whether `ls`, sampled by `sample_li`
    /// from `from`, is seen there.
    #[inline(always)]
    pub fn shadow(&self, from: SurfacePoint, ls: &LightLiSample) -> Shadow {
        if self.is_infinite() {
            Shadow::escape(from, ls.wi)
        } else {
            Shadow::segment(from, ls.point())
        }
    }

    /// Emitted power, used only to choose lights proportionally (luminance).
    /// In f64: an environment's pi R^2 passes the f32 range for a scene
    /// radius above ~1e19, and an infinite weight would leave the scene with
    /// no light sampling at all.
    pub fn power(&self) -> f64 {
        let pi = std::f64::consts::PI;
        match self {
            Light::Area(a) => pi * a.area as f64 * a.le.luminance() * if a.two_sided { 2.0 } else { 1.0 },
            Light::Point(p) => 4.0 * pi * p.intensity.luminance(),
            Light::Environment(e) => 4.0 * pi * pi * (e.radius as f64).powi(2) * e.le.luminance(),
        }
    }

    /// Radiance of the environment arriving from any direction.
    #[inline]
    pub fn environment_le(&self, lambda: &SampledWavelengths) -> SampledSpectrum {
        match self {
            Light::Environment(e) => e.le.sample(lambda),
            _ => SampledSpectrum::ZERO,
        }
    }

    /// A light sample for next-event estimation at `p_ref`: the point, the
    /// incident radiance and its solid-angle density (pbrt `SampleLi`).
    /// Always inlined (docs/performance-log.md, "Session 16").
    #[inline(always)]
    pub fn sample_li(&self, p_ref: Vec3A, u: Vec2, lambda: &SampledWavelengths) -> Option<LightLiSample> {
        match self {
            Light::Area(a) => {
                let (p, p_error) = a.sample_point(u);
                let to = p - p_ref;
                let dist2 = to.length_squared();
                if dist2 == 0.0 {
                    return None;
                }
                let dist = dist2.sqrt();
                let wi = to / dist;
                let cos_l = a.n.dot(-wi);
                let l = a.radiance(a.n, -wi, lambda);
                if l.is_black() || cos_l == 0.0 {
                    return None;
                }
                let pdf_w = dist2 / (cos_l.abs() * a.area);
                Some(LightLiSample { l, wi, p, p_error, n: a.n, pdf_w, slot: a.slot })
            }
            Light::Point(pl) => {
                let to = pl.p - p_ref;
                let dist2 = to.length_squared();
                if dist2 == 0.0 {
                    return None;
                }
                let dist = dist2.sqrt();
                let l = pl.intensity.sample(lambda) / dist2;
                Some(LightLiSample {
                    l,
                    wi: to / dist,
                    p: pl.p,
                    p_error: Vec3A::ZERO,
                    n: Vec3A::ZERO,
                    pdf_w: 1.0,
                    slot: NO_TRIANGLE,
                })
            }
            Light::Environment(e) => {
                let wi = uniform_sphere(u);
                Some(LightLiSample {
                    l: e.le.sample(lambda),
                    wi,
                    p: p_ref + wi * (2.0 * e.radius),
                    p_error: Vec3A::ZERO,
                    n: Vec3A::ZERO,
                    pdf_w: UNIFORM_SPHERE_PDF,
                    slot: NO_TRIANGLE,
                })
            }
        }
    }

    /// Solid-angle density of `sample_li` choosing the light point `p_l`
    /// (normal `n_l`) from `p_ref`; for the environment, of direction `wi`.
    #[inline]
    pub fn pdf_li(&self, p_ref: Vec3A, p_l: Vec3A, n_l: Vec3A) -> f32 {
        match self {
            Light::Area(a) => {
                let to = p_l - p_ref;
                let dist2 = to.length_squared();
                let cos_l = n_l.dot(to).abs() / dist2.sqrt();
                // At p_l == p_ref, where `sample_li` has no sample, cos_l
                // is 0 / 0: a NaN density made a NaN MIS weight (a review,
                // session 53).
                if cos_l.is_nan() || cos_l == 0.0 {
                    return 0.0;
                }
                dist2 / (cos_l * a.area)
            }
            Light::Point(_) => 0.0,
            Light::Environment(_) => UNIFORM_SPHERE_PDF,
        }
    }

    pub fn sample_le(&self, u1: Vec2, u2: Vec2, lambda: &SampledWavelengths) -> Option<LightLeSample> {
        match self {
            Light::Area(a) => {
                let (p, p_error) = a.sample_point(u1);
                let (u, flip) = if a.two_sided {
                    // Pick a side with the first coordinate, then remap it.
                    if u2.x < 0.5 {
                        (Vec2::new(u2.x * 2.0, u2.y), false)
                    } else {
                        (Vec2::new(u2.x * 2.0 - 1.0, u2.y), true)
                    }
                } else {
                    (u2, false)
                };
                let n = if flip { -a.n } else { a.n };
                let local = cosine_hemisphere(u);
                let d = Frame::from_normal(n).to_world(local);
                let side_pdf = if a.two_sided { 0.5 } else { 1.0 };
                let pdf_dir = side_pdf * local.z / PI;
                if pdf_dir == 0.0 {
                    return None;
                }
                Some(LightLeSample {
                    ray: Ray::new(p, d),
                    p_error,
                    n,
                    l: a.le.sample(lambda),
                    pdf_pos: 1.0 / a.area,
                    pdf_dir,
                    slot: a.slot,
                })
            }
            Light::Point(pl) => {
                let d = uniform_sphere(u2);
                Some(LightLeSample {
                    ray: Ray::new(pl.p, d),
                    p_error: Vec3A::ZERO,
                    n: Vec3A::ZERO,
                    l: pl.intensity.sample(lambda),
                    pdf_pos: 1.0,
                    pdf_dir: UNIFORM_SPHERE_PDF,
                    slot: NO_TRIANGLE,
                })
            }
            Light::Environment(e) => {
                // A direction into the scene, then a point on the disk of the
                // scene's bounding sphere perpendicular to it (pbrt-v4).
                let d = -uniform_sphere(u2);
                let frame = Frame::from_normal(d);
                let disk = crate::sampling::concentric_disk(u1) * e.radius;
                let o = e.center - d * e.radius + frame.s * disk.x + frame.t * disk.y;
                Some(LightLeSample {
                    ray: Ray::new(o, d),
                    p_error: Vec3A::ZERO,
                    n: d,
                    l: e.le.sample(lambda),
                    pdf_pos: 1.0 / (PI * e.radius * e.radius),
                    pdf_dir: UNIFORM_SPHERE_PDF,
                    slot: NO_TRIANGLE,
                })
            }
        }
    }

    /// Densities (area, solid angle) with which `sample_le` emits direction
    /// `w` from a point with normal `n` on this light.
    #[inline]
    pub fn pdf_le(&self, n: Vec3A, w: Vec3A) -> (f32, f32) {
        match self {
            Light::Area(a) => {
                let cos = n.dot(w);
                let pdf_dir = if a.two_sided { 0.5 * cos.abs() / PI } else { cos.max(0.0) / PI };
                (1.0 / a.area, pdf_dir)
            }
            Light::Point(_) => (1.0, UNIFORM_SPHERE_PDF),
            Light::Environment(e) => (1.0 / (PI * e.radius * e.radius), UNIFORM_SPHERE_PDF),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `pdf_li` is `sample_li`'s density: dist^2 / (|cos| area) at a point
    /// seen from the front (the control), and 0, not NaN, where the two
    /// points coincide (cos = 0 / 0; the old `cos == 0` test let the NaN
    /// through) or the light is seen edge-on.
    #[test]
    fn area_pdf_li_is_finite_where_sample_li_has_no_sample() {
        let v = [Vec3A::ZERO, Vec3A::X, Vec3A::Y];
        let area = AreaLight {
            v,
            n: Vec3A::Z,
            area: 0.5,
            le: Spectrum::Constant(1.0),
            two_sided: false,
            prim: 0,
            slot: 0,
            margin: 0.0,
        };
        let light = Light::Area(area);
        let p_l = Vec3A::new(0.25, 0.25, 0.0);
        let from = p_l + Vec3A::new(0.0, 0.0, 2.0);
        assert_eq!(light.pdf_li(from, p_l, Vec3A::Z), 4.0 / (1.0 * 0.5));
        assert_eq!(light.pdf_li(p_l, p_l, Vec3A::Z), 0.0);
        assert_eq!(light.pdf_li(p_l + Vec3A::X, p_l, Vec3A::Z), 0.0);
    }
}
