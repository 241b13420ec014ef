//! `prism export-mitsuba`: writes a loaded scene as a Mitsuba 3 scene (XML
//! plus one binary PLY per material and emission), so that prism and
//! Mitsuba can render the same scene side by side (benches/peers/run.sh,
//! docs/performance.md).
//!
//! What is exported is the scene as prism built it, not the JSON it came
//! from: the same triangles (vertex positions and winding, so emitters face
//! the same way), and every spectrum sampled at 1 nm over prism's range
//! [360, 830] nm as a Mitsuba `<spectrum value="lambda:value, ...">` list.
//! Mitsuba interpolates such a list linearly and returns 0 outside it; prism
//! looks its dense table up at the nearest integer nanometre, so the two
//! agree to within the 1 nm step. Its spectral variants read an emitter's
//! list as absolute spectral radiance, as prism does.
//!
//! Mapping, and where the two differ:
//! - camera: prism's pinhole, `fov` = full vertical field of view ->
//!   `perspective` with `fov_axis = "y"` and a `lookat` transform (Mitsuba's
//!   screen x is up x forward, prism's is forward x up mirrored onto the
//!   raster, i.e. the same picture);
//! - film: `hdrfilm`, linear sRGB, float32, `box` filter of radius 0.5 (a
//!   uniform point in the pixel, prism's pixel estimate);
//! - `diffuse` -> `twosided` `diffuse`: prism's BSDFs reflect on both sides,
//!   Mitsuba's are one-sided unless wrapped;
//! - one-sided area emission -> `area` emitter on the same triangles;
//! - no integrator in the file: benches/peers/mitsuba_render.py passes it
//!   (`path` / `ptracer`, max_depth = -1: unbounded with Russian roulette).
//!   Mitsuba's roulette starts at depth `rr_depth` (prism: after 4
//!   scattering events, so rr_depth = 4) and continues with probability
//!   min(max throughput, 0.95); prism has no 0.95 cap, which on the
//!   benchmark's diffuse box never binds for `path` (every reflectance is
//!   below 0.95, and so is the throughput at each roulette), but does for
//!   `ptracer`, whose throughput starts far above 1 (docs/performance.md).
//!
//! Anything else (conductors, dielectrics, mirrors, point lights, the
//! environment, two-sided emission) is refused with an error naming it:
//! the benchmark scene needs none of them.
//!
//! | option   | default      | meaning                                  |
//! |----------|--------------|------------------------------------------|
//! | SCENE    | -            | prism scene (JSON or glTF)               |
//! | DIR      | -            | output directory: scene.xml, meshes/     |
//! | --width  | the scene's  | image width (XML default, `$width`)      |
//! | --height | the scene's  | image height (`$height`)                 |
//! | --spp    | 64           | samples per pixel (`$spp`)               |

use crate::camera::Camera;
use crate::geometry::shading_normal;
use crate::light::Light;
use crate::materials::Bsdf;
use crate::output::Outputs;
use crate::scene::{load_scene, Scene};
use crate::spectrum::{Spectrum, LAMBDA_MAX, LAMBDA_MIN};
use anyhow::{anyhow, bail, ensure, Context, Result};
use glam::Vec3A;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// `prism export-mitsuba SCENE DIR`.
#[derive(clap::Args, Debug)]
pub struct ExportMitsubaArgs {
    /// Scene file (JSON or glTF).
    pub scene: PathBuf,
    /// Output directory (created if missing): scene.xml and meshes/*.ply.
    pub dir: PathBuf,
    /// Image width (with --height; default: the scene's).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height (with --width; default: the scene's).
    #[arg(long)]
    pub height: Option<u32>,
    /// Samples per pixel: the default of the scene's `$spp` (Mitsuba's -D spp=N overrides it).
    #[arg(long, default_value_t = 64)]
    pub spp: u32,
}

