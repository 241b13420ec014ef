//! The scene checks for path classes that some or all estimators with a
//! pinhole camera cannot sample (Veach 1997 §8.3.2), shared by the
//! estimators' `Integrator::unsamplable`: what each one reports before it
//! renders, so a missing caustic or light is named rather than silent.

use crate::geometry::SurfacePoint;
use crate::light::Light;
use crate::scene::Scene;
use glam::Vec3A;

/// The names of the point lights the pinhole sees directly: in the image
/// and unoccluded. Such a light is a delta in the image plane as well, so it
/// lands in one pixel with finite energy (its irradiance on the film), but
/// only a light-subpath vertex joined to the pinhole reaches it (light
/// tracing; BDPT's s = 1, t = 1): a camera ray never hits a point.
pub fn point_lights_in_view(scene: &Scene) -> Vec<&str> {
    let pinhole = SurfacePoint::at(scene.camera.position);
    scene
        .lights
        .iter()
        .zip(&scene.light_names)
        .filter_map(|(l, name)| match l {
            Light::Point(pl) => Some((pl.p, name.as_str())),
            _ => None,
        })
        .filter(|&(p, _)| scene.camera.sample_wi(p).is_some() && scene.unoccluded(SurfacePoint::at(p), pinhole))
        .map(|(_, name)| name)
        .collect()
}

/// A light path leaving the environment carries 1 / pdf_pos = pi R^2 in its
/// throughput (its origin is drawn on a disk of the scene's bounding radius
/// R, pbrt-v4), which passes f32::MAX for R above ~1e19: `light_subpath`
/// then drops the subpath (a zero pdf_pos, or a throughput that is not
/// finite), and light tracing and BDPT miss what the environment's light
/// paths carry. The warning for a scene that large, if it has an
/// environment: the same densities (`Light::pdf_le`) and the same test as
/// the walk, for the environment's brightest wavelength.
pub fn environment_paths_overflow(scene: &Scene) -> Option<String> {
    let (i, light @ Light::Environment(e)) = scene.environment()? else {
        return None;
    };
    // A black environment starts no light paths (its pmf is 0).
    if e.le.max_value() <= 0.0 {
        return None;
    }
    let (pdf_pos, pdf_dir) = light.pdf_le(Vec3A::Z, Vec3A::Z);
    let beta = e.le.max_value() / (scene.light_pmf(i) * pdf_dir) / pdf_pos;
    (pdf_pos == 0.0 || !beta.is_finite()).then(|| {
        format!(
            "light paths from the environment \"{}\" carry its radiance times pi R^2 (R = {:e}, the scene's bounding radius), which passes the f32 range: light paths from it are lost; make the scene smaller or the environment dimmer",
            scene.light_names[i as usize], e.radius
        )
    })
}

/// Delta lights seen only through smooth specular surfaces (S-D-S paths with
/// a delta light and a pinhole) cannot be sampled by any of prism's
/// estimators (Veach 1997 §8.3.2). This returns a warning per point light in
/// a scene that has smooth specular materials.
pub fn specular_chains_to_point_lights(scene: &Scene) -> Vec<String> {
    point_lights_with_specular(scene, |name, specular| {
        format!(
            "point light \"{name}\" seen via the smooth specular material(s) {specular} then a diffuse surface and specular again (S-D-S) cannot be sampled by any estimator with a pinhole camera; such caustics will be missing"
        )
    })
}

/// One message per point light, `message(light, materials)`, if some
/// triangle of the scene has a smooth specular material (listed,
/// comma-separated).
pub fn point_lights_with_specular(scene: &Scene, message: impl Fn(&str, &str) -> String) -> Vec<String> {
    let specular: Vec<&str> = scene
        .materials_in_use()
        .filter(|m| m.bsdf().flags().is_specular() && !m.is_non_specular())
        .map(|m| m.name.as_str())
        .collect();
    if specular.is_empty() {
        return Vec::new();
    }
    let specular = specular.join(", ");
    point_light_names(scene).map(|name| message(name, &specular)).collect()
}

/// The names of the scene's point lights (the lights with a delta position).
pub fn point_light_names(scene: &Scene) -> impl Iterator<Item = &str> {
    scene.lights.iter().zip(&scene.light_names).filter(|(l, _)| l.is_delta_position()).map(|(_, name)| name.as_str())
}
