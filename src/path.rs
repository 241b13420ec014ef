//! What the bidirectional estimators (light tracing, BDPT) share: the path
//! vertex with its forward and reverse densities in area measure, light- and
//! camera-subpath generation by random walk, the densities MIS needs, and the
//! connection of a light-subpath vertex to the pinhole (the t = 1 strategy).
//!
//! Notation (Veach 1997 ch. 10, pbrt-v3 `bdpt.h`, SmallVCM): a light subpath
//! y_0 .. y_{s-1} starts on a light, a camera subpath z_0 .. z_{t-1} at the
//! pinhole; strategy (s, t) joins y_{s-1} to z_{t-1}. Every vertex keeps
//! - `beta`: the subpath throughput up to and including the vertex, i.e.
//!   Veach's alpha_i (eq. 10.6) = product of (f |cos| / pdf) along the walk;
//!   for a light origin it is L_e / P_A (the emitted radiance over the
//!   density of choosing the light and the point on it): every prism emitter
//!   radiates one radiance in every direction it emits, so Veach's split
//!   Le = Le^(0) Le^(1) (eq. 8.7) is kept whole in beta and the origin's
//!   directional factor (`Vertex::scatter`) is 1, or 0 behind it;
//! - `pdf_fwd`: the density with which its own subpath generated it, and
//!   `pdf_rev`: the density with which the OTHER subpath would have generated
//!   it (the walk in the reverse direction), both in AREA measure (Veach
//!   §10.2.1: P_A = P_sigma_perp G, here pdf_w |cos at the vertex| / d^2 with
//!   the vertex's geometric normal). Specular scattering stores 0 for both
//!   (a delta density; MIS remaps it to 1 so it cancels, §10.3.5);
//! - `delta`: the vertex scattered by a specular (delta) lobe.
//!
//! Only MIS reads the densities. A walk records them when its `MIS`
//! parameter is true (BDPT); light tracing, whose strategies all have
//! weight 1, walks with `MIS = false` and its vertices keep `pdf_fwd` (past
//! the light origin), `pdf_rev` and `g_rev` at zero: that saves a BSDF
//! density and a segment per vertex, ~4 % of a light path.
//!
//! Vertices at infinity (the environment light, `VertexKind::Environment`)
//! follow pbrt-v3/v4: their own density is the solid-angle density of their
//! direction (light-choice pmf x `pdf_li`), a solid-angle density converted
//! "to" them is left unchanged, and the density they give the next vertex is
//! planar: the emitted ray's origin lies on a disk of radius R perpendicular
//! to the direction (density 1 / (pi R^2)), times |cos| at the vertex hit.
//!
//! Transport modes (Veach §5.2-5.3): camera subpaths carry radiance and call
//! the BSDF in `TransportMode::Radiance`; light subpaths carry importance and
//! call it in `TransportMode::Importance`, and every importance-mode BSDF
//! factor, in the walk as in connections, is multiplied by Veach's
//! shading-normal correction (eq. 5.19, `SurfaceInteraction::
//! shading_correction`), since the adjoint of a BSDF evaluated with a
//! shading normal is not the BSDF itself (pbrt-v3 does this; pbrt-v4's BDPT
//! omits it). With flat shading (ns = ng) the factor is 1.
//!
//! Russian roulette ends both walks: from the fourth scattering event on
//! (`russian_roulette`'s depth 3, counted from 0 at the first), the relative
//! throughput (beta over its value on leaving the endpoint, so a light
//! path's huge Le / pdf does not disable it) decides survival
//! (`roulette::russian_roulette`). It is NOT folded into the MIS densities
//! (TRANSPORT-NOTES §6h): the weights are then computed from densities that
//! ignore roulette, which still sum to one over the strategies of every path,
//! while each contribution divides by its true survival probability, so the
//! estimate stays unbiased.
//!
//! Dispersion: both subpaths of a sample share one `SampledWavelengths` and
//! fetch materials with `Scene::material_at`, so a dispersive surface met by either
//! walk keeps only the hero wavelength for the whole sample; connections are
//! evaluated after both walks, and the driver converts splats with the final
//! wavelengths (TRANSPORT-NOTES §7).

