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
//! Each contribution is weighted by MIS (Veach §10.3) with the densities of
//! pbrt-v3 `MISWeight`: the densities p_i of the other strategies that could
//! make the same path relative to the current one are products of ratios
//! pdf_rev / pdf_fwd of area densities vertex by vertex, with remap0 (a delta
//! density, stored as 0, becomes 1 so it cancels) and strategies that would
//! have to connect through a specular vertex, or hit a point light, left out
//! (TRANSPORT-NOTES §6b, §6g). pbrt walks both subpaths for every (s, t);
//! here the sums are built recursively along each subpath once per sample
//! (Georgiev, Krivanek, Davidovic, Slusallek 2012, "Light transport
//! simulation with vertex connection and merging", and its technical report
//! "Implementing vertex connection and merging", eqs. (31)-(36): SmallVCM's
//! dVCM and dVC), so a strategy's weight costs O(1) plus the four reverse
//! densities at and next to the connection, which come out of the same BSDF
//! evaluations as its contribution (`Vertex::scatter`). See `init_mis` for
//! the quantities. Those evaluations take a connection vertex's `wo` as the
//! direction its walk arrived along, as its f always did and as the walk's
//! own stored densities do; pbrt recomputes it from the vertex positions,
//! which differ from it by the ray-origin offset (tests/bdpt.rs measures
//! the effect on the weights: above 1e-3 relative for ~1 strategy in 20,000,
//! on peaked lobes). Roulette is not in these densities (src/path.rs explains
//! why that is still unbiased).
//!
//! `--strategies DIR` (src/render.rs `render_with_strategies`) records each
//! strategy's weighted and unweighted contribution for per-(s, t) images
//! (Veach fig. 10.4), for paths of up to `--strategies-max-length` bounces
//! (8), longer ones together (src/strategies.rs); without it the recording
//! costs one branch.
//!
//! | parameter | type   | default | meaning                                     |
//! |-----------|--------|---------|---------------------------------------------|
//! | max_depth | int    | 1024    | maximum scattering events (s + t - 2)       |
//! | mis       | string | power   | MIS heuristic: power, balance or uniform    |

use super::{Integrator, IntegratorOptions};
use crate::materials::TransportMode;
use crate::path::{camera_subpath, connect_to_camera, light_subpath, Scatter, Segment, Vertex};
use crate::render::{Splat, Workspace};
use crate::sampling::MisHeuristic;
use crate::sampling::Sampler;
use crate::scene::Scene;
use crate::select::select_f32;
use crate::spectrum::{SampledSpectrum, SampledWavelengths};
use crate::strategies::StrategyRecord;
use crate::unsamplable::{environment_paths_overflow, specular_chains_to_point_lights};
use glam::{UVec2, Vec2, Vec4};

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
        let Workspace { splats, paths, strategies, .. } = ws;
        camera_subpath(scene, raster, sampler, lambda, self.max_depth, &mut paths.camera);
        light_subpath::<true>(scene, sampler, lambda, self.max_depth, &mut paths.light);
        init_mis(scene, &mut paths.camera, Subpath::Camera, self.mis);
        init_mis(scene, &mut paths.light, Subpath::Light, self.mis);
        let (camera, light, lambda) = (&paths.camera[..], &paths.light[..], &*lambda);
        let (h, max_depth) = (self.mis, self.max_depth as usize);
        let mut l = SampledSpectrum::ZERO;
        // Adds strategy (s, t)'s weighted contribution: to the pixel, or for
        // t = 1 as a splat at `splat`.
        let mut add = |s: usize, t: usize, c: Connection, splat: Option<Vec2>| {
            let weighted = c.l * c.ends.weight(&c.rev, h);
            match splat {
                Some(raster) => splats.push(Splat { raster, l: weighted }),
                None => l += weighted,
            }
            if let Some(records) = strategies.as_mut() {
                let raster = splat.unwrap_or(raster);
                records.push(StrategyRecord { s: s as u32, t: t as u32, raster, weighted, unweighted: c.l });
            }
        };
        // The strategies with s + t - 2 <= max_depth, t outermost. (Each
        // kind in its own loop: one `match` on (s, t) in a single loop
        // mispredicted ~3 times a sample, as the kinds follow the paths'
        // lengths.) t = 1: every light vertex joined to the pinhole.
        for s in 1..light.len().min(max_depth + 1) + 1 {
            if let Some((c, raster)) = light_tracing(scene, light, camera, s, lambda) {
                add(s, 1, c, Some(raster));
            }
        }
        for t in 2..camera.len().min(max_depth + 2) + 1 {
            if let Some(c) = emitter_hit(scene, camera, t, lambda) {
                add(0, t, c, None);
            }
            // An escaped camera path can only be completed by itself (s = 0).
            // s = 1 draws a light of its own, so it runs whether or not the
            // light subpath is empty (one that emits nothing at the four
            // wavelengths is); the loop over s >= 2 then has nothing to join.
            if camera[t - 1].is_infinite() || t > max_depth + 1 {
                continue;
            }
            if let Some(c) = next_event(scene, light, camera, t, h, sampler, lambda) {
                add(1, t, c, None);
            }
            for s in 2..light.len().min(max_depth + 2 - t) + 1 {
                if let Some(c) = vertex_connection(scene, light, camera, s, t, lambda) {
                    add(s, t, c, None);
                }
            }
        }
        l
    }

    fn unsamplable(&self, scene: &Scene) -> Vec<String> {
        let mut warnings = specular_chains_to_point_lights(scene);
        warnings.extend(environment_paths_overflow(scene));
        warnings
    }
}

