//! RGB to spectrum upsampling, Jakob & Hanika 2019. (Helper A implements.)

use super::Spectrum;

/// A smooth reflectance spectrum in [0, 1] whose sRGB colour (under the
/// equal-energy... see docs) is `rgb`.
pub fn rgb_albedo(_rgb: [f32; 3]) -> Spectrum {
    todo!()
}
/// An emission spectrum: the albedo shape of rgb / m times D65 times m.
pub fn rgb_illuminant(_rgb: [f32; 3]) -> Spectrum {
    todo!()
}
/// The precomputed coefficient table (for textures).
pub struct RgbToSpectrumTable;
