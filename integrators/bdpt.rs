//! `bdpt`: bidirectional path tracing (Veach & Guibas 1994; Veach 1997
//! ch. 10; the structure of pbrt-v3 `integrators/bdpt.cpp`). Each sample
//! traces a camera subpath z_0 .. z_{t-1} through the pixel and a light
//! subpath y_0 .. y_{s-1} from a light chosen by power (src/path.rs), then
//! evaluates every connection strategy (s, t) with s + t - 2 <= max_depth:
//!
//! | strategy | what it is                                                     |
//! |----------|----------------------------------------------------------------|
//! | s = 0    | the camera subpath itself hits an emitter (area or environment) |
//! | s = 1    | next-event estimation: a FRESH light sample (`sample_li`) joined to z_{t-1}; for MIS its pdf_fwd is the light-origin density pmf x pdf_pos, as a light subpath would have made it (TRANSPORT-NOTES §6d) |
//! | t = 1    | light tracing: y_{s-1} joined to the pinhole and splatted       |
//! | (1, 1)   | the light's own point (y_0) seen by the pinhole: with it a point light in view is visible, and directly seen area lights get a second strategy (pbrt-v3 skips it and gives (0, 2) weight 1) |
//! | others   | y_{s-1} joined to z_{t-1} by a shadow ray, with G = |cos||cos| / d^2 (shading normals) |
//!
//! Each contribution is weighted by MIS (Veach §10.3) computed with the
//! ratio recursion of pbrt-v3 `MISWeight`: the densities p_i of the other
//! strategies that could make the same path are obtained relative to the
//! current one by multiplying ratios pdf_rev / pdf_fwd of area densities
//! vertex by vertex, with remap0 (a delta density, stored as 0, becomes 1 so
//! it cancels) and strategies that would have to connect through a specular
//! vertex, or hit a point light, left out (TRANSPORT-NOTES §6b, §6g). The
//! densities at and next to the connection are the only ones not known from
//! the walks; they are computed for the connection and substituted.
//! Roulette is not in these densities (src/path.rs explains why that is
//! still unbiased).
//!
//! `--strategies DIR` (src/render.rs `render_with_strategies`) records each
//! strategy's weighted and unweighted contribution for per-(s, t) images
//! (Veach fig. 10.4); without it the recording costs one branch.
//!
//! | parameter | type   | default | meaning                                     |
//! |-----------|--------|---------|---------------------------------------------|
//! | max_depth | int    | 1024    | maximum scattering events (s + t - 2)       |
//! | mis       | string | power   | MIS heuristic: power, balance or uniform    |

use super::{Integrator, IntegratorOptions, MisHeuristic};
use crate::materials::TransportMode;
use crate::path::{camera_subpath, connect_to_camera, light_subpath, specular_chains_to_point_lights, Vertex};
use crate::render::{Splat, StrategyRecord, Workspace};
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::spectrum::{SampledSpectrum, SampledWavelengths};
use glam::{UVec2, Vec2};

pub struct Bdpt {
    max_depth: u32,
    mis: MisHeuristic,
}

impl Bdpt {
    pub fn new(o: &IntegratorOptions) -> Self {
        Self { max_depth: o.max_depth, mis: o.mis }
    }
}

impl Integrator for Bdpt {
    fn sample(
        &self,
        scene: &Scene,
        pixel: UVec2,
        sampler: &mut Sampler,
        lambda: &mut SampledWavelengths,
        ws: &mut Workspace,
    ) -> SampledSpectrum {
        let raster = pixel.as_vec2() + sampler.get2d();
        let Workspace { splats, paths, strategies } = ws;
        camera_subpath(scene, raster, sampler, lambda, self.max_depth, &mut paths.camera);
        light_subpath(scene, sampler, lambda, self.max_depth, &mut paths.light);
        let (camera, light, lambda) = (&paths.camera[..], &paths.light[..], &*lambda);
        let mut l = SampledSpectrum::ZERO;
        for t in 1..=camera.len() {
            for s in 0..=light.len() {
                if s + t < 2 || s + t - 2 > self.max_depth as usize {
                    continue;
                }
                let Some(c) = connect(scene, light, camera, s, t, sampler, lambda) else {
                    continue;
                };
                let w = mis_weight(scene, light, camera, c.sampled.as_ref(), s, t, self.mis, lambda);
                let weighted = c.l * w;
                match c.splat {
                    Some(raster) => splats.push(Splat { raster, l: weighted }),
                    None => l += weighted,
                }
                if let Some(records) = strategies.as_mut() {
                    let raster = c.splat.unwrap_or(raster);
                    records.push(StrategyRecord { s: s as u32, t: t as u32, raster, weighted, unweighted: c.l });
                }
            }
        }
        l
    }