/// Runs the subcommand.
pub fn command(a: ExportMitsubaArgs) -> Result<()> {
    let mut builder = load_scene(&a.scene)?;
    if let (Some(w), Some(h)) = (a.width, a.height) {
        builder.set_resolution(w, h).map_err(|e| anyhow!("--width, --height: {e}"))?;
    } else if a.width.is_some() || a.height.is_some() {
        bail!("--width and --height must be given together");
    }
    ensure!(a.spp >= 1, "--spp must be at least 1");
    // The Mitsuba scene is rendered with unbounded depth (roulette ends
    // paths): a depth cap in the scene would compare unlike estimands.
    if let Some(d) = builder.defaults.max_depth {
        bail!(
            "{}: render.max_depth {d} is not exported (Mitsuba renders unbounded depth): remove it",
            a.scene.display()
        );
    }
    let scene = builder.build();
    let meshes = export(&scene, &a.dir, a.spp).with_context(|| format!("cannot export {}", a.scene.display()))?;
    eprintln!("wrote {} ({} triangles in {meshes} meshes)", a.dir.join("scene.xml").display(), scene.triangle_count());
    Ok(())
}

/// Triangles sharing a material, an emission and whether they have shading
/// normals (a PLY has them for every vertex or for none).
struct Group {
    material: u32,
    emission: Option<Spectrum>,
    smooth: bool,
    positions: Vec<Vec3A>,
    normals: Vec<Vec3A>,
}

/// Writes `dir/scene.xml` and `dir/meshes/*.ply`; returns the mesh count.
/// Everything unsupported is refused before anything is written.
pub fn export(scene: &Scene, dir: &Path, spp: u32) -> Result<usize> {
    check_lights(scene)?;
    check_normals(scene)?;
    let groups = group_triangles(scene);
    for g in &groups {
        let material = &scene.materials[g.material as usize];
        if !matches!(material.bsdf(), Bsdf::Diffuse(_)) {
            bail!("material {}: only diffuse materials are exported", material.name);
        }
    }
    let mesh_dir = dir.join("meshes");
    std::fs::create_dir_all(&mesh_dir).with_context(|| format!("cannot create {}", mesh_dir.display()))?;
    let mut xml = String::new();
    let _ = writeln!(xml, "<?xml version=\"1.0\" encoding=\"utf-8\"?>");
    let _ = writeln!(
        xml,
        "<!-- Exported by `prism export-mitsuba` (src/mitsuba.rs); render with benches/peers/mitsuba_render.py. -->"
    );
    let _ = writeln!(xml, "<scene version=\"3.0.0\">");
    sensor_xml(&mut xml, &scene.camera, spp);
    // The meshes and scene.xml are moved into place together: a failed
    // write leaves an earlier export as it was.
    let mut out = Outputs::default();
    for (k, g) in groups.iter().enumerate() {
        let file = format!("meshes/{k:03}.ply");
        out.bytes(&dir.join(&file), &ply_bytes(&g.positions, &g.normals))?;
        shape_xml(&mut xml, scene, g, &file);
    }
    let _ = writeln!(xml, "</scene>");
    out.bytes(&dir.join("scene.xml"), xml.as_bytes())?;
    out.commit()?;
    remove_stale_meshes(&mesh_dir, groups.len())?;
    Ok(groups.len())
}

/// Removes the meshes an earlier export of a scene with more groups left
/// behind (`meshes/NNN.ply` from `count` on; nothing else is touched), so
/// the directory holds exactly what scene.xml names.
fn remove_stale_meshes(mesh_dir: &Path, count: usize) -> Result<()> {
    let listing = std::fs::read_dir(mesh_dir).with_context(|| format!("cannot list {}", mesh_dir.display()))?;
    for entry in listing {
        let path = entry.with_context(|| format!("cannot list {}", mesh_dir.display()))?.path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        let stem = name.strip_suffix(".ply").unwrap_or_default();
        let index = stem.parse::<usize>().ok().filter(|k| format!("{k:03}") == stem);
        if index.is_some_and(|k| k >= count) {
            std::fs::remove_file(&path).with_context(|| format!("cannot remove {}", path.display()))?;
        }
    }
    Ok(())
}

/// Only one-sided area lights have a Mitsuba equivalent here.
fn check_lights(scene: &Scene) -> Result<()> {
    for (i, light) in scene.lights.iter().enumerate() {
        match light {
            Light::Area(a) if a.two_sided => {
                bail!("light {}: two-sided emission has no Mitsuba area emitter equivalent", scene.light_names[i])
            }
            Light::Area(_) => {}
            Light::Point(_) => bail!("light {}: point lights are not exported", scene.light_names[i]),
            Light::Environment(_) => bail!("light {}: environment lights are not exported", scene.light_names[i]),
        }
    }
    Ok(())
}

