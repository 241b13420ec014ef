//! The scene model: triangles with materials and emission, lights, camera,
//! and the queries the integrators make (closest hit as a surface
//! interaction, visibility, light selection).

mod coplanar;
mod gltf;
mod json;
pub mod locate;
mod render_space;
mod tagged;

pub use self::gltf::{gltf_conductor_eta_k, load_gltf, parse_gltf, GltfScene};
pub use json::{load_scene, parse_scene, LoadError};

use crate::accel::{Accel, TriangleHit, LANES};
use crate::camera::Camera;
use crate::geometry::{
    barycentric_error, edge_margin, kept_off_edges, near_edges, shading_normal, Frame, Ray, Shadow, SurfacePoint,
    NO_TRIANGLE,
};
use crate::light::{AreaLight, EnvironmentLight, Light, PointLight};
use crate::materials::Bsdf;
use crate::sampling::AliasTable;
use crate::shapes::Mesh;
use crate::spectrum::{SampledWavelengths, Spectrum};
use glam::{DVec3, Vec3A};
use std::cell::Cell;
use std::path::PathBuf;

thread_local! {
    /// Rays traced by this thread since the last `take_ray_count`.
    static RAYS: Cell<u64> = const { Cell::new(0) };
}

#[inline]
fn count_rays(n: u32) {
    RAYS.with(|c| c.set(c.get() + n as u64));
}

/// Returns and resets the number of rays this thread has traced.
pub fn take_ray_count() -> u64 {
    RAYS.with(|c| c.replace(0))
}

/// A named BSDF. It caches the two properties that a walk asks of the BSDF
/// at every hit, non-specular and dispersive: each was a `match` on the
/// BSDF's kind, together ~0.34 % of a `bdpt` sample's instructions
/// (docs/performance-log.md, "Session 45").
#[derive(Clone, Debug)]
pub struct Material {
    pub name: String,
    bsdf: Bsdf,
    non_specular: bool,
    dispersive: bool,
}

impl Material {
    pub fn new(name: &str, bsdf: Bsdf) -> Self {
        let (non_specular, dispersive) = (bsdf.flags().is_non_specular(), bsdf.is_dispersive());
        Self { name: name.to_string(), bsdf, non_specular, dispersive }
    }

    /// The BSDF, fixed at `new` (the cached properties follow it).
    #[inline]
    pub fn bsdf(&self) -> &Bsdf {
        &self.bsdf
    }

    /// `bsdf().flags().is_non_specular()`: whether a deterministic
    /// connection can end here.
    #[inline]
    pub fn is_non_specular(&self) -> bool {
        self.non_specular
    }
}

/// Defaults a scene file may set for `prism render`.
#[derive(Clone, Debug, Default)]
pub struct RenderDefaults {
    pub spp: Option<u32>,
    pub max_depth: Option<u32>,
    pub integrator: Option<String>,
    pub seed: Option<u64>,
}

const NO_LIGHT: u32 = u32::MAX;

/// What shading needs of one mesh beyond its vertex positions (those are
/// kept once, in the BVH: `Accel::vertices`). The mesh's triangles are
/// `start..start + len` in the scene's numbering, which is the BVH's input
/// order and the order of `SceneBuilder::mesh` calls.
#[derive(Debug)]
struct MeshRecord {
    start: u32,
    material: u32,
    /// Per-triangle area light (`NO_LIGHT` for a zero-area triangle) if the
    /// mesh emits; empty otherwise.
    lights: Vec<u32>,
    /// Vertex indices and per-vertex shading normals, if the mesh has normals.
    shading: Option<(Vec<[u32; 3]>, Vec<Vec3A>)>,
}

/// Reads a file the loaders name (scene, glTF, buffer, image), refusing
/// anything but a regular file: a FIFO would hang the loader and /dev/zero
/// would read until memory runs out.
fn read_regular_file(path: &std::path::Path) -> std::io::Result<Vec<u8>> {
    if std::fs::metadata(path)?.is_file() {
        std::fs::read(path)
    } else {
        Err(std::io::Error::other("not a regular file"))
    }
}

/// Whether a triangle with an area (in f64) has a cross product whose
/// squared length, which its normal and area are computed from, is not a
/// normal f32: subnormal (few bits left) or zero (the BVH leaves it out).
fn too_small_for_f32(v: &[Vec3A; 3]) -> bool {
    let l2 = (v[1] - v[0]).cross(v[2] - v[0]).length_squared();
    let [a, b, c] = v.map(|p| p.as_dvec3());
    l2 < f32::MIN_POSITIVE && a.is_finite() && b.is_finite() && c.is_finite() && (b - a).cross(c - a) != DVec3::ZERO
}

/// Whether a triangle is finer than f32 resolves where it lies: its longest
/// edge spans less than 2^-20 of its largest coordinate (8 to 16 units in
/// the last place), so rounding its vertices to f32, as the file's numbers
/// or a shape's tessellation were rounded, moved them by a sixteenth of an
/// edge or more. Its shape and normal are then the rounding's, whatever the
/// estimator: an icosphere of radius 1e-7 at x = 0.25 read 4 % brighter
/// than at the origin under `path`, `light` and `bdpt` alike, and one of
/// 3e-8 read 24 % brighter. A triangle whose coordinates are exact in f32
/// is named too (a sign 5e-4 across in the plane x = 1000: a review):
/// per triangle, rounding cannot be told from intent (the sphere's small
/// triangles lie in one plane x = const after rounding, as the sign does
/// by design), so the warning says "unless". A triangle without extent is
/// left to `too_small_for_f32`.
fn below_position_resolution(v: &[Vec3A; 3]) -> bool {
    let longest =
        [v[1] - v[0], v[2] - v[1], v[0] - v[2]].map(|e| e.abs().max_element()).into_iter().fold(0.0, f32::max);
    let largest = v.map(|p| p.abs().max_element()).into_iter().fold(0.0, f32::max);
    longest > 0.0 && longest < largest * (-20f32).exp2()
}

/// Geometric normal from the winding, normalize((v1 - v0) x (v2 - v0)), and
/// the area; +z for a zero-area or non-finite triangle.
#[inline]
fn normal_and_area(v: &[Vec3A; 3]) -> (Vec3A, f32) {
    let cross = (v[1] - v[0]).cross(v[2] - v[0]);
    let area = 0.5 * cross.length();
    let ng = if area > 0.0 && area.is_finite() { cross.normalize() } else { Vec3A::Z };
    (ng, area)
}