    fn unsamplable(&self, scene: &Scene) -> Vec<String> {
        specular_chains_to_point_lights(scene)
    }
}

/// An unweighted connection: its contribution, the raster position for a
/// t = 1 splat, and the endpoint vertex sampled for it (s = 1: the light
/// sample; t = 1: the camera), which MIS uses in place of the subpath's.
struct Connection {
    l: SampledSpectrum,
    splat: Option<Vec2>,
    sampled: Option<Vertex>,
}

/// The unweighted contribution of strategy (s, t) (pbrt-v3 `ConnectBDPT`),
/// visibility included; None when it is zero.
fn connect(
    scene: &Scene,
    light: &[Vertex],
    camera: &[Vertex],
    s: usize,
    t: usize,
    sampler: &mut Sampler,
    lambda: &SampledWavelengths,
) -> Option<Connection> {
    // An escaped camera path can only be completed by itself (s = 0).
    if t > 1 && s != 0 && camera[t - 1].is_infinite() {
        return None;
    }
    let c = if s == 0 {
        let pt = &camera[t - 1];
        let l = pt.beta * pt.le(scene, &camera[t - 2], lambda);
        Connection { l, splat: None, sampled: None }
    } else if t == 1 {
        let (splat, cam) = connect_to_camera(scene, &light[s - 1], lambda)?;
        Connection { l: splat.l, splat: Some(splat.raster), sampled: Some(cam) }
    } else if s == 1 {
        let pt = &camera[t - 1];
        let (u_light, u) = (sampler.get1d(), sampler.get2d());
        if !pt.is_connectible(scene) {
            return None;
        }
        let (i, pmf) = scene.sample_light(u_light)?;
        let source = &scene.lights[i as usize];
        let ls = source.sample_li(pt.p(), u, lambda)?;
        if ls.pdf_w <= 0.0 || ls.pdf_w.is_nan() || ls.l.is_black() {
            return None;
        }
        let beta = ls.l / (ls.pdf_w * pmf);
        let mut q = if source.is_infinite() {
            Vertex::environment(i, ls.p, -ls.wi, beta, 0.0)
        } else {
            Vertex::light(i, ls.point(), beta, 0.0)
        };
        q.pdf_fwd = q.pdf_light_origin(scene, pt);
        let l = pt.beta * pt.f(scene, &q, lambda, TransportMode::Radiance) * q.beta * ls.wi.dot(pt.si.frame.n).abs();
        if l.is_black() {
            return None;
        }
        let visible = if source.is_infinite() {
            scene.escapes(pt.si.point(), ls.wi)
        } else {
            scene.unoccluded(pt.si.point(), ls.point())
        };
        if !visible {
            return None;
        }
        Connection { l, splat: None, sampled: Some(q) }
    } else {
        let (qs, pt) = (&light[s - 1], &camera[t - 1]);
        if !qs.is_connectible(scene) || !pt.is_connectible(scene) {
            return None;
        }
        let (w, inv_d2) = qs.direction_to(pt)?;
        let g = qs.si.frame.n.dot(w).abs() * pt.si.frame.n.dot(w).abs() * inv_d2;
        let l = qs.beta
            * qs.f(scene, pt, lambda, TransportMode::Importance)
            * pt.f(scene, qs, lambda, TransportMode::Radiance)
            * pt.beta
            * g;
        if l.is_black() || !scene.unoccluded(qs.si.point(), pt.si.point()) {
            return None;
        }
        Connection { l, splat: None, sampled: None }
    };
    (!c.l.is_black()).then_some(c)
}

