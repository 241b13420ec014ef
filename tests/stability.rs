//! Where methods fail (VALIDATION.md §5, TRANSPORT-NOTES.md §8): every
//! estimator, on scenes built to break it, never produces a NaN, infinite or
//! negative sample; warns about the path classes it cannot sample (naming
//! the material or light) and never on the Cornell box; and agrees with the
//! others (z-test, src/stats.rs, at a looser budget) wherever it can sample.
//!
//! - `scenes/mirror-view.json`: a mirror sphere seen directly. Path tracing,
//!   BDPT and simple_path agree everywhere; light tracing equals path tracing
//!   on pixels whose first hit is diffuse and is exactly black on the mirror.
//! - `scenes/caustic.json` and `scenes/gap-room.json`: no bad numbers from
//!   any integrator; agreement with BDPT where the estimator samples the
//!   scene's light well (see the test for which, and why not the others).
//! - `scenes/sds-point-light.json`: a point light, water, a pool floor seen
//!   through the water (L S D S E). The caustic is missing identically in
//!   every estimator: the water is exactly black in all of them, the rest
//!   agrees, and with an area light in place of the point light the floor
//!   does light up (so the black is the missing path class, not the scene).
//! - Bad numbers: degenerate and zero-area triangles, zero-length and
//!   flipped shading normals, grazing rays, roughness 0, eta 1, lights and
//!   the camera inside closed objects, 1x1 and 64x1 images.
//! - Self-intersection: the same lit floor and box at scales 1e-3, 1, 1e5,
//!   and rays leaving the floor never hit it again (the floor is a plane
//!   through the origin, so the origin offset alone cannot help: the
//!   intersection test's conservative t must).
//! - The film's range: colours that overflow f32 and pixel sums past the
//!   i128 range are counted as infinite, never written wrapped or zeroed.
//!
//! Samples are checked where the film checks them (DroppedSamples: NaN,
//! infinite, negative, per reason) and pixels in CIE XYZ: linear sRGB may be
//! legitimately negative for a non-negative spectrum outside its gamut, XYZ
//! never is.

#[path = "common/scenes.rs"]
mod scenes;

use glam::{DMat3, DVec3, Vec2, Vec3A};
use prism::film::Film;
use prism::geometry::{edge_margin, triangle_point, Ray, SurfacePoint};
use prism::integrators::{Integrator, INTEGRATORS};
use prism::light::{AreaLight, Light};
use prism::render::{render, RenderOptions};
use prism::sampling::uniform_triangle;
use prism::sampling::MisHeuristic;
use prism::scene::{parse_scene, Scene};
use prism::spectrum::{SampledWavelengths, Spectrum};
use prism::stats::{interior_pixels, masked, ColourStats, Image, Verdict};
use scenes::{bdpt, integrator, scene};
use std::path::Path;
use std::process::Command;

const K: u32 = 16;

fn seed() -> u64 {
    scenes::seeds::from_env("PRISM_TEST_SEED", 0x57AB)
}

fn all_integrators() -> Vec<(&'static str, Box<dyn Integrator>)> {
    INTEGRATORS.iter().map(|i| (i.name, integrator(i.name))).collect()
}

/// XYZ of a linear sRGB pixel (inverse of the standard matrix of
/// spectrum::xyz_to_linear_srgb).
fn xyz(p: [f32; 3]) -> DVec3 {
    let m = DMat3::from_cols_array(&[
        3.240_454_2,
        -0.969_266,
        0.055_643_4,
        -1.537_138_5,
        1.876_010_8,
        -0.204_025_9,
        -0.498_531_4,
        0.041_556,
        1.057_225_2,
    ]);
    m.inverse() * DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)
}

/// Panics unless every pixel is finite with non-negative X, Y and Z.
fn assert_sane(image: &[[f32; 3]], what: &str) {
    for (i, p) in image.iter().enumerate() {
        assert!(p.iter().all(|c| c.is_finite()), "{what}: pixel {i} is not finite: {p:?}");
        let v = xyz(*p);
        let tol = 1e-5 * v.abs().max_element().max(1e-3);
        assert!(v.min_element() >= -tol, "{what}: pixel {i} is negative in XYZ: {v} (sRGB {p:?})");
    }
}

/// One render of `spp` samples; panics if the film dropped any sample or a
/// pixel is not sane.
fn render_checked(s: &Scene, integ: &dyn Integrator, spp: u32, seed: u64, what: &str) -> Image {
    let mut film = Film::new(s.camera.width, s.camera.height);
    render(s, integ, &RenderOptions { seed, threads: 0, progress: false }, &mut film, 0..spp);
    let d = film.dropped;
    assert_eq!(
        d.total(),
        0,
        "{what}: dropped samples: {} NaN, {} infinite, {} negative",
        d.nan,
        d.infinite,
        d.negative
    );
    let image = film.image();
    assert_sane(&image, what);
    image
}

/// `k` independent checked passes (seeds seed, seed + 1, ...).
fn passes_checked(s: &Scene, integ: &dyn Integrator, spp: u32, seed: u64, what: &str) -> Vec<Image> {
    (0..K).map(|i| render_checked(s, integ, spp, seed + i as u64, what)).collect()
}

/// A region of the view: its name, which first-hit materials belong to it,
/// and the fewest interior pixels a comparison needs there.
type Region<'a> = (&'a str, &'a dyn Fn(&str) -> bool, usize);

/// The interior pixels (`interior`) of regions of the view named by their
/// first-hit materials; panics unless each has at least its minimum count,
/// so that a changed scene cannot leave a comparison with nothing to compare.
fn regions<const N: usize>(s: &Scene, what: &str, regions: [Region; N]) -> [Vec<bool>; N] {
    regions.map(|(name, keep, min)| {
        let mask = interior_pixels(s, 4, keep);
        let n = mask.iter().filter(|&&m| m).count();
        eprintln!("{what}: {n} {name} pixels");
        assert!(n > min, "{what} should show more than {min} {name} pixels, not {n}");
        mask
    })
}

fn stats(passes: &[Image], s: &Scene, block: u32) -> ColourStats {
    ColourStats::from_passes(passes, s.camera.width, s.camera.height, block)
}

fn report(what: &str, c: &Verdict) {
    eprintln!("{what}: {c}");
}

// ------------------------------------------------------------------ warnings

fn warnings(name: &str, s: &Scene) -> Vec<String> {
    integrator(name).unsamplable(s)
}

#[test]
fn warnings_where_methods_fail() {
    let cornell = scene("cornell-box.json", 32, 32);
    let mirror = scene("mirror-view.json", 32, 32);
    let sds = scene("sds-point-light.json", 32, 32);
    for i in INTEGRATORS {
        let w = warnings(i.name, &cornell);
        assert!(w.is_empty(), "{}: warning on the Cornell box: {w:?}", i.name);
    }
    // Mirror seen directly: only light tracing, and it names the material.
    for i in INTEGRATORS {
        let w = warnings(i.name, &mirror);
        eprintln!("mirror-view, {}: {w:?}", i.name);
        if i.name == "light" {
            assert!(w.iter().any(|m| m.contains("chrome")), "light tracing does not name the mirror \"chrome\": {w:?}");
        } else {
            assert!(w.is_empty(), "{}: unexpected warning on mirror-view: {w:?}", i.name);
        }
    }
    // S-D-S with a point light: every estimator warns, naming the light;
    // those that warn about the specular chain also name the material.
    for i in INTEGRATORS {
        let w = warnings(i.name, &sds);
        eprintln!("sds-point-light, {}: {w:?}", i.name);
        assert!(w.iter().any(|m| m.contains("pool lamp")), "{}: the point light is not named: {w:?}", i.name);
        if i.name != "simple_path" {
            assert!(
                w.iter().any(|m| m.contains("pool lamp") && m.contains("water")),
                "{}: water not named: {w:?}",
                i.name
            );
        }
    }
    // A point light over diffuse surfaces only: nothing to warn about,
    // except that simple_path cannot hit a point light at all; nor when
    // the file defines a smooth glass that no object has (an audit found
    // the S-D-S warnings naming such a material).
    let text =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/sds-point-light.json")).unwrap();
    let text = text.replace(
        r#""water": { "type": "dielectric", "ior": 1.33 }"#,
        r#""water": { "type": "diffuse" }, "unused glass": { "type": "dielectric", "ior": 1.5 }"#,
    );
    let diffuse = parse_scene(&text, "sds-diffuse", Path::new(".")).unwrap().build();
    for i in INTEGRATORS {
        let w = warnings(i.name, &diffuse);
        assert_eq!(w.is_empty(), i.name != "simple_path", "{}: {w:?}", i.name);
    }
}

