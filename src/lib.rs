//! prism: a spectral bidirectional path tracer for light-transport research.
//! See ARCHITECTURE.md-style overview in README.md.

pub mod accel;
pub mod geometry;
pub mod sampling;
pub mod spectrum;

#[path = "../materials/mod.rs"]
pub mod materials;
