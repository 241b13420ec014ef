//! `light`: light tracing (particle tracing). Each sample traces one light
//! subpath: a light chosen by power, an emitted ray, then an importance-mode
//! random walk (src/path.rs); every vertex that a deterministic connection
//! can reach (the light's own point, non-specular surfaces) is joined to the
//! pinhole and its contribution beta f |cos| We / pdf is splatted into the
//! pixel it projects to. In BDPT terms these are the strategies (s, t = 1),
//! s >= 1, each with weight 1 (Veach 1997 §10.2, Arvo & Kirk 1990; pbrt-v4
//! `LightPathIntegrator`).
//!
//! The driver calls `sample` once per (pixel, sample index); the pixel is
//! only a stream id, the pixel estimate returned is zero and the image is
//! made of splats, which the film divides by spp: `--spp N` traces
//! N x width x height light paths (camera.rs explains the normalisation).
//!
//! What it cannot see: a pinhole cannot receive a delta direction, so
//! surfaces seen through a smooth specular chain (a mirror, glass) and the
//! environment seen directly stay black; `unsamplable` names them.
//!
//! | parameter | type | default | meaning                     |
//! |-----------|------|---------|-----------------------------|
//! | max_depth | int  | 1024    | maximum scattering events   |

use super::{Integrator, IntegratorOptions};
use crate::path::{connect_to_camera, light_subpath};
use crate::render::Workspace;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::{SampledSpectrum, SampledWavelengths};
use crate::unsamplable::{environment_paths_overflow, specular_chains_to_point_lights};
use glam::{UVec2, Vec2};
use rayon::prelude::*;

pub struct LightTracer {
    max_depth: u32,
}

impl LightTracer {
    pub fn new(o: &IntegratorOptions) -> Self {
        Self { max_depth: o.max_depth }
    }
}

impl Integrator for LightTracer {
    fn sample(
        &self,
        scene: &Scene,
        _pixel: UVec2,
        sampler: &mut Sampler,
        lambda: &mut SampledWavelengths,
        ws: &mut Workspace,
    ) -> SampledSpectrum {
        let path = &mut ws.paths.light;
        light_subpath::<false>(scene, sampler, lambda, self.max_depth, path);
        for v in path.iter() {
            if let Some(c) = connect_to_camera(scene, v, lambda) {
                ws.splats.push(c.splat);
            }
        }
        SampledSpectrum::ZERO
    }

    fn unsamplable(&self, scene: &Scene) -> Vec<String> {
        let mut warnings = Vec::new();
        let specular = specular_in_view(scene);
        if !specular.is_empty() {
            warnings.push(format!(
                "light tracing cannot see smooth specular surfaces through a pinhole: the material(s) {} in the camera's view, and everything seen through them, will be black (use path or bdpt)",
                specular.join(", ")
            ));
        }
        if let Some(sky) = background_seen(scene) {
            warnings.push(format!(
                "light tracing cannot see the environment \"{sky}\" directly through a pinhole: the background will be black (use path or bdpt)"
            ));
        }
        warnings.extend(specular_chains_to_point_lights(scene));
        warnings.extend(environment_paths_overflow(scene));
        warnings
    }
}

/// The purely specular materials of the triangles in the camera's view:
/// every such triangle whose projection's bounds meet the image, or which
/// reaches behind the pinhole from in front of it. Occlusion is not
/// considered, so a mirror hidden behind a wall is named as well: a grid of
/// camera rays, which took occlusion into account, missed what lay between
/// its rays (a mirror strip one pixel high between the rows of a 64 x 64
/// grid, black in light tracing and unreported).
fn specular_in_view(scene: &Scene) -> Vec<String> {
    let cam = &scene.camera;
    let image = (Vec2::ZERO, Vec2::new(cam.width as f32, cam.height as f32));
    let mut names: Vec<String> = Vec::new();
    for (v, _, material, _) in scene.triangles() {
        let m = &scene.materials[material as usize];
        if m.is_non_specular() || names.contains(&m.name) {
            continue;
        }
        let projected = v.map(|p| cam.project(p - cam.position));
        let in_view = match projected {
            [Some(a), Some(b), Some(c)] => {
                let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
                lo.cmple(image.1).all() && hi.cmpge(image.0).all()
            }
            [None, None, None] => false,
            _ => true,
        };
        if in_view {
            names.push(m.name.clone());
        }
    }
    names
}

/// The name of the environment light if the camera sees it: if a camera
/// ray through any point of the image on a half-pixel lattice (pixel
/// corners, edge midpoints and centres, (2W + 1) x (2H + 1) rays) escapes.
/// A sky seen only in slivers thinner than half a pixel can pass between
/// the rays; a 64 x 64 grid of pixel centres, the check until session 29,
/// missed one a pixel high at 256 x 256. A black environment is not named.
fn background_seen(scene: &Scene) -> Option<&str> {
    let (i, sky) = scene.environment()?;
    if sky.power() <= 0.0 {
        return None;
    }
    let cam = &scene.camera;
    let escapes = |j: u32| {
        (0..=2 * cam.width).any(|i| {
            let raster = Vec2::new(i as f32, j as f32) * 0.5;
            scene.intersect(&cam.generate_ray(raster)).is_none()
        })
    };
    (0..=2 * cam.height).into_par_iter().any(escapes).then(|| scene.light_names[i as usize].as_str())
}