use crate::camera::CameraWiSample;
use crate::geometry::{Frame, Ray, SurfacePoint};
use crate::light::Light;
use crate::materials::TransportMode;
use crate::render::Splat;
use crate::roulette::russian_roulette;
use crate::sampling::Sampler;
use crate::scene::{Material, Scene, SurfaceInteraction};
use crate::select::select_f32;
use crate::spectrum::{SampledSpectrum, SampledWavelengths};
use glam::{Vec2, Vec3A};

/// What a path vertex is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VertexKind {
    /// The pinhole (z_0). Its position is a delta; never "on a surface".
    Camera,
    /// A point on an area light or a point light (y_0 of a light subpath, or
    /// the light sample of the s = 1 strategy).
    Light,
    /// A scattering point on a surface (it may also emit).
    Surface,
    /// The environment light, a vertex at infinity: the end of a camera
    /// subpath that escaped, or the origin of a light subpath it emitted.
    Environment,
}

/// A vertex of a light or camera subpath (see the module doc for the
/// meaning of each density).
#[derive(Clone, Copy, Debug)]
pub struct Vertex {
    pub kind: VertexKind,
    /// Position, geometric normal `ng` (zero off surfaces: camera, point
    /// light, environment), shading frame, `wo` and material. `wo` is the
    /// unit direction towards the previous vertex of the vertex's own
    /// subpath; for an `Environment` vertex it is the direction light from
    /// the environment travels into the scene. `light` names the emitter at
    /// this vertex (a light, an emissive surface, the environment).
    pub si: SurfaceInteraction,
    pub beta: SampledSpectrum,
    pub delta: bool,
    /// Whether a deterministic connection can end here: the pinhole, a
    /// light, or a surface with a non-specular lobe (found once, when the
    /// vertex is made; BDPT asks at every connection).
    pub connectible: bool,
    /// pbrt's IsOnSurface, found once when the vertex is made: `si.ng` is
    /// not zero (`is_on_surface`).
    pub on_surface: bool,
    pub pdf_fwd: f32,
    pub pdf_rev: f32,
    /// Converts a density of leaving this vertex towards the previous vertex
    /// of its own subpath into area measure there (`Segment::to_this` of the
    /// segment arriving here), so a reverse density found at a connection
    /// needs no geometry recomputed; 0 for a subpath's first vertex and in
    /// walks without MIS.
    pub g_rev: f32,
    /// BDPT's recursive MIS quantities, set after the walk by
    /// `integrators::bdpt` (which explains them); zero until then.
    pub d_vcm: f32,
    pub d_vc: f32,
}

/// The straight segment from a vertex to `next` (`Vertex::segment_to`).
#[derive(Clone, Copy, Debug)]
pub struct Segment {
    /// Unit direction from the vertex towards `next`.
    pub w: Vec3A,
    /// 1 / d^2, or 1 if either end is at infinity.
    pub inv_d2: f32,
    /// Converts a density of leaving the vertex along `w` into area measure
    /// at `next`: |cos| at `next` (geometric normal; 1 off surfaces) / d^2
    /// (Veach eq. 8.10; pbrt `ConvertDensity`); 1 if `next` is at infinity,
    /// where densities stay in solid angle.
    pub to_next: f32,
    /// The same for a density of leaving `next` towards the vertex.
    pub to_this: f32,
}

/// A vertex's scattering towards a direction, with both densities MIS needs
/// (`Vertex::scatter`).
#[derive(Clone, Copy, Debug)]
pub struct Scatter {
    /// The BSDF (importance mode: times Veach's eq. 5.19 correction), or for
    /// a light origin its directional factor: 1 where it emits, 0 behind a
    /// one-sided emitter (the radiance itself is in the origin's `beta`);
    /// zero at the camera and at infinity.
    pub f: SampledSpectrum,
    /// Density of the vertex's walk choosing the direction: solid angle, or
    /// planar from the environment (pbrt `Vertex::Pdf` before conversion).
    pub pdf_fwd: f32,
    /// Density of the adjoint walk arriving along the direction choosing the
    /// vertex's `wo` (solid angle; zero for endpoints, which have no `wo`).
    pub pdf_rev: f32,
}