/// Index of the mesh holding triangle `prim`: the last one starting at or
/// before it (an empty mesh shares its start with the next one).
#[inline]
fn mesh_index(meshes: &[MeshRecord], prim: u32) -> usize {
    meshes.partition_point(|m| m.start <= prim) - 1
}

/// A ray's closest hit, with everything shading needs.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceInteraction {
    pub p: Vec3A,
    /// Bound on the rounding error of `p` per axis (`barycentric_error`).
    pub p_error: Vec3A,
    pub t: f32,
    /// Geometric normal (winding side).
    pub ng: Vec3A,
    /// Shading frame; its normal is on the same side as `ng`.
    pub frame: Frame,
    /// Unit direction back along the incoming ray.
    pub wo: Vec3A,
    pub material: u32,
    /// The area light of this triangle, if it emits.
    pub light: Option<u32>,
    /// The triangle's BVH slot (`NO_TRIANGLE` for a path's end points).
    pub slot: u32,
}

impl SurfaceInteraction {
    /// A ray leaving the surface in direction `w`, offset off the surface.
    #[inline]
    pub fn spawn_ray(&self, w: Vec3A) -> Ray {
        self.point().spawn_ray(w)
    }

    /// The point with its error bound and geometric normal, for visibility.
    #[inline]
    pub fn point(&self) -> SurfacePoint {
        SurfacePoint { p: self.p, p_error: self.p_error, n: self.ng, slot: self.slot }
    }

    /// Veach's shading-normal correction for adjoint (importance) transport,
    /// Veach 1997 eq. 5.19: |wo.ns| |wi.ng| / (|wo.ng| |wi.ns|), 0 when the
    /// denominator is 0. `wo` and `wi` are world directions.
    ///
    /// Exactly 1 where the shading normal is the geometric one (flat
    /// shading), the formula's value wherever its denominator is not 0.
    /// Where it is 0, the formula gave 0: wo or wi lies in the surface in
    /// f32 (or the product underflows). At a connection (`Vertex::scatter`)
    /// the BSDF's f is 0 there already, since each BSDF tests the same
    /// cosine, taken in the shading frame, for 0 (the dielectric's f can
    /// be large or infinite only if the product underflows, |cos| below
    /// ~1e-22 at both ends). In a walk, a direction sampled within ~1e-7 of
    /// the surface can round into it in world space: its walk, which the 0
    /// ended, goes on with its weight. Both are events of measure zero; the
    /// images of every scene of `scenes/` are bit-identical. The four dot
    /// products and the division skipped cost `bdpt` 0.36 % of its
    /// instructions (docs/performance-log.md, "Session 45").
    #[inline]
    pub fn shading_correction(&self, wo: Vec3A, wi: Vec3A) -> f32 {
        if self.frame.n == self.ng {
            return 1.0;
        }
        let num = wo.dot(self.frame.n).abs() * wi.dot(self.ng).abs();
        let den = wo.dot(self.ng).abs() * wi.dot(self.frame.n).abs();
        if den == 0.0 {
            0.0
        } else {
            num / den
        }
    }
}

pub struct Scene {
    pub camera: Camera,
    pub accel: Accel,
    meshes: Vec<MeshRecord>,
    /// The mesh of the triangle in each BVH slot, so a hit needs no search
    /// over `meshes` (2 bytes per triangle); None for a scene of more than
    /// 2^16 meshes, whose hits use `mesh_index`.
    slot_mesh: Option<Vec<u16>>,
    /// Vertices of the degenerate triangles, which the BVH does not store
    /// (never hit; kept for `triangles`), sorted by triangle index.
    degenerate: Vec<(u32, [Vec3A; 3])>,
    /// Triangles too small for f32 (`too_small_for_f32`).
    too_small: usize,
    /// Triangles finer than f32 resolves where the file put them
    /// (`below_position_resolution`).
    unresolved: usize,
    pub materials: Vec<Material>,
    pub lights: Vec<Light>,
    /// For each light, the name of the object or light entry it came from.
    pub light_names: Vec<String>,
    light_sampler: Option<AliasTable>,
    environment: Option<u32>,
    pub center: Vec3A,
    pub radius: f32,
    pub defaults: RenderDefaults,
    /// What `render_space` subtracted from the file's positions (0 for a
    /// scene that contains the origin).
    pub render_shift: Vec3A,
}

/// The most triangles a scene may hold: 2^27, about 12 GiB at the ~92 bytes
/// a built scene takes per triangle (docs/performance.md), so that a scene
/// of a few lines (many subdivided spheres, a glTF mesh instanced many
/// times) gets an error, not an allocation failure.
pub const MAX_TRIANGLES: usize = 1 << 27;

/// Whether a scene of `n` triangles is within `MAX_TRIANGLES`.
pub fn check_triangle_count(n: usize) -> Result<(), String> {
    match n > MAX_TRIANGLES {
        true => Err(format!("the scene would hold {n} triangles, more than the {MAX_TRIANGLES} (2^27) prism builds")),
        false => Ok(()),
    }
}

/// The largest radiance an emitter may give at any wavelength (an area
/// light, the environment): a camera ray that meets an emitter carries its
/// radiance to the film, whose colour conversion multiplies a spectrum's
/// largest value by up to 7.64 (one hero wavelength after dispersive glass,
/// where the wavelength density is low; four wavelengths give less:
/// `colour_gain_is_below_eight`), and the film refuses sample colours past
/// `film::MAX_SAMPLE` (2^48) as infinite. So 2^48 / 8: an emitter that a
/// camera ray meets is never dropped. An audit found 2^48 itself too loose
/// (a lamp of 2e14 in view lost 15 % of the samples; at 1e20 every
/// estimator's image of a lit room was black).
pub const MAX_RADIANCE: f32 = crate::film::MAX_SAMPLE / 8.0;

/// The dimmest brightest radiance a scene without point lights is rendered
/// without a warning (`Scene::dim_emission`): 2^-36, so that a sample
/// carrying 1e-3 of it still exceeds the film's resolution, 2^-60, by 2^14.
pub const MIN_EMISSION: f32 = 1.0 / (1u64 << 36) as f32;

/// Whether emitted radiance `s` is within `MAX_RADIANCE`.
pub fn check_radiance(s: &Spectrum) -> Result<(), String> {
    match s.max_value() > MAX_RADIANCE {
        true => Err(format!(
            "must be at most {MAX_RADIANCE:e} (2^45): the film takes one sample's colour up to 2^48, and a colour reaches 7.6 times the spectrum's largest value (max {:e})",
            s.max_value()
        )),
        false => Ok(()),
    }
}

