//! The glTF loader (src/scene/gltf.rs) on public sample models the project
//! did not write (scenes/gltf/README.md lists them with their licences), on
//! its error paths, inside a JSON scene, and on an export of the Cornell box
//! that must render the same image as the JSON scene within noise.
//!
//! The Cornell box export (scenes/gltf/cornell-box.gltf + .bin) is made by
//! `cornell_export` below from scenes/cornell-box.json;
//! `cornell_export_is_current` fails when they drift apart, and
//! `PRISM_WRITE_GLTF=1 cargo test --release --test gltf cornell_export`
//! rewrites the files.

#[path = "common/scenes.rs"]
mod scenes;

use glam::{Vec2, Vec3A};
use prism::film::Film;
use prism::geometry::Ray;
use prism::materials::Bsdf;
use prism::render::{render, RenderOptions};
use prism::scene::{gltf_conductor_eta_k, load_gltf, load_scene, parse_gltf, parse_scene, GltfScene, Scene};
use prism::spectrum::{illuminant, rgb_albedo, spectrum_to_xyz, xyz_to_linear_srgb, Spectrum};
use prism::stats::{render_passes, ColourStats, Verdict};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes").join("gltf")
}

fn load(name: &str) -> GltfScene {
    load_gltf(&dir().join(name)).unwrap_or_else(|e| panic!("{e}"))
}