/// An unweighted connection of strategy (s, t) (pbrt-v3 `ConnectBDPT`),
/// visibility included: its contribution, non-zero, and what its MIS weight
/// needs.
struct Connection {
    l: SampledSpectrum,
    ends: Ends,
    rev: Reverse,
}

impl Connection {
    /// Strategy (s, t)'s connection with contribution `l`, or None when `l`
    /// is zero; `sampled` as for `Ends::new`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn new(
        l: SampledSpectrum,
        rev: Reverse,
        light: &[Vertex],
        camera: &[Vertex],
        sampled: Option<&Vertex>,
        s: usize,
        t: usize,
    ) -> Option<Self> {
        (!l.is_black()).then(|| Self { l, ends: Ends::new(light, camera, sampled, s, t), rev })
    }
}

/// s = 0: the camera subpath's vertex z_{t-1} is on an emitter.
fn emitter_hit(scene: &Scene, camera: &[Vertex], t: usize, lambda: &SampledWavelengths) -> Option<Connection> {
    let (pt_minus, pt) = (&camera[t - 2], &camera[t - 1]);
    // Most vertices emit nothing: none of the work below for them.
    pt.si.light?;
    let l = pt.beta * pt.le(scene, pt_minus, lambda);
    if l.is_black() {
        return None;
    }
    Connection::new(l, Reverse::emitter(scene, pt, pt_minus), &[], camera, None, 0, t)
}

/// t = 1: the light subpath's vertex y_{s-1} joined to the pinhole, and the
/// raster position it splats to.
fn light_tracing(
    scene: &Scene,
    light: &[Vertex],
    camera: &[Vertex],
    s: usize,
    lambda: &SampledWavelengths,
) -> Option<(Connection, Vec2)> {
    let qs = &light[s - 1];
    let c = connect_to_camera(scene, qs, lambda)?;
    let sp = c.camera.scatter(scene, -c.segment.w, lambda, TransportMode::Radiance);
    let rev = Reverse::connection(qs, &c.scatter, &c.camera, &sp, &c.segment);
    Some((Connection::new(c.splat.l, rev, light, camera, None, s, 1)?, c.splat.raster))
}

