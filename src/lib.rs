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
pub mod path;
pub mod reference;
pub mod render;
pub mod render_state;
pub mod sampling;
pub mod scene;
pub mod shapes;
pub mod spectrum;
pub mod stats;
pub mod wide_bvh;

#[path = "../materials/mod.rs"]
pub mod materials;

#[path = "../integrators/mod.rs"]
pub mod integrators;
