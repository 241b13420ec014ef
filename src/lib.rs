//! prism: a spectral bidirectional path tracer for light-transport research.
//! The layout follows ARCHITECTURE.md: the shared core here, the BSDFs in
//! ../materials and the estimators in ../integrators, mounted as modules so
//! the renderer is one crate.

pub mod accel;
pub mod camera;
pub mod converge;
pub mod film;
pub mod geometry;
pub mod light;
pub mod mitsuba;
pub mod output;
pub mod path;
pub mod reference;
pub mod render;
pub mod render_state;
pub mod roulette;
pub mod sampling;
pub mod scene;
pub mod select;
pub mod shapes;
pub mod spectrum;
pub mod stats;
pub mod strategies;
pub mod unsamplable;
pub mod wide_bvh;

#[path = "../materials/mod.rs"]
pub mod materials;

#[path = "../integrators/mod.rs"]
pub mod integrators;

/// The instruction set this binary was compiled for: the architecture and
/// the vector extensions that change its floating-point code (FMA fuses
/// products into sums, so images are bit-identical within one build target,
/// not across targets; `.cargo/config.toml` explains the default). Recorded
/// in every render sidecar, reference and `prism converge` result.
pub fn build_target() -> String {
    let features = [("avx2", cfg!(target_feature = "avx2")), ("fma", cfg!(target_feature = "fma"))];
    let on: Vec<&str> = features.iter().filter(|(_, on)| *on).map(|(name, _)| *name).collect();
    if on.is_empty() {
        std::env::consts::ARCH.to_string()
    } else {
        format!("{} +{}", std::env::consts::ARCH, on.join(" +"))
    }
}