/// Reused per-worker vertex storage for the bidirectional estimators (no
/// allocation per sample once the vectors have grown to the longest path).
#[derive(Default)]
pub struct PathScratch {
    pub camera: Vec<Vertex>,
    pub light: Vec<Vertex>,
}

impl Vertex {
    fn new(kind: VertexKind, si: SurfaceInteraction, beta: SampledSpectrum, pdf_fwd: f32) -> Self {
        let (connectible, on_surface) = (kind != VertexKind::Surface, si.ng != Vec3A::ZERO);
        let (pdf_rev, g_rev, d_vcm, d_vc) = (0.0, 0.0, 0.0, 0.0);
        Self { kind, si, beta, delta: false, connectible, on_surface, pdf_fwd, pdf_rev, g_rev, d_vcm, d_vc }
    }

    /// A scattering point of a walk, with the material found there.
    fn surface(si: SurfaceInteraction, material: &Material, beta: SampledSpectrum) -> Self {
        Self { connectible: material.is_non_specular(), ..Self::new(VertexKind::Surface, si, beta, 0.0) }
    }

    fn endpoint(kind: VertexKind, at: SurfacePoint, wo: Vec3A, light: Option<u32>) -> SurfaceInteraction {
        let SurfacePoint { p, p_error, n, slot } = at;
        let frame = if n == Vec3A::ZERO { Frame::from_normal(Vec3A::Z) } else { Frame::from_normal(n) };
        debug_assert!(kind != VertexKind::Surface);
        SurfaceInteraction { p, p_error, t: 0.0, ng: n, frame, wo, material: u32::MAX, light, slot }
    }

    /// The pinhole as the first camera vertex, with throughput `beta`.
    pub fn camera(scene: &Scene, beta: SampledSpectrum) -> Self {
        let si = Self::endpoint(VertexKind::Camera, SurfacePoint::at(scene.camera.position), Vec3A::ZERO, None);
        Self::new(VertexKind::Camera, si, beta, 0.0)
    }

    /// A light origin (area or point light `light` at `at`, whose normal is
    /// zero for a point light), throughput `beta` = Le / pdf and origin
    /// density `pdf_fwd`.
    pub fn light(light: u32, at: SurfacePoint, beta: SampledSpectrum, pdf_fwd: f32) -> Self {
        let si = Self::endpoint(VertexKind::Light, at, Vec3A::ZERO, Some(light));
        Self::new(VertexKind::Light, si, beta, pdf_fwd)
    }

    /// The environment light `light` as a vertex at infinity; `w_in` is the
    /// direction its light travels into the scene, `p` any point far away
    /// along -w_in.
    pub fn environment(light: u32, p: Vec3A, w_in: Vec3A, beta: SampledSpectrum, pdf_fwd: f32) -> Self {
        let si = Self::endpoint(VertexKind::Environment, SurfacePoint::at(p), w_in, Some(light));
        Self::new(VertexKind::Environment, si, beta, pdf_fwd)
    }

    #[inline]
    pub fn p(&self) -> Vec3A {
        self.si.p
    }

    /// pbrt's IsOnSurface: the vertex has a normal that cosines refer to.
    #[inline]
    pub fn is_on_surface(&self) -> bool {
        self.on_surface
    }

    #[inline]
    pub fn is_infinite(&self) -> bool {
        self.kind == VertexKind::Environment
    }

