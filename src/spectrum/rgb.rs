//! RGB to spectrum upsampling of Jakob & Hanika 2019 ("A Low-Dimensional
//! Function Space for Efficient Spectral Upsampling", EG 2019): a reflectance
//! s(l) = S(c0 l^2 + c1 l + c2), S(x) = 1/2 + x / (2 sqrt(1 + x^2)), smooth
//! and bounded in [0, 1], fitted to a linear sRGB colour.
//!
//! # Round trip: the definition every fit and test here uses
//!
//! A reflectance s is seen under the sRGB white, CIE D65 normalised to Y = 1
//! (`illuminant("D65")`), as Jakob & Hanika and pbrt-v4 do:
//!
//!   XYZ = sum over l = 360..=830 nm (1 nm) of cmf(l) s(l) D65(l) / sum ybar D65
//!       = `spectrum_to_xyz(&s.scaled_by(&illuminant("D65")))`,
//!   rgb = `xyz_to_linear_srgb(XYZ)`.
//!
//! The tabulated D65 lands on the sRGB white (1, 1, 1) to 3e-6 under this
//! definition, so a flat reflectance g is exactly grey g.
//!
//! # The table
//!
//! Fitting costs a few thousand flops, so colours are first looked up in a
//! precomputed table (Jakob & Hanika Sec. 5, pbrt-v4's layout): three tables,
//! one per largest component m = argmax(rgb); each is indexed by z = rgb[m] on
//! res nodes z_k = smoothstep(smoothstep(k / (res - 1))) (dense near black and
//! white, where the coefficients change fastest) and by the two ratios
//! rgb[m+1] / z, rgb[m+2] / z on a uniform res x res grid. Cells are solved
//! along z from z_{res/5}, each warm-started from its neighbour.
//!
//! The committed table `data/rgb_to_spectrum_srgb.bin` is produced by
//! `RgbToSpectrumTable::generate(32).write(path)` (the CLI's
//! `prism rgb-table --res 32 --out src/spectrum/data/rgb_to_spectrum_srgb.bin`).

mod fit;

use super::{illuminant, Spectrum, LAMBDA_MIN};
use rayon::prelude::*;
use std::io;
use std::path::Path;
use std::sync::LazyLock;

use fit::{FitOptions, LAMBDA_SPAN};

/// Fit settings for table cells: converged to f64 noise, so that
/// regenerating the table reproduces it. pbrt-v4 caps the coefficients at 200;
/// here the chains stop at z_1 > 0 (black is never fitted), every cell
/// converges, and the largest |c| (about 1e4, at the darkest pure blue) is
/// still well represented in f32.
const TABLE_FIT: FitOptions = FitOptions { max_steps: 100, rgb_tolerance: 1e-10 };

/// Fit settings for `rgb_albedo`'s polish from the table's interpolated start.
const POLISH_FIT: FitOptions = FitOptions { max_steps: 30, rgb_tolerance: 2e-6 };

/// Fit settings for the intermediate colours of `polish`'s continuation.
const CONTINUATION_FIT: FitOptions = FitOptions { max_steps: 20, rgb_tolerance: 1e-7 };

/// File header: magic and format version.
const MAGIC: &[u8; 8] = b"PRISMRGB";
const VERSION: u32 = 1;

/// Coefficients of the sigmoid polynomial over the sRGB cube, for textures:
/// interpolate with [`RgbToSpectrumTable::coefficients`], evaluate with
/// [`sigmoid_polynomial`].
#[derive(Clone, Debug, PartialEq)]
pub struct RgbToSpectrumTable {
    res: usize,
    /// The z nodes z_k.
    z_nodes: Vec<f32>,
    /// Normalised-wavelength coefficients (t = (l - 360) / 470) of cell
    /// (m, k, j, i) at ((m * res + k) * res + j) * res + i.
    coeffs: Vec<[f32; 3]>,
}

static COMMITTED: LazyLock<RgbToSpectrumTable> = LazyLock::new(|| {
    RgbToSpectrumTable::from_bytes(include_bytes!("data/rgb_to_spectrum_srgb.bin"))
        .expect("committed RGB table is well formed")
});

fn smoothstep(x: f64) -> f64 {
    x * x * (3.0 - 2.0 * x)
}

/// The z nodes of a table of resolution `res`, rounded to the stored f32.
fn z_nodes(res: usize) -> Vec<f32> {
    (0..res).map(|k| smoothstep(smoothstep(k as f64 / (res - 1) as f64)) as f32).collect()
}