/// Parses glTF JSON `v` as if it were the file `name` of scenes/gltf.
fn parse(v: &Value, name: &str) -> Result<GltfScene, String> {
    parse_gltf(v.to_string().as_bytes(), name, &dir()).map_err(|e| e.to_string())
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn has(messages: &[String], needle: &str) -> bool {
    messages.iter().any(|m| m.contains(needle))
}

/// Renders `spp` samples per pixel at 32 x 32 and returns the image after
/// checking that no sample was dropped and that something is visible.
fn render_checked(scene: &Scene, integrator: &str, spp: u32) -> Vec<[f32; 3]> {
    let mut film = Film::new(scene.camera.width, scene.camera.height);
    let opts = RenderOptions { seed: 7, threads: 0, progress: false };
    render(scene, scenes::integrator(integrator).as_ref(), &opts, &mut film, 0..spp);
    assert_eq!(film.dropped.total(), 0, "{integrator}: dropped samples {:?}", film.dropped);
    let image = film.image();
    assert!(image.iter().flatten().all(|v| v.is_finite()));
    let mean: f32 = image.iter().flatten().sum::<f32>() / (image.len() * 3) as f32;
    assert!(mean > 0.0, "{integrator}: black image");
    image
}

#[test]
fn sample_models_load_and_render_without_dropped_samples() {
    // (file, a message the loader must print)
    let cases = [
        ("Box.gltf", "constant white (D65) environment"),
        ("BoxTextured.gltf", "baseColorTexture is replaced by its mean"),
        ("Triangle.gltf", "default framing"),
        ("Cameras.gltf", "orthographic camera ignored"),
        ("LightsPoint.gltf", "range is ignored"),
        ("LightsSpot.gltf", "rendered as a point light"),
    ];
    for (name, expected) in cases {
        let g = load(name);
        assert!(has(&g.messages, expected), "{name}: no message containing {expected:?} in {:#?}", g.messages);
        // Through the CLI's entry point too (the extension dispatch).
        let mut b = load_scene(&dir().join(name)).unwrap_or_else(|e| panic!("{e}"));
        b.set_resolution(32, 32).unwrap();
        let scene = b.build();
        assert!(scene.triangle_count() > 0, "{name}");
        for integrator in ["path", "bdpt"] {
            render_checked(&scene, integrator, 4);
        }
    }
}

#[test]
fn punctual_lights_become_point_lights_with_candela_luminance() {
    let scene = load("LightsPoint.gltf").builder.build();
    assert_eq!(scene.lights.len(), 3);
    assert!(scene.environment().is_none());
    // White 450 cd would have luminance 450; the red light has that of the
    // red primary (0.2126) times 450.
    let red = scene.light_names.iter().position(|n| n == "PointLightRed").expect("red light");
    let prism::light::Light::Point(p) = &scene.lights[red] else { panic!("not a point light") };
    assert!((p.p - Vec3A::new(2.0, 1.0, 0.0)).length() < 1e-6);
    let y = p.intensity.luminance();
    assert!((y / 450.0 - 0.2126).abs() < 2e-3, "luminance {y}");
}

#[test]
fn first_perspective_camera_is_used() {
    let g = load("Cameras.gltf");
    assert!(has(&g.messages, "nodes[1]: renders through this node's camera"), "{:#?}", g.messages);
    let scene = g.builder.build();
    let c = &scene.camera;
    assert_eq!((c.width, c.height), (480, 480));
    assert!((c.position - Vec3A::new(0.5, 0.5, 3.0)).length() < 1e-6);
    let center = c.generate_ray(Vec2::new(240.0, 240.0)).d;
    assert!((center - Vec3A::NEG_Z).length() < 1e-5, "{center}");
    // yfov 0.7 rad: the top edge's ray is 0.35 rad above the axis.
    let top = c.generate_ray(Vec2::new(240.0, 0.0)).d;
    assert!((top.y.atan2(-top.z) - 0.35).abs() < 1e-4);
}

/// prism's pinhole takes a camera node's position, -z and +y; a mirroring
/// or uneven scale, which a rasteriser's view (the inverse of the node's
/// transform) would show as a flipped or stretched image, is named (from
/// an audit: a mirrored camera rendered unmirrored without a word).
#[test]
fn a_mirrored_or_stretched_camera_is_named() {
    let warned = |scale: [f32; 3]| {
        let mut v = read_json(&dir().join("Cameras.gltf"));
        v["nodes"][1]["scale"] = json!(scale);
        let g = parse(&v, "Cameras (scaled)").unwrap();
        g.messages.into_iter().find(|m| m.contains("the camera's transform")).unwrap_or_default()
    };
    let m = warned([-1.0, 1.0, 1.0]);
    assert!(m.contains("nodes[1]: the camera's transform mirrors (its determinant is negative): rendered from its position, -z and +y alone"), "{m}");
    assert!(warned([1.0, 2.0, 1.0]).contains("scales unevenly or shears"));
    assert_eq!(warned([2.0, 2.0, 2.0]), "", "a uniform scale changes nothing");
    assert_eq!(warned([1.0, 1.0, 1.0]), "");
}

#[test]
fn metallic_base_colour_becomes_a_conductor_with_that_reflectance() {
    let scene = load("Box.gltf").builder.build();
    // Box.gltf: baseColorFactor (0.8, 0, 0), metallic and roughness default 1.
    let Bsdf::Conductor(c) = scene.materials[0].bsdf() else { panic!("{:?}", scene.materials[0].bsdf()) };
    let f0 = rgb_albedo([0.8, 0.0, 0.0]);
    for l in [420.0, 500.0, 580.0, 650.0] {
        let (n, k) = (c.eta.eval(l), c.k.eval(l));
        let r = ((n - 1.0).powi(2) + k * k) / ((n + 1.0).powi(2) + k * k);
        assert!((r - f0.eval(l).min(0.999)).abs() < 1e-3, "{l} nm: F0 {r} vs {}", f0.eval(l));
        assert_eq!(gltf_conductor_eta_k(f0.eval(l)), (n, k));
    }
    assert!((c.distrib.alpha_x - 1.0).abs() < 1e-6);
}

#[test]
fn material_rules_threshold_metallic_and_transmission_with_warnings() {
    let mut v = read_json(&dir().join("Box.gltf"));
    let pbr = &mut v["materials"][0]["pbrMetallicRoughness"];
    pbr["metallicFactor"] = json!(0.3);
    pbr["roughnessFactor"] = json!(0.5);
    let g = parse(&v, "Box (metallic 0.3)").unwrap();
    assert!(has(&g.messages, "metallic 0.3 is neither 0 nor 1: rendered as a non-metal (threshold 0.5)"));
    let scene = g.builder.build();
    assert!(matches!(scene.materials[0].bsdf(), Bsdf::Diffuse(_)));

    v["materials"][0]["extensions"] =
        json!({"KHR_materials_transmission": {"transmissionFactor": 1.0}, "KHR_materials_ior": {"ior": 1.33}});
    v["extensionsUsed"] = json!(["KHR_materials_transmission", "KHR_materials_ior"]);
    let g = parse(&v, "Box (glass)").unwrap();
    assert!(has(&g.messages, "does not tint transmission"), "{:#?}", g.messages);
    let scene = g.builder.build();
    let Bsdf::Dielectric(d) = scene.materials[0].bsdf() else { panic!("{:?}", scene.materials[0].bsdf()) };
    assert_eq!(d.eta, Spectrum::Constant(1.33));
    assert!((d.distrib.alpha_x - 0.25).abs() < 1e-6);

    // A rough interface nearer to index 1 than f32 resolves at its
    // roughness (alpha 0.25: 2e-4) is made smooth.
    v["materials"][0]["extensions"]["KHR_materials_ior"]["ior"] = json!(1.00015);
    let g = parse(&v, "Box (ior 1.00015)").unwrap();
    let said = "ior 1.00015 is too near 1 for a rough surface (it must differ from 1 by at least 2.00e-4 at alpha 0.25";
    assert!(has(&g.messages, said), "{:#?}", g.messages);
    let scene = g.builder.build();
    let Bsdf::Dielectric(d) = scene.materials[0].bsdf() else { panic!("not a dielectric") };
    assert_eq!(d.eta, Spectrum::Constant(1.00015));
    assert!(d.distrib.effectively_smooth());
}

#[test]
fn texture_mean_is_srgb_decoded() {
    let g = load("BoxTextured.gltf");
    let scene = g.builder.build();
    let Bsdf::Diffuse(d) = scene.materials[0].bsdf() else { panic!() };
    // The Cesium logo texture (256 x 256, 8-bit palette PNG), decoded by
    // hand outside prism (base64, zlib, PNG filters, palette; the sRGB
    // transfer function per texel, then the mean): linear (0.4036, 0.5237,
    // 0.5638); the mean of the undecoded values would be (0.6064, 0.7302,
    // 0.6915). The reflectance, back in linear sRGB under D65, must be the
    // first within the RGB-to-spectrum round trip's error.
    let rgb = xyz_to_linear_srgb(spectrum_to_xyz(&d.reflectance.scaled_by(&illuminant("D65").unwrap())));
    let decoded = glam::Vec3::new(0.4036, 0.5237, 0.5638);
    assert!((rgb - decoded).abs().max_element() < 0.01, "texture mean {rgb}, expected {decoded}");
    assert!(has(&g.messages, "baseColorTexture is replaced by its mean ["));
}

/// Factors outside [0, 1] (invalid glTF) are clamped before a texture's
/// mean multiplies them: a factor of 1e39, infinite in f32, times a mean of
/// 0 would be NaN (which only the NaN-dropping max and min further on kept
/// out of the BSDF).
#[test]
fn out_of_range_factors_are_clamped_before_the_texture_mean() {
    // A 1 x 1 PNG of (0, 0, 255): roughness (G) 0, metallic (B) 1.
    const BLUE: &str = "iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAIAAACQd1PeAAAADElEQVR4nGNgYPgPAAEDAQAIicLsAAAAAElFTkSuQmCC";
    let mut v = read_json(&dir().join("BoxTextured.gltf"));
    v["images"][0]["uri"] = json!(format!("data:image/png;base64,{BLUE}"));
    v["materials"][0]["pbrMetallicRoughness"] = json!({
        "metallicRoughnessTexture": {"index": 0}, "metallicFactor": 1.0, "roughnessFactor": 1e39
    });
    let g = parse(&v, "BoxTextured (roughnessFactor 1e39)").unwrap();
    assert!(has(&g.messages, "roughnessFactor [inf] is outside [0, 1] (invalid glTF): clamped"), "{:?}", g.messages);
    let scene = g.builder.build();
    let Bsdf::Conductor(c) = scene.materials[0].bsdf() else { panic!("not a conductor") };
    assert_eq!((c.distrib.alpha_x, c.distrib.alpha_y), (0.0, 0.0), "clamped to 1, times a mean of 0");
    v["materials"][0]["pbrMetallicRoughness"] =
        json!({"baseColorTexture": {"index": 0}, "baseColorFactor": [1e39, 1e39, 1e39, 1.0], "metallicFactor": 0.0});
    let scene = parse(&v, "BoxTextured (baseColorFactor 1e39)").unwrap().builder.build();
    let Bsdf::Diffuse(d) = scene.materials[0].bsdf() else { panic!("not diffuse") };
    let blue = reflectance_rgb(&d.reflectance);
    assert!(blue[0] < 0.05 && blue[1] < 0.05 && blue[2] > 0.95, "reflectance {blue:?}, expected pure blue");
}

/// A 1 x 1 PNG of `rgb`, as a data URI (made outside prism: zlib and the
/// PNG chunks by hand).
fn png_uri(rgb: [u8; 3]) -> String {
    let base64 = match rgb {
        [0, 128, 255] => "iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAIAAACQd1PeAAAADElEQVR4nGNgaPgPAAIDAYAkYfWXAAAAAElFTkSuQmCC",
        [128, 128, 128] => {
            "iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAIAAACQd1PeAAAADElEQVR4nGNoaGgAAAMEAYFL09IQAAAAAElFTkSuQmCC"
        }
        _ => panic!("no PNG of {rgb:?} here"),
    };
    format!("data:image/png;base64,{base64}")
}

/// Texels of 128 tell the transfer functions apart, where 0 and 255 (the
/// tests above) do not: read linear, 128 is 0.502; sRGB-decoded, 0.2159.
/// glTF 2.0 (section 3.9.2) stores metallicRoughnessTexture linear and
/// emissiveTexture in sRGB. Roughness (G) 0.502 is alpha 0.2520 (alpha =
/// roughness^2, as for the factor), decoded it would be 0.0466; a grey
/// emissive texel of 128 under emissiveFactor 1 emits a grey of 0.2159,
/// read linear it would be 0.502 (a review, session 55: no test held
/// either). (Controls: with either texture read the other way, this test
/// failed.)
#[test]
fn metallic_roughness_textures_are_linear_and_emissive_ones_srgb() {
    let mut v = read_json(&dir().join("BoxTextured.gltf"));
    v["images"][0]["uri"] = json!(png_uri([0, 128, 255]));
    v["materials"][0]["pbrMetallicRoughness"] =
        json!({"metallicRoughnessTexture": {"index": 0}, "metallicFactor": 1.0, "roughnessFactor": 1.0});
    let scene = parse(&v, "BoxTextured (roughness texel 128)").unwrap().builder.build();
    let Bsdf::Conductor(c) = scene.materials[0].bsdf() else { panic!("not a conductor") };
    let alpha = (128.0f32 / 255.0).powi(2);
    assert!((c.distrib.alpha_x - alpha).abs() < 1e-4, "alpha {} (linear texel: {alpha})", c.distrib.alpha_x);

    v["images"][0]["uri"] = json!(png_uri([128, 128, 128]));
    v["materials"][0]["pbrMetallicRoughness"] = json!({"metallicFactor": 0.0});
    v["materials"][0]["emissiveTexture"] = json!({"index": 0});
    v["materials"][0]["emissiveFactor"] = json!([1.0, 1.0, 1.0]);
    let scene = parse(&v, "BoxTextured (emissive texel 128)").unwrap().builder.build();
    let Some(prism::light::Light::Area(light)) = scene.lights.first() else { panic!("no area light") };
    let decoded = ((128.0f32 / 255.0 + 0.055) / 1.055).powf(2.4);
    for c in emission_rgb(&light.le) {
        assert!((c - decoded).abs() < 2e-3, "emitted {:?}, sRGB-decoded {decoded}", emission_rgb(&light.le));
    }
}

/// A node's world transform is its parent's times its own (glTF 2.0,
/// section 3.5.3): Box.gltf's parent node rotated 90 degrees about z and
/// its mesh node moved by (1, 0, 0) put the unit box's centre at (0, 1, 0);
/// the product taken the other way round would put it at (1, 0, 0), and
/// with it this test failed. (A review, session 55: no test held a world
/// position.)
#[test]
fn a_child_node_is_placed_in_its_parents_frame() {
    let mut v = read_json(&dir().join("Box.gltf"));
    v["nodes"][0] = json!({"children": [1], "rotation": [0.0, 0.0, std::f32::consts::FRAC_1_SQRT_2, std::f32::consts::FRAC_1_SQRT_2]});
    v["nodes"][1] = json!({"mesh": 0, "translation": [1.0, 0.0, 0.0]});
    let scene = parse(&v, "Box (parent and child)").unwrap().builder.build();
    let (lo, hi) = scene.accel.bounds();
    let centre = (lo + hi) * 0.5 + scene.render_shift;
    assert!((centre - Vec3A::new(0.0, 1.0, 0.0)).length() < 1e-5, "the box's centre is at {centre}");
}

/// A perspective camera's aspectRatio sets the image's width (480 rows:
/// 1.5 gives 720 columns) and, with yfov vertical, the horizontal field of
/// view: the right edge's ray is atan(1.5 tan(yfov / 2)) off the axis.
/// (Only 1.0 was tested: a review, session 55.)
#[test]
fn a_cameras_aspect_ratio_sets_the_width_and_horizontal_view() {
    let mut v = read_json(&dir().join("Cameras.gltf"));
    v["cameras"][0]["perspective"]["aspectRatio"] = json!(1.5);
    let scene = parse(&v, "Cameras (aspect 1.5)").unwrap().builder.build();
    let c = &scene.camera;
    assert_eq!((c.width, c.height), (720, 480));
    let right = c.generate_ray(Vec2::new(720.0, 240.0)).d;
    let expected = (1.5 * 0.35f32.tan()).atan();
    assert!((right.x.atan2(-right.z) - expected).abs() < 1e-4, "{right}: expected {expected} rad off the axis");
    let top = c.generate_ray(Vec2::new(360.0, 0.0)).d;
    assert!((top.y.atan2(-top.z) - 0.35).abs() < 1e-4, "{top}");
}

#[test]
fn primitive_modes_points_and_lines_are_skipped_triangle_modes_render() {
    // Points and lines have no area, so a path tracer's image has none of
    // them: each is skipped with a warning, and the surfaces render.
    let g = load("MeshPrimitiveModes.gltf");
    for (node, mode) in [(0, "POINTS"), (1, "LINES"), (2, "LINE_LOOP"), (3, "LINE_STRIP")] {
        let pascal = match mode {
            "POINTS" => "Points",
            "LINES" => "Lines",
            "LINE_LOOP" => "LineLoop",
            _ => "LineStrip",
        };
        let expected = format!(
            "nodes[{node}] (meshes[{node}] \"mesh with {mode}\"), primitive 0: mode {pascal} has no area: skipped"
        );
        assert!(has(&g.messages, &expected), "no {expected:?} in {:#?}", g.messages);
    }
    assert_eq!(g.builder.build().triangle_count(), 6 + 4 + 6);
    // TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN each cover the same hexagon
    // (radius 1, at x = -2, 0, 2), wound counter-clockwise as seen from +z.
    // The file puts them at y = -3; alone there, they would be moved to
    // render space, so they are put at y = 0, where rays can aim in the
    // file's coordinates.
    let mut v = read_json(&dir().join("MeshPrimitiveModes.gltf"));
    for (node, x) in [(4, -2), (5, 0), (6, 2)] {
        v["nodes"][node]["translation"] = json!([x, 0, 0]);
    }
    let scene = parse(&v, "MeshPrimitiveModes (at y = 0)").unwrap().builder.build();
    for cx in [-2.0f32, 0.0, 2.0] {
        for k in 0..12 {
            let a = (k as f32 + 0.5) * std::f32::consts::TAU / 12.0;
            let inside = Vec3A::new(cx + 0.8 * a.cos(), 0.8 * a.sin(), 5.0);
            let hit = scene.intersect(&Ray::new(inside, Vec3A::NEG_Z)).unwrap_or_else(|| panic!("hole at x {cx}, {k}"));
            assert!(hit.ng.z > 0.99, "x {cx}: triangle wound clockwise ({})", hit.ng);
            let outside = Vec3A::new(cx + 1.02 * a.cos(), 1.02 * a.sin(), 5.0);
            assert!(scene.intersect(&Ray::new(outside, Vec3A::NEG_Z)).is_none(), "x {cx}: covers too much");
        }
    }
}

#[test]
fn unsupported_features_are_named_errors() {
    let mut v = read_json(&dir().join("LightsPoint.gltf"));
    v["extensions"]["KHR_lights_punctual"]["lights"][1]["type"] = json!("directional");
    let e = parse(&v, "LightsPoint (directional)").err().unwrap();
    assert!(e.contains("nodes[2] \"PointLightGreen\": directional light \"PointLightGreen\" is not supported"), "{e}");
    // Including the file in a JSON scene would not help: it names the file.
    assert!(e.contains("remove it from the file"), "{e}");

    let mut v = read_json(&dir().join("Triangle.gltf"));
    v["extensionsUsed"] = json!(["KHR_draco_mesh_compression"]);
    v["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
    let e = parse(&v, "Triangle (draco)").err().unwrap();
    assert!(e.contains("extensionsRequired[0]: the file requires extension KHR_draco_mesh_compression"), "{e}");

    // Used but not required: a warning, and the file renders without it.
    v["extensionsRequired"] = json!([]);
    let g = parse(&v, "Triangle (draco used)").unwrap();
    assert!(has(&g.messages, "extension KHR_draco_mesh_compression is ignored"));

    let mut v = read_json(&dir().join("Triangle.gltf"));
    v["meshes"][0]["primitives"][0]["indices"] = json!(1);
    let e = parse(&v, "Triangle (bad indices)").err().unwrap();
    assert!(e.contains("nodes[0] (meshes[0]), primitive 0: indices must be SCALAR"), "{e}");

    // A NORMAL accessor with a NaN (the transform made it zero, and the
    // triangle rendered flat without a word until session 53). The buffer is
    // Triangle.gltf's 44 bytes and three normals, (NaN, 0, 1), (0, 0, 1),
    // (0, 0, 1); the control, its NaN replaced by 0, loads.
    let with_normals = |buffer: &str| {
        let mut v = read_json(&dir().join("Triangle.gltf"));
        v["buffers"][0] = json!({"uri": format!("data:application/octet-stream;base64,{buffer}"), "byteLength": 80});
        let view = json!({"buffer": 0, "byteOffset": 44, "byteLength": 36});
        v["bufferViews"].as_array_mut().unwrap().push(view);
        let accessor = json!({"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC3"});
        v["accessors"].as_array_mut().unwrap().push(accessor);
        v["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = json!(2);
        parse(&v, "Triangle (normals)")
    };
    let nan =
        "AAABAAIAAAAAAAAAAAAAAAAAAAAAAIA/AAAAAAAAAAAAAAAAAACAPwAAAAAAAMB/AAAAAAAAgD8AAAAAAAAAAAAAgD8AAAAAAAAAAAAAgD8=";
    let e = with_normals(nan).err().expect("a NaN normal loaded");
    assert!(e.contains("primitive 0: NORMAL values are not finite"), "{e}");
    let zero =
        "AAABAAIAAAAAAAAAAAAAAAAAAAAAAIA/AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAAAAAAAgD8AAAAAAAAAAAAAgD8=";
    with_normals(zero).expect("the control, finite normals");

    // A node scaled by 0 on one axis: its mesh collapses, said by a
    // warning; the control, an ordinary scale, has none.
    let scaled = |scale: [f32; 3]| {
        let mut v = read_json(&dir().join("Triangle.gltf"));
        v["nodes"][0]["scale"] = json!(scale);
        parse(&v, "Triangle (scaled)").unwrap().messages
    };
    let singular = "nodes[0] (meshes[0]): the node's transform is singular (a scale of 0)";
    assert!(has(&scaled([1.0, 0.0, 1.0]), singular), "{:?}", scaled([1.0, 0.0, 1.0]));
    assert!(!has(&scaled([1.0, 2.0, 1.0]), "singular"), "{:?}", scaled([1.0, 2.0, 1.0]));

    // A triangle too large for f32 normals (it would vanish from the BVH).
    let mut v = read_json(&dir().join("Triangle.gltf"));
    v["nodes"][0]["scale"] = json!([1e10, 1e10, 1e10]);
    let e = parse(&v, "Triangle (huge)").err().unwrap();
    assert!(e.contains("primitive 0: triangle 0 is too large for f32 arithmetic"), "{e}");

    // A camera whose field of view has no area (light tracing divides by
    // it), as the JSON loader refuses it.
    let mut v = read_json(&dir().join("Triangle.gltf"));
    v["cameras"] = json!([{"type": "perspective", "perspective": {"yfov": 1e-30, "znear": 0.1}}]);
    v["nodes"] = json!([{"mesh": 0}, {"camera": 0, "translation": [0.5, 0.5, 3.0]}]);
    v["scenes"][0]["nodes"] = json!([0, 1]);
    let e = parse(&v, "Triangle (tiny yfov)").err().unwrap();
    assert!(e.contains("nodes[1]: yfov 1e-30 rad is too small: the image has no area"), "{e}");
    // An aspect ratio glTF forbids is refused; one too wide is clamped,
    // with a warning.
    v["cameras"][0]["perspective"]["yfov"] = json!(0.7);
    v["cameras"][0]["perspective"]["aspectRatio"] = json!(0.0);
    let e = parse(&v, "Triangle (aspect 0)").err().unwrap();
    assert!(e.contains("nodes[1]: aspectRatio 0 is not a positive number"), "{e}");
    v["cameras"][0]["perspective"]["aspectRatio"] = json!(1e9);
    let g = parse(&v, "Triangle (aspect 1e9)").unwrap();
    assert!(has(&g.messages, "the width is clamped to 16384 pixels"), "{:?}", g.messages);
    v["cameras"][0]["perspective"].as_object_mut().unwrap().remove("aspectRatio");
    // Far from the origin a camera keeps its direction (position +
    // direction in f32 would round it to the axis).
    let (s, c) = (18.434949f64.to_radians().sin(), 18.434949f64.to_radians().cos());
    v["cameras"][0]["perspective"]["yfov"] = json!(0.7);
    v["nodes"][1] = json!({"camera": 0, "translation": [1e8, 0.0, 3.0], "rotation": [0.0, s, 0.0, c]});
    let forward = parse(&v, "Triangle (far camera)").unwrap().builder.build().camera.orientation().0;
    assert!((forward - Vec3A::new(-0.6, 0.0, -0.8)).length() < 1e-5, "{forward}");

    // The default camera frames any scene f32 can hold a camera for (its
    // diagonal, 2e30 here, passes f32 when squared: it used to be NaN), and
    // names the one it cannot.
    let mut v = read_json(&dir().join("Triangle.gltf"));
    let apart = |x: f64| json!([{"mesh": 0, "translation": [-x, 0, 0]}, {"mesh": 0, "translation": [x, 0, 0]}]);
    v["nodes"] = apart(1e30);
    v["scenes"][0]["nodes"] = json!([0, 1]);
    let g = parse(&v, "Triangle (far apart)").unwrap();
    let c = g.builder.build().camera;
    assert!(c.position.is_finite() && c.position.z > 1e30, "{:?}", c.position);
    v["nodes"] = apart(3e38);
    let e = parse(&v, "Triangle (too far apart)").err().unwrap();
    assert!(e.contains("too large to frame a default camera"), "{e}");

    // Emission whose spectrum overflows f32 (a finite colour times the
    // illuminant's peak) is an error: its power, infinite, left the scene
    // without a light to sample and rendered it black without a word.
    let mut v = read_json(&dir().join("LightsPoint.gltf"));
    v["extensions"]["KHR_lights_punctual"]["lights"][0]["color"] = json!([1.0, 1.0, 1.0]);
    v["extensions"]["KHR_lights_punctual"]["lights"][0]["intensity"] = json!(3.4e38);
    let e = parse(&v, "LightsPoint (3.4e38 cd)").err().unwrap();
    assert!(e.contains("\"PointLightRed\": the emitted spectrum is not finite at every wavelength"), "{e}");
    // Finite, but a light path leaving it carries 4 pi I: past 2^100 it is
    // refused as a JSON point light's intensity is (light tracing lost
    // every path of one at 1e38 without a word).
    v["extensions"]["KHR_lights_punctual"]["lights"][0]["intensity"] = json!(1e31);
    let e = parse(&v, "LightsPoint (1e31 cd)").err().unwrap();
    assert!(
        e.contains("light \"PointLightRed\": its spectrum (colour x intensity) as an intensity must be at most"),
        "{e}"
    );
    let mut v = read_json(&dir().join("cornell-box.gltf"));
    let light = &mut v["materials"][3];
    light["extras"]["prism"].as_object_mut().unwrap().remove("emission");
    light["emissiveFactor"] = json!([1.0, 1.0, 1.0]);
    light["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"] = json!(3.4e38);
    let e = parse(&v, "cornell-box (emissiveStrength 3.4e38)").err().unwrap();
    assert!(e.contains("materials[3] \"light\": the emitted spectrum is not finite at every wavelength"), "{e}");
    // Finite, but past the film's bound on one sample's colour; the
    // measured spectrum of the extras alike (1e15 at its peak).
    v["materials"][3]["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"] = json!(1e15);
    let e = parse(&v, "cornell-box (emissiveStrength 1e15)").err().unwrap();
    assert!(e.contains("materials[3] \"light\": the emitted radiance must be at most 3.5184372e13"), "{e}");
    let mut v = read_json(&dir().join("cornell-box.gltf"));
    let emission = &mut v["materials"][3]["extras"]["prism"]["emission"];
    emission["values"] = json!([0.0, 8.0, 15.6, 1e15]);
    let e = parse(&v, "cornell-box (measured emission 1e15)").err().unwrap();
    assert!(e.contains("materials[3] \"light\": the emitted radiance must be at most 3.5184372e13"), "{e}");
    // Wavelengths are nanometres above 0, as in the JSON format (a docs
    // audit, session 60: the extras took 0 and below).
    let mut v = read_json(&dir().join("cornell-box.gltf"));
    let emission = &mut v["materials"][3]["extras"]["prism"]["emission"];
    let n = emission["wavelengths"].as_array().unwrap().len();
    emission["wavelengths"] = json!((0..n).map(|i| i as f64 * 100.0 - 50.0).collect::<Vec<_>>());
    let e = parse(&v, "cornell-box (emission from -50 nm)").err().unwrap();
    assert!(e.contains("\"wavelengths\" are in nanometres, all above 0"), "{e}");

    // An accessor's byteOffset near 2^64 does not wrap its end round to
    // the view's start (the indices were read as absent: sequential).
    let mut v = read_json(&dir().join("Triangle.gltf"));
    v["accessors"][0]["byteOffset"] = json!(u64::MAX);
    let e = parse(&v, "Triangle (byteOffset 2^64 - 1)").err().unwrap();
    assert!(
        e.contains("accessors[0]: 3 elements of 2 bytes every 2 from byteOffset 18446744073709551615 run past"),
        "{e}"
    );
    // TRIANGLES takes indices three at a time: the rest of a count that is
    // not a multiple of 3 is dropped with a warning, not quietly.
    let mut v = read_json(&dir().join("Triangle.gltf"));
    v["accessors"][0]["count"] = json!(2);
    let g = parse(&v, "Triangle (2 indices)").unwrap();
    let warned = "primitive 0: 2 vertices do not make whole triangles (mode Triangles): the last 2 are ignored";
    assert!(has(&g.messages, warned), "{:?}", g.messages);

    // Buffers and images are read only from regular files (a FIFO or a
    // device would hang or exhaust memory).
    let mut v = read_json(&dir().join("Triangle.gltf"));
    v["buffers"][0]["uri"] = json!(".");
    let e = parse(&v, "Triangle (buffer is a directory)").err().unwrap();
    assert!(e.contains("not a regular file"), "{e}");
}

/// What the loader reads past, ignores or skips, it says, with the effect
/// (a Khronos sample-model audit, session 42).
#[test]
fn what_is_passed_over_is_said() {
    let triangle = read_json(&dir().join("Triangle.gltf"));
    let messages = |v: &Value, name: &str| parse(v, name).unwrap_or_else(|e| panic!("{e}")).messages;

    // A byte-order mark (glTF forbids writers one; readers may skip it).
    let bytes = [b"\xEF\xBB\xBF".as_slice(), triangle.to_string().as_bytes()].concat();
    let g = parse_gltf(&bytes, "Triangle (BOM)", &dir()).unwrap_or_else(|e| panic!("{e}"));
    assert!(has(&g.messages, "UTF-8 byte-order mark"), "{:?}", g.messages);
    assert_eq!(g.builder.build().triangle_count(), 1);

    // A .gltf buffer without a uri (only a .glb's first may omit it).
    let mut v = triangle.clone();
    v["buffers"][0].as_object_mut().unwrap().remove("uri");
    let e = parse(&v, "Triangle (no uri)").err().unwrap();
    assert!(e.contains("buffers[0]: has no uri"), "{e}");

    // Extensions whose absence prism's rendering does not mean.
    let mut v = triangle.clone();
    v["extensionsUsed"] = json!(["KHR_materials_volume", "KHR_materials_pbrSpecularGlossiness"]);
    let m = messages(&v, "Triangle (extensions)");
    assert!(has(&m, "KHR_materials_volume is ignored (transmissive meshes are solid volumes"), "{m:?}");
    assert!(has(&m, "KHR_materials_pbrSpecularGlossiness is ignored (its materials take their metallic"), "{m:?}");

    // A skin: the mesh stays where its node puts it, which glTF does not.
    let mut v = triangle.clone();
    v["nodes"] = json!([{"mesh": 0, "skin": 0}, {}]);
    v["skins"] = json!([{"joints": [1]}]);
    let m = messages(&v, "Triangle (skin)");
    assert!(has(&m, "nodes[0]: skinning is ignored: the mesh is placed by its node's transform"), "{m:?}");

    // Animations, and a scene with nothing to render.
    let mut v = triangle.clone();
    v["animations"] = json!([{
        "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}],
        "samplers": [{"input": 0, "output": 1}]
    }]);
    let m = messages(&v, "Triangle (animated)");
    assert!(has(&m, "animations: 1 animation(s) ignored: the static pose is rendered"), "{m:?}");
    assert!(!has(&m, "no surfaces"), "{m:?}");
    v["scenes"][0]["nodes"] = json!([]);
    let m = messages(&v, "Triangle (empty scene)");
    assert!(has(&m, "scenes: the scene has no surfaces to render"), "{m:?}");
}

/// glTF's nodes form disjoint trees (glTF 2.0, 3.5.3 "Node hierarchy": no
/// node is the child of two parents or a root and a child). A node reached
/// twice is an error that names it: walked as given, a chain of nodes each
/// listing its child twice is a walk of 2^depth nodes (it hung the loader).
#[test]
fn a_node_reached_twice_is_an_error() {
    let v = read_json(&dir().join("Triangle.gltf"));
    let with = |nodes: Value, roots: Value| {
        let mut v = v.clone();
        v["nodes"] = nodes;
        v["scenes"][0]["nodes"] = roots;
        v
    };
    let cases = [
        ("twice a child", json!([{"children": [1, 1]}, {"mesh": 0}]), json!([0]), "nodes[1]"),
        ("root and child", json!([{"children": [1]}, {"mesh": 0}]), json!([0, 1]), "nodes[1]"),
        ("twice a root", json!([{"mesh": 0}]), json!([0, 0]), "nodes[0]"),
        ("its own child", json!([{"mesh": 0, "children": [0]}]), json!([0]), "nodes[0]"),
    ];
    for (what, nodes, roots, node) in cases {
        let e = parse(&with(nodes, roots), what).err().unwrap_or_else(|| panic!("{what}: loaded"));
        assert!(e.contains(&format!("{node}: the node is reached twice")), "{what}: {e}");
    }
    let mut chain: Vec<Value> = (1..=64).map(|i| json!({"children": [i, i]})).collect();
    chain.push(json!({"mesh": 0}));
    let e = parse(&with(json!(chain), json!([0])), "chain").err().unwrap();
    assert!(e.contains("nodes[64]: the node is reached twice"), "{e}");
    // One node in the trees of two scenes is allowed: one scene renders.
    let mut two = with(json!([{"mesh": 0}]), json!([0]));
    two["scenes"] = json!([{"nodes": [0]}, {"nodes": [0]}]);
    assert!(parse(&two, "two scenes").is_ok());
}

/// An error in a `.gltf` file names the line and column of the element at
/// fault, as the JSON scene loader does (a `.glb` frames its JSON in binary
/// chunks: no line). The text is laid out by hand: `nodes[0]` is the `{}`
/// at line 5, column 5, and the required extension at line 3, column 26.
#[test]
fn gltf_errors_name_the_line() {
    let text = "{\n  \"asset\": {\"version\": \"2.0\"},\n  \"scenes\": [{\"nodes\": [0, 0]}],\n  \"nodes\": [\n    {}\n  ]\n}\n";
    let e = parse_gltf(text.as_bytes(), "x.gltf", &dir()).err().unwrap().to_string();
    assert!(e.starts_with("x.gltf:5:5: nodes[0]: the node is reached twice"), "{e}");
    let text = text.replace("\"scenes\": [{\"nodes\": [0, 0]}],", "\"extensionsRequired\": [\"EXT_x\"],");
    let e = parse_gltf(text.as_bytes(), "x.gltf", &dir()).err().unwrap().to_string();
    assert!(e.starts_with("x.gltf:3:26: extensionsRequired[0]: the file requires extension EXT_x"), "{e}");
    // A label whose path ends in a colon (an unnamed node's light).
    let text = "{\n  \"asset\": {\"version\": \"2.0\"},\n  \"extensionsUsed\": [\"KHR_lights_punctual\"],\n  \"extensions\": {\"KHR_lights_punctual\": {\"lights\": [{\"type\": \"point\", \"intensity\": 3.4e38}]}},\n  \"scenes\": [{\"nodes\": [0]}],\n  \"nodes\": [\n    {\"extensions\": {\"KHR_lights_punctual\": {\"light\": 0}}}\n  ]\n}\n";
    let e = parse_gltf(text.as_bytes(), "z.gltf", &dir()).err().unwrap().to_string();
    assert!(e.starts_with("z.gltf:7:5: nodes[0]: light"), "{e}");
    // A field the file lacks: the deepest part of its path that it has.
    let e = parse_gltf(b"{\"asset\": {\"version\": \"2.0\"}}", "y.gltf", &dir()).err().unwrap().to_string();
    assert!(e.starts_with("y.gltf:1:1: scenes: the file has no scene"), "{e}");
}

/// A glTF file may instance one mesh from many nodes: 135 nodes of a
/// million-triangle mesh (3 MB of one-byte indices) declare 135 million
/// triangles, more than `MAX_TRIANGLES` (2^27 = 134,217,728). The loader
/// counts them from the accessors before reading any, and names the node
/// that crosses the limit (it would have filled the memory first).
#[test]
fn instanced_meshes_beyond_the_triangle_limit_are_an_error() {
    let n = 3_000_000;
    let v = json!({
        "asset": {"version": "2.0"},
        "buffers": [{"uri": format!("data:application/octet-stream;base64,{}", "AAAA".repeat((n + 12) / 3)), "byteLength": n + 12}],
        "bufferViews": [{"buffer": 0, "byteLength": n}, {"buffer": 0, "byteOffset": n, "byteLength": 12}],
        "accessors": [
            {"bufferView": 0, "componentType": 5121, "count": n, "type": "SCALAR"},
            {"bufferView": 1, "componentType": 5126, "count": 1, "type": "VEC3", "min": [0, 0, 0], "max": [0, 0, 0]}
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 1}, "indices": 0}]}],
        "nodes": vec![json!({"mesh": 0}); 135],
        "scenes": [{"nodes": (0..135).collect::<Vec<_>>()}]
    });
    let e = parse(&v, "instanced").err().unwrap();
    assert!(
        e.contains("nodes[134]: the scene would hold 135000000 triangles, more than the 134217728 (2^27) prism builds"),
        "{e}"
    );
}