    /// The emitter at this vertex, if any (a surface vertex on an emissive
    /// triangle is one).
    #[inline]
    pub fn emitter<'a>(&self, scene: &'a Scene) -> Option<(u32, &'a Light)> {
        self.si.light.map(|i| (i, &scene.lights[i as usize]))
    }

    /// A point light: its position cannot be hit by a walk.
    #[inline]
    pub fn is_delta_light(&self, scene: &Scene) -> bool {
        self.kind == VertexKind::Light && self.emitter(scene).is_some_and(|(_, l)| l.is_delta_position())
    }

    /// Unit direction from this vertex towards `next`, and 1 / d^2 (1 when
    /// `next` is at infinity); None for coincident points, and for points
    /// so close that d^2 is below the normal f32 range (d < 1.1e-19), where
    /// 1 / d^2 may overflow.
    #[inline]
    pub fn direction_to(&self, next: &Vertex) -> Option<(Vec3A, f32)> {
        if next.is_infinite() {
            return Some((-next.si.wo, 1.0));
        }
        if self.is_infinite() {
            return Some((self.si.wo, 1.0));
        }
        let d = next.p() - self.p();
        let d2 = d.length_squared();
        if !(f32::MIN_POSITIVE..=f32::MAX).contains(&d2) {
            return None;
        }
        Some((d / d2.sqrt(), 1.0 / d2))
    }

    /// The segment to `next`, with the factors that convert densities of
    /// leaving either end into area measure at the other (see `Segment`;
    /// from a vertex at infinity a density is planar, per unit area across
    /// the direction, so only |cos| applies). None for coincident points.
    #[inline]
    pub fn segment_to(&self, next: &Vertex) -> Option<Segment> {
        let (w, inv_d2) = self.direction_to(next)?;
        let cos = |v: &Vertex| if v.is_on_surface() { v.si.ng.dot(w).abs() } else { 1.0 };
        let to = |v: &Vertex| if v.is_infinite() { 1.0 } else { cos(v) * inv_d2 };
        Some(Segment { w, inv_d2, to_next: to(next), to_this: to(self) })
    }

    /// Converts a density of leaving this vertex towards `next` into area
    /// measure at `next` (`Segment::to_next`); 0 for coincident points.
    #[inline]
    pub fn convert_density(&self, pdf: f32, next: &Vertex) -> f32 {
        self.segment_to(next).map_or(0.0, |g| pdf * g.to_next)
    }

    /// Scattering at this vertex towards the unit direction `wi`: f and both
    /// densities from one BSDF evaluation (SmallVCM `BSDF::Evaluate`), `wo`
    /// being the direction the walk arrived along. A light origin gives
    /// its directional factor (1 or 0) and its emission density, the pinhole its directional
    /// importance density, a vertex at infinity the planar density of its
    /// emitted rays (pbrt `Vertex::f`, `Vertex::Pdf`, `PdfLight`). Always
    /// inlined, as the profile-guided build chose (docs/performance-log.md,
    /// "Session 16").
    #[inline(always)]
    pub fn scatter(&self, scene: &Scene, wi: Vec3A, lambda: &SampledWavelengths, mode: TransportMode) -> Scatter {
        // Surfaces first, by a conditional branch: a `match` on the kind
        // compiles to a jump table, whose indirect jump mispredicted ~10
        // times per bdpt sample, as connection ends alternate between kinds.
        if self.kind == VertexKind::Surface {
            let frame = &self.si.frame;
            let e = scene.bsdf(&self.si).eval_with_pdfs(frame.to_local(self.si.wo), frame.to_local(wi), lambda, mode);
            // Importance only; computed either way and selected, as the two
            // ends of a connection alternate between the modes.
            let correction = self.si.shading_correction(self.si.wo, wi);
            let f = e.f * select_f32(mode == TransportMode::Importance, correction, 1.0);
            return Scatter { f, pdf_fwd: e.pdf, pdf_rev: e.pdf_rev };
        }
        if self.kind == VertexKind::Camera {
            return Scatter { f: SampledSpectrum::ZERO, pdf_fwd: scene.camera.pdf_dir(wi), pdf_rev: 0.0 };
        }
        // A light origin or the environment.
        let Some((_, light)) = self.emitter(scene) else {
            return Scatter { f: SampledSpectrum::ZERO, pdf_fwd: 0.0, pdf_rev: 0.0 };
        };
        let f = match light {
            Light::Area(a) if !a.emits_toward(self.si.ng, wi) => SampledSpectrum::ZERO,
            Light::Environment(_) => SampledSpectrum::ZERO,
            _ => SampledSpectrum::ONE,
        };
        let (pdf_pos, pdf_dir) = light.pdf_le(self.si.ng, wi);
        let pdf_fwd = if self.is_infinite() { pdf_pos } else { pdf_dir };
        Scatter { f, pdf_fwd, pdf_rev: 0.0 }
    }

    /// This vertex as an emitter: area density at `next` of a light subpath
    /// starting here choosing `next` (pbrt `PdfLight`): `pdf_dir` / d^2 x
    /// |cos at next|, or the planar density 1 / (pi R^2) x |cos| for the
    /// environment.
    pub fn pdf_light(&self, scene: &Scene, next: &Vertex) -> f32 {
        let Some((_, light)) = self.emitter(scene) else {
            return 0.0;
        };
        let Some((w, _)) = self.direction_to(next) else {
            return 0.0;
        };
        let (pdf_pos, pdf_dir) = light.pdf_le(self.si.ng, w);
        let pdf = if self.is_infinite() { pdf_pos } else { pdf_dir };
        self.convert_density(pdf, next)
    }

    /// This vertex as an emitter: density of a light subpath starting here
    /// (pbrt `PdfLightOrigin`): light-choice pmf x area density of the point,
    /// or for the environment pmf x solid-angle density of its direction.
    pub fn pdf_light_origin(&self, scene: &Scene, next: &Vertex) -> f32 {
        let Some((i, light)) = self.emitter(scene) else {
            return 0.0;
        };
        let pmf = scene.light_pmf(i);
        if self.is_infinite() {
            return pmf * light.pdf_li(next.p(), self.p(), Vec3A::ZERO);
        }
        let Some((w, _)) = self.direction_to(next) else {
            return 0.0;
        };
        pmf * light.pdf_le(self.si.ng, w).0
    }

    /// Radiance this vertex emits towards `toward` (zero if it emits nothing).
    pub fn le(&self, scene: &Scene, toward: &Vertex, lambda: &SampledWavelengths) -> SampledSpectrum {
        let Some((_, light)) = self.emitter(scene) else {
            return SampledSpectrum::ZERO;
        };
        match light {
            Light::Environment(_) => light.environment_le(lambda),
            Light::Area(a) => match self.direction_to(toward) {
                Some((w, _)) => a.radiance(self.si.ng, w, lambda),
                None => SampledSpectrum::ZERO,
            },
            Light::Point(_) => SampledSpectrum::ZERO,
        }
    }
}

