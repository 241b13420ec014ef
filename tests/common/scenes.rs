//! Helpers of the integrator tests: the repository's scene files at a test
//! resolution, integrators by name, exact colours, seeds, and the colour
//! statistics of 32 x 32 renders.
#![allow(dead_code)]

use prism::integrators::{self, Integrator, IntegratorOptions};
use prism::sampling::MisHeuristic;
use prism::scene::{load_scene, parse_scene, Scene};
use prism::spectrum::{spectrum_to_xyz, xyz_to_linear_srgb, Spectrum};
use prism::stats::{ColourStats, Image, Verdict};
use std::path::{Path, PathBuf};

#[path = "seeds.rs"]
pub mod seeds;

/// A fresh, empty directory `prism-<name>-<pid>` for one test's files,
/// under Cargo's directory for integration tests' temporary files.
pub fn temp_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("prism-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Loads `scenes/<name>` at `width` x `height`.
pub fn scene(name: &str, width: u32, height: u32) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes").join(name);
    let mut b = load_scene(&path).unwrap_or_else(|e| panic!("{e}"));
    b.set_resolution(width, height).unwrap();
    b.build()
}

/// Loads a scene file after replacing `from` by `to` in its text (for
/// variants such as a biased albedo in negative controls).
pub fn scene_variant(name: &str, width: u32, height: u32, from: &str, to: &str) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes").join(name);
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains(from), "{name} does not contain {from:?}");
    let text = text.replace(from, to);
    let mut b = parse_scene(&text, name, path.parent().unwrap()).unwrap_or_else(|e| panic!("{e}"));
    b.set_resolution(width, height).unwrap();
    b.build()
}

pub fn integrator(name: &str) -> Box<dyn Integrator> {
    integrators::create(name, &IntegratorOptions::default()).unwrap()
}

/// BDPT with the MIS heuristic `mis`.
pub fn bdpt(mis: MisHeuristic) -> Box<dyn Integrator> {
    integrators::create("bdpt", &IntegratorOptions { mis, ..Default::default() }).unwrap()
}

/// Linear sRGB of a spectrum's exact colour (1 nm sums).
pub fn srgb_of(s: &Spectrum) -> [f64; 3] {
    xyz_to_linear_srgb(spectrum_to_xyz(s)).to_array().map(f64::from)
}

/// Base seed `base`, shifted by 1000 x $PRISM_SEED_OFFSET (default 0): the
/// tests use fixed seeds, and must pass for any other.
pub fn seed(base: u64) -> u64 {
    base + 1000 * seeds::from_env("PRISM_SEED_OFFSET", 0)
}

/// Block statistics (sRGB and luminance, see `prism::stats::Verdict`) of
/// passes of a 32 x 32 image.
pub fn stats(passes: &[Image], block: u32) -> ColourStats {
    ColourStats::from_passes(passes, 32, 32, block)
}

pub fn versus(a: &ColourStats, b: &ColourStats) -> Verdict {
    Verdict::versus(a, b, 1)
}

/// Two coincident quads (the same corners in the same order), one red and
/// one green, filling a `size` x `size` view under a constant sky: every
/// camera ray meets both at one distance, an exact tie.
pub fn coincident_quads(size: u32) -> String {
    let quad = r#"{"type": "quad", "corners": [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]}"#;
    format!(
        r#"{{
  "camera": {{"position": [0, 0, -3], "look_at": [0, 0, 0], "fov": 30, "width": {size}, "height": {size}}},
  "materials": {{"red": {{"type": "diffuse", "reflectance": {{"rgb": [0.8, 0.1, 0.1]}}}},
                "green": {{"type": "diffuse", "reflectance": {{"rgb": [0.1, 0.8, 0.1]}}}}}},
  "objects": [{{"shape": {quad}, "material": "red"}}, {{"shape": {quad}, "material": "green"}}],
  "lights": [{{"type": "environment", "radiance": 1.0}}]
}}"#
    )
}

/// A valid scene of a few lines (an 8 x 8 image of a sphere under a constant
/// sky) for the command-line and bad-input tests, which edit it.
pub const TINY_SCENE: &str = r#"{
  "camera": {"position": [0, 0, -3], "look_at": [0, 0, 0], "fov": 40, "width": 8, "height": 8},
  "materials": {"white": {"type": "diffuse", "reflectance": 0.5}},
  "objects": [{"shape": {"type": "sphere", "center": [0, 0, 0], "radius": 1}, "material": "white"}],
  "lights": [{"type": "environment", "radiance": 1.0}]
}
"#;