#[test]
fn json_scene_includes_gltf_with_material_overrides() {
    let scene_text = |materials: &str, material: &str| {
        format!(
            r#"{{
  "camera": {{"position": [0, 1, 4], "look_at": [0, 0, 0], "fov": 40, "width": 32, "height": 32}},
  "materials": {{"grey": {{"type": "diffuse", "reflectance": 0.5}}}},
  "objects": [
    {{"name": "box", "shape": {{"type": "gltf", "file": "Box.gltf", "materials": {materials}}}{material},
      "transform": {{"translate": [0, 0.5, 0]}}}},
    {{"shape": {{"type": "quad", "corners": [[-5, 0, -5], [-5, 0, 5], [5, 0, 5], [5, 0, -5]]}}, "material": "grey"}}
  ],
  "lights": [{{"type": "point", "position": [2, 4, 3], "intensity": 20}}]
}}"#
        )
    };
    let parse_json = |t: &str| parse_scene(t, "include.json", &dir()).map(|b| b.build()).map_err(|e| e.to_string());
    let scene = parse_json(&scene_text(r##"{"#0": "grey"}"##, "")).unwrap();
    // The box's 12 triangles, moved up by 0.5 (it spans [-0.5, 0.5]); the
    // override replaced the glTF metal by the scene's grey.
    assert_eq!(scene.triangle_count(), 12 + 2);
    assert_eq!(scene.materials.len(), 1);
    let hit = scene.intersect(&Ray::new(Vec3A::new(0.0, 3.0, 0.0), Vec3A::NEG_Y)).unwrap();
    assert!((hit.p.y - 1.0).abs() < 1e-5, "{}", hit.p);
    render_checked(&scene, "path", 4);

    // Without an override the glTF material maps itself (a conductor).
    let scene = parse_json(&scene_text("{}", "")).unwrap();
    assert!(scene.materials.iter().any(|m| matches!(m.bsdf(), Bsdf::Conductor(_))));
    // `material` replaces every glTF material.
    let scene = parse_json(&scene_text("{}", r#", "material": "grey""#)).unwrap();
    assert_eq!(scene.materials.len(), 1);

    let e = parse_json(&scene_text(r#"{"Gold": "grey"}"#, "")).err().unwrap();
    assert!(e.contains("objects[0].shape.materials.Gold") && e.contains("has no material \"Gold\" (known: #0)"), "{e}");
    let e = parse_json(&scene_text(r##"{"#0": "nosuch"}"##, "")).err().unwrap();
    assert!(e.contains("unknown material \"nosuch\""), "{e}");
    let e = parse_json(&scene_text("{}", "").replace("Box.gltf", "nosuch.gltf")).err().unwrap();
    assert!(e.contains("objects[0].shape.file") && e.contains("cannot read glTF file"), "{e}");
    let e = parse_json(&scene_text("{}", "").replace(r#""material": "grey""#, r#""comment": "x""#)).err().unwrap();
    assert!(e.contains("objects[1]: missing field `material`"), "{e}");

    // An included file's camera is not used, so its invalid aspect ratio,
    // which the file refuses on its own, does not stop the scene.
    let d = scenes::temp_dir("gltf-include-camera");
    let mut v = read_json(&dir().join("Cameras.gltf"));
    v["cameras"][0]["perspective"]["aspectRatio"] = json!(0.0);
    let file = d.join("cameras.gltf");
    std::fs::write(&file, v.to_string()).unwrap();
    let e = load_gltf(&file).err().unwrap().to_string();
    assert!(e.contains("aspectRatio 0 is not a positive number"), "{e}");
    let text = scene_text("{}", "").replace("Box.gltf", file.to_str().unwrap());
    parse_json(&text).unwrap();
    // Nor its yfov or its node's transform, which the file refuses on its
    // own too (they failed the include until session 50, an audit).
    for what in ["yfov 0", "a zero scale"] {
        let mut v = read_json(&dir().join("Cameras.gltf"));
        match what {
            "yfov 0" => v["cameras"][0]["perspective"]["yfov"] = json!(0.0),
            _ => {
                let n = v["nodes"].as_array().unwrap().iter().position(|n| n.get("camera").is_some()).unwrap();
                v["nodes"][n]["scale"] = json!([0.0, 0.0, 0.0]);
            }
        }
        std::fs::write(&file, v.to_string()).unwrap();
        assert!(load_gltf(&file).is_err(), "{what}: the file on its own loads");
        parse_json(&text).unwrap_or_else(|e| panic!("{what}: {e}"));
    }
    std::fs::remove_dir_all(&d).unwrap();
}

// ------------------------------------------------------------- Cornell box

/// Linear sRGB of a reflectance under D65 (the definition `rgb_albedo`
/// inverts, src/spectrum/rgb.rs).
fn reflectance_rgb(s: &Spectrum) -> [f32; 3] {
    let rgb = xyz_to_linear_srgb(spectrum_to_xyz(&s.scaled_by(&illuminant("D65").unwrap())));
    rgb.to_array().map(|c| c.clamp(0.0, 1.0))
}

/// Linear sRGB of an emission spectrum seen directly (the colour
/// `rgb_illuminant` reproduces).
fn emission_rgb(s: &Spectrum) -> [f32; 3] {
    xyz_to_linear_srgb(spectrum_to_xyz(s)).to_array().map(|c| c.max(0.0))
}

fn tabulated(v: &Value) -> Spectrum {
    let nums = |k: &str| v[k].as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32).collect::<Vec<_>>();
    let pts: Vec<(f32, f32)> = nums("wavelengths").into_iter().zip(nums("values")).collect();
    Spectrum::piecewise_linear(&pts)
}

/// The emissive colour as the export writes it: factor in [0, 1] and
/// strength, so that factor x strength (in f32, as the loader computes it)
/// is the light's RGB.
fn emissive_split(rgb: [f32; 3]) -> ([f32; 3], f32) {
    let m = rgb[0].max(rgb[1]).max(rgb[2]);
    (rgb.map(|c| c / m), m)
}

/// An f32 as the shortest decimal that reads back as the same f32 (what
/// glTF readers parse it into), instead of its exact f64 expansion.
fn num(x: f32) -> Value {
    json!(x.to_string().parse::<f64>().unwrap())
}

fn nums(x: &[f32]) -> Value {
    Value::Array(x.iter().map(|&v| num(v)).collect())
}

/// glTF JSON and binary buffer of scenes/cornell-box.json: one node and mesh
/// per object (same names, quads as triangles (0, 1, 2), (0, 2, 3) as the
/// JSON loader makes them), lengths in millimetres as in the source (glTF
/// nominally uses metres; radiance does not depend on scale), the camera as
/// a node at the pinhole rotated 180 degrees about y (glTF cameras look
/// down -z). Materials carry the RGB of each measured spectrum (reflectance
/// under D65; the light's colour with its luminance in
/// KHR_materials_emissive_strength) and, in `extras.prism`, the spectra
/// themselves.
fn cornell_export() -> (Value, Vec<u8>) {
    let src = read_json(&Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell-box.json"));
    let spectra = &src["spectra"];
    let reflectance_of = |material: &str| src["materials"][material]["reflectance"].as_str().unwrap().to_string();
    let mut materials = Vec::new();
    let mut material_index = std::collections::BTreeMap::new();
    for name in ["white", "red", "green"] {
        let spec = &spectra[reflectance_of(name)];
        let rgb = reflectance_rgb(&tabulated(spec));
        material_index.insert(name.to_string(), materials.len());
        materials.push(json!({
            "name": name,
            "pbrMetallicRoughness": {"baseColorFactor": nums(&[rgb[0], rgb[1], rgb[2], 1.0]), "metallicFactor": 0.0, "roughnessFactor": 1.0},
            "extras": {"prism": {"reflectance": spec}}
        }));
    }
    let (mut positions, mut indices) = (Vec::new(), Vec::new());
    let (mut nodes, mut meshes, mut accessors) = (Vec::new(), Vec::new(), Vec::new());
    for (i, o) in src["objects"].as_array().unwrap().iter().enumerate() {
        assert_eq!(o["shape"]["type"], "quad");
        let corners: Vec<[f32; 3]> = o["shape"]["corners"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| [0, 1, 2].map(|k| c[k].as_f64().unwrap() as f32))
            .collect();
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for c in &corners {
            for k in 0..3 {
                lo[k] = lo[k].min(c[k]);
                hi[k] = hi[k].max(c[k]);
            }
            positions.extend(c.iter().flat_map(|x| x.to_le_bytes()));
        }
        indices.extend([0u16, 1, 2, 0, 2, 3].iter().flat_map(|x| x.to_le_bytes()));
        let material = o["material"].as_str().unwrap();
        let material = match o.get("emission") {
            Some(e) => {
                assert_eq!(material, "white", "the light's material");
                let spec = &spectra[e.as_str().unwrap()];
                let (factor, strength) = emissive_split(emission_rgb(&tabulated(spec)));
                let white = &spectra[reflectance_of("white")];
                let base = reflectance_rgb(&tabulated(white));
                materials.push(json!({
                    "name": "light",
                    "pbrMetallicRoughness": {"baseColorFactor": nums(&[base[0], base[1], base[2], 1.0]), "metallicFactor": 0.0, "roughnessFactor": 1.0},
                    "emissiveFactor": nums(&factor),
                    "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": num(strength)}},
                    "extras": {"prism": {"reflectance": white, "emission": spec}}
                }));
                materials.len() - 1
            }
            None => material_index[material],
        };
        let name = o["name"].as_str().unwrap();
        nodes.push(json!({"name": name, "mesh": i}));
        meshes.push(json!({"name": name, "primitives": [{"attributes": {"POSITION": 2 * i}, "indices": 2 * i + 1, "material": material}]}));
        accessors.push(json!({"bufferView": 0, "byteOffset": 48 * i, "componentType": 5126, "count": 4, "type": "VEC3", "min": nums(&lo), "max": nums(&hi)}));
        accessors
            .push(json!({"bufferView": 1, "byteOffset": 12 * i, "componentType": 5123, "count": 6, "type": "SCALAR"}));
    }
    let cam = &src["camera"];
    let position: Vec<f32> = (0..3).map(|k| cam["position"][k].as_f64().unwrap() as f32).collect();
    assert!(cam["look_at"][2].as_f64().unwrap() > position[2] as f64, "the camera looks along +z");
    nodes
        .push(json!({"name": "camera", "camera": 0, "translation": nums(&position), "rotation": [0.0, 1.0, 0.0, 0.0]}));
    let fov = (cam["fov"].as_f64().unwrap() as f32).to_radians();
    let aspect = cam["width"].as_f64().unwrap() as f32 / cam["height"].as_f64().unwrap() as f32;
    let n_nodes = nodes.len();
    let (pos_len, idx_len) = (positions.len(), indices.len());
    let mut bin = positions;
    bin.extend(indices);
    let gltf = json!({
        "asset": {
            "version": "2.0",
            "generator": "prism tests/gltf.rs cornell_export, from scenes/cornell-box.json",
            "copyright": "Geometry, camera and spectra: Cornell University Program of Computer Graphics, 'Cornell Box Data'"
        },
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "scene": 0,
        "scenes": [{"name": "cornell-box", "nodes": (0..n_nodes).collect::<Vec<_>>()}],
        "nodes": nodes,
        "cameras": [{"name": "camera", "type": "perspective", "perspective": {"yfov": num(fov), "aspectRatio": num(aspect), "znear": 1.0}}],
        "meshes": meshes,
        "materials": materials,
        "accessors": accessors,
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": pos_len, "target": 34962},
            {"buffer": 0, "byteOffset": pos_len, "byteLength": idx_len, "target": 34963}
        ],
        "buffers": [{"byteLength": bin.len(), "uri": "cornell-box.bin"}]
    });
    (gltf, bin)
}

#[test]
fn cornell_export_is_current() {
    let (gltf, bin) = cornell_export();
    let (gltf_path, bin_path) = (dir().join("cornell-box.gltf"), dir().join("cornell-box.bin"));
    let current = read_json(&gltf_path) == gltf && std::fs::read(&bin_path).ok().as_ref() == Some(&bin);
    // PRISM_WRITE_GLTF rewrites stale files, and the test still fails on
    // them: with the variable set it would otherwise pass on any export.
    if !current && std::env::var_os("PRISM_WRITE_GLTF").is_some() {
        std::fs::write(&gltf_path, serde_json::to_string_pretty(&gltf).unwrap() + "\n").unwrap();
        std::fs::write(&bin_path, &bin).unwrap();
        panic!("the export was stale and is written anew: commit it and rerun");
    }
    assert!(current, "stale: rerun with PRISM_WRITE_GLTF=1");
}

const K: u32 = 16;
/// 256: at 64 the x1.02 control failed by a worst |z| of 5.9-9.9 over seed
/// offsets 0-5 against a threshold of 5.5, too close to pass some day; at
/// 256 by 12.2-17.8 over offsets 0-7.
const SPP: u32 = 256;
const BLOCK: u32 = 8;

/// Block statistics of `path` at `scenes::seed(base)`: the seed sweeps of
/// docs/validation.md move these renders too. Two renders compared differ
/// in base by less than 1000, so that one offset's passes of one are never
/// the next offset's of the other.
fn block_stats(scene: &Scene, base: u64) -> ColourStats {
    let passes = render_passes(scene, scenes::integrator("path").as_ref(), SPP, K, scenes::seed(base), 0);
    ColourStats::from_passes(&passes, 32, 32, BLOCK)
}

/// The z-test both ways: `a` and `b` agree, and `b` scaled by 1.02 (a
/// deliberate 2 % bias, the negative control) does not.
fn assert_agree_and_control_fails(what: &str, a: &ColourStats, b: &ColourStats) {
    let same = Verdict::versus(a, b, 1);
    eprintln!("{what}: {same}");
    assert!(same.passed(), "{what}: {same}");
    let biased = Verdict::versus(a, &b.scaled(1.02), 1);
    eprintln!("{what}, b x 1.02: {biased}");
    assert!(!biased.passed(), "{what}: the negative control passed: {biased}");
}

fn scene_at_32(mut b: prism::scene::SceneBuilder) -> Scene {
    b.set_resolution(32, 32).unwrap();
    b.build()
}

/// With its measured spectra (extras.prism) the export is the JSON scene:
/// the same spectra, triangles, camera, so at one seed the two render bit
/// for bit the same image. (Until session 49 this was a z-test of renders
/// at two seeds, which an import error of 0.1-0.2 % would have passed; an
/// audit.) The control: the JSON scene at another seed differs.
#[test]
fn cornell_gltf_with_spectra_matches_json_scene() {
    let gltf = scene_at_32(load("cornell-box.gltf").builder);
    let json = scenes::scene("cornell-box.json", 32, 32);
    assert_eq!(gltf.triangle_count(), json.triangle_count());
    assert_eq!(gltf.lights.len(), json.lights.len());
    let render = |s: &Scene, base: u64| {
        let pass = render_passes(s, scenes::integrator("path").as_ref(), 16, 1, scenes::seed(base), 0).remove(0);
        pass.into_iter().flatten().map(f32::to_bits).collect::<Vec<_>>()
    };
    let differ = |a: &[u32], b: &[u32]| a.iter().zip(b).filter(|(x, y)| x != y).count();
    let (g, j) = (render(&gltf, 1), render(&json, 1));
    assert_eq!(differ(&g, &j), 0, "the glTF export and the JSON scene render different images at one seed");
    assert!(differ(&j, &render(&json, 2)) > 0, "the control: another seed renders the same image");
}

/// What any other glTF reader sees: RGB only. Without the extras the export
/// must match a JSON variant of the box whose spectra are replaced by the
/// same RGB values (the measured spectra themselves cannot be compared: a
/// reflectance upsampled from RGB is metameric to the measured one under
/// D65, not under the box's warm light).
#[test]
fn cornell_gltf_rgb_matches_json_rgb_variant() {
    let mut v = read_json(&dir().join("cornell-box.gltf"));
    for m in v["materials"].as_array_mut().unwrap() {
        m.as_object_mut().unwrap().remove("extras");
    }
    let g = parse(&v, "cornell-box.gltf (no extras)").unwrap();
    let gltf = scene_at_32(g.builder);

    let mut src = read_json(&Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell-box.json"));
    for name in ["white", "red", "green"] {
        let rgb = reflectance_rgb(&tabulated(&src["spectra"][name]));
        src["spectra"][name] = json!({"rgb": rgb});
    }
    let (factor, strength) = emissive_split(emission_rgb(&tabulated(&src["spectra"]["light"])));
    src["spectra"]["light"] = json!({"rgb": factor.map(|c| c * strength)});
    let b = parse_scene(&src.to_string(), "cornell-box.json (rgb)", &dir()).unwrap_or_else(|e| panic!("{e}"));
    let json = scene_at_32(b);
    assert_agree_and_control_fails(
        "cornell glTF (RGB) vs JSON (RGB)",
        &block_stats(&gltf, 1),
        &block_stats(&json, 501),
    );
}

/// Invalid glTF the crate's validator lets through is named, not read one
/// way in silence (from an audit): TRS beside a matrix, a projective last
/// row, a strip of two vertices, a mesh without primitives, a version that
/// is not 2.x, an emissiveFactor above 1; indices with a byteStride, which
/// readers that ignore it would wind otherwise, are refused.
#[test]
fn invalid_constructs_are_named() {
    let warns = |edit: &dyn Fn(&mut Value), needle: &str| {
        let mut v = read_json(&dir().join("Triangle.gltf"));
        edit(&mut v);
        let g = parse(&v, "Triangle (edited)").unwrap_or_else(|e| panic!("{e}"));
        assert!(has(&g.messages, needle), "no {needle:?} in {:#?}", g.messages);
    };
    let matrix = json!([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]);
    warns(
        &|v| {
            v["nodes"][0]
                .as_object_mut()
                .unwrap()
                .extend([("matrix".into(), matrix.clone()), ("translation".into(), json!([1, 0, 0]))])
        },
        "nodes[0]: the node has a matrix and translation, rotation or scale: the matrix is used",
    );
    warns(
        &|v| v["nodes"][0]["matrix"] = json!([1, 0, 0, 0.5, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]),
        "the matrix's last row [0.5, 0.0, 0.0, 1.0] is not [0, 0, 0, 1]: dropped",
    );
    warns(
        &|v| {
            v["meshes"][0]["primitives"][0]["mode"] = json!(5);
            v["accessors"][0]["count"] = json!(2);
        },
        "2 vertices make no triangle (mode TriangleStrip)",
    );
    warns(&|v| v["asset"]["version"] = json!("1.0"), "asset.version: version 1.0 is not glTF 2.x: read as glTF 2.0");
    warns(
        &|v| {
            v["materials"] = json!([{"emissiveFactor": [2, 1, 1]}]);
            v["meshes"][0]["primitives"][0]["material"] = json!(0);
        },
        "emissiveFactor [2.0, 1.0, 1.0] is above 1 (invalid glTF",
    );
    let mut v = read_json(&dir().join("Triangle.gltf"));
    v["nodes"][0]["mesh"] = json!(1);
    v["meshes"].as_array_mut().unwrap().push(json!({"primitives": []}));
    let g = parse(&v, "Triangle (no primitives)").unwrap_or_else(|e| panic!("{e}"));
    assert!(has(&g.messages, "meshes[1]): the mesh has no primitives (glTF requires one)"), "{:#?}", g.messages);
    let mut v = read_json(&dir().join("Triangle.gltf"));
    v["bufferViews"][0]["byteStride"] = json!(4);
    let e = parse(&v, "Triangle (strided indices)").err().unwrap();
    assert!(e.contains("bufferViews[0] of the indices has a byteStride (only vertex attributes may)"), "{e}");
}

/// The crate's validation faults name their field and its line, as the
/// scene loader's do (from an audit: they read `invalid glTF: invalid
/// glTF: nodes[0].children[0]: Index out of bounds;` with no position), and
/// so does a missing required field.
#[test]
fn validation_faults_name_their_field_and_line() {
    let pretty = |v: &Value| serde_json::to_string_pretty(v).unwrap();
    let parse_pretty = |v: &Value| parse_gltf(pretty(v).as_bytes(), "t.gltf", &dir()).err().unwrap().to_string();
    let mut v = read_json(&dir().join("Triangle.gltf"));
    v["nodes"][0]["children"] = json!([9]);
    let line = pretty(&v).lines().position(|l| l.contains("\"children\"")).unwrap() + 2;
    let e = parse_pretty(&v);
    assert!(e.starts_with(&format!("t.gltf:{line}:")), "{e}");
    assert!(e.ends_with("nodes[0].children[0]: invalid glTF: index out of bounds"), "{e}");
    v["nodes"][0]["camera"] = json!(3);
    assert!(parse_pretty(&v).ends_with("invalid glTF: index out of bounds (and 1 more)"), "{}", parse_pretty(&v));
    let mut v = read_json(&dir().join("Triangle.gltf"));
    v.as_object_mut().unwrap().remove("asset");
    let lines = pretty(&v).lines().count();
    let e = parse_pretty(&v);
    assert!(e.starts_with(&format!("t.gltf:{lines}:1: not a valid glTF: missing field `asset`")), "{e}");
    // A path through a keyed field (the crate writes `attributes["POSITION"]`)
    // is located too (it was not until session 50, an audit).
    let mut v = read_json(&dir().join("Triangle.gltf"));
    let position = v["meshes"][0]["primitives"][0]["attributes"]["POSITION"].as_u64().unwrap() as usize;
    v["accessors"][position].as_object_mut().unwrap().remove("min");
    // (The path ends in the accessor's `min`, which the primitive's
    // POSITION only names: the line is that of `"POSITION"`.)
    let line = pretty(&v).lines().position(|l| l.contains("\"POSITION\"")).unwrap() + 1;
    let e = parse_pretty(&v);
    assert!(e.starts_with(&format!("t.gltf:{line}:")), "{e}");
    assert!(e.contains("attributes[\"POSITION\"]"), "{e}");
}

/// A file whose `asset.minVersion` is later than 2.0 does not load in a
/// glTF 2.0 reader (glTF 2.0, "asset"; it loaded without a word until
/// session 50, an audit); 2.0 itself does.
#[test]
fn a_later_min_version_is_refused() {
    let mut v = read_json(&dir().join("Triangle.gltf"));
    v["asset"]["version"] = json!("2.1");
    v["asset"]["minVersion"] = json!("2.1");
    let e = parse(&v, "Triangle (2.1)").err().unwrap();
    assert!(e.contains("asset.minVersion") && e.contains("needs glTF 2.1"), "{e}");
    v["asset"]["minVersion"] = json!("3.0");
    assert!(parse(&v, "Triangle (3.0)").err().unwrap().contains("needs glTF 3.0"));
    for fine in ["2.0", "1.0"] {
        v["asset"]["minVersion"] = json!(fine);
        parse(&v, fine).unwrap_or_else(|e| panic!("{fine}: {e}"));
    }
    // Not MAJOR.MINOR (the schema's pattern): warned of and ignored.
    for odd in ["2", "2.0.0", "+2.0", "garbage"] {
        v["asset"]["minVersion"] = json!(odd);
        let g = parse(&v, odd).unwrap_or_else(|e| panic!("{odd}: {e}"));
        assert!(has(&g.messages, "is not MAJOR.MINOR: ignored"), "{odd}: {:#?}", g.messages);
    }
}

/// Faults gltf-json's own validator does not catch safely: a POSITION
/// accessor index out of range (its validator indexes without a bounds
/// check and would panic) is a named error; factors outside [0, 1] (invalid
/// glTF) are clamped with a warning naming the material and the value.
#[test]
fn bad_accessor_indices_and_factors_are_reported() {
    let mut v = read_json(&dir().join("Triangle.gltf"));
    v["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(7);
    let e = parse(&v, "Triangle (POSITION 7)").err().unwrap();
    assert!(e.contains("meshes[0].primitives[0].attributes.POSITION: accessor 7 does not exist"), "{e}");

    let mut v = read_json(&dir().join("Box.gltf"));
    let pbr = &mut v["materials"][0]["pbrMetallicRoughness"];
    pbr["baseColorFactor"] = json!([-1.0, 2.0, 0.5, 1.0]);
    pbr["roughnessFactor"] = json!(-1.0);
    let g = parse(&v, "Box (factors out of range)").unwrap();
    assert!(has(&g.messages, "baseColorFactor [-1.0, 2.0, 0.5, 1.0] is outside [0, 1]"), "{:?}", g.messages);
    assert!(has(&g.messages, "roughnessFactor [-1.0] is outside [0, 1]"), "{:?}", g.messages);
    assert!(!has(&g.messages, "metallicFactor"), "{:?}", g.messages);
}

/// Accessors the glTF crate's reader would panic on or cut short: a
/// byteStride shorter than the element (it panicked), indices running past
/// their buffer view (read as no index list at all: the triangle soup of
/// the positions), a zero count, sparse accessors, whose indices are not
/// checked, and accessors without a buffer view, which glTF reads as zeros
/// and the reader as no data (indices without one would be the triangle
/// soup of the positions, normals without one flat shading). Each is an
/// error naming the accessor.
#[test]
fn accessor_layouts_outside_their_views_are_errors() {
    type Case = (&'static str, fn(&mut Value), &'static str);
    let cases: [Case; 5] = [
        (
            "POSITION stride 4",
            |v| v["bufferViews"][1]["byteStride"] = json!(4),
            "accessors[1]: bufferViews[1].byteStride 4 is shorter than its 12-byte elements",
        ),
        (
            "4 indices in a view of 3",
            |v| v["accessors"][0]["count"] = json!(4),
            "accessors[0]: 4 elements of 2 bytes every 2 from byteOffset 0 run past bufferViews[0] (6 bytes)",
        ),
        (
            "POSITION stride 16",
            |v| v["bufferViews"][1]["byteStride"] = json!(16),
            "accessors[1]: 3 elements of 12 bytes every 16 from byteOffset 0 run past bufferViews[1] (36 bytes)",
        ),
        ("POSITION count 0", |v| v["accessors"][1]["count"] = json!(0), "accessors[1]: count is 0"),
        (
            "sparse POSITION",
            |v| {
                let sparse = json!({"count": 1, "indices": {"bufferView": 0, "componentType": 5123}, "values": {"bufferView": 1}});
                v["accessors"][1]["sparse"] = sparse;
            },
            "accessors[1]: sparse accessors are not supported",
        ),
    ];
    for (what, edit, expected) in cases {
        let mut v = read_json(&dir().join("Triangle.gltf"));
        edit(&mut v);
        let e = parse(&v, what).err().unwrap_or_else(|| panic!("{what}: loaded"));
        assert!(e.contains(&format!("primitive 0: {expected}")), "{what}: {e}");
    }
    // Without a view (the crate's validation refuses these, with the
    // accessor's path and line, before `check_layout` could see them).
    for (file, accessor, what) in [("Triangle", 0, "indices"), ("Triangle", 1, "POSITION"), ("Box", 1, "NORMAL")] {
        let mut v = read_json(&dir().join(format!("{file}.gltf")));
        v["accessors"][accessor].as_object_mut().unwrap().remove("bufferView");
        let e = parse(&v, what).err().unwrap_or_else(|| panic!("{what} without a bufferView: loaded"));
        assert!(e.contains(&format!("accessors[{accessor}].bufferView: invalid glTF: missing data")), "{what}: {e}");
    }
}

/// glTF 2.0 (5.25): a node's rotation is a unit quaternion. The crate's
/// matrix of one that is not turns the mesh by another angle and scales it
/// across the axis (for (0, 0, 0.5, 0.5) it maps (1, 0, 0) to (0.5, 0.5,
/// 0)); it is normalised, with a warning, and a zero or infinite one is an
/// error. A rotation within rounding of unit length (the Khronos samples
/// write four digits) is read as before, without a word.
#[test]
fn a_rotation_of_other_than_unit_length_is_normalised_with_a_warning() {
    let rotated = |r: [f32; 4]| {
        let mut v = read_json(&dir().join("Triangle.gltf"));
        v["nodes"][0]["rotation"] = json!(r);
        parse(&v, "Triangle (rotated)")
    };
    let vertices = |g: GltfScene| g.builder.build().triangles().flat_map(|t| t.0).collect::<Vec<Vec3A>>();
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let unit = rotated([0.0, 0.0, h, h]).unwrap();
    assert!(!has(&unit.messages, "unit quaternion"), "{:?}", unit.messages);
    let short = rotated([0.0, 0.0, 0.5, 0.5]).unwrap();
    let warning = "nodes[0]: rotation [0.0, 0.0, 0.5, 0.5] is not a unit quaternion (length 0.707107): normalised";
    assert!(has(&short.messages, warning), "{:?}", short.messages);
    let (unit, short) = (vertices(unit), vertices(short));
    // Triangle.gltf's (1, 0, 0) turned a quarter about z is (0, 1, 0).
    assert!(unit.iter().any(|p| p.distance(Vec3A::Y) < 1e-6), "{unit:?}");
    assert_eq!(unit.len(), short.len());
    for (a, b) in short.iter().zip(&unit) {
        assert!(a.distance(*b) < 1e-6, "{a} against {b}");
    }
    let rounded = rotated([-0.383, 0.0, 0.0, 0.924]).unwrap(); // Cameras.gltf's
    assert!(!has(&rounded.messages, "unit quaternion"), "{:?}", rounded.messages);
    let e = rotated([0.0; 4]).err().expect("a zero rotation loaded");
    assert!(e.contains("nodes[0]: rotation [0.0, 0.0, 0.0, 0.0] is zero or not finite: not a rotation"), "{e}");
    let mut v = read_json(&dir().join("Triangle.gltf"));
    v["nodes"][0]["rotation"] = json!([0.0, 0.0, 1e39, 1.0]);
    let e = parse(&v, "Triangle (rotated)").err().expect("an infinite rotation loaded");
    assert!(e.contains("nodes[0]: rotation [0.0, 0.0, inf, 1.0] is zero or not finite"), "{e}");
}
