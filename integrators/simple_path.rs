//! `simple_path`: path tracing with BSDF sampling only. No next-event
//! estimation, no MIS: emission counts only when a sampled ray hits it.
//! Obviously correct (the rendering equation's Neumann series sampled one
//! vertex at a time, Kajiya 1986), slow, and the baseline every other
//! estimator is tested against. It cannot see point lights (they cannot be
//! hit) and says so.
//!
//! | parameter | type | default | meaning                          |
//! |-----------|------|---------|----------------------------------|
//! | max_depth | int  | 1024    | maximum scattering events        |

use super::{Integrator, IntegratorOptions};
use crate::light::Light;
use crate::materials::TransportMode;
use crate::render::Workspace;
use crate::roulette::russian_roulette;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::{SampledSpectrum, SampledWavelengths};
use glam::UVec2;

pub struct SimplePath {
    max_depth: u32,
}

impl SimplePath {
    pub fn new(o: &IntegratorOptions) -> Self {
        Self { max_depth: o.max_depth }
    }
}

impl Integrator for SimplePath {
    fn sample(
        &self,
        scene: &Scene,
        pixel: UVec2,
        sampler: &mut Sampler,
        lambda: &mut SampledWavelengths,
        _ws: &mut Workspace,
    ) -> SampledSpectrum {
        let mut ray = scene.camera.generate_ray(pixel.as_vec2() + sampler.get2d());
        let mut l = SampledSpectrum::ZERO;
        let mut beta = SampledSpectrum::ONE;
        let mut eta_scale = 1.0;
        for depth in 0.. {
            let Some(si) = scene.intersect(&ray) else {
                if let Some((_, env)) = scene.environment() {
                    l += beta * env.environment_le(lambda);
                }
                break;
            };
            if let Some(i) = si.light {
                if let Light::Area(a) = &scene.lights[i as usize] {
                    l += beta * a.radiance(si.ng, si.wo, lambda);
                }
            }
            if depth == self.max_depth {
                break;
            }
            let bsdf = scene.material_at(&si, lambda).bsdf();
            let wo = si.frame.to_local(si.wo);
            let Some(bs) = bsdf.sample(wo, sampler.get1d(), sampler.get2d(), lambda, TransportMode::Radiance) else {
                break;
            };
            beta *= bs.f * (bs.wi.z.abs() / bs.pdf);
            if bs.flags.is_transmission() {
                eta_scale *= bs.eta * bs.eta;
            }
            if beta.is_black() || !russian_roulette(&mut beta, eta_scale, depth, || sampler.get1d()) {
                break;
            }
            ray = si.spawn_ray(si.frame.to_world(bs.wi));
        }
        l
    }

    fn unsamplable(&self, scene: &Scene) -> Vec<String> {
        crate::unsamplable::point_light_names(scene)
            .map(|name| {
                format!("simple_path cannot hit the point light \"{name}\": its light is missing from the image")
            })
            .collect()
    }
}
