//! `path`: unidirectional path tracing with next-event estimation. At every
//! non-specular vertex a light is chosen by power and a point on it sampled
//! (NEE); BSDF-sampled rays that hit an emitter also count; the two
//! strategies are combined with Veach's power heuristic (Veach & Guibas 1995,
//! Veach 1997 §9.2). Specular vertices and delta lights take weight 1 for
//! their only strategy.
//! A point light the camera sees directly is a delta in the image plane
//! that no camera ray hits: `unsamplable` names it (light and bdpt render
//! it; pbrt-v4's path tracer has the same blind spot). So is a point
//! light's caustic: light that leaves it by a smooth specular bounce (glass,
//! a mirror) before a diffuse one can reach no NEE, and no BSDF-sampled ray
//! hits a point; `unsamplable` names those too.
//!
//! | parameter | type | default | meaning                          |
//! |-----------|------|---------|----------------------------------|
//! | max_depth | int  | 1024    | maximum scattering events        |

use super::{Integrator, IntegratorOptions};
use crate::accel::LANES;
use crate::geometry::Ray;
use crate::light::Light;
use crate::materials::{Bsdf, TransportMode};
use crate::render::Workspace;
use crate::roulette::russian_roulette;
use crate::sampling::{power_heuristic, Sampler};
use crate::scene::{Scene, SurfaceInteraction};
use crate::spectrum::{SampledSpectrum, SampledWavelengths};
use glam::{UVec2, Vec3A};

pub struct PathTracer {
    max_depth: u32,
}

impl PathTracer {
    pub fn new(o: &IntegratorOptions) -> Self {
        Self { max_depth: o.max_depth }
    }
}

/// What the previous vertex knows for weighting an emitter hit by its ray.
struct PrevVertex {
    p: Vec3A,
    /// Solid-angle pdf of the BSDF sample that made the ray.
    pdf_bsdf: f32,
    /// The ray came from the camera or a specular lobe: no NEE competed.
    specular: bool,
}

impl Integrator for PathTracer {
    fn sample(
        &self,
        scene: &Scene,
        pixel: UVec2,
        sampler: &mut Sampler,
        lambda: &mut SampledWavelengths,
        _ws: &mut Workspace,
    ) -> SampledSpectrum {
        let ray = scene.camera.generate_ray(pixel.as_vec2() + sampler.get2d());
        let si = scene.intersect(&ray);
        self.trace(scene, ray, si, sampler, lambda)
    }

    /// The samples' camera rays leave one pixel in nearly one direction:
    /// they are traced together, as a packet (`Scene::intersect8`), and
    /// each path then goes on alone; its later rays part ways, and
    /// incoherent packets cost more than rays alone (docs/performance-log.md,
    /// "Session 20"). Each lane computes what `sample` computes for its
    /// sample (tests/lanes.rs).
    fn sample_lanes(
        &self,
        scene: &Scene,
        pixel: UVec2,
        samplers: &mut [Sampler],
        lambdas: &mut [SampledWavelengths],
    ) -> Option<[SampledSpectrum; LANES]> {
        debug_assert!(samplers.len() <= LANES, "{} samples for {LANES} lanes", samplers.len());
        let n = samplers.len().min(LANES);
        let rays = std::array::from_fn(|i| match samplers.get_mut(i) {
            Some(s) => scene.camera.generate_ray(pixel.as_vec2() + s.get2d()),
            None => Ray::new(Vec3A::ZERO, Vec3A::ZERO),
        });
        let mut l = [SampledSpectrum::ZERO; LANES];
        scene.intersect8(&rays, n, |i, si| l[i] = self.trace(scene, rays[i], si, &mut samplers[i], &mut lambdas[i]));
        Some(l)
    }

    fn unsamplable(&self, scene: &Scene) -> Vec<String> {
        let mut warnings = crate::unsamplable::specular_chains_to_point_lights(scene);
        // A camera path reaches a point light only by next-event estimation
        // from a non-specular vertex: light that leaves it by a smooth
        // specular bounce first (a caustic, L S+ D ... E) is never sampled.
        warnings.extend(crate::unsamplable::point_lights_with_specular(scene, |name, specular| {
            format!("path tracing cannot reach the point light \"{name}\" through the smooth specular material(s) {specular}: its caustics (light -> specular -> diffuse) are missing from the image (light and bdpt render them)")
        }));
        warnings.extend(crate::unsamplable::point_lights_in_view(scene).into_iter().map(|name| {
            format!("path tracing cannot see the point light \"{name}\" directly through the pinhole: its pixel will lack the light itself (light and bdpt render it)")
        }));
        warnings
    }
}

