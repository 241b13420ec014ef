//! The agreement matrix (VALIDATION.md §3): on scenes where every estimator
//! can sample every light path, every pair of integrators agrees, and each
//! agrees with a stored high-spp reference (tests/references, made by the
//! command in its sidecar). Negative controls: a 2% bias and a dropped last
//! bounce are rejected by the same harness. Colours are compared by
//! `stats::Verdict` (the chi-square on luminance, worst z on each channel).

#[path = "common/scenes.rs"]
mod scenes;

use prism::integrators::{self, IntegratorOptions, INTEGRATORS};
use prism::reference::read_reference;
use prism::scene::{parse_scene, Scene};
use prism::stats::{render_passes, ColourStats, Verdict};
use scenes::{scene, seed};
use std::path::Path;

const K: u32 = 16;
const RES: u32 = 32;
const BLOCK: u32 = 8;

/// Samples per pixel per pass for each estimator: sized for ~equal noise,
/// and more where the controls need power or rare bright paths samples.
fn spp_for(scene: &str, integrator: &str) -> u32 {
    match (scene, integrator) {
        // On the box the controls need more (at 256 its x1.02 control
        // passed at seed offset 4: p 1.2e-3); on the glossy box 1024 spp
        // met a rare bright path at that offset (z 7.3) that 256 did not.
        ("cornell-box.json" | "cornell-dispersion.json", "simple_path") => 1024,
        (_, "simple_path") => 256,
        // Rare bright paths skew the pass means, and the rule's tails with
        // them: light tracing's splats from the rough glass in view, the
        // glossy box's blue at the top right, which only BSDF sampling
        // finds, and the dispersive caustic's single wavelengths. These
        // keep each estimator's false failures against exact values (by
        // bootstrap, `examples/test_size.rs`, a proxy for the pairwise
        // comparisons) within 2.7 times the rule's bound at the matrix's
        // family of 10, where 32 spp (128 for path and light on the
        // glossy box) were up to 13 times over it (docs/validation.md,
        // "The size of the rule").
        ("cornell-glossy.json", "path" | "light") => 512,
        ("cornell-glossy.json", "bdpt") => 128,
        // The dispersive caustics' single wavelengths: at 128 spp the
        // matrix's x1.05 control failed only at Y chi-square p 1e-5.
        ("cornell-dispersion.json", _) => 512,
        _ => 32,
    }
}

/// The colour statistics of K passes of `spp` samples of `integrator` on
/// `s`, seeds `seed(base)` onwards; the estimator must sample all of `s`.
fn estimate(s: &Scene, integrator: &str, options: &IntegratorOptions, spp: u32, base: u64) -> ColourStats {
    let integ = integrators::create(integrator, options).unwrap();
    assert!(integ.unsamplable(s).is_empty(), "{integrator} cannot sample the scene: {:?}", integ.unsamplable(s));
    ColourStats::from_passes(&render_passes(s, integ.as_ref(), spp, K, seed(base), 0), RES, RES, BLOCK)
}

/// `estimate` on a scene file of the suite at the matrix's samples.
fn stats(scene_file: &str, integrator: &str, max_depth: u32, base_seed: u64) -> ColourStats {
    let options = IntegratorOptions { max_depth, ..Default::default() };
    estimate(&scene(scene_file, RES, RES), integrator, &options, spp_for(scene_file, integrator), base_seed)
}

fn reference(scene_file: &str) -> ColourStats {
    let exr = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/references").join(scene_file.replace(".json", ".exr"));
    let (_, meta) = read_reference(&exr).unwrap_or_else(|e| panic!("{e:#}"));
    assert_eq!((meta.width, meta.height, meta.block), (RES, RES, BLOCK));
    meta.colour_stats().unwrap_or_else(|e| panic!("{e:#}"))
}

/// The matrix's comparisons, made together: each integrator against the
/// reference and against every other one.
fn matrix_family() -> usize {
    let n = INTEGRATORS.len();
    n + n * (n - 1) / 2
}