/// The colour of cell (m, k, j, i): rgb[m] = z_k, the next two components
/// are z_k times i / (res - 1) and j / (res - 1).
fn cell_rgb(res: usize, z: f32, m: usize, i: usize, j: usize) -> [f64; 3] {
    let z = z as f64;
    let mut rgb = [0.0; 3];
    rgb[m] = z;
    rgb[(m + 1) % 3] = z * i as f64 / (res - 1) as f64;
    rgb[(m + 2) % 3] = z * j as f64 / (res - 1) as f64;
    rgb
}

/// Solves the cells (m, k, j, i) for every k. From flat grey (c = 0) at
/// k0 = res / 5, a dim colour near grey's reach, upwards then downwards,
/// each cell starting from its neighbour's solution (pbrt-v4's order).
///
/// Black (z = 0) and white (the grey chain at z = 1) are reached by no
/// sigmoid: fitting them only drives the coefficients towards infinity along
/// an arbitrary direction, which would spoil the interpolation around them.
/// Their cells keep their neighbour's coefficients instead. The grey chain
/// itself is the exact flat S(c2) = z.
fn solve_chain(res: usize, z: &[f32], m: usize, i: usize, j: usize) -> Vec<[f32; 3]> {
    if i == res - 1 && j == res - 1 {
        let mut out: Vec<[f32; 3]> = z.iter().map(|&g| [0.0, 0.0, flat_coefficient(g as f64) as f32]).collect();
        out[0] = out[1];
        out[res - 1] = out[res - 2];
        return out;
    }
    let k0 = (res / 5).max(1);
    let mut out = vec![[0.0f32; 3]; res];
    let mut c = [0.0f64; 3];
    for k in k0..res {
        fit::fit(cell_rgb(res, z[k], m, i, j), &mut c, TABLE_FIT);
        out[k] = c.map(|v| v as f32);
    }
    c = out[k0].map(|v| v as f64);
    for k in (1..k0).rev() {
        fit::fit(cell_rgb(res, z[k], m, i, j), &mut c, TABLE_FIT);
        out[k] = c.map(|v| v as f32);
    }
    out[0] = out[1];
    out
}

impl RgbToSpectrumTable {
    /// Solves a table of resolution `res` (>= 3) over the sRGB cube, in
    /// parallel over the 3 res^2 chains of cells. The file written by
    /// [`write`](Self::write) is 3 * res^3 * 12 bytes plus a header: 1.2 MB at
    /// res = 32 (the committed table).
    pub fn generate(res: usize) -> RgbToSpectrumTable {
        assert!(res >= 3, "an RGB table needs at least 3 nodes per axis");
        let z = z_nodes(res);
        let chains: Vec<(usize, usize, usize)> =
            (0..3).flat_map(|m| (0..res).flat_map(move |j| (0..res).map(move |i| (m, j, i)))).collect();
        let solved: Vec<Vec<[f32; 3]>> = chains.par_iter().map(|&(m, j, i)| solve_chain(res, &z, m, i, j)).collect();
        let mut coeffs = vec![[0.0f32; 3]; 3 * res * res * res];
        for (&(m, j, i), chain) in chains.iter().zip(&solved) {
            for (k, c) in chain.iter().enumerate() {
                coeffs[((m * res + k) * res + j) * res + i] = *c;
            }
        }
        RgbToSpectrumTable { res, z_nodes: z, coeffs }
    }