impl PathTracer {
    /// The path from its first ray, `ray`, which found `hit`.
    #[inline(always)]
    fn trace(
        &self,
        scene: &Scene,
        mut ray: Ray,
        mut hit: Option<SurfaceInteraction>,
        sampler: &mut Sampler,
        lambda: &mut SampledWavelengths,
    ) -> SampledSpectrum {
        let mut l = SampledSpectrum::ZERO;
        let mut beta = SampledSpectrum::ONE;
        let mut eta_scale = 1.0;
        let mut prev = PrevVertex { p: ray.o, pdf_bsdf: 0.0, specular: true };
        for depth in 0.. {
            let Some(si) = hit.take() else {
                if let Some((i, env)) = scene.environment() {
                    let w = emitter_weight(scene, &prev, i, env, prev.p + ray.d, Vec3A::ZERO);
                    l += beta * env.environment_le(lambda) * w;
                }
                break;
            };
            if let Some(i) = si.light {
                let light = &scene.lights[i as usize];
                if let Light::Area(a) = light {
                    let le = a.radiance(si.ng, si.wo, lambda);
                    if !le.is_black() {
                        l += beta * le * emitter_weight(scene, &prev, i, light, si.p, si.ng);
                    }
                }
            }
            if depth == self.max_depth {
                break;
            }
            let material = scene.material_at(&si, lambda);
            let (bsdf, wo) = (material.bsdf(), si.frame.to_local(si.wo));
            if material.is_non_specular() {
                l += beta * next_event(scene, &si, bsdf, wo, sampler, lambda);
            }
            let Some(bs) = bsdf.sample(wo, sampler.get1d(), sampler.get2d(), lambda, TransportMode::Radiance) else {
                break;
            };
            beta *= bs.f * (bs.wi.z.abs() / bs.pdf);
            if bs.flags.is_transmission() {
                eta_scale *= bs.eta * bs.eta;
            }
            prev = PrevVertex { p: si.p, pdf_bsdf: bs.pdf, specular: bs.is_specular() };
            if beta.is_black() || !russian_roulette(&mut beta, eta_scale, depth, || sampler.get1d()) {
                break;
            }
            ray = si.spawn_ray(si.frame.to_world(bs.wi));
            hit = scene.intersect(&ray);
        }
        l
    }
}

/// MIS weight of an emitter found by a BSDF-sampled ray, against NEE having
/// chosen the same point (power heuristic; NEE's pdf includes the light
/// selection probability). For the environment `p_l` is any point along the
/// ray's direction.
#[inline]
fn emitter_weight(scene: &Scene, prev: &PrevVertex, i: u32, light: &Light, p_l: Vec3A, n_l: Vec3A) -> f32 {
    if prev.specular {
        return 1.0;
    }
    let pdf_light = scene.light_pmf(i) * light.pdf_li(prev.p, p_l, n_l);
    power_heuristic(prev.pdf_bsdf, pdf_light)
}

/// Next-event estimation: one light sample, weighted against BSDF sampling.
#[inline]
fn next_event(
    scene: &Scene,
    si: &SurfaceInteraction,
    bsdf: &Bsdf,
    wo: Vec3A,
    sampler: &mut Sampler,
    lambda: &SampledWavelengths,
) -> SampledSpectrum {
    let u_light = sampler.get_bits();
    let u = sampler.get2d();
    let Some((i, pmf)) = scene.sample_light(u_light) else {
        return SampledSpectrum::ZERO;
    };
    let light = &scene.lights[i as usize];
    let Some(ls) = light.sample_li(si.p, u, lambda) else {
        return SampledSpectrum::ZERO;
    };
    let wi = si.frame.to_local(ls.wi);
    let f = bsdf.eval(wo, wi, lambda, TransportMode::Radiance) * wi.z.abs();
    if f.is_black() {
        return SampledSpectrum::ZERO;
    }
    if !scene.visible(&light.shadow(si.point(), &ls)) {
        return SampledSpectrum::ZERO;
    }
    let pdf_light = pmf * ls.pdf_w;
    let w = if light.is_delta_position() {
        1.0
    } else {
        power_heuristic(pdf_light, bsdf.pdf(wo, wi, lambda, TransportMode::Radiance))
    };
    f * ls.l * (w / pdf_light)
}