/// Every integrator against the reference and against every other one,
/// and each estimate scaled by `control` against the reference (the
/// negative control: it must be rejected).
fn matrix(scene_file: &str, control: f64) {
    let reference = reference(scene_file);
    // Seeds of their own (an audit, session 36): with one seed for all,
    // the estimators' first dimensions (wavelengths, pixel positions) were
    // the same numbers, their pass means correlated, and each z understated.
    let all: Vec<(&str, ColourStats)> = INTEGRATORS
        .iter()
        .enumerate()
        .map(|(k, i)| (i.name, stats(scene_file, i.name, 1024, 200 + 100 * k as u64)))
        .collect();
    let family = matrix_family();
    let mut failures = Vec::new();
    for (i, (name, s)) in all.iter().enumerate() {
        let c = Verdict::versus(s, &reference, family);
        eprintln!("{scene_file}: {name} vs reference: {c}");
        if !c.passed() {
            failures.push(format!("{name} vs reference: {c}"));
        }
        let c = Verdict::versus(&s.scaled(control), &reference, family);
        eprintln!("{scene_file}: {name} x{control} vs reference (negative control): {c}");
        if c.passed() {
            failures.push(format!("{name} x{control} went undetected: {c}"));
        }
        for (other, t) in &all[i + 1..] {
            let c = Verdict::versus(s, t, family);
            eprintln!("{scene_file}: {name} vs {other}: {c}");
            if !c.passed() {
                failures.push(format!("{name} vs {other}: {c}"));
            }
        }
    }
    assert!(failures.is_empty(), "{scene_file}:\n{}", failures.join("\n"));
}

/// The box's matrix sees a 2 % bias of each estimator (Y chi-square p
/// 9e-17 to 7e-54 at seed offset 0, against the family's 1e-4).
#[test]
fn agreement_matrix_cornell_box() {
    matrix("cornell-box.json", 1.02);
}

/// Rough gold and rough glass: glossy reflection, rough refraction seen by
/// the camera, caustics through rough glass. The control is 5 %: BSDF
/// sampling alone (simple_path) would not see 2 % here.
#[test]
fn agreement_matrix_cornell_glossy() {
    matrix("cornell-glossy.json", 1.05);
}

/// A dispersive (SF11) sphere seen only through diffuse bounces: paths through
/// it keep only their hero wavelength, in every estimator. The control is
/// 5 %: the caustics of single wavelengths are the weakest (at 128 spp a
/// 2 % bias passed for three estimators).
#[test]
fn agreement_matrix_cornell_dispersion() {
    matrix("cornell-dispersion.json", 1.05);
}

/// Rough dispersive glass: the dispersive box's SF11 sphere made rough
/// (roughness 0.5, GGX alpha 0.25). A rough dispersive interface is
/// sampled and evaluated at the hero wavelength only, so every path that
/// meets it keeps the hero alone, on the camera and the light subpaths
/// alike (`Scene::material_at`); light and bdpt agree with path. The other
/// dispersion tests have smooth glass only (an audit, session 43).
/// Controls: light and bdpt x1.05 are rejected; light tracing's subpath
/// walking on a copy of the wavelengths, so that its splats keep all four,
/// failed light vs path at z 42. With 256 spp for path and light the first
/// control passed at seed offset 63 (session 47: Y chi-square p 5.4e-4,
/// against 6.5e-6 to 6e-10 at offsets 0 and 59-66); path and light now
/// take 512.
#[test]
fn agreement_across_rough_dispersive_glass() {
    let s = scenes::scene_variant(
        "cornell-dispersion.json",
        RES,
        RES,
        "\"ior\": \"SF11\"",
        "\"ior\": \"SF11\", \"roughness\": 0.5",
    );
    light_and_bdpt_agree_with_path("rough dispersive glass", &s, [512, 128, 512], 70, 1.05);
}

/// The prism's rainbow (`scenes/prism-dispersion.json`): a nearly
/// collimated beam refracted twice by dispersive SF11 onto a diffuse
/// screen, every path of the rainbow keeping its hero wavelength alone.
/// Path tracing finds it only by threading a BSDF-sampled ray through the
/// prism back into the small light (unbiased, far too noisy to compare),
/// so light tracing and bdpt are compared with each other; before session
/// 43 the scene was in no test, and its slit light touched the tube's walls,
/// which bdpt's next-event estimation saw through (see the scene's comment:
/// this test failed, chi-square p 5e-4 to 2e-2 over four seeds). Control:
/// light x1.1 is rejected (x1.05 passed at one seed offset of four).
#[test]
fn light_and_bdpt_agree_on_the_prism_rainbow() {
    let s = scene("prism-dispersion.json", RES, RES);
    let stats = |name: &str, spp: u32, base: u64| estimate(&s, name, &IntegratorOptions::default(), spp, base);
    let light = stats("light", 4096, 80);
    let bdpt = stats("bdpt", 2048, 180);
    let c = Verdict::versus(&bdpt, &light, 1);
    eprintln!("prism rainbow: bdpt vs light: {c}");
    assert!(c.passed(), "bdpt vs light on the rainbow: {c}");
    let c = Verdict::versus(&light.scaled(1.1), &bdpt, 1);
    eprintln!("prism rainbow: light x1.1 vs bdpt (control): {c}");
    assert!(!c.passed(), "a 10% bias of light tracing passed: {c}");
}

