//! The unbiasedness suite (VALIDATION.md §2-3): white rooms with analytic
//! answers for every registered integrator, and negative controls that the
//! same harness (src/stats.rs) must reject.

#[path = "common/scenes.rs"]
mod scenes;

use prism::integrators::{self, IntegratorOptions, INTEGRATORS};
use prism::scene::Scene;
use prism::spectrum::Spectrum;
use prism::stats::{render_passes, ColourStats, Verdict};
use scenes::{scene, scene_variant, seed, srgb_of};

const K: u32 = 16;
const RES: u32 = 16;

/// One of `family` comparisons of an estimate with its analytic value.
fn analytic(s: &Scene, integrator: &str, spp: u32, max_depth: u32, expected: [f64; 3], family: usize) -> Verdict {
    Verdict::versus_value(&block_stats(s, integrator, spp, max_depth), expected, family)
}

fn block_stats(s: &Scene, integrator: &str, spp: u32, max_depth: u32) -> ColourStats {
    let integ = integrators::create(integrator, &IntegratorOptions { max_depth, ..Default::default() }).unwrap();
    ColourStats::from_passes(&render_passes(s, integ.as_ref(), spp, K, seed(3), 0), RES, RES, 8)
}

/// Samples per pixel that give each estimator enough power in a white room:
/// at half these, at the rooms' family, light tracing's x1.02 control had
/// a chi-square noncentrality of about 40 (power ~0.96).
fn spp_for(integrator: &str) -> u32 {
    match integrator {
        "light" => 128,
        _ => 64,
    }
}

/// The white-room test's comparisons, made together: two albedos, every
/// estimator (VALIDATION.md §1: alpha over the number of comparisons).
fn white_room_family() -> usize {
    2 * INTEGRATORS.len()
}

/// Le / (1 - rho) with Le = 0.5 for the box rooms.
fn room_value(rho: f64) -> [f64; 3] {
    srgb_of(&Spectrum::Constant((0.5 / (1.0 - rho)) as f32))
}

#[test]
fn white_room_every_integrator() {
    for rho in [0.8, 0.3] {
        // The rho = 0.3 room is the same file with another albedo.
        let s = scene_variant("white-room.json", RES, RES, "\"reflectance\": 0.8", &format!("\"reflectance\": {rho}"));
        for i in INTEGRATORS {
            let c = analytic(&s, i.name, spp_for(i.name), 1024, room_value(rho), white_room_family());
            eprintln!("white room rho {rho} {}: {c}", i.name);
            assert!(c.passed(), "white room rho {rho}, {}: {c}", i.name);
        }
    }
}

/// Negative controls: the harness, at the white-room test's family, rejects
/// a 2% bias and a depth cap that drops the tail of the Neumann series
/// (1 - rho^(N+1) of the answer).
#[test]
fn white_room_negative_controls() {
    for i in INTEGRATORS {
        let s = scene("white-room.json", RES, RES);
        let integ = integrators::create(i.name, &IntegratorOptions::default()).unwrap();
        let stats =
            ColourStats::from_passes(&render_passes(&s, integ.as_ref(), spp_for(i.name), K, seed(3), 0), RES, RES, 8);
        let c = Verdict::versus_value(&stats.scaled(1.02), room_value(0.8), white_room_family());
        eprintln!("white room x1.02 {}: {c}", i.name);
        assert!(!c.passed(), "{}: a 2% bias passed: {c}", i.name);
        let c = analytic(&s, i.name, spp_for(i.name), 10, room_value(0.8), white_room_family());
        eprintln!("white room max_depth 10 {}: {c}", i.name);
        assert!(!c.passed(), "{}: a depth cap of 10 passed: {c}", i.name);
    }
}

/// Spectral Le(lambda) and rho(lambda) on a tessellated sphere: the pixel is
/// the colour of Le / (1 - rho), computed here from the scene file's own
/// tables (an independent path from the loader). Negative control: the
/// same statistics scaled by 0.98 are rejected, for every integrator, at
/// the test's family (light tracing renders 1024 spp here: at 16 spp a 2 %
/// bias passed). The others render 128 spp: at 32 spp the rule failed
/// right estimates in 1-2 of 200 seeds each (path at seed offset 40, Y z
/// 5.19, and 3.53 with 4x the samples, where a bias would double it), 2-3x
/// its bound (docs/validation.md, "Session 39").
#[test]
fn spectral_white_room_sphere_every_integrator() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/white-room-sphere.json");
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let table = |name: &str| -> Spectrum {
        let s = &json["spectra"][name];
        let w = s["wavelengths"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32);
        let v = s["values"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32);
        Spectrum::piecewise_linear(&w.zip(v).collect::<Vec<_>>())
    };
    let (le, rho) = (table("le"), table("rho"));
    let expected = srgb_of(&Spectrum::from_fn(|l| le.eval(l) / (1.0 - rho.eval(l))));
    let s = scene("white-room-sphere.json", RES, RES);
    let family = INTEGRATORS.len();
    for i in INTEGRATORS {
        let spp = if i.name == "light" { 1024 } else { 128 };
        let stats = block_stats(&s, i.name, spp, 1024);
        let c = Verdict::versus_value(&stats, expected, family);
        eprintln!("spectral sphere room {}: {c}", i.name);
        assert!(c.passed(), "spectral sphere room, {}: {c}", i.name);
        let c = Verdict::versus_value(&stats.scaled(0.98), expected, family);
        eprintln!("spectral sphere room x0.98 {}: {c}", i.name);
        assert!(!c.passed(), "spectral sphere room, {}: a 2% bias passed: {c}", i.name);
    }
}

/// Mirror walls (constant reflectance 0.6): estimators that can sample
/// specular surfaces seen by the camera read Le / (1 - rho); those that
/// cannot must say so before rendering. Negative control: the same
/// statistics scaled by 1.02 are rejected (added after an audit, session
/// 49, as the other white rooms have it).
#[test]
fn mirror_white_room() {
    let expected = srgb_of(&Spectrum::Constant(0.5 / (1.0 - 0.6)));
    let s = scene("white-room-mirror.json", RES, RES);
    // Every estimator but light tracing is compared.
    let family = INTEGRATORS.len() - 1;
    for i in INTEGRATORS {
        let integ = integrators::create(i.name, &IntegratorOptions::default()).unwrap();
        let warnings = integ.unsamplable(&s);
        if i.name == "light" {
            assert!(!warnings.is_empty(), "light tracing must warn that it cannot see the mirrors");
            continue;
        }
        assert!(warnings.is_empty(), "{}: unexpected warnings {warnings:?}", i.name);
        let stats = block_stats(&s, i.name, spp_for(i.name), 1024);
        let c = Verdict::versus_value(&stats, expected, family);
        eprintln!("mirror room {}: {c}", i.name);
        assert!(c.passed(), "mirror room, {}: {c}", i.name);
        let c = Verdict::versus_value(&stats.scaled(1.02), expected, family);
        eprintln!("mirror room x1.02 {}: {c}", i.name);
        assert!(!c.passed(), "mirror room, {}: a 2% bias passed: {c}", i.name);
    }
}