/// s = 1: a fresh light sample joined to z_{t-1} (next-event estimation);
/// that light vertex replaces y_0 in the MIS weight.
fn next_event(
    scene: &Scene,
    light: &[Vertex],
    camera: &[Vertex],
    t: usize,
    mis: MisHeuristic,
    sampler: &mut Sampler,
    lambda: &SampledWavelengths,
) -> Option<Connection> {
    let pt = &camera[t - 1];
    let (u_light, u) = (sampler.get_bits(), sampler.get2d());
    if !pt.connectible {
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
    init_mis(scene, std::slice::from_mut(&mut q), Subpath::Light, mis);
    let g = q.segment_to(pt)?;
    let sp = pt.scatter(scene, -g.w, lambda, TransportMode::Radiance);
    let l = pt.beta * sp.f * q.beta * g.w.dot(pt.si.frame.n).abs();
    if l.is_black() {
        return None;
    }
    if !scene.visible(&source.shadow(pt.si.point(), &ls)) {
        return None;
    }
    let sq = q.scatter(scene, g.w, lambda, TransportMode::Importance);
    let rev = Reverse::connection(&q, &sq, pt, &sp, &g);
    Connection::new(l, rev, light, camera, Some(&q), 1, t)
}

/// s, t >= 2: y_{s-1} joined to z_{t-1} by a shadow ray, with
/// G = |cos||cos| / d^2 (shading normals).
fn vertex_connection(
    scene: &Scene,
    light: &[Vertex],
    camera: &[Vertex],
    s: usize,
    t: usize,
    lambda: &SampledWavelengths,
) -> Option<Connection> {
    let (qs, pt) = (&light[s - 1], &camera[t - 1]);
    if !qs.connectible || !pt.connectible {
        return None;
    }
    let g = qs.segment_to(pt)?;
    let sp = pt.scatter(scene, -g.w, lambda, TransportMode::Radiance);
    if sp.f.is_black() {
        return None;
    }
    let sq = qs.scatter(scene, g.w, lambda, TransportMode::Importance);
    let geometry = qs.si.frame.n.dot(g.w).abs() * pt.si.frame.n.dot(g.w).abs() * g.inv_d2;
    let l = qs.beta * sq.f * sp.f * pt.beta * geometry;
    if l.is_black() || !scene.unoccluded(qs.si.point(), pt.si.point()) {
        return None;
    }
    Connection::new(l, Reverse::connection(qs, &sq, pt, &sp, &g), light, camera, None, s, t)
}

/// Which subpath a vertex array is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Subpath {
    Camera,
    Light,
}

/// A delta density (stored as 0) becomes 1, so it cancels in the ratios;
/// a density that overflowed f32 becomes f32::MAX (each lane).
#[inline]
fn remap0(x: Vec4) -> Vec4 {
    Vec4::select(x.cmpeq(Vec4::ZERO), Vec4::ONE, x).min(Vec4::splat(f32::MAX))
}

/// R_j of `init_mis` for each lane's densities: the ratio of the densities
/// with which the other and the own subpath make a vertex, through the
/// heuristic (pbrt's `remap0(pdfRev) / remap0(pdfFwd)`; every heuristic maps
/// a product of ratios to the product of their images, so the sums can be
/// built factor by factor).
///
/// Saturated to the normal f32 range [1.2e-38, 3.4e38], so that no product
/// of a ratio with a sum in [0, inf] is NaN and every weight lies in
/// [0, 1]. Unsaturated, the power heuristic's square of a ratio beyond
/// ~1e19 overflowed, one below ~1e-19 underflowed to 0, and 0 x inf made
/// weights NaN: a sphere flattened onto a floor, 1e-18 above it in a
/// 500-unit room, gave densities of 1e35 beside 1e-7. Within the range
/// nothing changes (the Cornell box's images are bit-identical); beyond it
/// the weights of a path's strategies may no longer sum to exactly one,
/// which needs segments ~1e-10 of their neighbours' length: geometry below
/// f32's resolution, where the estimators disagree in any case
/// (docs/scene-format.md). Chains of very narrow lobes reach it too: 0.15 %
/// of the ratios through a rough glass of index 1.0002 and alpha 0.0025 (an
/// audit, session 44), which the loaders now refuse for its own sake
/// (`Dielectric::MIN_LOBE_WIDTH`). f64 sums would be exact further out but cost
/// 3.7 % of a sample's instructions (docs/performance-log.md, session 29).
#[inline]
fn ratios(h: MisHeuristic, rev: Vec4, fwd: Vec4) -> Vec4 {
    h.terms(remap0(rev) / remap0(fwd)).clamp(Vec4::splat(f32::MIN_POSITIVE), Vec4::splat(f32::MAX))
}