/// The harness rejects a last bounce dropped (max depth 3 on the Cornell
/// box), for every integrator, against the stored reference, at the
/// matrix's family (its threshold; a 2 % bias is the box matrix's own
/// control). The matrix's samples, but a quarter of simple_path's: at 256
/// it is rejected at z 10-14, chi-square 262-269 over 16 blocks (seed
/// offsets 0, 92, 93; session 56), the others at z 28-67.
#[test]
fn agreement_negative_controls() {
    let reference = reference("cornell-box.json");
    let s = scene("cornell-box.json", RES, RES);
    let options = IntegratorOptions { max_depth: 3, ..Default::default() };
    for i in INTEGRATORS {
        let spp = spp_for("cornell-box.json", i.name).min(256);
        let c = Verdict::versus(&estimate(&s, i.name, &options, spp, 42), &reference, matrix_family());
        eprintln!("{} max depth 3: {c}", i.name);
        assert!(!c.passed(), "{}: dropped bounces passed: {c}", i.name);
    }
}

/// A depth cap is part of the estimand: every integrator counts scattering
/// events alike, so at max depth 2 (direct light and one bounce more) all of
/// them agree with path tracing on the Cornell box. Every other test runs at
/// depth 1024, where an off-by-one in one integrator's cap changes nothing
/// (BDPT's `s + t - 2 >= max_depth` for `>` passed the whole suite: z 91
/// here). Control: path at depth 3 is rejected against path at depth 2.
#[test]
fn every_integrator_agrees_at_a_small_max_depth() {
    let path = stats("cornell-box.json", "path", 2, 43);
    let family = INTEGRATORS.len();
    let mut failures = Vec::new();
    // Seeds 100 apart: each pass of K its own stream (as in `matrix`).
    for (k, i) in INTEGRATORS.iter().filter(|i| i.name != "path").enumerate() {
        let c = Verdict::versus(&stats("cornell-box.json", i.name, 2, 143 + 100 * k as u64), &path, family);
        eprintln!("max depth 2: {} vs path: {c}", i.name);
        if !c.passed() {
            failures.push(format!("{}: {c}", i.name));
        }
    }
    let c = Verdict::versus(&stats("cornell-box.json", "path", 3, 543), &path, family);
    eprintln!("control: path at max depth 3 vs 2: {c}");
    assert!(!c.passed(), "one bounce more went unnoticed: {c}");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Interpolated shading normals make transport non-reciprocal; with Veach's
/// correction for adjoint transport (SurfaceInteraction::shading_correction)
/// the estimators still agree. A smooth-shaded diffuse sphere in the Cornell
/// box, path tracing against BDPT and light tracing (VALIDATION.md §3). The
/// sphere is an icosahedron (subdivisions 0), large in the view, so that
/// shading normals stray far from the facets': with a finer, smaller sphere
/// dropping the correction moved blocks by at most 1 % and passed; here it
/// fails light vs path at z 9.1 (checked by removing it from src/path.rs).
/// Negative controls: light tracing and BDPT scaled by 1.02 are rejected.
#[test]
fn agreement_with_smooth_shading_normals() {
    let from = "\"name\": \"light\"";
    let sphere = "\"name\": \"ball\", \"shape\": {\"type\": \"sphere\", \"center\": [278.0, 200.0, 250.0], \"radius\": 150.0, \"subdivisions\": 0, \"smooth\": true}, \"material\": \"white\"}, {\"name\": \"light\"";
    let s = scenes::scene_variant("cornell-box.json", RES, RES, from, sphere);
    light_and_bdpt_agree_with_path("smooth normals", &s, [32, 32, 32], 50, 1.02);
}

/// Light tracing and bdpt each agree with path on `s` (a family of 2), and
/// each scaled by `bias` does not (the controls). `spp` are path's,
/// bdpt's and light's; their seeds start at `base`, `base + 100` and
/// `base + 200`.
fn light_and_bdpt_agree_with_path(what: &str, s: &Scene, spp: [u32; 3], base: u64, bias: f64) {
    let stats = |name: &str, spp: u32, base: u64| estimate(s, name, &IntegratorOptions::default(), spp, base);
    let path = stats("path", spp[0], base);
    let mut failures = Vec::new();
    for (name, spp, base) in [("bdpt", spp[1], base + 100), ("light", spp[2], base + 200)] {
        let st = stats(name, spp, base);
        let c = Verdict::versus(&st, &path, 2);
        eprintln!("{what}: {name} vs path: {c}");
        if !c.passed() {
            failures.push(format!("{name}: {c}"));
        }
        let c = Verdict::versus(&st.scaled(bias), &path, 2);
        eprintln!("{what}: {name} x{bias} vs path (control): {c}");
        if c.passed() {
            failures.push(format!("{name} scaled by {bias} passed: {c}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A two-sided emitter: the Cornell box's light hung edge-on to the camera
/// in the middle of the room, one face lighting the red wall, the other the
/// green one. `simple_path` finds emitters only by BSDF sampling, so it
/// shares no light-sampling density with the others; `path` (NEE: both
/// faces accepted, the same area pdf), `light` (emission from a face chosen
/// with probability 1/2) and `bdpt` (both, and the walk densities) must agree
/// with it. No other image test has a two-sided emitter: a forgotten 1/2 in
/// the face choice doubled light tracing's emission and passed the suite
/// (docs/validation.md, "Mutation testing"). Controls: the same light
/// one-sided (the green wall goes dark) and bdpt x1.02 are rejected.
#[test]
fn a_two_sided_emitter_agrees_across_integrators() {
    let ceiling = "[343.0, 548.7, 227.0],\n          [343.0, 548.7, 332.0],\n          [213.0, 548.7, 332.0],\n          [213.0, 548.7, 227.0]\n        ]\n      },\n      \"material\": \"white\",\n      \"emission\": \"light\"";
    let hung = |sides: &str| {
        let corners = "[278.0, 380.0, 100.0], [278.0, 500.0, 100.0], [278.0, 500.0, 230.0], [278.0, 380.0, 230.0]";
        let light = format!("{corners}]}}, \"material\": \"white\", \"emission\": \"light\"{sides}");
        scenes::scene_variant("cornell-box.json", RES, RES, ceiling, &light)
    };
    let (two, one) = (hung(", \"two_sided\": true"), hung(""));
    let stats =
        |s: &Scene, name: &str, spp: u32, base: u64| estimate(s, name, &IntegratorOptions::default(), spp, base);
    // (At a quarter of these samples bdpt's x1.02 control passed at seed
    // offset 5: p 1.1e-3.)
    let simple = stats(&two, "simple_path", 1024, 60);
    let mut failures = Vec::new();
    let [.., bdpt] = [("path", 160), ("light", 260), ("bdpt", 360)].map(|(name, base)| {
        let st = stats(&two, name, 128, base);
        let c = Verdict::versus(&st, &simple, 3);
        eprintln!("two-sided emitter: {name} vs simple_path: {c}");
        if !c.passed() {
            failures.push(format!("{name}: {c}"));
        }
        st
    });
    for (what, control) in [("one-sided", stats(&one, "path", 128, 460)), ("bdpt x1.02", bdpt.scaled(1.02))] {
        let c = Verdict::versus(&control, &simple, 3);
        eprintln!("two-sided emitter: {what} vs simple_path (control): {c}");
        if c.passed() {
            failures.push(format!("control {what} passed: {c}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Three kinds of light at once: the box's area light, a point light and a
/// constant sky entering through the open front, the camera inside the box
/// looking at the back wall (no sky in view, which light tracing could not
/// show). Each lights about a third of the room. Everywhere else the sky
/// and the point light are a scene's only light, so their selection
/// probability is 1 and a light subpath or next-event estimate that forgot
/// to divide by it (or used another light's) could not show; here the
/// alias table gives each a share of about a third. `light` and `bdpt`
/// agree with `path`. Controls: each x1.02 is rejected.
#[test]
fn point_area_and_environment_lights_together() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell-box.json");
    let mut text = std::fs::read_to_string(&path).unwrap();
    for (from, to) in [
        ("\"position\": [278.0, 273.0, -800.0]", "\"position\": [278.0, 273.0, 60.0]"),
        ("\"look_at\": [278.0, 273.0, 0.0]", "\"look_at\": [278.0, 273.0, 559.0]"),
        ("\"fov\": 39.3077", "\"fov\": 60"),
        (
            "\"render\": {",
            "\"lights\": [{\"type\": \"point\", \"position\": [400, 450, 350], \"intensity\": 120000}, \
             {\"type\": \"environment\", \"radiance\": 0.8}],\n  \"render\": {",
        ),
    ] {
        assert!(text.contains(from), "cornell-box.json has no {from}");
        text = text.replace(from, to);
    }
    let mut b = parse_scene(&text, "three lights", path.parent().unwrap()).unwrap_or_else(|e| panic!("{e}"));
    b.set_resolution(RES, RES).unwrap();
    let s = b.build();
    assert_eq!(s.lights.len(), 4, "two triangles of the area light, the point light and the sky");
    // (`estimate` asserts that no estimator warns: light tracing would of
    // sky in view, which it cannot show.)
    let stats = |name: &str, spp: u32, base: u64| estimate(&s, name, &IntegratorOptions::default(), spp, base);
    let path = stats("path", 128, 70);
    let mut failures = Vec::new();
    for (name, spp, base) in [("light", 512, 90), ("bdpt", 32, 110)] {
        let st = stats(name, spp, base);
        let c = Verdict::versus(&st, &path, 2);
        eprintln!("three lights: {name} vs path: {c}");
        if !c.passed() {
            failures.push(format!("{name}: {c}"));
        }
        let c = Verdict::versus(&st.scaled(1.02), &path, 2);
        eprintln!("three lights: {name} x1.02 vs path (control): {c}");
        if c.passed() {
            failures.push(format!("control {name} x1.02 passed: {c}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The camera and a diffuse floor below one rough glass interface (GGX,
/// alpha 0.3, eta 1.5), the light above it in air. Radiance crossing into
/// a denser medium grows by eta^2 (Veach 1997 §5.2; radiance-mode
/// refraction carries 1 / eta'^2, importance-mode does not): through a
/// closed glass object in air the factors of entering and leaving cancel,
/// here every path crosses once, so an estimator passing the wrong
/// transport mode (radiance walks in importance mode, or the reverse) would
/// be off by eta^2 = 2.25 against the others. Path, BDPT and light tracing
/// agree, and each scaled by 1.1 does not. (A BTDF whose two modes are swapped for every caller keeps the
/// estimators in agreement, each wrong by eta^2 the same way: that is
/// bsdf_props's `rough_transmission_eta2_only_in_radiance_mode` to catch.)
/// Premise control: with the interface turned over (camera and floor in
/// air, light in glass) path's image changes by ~eta^4; a BTDF without the
/// eta^2 factor is symmetric and would render both the same.
#[test]
fn agreement_across_one_rough_glass_interface() {
    let stats = |name: &str, spp: u32, flipped: bool, base: u64| {
        estimate(&one_interface(flipped), name, &IntegratorOptions::default(), spp, base)
    };
    let path = stats("path", 32, false, 60);
    let mut failures = Vec::new();
    for (name, spp, base) in [("bdpt", 32, 160), ("light", 32, 260)] {
        let st = stats(name, spp, false, base);
        let c = Verdict::versus(&st, &path, 2);
        eprintln!("one interface: {name} vs path: {c}");
        if !c.passed() {
            failures.push(format!("{name}: {c}"));
        }
        // The power to see a 10 % difference (an audit, session 49: the
        // test had only the premise control below). At 5 % the worst |z|
        // was ~5, below the threshold, and the control failed by the
        // chi-square alone (p ~2e-5).
        let c = Verdict::versus(&st.scaled(1.1), &path, 2);
        eprintln!("one interface: {name} x1.1 vs path (control): {c}");
        if c.passed() {
            failures.push(format!("control {name} x1.1 passed: {c}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    let c = Verdict::versus(&stats("path", 32, true, 360), &path, 1);
    eprintln!("one interface, turned over (premise control): {c}");
    assert!(!c.passed(), "turning the interface over changed nothing: {c}");
}

/// The scene of `agreement_across_one_rough_glass_interface`: the glass
/// quad's normal (its outside) points up, to the light, unless `flipped`.
fn one_interface(flipped: bool) -> Scene {
    use glam::Vec3A;
    use prism::camera::Camera;
    use prism::materials::{Bsdf, Dielectric, Diffuse};
    use prism::scene::SceneBuilder;
    use prism::shapes::Mesh;
    use prism::spectrum::Spectrum;
    let v = Vec3A::new;
    // Looking down at the floor: the view holds no grazing look at the
    // interface from below (its reflection of the floor there is a
    // caustic-like path that camera subpaths rarely find).
    let camera = Camera::new(v(0.0, 0.5, -1.5), v(0.0, -1.0, 0.5), Vec3A::Y, 50.0, RES, RES);
    let mut b = SceneBuilder::new(camera);
    let white = b.material("white", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.8))));
    let glass = b.material("glass", Bsdf::Dielectric(Dielectric::new(Spectrum::Constant(1.5), 0.3, 0.3)));
    let quad = |y: f32, r: f32| Mesh::quad([v(-r, y, -r), v(-r, y, r), v(r, y, r), v(r, y, -r)]);
    b.mesh("floor", quad(0.0, 3.0), white, None);
    let mut interface = quad(1.0, 4.0);
    if flipped {
        interface.flip();
    }
    b.mesh("interface", interface, glass, None);
    let mut lamp = quad(2.0, 0.5);
    lamp.flip();
    b.mesh("lamp", lamp, white, Some((Spectrum::Constant(5.0), false)));
    b.build()
}

/// BDPT through a rough interface of index near 1 (an audit, session 44):
/// at eta 1.0002 and alpha 0.01, alpha |eta - 1| = 2e-6, its connections
/// evaluated the refraction lobe at directions that rounding had moved by
/// a tenth of its width, and it read 16 % dark against `path` (28 % at
/// alpha 0.0025) in a room whose lamp shines through a glass sphere the
/// camera does not see. The loaders refuse such an interface
/// (`Dielectric::MIN_LOBE_WIDTH`); at the bound, alpha 0.25, BDPT agrees
/// with path. Control: the refused interface, built without a loader,
/// fails.
#[test]
fn bdpt_agrees_through_rough_glass_near_index_one() {
    let check = |alpha: f32, base: u64| {
        let (s, refused) = near_one_glass(alpha);
        let stats = |name: &str, base: u64| estimate(&s, name, &IntegratorOptions::default(), 32, base);
        let c = Verdict::versus(&stats("bdpt", base + 100), &stats("path", base), 2);
        eprintln!("glass of index 1.0002, alpha {alpha}: bdpt vs path: {c}");
        (c, refused)
    };
    let (c, refused) = check(0.25, 70);
    assert!(!refused && c.passed(), "at the bound: {c}");
    let (c, refused) = check(0.01, 370);
    assert!(refused, "control: alpha 0.01 is accepted");
    assert!(!c.passed(), "control: BDPT passed through an interface the loaders refuse: {c}");
}

/// The scene of `bdpt_agrees_through_rough_glass_near_index_one`, with its
/// glass sphere of index 1.0002 and `alpha`, and whether the loaders
/// refuse that glass.
fn near_one_glass(alpha: f32) -> (Scene, bool) {
    use glam::Vec3A;
    use prism::camera::Camera;
    use prism::materials::{Bsdf, Dielectric, Diffuse};
    use prism::scene::SceneBuilder;
    use prism::shapes::Mesh;
    use prism::spectrum::Spectrum;
    let v = Vec3A::new;
    let camera = Camera::new(v(0.0, 1.2, -0.9), v(0.0, 0.2, 0.6), Vec3A::Y, 50.0, RES, RES);
    let mut b = SceneBuilder::new(camera);
    let white = b.material("white", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.7))));
    let black = b.material("black", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.0))));
    let dielectric = Dielectric::new(Spectrum::Constant(1.0002), alpha, alpha);
    let refused = dielectric.index_unresolved();
    let glass = b.material("glass", Bsdf::Dielectric(dielectric));
    let mut room = Mesh::cuboid(v(-1.0, 0.0, -1.0), v(1.0, 2.0, 1.0));
    room.flip();
    b.mesh("room", room, white, None);
    let lamp = Mesh::quad([v(-0.3, 1.99, -0.3), v(0.3, 1.99, -0.3), v(0.3, 1.99, 0.3), v(-0.3, 1.99, 0.3)]);
    b.mesh("lamp", lamp, black, Some((Spectrum::Constant(5.0), false)));
    b.mesh("ball", Mesh::sphere(v(0.0, 1.55, -0.25), 0.3, 3, false), glass, None);
    (b.build(), refused)
}
