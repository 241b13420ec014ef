//! The film: box-filtered pixel accumulation in f64, an additive splat buffer
//! (light tracing and BDPT's t = 1 strategy), the check that keeps NaN,
//! infinite and negative samples out of the image (counted, per reason), and
//! the outputs: EXR (f32 linear sRGB), PNG preview, JSON sidecar. Files are
//! written to a temporary name and renamed, so a failed render never leaves a
//! half-written file and never clobbers an existing one.

use crate::spectrum::{to_linear_srgb, SampledSpectrum, SampledWavelengths};
use anyhow::{Context, Result};
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Samples kept out of the film, by reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DroppedSamples {
    pub nan: u64,
    pub infinite: u64,
    pub negative: u64,
}

impl DroppedSamples {
    pub fn total(&self) -> u64 {
        self.nan + self.infinite + self.negative
    }

    pub fn merge(&mut self, o: &DroppedSamples) {
        self.nan += o.nan;
        self.infinite += o.infinite;
        self.negative += o.negative;
    }

    /// Converts a spectral sample to linear sRGB, or counts why it is dropped.
    /// The check is on the spectral values: sRGB itself may legitimately be
    /// negative for saturated spectra.
    #[inline]
    pub fn admit(&mut self, l: SampledSpectrum, lambda: &SampledWavelengths) -> Option<Vec3> {
        if l.0.is_nan_mask().any() {
            self.nan += 1;
            return None;
        }
        if !l.is_finite() {
            self.infinite += 1;
            return None;
        }
        if l.min_component() < 0.0 {
            self.negative += 1;
            return None;
        }
        Some(to_linear_srgb(l, lambda))
    }
}

pub struct Film {
    pub width: u32,
    pub height: u32,
    /// Sum of camera-sample estimates per pixel (linear sRGB).
    pub pixels: Vec<[f64; 3]>,
    /// Sum of splatted contributions per pixel.
    pub splats: Vec<[f64; 3]>,
    /// Samples per pixel accumulated so far.
    pub spp: u64,
    pub dropped: DroppedSamples,
}

impl Film {
    pub fn new(width: u32, height: u32) -> Self {
        // In usize: width * height in u32 wraps for images of 2^32 pixels or more.
        let n = width as usize * height as usize;
        Self {
            width,
            height,
            pixels: vec![[0.0; 3]; n],
            splats: vec![[0.0; 3]; n],
            spp: 0,
            dropped: DroppedSamples::default(),
        }
    }

    /// The pixel estimates: camera samples averaged over spp, plus splats
    /// divided by spp (spp light paths per pixel were traced; the camera's
    /// importance is normalised over the whole image, see camera.rs).
    pub fn image(&self) -> Vec<[f32; 3]> {
        let inv = if self.spp == 0 { 0.0 } else { 1.0 / self.spp as f64 };
        self.pixels.iter().zip(&self.splats).map(|(p, s)| [0, 1, 2].map(|c| ((p[c] + s[c]) * inv) as f32)).collect()
    }
}

/// Writes `bytes` through `write` to a temporary file beside `path`, then
/// renames it into place.
fn write_atomically(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = path.file_name().context("output path has no file name")?.to_string_lossy();
    let ext = path.extension().map(|e| e.to_string_lossy().to_string()).unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.tmp.{ext}", std::process::id()));
    let result = write(&tmp).and_then(|_| {
        std::fs::rename(&tmp, path).with_context(|| format!("cannot move output into {}", path.display()))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Writes an f32 RGB EXR (linear sRGB).
pub fn write_exr(path: &Path, width: u32, height: u32, image: &[[f32; 3]]) -> Result<()> {
    write_atomically(path, |tmp| {
        exr::prelude::write_rgb_file(tmp, width as usize, height as usize, |x, y| {
            let p = image[y * width as usize + x];
            (p[0], p[1], p[2])
        })
        .with_context(|| format!("cannot write {}", path.display()))
    })
}

/// Reads an RGB EXR into (width, height, pixels).
pub fn read_exr(path: &Path) -> Result<(u32, u32, Vec<[f32; 3]>)> {
    use exr::prelude::*;
    let img = read_first_rgba_layer_from_file(
        path,
        |res, _| (res.width(), vec![[0f32; 3]; res.width() * res.height()]),
        |(w, px): &mut (usize, Vec<[f32; 3]>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            px[pos.y() * *w + pos.x()] = [r, g, b];
        },
    )
    .with_context(|| format!("cannot read {}", path.display()))?;
    let size = img.layer_data.size;
    let (_, px) = img.layer_data.channel_data.pixels;
    Ok((size.width() as u32, size.height() as u32, px))
}

/// Writes an 8-bit sRGB PNG preview: linear values times 2^exposure, sRGB
/// transfer curve, clamped.
pub fn write_png(path: &Path, width: u32, height: u32, image: &[[f32; 3]], exposure: f32) -> Result<()> {
    let scale = 2f32.powf(exposure);
    let mut buf = image::RgbImage::new(width, height);
    for (i, p) in image.iter().enumerate() {
        let px = p.map(|c| (srgb_encode(c * scale) * 255.0 + 0.5) as u8);
        buf.put_pixel(i as u32 % width, i as u32 / width, image::Rgb(px));
    }
    write_atomically(path, |tmp| {
        buf.save_with_format(tmp, image::ImageFormat::Png).with_context(|| format!("cannot write {}", path.display()))
    })
}

fn srgb_encode(c: f32) -> f32 {
    let c = if c.is_finite() { c.clamp(0.0, 1.0) } else { 0.0 };
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// Writes a JSON document atomically.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    write_atomically(path, |tmp| {
        std::fs::write(tmp, text + "\n").with_context(|| format!("cannot write {}", path.display()))
    })
}