/// Sets the recursive MIS quantities of every vertex of a subpath v_0 ..
/// v_{n-1} (y for the light, z for the camera) for heuristic `h`, once its
/// walk is done; the s = 1 light sample is a one-vertex light subpath.
///
/// pbrt's weight of strategy (s, t) is w = 1 / (1 + S_C + S_L): on the light
/// side S_L = sum over i = s-1 .. 0 of [i allowed] prod_{j=i}^{s-1} R_j with
/// R_j = h(remap0(rev_j) / remap0(fwd_j)) for y_j, and likewise S_C over
/// i = t-1 .. 1 on the camera side. "Allowed" leaves out strategies that
/// would connect at a delta vertex or hit a point light: strategy i needs
/// v_i and v_{i-1} non-delta (v_0 on the light side: not a point light;
/// v_1 on the camera side: not at infinity, the pinhole cannot be joined to
/// it; no camera strategy has i = 0). Only rev_{s-1}, rev_{s-2} (and their
/// camera counterparts) depend on the connection, so with the connection
/// vertex v = v_{s-1}
///
///   S = R_{s-1} (d_vcm(v) + R_{s-2} d_vc(v)),
///   d_vcm(v_m) = [v_{m-1} non-delta] (the rules above at m = 0, 1),
///   d_vc(v_m) = [v_{m-1} allowed] + R_{m-2} d_vc(v_{m-1}),  d_vc(v_0) = 0,
///
/// with R_{m-2} from the densities the walk stored. These are Georgiev et
/// al.'s dVCM and dVC (tech. rep. eqs. (31)-(36), merging off) multiplied by
/// h(pdf_fwd(v)) (dVC also by h(pdf_fwd(v_{m-1})) and the conversion of
/// rev_{m-1} to area measure), i.e. written with pbrt's ratios: quantities
/// of the order of the number of strategies, where the raw ones carry the
/// scene's scale (a squared distance per segment, squared again by the
/// power heuristic) and can leave the f32 range in large scenes.
pub fn init_mis(scene: &Scene, path: &mut [Vertex], subpath: Subpath, h: MisHeuristic) {
    for m in 0..path.len() {
        let d_vcm = match (subpath, m) {
            (Subpath::Light, 0) => !path[0].is_delta_light(scene),
            (Subpath::Camera, 0) => false,
            (Subpath::Camera, 1) => !path[0].delta && !path[1].is_infinite(),
            _ => !path[m - 1].delta,
        };
        let d_vc = match m {
            0 => 0.0,
            _ => {
                let prev = &path[m - 1];
                let allowed = (prev.d_vcm != 0.0 && !prev.delta) as u8 as f32;
                if m >= 2 && prev.d_vc != 0.0 {
                    allowed
                        + ratios(h, Vec4::splat(path[m - 2].pdf_rev), Vec4::splat(path[m - 2].pdf_fwd)).x * prev.d_vc
                } else {
                    allowed
                }
            }
        };
        path[m].d_vcm = d_vcm as u8 as f32;
        path[m].d_vc = d_vc;
    }
}

/// The reverse densities at and next to the connection, in
/// area measure: of the connection vertices pt = z_{t-1}, qs = y_{s-1} and
/// their predecessors being made by the other subpath's walk. pbrt-v3
/// `MISWeight` substitutes them with scoped assignments.
#[derive(Clone, Copy, Debug, Default)]
struct Reverse {
    pt: f32,
    pt_minus: f32,
    qs: f32,
    qs_minus: f32,
}

