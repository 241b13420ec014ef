//! Named measured spectra (metals, glasses, CIE illuminants), blackbody
//! emission and dispersion formulas. (Helper A implements.)

use super::Spectrum;

pub const METAL_NAMES: &[&str] = &["Ag", "Al", "Au", "Cu", "CuZn"];
pub const GLASS_NAMES: &[&str] = &["BK7", "BAF10", "FK51A", "LASF9", "SF5", "SF10", "SF11"];
pub const ILLUMINANT_NAMES: &[&str] = &["D65", "A", "D50", "F2", "F11"];

/// Complex index of refraction (eta, k) of a named metal.
pub fn metal_eta_k(_name: &str) -> Option<(Spectrum, Spectrum)> {
    todo!()
}
/// Index of refraction of a named glass.
pub fn glass_ior(_name: &str) -> Option<Spectrum> {
    todo!()
}
/// A CIE illuminant normalised to luminance Y = 1.
pub fn illuminant(_name: &str) -> Option<Spectrum> {
    todo!()
}
/// Planck's law at `kelvin`, normalised to luminance Y = 1.
pub fn blackbody(_kelvin: f32) -> Spectrum {
    todo!()
}
/// Sellmeier: n^2 = 1 + sum B_i l^2 / (l^2 - C_i), l in micrometres, C in um^2.
pub fn sellmeier(_b: [f32; 3], _c: [f32; 3]) -> Spectrum {
    todo!()
}
/// Cauchy: n = A + B / l^2, l in micrometres.
pub fn cauchy(_a: f32, _b: f32) -> Spectrum {
    todo!()
}