/// Generates a camera subpath through raster position `raster` into `path`
/// (cleared first): the pinhole, then up to `max_depth` + 1 vertices found
/// by a radiance-mode random walk; a ray that escapes ends on an
/// `Environment` vertex if the scene has one (pbrt-v3
/// `GenerateCameraSubpath`).
pub fn camera_subpath(
    scene: &Scene,
    raster: Vec2,
    sampler: &mut Sampler,
    lambda: &mut SampledWavelengths,
    max_depth: u32,
    path: &mut Vec<Vertex>,
) {
    path.clear();
    let ray = scene.camera.generate_ray(raster);
    // beta = We cos / (pdf_pos pdf_dir) = 1 for a pixel's box filter (camera.rs).
    path.push(Vertex::camera(scene, SampledSpectrum::ONE));
    let pdf_dir = scene.camera.pdf_dir(ray.d);
    random_walk::<true>(
        scene,
        ray,
        SampledSpectrum::ONE,
        pdf_dir,
        sampler,
        lambda,
        TransportMode::Radiance,
        max_depth as usize + 2,
        path,
    );
}

/// Generates a light subpath into `path` (cleared first): a light chosen by
/// power, an emitted ray from `sample_le`, then an importance-mode random
/// walk, up to `max_depth` + 1 vertices (pbrt-v3 `GenerateLightSubpath`),
/// with the densities MIS needs if `MIS` (see the module doc). Leaves
/// `path` empty if the scene has no light or emission fails.
pub fn light_subpath<const MIS: bool>(
    scene: &Scene,
    sampler: &mut Sampler,
    lambda: &mut SampledWavelengths,
    max_depth: u32,
    path: &mut Vec<Vertex>,
) {
    path.clear();
    let u_light = sampler.get_bits();
    let (u1, u2) = (sampler.get2d(), sampler.get2d());
    let Some((i, pmf)) = scene.sample_light(u_light) else {
        return;
    };
    let light = &scene.lights[i as usize];
    let Some(le) = light.sample_le(u1, u2, lambda) else {
        return;
    };
    if le.pdf_pos == 0.0 || le.pdf_dir == 0.0 || le.l.is_black() {
        return;
    }
    let mut ray = le.ray;
    let (origin, beta, pdf_walk) = if light.is_infinite() {
        // The origin is the direction (solid angle, pmf pdf_dir); the point
        // on the disk is the "direction" of the first step (planar pdf_pos).
        let v = Vertex::environment(i, le.ray.o, le.ray.d, le.l / (pmf * le.pdf_dir), pmf * le.pdf_dir);
        (v, v.beta / le.pdf_pos, le.pdf_pos)
    } else {
        let n = if light.is_delta_position() { Vec3A::ZERO } else { le.n };
        let at = SurfacePoint { p: le.ray.o, p_error: le.p_error, n, slot: le.slot };
        let v = Vertex::light(i, at, le.l / (pmf * le.pdf_pos), pmf * le.pdf_pos);
        let cos = if n == Vec3A::ZERO { 1.0 } else { n.dot(le.ray.d).abs() };
        // `sample_le` leaves the origin on the emitter: move it off, or the
        // ray may hit its own triangle at t ~ 0.
        ray = at.spawn_ray(ray.d);
        (v, v.beta * (cos / le.pdf_dir), le.pdf_dir)
    };
    path.push(origin);
    random_walk::<MIS>(
        scene,
        ray,
        beta,
        pdf_walk,
        sampler,
        lambda,
        TransportMode::Importance,
        max_depth as usize + 1,
        path,
    );
}