impl Reverse {
    /// s = 0: the camera subpath ends on an emitter pt, which a light
    /// subpath would have started from (pbrt `PdfLightOrigin`, `PdfLight`).
    fn emitter(scene: &Scene, pt: &Vertex, pt_minus: &Vertex) -> Self {
        Self { pt: pt.pdf_light_origin(scene, pt_minus), pt_minus: pt.pdf_light(scene, pt_minus), ..Self::default() }
    }

    /// s, t >= 1: qs and pt joined by `g` (from qs to pt), with their
    /// scatterings `sq` towards pt and `sp` towards qs (SmallVCM
    /// `ConnectVertices`: cameraBsdfDirPdfA, lightBsdfRevPdfW, ...). The
    /// densities of leaving a connection vertex towards its predecessor are
    /// converted with the factor its walk stored (`Vertex::g_rev`).
    fn connection(qs: &Vertex, sq: &Scatter, pt: &Vertex, sp: &Scatter, g: &Segment) -> Self {
        Self {
            pt: sq.pdf_fwd * g.to_next,
            pt_minus: sp.pdf_rev * pt.g_rev,
            qs: sp.pdf_fwd * g.to_this,
            qs_minus: sq.pdf_rev * qs.g_rev,
        }
    }
}

/// What the weight needs of one side of the connection: the connection
/// vertex's forward density and MIS quantities, and its predecessor's
/// forward density.
#[derive(Clone, Copy, Debug)]
struct End {
    pdf_fwd: f32,
    d_vcm: f32,
    d_vc: f32,
    prev_pdf_fwd: f32,
}

impl End {
    /// A side with no vertex (the camera side of t = 1, the light side of
    /// s = 0): no strategy differs from this one there, so its sum is 0.
    const NONE: Self = Self { pdf_fwd: 0.0, d_vcm: 0.0, d_vc: 0.0, prev_pdf_fwd: 0.0 };

    fn of(v: &Vertex, prev: Option<&Vertex>) -> Self {
        Self { pdf_fwd: v.pdf_fwd, d_vcm: v.d_vcm, d_vc: v.d_vc, prev_pdf_fwd: prev.map_or(0.0, |p| p.pdf_fwd) }
    }

    /// S_L or S_C of `init_mis` (Georgiev et al. tech. rep. eqs. (40)-(41)
    /// in ratio form, for vertex connection; the same sums serve emitter
    /// hits, next-event estimation and light tracing, eqs. (42)-(47)) from
    /// the ratios R at the connection vertex (`r`) and at its predecessor
    /// (`r_prev`).
    #[inline]
    fn sum(&self, r: f32, r_prev: f32) -> f32 {
        // Both terms are computed and the zero cases selected: whether d_vc
        // or the sum is 0 depends on the vertices' kinds, in no order a
        // predictor learns.
        let inner = self.d_vcm + select_f32(self.d_vc != 0.0, r_prev * self.d_vc, 0.0);
        select_f32(inner != 0.0, r * inner, 0.0)
    }
}

/// The ends of strategy (s, t): qs = y_{s-1} and pt = z_{t-1} with their
/// predecessors (`sampled`: the light sample of s = 1, t > 1, which stands
/// in for y_0). There is no camera side for t = 1: no strategy has fewer
/// camera vertices.
#[derive(Clone, Copy, Debug)]
struct Ends {
    light: End,
    camera: End,
}

impl Ends {
    /// Always inlined: called out of line it returned through the stack,
    /// and `weight`'s vector loads of its fields stalled on store
    /// forwarding (-1.5 % instructions; time 0.992x, standard error 0.006;
    /// docs/performance-log.md, "Session 38").
    #[inline(always)]
    fn new(light: &[Vertex], camera: &[Vertex], sampled: Option<&Vertex>, s: usize, t: usize) -> Self {
        let light = match s {
            0 => End::NONE,
            1 if t > 1 => End::of(sampled.expect("s = 1 has a sampled light vertex"), None),
            _ => End::of(&light[s - 1], s.checked_sub(2).map(|i| &light[i])),
        };
        let camera = if t > 1 { End::of(&camera[t - 1], Some(&camera[t - 2])) } else { End::NONE };
        Self { light, camera }
    }