/// Light tracing names a mirror it cannot see however little of the image
/// the mirror covers: a strip one pixel high (row 128 of 256), which a grid
/// of 64 x 64 camera rays passed over without a warning. Control: the same
/// strip made diffuse gives no warning.
#[test]
fn light_tracing_names_a_mirror_strip_one_pixel_high() {
    let text = |material: &str| {
        format!(
            r#"{{
  "camera": {{"position": [0, 0, 0], "look_at": [0, 0, 5], "fov": 40, "width": 256, "height": 256}},
  "materials": {{"wall": {{"type": "diffuse", "reflectance": 0.5}}, "strip": {material}}},
  "objects": [
    {{"shape": {{"type": "quad", "corners": [[-5, -5, 8], [5, -5, 8], [5, 5, 8], [-5, 5, 8]]}}, "material": "wall"}},
    {{"shape": {{"type": "quad", "corners": [[-1, -0.012, 4.988], [1, -0.012, 4.988], [1, -0.002, 4.998], [-1, -0.002, 4.998]]}}, "material": "strip"}},
    {{"shape": {{"type": "quad", "corners": [[-3, 3, 2], [3, 3, 2], [3, 3, 8], [-3, 3, 8]]}}, "material": "wall", "emission": 5}}
  ]
}}"#
        )
    };
    let build = |material: &str| parse_scene(&text(material), "strip", Path::new(".")).unwrap().build();
    let w = warnings("light", &build(r#"{"type": "mirror"}"#));
    assert!(w.iter().any(|m| m.contains("material(s) strip in the camera's view")), "{w:?}");
    let w = warnings("light", &build(r#"{"type": "diffuse"}"#));
    assert!(w.is_empty(), "{w:?}");
}

/// `prism render` prints the warnings before rendering, on stderr, and none
/// (not even a dropped-sample warning) on the Cornell box.
#[test]
fn cli_prints_the_warnings() {
    let dir = scenes::temp_dir("stability-cli");
    let run = |scene: &str, integ: &str| {
        let out = dir.join(format!("{integ}.exr"));
        let o = Command::new(env!("CARGO_BIN_EXE_prism"))
            .args(["render", &format!("scenes/{scene}"), "--integrator", integ, "--spp", "1", "--width", "8"])
            .args(["--height", "8", "--quiet", "--out", out.to_str().unwrap()])
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .output()
            .unwrap();
        assert!(o.status.success(), "{scene} {integ}: {}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).to_string()
    };
    for i in INTEGRATORS {
        let e = run("cornell-box.json", i.name);
        assert!(!e.contains("warning"), "{}: {e}", i.name);
        let e = run("sds-point-light.json", i.name);
        assert!(e.lines().any(|l| l.starts_with("warning: ") && l.contains("pool lamp")), "{}: {e}", i.name);
    }
    let e = run("mirror-view.json", "light");
    assert!(e.lines().any(|l| l.starts_with("warning: ") && l.contains("chrome")), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

// ---------------------------------------------------------------- mirror-view

#[test]
fn mirror_seen_directly() {
    const RES: u32 = 32;
    const BLOCK: u32 = 8;
    let s = scene("mirror-view.json", RES, RES);
    let [diffuse, mirror] = regions(
        &s,
        "mirror-view",
        [("diffuse-first", &|n| n != "chrome" && !n.is_empty(), 300), ("mirror", &|n| n == "chrome", 30)],
    );

    let spp = |name: &str| match name {
        "simple_path" => 256,
        "path" => 64,
        "light" => 32,
        _ => 32,
    };
    let passes: Vec<(&str, Vec<Image>)> = INTEGRATORS
        .iter()
        .enumerate()
        .map(|(k, i)| {
            // Seeds 20 apart: no two estimators share a pass's stream.
            let base = seed() + 100 + 20 * k as u64;
            (i.name, passes_checked(&s, integrator(i.name).as_ref(), spp(i.name), base, i.name))
        })
        .collect();
    let get = |n: &str| &passes.iter().find(|(name, _)| *name == n).unwrap().1;
    let path = stats(get("path"), &s, BLOCK);

    // Light tracing is black on the mirror, in every pass.
    for (k, img) in get("light").iter().enumerate() {
        for (i, p) in img.iter().enumerate() {
            assert!(!mirror[i] || *p == [0.0; 3], "light pass {k}: mirror pixel {i} is {p:?}, not black");
        }
    }
    // ... while path tracing renders it.
    let mirror_mean: f64 =
        get("path").iter().flat_map(|img| img.iter().zip(&mirror).filter(|(_, &m)| m)).map(|(p, _)| p[1] as f64).sum();
    assert!(mirror_mean > 0.0, "path tracing shows a black mirror");

    let family = 3;
    let mut failures = Vec::new();
    for (name, mask) in [("bdpt", None), ("simple_path", None), ("light", Some(&diffuse))] {
        let (a, b) = match mask {
            None => (stats(get(name), &s, BLOCK), path.clone()),
            Some(m) => (stats(&masked(get(name), m), &s, BLOCK), stats(&masked(get("path"), m), &s, BLOCK)),
        };
        let c = Verdict::versus(&a, &b, family);
        report(
            &format!("mirror-view {name} vs path{}", if mask.is_some() { " (diffuse-first pixels)" } else { "" }),
            &c,
        );
        if !c.passed() {
            failures.push(format!("{name}: {c}"));
        }
        // Negative control: a 5% bias is rejected at this budget.
        let c = Verdict::versus(&a.scaled(1.05), &b, family);
        report(&format!("  negative control {name} x1.05"), &c);
        assert!(!c.passed(), "{name}: a 5% bias went undetected: {c}");
    }
    // Light tracing over the whole image must DISAGREE (its mirror is black).
    let c = Verdict::versus(&stats(get("light"), &s, BLOCK), &path, family);
    report("mirror-view light vs path, all pixels (must disagree)", &c);
    assert!(!c.passed(), "light tracing's black mirror went undetected: {c}");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

// ------------------------------------------------------ caustic and gap room

/// The caustic and the indirect-only gap room, where the estimators differ
/// most. Every integrator renders both without a dropped sample or a bad
/// pixel, and warns exactly where it cannot sample (light tracing: the
/// caustic scene's glass sphere seen directly). Those that sample the
/// scene's light well agree with BDPT (which samples every path of both) at
/// a looser budget (colour rule of `prism::stats::Verdict`), with a 5% bias
/// as the control (10% for path and light tracing in the gap room): light tracing on the
/// diffuse-first pixels of the caustic scene, path and light tracing in the
/// gap room. BDPT itself is checked for bad numbers only here (its run
/// against its own reference would compare the estimator with itself; its
/// agreement with the others is proven in tests/agreement.rs and
/// tests/bdpt.rs). Path tracing on the caustic and BSDF-only path
/// tracing on either reach the light only through rare BSDF-sampled hits of
/// a small emitter: at these budgets their block means are heavy-tailed (a
/// z of 14 at 128 spp that is noise: at 8192 spp path tracing and BDPT agree
/// within 2-4% on every block), so they are checked for bad numbers only;
/// their convergence is charted in docs/results.md.
#[test]
fn caustic_and_gap_room_agree_where_sampled() {
    const RES: u32 = 32;
    const BLOCK: u32 = 8;
    // (scene, integrator, spp, the bias its comparison with BDPT must
    // reject; None: bad numbers only). Path and light tracing in the gap
    // room are the noisiest of the compared: their control is 10%.
    let runs = [
        ("caustic.json", "simple_path", 64, None),
        ("caustic.json", "path", 64, None),
        ("caustic.json", "light", 128, Some(1.05)),
        ("caustic.json", "bdpt", 64, None),
        ("gap-room.json", "simple_path", 64, None),
        // 2048: at 512 path's rare bright paths (the light through the gap
        // by a BSDF sample) failed 4.9e-3 of bootstrap tests at a family of
        // 2 (`examples/test_size.rs`), 3.3 times the bound; 2.0e-3 at 2048
        // (at this test's family of 3, about 1.5e-3 against ~1e-3).
        ("gap-room.json", "path", 2048, Some(1.10)),
        ("gap-room.json", "light", 512, Some(1.10)),
        ("gap-room.json", "bdpt", 128, None),
    ];
    let family = runs.iter().filter(|r| r.3.is_some()).count();
    let mut failures = Vec::new();
    for file in ["caustic.json", "gap-room.json"] {
        let s = scene(file, RES, RES);
        let reference = passes_checked(&s, integrator("bdpt").as_ref(), 256, seed() + 300, "bdpt reference");
        let diffuse = interior_pixels(&s, 4, |n| n != "glass" && !n.is_empty());
        for &(_, name, spp, control) in runs.iter().filter(|r| r.0 == file) {
            let integ = integrator(name);
            let warns = !integ.unsamplable(&s).is_empty();
            assert_eq!(warns, file == "caustic.json" && name == "light", "{file}, {name}: {:?}", integ.unsamplable(&s));
            let passes = passes_checked(&s, integ.as_ref(), spp, seed() + 400, &format!("{file} {name}"));
            let Some(control) = control else {
                continue;
            };
            let colour = |p: &[Image]| ColourStats::from_passes(p, RES, RES, BLOCK);
            let (a, b) = if warns {
                (colour(&masked(&passes, &diffuse)), colour(&masked(&reference, &diffuse)))
            } else {
                (colour(&passes), colour(&reference))
            };
            let v = Verdict::versus(&a, &b, family);
            eprintln!("{file} {name} vs bdpt{}: {v}", if warns { " (diffuse-first pixels)" } else { "" });
            if !v.passed() {
                failures.push(format!("{file} {name}: {v}"));
            }
            let c = Verdict::versus(&a.scaled(control), &b, family);
            eprintln!("  negative control {file} {name} x{control}: {c}");
            if c.passed() {
                failures.push(format!("{file} {name}: a bias x{control} went undetected: {c}"));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

// ----------------------------------------------------------------- veach-mis

/// Tiny lights on glossy plates (Veach's MIS scene: lights of radius 0.5 down
/// to 0.02, 25x smaller, 2000x brighter, over plates from nearly smooth to
/// rough), where each sampling technique alone fails somewhere: light
/// sampling on the smooth plates, BSDF sampling on the smallest light. The
/// estimators that combine them agree everywhere: path (NEE + BSDF sampling,
/// power heuristic) and bdpt with the power and balance heuristics; light tracing on
/// the pixels whose first hit is the diffuse backdrop (it reaches the plates'
/// highlights only by its rare light -> plate -> pinhole connections).
/// simple_path, which must hit a 0.02 light by BSDF sampling, and bdpt with
/// uniform weights are checked for bad numbers only (their block means are
/// heavy-tailed here).
type Run<'a> = (&'a str, Box<dyn Integrator>, u32, Option<&'a [bool]>);

#[test]
fn tiny_lights_on_glossy_plates_agree_where_combined() {
    const RES: u32 = 32;
    const BLOCK: u32 = 8;
    let s = scene("veach-mis.json", RES, RES);
    let [backdrop, _] =
        regions(&s, "veach-mis", [("backdrop", &|n| n == "backdrop", 200), ("plate", &|n| n.starts_with("plate"), 20)]);
    for (name, integ) in all_integrators() {
        assert!(integ.unsamplable(&s).is_empty(), "{name} warns on veach-mis: {:?}", integ.unsamplable(&s));
    }
    passes_checked(&s, integrator("simple_path").as_ref(), 64, seed() + 500, "veach-mis simple_path");
    // Uniform weights give the strategies that find the tiny lights rarely
    // their full share, so their pass means are heavy-tailed: at 256 spp the
    // uniform heuristic failed against path at PRISM_TEST_SEED 31676 and
    // 110866 (sRGB z 9.7 and 8.1), and at 1024 spp a bootstrap of 256
    // passes (`examples/test_size.rs`) still fails 1.1e-2 of its tests, 15
    // times the bound. Bad numbers only here; its unbiasedness is proven on
    // the Cornell box (bdpt.rs, `uniform_and_balance_mis_are_unbiased`).
    passes_checked(&s, bdpt(MisHeuristic::Uniform).as_ref(), 64, seed() + 550, "veach-mis bdpt --mis uniform");
    let path = passes_checked(&s, integrator("path").as_ref(), 256, seed() + 600, "veach-mis path");
    // (label, estimator, spp, the pixels compared: None for all).
    let others: [Run; 3] = [
        ("bdpt", integrator("bdpt"), 128, None),
        ("bdpt --mis balance", bdpt(MisHeuristic::Balance), 128, None),
        ("light", integrator("light"), 256, Some(&backdrop)),
    ];
    let family = others.len();
    let colour = |p: &[Image]| ColourStats::from_passes(p, RES, RES, BLOCK);
    let mut failures = Vec::new();
    for (name, integ, spp, mask) in &others {
        let passes = passes_checked(&s, integ.as_ref(), *spp, seed() + 700, &format!("veach-mis {name}"));
        let (a, b) = match mask {
            None => (colour(&passes), colour(&path)),
            Some(m) => (colour(&masked(&passes, m)), colour(&masked(&path, m))),
        };
        let v = Verdict::versus(&a, &b, family);
        eprintln!("veach-mis {name} vs path{}: {v}", if mask.is_some() { " (backdrop pixels)" } else { "" });
        if !v.passed() {
            failures.push(format!("{name}: {v}"));
        }
        let c = Verdict::versus(&a.scaled(1.05), &b, family);
        eprintln!("  negative control {name} x1.05: {c}");
        if c.passed() {
            failures.push(format!("{name}: a 5% bias went undetected: {c}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

// ------------------------------------------------------------ sds-point-light

#[test]
fn sds_caustic_is_missing_identically() {
    const RES: u32 = 32;
    const BLOCK: u32 = 8;
    let s = scene("sds-point-light.json", RES, RES);
    let [water, deck] =
        regions(&s, "sds-point-light", [("water", &|n| n == "water", 100), ("deck", &|n| n == "deck", 100)]);

    let spp = |name: &str| if name == "light" { 64 } else { 32 };
    let passes: Vec<(&str, Vec<Image>)> = INTEGRATORS
        .iter()
        .enumerate()
        .map(|(k, i)| {
            let base = seed() + 200 + 20 * k as u64;
            (i.name, passes_checked(&s, integrator(i.name).as_ref(), spp(i.name), base, i.name))
        })
        .collect();
    // Through the water every estimator shows exactly nothing: the caustic
    // (L S D S E) and the light's reflection (E S L) are missing in all.
    for (name, ps) in &passes {
        for img in ps {
            for (i, p) in img.iter().enumerate() {
                assert!(!water[i] || *p == [0.0; 3], "{name}: water pixel {i} is {p:?}, not black");
            }
        }
    }
    // simple_path cannot hit a point light: everything is black.
    let simple = &passes.iter().find(|(n, _)| *n == "simple_path").unwrap().1;
    assert!(simple.iter().flatten().all(|p| *p == [0.0; 3]), "simple_path found light from a point light");
    // The deck is lit directly (D L): path, light and bdpt agree everywhere.
    let st: Vec<(&str, ColourStats)> = passes
        .iter()
        .filter(|(n, _)| *n != "simple_path")
        .map(|(n, ps)| (*n, ColourStats::from_passes(ps, RES, RES, BLOCK)))
        .collect();
    let path_passes = &passes.iter().find(|(n, _)| *n == "path").unwrap().1;
    let deck_mean: f64 =
        path_passes.iter().flat_map(|img| img.iter().zip(&deck).filter(|(_, &m)| m)).map(|(p, _)| p[1] as f64).sum();
    assert!(deck_mean > 0.0, "the deck is black");
    let family = 3;
    let mut failures = Vec::new();
    for i in 0..st.len() {
        for j in i + 1..st.len() {
            let v = Verdict::versus(&st[i].1, &st[j].1, family);
            eprintln!("sds {} vs {}: {v}", st[i].0, st[j].0);
            if !v.passed() {
                failures.push(format!("{} vs {}: {v}", st[i].0, st[j].0));
            }
        }
    }
    let v = Verdict::versus(&st[0].1.scaled(1.05), &st[1].1, family);
    eprintln!("  negative control x1.05: {v}");
    assert!(!v.passed(), "a 5% bias went undetected: {v}");
    assert!(failures.is_empty(), "{}", failures.join("\n"));

    // Control: a small area light in place of the point light makes the
    // pool floor visible through the water for path tracing and BDPT, so the
    // black above is the missing path class, not a scene that blocks light.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/sds-point-light.json");
    let text = std::fs::read_to_string(&path).unwrap();
    let point = r#"{ "type": "point", "name": "pool lamp", "position": [0.3, 2.5, 0.2], "intensity": 10 }"#;
    assert!(text.contains(point));
    let bulb = r#"{ "name": "bulb", "shape": { "type": "sphere", "center": [0.3, 2.5, 0.2], "radius": 0.15, "subdivisions": 2 }, "material": "black", "emission": 40 },
    { "name": "deck -x""#;
    let text = text.replace(point, "").replace(
        r#"{
      "name": "deck -x""#,
        bulb,
    );
    let mut b = parse_scene(&text, "sds-area", path.parent().unwrap()).unwrap_or_else(|e| panic!("{e}"));
    b.set_resolution(16, 16).unwrap();
    let area = b.build();
    assert!(warnings("path", &area).is_empty() && warnings("bdpt", &area).is_empty());
    let water = interior_pixels(&area, 4, |n| n == "water");
    for name in ["path", "bdpt"] {
        let img = render_checked(&area, integrator(name).as_ref(), 256, seed() + 300, name);
        let lit = img.iter().zip(&water).filter(|(p, &m)| m && xyz(**p).y > 0.0).count();
        let n = water.iter().filter(|&&m| m).count();
        eprintln!("area-light control, {name}: {lit} of {n} water pixels lit");
        assert!(n > 20 && lit * 4 > n, "{name}: with an area light the pool floor should show through the water");
    }
}

// --------------------------------------------------------------- bad numbers

/// A lit stage (floor, back wall, a 1x1 area light facing down) with extra
/// materials, objects and lights, and an optional camera override.
fn stage(materials: &str, objects: &str, lights: &str, camera: Option<&str>) -> String {
    let camera =
        camera.unwrap_or(r#"{"position": [0, 1, -3], "look_at": [0, 0.7, 0], "fov": 45, "width": 16, "height": 16}"#);
    format!(
        r#"{{
  "camera": {camera},
  "materials": {{
    "white": {{"type": "diffuse", "reflectance": 0.7}},
    "black": {{"type": "diffuse", "reflectance": 0}}{materials}
  }},
  "objects": [
    {{"name": "floor", "shape": {{"type": "quad", "corners": [[-2, 0, -2], [-2, 0, 2], [2, 0, 2], [2, 0, -2]]}}, "material": "white"}},
    {{"name": "wall", "shape": {{"type": "quad", "corners": [[-2, 0, 2], [-2, 3, 2], [2, 3, 2], [2, 0, 2]]}}, "material": "white"}},
    {{"name": "lamp", "shape": {{"type": "quad", "corners": [[-0.5, 2.5, -0.5], [0.5, 2.5, -0.5], [0.5, 2.5, 0.5], [-0.5, 2.5, 0.5]]}},
     "material": "black", "emission": 5}}{objects}
  ],
  "lights": [{lights}]
}}"#
    )
}

/// Renders `text` with every integrator and checks every sample.
fn all_sane(case: &str, text: &str, spp: u32) {
    let b = parse_scene(text, case, Path::new(".")).unwrap_or_else(|e| panic!("{case}: {e}"));
    let s = b.build();
    for (name, integ) in all_integrators() {
        render_checked(&s, integ.as_ref(), spp, seed() + 400, &format!("{case}, {name}"));
    }
}

#[test]
fn bad_numbers_degenerate_geometry() {
    let mesh = |positions: &str, normals: &str, extra: &str| {
        format!(
            r#",
    {{"shape": {{"type": "mesh", "positions": {positions}, "indices": [[0, 1, 2], [0, 2, 3]], "normals": {normals}}}, "material": "white"{extra}}}"#
        )
    };
    let quad = "[[-0.6, 0.2, -0.5], [-0.6, 1.2, -0.3], [0.6, 1.2, -0.3], [0.6, 0.2, -0.5]]";
    let degenerate = [
        // zero-area triangles: collinear, repeated vertices, one point; an
        // emitting zero-area triangle; a needle of area ~1e-14.
        mesh("[[0, 0.5, 0], [0.5, 0.5, 0], [1, 0.5, 0], [1.5, 0.5, 0]]", "[]", ""),
        mesh("[[0, 1, 0], [0, 1, 0], [0.5, 1.5, 0], [0.5, 1.5, 0]]", "[]", ""),
        mesh("[[0.2, 0.2, 0.2], [0.2, 0.2, 0.2], [0.2, 0.2, 0.2], [0.2, 0.2, 0.2]]", "[]", ""),
        mesh("[[-1, 0.5, 0], [-0.5, 0.5, 0], [0, 0.5, 0], [0.5, 0.5, 0]]", "[]", r#", "emission": 5"#),
        mesh(
            "[[0, 0.5, -0.5], [1e-7, 0.5, -0.5], [0, 0.5000001, -0.5], [0, 0.5, -0.5]]",
            "[]",
            r#", "emission": 1000"#,
        ),
    ]
    .concat();
    all_sane("zero-area triangles", &stage("", &degenerate, "", None), 16);

    // A sphere flattened onto the floor (a disk of two faces 1e-20 above
    // it): segments 1e-20 long beside ones of units put density ratios
    // beyond f32 (bdpt's MIS weights were NaN, `ratios`).
    let flat = r#",
    {"shape": {"type": "sphere", "center": [0, 2, 0], "radius": 0.8, "subdivisions": 3}, "material": "white",
     "transform": {"scale": [1, 1e-20, 1]}}"#;
    all_sane("sphere flattened onto the floor", &stage("", flat, "", None), 16);

    // Shading normals: all zero; one zero; opposite to the geometric normal;
    // zero under a transform (normalised to NaN); perpendicular to the surface.
    let zero = "[[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]]";
    let one_zero = "[[0, 0.2, -1], [0, 0, 0], [0, 0.2, -1], [0, 0.2, -1]]";
    let flipped = "[[0, -0.2, 1], [0, -0.2, 1], [0, -0.2, 1], [0, -0.2, 1]]";
    let transform = r#", "transform": {"scale": [1, 0.5, 1], "rotate": {"axis": [0, 1, 0], "degrees": 20}}"#;
    for (case, normals, extra) in [
        ("zero normals", zero, ""),
        ("one zero normal", one_zero, ""),
        ("flipped normals", flipped, ""),
        ("zero normals, transformed", zero, transform),
        ("normals in the surface plane", "[[1, 0, 0], [1, 0, 0], [1, 0, 0], [1, 0, 0]]", ""),
    ] {
        for (mat, def) in [
            ("white", ""),
            ("glass", r#", "glass": {"type": "dielectric", "ior": 1.5}"#),
            ("rough", r#", "rough": {"type": "conductor", "metal": "Au", "roughness": 0.4}"#),
        ] {
            let obj = mesh(quad, normals, extra).replace("\"white\"", &format!("\"{mat}\""));
            all_sane(&format!("{case} ({mat})"), &stage(def, &obj, "", None), 16);
        }
    }
}

/// An emitter in another surface's plane is named (`Scene::
/// emitters_on_surfaces`): the stage's lamp (y = 2.5, x and z in
/// [-0.5, 0.5], facing down) under a ceiling in its plane, and under a
/// second lamp laid on it facing up (the two-sided lamp an audit built
/// so, whose upper side `path` lost); controls: each 0.01 above it, and
/// each as a panel in its plane that only shares its edge x = 0.5.
#[test]
fn an_emitter_in_a_surface_is_named() {
    let warning = |corners: &str, emission: &str| {
        let objects = format!(
            r#",
    {{"name": "ceiling", "shape": {{"type": "quad", "corners": {corners}}}, "material": "white"{emission}}}"#
        );
        let text = stage("", &objects, "", None);
        parse_scene(&text, "coplanar", Path::new(".")).unwrap().build().emitters_on_surfaces()
    };
    let on = "[[-2, 2.5, -2], [-2, 2.5, 2], [2, 2.5, 2], [2, 2.5, -2]]";
    let above = "[[-2, 2.51, -2], [-2, 2.51, 2], [2, 2.51, 2], [2, 2.51, -2]]";
    let beside = "[[0.5, 2.5, -0.5], [0.5, 2.5, 0.5], [2, 2.5, 0.5], [2, 2.5, -0.5]]";
    let w = warning(on, "").unwrap_or_default();
    assert!(w.contains("\"lamp (triangle") && w.contains("a \"white\" surface"), "a lamp in the ceiling's plane: {w}");
    let w = warning(on, r#", "emission": 5"#).unwrap_or_default();
    assert!(w.contains("\"lamp (triangle") && w.contains("the emitter \"ceiling (triangle"), "a lamp on a lamp: {w}");
    for emission in ["", r#", "emission": 5"#] {
        assert_eq!(warning(above, emission), None, "a ceiling 0.01 above ({emission})");
        assert_eq!(warning(beside, emission), None, "a panel beside ({emission})");
    }
    // Triangles that only share an edge, whatever its direction: the
    // emitting walls of the mirror room, level and turned (their edges'
    // ends rounded apart on the edge's normal, and two triangles of a wall
    // were taken to overlap, before the spans were measured from the edge).
    let room = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/white-room-mirror.json"));
    let room = room.unwrap();
    let turned = room.replace(
        r#""inward": true"#,
        r#""inward": true}, "transform": {"rotate": {"axis": [1, 0.3, 0.2], "degrees": 37}"#,
    );
    for (case, text) in [("level", &room), ("turned", &turned)] {
        let s = parse_scene(text, case, Path::new(".")).unwrap().build();
        assert_eq!(s.emitters_on_surfaces(), None, "the {case} mirror room");
    }
    // Nor a T-junction (vertex 4 on the edge 3-5), turned, whose vertex
    // rounds a hair off its neighbour's edge (a review found it warned).
    let panel = r#",
    {"name": "panel", "shape": {"type": "mesh", "positions": [[0, 0, 0], [0.5, 0, 0], [1, 0, 0], [0, 1, 0], [0.5, 1, 0], [1, 1, 0], [0, 2, 0], [1, 2, 0]],
     "indices": [[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [3, 5, 7], [3, 7, 6]]}, "material": "white", "emission": 1,
     "transform": {"rotate": {"axis": [1, 0.3, 0.2], "degrees": 37}, "translate": [0.1, -0.2, 0.5]}}"#;
    let s = parse_scene(&stage("", panel, "", None), "t-junction", Path::new(".")).unwrap().build();
    assert_eq!(s.emitters_on_surfaces(), None, "a T-junction");
    // A lamp in a ceiling's plane, turned and moved to x = 2e4: its
    // vertices round there by ~2e-3, which render space keeps, and the
    // check must allow for it (it named nothing, and path read 30 % below
    // light; an audit, session 42).
    let far_scene = |far: &str, ceiling_y: f32| {
        let text = format!(
            r#"{{"camera": {{"position": [20000, -3, 0], "look_at": [20000, 0, 3], "fov": 40, "width": 8, "height": 8}},
  "materials": {{"white": {{"type": "diffuse", "reflectance": 0.7}}}},
  "objects": [
    {{"name": "ceiling", "shape": {{"type": "quad", "corners": [[-2, {ceiling_y}, -2], [-2, {ceiling_y}, 2], [2, {ceiling_y}, 2], [2, {ceiling_y}, -2]]}}, "material": "white", "transform": {far}}},
    {{"name": "lamp", "shape": {{"type": "quad", "corners": [[-0.5, 2.5, -0.5], [0.5, 2.5, -0.5], [0.5, 2.5, 0.5], [-0.5, 2.5, 0.5]]}},
     "material": "white", "emission": 5, "transform": {far}}}
  ]
}}"#
        );
        let s = parse_scene(&text, "far", Path::new(".")).unwrap().build();
        assert_ne!(s.render_shift, Vec3A::ZERO, "the scene was not moved: no test of the shift");
        s.emitters_on_surfaces()
    };
    let turned = r#"{"rotate": {"axis": [1, 2, 3], "degrees": 37}, "translate": [20000, 0, 0]}"#;
    let w = far_scene(turned, 2.5).unwrap_or_default();
    assert!(w.contains("\"lamp (triangle") && w.contains("a \"white\" surface"), "far and turned: {w}");
    // The shift rounds only its own axis: a ceiling 0.01 above, level and
    // moved along x, is no surface of the lamp's (a review found it named
    // when the shift widened the tolerance on every axis).
    assert_eq!(far_scene(r#"{"translate": [20000, 0, 0]}"#, 2.51), None, "far and level, 0.01 apart");
}

/// An emitting disk cut as a fan: every triangle lies in the plane and the
/// bounds of every other, and none overlaps another. Alone it is named
/// nowhere; flat on a panel, or on a ceiling cut into a grid, every one of
/// its triangles is, and so is each triangle of a quad lamp on a finely
/// cut ceiling. (The check once tested every pair of the fan's triangles,
/// 98 s for a fan of 64,000, an audit; its first bound charged the
/// ceiling's triangles too, and missed the fan of 128 on a grid of 10 x 10
/// and one of the quad's triangles on a grid of 200 x 200, a review.)
#[test]
fn an_emitting_fan_is_named_only_on_a_surface() {
    use prism::camera::Camera;
    use prism::materials::{Bsdf, Diffuse};
    use prism::scene::SceneBuilder;
    use prism::shapes::Mesh;
    use prism::spectrum::Spectrum;
    let v = Vec3A::new;
    let fan = |n: usize, r: f32, centre: Vec3A| {
        let rim = (0..n).map(|i| {
            let a = std::f32::consts::TAU * i as f32 / n as f32;
            centre + v(r * a.cos(), 0.0, r * a.sin())
        });
        let positions = std::iter::once(centre).chain(rim).collect();
        let indices = (0..n as u32).map(|i| [0, (i + 1) % n as u32 + 1, i + 1]).collect();
        Mesh { positions, normals: Vec::new(), indices }
    };
    // A ceiling at y = 2 over [-2, 2]^2 in cells x cells squares.
    let grid = |cells: u32| {
        let at = |i: u32| -2.0 + 4.0 * i as f32 / cells as f32;
        let positions = (0..=cells).flat_map(|j| (0..=cells).map(move |i| v(at(i), 2.0, at(j)))).collect();
        let k = |i: u32, j: u32| j * (cells + 1) + i;
        let indices = (0..cells)
            .flat_map(|j| {
                (0..cells).flat_map(move |i| {
                    [[k(i, j), k(i + 1, j), k(i + 1, j + 1)], [k(i, j), k(i + 1, j + 1), k(i, j + 1)]]
                })
            })
            .collect();
        Mesh { positions, normals: Vec::new(), indices }
    };
    let check = |lamp: Mesh, ceiling: Option<Mesh>| {
        let camera = Camera::new(v(0.0, 1.0, -3.0), v(0.0, 1.0, 0.0), Vec3A::Y, 45.0, 8, 8);
        let mut b = SceneBuilder::new(camera);
        let white = b.material("white", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.7))));
        if let Some(ceiling) = ceiling {
            b.mesh("ceiling", ceiling, white, None);
        }
        b.mesh("lamp", lamp, white, Some((Spectrum::Constant(5.0), false)));
        b.build().emitters_on_surfaces()
    };
    let named_all = |w: Option<String>, n: usize| {
        let w = w.unwrap_or_default();
        let all = if n == 1 { String::new() } else { format!("(and {} more", n - 1) };
        w.contains("\"lamp (triangle") && w.contains(&all) && w.contains("a \"white\" surface")
    };
    let origin = v(0.0, 2.0, 0.0);
    assert_eq!(check(fan(2000, 0.5, origin), None), None, "the fan alone");
    assert!(named_all(check(fan(2000, 0.5, origin), Some(grid(1))), 2000), "the fan on a panel");
    assert!(named_all(check(fan(128, 0.15, v(0.37, 2.0, 0.11)), Some(grid(10))), 128), "a fan on a grid of 10");
    assert!(named_all(check(fan(2000, 0.3, origin), Some(grid(50))), 2000), "a fan on a grid of 50");
    let quad = Mesh::quad([v(-0.25, 2.0, -0.25), v(0.25, 2.0, -0.25), v(0.25, 2.0, 0.25), v(-0.25, 2.0, 0.25)]);
    assert!(named_all(check(quad, Some(grid(200))), 2), "a quad lamp on a grid of 200");
}

/// A point light on a surface is named (`Scene::point_lights_on_surfaces`):
/// on a quad turned about an oblique axis, where rounding puts it a hair
/// off the plane, `path` read 0.21 against `light` and `bdpt` 0.33 (an
/// audit: the light's rays met the quad at t ~ 1e-8 and scattered from a
/// point no camera path reaches), and on the stage's level floor, exactly
/// in its plane. Controls: 1e-4 off the turned quad (light tracing's
/// answer again, only noisier for `path`), and in the floor's plane but
/// beyond its edge.
#[test]
fn a_point_light_on_a_surface_is_named() {
    let tilted = r#",
    {"name": "tilt", "shape": {"type": "quad", "corners": [[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]]}, "material": "white",
     "transform": {"rotate": {"axis": [1, 0.3, 0.2], "degrees": 37}, "translate": [0.1, -0.2, 0.5]}}"#;
    let warning = |position: &str| {
        let light = format!(r#"{{"type": "point", "name": "bulb", "position": {position}, "intensity": 2}}"#);
        let text = stage("", tilted, &light, None);
        parse_scene(&text, "point on a surface", Path::new(".")).unwrap().build().point_lights_on_surfaces()
    };
    // The quad's point (0.2, 0.1, 0), turned and moved, and 1e-4 along its normal.
    let on_tilted = "[0.2893899977207184, -0.0851951465010643, 0.5308427214622498]";
    let off_tilted = "[0.28941054589252746, -0.08525069130420083, 0.5309232978079091]";
    for (case, at) in [("on the turned quad", on_tilted), ("on the floor", "[0.3, 0, 0.4]")] {
        let w = warning(at).unwrap_or_default();
        assert!(w.contains("\"bulb\"") && w.contains("\"white\" surface"), "{case}: {w}");
    }
    for (case, at) in [("1e-4 off the turned quad", off_tilted), ("beyond the floor's edge", "[3, 0, 0.4]")] {
        assert_eq!(warning(at), None, "{case}");
    }
    // Nor 0.05 over a ground of 1e5, whose coordinates' rounding is ~0.01
    // (the tolerance is the light's; a review found it warned).
    let ground = r#",
    {"name": "ground", "shape": {"type": "quad", "corners": [[-1e5, -1, -1e5], [-1e5, -1, 1e5], [1e5, -1, 1e5], [1e5, -1, -1e5]]}, "material": "white"}"#;
    let light = r#"{"type": "point", "name": "bulb", "position": [0.3, -0.95, 0.2], "intensity": 2}"#;
    let s = parse_scene(&stage("", ground, light, None), "ground", Path::new(".")).unwrap().build();
    assert_eq!(s.point_lights_on_surfaces(), None, "0.05 over a ground of 1e5");
    // The turned quad a hundredth the size, and the light on it, alone and
    // moved to (789, -456, 124): both round there by ~6e-5, which render
    // space keeps, while its coordinates are ~0.01 (an audit, session 42:
    // unnamed, with path at 0.28 against light's 0.49).
    let far = r#"{"camera": {"position": [789, -456, 120], "look_at": [789.1, -456.2, 123.5], "fov": 1, "width": 8, "height": 8},
  "materials": {"white": {"type": "diffuse", "reflectance": 0.7}},
  "objects": [{"name": "tilt", "shape": {"type": "quad", "corners": [[-0.005, -0.005, 0], [0.005, -0.005, 0], [0.005, 0.005, 0], [-0.005, 0.005, 0]]},
    "material": "white", "transform": {"rotate": {"axis": [1, 0.3, 0.2], "degrees": 37}, "translate": [789.1, -456.2, 123.5]}}],
  "lights": [{"type": "point", "name": "bulb", "position": [789.101893899977, -456.198851951465, 123.500308427215], "intensity": 2}]}"#;
    let s = parse_scene(far, "far", Path::new(".")).unwrap().build();
    assert_ne!(s.render_shift, Vec3A::ZERO, "the scene was not moved: no test of the shift");
    let w = s.point_lights_on_surfaces().unwrap_or_default();
    assert!(w.contains("\"bulb\"") && w.contains("\"white\" surface"), "far and turned: {w}");
}

#[test]
fn bad_numbers_grazing_and_materials() {
    // Grazing: the camera exactly in the floor's plane, a quad seen edge-on,
    // an area light perpendicular to the floor touching it, a point light in
    // the floor's plane, a light facing away from everything.
    let objects = r#",
    {"name": "edge-on", "shape": {"type": "quad", "corners": [[-1, 0.2, 0], [-1, 1.2, 0], [-1, 1.2, 1], [-1, 0.2, 1]]}, "material": "white"},
    {"name": "side lamp", "shape": {"type": "quad", "corners": [[1.5, 0, -1], [1.5, 0, 1], [1.5, 1, 1], [1.5, 1, -1]]}, "material": "black", "emission": 3},
    {"name": "away", "shape": {"type": "quad", "corners": [[-0.5, 2.9, -0.5], [-0.5, 2.9, 0.5], [0.5, 2.9, 0.5], [0.5, 2.9, -0.5]]}, "material": "black", "emission": 3}"#;
    let lights = r#"{"type": "point", "name": "in the floor", "position": [0, 0, 1], "intensity": 2}"#;
    let camera = r#"{"position": [-1, 0, -3], "look_at": [-1, 0, 0], "fov": 60, "width": 16, "height": 16}"#;
    all_sane("grazing", &stage("", objects, lights, Some(camera)), 16);

    // Roughness exactly 0 (smooth), eta exactly 1 (smooth and rough), alpha
    // at the clamp, alpha 1, anisotropy with one zero axis, albedo 0 and 1.
    let materials = r#",
    "c0": {"type": "conductor", "metal": "Ag", "roughness": 0},
    "c1": {"type": "conductor", "metal": "Cu", "alpha": 1},
    "ca": {"type": "conductor", "metal": "Al", "alpha_x": 0, "alpha_y": 0.5},
    "ct": {"type": "conductor", "metal": "Au", "alpha": 1e-5},
    "d0": {"type": "dielectric", "ior": 1.5, "roughness": 0},
    "e1": {"type": "dielectric", "ior": 1},
    "e1r": {"type": "dielectric", "ior": 1, "roughness": 0.5},
    "dt": {"type": "dielectric", "ior": 1.5, "alpha": 1e-5},
    "da": {"type": "dielectric", "ior": "BK7", "alpha_x": 0, "alpha_y": 0.3},
    "m1": {"type": "mirror", "reflectance": 1},
    "w1": {"type": "diffuse", "reflectance": 1}"#;
    let mut objects = String::new();
    for (i, m) in ["c0", "c1", "ca", "ct", "d0", "e1", "e1r", "dt", "da", "m1", "w1"].iter().enumerate() {
        let (x, z) = (-1.5 + (i % 4) as f32 * 1.0, -0.5 + (i / 4) as f32 * 0.7);
        objects += &format!(
            r#",
    {{"shape": {{"type": "sphere", "center": [{x}, 0.35, {z}], "radius": 0.3, "subdivisions": 2, "smooth": {}}}, "material": "{m}"}}"#,
            i % 2 == 0
        );
    }
    all_sane("roughness 0, eta 1", &stage(materials, &objects, "", None), 16);
}

#[test]
fn bad_numbers_enclosures_and_tiny_images() {
    let glass = r#",
    "glass": {"type": "dielectric", "ior": 1.5}"#;
    // Lights inside closed objects: an emitting sphere in a closed diffuse
    // box, a point light in a closed diffuse sphere, an emitting sphere in a
    // glass sphere.
    let objects = r#",
    {"shape": {"type": "cuboid", "min": [-1.2, 0.1, -0.3], "max": [-0.4, 0.9, 0.5]}, "material": "white"},
    {"shape": {"type": "sphere", "center": [-0.8, 0.5, 0.1], "radius": 0.2, "subdivisions": 1}, "material": "black", "emission": 10},
    {"shape": {"type": "sphere", "center": [0.8, 0.5, 0.1], "radius": 0.4, "subdivisions": 2}, "material": "white"},
    {"shape": {"type": "sphere", "center": [0, 1.5, 0.5], "radius": 0.4, "subdivisions": 2}, "material": "glass"},
    {"shape": {"type": "sphere", "center": [0, 1.5, 0.5], "radius": 0.1, "subdivisions": 1}, "material": "black", "emission": 20}"#;
    let lights = r#"{"type": "point", "name": "trapped", "position": [0.8, 0.5, 0.1], "intensity": 5}"#;
    all_sane("lights inside closed objects", &stage(glass, objects, lights, None), 16);

    // The camera inside a glass sphere, inside a closed diffuse sphere,
    // inside a closed box that holds an emitter.
    let camera = r#"{"position": [0, 1, -1.5], "look_at": [0, 0.7, 0], "fov": 60, "width": 16, "height": 16}"#;
    for (case, obj) in [
        (
            "camera inside glass",
            r#"{"shape": {"type": "sphere", "center": [0, 1, -1.5], "radius": 0.3, "subdivisions": 2}, "material": "glass"}"#,
        ),
        (
            "camera inside a diffuse sphere",
            r#"{"shape": {"type": "sphere", "center": [0, 1, -1.5], "radius": 0.3, "subdivisions": 2}, "material": "white"}"#,
        ),
        (
            "camera inside a lit box",
            r#"{"shape": {"type": "cuboid", "min": [-0.5, 0.5, -2], "max": [0.5, 1.5, -1]}, "material": "white"},
    {"shape": {"type": "sphere", "center": [0.2, 0.8, -1.3], "radius": 0.1, "subdivisions": 1}, "material": "black", "emission": 10}"#,
        ),
    ] {
        all_sane(case, &stage(glass, &format!(",\n    {obj}"), "", Some(camera)), 16);
    }

    // 1x1 and 64x1 images, and a 0.01 degree field of view.
    for name in ["cornell-box.json", "mirror-view.json", "sds-point-light.json"] {
        let s = scene(name, 1, 1);
        for (integ, i) in all_integrators() {
            render_checked(&s, i.as_ref(), 256, seed() + 500, &format!("{name} 1x1, {integ}"));
        }
    }
    let wide = r#"{"position": [0, 1, -3], "look_at": [0, 0.7, 0], "fov": 45, "width": 64, "height": 1}"#;
    all_sane("64x1 image", &stage("", "", "", Some(wide)), 64);
    let narrow = r#"{"position": [0, 1, -3], "look_at": [0, 0.7, 0], "fov": 0.01, "width": 4, "height": 4}"#;
    all_sane("fov 0.01 degrees", &stage("", "", "", Some(narrow)), 64);
}

// ------------------------------------------------------------ render space

/// A closed unit room (six inward walls, a block, an area lamp under the
/// ceiling and a point light), everything moved by `offset`. Every
/// coordinate is a multiple of 1/16, exact in f32 at the offsets used.
fn room_at(offset: [f32; 3]) -> String {
    let v = |x: f32, y: f32, z: f32| format!("[{}, {}, {}]", x + offset[0], y + offset[1], z + offset[2]);
    format!(
        r#"{{
  "camera": {{"position": {}, "look_at": {}, "fov": 70, "width": 12, "height": 12}},
  "materials": {{"white": {{"type": "diffuse", "reflectance": 0.6}}, "red": {{"type": "diffuse", "reflectance": {{"rgb": [0.7, 0.1, 0.1]}}}},
                 "black": {{"type": "diffuse", "reflectance": 0}}}},
  "objects": [
    {{"shape": {{"type": "cuboid", "min": {}, "max": {}, "inward": true}}, "material": "white"}},
    {{"shape": {{"type": "cuboid", "min": {}, "max": {}}}, "material": "red"}},
    {{"shape": {{"type": "quad", "corners": [{}, {}, {}, {}]}}, "material": "black", "emission": 10}}
  ],
  "lights": [{{"type": "point", "position": {}, "intensity": 0.5}}]
}}"#,
        v(0.5, 0.5, 0.0625),
        v(0.5, 0.375, 1.0),
        v(0.0, 0.0, 0.0),
        v(1.0, 1.0, 1.0),
        v(0.5625, 0.0, 0.5),
        v(0.8125, 0.375, 0.75),
        v(0.375, 0.9375, 0.375),
        v(0.625, 0.9375, 0.375),
        v(0.625, 0.9375, 0.625),
        v(0.375, 0.9375, 0.625),
        v(0.25, 0.625, 0.5),
    )
}

/// A scene far from the origin renders bit for bit as the same scene at
/// the origin (`render_space`): the loader moves it back exactly, so no
/// estimator computes at the far coordinates' precision. Before, the
/// audit's room at x = 1e4 read 0.7 % dark under bdpt (its MIS weights
/// summed below 1; path and light within 0.05 %) and a closed box leaked
/// light under path from an offset of 10 on (session 42). The control: the
/// room at a half-unit offset, which is not moved (it is nearer the origin
/// than its size), renders different pixels, so the equality is not that
/// of an image insensitive to rounding.
#[test]
fn a_far_scene_renders_as_at_the_origin() {
    let build = |offset: [f32; 3]| {
        let text = room_at(offset);
        parse_scene(&text, "room", Path::new(".")).unwrap_or_else(|e| panic!("{e}")).build()
    };
    let at_origin = build([0.0; 3]);
    for (name, integ) in all_integrators() {
        let image = |s: &Scene| render_checked(s, integ.as_ref(), 4, seed(), name);
        let near = image(&at_origin);
        for offset in [[1e4, 0.0, 0.0], [1e4, 3072.0, 500.0], [3e5, 1e6, 7e4]] {
            assert_eq!(image(&build(offset)), near, "{name}: the room at {offset:?}");
        }
        // (simple_path's weights are reflectances, whatever the positions:
        // rounding that sends no ray elsewhere leaves its pixels alone.)
        if name != "simple_path" {
            assert_ne!(image(&build([0.5, 0.0, 0.0])), near, "{name}: the control");
        }
    }
}

/// Light inside a closed, flat-faceted shell, in a room the camera sees:
/// none gets out, so every pixel is exactly 0 in every estimator. A point
/// light inside a cube and inside an icosphere of 4 subdivisions; an
/// icosphere of 3 wound inward that emits into itself. Before session 43,
/// connections between points within rounding of each other's planes (the
/// two faces of one wall, or nearly coplanar neighbours) leaked: bdpt's
/// vertex connections lit 776-823 of the cube's 1024 pixels over four
/// seeds (up to 1.3e-4 on the icosphere), and next-event estimation to the
/// emitting shell's own faces lit the room under path and bdpt (a review).
/// The control: this test without the `ends_resolved` test of
/// `Scene::visible` (`Shadow::segment`), which every connection's shadow
/// segment passes. A surface point that rounding puts exactly on its
/// triangle's edge, where a cube's edge lies exactly in the neighbouring
/// face's plane, leaked too: a light sample there (u.x = 2^-24: b0 =
/// 2^-25 rounds away) met the neighbour at t = 1, outside the segment's
/// open range, and a hit there spawned its ray, offset along its own
/// normal, still in the neighbour's plane, which it left through at t = 0.
/// An emitting cube wound inward lit a pixel in about one image of 20 at
/// 64 spp under each estimator (session 44), and the seed sweep at offset
/// 63 (session 47) found bdpt's light paths leaving the cube with the
/// point light (two pixels, up to 3.5e-3). Since session 47 every point
/// on a triangle is kept a few error bounds off its edges
/// (`geometry::triangle_point`; tested with a control by
/// `a_point_by_a_cubes_edge_stays_inside_it`), and a camera ray that
/// passes a convex edge within the f32 test's rounding, which it could
/// meet first on the face it would leave by (2 of 150 renders of this
/// cube under `path`), is traced again in f64 (`Accel::intersect_exact`;
/// `a_ray_by_a_cubes_edge_meets_it_from_outside`). Shading normals let
/// light through by design (docs/scene-format.md), so the shells are
/// flat.
///
/// The premise control (an audit, session 49): without the point lights'
/// shells, and with the emitting shell wound outward, every estimator
/// lights most of the room.
#[test]
fn a_closed_shell_keeps_its_light_in() {
    let point = r#""lights": [{"type": "point", "position": [0.5, 0.5, 0.5], "intensity": 1}]"#;
    let sphere = r#"{"type": "sphere", "center": [0.5, 0.5, 0.5], "radius": 0.1, "subdivisions": 3"#;
    let (inward, outward) = (format!(r#"{sphere}, "inward": true}}"#), format!("{sphere}}}"));
    let cases = [
        (r#"{"type": "cuboid", "min": [0.4, 0.4, 0.4], "max": [0.6, 0.6, 0.6]}"#, false, None),
        (r#"{"type": "sphere", "center": [0.5, 0.5, 0.5], "radius": 0.1, "subdivisions": 4}"#, false, None),
        (inward.as_str(), true, Some(outward.as_str())),
    ];
    let lit = |shell: Option<&str>, emitting: bool, spp: u32| {
        let (emission, lights) = if emitting { (r#", "emission": 1"#, r#""lights": []"#) } else { ("", point) };
        let shell = shell.map_or(String::new(), |s| format!(r#", {{"shape": {s}, "material": "white"{emission}}}"#));
        let text = format!(
            r#"{{
  "camera": {{"position": [0.5, 0.5, 0.02], "look_at": [0.5, 0.5, 0.5], "fov": 50, "width": 32, "height": 32}},
  "materials": {{"white": {{"type": "diffuse", "reflectance": 0.7}}}},
  "objects": [
    {{"shape": {{"type": "cuboid", "min": [0, 0, 0], "max": [1, 1, 1], "inward": true}}, "material": "white"}}{shell}
  ],
  {lights}
}}"#
        );
        let scene = parse_scene(&text, "shell", Path::new(".")).unwrap_or_else(|e| panic!("{e}")).build();
        let each = all_integrators().into_iter().map(|(name, integ)| {
            let image = render_checked(&scene, integ.as_ref(), spp, seed(), name);
            let max = image.iter().flatten().fold(0f32, |m, &c| m.max(c));
            let reaches = integ.unsamplable(&scene).is_empty();
            (name, image.iter().filter(|p| p.iter().any(|&c| c != 0.0)).count(), max, reaches)
        });
        each.collect::<Vec<_>>()
    };
    for (shell, emitting, opened) in cases {
        for (name, n, max, _) in lit(Some(shell), emitting, 64) {
            assert_eq!(n, 0, "{name}, shell {shell}: {n} pixels lit (max {max:e})");
        }
        // (`simple_path` cannot reach a point light, and says so.)
        for (name, n, _, reaches) in lit(opened, emitting, 16) {
            assert!(n > 512 || !reaches, "the control, {name}, shell {opened:?}: only {n} of 1024 pixels lit");
        }
    }
}

/// The cube [0.4, 0.6]^3, wound outward, in a room [lo, hi]^3 wound
/// inward. A room that holds the origin keeps render space the file's.
fn cube_in_a_room(lo: f32, hi: f32) -> Scene {
    let text = format!(
        r#"{{
  "camera": {{"position": [0.5, 0.5, -1], "look_at": [0.5, 0.5, 0.5], "fov": 30, "width": 8, "height": 8}},
  "materials": {{"white": {{"type": "diffuse", "reflectance": 0.7}}}},
  "objects": [
    {{"shape": {{"type": "cuboid", "min": [{lo}, {lo}, {lo}], "max": [{hi}, {hi}, {hi}], "inward": true}}, "material": "white"}},
    {{"shape": {{"type": "cuboid", "min": [0.4, 0.4, 0.4], "max": [0.6, 0.6, 0.6]}}, "material": "white"}}
  ]
}}"#
    );
    parse_scene(&text, "cube", Path::new(".")).unwrap_or_else(|e| panic!("{e}")).build()
}

/// A point that rounding would put on its triangle's edge is kept off it
/// (`geometry::triangle_point`). Rays from the centre of a cube to points
/// of its four edges along z (in a room that holds the origin, so that
/// render space is the file's) hit one of the two faces by the edge; a ray
/// spawned there into the cube across its own face and out through the
/// other face must meet that face just ahead, not leave the cube. The
/// control: the same hits, their points made without the margin
/// (`triangle_point(.., 0)`), let rays out, as they did light inside a
/// closed cube (the seed sweep at offset 63, session 47).
#[test]
fn a_point_by_a_cubes_edge_stays_inside_it() {
    let scene = cube_in_a_room(0.0, 1.0);
    let centre = Vec3A::splat(0.5);
    let out = |r: &Ray| scene.intersect(r).is_none_or(|h| h.t > 1e-3);
    let (mut escaped, mut escaped_without_margin, mut rays) = (0, 0, 0);
    for k in 0..2000 {
        let z = 0.41 + 0.18 * k as f32 / 2000.0;
        for (x, y) in [(0.4f32, 0.4f32), (0.6, 0.4), (0.4, 0.6), (0.6, 0.6)] {
            let ray = Ray::new(centre, Vec3A::new(x, y, z) - centre);
            let (Some(si), Some(hit)) = (scene.intersect(&ray), scene.accel.intersect(&ray, f32::INFINITY)) else {
                panic!("the ray to ({x}, {y}, {z}) misses the cube");
            };
            // Into the cube across the face hit (normal n), out through the
            // other.
            let (inward, outward) =
                (Vec3A::new(0.5 - x, 0.5 - y, 0.0).signum(), Vec3A::new(x - 0.5, y - 0.5, 0.0).signum());
            let across = |n: Vec3A| {
                let w = if n.x.abs() > 0.5 {
                    Vec3A::new(0.8 * inward.x, 0.5 * outward.y, 0.3)
                } else {
                    Vec3A::new(0.5 * outward.x, 0.8 * inward.y, 0.3)
                };
                w.normalize()
            };
            rays += 1;
            escaped += out(&si.spawn_ray(across(si.ng))) as u32;
            // The control, on the f32 test's own hit and face.
            let n = (hit.v[1] - hit.v[0]).cross(hit.v[2] - hit.v[0]).normalize();
            let (p, p_error) = triangle_point(&hit.v, [1.0 - hit.b1 - hit.b2, hit.b1, hit.b2], 0.0);
            let bare = SurfacePoint { p, p_error, n, slot: hit.slot };
            escaped_without_margin += out(&bare.spawn_ray(across(n))) as u32;
        }
    }
    assert_eq!(escaped, 0, "{escaped} of {rays} rays left the cube by an edge");
    assert!(escaped_without_margin > 0, "the control: no ray of {rays} left without the margin");
}

/// The strip light of an audit (session 49): a right triangle 1 cm by 1 m,
/// 10 away from the origin, emitting down (-z), whose edge margin
/// (`geometry::edge_margin`: 16 rounding bounds E of a point on it over its
/// least altitude, 1 cm) is 7.3e-3.
fn strip_light() -> AreaLight {
    let v = [Vec3A::new(10.0, 0.0, 0.0), Vec3A::new(10.0, 0.01, 0.0), Vec3A::new(11.0, 0.0, 0.0)];
    let n = (v[1] - v[0]).cross(v[2] - v[0]);
    let (area, margin) = (0.5 * n.length(), edge_margin(&v));
    AreaLight { v, n: n.normalize(), area, le: Spectrum::Constant(1.0), two_sided: false, prim: 0, slot: 0, margin }
}

/// The projected solid angle of a polygon wholly above the plane through
/// `r` with normal `n` (Lambert 1760): half the sum over its edges of the
/// angle each subtends at `r` times n . the unit normal of the plane
/// through `r` and the edge. In f64, from the vertices alone.
fn projected_solid_angle(r: DVec3, n: DVec3, polygon: &[Vec3A]) -> f64 {
    let u: Vec<DVec3> = polygon.iter().map(|p| (p.as_dvec3() - r).normalize()).collect();
    let sum: f64 = (0..u.len())
        .map(|i| {
            let (a, b) = (u[i], u[(i + 1) % u.len()]);
            a.dot(b).clamp(-1.0, 1.0).acos() * n.dot(a.cross(b).normalize())
        })
        .sum();
    0.5 * sum.abs()
}

/// A light's points stay uniform on the triangle (density 1 / area) even
/// on a sliver, whose points within its large margin of an edge are moved
/// off it (`geometry::triangle_point`): across the edge, by 16 rounding
/// bounds at most, not along the strip. At a receiver 5 mm below the strip
/// light, 5 mm from its 1 cm end and facing it, two estimates over a
/// 1024^2 grid of the unit square: next-event estimation (`sample_li`:
/// cos / pdf_w) and emission from where light paths start (`sample_le`:
/// area |cos cos| / d^2 at the ray's origin) each give the strip's
/// projected solid angle (Lambert's formula) to 0.2 %. The control: the
/// points moved by the rule before session 49 (the barycentrics raised to
/// the margin and renormalised) read 2 % or more low.
#[test]
fn light_points_keep_their_density_on_slivers() {
    let a = strip_light();
    let (light, lambda) = (Light::Area(a.clone()), SampledWavelengths::sample_visible(0.37));
    let r = Vec3A::new(10.005, 0.005, -0.005);
    let exact = projected_solid_angle(r.as_dvec3(), DVec3::Z, &a.v);
    // The integrand of the projected solid angle, per unit area of the
    // light, at a point q on it.
    let per_area = |q: Vec3A| {
        let d = (q - r).as_dvec3();
        let cos = d.z / d.length();
        a.area as f64 * cos * cos / d.length_squared()
    };
    let old_rule = |u: Vec2| {
        let (b0, b1) = uniform_triangle(u);
        let c = [b0, b1, 1.0 - b0 - b1].map(|x| x.max(a.margin));
        let s = c[0] + c[1] + c[2];
        a.v[0] * (c[0] / s) + a.v[1] * (c[1] / s) + a.v[2] * (c[2] / s)
    };
    let n = 1024;
    let grid = (0..n * n).map(|k| Vec2::new((k / n) as f32 + 0.5, (k % n) as f32 + 0.5) / n as f32);
    let (mut nee, mut emitted, mut old) = (0.0, 0.0, 0.0);
    for u in grid {
        let ls = light.sample_li(r, u, &lambda).expect("the strip faces the receiver");
        nee += ls.wi.z as f64 / ls.pdf_w as f64;
        emitted += per_area(light.sample_le(u, Vec2::splat(0.5), &lambda).expect("an emitted ray").ray.o);
        old += per_area(old_rule(u));
    }
    let rel = |x: f64| x / (n * n) as f64 / exact - 1.0;
    let (nee, emitted, old) = (rel(nee), rel(emitted), rel(old));
    eprintln!("projected solid angle {exact:.6}: next-event {nee:+.2e}, emitted {emitted:+.2e}; old rule {old:+.2e}");
    assert!(nee.abs() < 2e-3 && emitted.abs() < 2e-3, "next-event {nee:e}, emitted {emitted:e}");
    assert!(old < -2e-2, "the control: the old rule's error is {old:e}");
}

/// A hit is where the ray meets the surface, moved off a sliver's edges by
/// at most 16 rounding bounds E (7.3e-5 here) across them
/// (`geometry::triangle_point`). Rays from below at points of the strip
/// light's triangle within its margin of each edge (barycentrics 1e-6 to
/// 1e-3, 30 % to 70 % along the edge: away from the vertices, where a
/// point must move further to be 16 E from both edges) meet it within 16 E
/// (and 1e-6 of f32's spacing) of those points. The control: the rule
/// before session 49 moved such points up to 7 mm.
#[test]
fn hits_by_a_slivers_edges_stay_where_the_ray_meets_it() {
    let text = r#"{
  "camera": {"position": [10.5, 0.005, -2], "look_at": [10.5, 0.005, 0], "fov": 30, "width": 8, "height": 8},
  "materials": {"white": {"type": "diffuse", "reflectance": 0.7}},
  "objects": [
    {"shape": {"type": "mesh", "positions": [[10, 0, 0], [10, 0.01, 0], [11, 0, 0]], "indices": [[0, 1, 2]]},
     "material": "white", "emission": 1},
    {"shape": {"type": "mesh", "positions": [[-1, -1, -1], [-0.9, -1, -1], [-1, -0.9, -1]], "indices": [[0, 1, 2]]},
     "material": "white"}
  ]
}"#;
    let scene = parse_scene(text, "strip", Path::new(".")).unwrap_or_else(|e| panic!("{e}")).build();
    let light = strip_light();
    let v = light.v;
    let (mut worst, mut old) = (0f32, 0f32);
    for small in [1e-6f32, 1e-5, 1e-4, 1e-3] {
        for along in [0.3f32, 0.5, 0.7] {
            for edge in 0..3 {
                let mut b = [small; 3];
                b[(edge + 1) % 3] = along * (1.0 - small);
                b[(edge + 2) % 3] = (1.0 - along) * (1.0 - small);
                let q = v[0] * b[0] + v[1] * b[1] + v[2] * b[2];
                let o = Vec3A::new(10.3, 0.004, -1.0);
                let si = scene.intersect(&Ray::new(o, (q - o).normalize())).expect("the strip is hit");
                worst = worst.max((si.p - q).length());
                let c = b.map(|x| x.max(light.margin));
                let s = c[0] + c[1] + c[2];
                old = old.max((v[0] * (c[0] / s) + v[1] * (c[1] / s) + v[2] * (c[2] / s) - q).length());
            }
        }
    }
    eprintln!("hits lie within {worst:e} of the points aimed at; the old rule's up to {old:e}");
    assert!(worst < 7.4e-5 + 1e-6, "a hit lies {worst:e} from the point its ray was aimed at");
    assert!(old > 1e-3, "the control: the old rule moved them at most {old:e}");
}

/// A ray that passes a cube's edge, clipping it or missing it by a
/// hair, meets the cube from outside first, if at all: the first hit on
/// the cube faces the ray (d . n < 0; the cube is wound outward). Rays
/// enter by the face z = 0.6 and would leave by y = 0.6, aimed at points
/// of that edge moved off it by -8..8 ulps along (y + z), from 0.5, 10,
/// 100 and 1000 away (the f32 test's rounding grows with the distance).
/// Only rays whose line passes within 1e-7 of the edge (in f64, at the
/// plane y = 0.6) are counted, 20,000 from each distance: from 0.5 and 10
/// away that keeps the targets within about an ulp of the edge, from 100
/// and 1,000 away the origin's rounding (up to ~3e-5) decides. The
/// control: the f32 test alone (`Accel::intersect`) meets thousands of
/// them first on a back face, which had a path go on inside the shell
/// (session 47). A review (session 48) found the band where the f64
/// retrace then counted an edge's product within its rounding bound as 0
/// (a miss by 4e-12 to 1e-8 from 1,000 away): 517 of these rays (515 from
/// 1,000 away, 2 from 100), and the review's own ray, met the cube first
/// on a back face.
#[test]
fn a_ray_by_a_cubes_edge_meets_it_from_outside() {
    let scene = cube_in_a_room(-3000.0, 3000.0);
    let on_cube = |p: Vec3A| p.cmpge(Vec3A::splat(0.39)).all() && p.cmple(Vec3A::splat(0.61)).all();
    let back_first = |ray: &Ray| scene.intersect(ray).is_some_and(|si| on_cube(si.p) && ray.d.dot(si.ng) >= 0.0);
    let bits = |b: [u32; 3]| Vec3A::from_array(b.map(f32::from_bits));
    let review = Ray::new(bits([0x4385_a433, 0xc35c_0353, 0x447d_b102]), bits([0xbe88_9d03, 0x3e61_e85f, 0xbf81_d02f]));
    assert!(!back_first(&review), "the review's ray, 1.6e-8 outside the edge, met the cube first on a back face");
    // How far outside the edge (> 0) the ray's line passes, at y = 0.6.
    let beyond = |r: &Ray| {
        let (o, d) = (r.o.as_dvec3(), r.d.as_dvec3());
        o.z + (0.6f32 as f64 - o.y) / d.y * d.z - 0.6f32 as f64
    };
    let mut inside_f32 = 0;
    for distance in [0.5f32, 10.0, 100.0, 1000.0] {
        let (mut inside, mut on_it, mut near) = (0, 0, 0);
        let mut u = prism::sampling::Sampler::new(7, 0, 0);
        for k in 0.. {
            let step = ((k % 17) as f32 - 8.0) * 2f32.powi(-24);
            let target = Vec3A::new(0.42 + 0.16 * u.get1d(), 0.6 + step, 0.6 + step);
            let d = Vec3A::new(u.get1d() - 0.5, 0.2 + u.get1d(), -0.2 - u.get1d()).normalize();
            let ray = Ray::new(target - distance * d, d);
            if beyond(&ray).abs() > 1e-7 {
                continue;
            }
            if let Some(si) = scene.intersect(&ray).filter(|si| on_cube(si.p)) {
                on_it += 1;
                inside += (d.dot(si.ng) >= 0.0) as u32;
            }
            if let Some(h) = scene.accel.intersect(&ray, f32::INFINITY) {
                let n = (h.v[1] - h.v[0]).cross(h.v[2] - h.v[0]);
                inside_f32 += (on_cube(ray.at(h.t)) && d.dot(n) >= 0.0) as u32;
            }
            near += 1;
            if near == 20_000 {
                break;
            }
        }
        assert!(on_it > 5_000, "from {distance}: only {on_it} of 20,000 rays met the cube");
        assert_eq!(inside, 0, "from {distance}: {inside} of {on_it} rays met the cube first on a back face");
    }
    assert!(inside_f32 > 1000, "the control: the f32 test met only {inside_f32} rays first on a back face");
}

// ----------------------------------------------------------- self-intersection

/// A lit floor and a small box, everything (camera too) scaled by `k`.
fn floor_and_box(k: f32) -> Scene {
    let v = |x: f32, y: f32, z: f32| format!("[{}, {}, {}]", x * k, y * k, z * k);
    let text = format!(
        r#"{{
  "camera": {{"position": {}, "look_at": {}, "fov": 40, "width": 32, "height": 32}},
  "materials": {{"white": {{"type": "diffuse", "reflectance": 0.7}}, "black": {{"type": "diffuse", "reflectance": 0}}}},
  "objects": [
    {{"shape": {{"type": "quad", "corners": [{}, {}, {}, {}]}}, "material": "white"}},
    {{"shape": {{"type": "cuboid", "min": {}, "max": {}}}, "material": "white"}},
    {{"shape": {{"type": "quad", "corners": [{}, {}, {}, {}]}}, "material": "black", "emission": 4}}
  ]
}}"#,
        v(0.6, 1.4, -2.2),
        v(0.0, 0.15, 0.0),
        v(-1.5, 0.0, -1.5),
        v(-1.5, 0.0, 1.5),
        v(1.5, 0.0, 1.5),
        v(1.5, 0.0, -1.5),
        v(-0.25, 0.0, -0.2),
        v(0.15, 0.35, 0.3),
        v(-0.4, 1.6, -0.9),
        v(0.6, 1.6, -0.9),
        v(0.6, 1.6, 0.1),
        v(-0.4, 1.6, 0.1),
    );
    parse_scene(&text, "floor-and-box", Path::new(".")).unwrap_or_else(|e| panic!("{e}")).build()
}

/// The fraction of cosine-distributed rays that, leaving the floor of
/// `floor_and_box(k)` (y = 0) through `offset_ray_origin`, hit the floor again.
fn floor_self_hits(k: f32) -> (usize, usize, f32) {
    use glam::Vec3A;
    use prism::geometry::{offset_ray_origin, Ray};
    let s = floor_and_box(k);
    let mut rng = prism::sampling::Sampler::new(seed(), 0, 0);
    let (mut hits, mut n, mut worst) = (0, 0, 0.0f32);
    while n < 50_000 {
        let p = Vec3A::new(rng.get1d() * 3.0 - 1.5, 0.0, rng.get1d() * 3.0 - 1.5);
        if (-0.3..0.2).contains(&p.x) && (-0.25..0.35).contains(&p.z) {
            continue; // under the box
        }
        let (cos, phi) = (rng.get1d().sqrt(), std::f32::consts::TAU * rng.get1d());
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        let w = Vec3A::new(sin * phi.cos(), cos, sin * phi.sin());
        let p = p * k;
        n += 1;
        // The floor's vertices have y = 0, so p has no error in y: the
        // origin stays on the plane and only the intersection test's taking
        // hits certainly ahead (src/accel/lanes.rs: t > delta_t, or the
        // plane distance in f64, exactly 0 here) keeps the ray off it.
        let e = Vec3A::new(p.x.abs(), 0.0, p.z.abs()) * prism::geometry::gamma(7);
        if let Some(si) = s.intersect(&Ray::new(offset_ray_origin(p, e, Vec3A::Y, w), w)) {
            if si.ng.y > 0.9 && si.p.y.abs() <= 1e-3 * k {
                hits += 1;
                worst = worst.max(si.t / k);
            }
        }
    }
    (hits, n, worst)
}

fn assert_no_self_hits(scales: &[f32]) {
    let mut failures = Vec::new();
    for &k in scales {
        let (hits, n, worst) = floor_self_hits(k);
        eprintln!("scale {k:e}: {hits} of {n} rays leaving the floor hit it again (largest t / scale {worst:e})");
        if hits > 0 {
            failures.push(format!("scale {k:e}: {hits} of {n} rays hit the floor they leave"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn rays_leaving_a_surface_do_not_hit_it_again() {
    assert_no_self_hits(&[1e-3, 1.0]);
}

/// A ray leaving a plane through the origin (y = 0) starts on the plane
/// (p.y has no error, so `offset_ray_origin` moves it by 0 in y); the
/// watertight test's rounding error in t grows with |x|, |z|. With only
/// t > 0 accepted, about 9% of these rays re-hit the floor at scale 1e3; the
/// conservative t > delta_t of src/accel/lanes.rs (pbrt-v4 section 6.8.7),
/// and within it the plane distance in f64 (0 here), must reject every one.
#[test]
fn rays_leaving_a_surface_do_not_hit_it_again_at_large_scales() {
    assert_no_self_hits(&[1e2, 1e3, 1e4, 1e5]);
}

/// A black cover 1e-4 below the stage's lamp (2.5 above the floor) takes
/// all of its light, for every estimator: next-event estimation and BDPT's
/// connections test the whole segment to the light, as rays leaving the
/// lamp do. Control: without the cover the floor is lit. With pbrt-v4's
/// shadow epsilon (segments stopped at 1 - 1e-4 of their length) `path`
/// let 88 % of the lamp's light through the cover, `bdpt` 61 %, `light` and
/// `simple_path` none.
#[test]
fn an_occluder_just_below_a_light_blocks_every_estimator() {
    let cover = r#",
    {"name": "cover", "shape": {"type": "quad", "corners": [[-0.8, 2.4999, -0.8], [0.8, 2.4999, -0.8], [0.8, 2.4999, 0.8], [-0.8, 2.4999, 0.8]]}, "material": "black"}"#;
    let build = |objects: &str| parse_scene(&stage("", objects, "", None), "lamp", Path::new(".")).unwrap().build();
    let (open, covered) = (build(""), build(cover));
    let mean_y = |image: &Image| image.iter().map(|&p| xyz(p).y).sum::<f64>() / image.len() as f64;
    for (name, integ) in all_integrators() {
        let lit = mean_y(&render_checked(&open, integ.as_ref(), 64, seed(), name));
        let through = mean_y(&render_checked(&covered, integ.as_ref(), 64, seed(), name));
        assert!(lit > 0.01, "{name}: the floor is dark without the cover ({lit})");
        assert!(through <= 1e-6 * lit, "{name}: {through} through the cover, {lit} without it");
    }
}

/// The image of `floor_and_box(k)` against `floor_and_box(1)`.
fn scale_invariance(scales: &[f32]) {
    const BLOCK: u32 = 8;
    let integrators = [("path", 16), ("bdpt", 8), ("light", 16)];
    let family = scales.len() * integrators.len();
    let mut failures = Vec::new();
    for (name, spp) in integrators {
        let integ = integrator(name);
        let reference = floor_and_box(1.0);
        let base = stats(&passes_checked(&reference, integ.as_ref(), spp, seed() + 600, name), &reference, BLOCK);
        for &k in scales {
            let s = floor_and_box(k);
            let st = stats(&passes_checked(&s, integ.as_ref(), spp, seed() + 700, &format!("{name} x{k}")), &s, BLOCK);
            let c = Verdict::versus(&st, &base, family);
            report(&format!("floor and box x{k:e} vs x1, {name}"), &c);
            if !c.passed() {
                failures.push(format!("{name} x{k:e}: {c}"));
            }
            let c = Verdict::versus(&st.scaled(1.05), &base, family);
            report(&format!("  negative control {name} x{k:e} x1.05"), &c);
            assert!(!c.passed(), "{name}: a 5% bias went undetected: {c}");
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn scale_invariance_small_scale() {
    scale_invariance(&[1e-3]);
}

/// Before the conservative t test (see
/// `rays_leaving_a_surface_do_not_hit_it_again_at_large_scales`), light
/// tracing lost ~28% of the floor's light at scale 1e5, BDPT ~6%, path
/// tracing ~0.5%; before the error-bound offset, scale 1e-3 failed too (a
/// fixed 2^-16 offset near the origin was 0.5% of that scene).
#[test]
fn scale_invariance_large_scale() {
    scale_invariance(&[1e5]);
}

/// The film's limits: a finite spectrum so large that its colour overflows
/// f32 (the sRGB matrix would turn the infinities into NaN), and a pixel
/// whose exact i128 sum would pass 2^127 (2^20 samples of 1.5e14, where the
/// film's per-sample bound of 2^48 leaves room for 2^19). Both are counted
/// as infinite, never written as a wrapped or zeroed pixel. (The skies are
/// built, not loaded: a scene file may not give a radiance past 2^45 (2^48
/// from session 40 to 42); the film's bounds still catch what an estimator makes.)
#[test]
fn the_film_counts_what_leaves_its_range() {
    use glam::Vec3A;
    use prism::spectrum::Spectrum;
    let sky = |radiance: Spectrum, size: u32| {
        let camera = prism::camera::Camera::new(Vec3A::new(0.0, 0.0, -4.0), Vec3A::ZERO, Vec3A::Y, 40.0, size, size);
        let mut b = prism::scene::SceneBuilder::new(camera);
        b.environment("sky", radiance);
        b.build()
    };
    let opts = RenderOptions { seed: seed(), threads: 1, progress: false };
    let path = integrator("path");

    let s = sky(Spectrum::Constant(1e37), 2);
    let mut film = Film::new(2, 2);
    render(&s, path.as_ref(), &opts, &mut film, 0..4);
    assert_eq!(film.dropped.infinite, 16, "colours beyond f32 not all counted: {:?}", film.dropped);
    assert!(film.image().iter().flatten().all(|&c| c == 0.0));

    let s = sky(prism::spectrum::rgb_illuminant([1.0; 3]).scale(1.5e14), 1);
    let mut film = Film::new(1, 1);
    let spp = 1u32 << 20;
    render(&s, path.as_ref(), &opts, &mut film, 0..spp);
    let dropped = film.dropped.infinite;
    let kept = spp as u64 - dropped;
    eprintln!("1.5e14 sky, 2^20 samples: {dropped} dropped as beyond the film's range");
    assert!(dropped > 0 && film.dropped.nan == 0 && film.dropped.negative == 0, "{:?}", film.dropped);
    // Every kept sample is ~1.5e14 per channel: the pixel (sum / spp) is
    // kept / spp of that, not a wrapped negative number.
    let pixel = film.image()[0];
    for c in pixel {
        let per_sample = c as f64 * spp as f64 / kept as f64;
        assert!((1.0e14..2.5e14).contains(&per_sample), "pixel {pixel:?}: {per_sample:e} per kept sample");
    }
}
