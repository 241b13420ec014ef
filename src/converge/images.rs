//! The image panels of the report: tone-mapped finals beside the reference,
//! false-colour per-pixel errors, composed side by side with captions.

use super::chart::{svg_to_png, xml_escape};
use crate::output::srgb8;
use anyhow::{Context, Result};
use image::{Rgb, RgbImage};

/// Scale that maps the reference's log-average luminance to 0.18 (Reinhard's key).
pub(super) fn auto_exposure(reference: &[[f32; 3]]) -> f32 {
    let lum = |p: &[f32; 3]| (0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]).max(0.0) as f64;
    let n = reference.len().max(1) as f64;
    let log_avg = (reference.iter().map(|p| (lum(p) + 1e-4).ln()).sum::<f64>() / n).exp();
    if log_avg > 1e-6 {
        (0.18 / log_avg) as f32
    } else {
        1.0
    }
}

pub(super) fn tonemap(image: &[[f32; 3]], w: u32, h: u32, scale: f32) -> RgbImage {
    RgbImage::from_fn(w, h, |x, y| Rgb(image[(y * w + x) as usize].map(|c| srgb8(c * scale))))
}

/// Per-pixel relMSE: mean over channels of (x - ref)^2 / (ref^2 + 0.01).
pub fn pixel_errors(image: &[[f32; 3]], reference: &[[f32; 3]]) -> Vec<f64> {
    image
        .iter()
        .zip(reference)
        .map(|(x, r)| {
            (0..3).map(|c| (x[c] as f64 - r[c] as f64).powi(2) / ((r[c] as f64).powi(2) + 0.01)).sum::<f64>() / 3.0
        })
        .collect()
}

/// Whole decades spanning the 2nd to 99.5th percentile of all error maps.
pub(super) fn error_range(maps: &[Vec<f64>]) -> (f64, f64) {
    let mut all: Vec<f64> = maps.iter().flatten().copied().filter(|v| v.is_finite() && *v > 0.0).collect();
    if all.is_empty() {
        return (1e-6, 1.0);
    }
    all.sort_by(f64::total_cmp);
    let q = |f: f64| all[((all.len() - 1) as f64 * f) as usize];
    let lo = q(0.02).log10().floor();
    let hi = q(0.995).log10().ceil().max(lo + 1.0);
    (10f64.powf(lo), 10f64.powf(hi))
}

/// Viridis, 9 stops.
const VIRIDIS: [[u8; 3]; 9] = [
    [68, 1, 84],
    [71, 44, 122],
    [59, 81, 139],
    [44, 113, 142],
    [33, 144, 141],
    [39, 173, 129],
    [92, 200, 99],
    [170, 220, 50],
    [253, 231, 37],
];

fn viridis(t: f64) -> [u8; 3] {
    let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 } * (VIRIDIS.len() - 1) as f64;
    let i = (t.floor() as usize).min(VIRIDIS.len() - 2);
    let f = t - i as f64;
    [0, 1, 2].map(|c| (VIRIDIS[i][c] as f64 * (1.0 - f) + VIRIDIS[i + 1][c] as f64 * f).round() as u8)
}

pub(super) fn false_colour(errors: &[f64], w: u32, h: u32, lo: f64, hi: f64) -> RgbImage {
    let (l0, l1) = (lo.log10(), hi.log10());
    RgbImage::from_fn(w, h, |x, y| {
        let e = errors[(y * w + x) as usize];
        let t = if e > 0.0 { (e.log10() - l0) / (l1 - l0) } else { 0.0 };
        Rgb(viridis(t))
    })
}

/// Panels side by side (upscaled by an integer factor to at least 256 px
/// wide), a caption above each, and optionally a log colour bar from `lo` to
/// `hi` underneath; the text is drawn by resvg with the embedded font.
pub(super) fn compose(panels: &[(String, RgbImage)], colour_bar: Option<(f64, f64)>) -> Result<RgbImage> {
    const GAP: u32 = 8;
    const CAPTION: u32 = 28;
    const BAR: u32 = 56;
    let (pw, ph) = panels.first().map(|p| p.1.dimensions()).context("no panels")?;
    let k = 256u32.div_ceil(pw).max(1);
    let (cw, ch) = (pw * k, ph * k);
    let n = panels.len() as u32;
    let width = GAP + n * (cw + GAP);
    let bar_h = if colour_bar.is_some() { BAR } else { 0 };
    let height = CAPTION + ch + GAP + bar_h;
    let mut svg = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}">"#
    );
    svg.push_str(&format!(r#"<rect width="{width}" height="{height}" fill="white"/>"#));
    for (i, (caption, _)) in panels.iter().enumerate() {
        let cx = GAP + i as u32 * (cw + GAP) + cw / 2;
        let size = if caption.len() as u32 * 8 > cw { 11 } else { 14 };
        svg.push_str(&format!(
            r#"<text x="{cx}" y="{}" text-anchor="middle" font-family="sans-serif" font-size="{size}">{}</text>"#,
            CAPTION - 9,
            xml_escape(caption)
        ));
    }
    if let Some((lo, hi)) = colour_bar {
        let y = CAPTION + ch + GAP;
        let (x0, bw) = (GAP + 60, (width - 2 * GAP - 120).min(600));
        svg.push_str(r#"<defs><linearGradient id="v" x1="0" x2="1" y1="0" y2="0">"#);
        for (i, c) in VIRIDIS.iter().enumerate() {
            let off = i as f64 / (VIRIDIS.len() - 1) as f64;
            svg.push_str(&format!(r#"<stop offset="{off}" stop-color="rgb({},{},{})"/>"#, c[0], c[1], c[2]));
        }
        svg.push_str("</linearGradient></defs>");
        svg.push_str(&format!(r#"<rect x="{x0}" y="{y}" width="{bw}" height="14" fill="url(#v)"/>"#));
        let decades = (hi.log10() - lo.log10()).round().max(1.0) as u32;
        for d in 0..=decades {
            let x = x0 as f64 + bw as f64 * d as f64 / decades as f64;
            let v = lo * 10f64.powi(d as i32);
            svg.push_str(&format!(
                r#"<line x1="{x}" x2="{x}" y1="{y}" y2="{}" stroke="black"/><text x="{x}" y="{}" text-anchor="middle" font-family="sans-serif" font-size="12">{}</text>"#,
                y + 18,
                y + 31,
                format_args!("{v:.0e}")
            ));
        }
        svg.push_str(&format!(
            r#"<text x="{}" y="{}" font-family="sans-serif" font-size="12">per-pixel (x - ref)^2 / (ref^2 + 0.01), log scale</text>"#,
            x0 + bw + 12,
            y + 12
        ));
    }
    svg.push_str("</svg>");
    let mut canvas = svg_to_png(&svg, 1.0)?;
    for (i, (_, img)) in panels.iter().enumerate() {
        let ox = GAP + i as u32 * (cw + GAP);
        for y in 0..ch {
            for x in 0..cw {
                canvas.put_pixel(ox + x, CAPTION + y, *img.get_pixel(x / k, y / k));
            }
        }
    }
    Ok(canvas)
}