    /// The MIS weight 1 / (1 + S_C + S_L) (Georgiev et al. tech. rep.
    /// eq. (37)). The four ratios R (`ratios`) are one vector division,
    /// lane for lane the scalar ones.
    #[inline]
    fn weight(&self, rev: &Reverse, h: MisHeuristic) -> f32 {
        let (c, l) = (&self.camera, &self.light);
        let num = Vec4::new(rev.pt, rev.pt_minus, rev.qs, rev.qs_minus);
        let den = Vec4::new(c.pdf_fwd, c.prev_pdf_fwd, l.pdf_fwd, l.prev_pdf_fwd);
        let r = ratios(h, num, den);
        1.0 / (1.0 + c.sum(r.x, r.y) + l.sum(r.z, r.w))
    }
}

/// The MIS weight of strategy (s, t) for the path made of `light[..s]` and
/// `camera[..t]`, whose MIS quantities `init_mis` has set for `heuristic`;
/// `sampled` is the endpoint the connection made: the camera vertex when
/// t = 1, the light sample (also prepared by `init_mis`) when s = 1 and
/// t > 1. The densities at the connection are computed as the
/// connections compute them. Public so that tests can check that the weights of all strategies of a
/// path sum to one and match Veach's formula.
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
    let rev = if s == 0 {
        Reverse::emitter(scene, &camera[t - 1], &camera[t - 2])
    } else {
        let pt = if t == 1 { sampled.expect("t = 1 has a sampled camera vertex") } else { &camera[t - 1] };
        let qs = if s == 1 && t > 1 { sampled.expect("s = 1 has a sampled light vertex") } else { &light[s - 1] };
        let Some(g) = qs.segment_to(pt) else {
            return 0.0;
        };
        let sq = qs.scatter(scene, g.w, lambda, TransportMode::Importance);
        let sp = pt.scatter(scene, -g.w, lambda, TransportMode::Radiance);
        Reverse::connection(qs, &sq, pt, &sp, &g)
    };
    Ends::new(light, camera, sampled, s, t).weight(&rev, heuristic)
}

/// Unit tests of the pieces that need no scene.
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn remap0_only_touches_zero_and_overflow() {
        let v = remap0(Vec4::new(0.0, 0.25, -0.0, 3.0)).to_array();
        assert_eq!(v, [1.0, 0.25, 1.0, 3.0]);
        let v = remap0(Vec4::new(f32::INFINITY, f32::MAX, 1e-44, 0.0)).to_array();
        assert_eq!(v, [f32::MAX, f32::MAX, 1e-44, 1.0]);
    }

    /// Densities from a segment 1e-18 long next to ones of hundreds of units
    /// (a NaN sample of a flattened mesh on a floor): the connection
    /// vertex's squared ratio (5.5e-44)^2 underflows f32 and its
    /// predecessor's (1e38 / 1e-6)^2 overflows; unsaturated, the sum was
    /// 0 x inf. Saturated, the weight is 1 / (1 + 2^-126 (1 + f32::MAX)).
    #[test]
    fn extreme_density_ratios_give_a_weight_in_0_1() {
        let camera = End { pdf_fwd: 1.0, d_vcm: 1.0, d_vc: 1.0, prev_pdf_fwd: 1e-6 };
        let ends = Ends { light: End::NONE, camera };
        let rev = Reverse { pt: 5.5e-44, pt_minus: 1e38, ..Reverse::default() };
        let w = ends.weight(&rev, MisHeuristic::Power);
        let saturated = 1.0 / (1.0 + f32::MIN_POSITIVE as f64 * (1.0 + f32::MAX as f64));
        assert!((w as f64 - saturated).abs() <= 1e-6, "weight {w}, expected {saturated}");
        for h in [MisHeuristic::Balance, MisHeuristic::Uniform] {
            let w = ends.weight(&rev, h);
            assert!((0.0..=1.0).contains(&w), "{h:?}: weight {w}");
        }
    }
}