/// The largest intensity a point light may give at any wavelength: a light
/// path leaves it with 4 pi I over its selection probability in its
/// throughput, which at 1e38 passed f32, and light tracing lost every path
/// without a word (an audit, session 43); 2^100 leaves that product 2^24
/// of room below f32::MAX. The film's bound does not apply: what a point
/// light brings to a pixel falls with the square of the distance, which
/// the scene's scale sets (a sun 1e6 units away wants ~1e15).
pub const MAX_INTENSITY: f32 = (1u128 << 100) as f32;

/// Whether a point light's intensity `s` is within `MAX_INTENSITY`.
pub fn check_intensity(s: &Spectrum) -> Result<(), String> {
    match s.max_value() > MAX_INTENSITY {
        true => Err(format!(
            "must be at most {MAX_INTENSITY:e} (2^100): a light path leaves a point light with 4 pi times it in its throughput, which must stay within f32 (max {:e})",
            s.max_value()
        )),
        false => Ok(()),
    }
}

/// A mesh with its material, its emission (radiance, two-sided) if any, and
/// its name.
type MeshEntry = (Mesh, u32, Option<(Spectrum, bool)>, String);

/// Assembles a scene from meshes, materials and lights (used by the JSON
/// loader and by tests that build scenes in code).
pub struct SceneBuilder {
    camera: Camera,
    materials: Vec<Material>,
    meshes: Vec<MeshEntry>,
    /// Triangles in `meshes`.
    triangles: usize,
    lights: Vec<(Light, String)>,
    pub defaults: RenderDefaults,
    /// The scene file's top-level `comment` (converge's report quotes it).
    pub comment: Option<String>,
    /// The files the loaders read or name beside the scene file: meshes,
    /// included glTF files, their buffers and images. A command's outputs
    /// may not replace them (`--png albedo.png` overwrote a texture; an
    /// audit, session 49).
    pub inputs: Vec<PathBuf>,
}

impl SceneBuilder {
    pub fn new(camera: Camera) -> Self {
        Self {
            camera,
            materials: Vec::new(),
            meshes: Vec::new(),
            triangles: 0,
            lights: Vec::new(),
            defaults: RenderDefaults::default(),
            comment: None,
            inputs: Vec::new(),
        }
    }

    /// Adds a material; returns its index.
    pub fn material(&mut self, name: &str, bsdf: Bsdf) -> u32 {
        self.materials.push(Material::new(name, bsdf));
        (self.materials.len() - 1) as u32
    }

    /// Adds a mesh with a material and optional emission (radiance, two-sided).
    pub fn mesh(&mut self, name: &str, mesh: Mesh, material: u32, emission: Option<(Spectrum, bool)>) -> &mut Self {
        self.triangles += mesh.len();
        self.meshes.push((mesh, material, emission, name.to_string()));
        self
    }

    /// Triangles added so far.
    pub fn triangle_count(&self) -> usize {
        self.triangles
    }

    /// Changes the image resolution (the vertical field of view is kept),
    /// unless the film would not fit or the image would have no area (a
    /// tiny field of view squeezed by the aspect ratio).
    pub fn set_resolution(&mut self, width: u32, height: u32) -> Result<(), String> {
        Camera::check_resolution(width, height)?;
        let camera = self.camera.with_resolution(width, height);
        if !camera.has_image_area() {
            let why = "the image has no area at this aspect ratio (the field of view is too small)";
            return Err(format!("{width} x {height}: {why}"));
        }
        self.camera = camera;
        Ok(())
    }

    /// The image's width and height, as the scene or `set_resolution` set
    /// them.
    pub fn resolution(&self) -> (u32, u32) {
        (self.camera.width, self.camera.height)
    }

    pub fn point_light(&mut self, name: &str, p: Vec3A, intensity: Spectrum) -> &mut Self {
        self.lights.push((Light::Point(PointLight { p, intensity }), name.to_string()));
        self
    }

    pub fn environment(&mut self, name: &str, le: Spectrum) -> &mut Self {
        let env = EnvironmentLight { le, center: Vec3A::ZERO, radius: 1.0 };
        self.lights.push((Light::Environment(env), name.to_string()));
        self
    }