/// Extends `path` (holding the subpath's endpoint) by tracing `ray` and
/// sampling BSDFs (pbrt-v3 `RandomWalk`) until `max_vertices`, a miss,
/// absorption or roulette. `beta` is the throughput the ray carries and
/// `pdf` the density (solid angle; planar from the environment) with which
/// its direction was chosen; with `MIS`, each vertex also gets its
/// densities in area measure. Always inlined, as the profile-guided build
/// chose (docs/performance-log.md, "Session 16").
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn random_walk<const MIS: bool>(
    scene: &Scene,
    mut ray: Ray,
    mut beta: SampledSpectrum,
    mut pdf: f32,
    sampler: &mut Sampler,
    lambda: &mut SampledWavelengths,
    mode: TransportMode,
    max_vertices: usize,
    path: &mut Vec<Vertex>,
) {
    let beta0 = beta.max_component();
    if beta0 <= 0.0 || !beta0.is_finite() {
        return;
    }
    let mut eta_scale = 1.0;
    for depth in 0.. {
        if path.len() >= max_vertices {
            return;
        }
        let Some(si) = scene.intersect(&ray) else {
            // Only radiance (camera) walks can end on the environment:
            // a light walk that escapes carries importance to nothing.
            if let (TransportMode::Radiance, Some((i, _))) = (mode, scene.environment()) {
                let far = ray.o + ray.d * (2.0 * scene.radius);
                push_vertex::<MIS>(path, Vertex::environment(i, far, -ray.d, beta, 0.0), pdf);
            }
            return;
        };
        // Fetch the BSDF now, even if the walk stops here: connections will
        // evaluate it, and a dispersive one must end the secondaries first.
        let material = scene.material_at(&si, lambda);
        push_vertex::<MIS>(path, Vertex::surface(si, material, beta), pdf);
        let bsdf = material.bsdf();
        if path.len() >= max_vertices {
            return;
        }
        let wo = si.frame.to_local(si.wo);
        let Some(bs) = bsdf.sample(wo, sampler.get1d(), sampler.get2d(), lambda, mode) else {
            return;
        };
        let wi = si.frame.to_world(bs.wi);
        beta *= bs.f * (bs.wi.z.abs() / bs.pdf);
        // A delta density is stored as 0 (module doc).
        pdf = select_f32(bs.is_specular(), 0.0, bs.pdf);
        if MIS {
            let pdf_rev = bsdf.pdf(bs.wi, wo, lambda, mode.flip());
            let n = path.len();
            path[n - 2].pdf_rev = select_f32(bs.is_specular(), 0.0, pdf_rev) * path[n - 1].g_rev;
        }
        match mode {
            TransportMode::Importance => beta *= si.shading_correction(si.wo, wi),
            TransportMode::Radiance if bs.flags.is_transmission() => eta_scale *= bs.eta * bs.eta,
            TransportMode::Radiance => {}
        }
        let n = path.len();
        path[n - 1].delta = bs.is_specular();
        // Roulette on the throughput relative to the walk's start.
        let mut rel = beta / beta0;
        if beta.is_black() || !russian_roulette(&mut rel, eta_scale, depth, || sampler.get1d()) {
            return;
        }
        beta = rel * beta0;
        ray = si.spawn_ray(wi);
    }
}