/// Vertex normals on both sides of their triangle have no Mitsuba
/// equivalent: prism turns their interpolation to the winding side, and the
/// export can only turn each of them (a triangle whose normals are on one
/// side, or zero, is the same either way).
fn check_normals(scene: &Scene) -> Result<()> {
    for (i, (v, ns, material, _)) in scene.triangles().enumerate() {
        let Some(ns) = ns else { continue };
        let ng = (v[1] - v[0]).cross(v[2] - v[0]);
        let sides: Vec<bool> = ns.iter().filter(|n| **n != Vec3A::ZERO).map(|n| n.dot(ng) < 0.0).collect();
        if sides.contains(&true) && sides.contains(&false) {
            bail!(
                "triangle {i} (material {}): its vertex normals lie on both sides of its face, which Mitsuba \
                 would shade otherwise than prism: not exported",
                scene.materials[material as usize].name
            );
        }
    }
    Ok(())
}

/// The scene's triangles by (material, emission, smooth shading), in order
/// of first appearance: one PLY each.
fn group_triangles(scene: &Scene) -> Vec<Group> {
    let mut groups: Vec<Group> = Vec::new();
    for (v, ns, material, light) in scene.triangles() {
        let emission = light.map(|l| match &scene.lights[l as usize] {
            Light::Area(a) => a.le.clone(),
            _ => unreachable!("a triangle's light is an area light"),
        });
        let smooth = ns.is_some();
        let same = |g: &Group| g.material == material && g.emission == emission && g.smooth == smooth;
        let k = match groups.iter().position(same) {
            Some(k) => k,
            None => {
                groups.push(Group { material, emission, smooth, positions: Vec::new(), normals: Vec::new() });
                groups.len() - 1
            }
        };
        groups[k].positions.extend(v);
        // (Zero for a degenerate triangle, which is never hit.)
        let ng = (v[1] - v[0]).cross(v[2] - v[0]).normalize_or_zero();
        // Each vertex normal as prism shades with it, on the winding side
        // (Mitsuba's area emitter emits on its shading normal's side,
        // prism's on the winding side). Prism turns the interpolated
        // normal: for vertex normals on both sides the two differ inside.
        groups[k].normals.extend(ns.into_iter().flatten().map(|n| shading_normal(n, ng)));
    }
    groups
}

/// The pinhole as a `perspective` sensor (vertical fov, look-at) with an
/// RGB float `hdrfilm` and a box filter.
fn sensor_xml(xml: &mut String, cam: &Camera, spp: u32) {
    let (forward, up, fov_y) = cam.orientation();
    // The target as far along the view as the camera is from the origin
    // (in f64): one unit ahead of a camera at 1e8 is the camera in f32.
    let p = cam.position.as_dvec3();
    let t = p + forward.as_dvec3() * p.length().max(1.0);
    let _ = writeln!(xml, "  <default name=\"spp\" value=\"{spp}\"/>");
    let _ = writeln!(xml, "  <default name=\"width\" value=\"{}\"/>", cam.width);
    let _ = writeln!(xml, "  <default name=\"height\" value=\"{}\"/>", cam.height);
    let _ = writeln!(xml, "  <sensor type=\"perspective\">");
    let _ = writeln!(xml, "    <string name=\"fov_axis\" value=\"y\"/>");
    let _ = writeln!(xml, "    <float name=\"fov\" value=\"{fov_y}\"/>");
    let _ = writeln!(xml, "    <transform name=\"to_world\">");
    let _ = writeln!(
        xml,
        "      <lookat origin=\"{}, {}, {}\" target=\"{}, {}, {}\" up=\"{}, {}, {}\"/>",
        p.x, p.y, p.z, t.x, t.y, t.z, up.x, up.y, up.z
    );
    let _ = writeln!(xml, "    </transform>");
    let _ =
        writeln!(xml, "    <sampler type=\"independent\"><integer name=\"sample_count\" value=\"$spp\"/></sampler>");
    let _ = writeln!(xml, "    <film type=\"hdrfilm\">");
    let _ = writeln!(xml, "      <integer name=\"width\" value=\"$width\"/>");
    let _ = writeln!(xml, "      <integer name=\"height\" value=\"$height\"/>");
    let _ = writeln!(xml, "      <string name=\"pixel_format\" value=\"rgb\"/>");
    let _ = writeln!(xml, "      <string name=\"component_format\" value=\"float32\"/>");
    let _ = writeln!(xml, "      <rfilter type=\"box\"/>");
    let _ = writeln!(xml, "    </film>");
    let _ = writeln!(xml, "  </sensor>");
}