    /// The committed table (`src/spectrum/data/rgb_to_spectrum_srgb.bin`).
    pub fn get() -> &'static RgbToSpectrumTable {
        &COMMITTED
    }

    /// Nodes per axis.
    pub fn res(&self) -> usize {
        self.res
    }

    /// Writes the table: "PRISMRGB", u32 version, u32 res, res f32 z nodes,
    /// then 3 res^3 x 3 f32 coefficients, all little-endian.
    /// Atomically (`output::write_bytes`): it replaces the committed table.
    pub fn write(&self, path: impl AsRef<Path>) -> anyhow::Result<()> {
        crate::output::write_bytes(path.as_ref(), &self.to_bytes())
    }

    /// Reads a table written by [`write`](Self::write).
    pub fn read(path: impl AsRef<Path>) -> io::Result<RgbToSpectrumTable> {
        Self::from_bytes(&std::fs::read(path)?)
    }

    /// The file contents of [`write`](Self::write).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(16 + 4 * (self.z_nodes.len() + 3 * self.coeffs.len()));
        b.extend_from_slice(MAGIC);
        b.extend_from_slice(&VERSION.to_le_bytes());
        b.extend_from_slice(&(self.res as u32).to_le_bytes());
        for v in self.z_nodes.iter().chain(self.coeffs.iter().flatten()) {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b
    }

    /// Parses the file contents of [`write`](Self::write).
    pub fn from_bytes(bytes: &[u8]) -> io::Result<RgbToSpectrumTable> {
        let bad = |what: &str| io::Error::new(io::ErrorKind::InvalidData, format!("RGB table: {what}"));
        if bytes.len() < 16 || &bytes[..8] != MAGIC {
            return Err(bad("not a prism RGB table"));
        }
        let word = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
        if word(8) != VERSION {
            return Err(bad("unknown version"));
        }
        let res = word(12) as usize;
        if !(3..=1024).contains(&res) || bytes.len() != 16 + 4 * (res + 9 * res * res * res) {
            return Err(bad("size does not match its resolution"));
        }
        let floats: Vec<f32> = bytes[16..].chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
        let (z_nodes, rest) = floats.split_at(res);
        if !z_nodes.windows(2).all(|w| w[0] < w[1]) || rest.iter().any(|v| !v.is_finite()) {
            return Err(bad("nodes not increasing or coefficients not finite"));
        }
        Ok(RgbToSpectrumTable {
            res,
            z_nodes: z_nodes.to_vec(),
            coeffs: rest.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        })
    }

    /// Trilinearly interpolated normalised-wavelength coefficients. Needs
    /// rgb in [0, 1]^3, not black.
    fn lookup(&self, rgb: [f32; 3]) -> [f64; 3] {
        let res = self.res;
        let m = if rgb[0] > rgb[1] {
            if rgb[0] > rgb[2] {
                0
            } else {
                2
            }
        } else if rgb[1] > rgb[2] {
            1
        } else {
            2
        };
        let z = rgb[m];
        let last = (res - 1) as f32;
        let x = (rgb[(m + 1) % 3] / z * last).clamp(0.0, last);
        let y = (rgb[(m + 2) % 3] / z * last).clamp(0.0, last);
        let xi = (x as usize).min(res - 2);
        let yi = (y as usize).min(res - 2);
        let zi = self.z_nodes.partition_point(|&n| n <= z).saturating_sub(1).min(res - 2);
        let dx = (x - xi as f32) as f64;
        let dy = (y - yi as f32) as f64;
        let dz = ((z - self.z_nodes[zi]) / (self.z_nodes[zi + 1] - self.z_nodes[zi])).clamp(0.0, 1.0) as f64;
        let mut c = [0.0f64; 3];
        for (dk, wz) in [(0, 1.0 - dz), (1, dz)] {
            for (dj, wy) in [(0, 1.0 - dy), (1, dy)] {
                for (di, wx) in [(0, 1.0 - dx), (1, dx)] {
                    let cell = self.coeffs[((m * res + zi + dk) * res + yi + dj) * res + xi + di];
                    let w = wx * wy * wz;
                    for q in 0..3 {
                        c[q] += w * cell[q] as f64;
                    }
                }
            }
        }
        c
    }

    /// Coefficients (c0, c1, c2) of the reflectance
    /// S(c0 l^2 + c1 l + c2), l in nm, for linear sRGB `rgb` (clamped to
    /// [0, 1]), interpolated from the table without polishing (pbrt-v4's
    /// `RGBToSpectrumTable`): for textures, evaluate with
    /// [`sigmoid_polynomial`]. Greys g give the exactly flat (0, 0, x) with
    /// S(x) = g, x = (g - 1/2) / sqrt(g (1 - g)), clamped to +-1e4 for g = 0, 1
    /// (where S evaluates to exactly 0 or 1 in f32).
    pub fn coefficients(&self, rgb: [f32; 3]) -> [f32; 3] {
        let rgb = rgb.map(clamp_unit);
        if rgb[0] == rgb[1] && rgb[1] == rgb[2] {
            let x = flat_coefficient(rgb[0] as f64).clamp(-1e4, 1e4);
            return [0.0, 0.0, x as f32];
        }
        to_nanometres(&self.lookup(rgb)).map(|v| v as f32)
    }
}