    /// Moves the geometry, the point lights and the camera by the exact
    /// shift of `render_space::origin_shift`, which it returns.
    fn move_to_render_space(&mut self) -> Vec3A {
        let (lo, hi) = self
            .meshes
            .iter()
            .flat_map(|(mesh, ..)| &mesh.positions)
            .fold((Vec3A::INFINITY, Vec3A::NEG_INFINITY), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        let shift = render_space::origin_shift(lo, hi);
        if shift == Vec3A::ZERO {
            return shift;
        }
        for p in self.meshes.iter_mut().flat_map(|(mesh, ..)| &mut mesh.positions) {
            *p -= shift;
        }
        for (light, _) in &mut self.lights {
            if let Light::Point(l) = light {
                l.p = render_space::shifted(l.p, shift);
            }
        }
        self.camera.position = render_space::shifted(self.camera.position, shift);
        shift
    }

    /// The scene, in render space (`render_space`: moved near the origin,
    /// exactly, if it lies far from it; its positions are then not the
    /// file's).
    pub fn build(mut self) -> Scene {
        // Counted where the file put them: render space moves them exactly,
        // so their rounding is the file's.
        let unresolved =
            self.meshes.iter().flat_map(|(mesh, ..)| mesh.triangles()).filter(below_position_resolution).count();
        let render_shift = self.move_to_render_space();
        let mut lights = Vec::new();
        let mut light_names = Vec::new();
        let mut records = Vec::with_capacity(self.meshes.len());
        let mut start = 0u32;
        for (mesh, material, emission, name) in &self.meshes {
            let mesh_lights = match emission {
                Some(e) => area_lights(mesh, e, start, name, &mut lights, &mut light_names),
                None => Vec::new(),
            };
            records.push(MeshRecord { start, material: *material, lights: mesh_lights, shading: None });
            start =
                u32::try_from(mesh.len()).ok().and_then(|n| start.checked_add(n)).expect("at most 2^32 - 2 triangles");
        }
        let vertices = |i: usize| {
            let m = mesh_index(&records, i as u32);
            let mesh = &self.meshes[m].0;
            mesh.indices[i - records[m].start as usize].map(|j| mesh.positions[j as usize])
        };
        let accel = Accel::build_with(start as usize, vertices);
        let slot_mesh = (records.len() <= 1 << 16)
            .then(|| accel.slot_prims().iter().map(|&p| mesh_index(&records, p) as u16).collect());
        assign_light_slots(&mut lights, &accel);
        let degenerate: Vec<(u32, [Vec3A; 3])> =
            accel.degenerate().iter().map(|&i| (i, vertices(i as usize))).collect();
        let too_small = (0..start as usize).filter(|&i| too_small_for_f32(&vertices(i))).count();
        // Positions now live in the BVH; keep indices and normals of the
        // meshes that have normals, drop the rest.
        for (record, (mesh, ..)) in records.iter_mut().zip(self.meshes) {
            if !mesh.normals.is_empty() {
                record.shading = Some((mesh.indices, mesh.normals));
            }
        }
        let (center, radius) = bounding_sphere(&accel, self.camera.position);
        let mut environment = None;
        for (mut light, name) in self.lights {
            if let Light::Environment(e) = &mut light {
                e.center = center;
                e.radius = radius;
                environment = Some(lights.len() as u32);
            }
            lights.push(light);
            light_names.push(name);
        }
        let powers: Vec<f64> = lights.iter().map(Light::power).collect();
        let light_sampler = AliasTable::new(&powers);
        Scene {
            camera: self.camera,
            accel,
            meshes: records,
            slot_mesh,
            degenerate,
            too_small,
            unresolved,
            materials: self.materials,
            lights,
            light_names,
            light_sampler,
            environment,
            center,
            radius,
            defaults: self.defaults,
            render_shift,
        }
    }
}

/// Gives each area light its triangle's BVH slot.
fn assign_light_slots(lights: &mut [Light], accel: &Accel) {
    fn area(l: &mut Light) -> Option<&mut AreaLight> {
        match l {
            Light::Area(a) => Some(a),
            _ => None,
        }
    }
    let prims: Vec<u32> = lights.iter_mut().filter_map(area).map(|a| a.prim).collect();
    for (a, slot) in lights.iter_mut().filter_map(area).zip(accel.slots_of(&prims)) {
        a.slot = slot;
    }
}

/// Centre and radius of a sphere around the geometry and the camera (the
/// environment's disk of light-path origins; a radius of at least 1e-3).
fn bounding_sphere(accel: &Accel, camera: Vec3A) -> (Vec3A, f32) {
    let (lo, hi) = accel.bounds();
    let (lo, hi) = (lo.min(camera), hi.max(camera));
    ((lo + hi) * 0.5, ((hi - lo).length() * 0.5).max(1e-3))
}

/// One area light per triangle of the emitting `mesh` (its first triangle
/// is primitive `start`), appended to `lights` and `names`; returns each
/// triangle's light index, `NO_LIGHT` for a triangle that cannot emit.
fn area_lights(
    mesh: &Mesh,
    (le, two_sided): &(Spectrum, bool),
    start: u32,
    name: &str,
    lights: &mut Vec<Light>,
    names: &mut Vec<String>,
) -> Vec<u32> {
    let mut mesh_lights = Vec::with_capacity(mesh.len());
    for (k, idx) in mesh.indices.iter().enumerate() {
        let v = idx.map(|i| mesh.positions[i as usize]);
        let (ng, area) = normal_and_area(&v);
        let mut light = NO_LIGHT;
        // Not a triangle the BVH leaves out as degenerate: f32's cross
        // product of an exactly collinear one need not be 0, and a light no
        // ray can hit would make next-event estimation and light tracing see
        // more than path tracing's hits.
        if area > 0.0 && area.is_finite() && !crate::accel::is_degenerate(&v) {
            light = lights.len() as u32;
            lights.push(Light::Area(AreaLight {
                v,
                n: ng,
                area,
                le: le.clone(),
                two_sided: *two_sided,
                prim: start + k as u32,
                slot: NO_TRIANGLE,
                margin: edge_margin(&v),
            }));
            names.push(format!("{name} (triangle {k})"));
        }
        mesh_lights.push(light);
    }
    mesh_lights
}

impl Scene {
    /// Closest surface hit along the ray. Always inlined, traversal and
    /// all, as the profile-guided build chose (docs/performance-log.md,
    /// "Session 16").
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray) -> Option<SurfaceInteraction> {
        count_rays(1);
        let hit = self.accel.intersect(ray, f32::INFINITY)?;
        self.interaction(ray, &hit)
    }

    /// `intersect` for the first `n` rays of a packet, traced together
    /// (`Accel::intersect8`): for rays that start close together towards
    /// close directions, such as a pixel's camera rays. Calls `each` with
    /// every lane's index and hit in lane order, so that no array of
    /// interactions (~1 KiB) is built and copied.
    #[inline(always)]
    pub fn intersect8(&self, rays: &[Ray; LANES], n: usize, mut each: impl FnMut(usize, Option<SurfaceInteraction>)) {
        let n = n.min(LANES);
        count_rays(n as u32);
        let hits = self.accel.intersect8(rays, [f32::INFINITY; LANES], (1 << n) - 1);
        for (l, (ray, hit)) in rays.iter().zip(&hits).take(n).enumerate() {
            each(l, hit.as_ref().and_then(|hit| self.interaction(ray, hit)));
        }
    }

    /// The surface interaction of a ray's hit, None if traced again in
    /// f64 it misses (`hit_by_an_edge`).
    #[inline(always)]
    fn interaction(&self, ray: &Ray, hit: &TriangleHit) -> Option<SurfaceInteraction> {
        let b = [1.0 - hit.b1 - hit.b2, hit.b1, hit.b2];
        let by_an_edge = near_edges(b, hit.margin.max(hit.edge_error));
        let (hit, b) = if by_an_edge { self.hit_by_an_edge(ray)? } else { (*hit, b) };
        Some(self.interaction_at(ray, &hit, b))
    }

    /// A hit the f32 test may be wrong about (a barycentric within
    /// `TriangleHit::edge_error` of 0: the ray passes that close to an
    /// edge, where the test can find both faces of a convex edge the ray
    /// passes, or first the one it would leave by), or within its
    /// triangle's margin of an edge (`triangle_point`): traced again in f64
    /// (`Accel::intersect_exact`), with the point kept off the edges.
    /// (Every ray `interaction` serves was traced to infinity.)
    #[cold]
    #[inline(never)]
    fn hit_by_an_edge(&self, ray: &Ray) -> Option<(TriangleHit, [f32; 3])> {
        let hit = self.accel.intersect_exact(ray, f32::INFINITY)?;
        Some((hit, kept_off_edges(&hit.v, [1.0 - hit.b1 - hit.b2, hit.b1, hit.b2], hit.margin)))
    }