/// One group as a `ply` shape with its two-sided diffuse BSDF and, if it
/// emits, its area emitter.
fn shape_xml(xml: &mut String, scene: &Scene, g: &Group, file: &str) {
    let material = &scene.materials[g.material as usize];
    let Bsdf::Diffuse(d) = material.bsdf() else {
        unreachable!("export checks that every material is diffuse");
    };
    let _ = writeln!(xml, "  <!-- material {} -->", xml_escape(&material.name));
    let _ = writeln!(xml, "  <shape type=\"ply\">");
    let _ = writeln!(xml, "    <string name=\"filename\" value=\"{file}\"/>");
    if g.normals.is_empty() {
        let _ = writeln!(xml, "    <boolean name=\"face_normals\" value=\"true\"/>");
    }
    let _ = writeln!(xml, "    <bsdf type=\"twosided\"><bsdf type=\"diffuse\">");
    let _ = writeln!(xml, "      <spectrum name=\"reflectance\" value=\"{}\"/>", spectrum_list(&d.reflectance));
    let _ = writeln!(xml, "    </bsdf></bsdf>");
    if let Some(le) = &g.emission {
        let _ = writeln!(xml, "    <emitter type=\"area\">");
        let _ = writeln!(xml, "      <spectrum name=\"radiance\" value=\"{}\"/>", spectrum_list(le));
        let _ = writeln!(xml, "    </emitter>");
    }
    let _ = writeln!(xml, "  </shape>");
}

/// `"360:v, 361:v, ..., 830:v"`: prism's 1 nm table at every integer
/// nanometre of its range (a tabulated spectrum's means over each
/// nanometre; a constant as its two end points); `"0"` if it is zero
/// over all of them, which Mitsuba refuses as an irregular spectrum (it has
/// no mass to sample).
pub fn spectrum_list(s: &Spectrum) -> String {
    let (lo, hi) = (LAMBDA_MIN as u32, LAMBDA_MAX as u32);
    let lambdas: Vec<u32> = if s.is_constant() { vec![lo, hi] } else { (lo..=hi).collect() };
    if lambdas.iter().all(|&l| s.eval(l as f32) == 0.0) {
        return "0".to_string();
    }
    lambdas.iter().map(|&l| format!("{l}:{}", s.eval(l as f32))).collect::<Vec<_>>().join(", ")
}

/// A name as the text of an XML comment: no control characters (XML 1.0
/// allows none but tab and newlines, which a one-line comment does not
/// want) and no `--`.
fn xml_escape(s: &str) -> String {
    let mut s: String = s.chars().filter(|c| !c.is_control()).collect();
    s = s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;");
    while s.contains("--") {
        s = s.replace("--", "- -");
    }
    s
}