/// The c2 of the flat reflectance g: S(c2) = g for
/// c2 = (g - 1/2) / sqrt(g (1 - g)) (infinite at g = 0 and 1).
fn flat_coefficient(g: f64) -> f64 {
    (g - 0.5) / (g * (1.0 - g)).sqrt()
}

/// Normalised-wavelength coefficients (t = (l - 360) / 470) to nanometres:
/// expand A t^2 + B t + C with t = (l - l0) / w.
fn to_nanometres(c: &[f64; 3]) -> [f64; 3] {
    let (l0, w) = (LAMBDA_MIN as f64, LAMBDA_SPAN);
    let [a, b, cc] = *c;
    [a / (w * w), b / w - 2.0 * a * l0 / (w * w), cc - b * l0 / w + a * l0 * l0 / (w * w)]
}

/// The reflectance S(c0 l^2 + c1 l + c2) at `lambda` nm, for coefficients from
/// [`RgbToSpectrumTable::coefficients`]; in [0, 1].
#[inline]
pub fn sigmoid_polynomial(c: [f32; 3], lambda: f32) -> f32 {
    let x = (c[0] * lambda + c[1]) * lambda + c[2];
    if x.is_infinite() {
        return if x > 0.0 { 1.0 } else { 0.0 };
    }
    if x.is_nan() {
        return 0.0;
    }
    (0.5 + x / (2.0 * (1.0 + x * x).sqrt())).clamp(0.0, 1.0)
}

/// [0, 1] clamp that sends NaN to 0.
fn clamp_unit(v: f32) -> f32 {
    if v > 0.0 {
        v.min(1.0)
    } else {
        0.0
    }
}

/// A smooth reflectance spectrum in [0, 1] whose linear sRGB colour under D65
/// (the module's round-trip definition) is `rgb`, to about 1e-5 in every
/// component (measured worst 6e-6 over a 97^3 grid and 2e5 random colours).
///
/// Components are clamped to [0, 1] first (NaN to 0): a reflectance cannot be
/// brighter than white. Greys, including black and white, give the flat
/// `Constant(g)`; other colours start from the committed table's
/// interpolated coefficients and are polished by Gauss-Newton in CIELAB (a few
/// steps of about 10 k flops each; a continuation fallback near white, see
/// `polish`).
pub fn rgb_albedo(rgb: [f32; 3]) -> Spectrum {
    let rgb = rgb.map(clamp_unit);
    if rgb[0] == rgb[1] && rgb[1] == rgb[2] {
        return Spectrum::Constant(rgb[0]);
    }
    let c = polish(rgb.map(|v| v as f64), RgbToSpectrumTable::get().lookup(rgb));
    fit::spectrum_of(&c)
}

/// Coefficients for `rgb` from the table's interpolated `start`.
///
/// Gauss-Newton from `start` converges in a few steps almost everywhere. Near
/// white, though, the solution's shape changes quickly across a cell (a
/// single dip of the reflectance on one side, dips at both ends of the
/// spectrum on the other), the interpolated start can lie outside the basin,
/// and the iteration runs off to large coefficients. Then continuation
/// (homotopy) takes over: `start` solves its own colour exactly, so the
/// target is approached along the segment from that colour in small steps,
/// each warm-started from the last, the way the table's chains are solved.
fn polish(rgb: [f64; 3], start: [f64; 3]) -> [f64; 3] {
    let mut best = start;
    let mut best_err = fit::fit(rgb, &mut best, POLISH_FIT);
    if best_err <= POLISH_FIT.rgb_tolerance {
        return best;
    }
    let from = fit::rgb_of(&start);
    for steps in [8, 64] {
        let mut c = start;
        for s in 1..steps {
            let a = s as f64 / steps as f64;
            let via = [0, 1, 2].map(|q| from[q] + a * (rgb[q] - from[q]));
            fit::fit(via, &mut c, CONTINUATION_FIT);
        }
        let err = fit::fit(rgb, &mut c, POLISH_FIT);
        if err < best_err {
            (best, best_err) = (c, err);
        }
        if best_err <= POLISH_FIT.rgb_tolerance {
            break;
        }
    }
    best
}