    /// The surface interaction at barycentrics `b` of a ray's hit.
    #[inline(always)]
    fn interaction_at(&self, ray: &Ray, hit: &TriangleHit, b: [f32; 3]) -> SurfaceInteraction {
        let v = hit.v;
        let m = &self.meshes[self.mesh_of(hit.slot, hit.prim)];
        let k = (hit.prim - m.start) as usize;
        let (p, p_error) = (v[0] * b[0] + v[1] * b[1] + v[2] * b[2], barycentric_error(&v, b[0], b[1], b[2]));
        // What `normal_and_area` gives a triangle the BVH holds (non-zero,
        // finite area), without the area.
        let ng = (v[1] - v[0]).cross(v[2] - v[0]).normalize();
        let ns = match &m.shading {
            Some((indices, normals)) => {
                let n = indices[k].map(|i| normals[i as usize]);
                shading_normal(n[0] * b[0] + n[1] * b[1] + n[2] * b[2], ng)
            }
            None => ng,
        };
        SurfaceInteraction {
            p,
            p_error,
            t: hit.t,
            ng,
            frame: Frame::from_normal(ns),
            wo: -ray.d,
            material: m.material,
            light: m.lights.get(k).copied().filter(|&l| l != NO_LIGHT),
            slot: hit.slot,
        }
    }

    /// The index in `meshes` of the mesh holding triangle `prim`, which is
    /// in BVH slot `slot`.
    #[inline]
    fn mesh_of(&self, slot: u32, prim: u32) -> usize {
        match &self.slot_mesh {
            Some(by_slot) => by_slot[slot as usize] as usize,
            None => mesh_index(&self.meshes, prim),
        }
    }

    /// Whether the segment between two points is unobstructed; each end is
    /// offset off its own surface (`Shadow::segment`).
    /// Always inlined, so that its callers pass no `SurfacePoint` through
    /// memory; the traversal itself (`Accel::occluded`) stays out of line.
    #[inline(always)]
    pub fn unoccluded(&self, a: SurfacePoint, b: SurfacePoint) -> bool {
        self.visible(&Shadow::segment(a, b))
    }

    /// Whether nothing blocks a shadow ray (a segment whose ends' sides
    /// rounding decides is blocked, and not traced: `Shadow::segment`).
    #[inline(always)]
    pub fn visible(&self, shadow: &Shadow) -> bool {
        if !shadow.ends_resolved {
            return false;
        }
        count_rays(1);
        !self.accel.occluded(&shadow.ray, shadow.t_max)
    }

    #[inline]
    pub fn bsdf(&self, si: &SurfaceInteraction) -> &Bsdf {
        &self.materials[si.material as usize].bsdf
    }

    /// The material at a hit; a dispersive one makes the path keep only its
    /// hero wavelength from here on (pbrt-v4: at material evaluation, so the
    /// decision does not depend on which lobe is then sampled).
    #[inline]
    pub fn material_at(&self, si: &SurfaceInteraction, lambda: &mut SampledWavelengths) -> &Material {
        let m = &self.materials[si.material as usize];
        if m.dispersive {
            lambda.terminate_secondary();
        }
        m
    }

    /// Choose a light proportionally to power: (index, probability).
    #[inline]
    pub fn sample_light(&self, bits: u64) -> Option<(u32, f32)> {
        let (i, pmf) = self.light_sampler.as_ref()?.sample(bits);
        Some((i as u32, pmf))
    }

    /// Probability that `sample_light` picks light `i`.
    #[inline]
    pub fn light_pmf(&self, i: u32) -> f32 {
        self.light_sampler.as_ref().map_or(0.0, |t| t.pmf(i as usize))
    }

    #[inline]
    pub fn environment(&self) -> Option<(u32, &Light)> {
        self.environment.map(|i| (i, &self.lights[i as usize]))
    }

    pub fn triangle_count(&self) -> usize {
        self.accel.len()
    }

    /// The warnings `render` and `converge` print about the scene itself,
    /// whatever the estimator: geometry that rounding decides, emission the
    /// film cannot resolve.
    pub fn geometry_warnings(&self) -> Vec<String> {
        [
            self.too_small_triangles(),
            self.unresolved_triangles(),
            self.emitters_on_surfaces(),
            self.point_lights_on_surfaces(),
            self.dim_emission(),
            self.no_emission(),
            self.no_surfaces(),
        ]
        .into_iter()
        .flatten()
        .collect()
    }

    /// A warning if nothing emits at the wavelengths rendered (no light, or
    /// every light of zero power, which `light_sampler` cannot choose from):
    /// every estimator renders black. A JSON scene gets no default light
    /// (docs/scene-format.md); a scene without one rendered black with no
    /// word of why (an audit, session 49).
    pub fn no_emission(&self) -> Option<String> {
        self.light_sampler.is_none().then(|| {
            "nothing in the scene emits light (no light or emitter, or every one of zero power): the image is black"
                .to_string()
        })
    }

    /// A warning if no triangle has area (no object, or every triangle
    /// degenerate, as under a glTF node scaled by 0): nothing but an
    /// environment can reach the camera. Such scenes
    /// rendered black without a word (a review, session 53).
    pub fn no_surfaces(&self) -> Option<String> {
        (self.accel.len() == self.accel.degenerate().len()).then(|| {
            "no surface in the scene has area (no object, or every triangle degenerate): the image shows at most the \
             environment"
                .to_string()
        })
    }

    /// A warning if the scene's brightest emitter (its radiance at its
    /// brightest wavelength) is below `MIN_EMISSION` but not black: the film
    /// truncates every sample to its resolution of 2^-60 (`film::to_fixed`),
    /// which such a scene's samples approach (an audit: at emission 1e-16
    /// the image read 7 % dark, at 1e-18 black). Not for a scene with point
    /// lights, whose intensity is no radiance: what one brings to a pixel
    /// depends on the scene's scale.
    pub fn dim_emission(&self) -> Option<String> {
        if self.lights.iter().any(Light::is_delta_position) {
            return None;
        }
        let brightest = self.lights.iter().map(Light::max_emitted).fold(0.0, f32::max);
        (brightest > 0.0 && brightest < MIN_EMISSION).then(|| {
            format!(
                "the brightest emitter gives at most {brightest:e}, below {MIN_EMISSION:e} (2^-36): the film resolves \
                 2^-60 per sample and truncates what is finer, so the image reads dark or black (scale the emission up)"
            )
        })
    }