/// A binary little-endian PLY triangle soup: vertices 3i, 3i+1, 3i+2 make
/// triangle i (winding kept), with per-vertex normals if given.
fn ply_bytes(positions: &[Vec3A], normals: &[Vec3A]) -> Vec<u8> {
    let n_tris = positions.len() / 3;
    let mut header = format!("ply\nformat binary_little_endian 1.0\nelement vertex {}\n", positions.len());
    header += "property float x\nproperty float y\nproperty float z\n";
    if !normals.is_empty() {
        header += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    header += &format!("element face {n_tris}\nproperty list uchar int vertex_indices\nend_header\n");
    let mut bytes = header.into_bytes();
    for (i, p) in positions.iter().enumerate() {
        let mut floats = vec![p.x, p.y, p.z];
        if let Some(n) = normals.get(i) {
            floats.extend([n.x, n.y, n.z]);
        }
        for f in floats {
            bytes.extend(f.to_le_bytes());
        }
    }
    for t in 0..n_tris as i32 {
        bytes.push(3);
        for j in 0..3 {
            bytes.extend((3 * t + j).to_le_bytes());
        }
    }
    bytes
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spectrum_list_samples_every_nanometre() {
        let s = Spectrum::piecewise_linear(&[(400.0, 0.0), (500.0, 1.0)]);
        let list = spectrum_list(&s);
        assert!(list.starts_with("360:0, 361:0,"), "{list}");
        assert!(list.contains(", 450:0.5,"), "{list}");
        assert!(list.ends_with(", 830:1"), "{list}");
        assert_eq!(spectrum_list(&Spectrum::Constant(0.25)), "360:0.25, 830:0.25");
    }

    #[test]
    fn cornell_box_exports() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell-box.json");
        let scene = load_scene(&path).unwrap().build();
        let dir = std::env::temp_dir().join(format!("prism-mitsuba-export-{}", std::process::id()));
        let meshes = export(&scene, &dir, 4).unwrap();
        // white, red, green, and the white emitter.
        assert_eq!(meshes, 4);
        let xml = std::fs::read_to_string(dir.join("scene.xml")).unwrap();
        assert_eq!(xml.matches("<emitter type=\"area\">").count(), 1);
        assert!(xml.contains("fov_axis\" value=\"y\""));
        let ply = std::fs::read(dir.join("meshes/000.ply")).unwrap();
        assert!(ply.starts_with(b"ply\nformat binary_little_endian 1.0\n"));
        let _ = std::fs::remove_dir_all(dir);
    }

    /// From an audit: a camera far from the origin keeps its view (the
    /// target, one unit ahead of a camera at z = -1e8, was the camera in
    /// f32: no direction), vertex normals are turned to the winding side,
    /// where prism emits (a zero one is the face normal; Mitsuba emits on
    /// the normal's side), and a name becomes a well-formed XML comment
    /// (`a---b` made `a- --b`).
    #[test]
    fn far_cameras_turned_normals_and_odd_names_export_as_prism_sees_them() {
        use crate::camera::Camera;
        use crate::materials::Diffuse;
        use crate::scene::SceneBuilder;
        use crate::shapes::Mesh;
        let camera = Camera::new(Vec3A::new(278.0, 273.0, -1e8), Vec3A::new(278.0, 273.0, 0.0), Vec3A::Y, 40.0, 8, 8);
        let mut b = SceneBuilder::new(camera);
        let m = b.material("a---b\u{1}", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.5))));
        // Wound towards -z (the camera): (0, 1, 0) x (1, 0, 0) = -z.
        let positions = vec![Vec3A::ZERO, Vec3A::Y, Vec3A::X];
        let triangle = Mesh { positions, normals: vec![Vec3A::Z, Vec3A::Z, Vec3A::ZERO], indices: vec![[0, 1, 2]] };
        b.mesh("lamp", triangle, m, Some((Spectrum::Constant(1.0), false)));
        let dir = std::env::temp_dir().join(format!("prism-mitsuba-far-{}", std::process::id()));
        assert_eq!(export(&b.build(), &dir, 1).unwrap(), 1);
        let xml = std::fs::read_to_string(dir.join("scene.xml")).unwrap();
        let point = |name: &str| {
            let from = xml.find(&format!("{name}=\"")).unwrap() + name.len() + 2;
            let text = &xml[from..from + xml[from..].find('"').unwrap()];
            let v: Vec<f64> = text.split(", ").map(|x| x.parse().unwrap()).collect();
            glam::DVec3::new(v[0], v[1], v[2])
        };
        let view = (point("target") - point("origin")).normalize();
        assert!((view - glam::DVec3::Z).length() < 1e-6, "view {view}");
        let comment = &xml[xml.find("<!-- material ").unwrap() + 5..];
        let comment = &comment[..comment.find("-->").unwrap()];
        assert!(!comment.contains("--") && !comment.contains('\u{1}'), "{comment:?}");
        let ply = std::fs::read(dir.join("meshes/000.ply")).unwrap();
        let body = ply.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        let float = |i: usize| f32::from_le_bytes(ply[body + 4 * i..body + 4 * i + 4].try_into().unwrap());
        for vertex in 0..3 {
            let n = Vec3A::new(float(6 * vertex + 3), float(6 * vertex + 4), float(6 * vertex + 5));
            assert_eq!(n, -Vec3A::Z, "vertex {vertex}");
        }
        let _ = std::fs::remove_dir_all(dir);
    }

    /// From an audit: a black reflectance made `"360:0, 830:0"`, which
    /// Mitsuba refuses ("no probability mass found").
    #[test]
    fn a_zero_spectrum_is_a_plain_zero() {
        assert_eq!(spectrum_list(&Spectrum::Constant(0.0)), "0");
        // Zero up to 850 nm (held below its first point), past prism's range.
        assert_eq!(spectrum_list(&Spectrum::piecewise_linear(&[(850.0, 0.0), (900.0, 1.0)])), "0");
        let list = spectrum_list(&Spectrum::piecewise_linear(&[(829.0, 0.0), (830.0, 1e-3)]));
        assert!(list.starts_with("360:0, ") && list.ends_with(", 830:0.00075"), "{list}");
    }

    /// From an audit: vertex normals on both sides of a face shaded its
    /// minimal triangle 27 % brighter in prism than in Mitsuba, and random
    /// meshes 5-19 % (prism turns their interpolation, the export turned
    /// each); such a mesh is refused, one whose normals are on one side (or
    /// zero) is not.
    #[test]
    fn normals_on_both_sides_of_a_face_are_not_exported() {
        use crate::camera::Camera;
        use crate::materials::Diffuse;
        use crate::scene::SceneBuilder;
        use crate::shapes::Mesh;
        let scene = |normals: Vec<Vec3A>| {
            let camera = Camera::new(Vec3A::new(0.0, 0.0, -5.0), Vec3A::ZERO, Vec3A::Y, 40.0, 8, 8);
            let mut b = SceneBuilder::new(camera);
            let m = b.material("grey", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.5))));
            // Wound towards -z: (0, 1, 0) x (1, 0, 0) = -z.
            let positions = vec![Vec3A::ZERO, Vec3A::Y, Vec3A::X];
            b.mesh("tri", Mesh { positions, normals, indices: vec![[0, 1, 2]] }, m, None);
            b.build()
        };
        let tilted = Vec3A::new(0.6, 0.0, 0.8);
        let mixed = scene(vec![-Vec3A::Z, tilted, -Vec3A::Z]);
        let e = check_normals(&mixed).unwrap_err().to_string();
        assert!(e.contains("triangle 0 (material grey): its vertex normals lie on both sides of its face"), "{e}");
        for one_side in [vec![-Vec3A::Z, -tilted, Vec3A::ZERO], vec![Vec3A::Z, tilted, Vec3A::Z]] {
            check_normals(&scene(one_side)).unwrap();
        }
    }

    #[test]
    fn meshes_with_and_without_normals_go_to_separate_plys() {
        use crate::camera::Camera;
        use crate::materials::Diffuse;
        use crate::scene::SceneBuilder;
        use crate::shapes::Mesh;
        let camera = Camera::new(Vec3A::new(0.0, 0.0, -5.0), Vec3A::ZERO, Vec3A::Y, 40.0, 8, 8);
        let mut b = SceneBuilder::new(camera);
        let m = b.material("grey", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.5))));
        b.mesh("smooth", Mesh::sphere(Vec3A::ZERO, 1.0, 1, true), m, None);
        let quad = [Vec3A::new(-2., -1., 2.), Vec3A::new(2., -1., 2.), Vec3A::new(2., 1., 2.), Vec3A::new(-2., 1., 2.)];
        b.mesh("flat", Mesh::quad(quad), m, Some((Spectrum::Constant(1.0), false)));
        let dir = std::env::temp_dir().join(format!("prism-mitsuba-normals-{}", std::process::id()));
        assert_eq!(export(&b.build(), &dir, 1).unwrap(), 2);
        let header = |f: &str| {
            let bytes = std::fs::read(dir.join(f)).unwrap();
            let end = bytes.windows(10).position(|w| w == b"end_header").unwrap();
            String::from_utf8_lossy(&bytes[..end]).into_owned()
        };
        assert!(header("meshes/000.ply").contains("property float nx"));
        assert!(!header("meshes/001.ply").contains("property float nx"));
        let xml = std::fs::read_to_string(dir.join("scene.xml")).unwrap();
        assert_eq!(xml.matches("face_normals").count(), 1);
        assert_eq!(xml.matches("<emitter type=\"area\">").count(), 1);
        let _ = std::fs::remove_dir_all(dir);
    }
}