/// An emission spectrum for linear sRGB `rgb` (pbrt-v4's
/// `RGBIlluminantSpectrum`): with m the largest component, the reflectance
/// `rgb_albedo(rgb / m)` times D65 (Y = 1) times m. Seen directly its colour
/// is `rgb`; white (1, 1, 1) is exactly D65 with luminance 1, and (s, s, s) is
/// s D65. Negative components and NaN are clamped to 0; there is no upper
/// bound (components must be finite).
pub fn rgb_illuminant(rgb: [f32; 3]) -> Spectrum {
    let rgb = rgb.map(|v| if v > 0.0 { v } else { 0.0 });
    let m = rgb[0].max(rgb[1]).max(rgb[2]);
    if m == 0.0 {
        return Spectrum::Constant(0.0);
    }
    let d65 = illuminant("D65").expect("D65 is tabulated");
    let shape = rgb_albedo(rgb.map(|v| v / m));
    if shape == Spectrum::Constant(1.0) {
        d65.scale(m)
    } else {
        shape.scaled_by(&d65).scale(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The committed data is what `generate` produces: re-solve a few whole
    /// chains (one per table, including the corner towards the pure primary
    /// and the grey diagonal) and compare every cell.
    #[test]
    fn committed_table_matches_freshly_solved_chains() {
        let t = RgbToSpectrumTable::get();
        let res = t.res;
        assert_eq!(res, 32);
        assert_eq!(t.z_nodes, z_nodes(res));
        for (m, i, j) in [(0, 0, 0), (1, 7, 30), (2, 31, 12), (0, 31, 31)] {
            let fresh = solve_chain(res, &t.z_nodes, m, i, j);
            for (k, c) in fresh.iter().enumerate() {
                let stored = t.coeffs[((m * res + k) * res + j) * res + i];
                for q in 0..3 {
                    let tol = 1e-4 * c[q].abs().max(1.0);
                    assert!(
                        (stored[q] - c[q]).abs() <= tol,
                        "cell (m {m}, k {k}, j {j}, i {i}): stored {stored:?}, fresh {c:?}"
                    );
                }
            }
        }
    }

    /// Every stored cell reproduces its own colour (to f32 storage of the
    /// coefficients); the black cell copies its neighbour.
    #[test]
    fn committed_cells_reproduce_their_colours() {
        let t = RgbToSpectrumTable::get();
        let res = t.res;
        let mut worst = 0.0f64;
        for m in 0..3 {
            for k in 1..res {
                for j in (0..res).step_by(3) {
                    for i in (0..res).step_by(3) {
                        let idx = ((m * res + k) * res + j) * res + i;
                        let rgb = cell_rgb(res, t.z_nodes[k], m, i, j);
                        let back = fit::rgb_of(&t.coeffs[idx].map(|v| v as f64));
                        for q in 0..3 {
                            worst = worst.max((back[q] - rgb[q]).abs());
                        }
                    }
                }
            }
            for j in 0..res {
                for i in 0..res {
                    let c0 = t.coeffs[(m * res * res + j) * res + i];
                    assert_eq!(c0, t.coeffs[((m * res + 1) * res + j) * res + i]);
                }
            }
        }
        assert!(worst < 1e-5, "{worst}");
    }

    #[test]
    fn nanometre_coefficients_evaluate_like_normalised_ones() {
        let c = [-12.0, 9.5, -1.25];
        let nm = to_nanometres(&c).map(|v| v as f32);
        for l in [360.0f32, 432.0, 555.0, 700.0, 830.0] {
            let t = (l as f64 - 360.0) / 470.0;
            let s = fit::sigmoid((c[0] * t + c[1]) * t + c[2]) as f32;
            assert!((sigmoid_polynomial(nm, l) - s).abs() < 1e-5, "{l}");
        }
        assert_eq!(sigmoid_polynomial([0.0, 0.0, f32::INFINITY], 500.0), 1.0);
        assert_eq!(sigmoid_polynomial([0.0, 0.0, -1e4], 500.0), 0.0);
        assert_eq!(sigmoid_polynomial([0.0, 0.0, 1e4], 500.0), 1.0);
    }

    #[test]
    fn lookup_of_a_cell_colour_returns_the_cell() {
        let t = RgbToSpectrumTable::get();
        let res = t.res;
        let (m, k, j, i) = (1, 20, 5, 9);
        let rgb = cell_rgb(res, t.z_nodes[k], m, i, j).map(|v| v as f32);
        let c = t.lookup(rgb);
        let stored = t.coeffs[((m * res + k) * res + j) * res + i];
        for q in 0..3 {
            assert!((c[q] - stored[q] as f64).abs() < 1e-3 * (1.0 + c[q].abs()), "{c:?} {stored:?}");
        }
    }
}