/// Appends `v`, reached from the path's last vertex by a direction chosen
/// with density `pdf`; with `MIS`, its forward density in area measure and
/// the factor that will convert its reverse density, from one `Segment`.
#[inline]
fn push_vertex<const MIS: bool>(path: &mut Vec<Vertex>, mut v: Vertex, pdf: f32) {
    if MIS {
        let prev = path.last().expect("a walk starts at an endpoint");
        if let Some(g) = prev.segment_to(&v) {
            v.pdf_fwd = pdf * g.to_next;
            v.g_rev = g.to_this;
        }
    }
    path.push(v);
}

/// The t = 1 strategy: vertex `v` of a light subpath seen by the pinhole
/// (Veach §10.2; pbrt-v3 `ConnectBDPT` t == 1): the splat
/// beta f |cos_v| We / pdf (`Camera::sample_wi`; f in importance mode with
/// the shading correction, |cos| with the shading normal), or None if `v`
/// cannot connect, projects outside the image, carries nothing or is
/// occluded. Always inlined, as the profile-guided build chose
/// (docs/performance-log.md, "Session 16").
#[inline(always)]
pub fn connect_to_camera(scene: &Scene, v: &Vertex, lambda: &SampledWavelengths) -> Option<CameraConnection> {
    if v.is_infinite() || !v.connectible {
        return None;
    }
    let cs: CameraWiSample = scene.camera.sample_wi(v.p())?;
    if cs.pdf_w <= 0.0 || cs.pdf_w.is_nan() || cs.we == 0.0 {
        return None;
    }
    let camera = Vertex::camera(scene, SampledSpectrum::splat(cs.we / cs.pdf_w));
    let segment = v.segment_to(&camera)?;
    let scatter = v.scatter(scene, segment.w, lambda, TransportMode::Importance);
    let cos = if v.is_on_surface() { segment.w.dot(v.si.frame.n).abs() } else { 1.0 };
    let l = v.beta * scatter.f * camera.beta * cos;
    if l.is_black() || !scene.unoccluded(v.si.point(), camera.si.point()) {
        return None;
    }
    Some(CameraConnection { splat: Splat { raster: cs.raster, l }, camera, segment, scatter })
}

/// A light-subpath vertex joined to the pinhole (`connect_to_camera`): the
/// splat, the camera vertex made for it, the segment from the light vertex
/// to it and the light vertex's scattering along that segment (BDPT's MIS
/// reads the densities there).
pub struct CameraConnection {
    pub splat: Splat,
    pub camera: Vertex,
    pub segment: Segment,
    pub scatter: Scatter,
}