/// A delta density (stored as 0) becomes 1, so it cancels in the ratios.
#[inline]
fn remap0(x: f32) -> f32 {
    if x != 0.0 {
        x
    } else {
        1.0
    }
}

/// The MIS weight of strategy (s, t) for the path made of `light[..s]` and
/// `camera[..t]` (pbrt-v3 `MISWeight`, generalised to three heuristics).
/// `sampled` is the endpoint the connection made: the camera vertex when
/// t = 1, the light sample when s = 1 (and t > 1); it stands in for
/// camera[0] or light[0]. Public so that tests can check that the weights of
/// all strategies of a path sum to one.
#[allow(clippy::too_many_arguments)]
pub fn mis_weight(
    scene: &Scene,
    light: &[Vertex],
    camera: &[Vertex],
    sampled: Option<&Vertex>,
    s: usize,
    t: usize,
    heuristic: MisHeuristic,
    lambda: &SampledWavelengths,
) -> f32 {
    use TransportMode::{Importance, Radiance};
    let pt = if t == 1 { sampled.expect("t = 1 has a sampled camera vertex") } else { &camera[t - 1] };
    let qs = match s {
        0 => None,
        1 if t > 1 => Some(sampled.expect("s = 1 has a sampled light vertex")),
        _ => Some(&light[s - 1]),
    };
    let pt_minus = (t > 1).then(|| &camera[t - 2]);
    let qs_minus = (s > 1).then(|| &light[s - 2]);

    // The reverse densities at and next to the connection (Veach §10.3.4).
    let pt_rev = match qs {
        Some(qs) => qs.pdf(scene, qs_minus, pt, lambda, Importance),
        None => pt.pdf_light_origin(scene, pt_minus.expect("s = 0 needs t >= 2")),
    };
    let pt_minus_rev = pt_minus.map_or(0.0, |pm| match qs {
        Some(qs) => pt.pdf(scene, Some(qs), pm, lambda, Importance),
        None => pt.pdf_light(scene, pm),
    });
    let qs_rev = qs.map_or(0.0, |qs| pt.pdf(scene, pt_minus, qs, lambda, Radiance));
    let qs_minus_rev = qs_minus.map_or(0.0, |qm| qs.expect("s >= 2").pdf(scene, Some(pt), qm, lambda, Radiance));

    let mut sum = 0.0;
    // Strategies with fewer camera vertices: (s + t - i, i), i = t-1 .. 1.
    let mut r = 1.0;
    for i in (1..t).rev() {
        let v = &camera[i];
        let rev = if i == t - 1 {
            pt_rev
        } else if i == t - 2 {
            pt_minus_rev
        } else {
            v.pdf_rev
        };
        r *= remap0(rev) / remap0(v.pdf_fwd);
        // Joining z_{i-1} to z_i needs both non-specular (z_{t-1} is the
        // connection vertex, non-specular by construction); a light at
        // infinity cannot be joined to the pinhole.
        let delta = (i != t - 1 && v.delta) || camera[i - 1].delta;
        let pinhole_sees_infinity = i == 1 && v.is_infinite();
        if !delta && !pinhole_sees_infinity {
            sum += heuristic.term(r);
        }
    }
    // Strategies with fewer light vertices: (i, s + t - i), i = s-1 .. 0.
    let mut r = 1.0;
    for i in (0..s).rev() {
        let v = if i == s - 1 { qs.expect("s >= 1") } else { &light[i] };
        let rev = if i == s - 1 {
            qs_rev
        } else if i == s - 2 {
            qs_minus_rev
        } else {
            v.pdf_rev
        };
        r *= remap0(rev) / remap0(v.pdf_fwd);
        let delta_prev = if i > 0 { light[i - 1].delta } else { v.is_delta_light(scene) };
        let delta = (i != s - 1 && v.delta) || delta_prev;
        if !delta {
            sum += heuristic.term(r);
        }
    }
    1.0 / (1.0 + sum)
}

/// Unit tests of the pieces that need no scene.
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn remap0_only_touches_zero() {
        assert_eq!(remap0(0.0), 1.0);
        assert_eq!(remap0(0.25), 0.25);
    }
}