    /// A warning if triangles are too small for f32 (`too_small_for_f32`):
    /// a scene modelled at 1e-11 units read 12 % bright (its emitter's
    /// area), and at 1e-12 black (every triangle left the BVH).
    pub fn too_small_triangles(&self) -> Option<String> {
        let n = self.too_small;
        (n > 0).then(|| {
            format!(
                "{n} triangle(s) are too small or too thin for f32 arithmetic: their normals and areas lose \
                 precision or vanish (a scene modelled at ~1e-10 units or less needs scaling up)"
            )
        })
    }

    /// A warning if triangles are finer than f32 resolves where they lie
    /// (`below_position_resolution`).
    pub fn unresolved_triangles(&self) -> Option<String> {
        let n = self.unresolved;
        (n > 0).then(|| {
            format!(
                "{n} triangle(s) are finer than f32 resolves where they lie (edges under 2^-20 of their coordinates): \
                 unless their coordinates are exact in f32, rounding changed their shape and normals (model them nearer \
                 the origin, or larger)"
            )
        })
    }

    /// The materials some triangle of the scene has, each once, in the
    /// order of `materials`; a material that only the scene file defines
    /// is not among them.
    pub fn materials_in_use(&self) -> impl Iterator<Item = &Material> + '_ {
        let ends = self.meshes.iter().skip(1).map(|m| m.start).chain([self.triangle_count() as u32]);
        let mut used = vec![false; self.materials.len()];
        for (m, end) in self.meshes.iter().zip(ends) {
            used[m.material as usize] |= end > m.start;
        }
        self.materials.iter().zip(used).filter_map(|(m, used)| used.then_some(m))
    }

    /// The triangles as built, in input order (scene exporters): vertices
    /// in winding order, per-vertex shading normals, material, area light.
    /// Makes the input -> BVH slot map (4 bytes per triangle) for the
    /// iteration.
    pub fn triangles(&self) -> impl Iterator<Item = ([Vec3A; 3], Option<[Vec3A; 3]>, u32, Option<u32>)> + '_ {
        let slots = self.accel.slot_map();
        (0..self.triangle_count()).map(move |i| {
            let prim = i as u32;
            let v = match slots[i] {
                NO_TRIANGLE => {
                    let d = self.degenerate.binary_search_by_key(&prim, |d| d.0).expect("a degenerate triangle");
                    self.degenerate[d].1
                }
                s => self.accel.vertices(s),
            };
            let m = &self.meshes[mesh_index(&self.meshes, prim)];
            let k = i - m.start as usize;
            let ns = m.shading.as_ref().map(|(indices, normals)| indices[k].map(|j| normals[j as usize]));
            (v, ns, m.material, m.lights.get(k).copied().filter(|&l| l != NO_LIGHT))
        })
    }

    /// Heap bytes of the geometry (BVH, triangles, shading data), for
    /// memory reports.
    pub fn geometry_bytes(&self) -> usize {
        let shading: usize = self
            .meshes
            .iter()
            .map(|m| {
                m.lights.capacity() * 4 + m.shading.as_ref().map_or(0, |(i, n)| i.capacity() * 12 + n.capacity() * 16)
            })
            .sum();
        self.accel.heap_bytes()
            + self.slot_mesh.as_ref().map_or(0, |m| m.capacity() * 2)
            + self.meshes.capacity() * std::mem::size_of::<MeshRecord>()
            + self.degenerate.capacity() * std::mem::size_of::<(u32, [Vec3A; 3])>()
            + shading
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::materials::Diffuse;

    /// `MAX_RADIANCE`'s margin: over a fine grid of hero wavelengths, a
    /// spectrum of 1 becomes a film colour of at most 8 in any channel, with
    /// four wavelengths and with the hero alone (after dispersive glass), so
    /// a directly seen emitter within `MAX_RADIANCE` stays within the film's
    /// `MAX_SAMPLE`. The hero alone reaches 7.6 (the margin is not idle).
    #[test]
    fn colour_gain_is_below_eight() {
        use crate::spectrum::{SampledCmf, SampledSpectrum, SampledWavelengths};
        let gain = |l: &SampledWavelengths| SampledCmf::linear_srgb(l).apply(SampledSpectrum::ONE).abs().max_element();
        let (mut four, mut hero) = (0f32, 0f32);
        for k in 0..200_000 {
            let mut l = SampledWavelengths::sample_visible((k as f32 + 0.5) / 200_000.0);
            four = four.max(gain(&l));
            l.terminate_secondary();
            hero = hero.max(gain(&l));
        }
        assert!(four <= 8.0 && hero <= 8.0, "colour gain {four} (four wavelengths), {hero} (hero alone)");
        assert!(hero > 7.0, "hero alone {hero}");
        assert_eq!(MAX_RADIANCE * 8.0, crate::film::MAX_SAMPLE);
    }

    /// A light bright enough (4e36 W/sr) that its luminance summed in f32
    /// overflows is still sampled, in proportion to its power, beside a
    /// normal one: an infinite power emptied the light sampler, and every
    /// estimator rendered black.
    #[test]
    fn lights_near_the_top_of_f32_are_still_sampled() {
        // In either order, so that a table that falls to its last entry
        // cannot pass (a review, session 55), and with the pmfs: the
        // lamp's is its share of the power, 1 / 4e36.
        for star_first in [false, true] {
            let camera = Camera::new(Vec3A::new(0.0, 0.0, -5.0), Vec3A::ZERO, Vec3A::Y, 40.0, 8, 8);
            let mut b = SceneBuilder::new(camera);
            let lights = [("lamp", Vec3A::Y, 1.0), ("star", Vec3A::X, 4e36)];
            for (name, p, intensity) in if star_first { [lights[1], lights[0]] } else { lights } {
                b.point_light(name, p, Spectrum::Constant(intensity));
            }
            let scene = b.build();
            assert!(scene.lights.iter().all(|l| l.power().is_finite()));
            let (star, lamp) = if star_first { (0, 1) } else { (1, 0) };
            // (Bits whose alias coin is not exactly 0: a coin of 0 takes
            // even a bin of threshold 2.5e-37, a probability of 2^-64.)
            for u in [(1u64 << 60) | 0x5555, 0x9000_0000_0000_1234, (15 << 60) | 0x777] {
                let (i, pmf) = scene.sample_light(u).expect("no light sampling");
                assert_eq!((i, pmf), (star, 1.0), "star first: {star_first}: the brighter light is chosen");
            }
            let lamp_pmf = scene.light_pmf(lamp);
            assert!((lamp_pmf / 2.5e-37 - 1.0).abs() < 1e-3, "star first: {star_first}: the lamp's pmf {lamp_pmf}");
        }
    }

    /// A scene whose brightest emitter is below 2^-36 is warned of, one at
    /// or above it is not, nor a scene with a point light (its intensity
    /// says nothing of a pixel's value without the scene's scale) or none.
    #[test]
    fn emission_below_the_film_is_warned_of() {
        let warns = |lights: &[(f32, bool)]| {
            let camera = Camera::new(Vec3A::new(0.0, 0.0, -5.0), Vec3A::ZERO, Vec3A::Y, 40.0, 8, 8);
            let mut b = SceneBuilder::new(camera);
            for &(value, point) in lights {
                match point {
                    true => b.point_light("lamp", Vec3A::Y, Spectrum::Constant(value)),
                    false => b.environment("sky", Spectrum::Constant(value)),
                };
            }
            b.build().dim_emission().is_some()
        };
        assert!(warns(&[(1e-17, false)]));
        assert!(warns(&[(MIN_EMISSION * 0.99, false)]));
        assert!(!warns(&[(MIN_EMISSION, false)]));
        assert!(!warns(&[(1e-17, true)]));
        assert!(!warns(&[(1e-17, false), (1e-17, true)]));
        assert!(!warns(&[(0.0, false)]));
        assert!(!warns(&[]));
    }

    /// A scene without a light, or whose lights all have zero power, is
    /// warned of as black; one with a light of any power is not.
    #[test]
    fn a_scene_that_emits_nothing_is_warned_of() {
        let warns = |lights: &[f32]| {
            let camera = Camera::new(Vec3A::new(0.0, 0.0, -5.0), Vec3A::ZERO, Vec3A::Y, 40.0, 8, 8);
            let mut b = SceneBuilder::new(camera);
            let grey = b.material("grey", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.5))));
            let quad = [Vec3A::ZERO, Vec3A::X, Vec3A::X + Vec3A::Y, Vec3A::Y];
            for &value in lights {
                b.mesh("lamp", Mesh::quad(quad), grey, Some((Spectrum::Constant(value), false)));
            }
            b.build().no_emission().is_some()
        };
        assert!(warns(&[]));
        assert!(warns(&[0.0]));
        assert!(warns(&[0.0, 0.0]));
        assert!(!warns(&[1e-30]));
        assert!(!warns(&[0.0, 1.0]));
    }

    /// A scene without a triangle of area is warned of: none at all, or
    /// only a degenerate one; one triangle with area is not.
    #[test]
    fn a_scene_without_surfaces_is_warned_of() {
        let warns = |positions: Vec<Vec3A>| {
            let camera = Camera::new(Vec3A::new(0.0, 0.0, -5.0), Vec3A::ZERO, Vec3A::Y, 40.0, 8, 8);
            let mut b = SceneBuilder::new(camera);
            if !positions.is_empty() {
                let grey = b.material("grey", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.5))));
                b.mesh("m", Mesh { positions, normals: Vec::new(), indices: vec![[0, 1, 2]] }, grey, None);
            }
            b.build().no_surfaces().is_some()
        };
        assert!(warns(Vec::new()));
        assert!(warns(vec![Vec3A::ZERO, Vec3A::X, 2.0 * Vec3A::X]));
        assert!(!warns(vec![Vec3A::ZERO, Vec3A::X, Vec3A::Y]));
    }

    /// Triangles whose normals f32 cannot hold are counted and warned of:
    /// a unit quad at 1e-11 units (its cross product's squared length,
    /// 1e-44, is subnormal) and at 1e-12 (0), not at 1e-9, nor a triangle
    /// without area.
    #[test]
    fn triangles_too_small_for_f32_are_warned_of() {
        let warning = |scale: f32| {
            let camera = Camera::new(Vec3A::new(0.0, 0.0, -5.0), Vec3A::ZERO, Vec3A::Y, 40.0, 8, 8);
            let mut b = SceneBuilder::new(camera);
            let grey = b.material("grey", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.5))));
            let quad = [Vec3A::ZERO, Vec3A::X, Vec3A::X + Vec3A::Y, Vec3A::Y].map(|p| p * scale);
            b.mesh("quad", Mesh::quad(quad), grey, None);
            let flat = Mesh {
                positions: vec![Vec3A::ZERO, Vec3A::X, Vec3A::X * 2.0],
                normals: Vec::new(),
                indices: vec![[0, 1, 2]],
            };
            b.mesh("no area", flat, grey, None);
            b.build().too_small_triangles()
        };
        for scale in [1e-11, 1e-12] {
            let w = warning(scale).unwrap_or_default();
            assert!(w.starts_with("2 triangle(s) are too small or too thin for f32"), "{scale}: {w}");
        }
        assert_eq!(warning(1e-9), None);
    }

    /// Triangles finer than f32 resolves where they lie are counted and
    /// warned of: an icosphere of radius 1e-7 at x = 0.25 (edges of about
    /// 8e-9, under one unit in the last place of 0.25), not the same sphere
    /// at the origin, nor one of radius 1e-5 at x = 0.25 (edges of ~27
    /// units in the last place). The count is the file's: render space
    /// moves the lone sphere to the origin, exactly.
    #[test]
    fn triangles_finer_than_their_position_are_warned_of() {
        let warning = |center: Vec3A, radius: f32| {
            let camera = Camera::new(center - Vec3A::Z * 5.0 * radius, center, Vec3A::Y, 40.0, 8, 8);
            let mut b = SceneBuilder::new(camera);
            let grey = b.material("grey", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.5))));
            b.mesh("ball", Mesh::sphere(center, radius, 3, false), grey, None);
            b.build().unresolved_triangles()
        };
        let far = Vec3A::new(0.25, 0.0, 0.0);
        let w = warning(far, 1e-7).unwrap_or_default();
        assert!(w.starts_with("1280 triangle(s) are finer than f32 resolves where they lie"), "{w}");
        assert_eq!(warning(Vec3A::ZERO, 1e-7), None);
        assert_eq!(warning(far, 1e-5), None);
    }

    /// Meshes of every kind (flat, smooth, emissive, empty, with a
    /// degenerate triangle): `triangles` gives back what went in, and the
    /// geometry (BVH included) stays within the memory budget of issue 10.
    #[test]
    fn triangles_round_trip_and_geometry_is_compact() {
        let camera = Camera::new(Vec3A::new(0.0, 0.0, -5.0), Vec3A::ZERO, Vec3A::Y, 40.0, 8, 8);
        let mut b = SceneBuilder::new(camera);
        let grey = b.material("grey", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.5))));
        let white = b.material("white", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.8))));
        let quad = [Vec3A::new(-2., -1., 2.), Vec3A::new(2., -1., 2.), Vec3A::new(2., 1., 2.), Vec3A::new(-2., 1., 2.)];
        let p = Vec3A::new(0.5, 0.5, 0.5);
        let degenerate = Mesh { positions: vec![p, p, Vec3A::ONE], normals: Vec::new(), indices: vec![[0, 1, 2]] };
        let meshes = [
            (Mesh::default(), grey, None),
            (Mesh::sphere(Vec3A::ZERO, 1.0, 6, false), grey, None),
            (Mesh::default(), white, None),
            (Mesh::sphere(Vec3A::X * 3.0, 0.5, 1, true), white, None),
            (degenerate, grey, Some((Spectrum::Constant(1.0), false))),
            (Mesh::quad(quad), white, Some((Spectrum::Constant(1.0), false))),
        ];
        let mut want = Vec::new();
        for (k, (mesh, material, emission)) in meshes.iter().enumerate() {
            for (t, idx) in mesh.indices.iter().enumerate() {
                let ns = (!mesh.normals.is_empty()).then(|| idx.map(|i| mesh.normals[i as usize]));
                want.push((idx.map(|i| mesh.positions[i as usize]), ns, *material, emission.is_some() && k == 5, t));
            }
            b.mesh(&format!("mesh {k}"), mesh.clone(), *material, emission.clone());
        }
        let scene = b.build();
        assert_eq!(scene.triangle_count(), want.len());
        assert_eq!(scene.lights.len(), 2);
        assert_eq!(scene.triangles().count(), want.len());
        for (i, ((v, ns, material, emits, t), got)) in want.iter().zip(scene.triangles()).enumerate() {
            assert_eq!((got.0, got.1, got.2), (*v, *ns, *material), "triangle {i}");
            assert_eq!(got.3, emits.then_some(*t as u32), "triangle {i}");
        }
        let per_triangle = scene.geometry_bytes() as f64 / scene.triangle_count() as f64;
        assert!(per_triangle < 64.0, "{per_triangle} bytes per triangle");
        // A ray down onto the quad hits it with its material and light.
        let si = scene.intersect(&Ray::new(Vec3A::new(1.5, 0.5, -1.0), Vec3A::Z)).expect("hit");
        assert_eq!((si.material, si.light), (white, Some(0)));
        assert_eq!(si.ng, Vec3A::Z);
    }

    /// An emissive triangle whose corners are exactly collinear (in f64)
    /// but whose f32 cross product is not 0 (an audit, session 36: area
    /// ~1) is no light, as the BVH leaves it out; its neighbour is one.
    #[test]
    fn collinear_emitters_are_no_lights() {
        let collinear = [
            Vec3A::new(0.006_062_507_6, 0.018_187_523, 0.0),
            Vec3A::new(1947.0, 5841.0, 0.0),
            Vec3A::new(3894.0, 11682.0, 0.0),
        ];
        assert!(normal_and_area(&collinear).1 > 0.5, "premise: f32 gives the collinear triangle an area");
        assert!(crate::accel::is_degenerate(&collinear), "premise: the BVH leaves it out");
        let camera = Camera::new(Vec3A::new(0.0, 0.0, -5.0), Vec3A::ZERO, Vec3A::Y, 40.0, 8, 8);
        let mut b = SceneBuilder::new(camera);
        let grey = b.material("grey", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.5))));
        let mut positions = collinear.to_vec();
        positions.extend([Vec3A::ZERO, Vec3A::X, Vec3A::Y]);
        let mesh = Mesh { positions, normals: Vec::new(), indices: vec![[0, 1, 2], [3, 4, 5]] };
        b.mesh("lamp", mesh, grey, Some((Spectrum::Constant(1.0), false)));
        let scene = b.build();
        assert_eq!(scene.lights.len(), 1, "{:?}", scene.light_names);
    }

    /// A hit's mesh from the per-slot table is the one the search over
    /// the mesh starts finds (the path of scenes with more than 2^16
    /// meshes): same material, same area light, for every triangle of a
    /// scene of many small meshes.
    #[test]
    fn slot_mesh_table_agrees_with_the_search() {
        let camera = Camera::new(Vec3A::new(0.0, 0.0, -5.0), Vec3A::ZERO, Vec3A::Y, 40.0, 8, 8);
        let mut b = SceneBuilder::new(camera);
        let materials: Vec<u32> = (0..3)
            .map(|k| {
                b.material(&format!("m{k}"), Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.2 + 0.2 * k as f32))))
            })
            .collect();
        for k in 0..300 {
            let (x, y) = ((k % 20) as f32, (k / 20) as f32);
            let quad = [
                Vec3A::new(x, y, 0.0),
                Vec3A::new(x + 0.9, y, 0.0),
                Vec3A::new(x + 0.9, y + 0.9, 0.0),
                Vec3A::new(x, y + 0.9, 0.0),
            ];
            let emission = (k % 7 == 0).then_some((Spectrum::Constant(1.0), false));
            b.mesh(&format!("quad {k}"), Mesh::quad(quad), materials[k % 3], emission);
        }
        let mut scene = b.build();
        let hits = |scene: &Scene| -> Vec<(u32, Option<u32>)> {
            (0..300 * 2)
                .map(|i| {
                    let (k, half) = (i / 2, i % 2);
                    let (x, y) = ((k % 20) as f32, (k / 20) as f32);
                    let o = Vec3A::new(x + 0.3 + 0.3 * half as f32, y + 0.6 - 0.3 * half as f32, -1.0);
                    let si = scene.intersect(&Ray::new(o, Vec3A::Z)).expect("hit");
                    (si.material, si.light)
                })
                .collect()
        };
        assert!(scene.slot_mesh.is_some());
        let by_table = hits(&scene);
        assert_eq!(by_table.iter().filter(|h| h.1.is_some()).count(), 2 * 43);
        assert_eq!(
            by_table.iter().step_by(2).map(|h| h.0).collect::<Vec<_>>(),
            (0..300).map(|k| materials[k % 3]).collect::<Vec<_>>()
        );
        scene.slot_mesh = None;
        assert_eq!(hits(&scene), by_table);
    }
}
