//! Per-strategy images (`render::render_with_strategies`, BDPT's `--strategies`):
//! the integrator appends a small `StrategyRecord` per strategy to the
//! workspace; the task sums the t >= 2 ones into per-(s, t) buffers for its
//! own pixels and keeps the t = 1 ones as splats, both in sample order, and
//! the merge adds them in task order like the film: still
//! deterministic. Without it the workspace holds no record list and the
//! integrator's check costs one branch.

use crate::film::DroppedSamples;
use crate::output::Outputs;
use crate::render::splat_pixel;
use crate::spectrum::{SampledCmf, SampledSpectrum};
use glam::{UVec2, Vec2, Vec3};
use std::collections::BTreeMap;
use std::path::Path;

/// One connection strategy's contribution to a sample of a bidirectional
/// estimator: `weighted` is what went into the image (times the MIS weight),
/// `unweighted` the strategy's contribution alone. A t >= 2 record belongs to
/// the sample's pixel; a t = 1 record is a splat at `raster`.
#[derive(Clone, Copy, Debug)]
pub struct StrategyRecord {
    pub s: u32,
    pub t: u32,
    pub raster: Vec2,
    pub weighted: SampledSpectrum,
    pub unweighted: SampledSpectrum,
}

/// Sums of weighted and unweighted contributions per pixel, for every
/// strategy (s, t) of paths of at most `max_length` bounces (s + t - 2)
/// that contributed, and for all longer ones together under `LONGER`
/// (linear sRGB, like `Film`). The weighted images still add up to the
/// image. Without the bound, every length a render's paths reach had its
/// own images: ~2,300 strategies (110 MB, 4,600 files) for the white room
/// at 32x32, and past this machine's memory at 512x512 (an audit, session
/// 49).
pub struct StrategyImages {
    pub width: u32,
    pub height: u32,
    /// The longest paths, in bounces, whose strategies have images of
    /// their own.
    pub max_length: u32,
    /// Samples per pixel accumulated so far.
    pub spp: u64,
    /// (s, t) -> [weighted, unweighted] sums per pixel.
    pub sums: BTreeMap<(u32, u32), [Vec<[f64; 3]>; 2]>,
    /// Records kept out (NaN, infinite, negative), counted apart from the film's.
    pub dropped: DroppedSamples,
}

/// The key in `StrategyImages::sums` of the strategies of paths longer
/// than `max_length`, together; only their weighted sum is written (the sum
/// of their unweighted estimates estimates nothing).
pub const LONGER: (u32, u32) = (u32::MAX, u32::MAX);

/// The key of strategy (s, t)'s sums: its own for paths of at most
/// `max_length` bounces (s + t - 2), `LONGER` for longer ones (and for
/// `LONGER` itself).
fn key(s: u32, t: u32, max_length: u32) -> (u32, u32) {
    if s.saturating_add(t).saturating_sub(2) > max_length {
        LONGER
    } else {
        (s, t)
    }
}

/// The file of `LONGER`'s weighted image.
const LONGER_FILE: &str = "longer_paths_weighted.exr";

/// What `--strategies-max-length` is when not given.
pub const DEFAULT_MAX_LENGTH: u32 = 8;

impl StrategyImages {
    pub fn new(width: u32, height: u32, max_length: u32) -> Self {
        Self { width, height, max_length, spp: 0, sums: BTreeMap::new(), dropped: DroppedSamples::default() }
    }

    /// Bytes the images of paths up to `max_length` bounces can take at
    /// `width` x `height` when no path is longer than `max_depth`: K =
    /// min(max_length, max_depth), (K + 1)(K + 4) / 2 strategies (K + 2 of
    /// length K), and `LONGER` if max_depth > max_length, each two images
    /// of three f64 a pixel.
    pub fn most_bytes(width: u32, height: u32, max_length: u32, max_depth: u32) -> f64 {
        let k = max_length.min(max_depth) as f64;
        let longer = if max_depth > max_length { 1.0 } else { 0.0 };
        ((k + 1.0) * (k + 4.0) / 2.0 + longer) * 48.0 * width as f64 * height as f64
    }

    fn buffers(&mut self, (s, t): (u32, u32)) -> &mut [Vec<[f64; 3]>; 2] {
        let n = (self.width * self.height) as usize;
        self.sums.entry(key(s, t, self.max_length)).or_insert_with(|| [vec![[0.0; 3]; n], vec![[0.0; 3]; n]])
    }

    /// The image of strategy (s, t), weighted (its share of the final image)
    /// or unweighted (its own estimate of the paths it can make), divided by
    /// spp as `Film::image` does.
    pub fn image(&self, s: u32, t: u32, weighted: bool) -> Option<Vec<[f32; 3]>> {
        let inv = if self.spp == 0 { 0.0 } else { 1.0 / self.spp as f64 };
        let b = &self.sums.get(&(s, t))?[if weighted { 0 } else { 1 }];
        Some(b.iter().map(|p| p.map(|c| (c * inv) as f32)).collect())
    }

    /// Stages `s<s>_t<t>_weighted.exr` and `s<s>_t<t>_unweighted.exr` for
    /// every strategy in `dir`, and `longer_paths_weighted.exr` for
    /// `LONGER`; returns their file names.
    pub fn stage_exrs(&self, dir: &Path, out: &mut Outputs) -> anyhow::Result<Vec<String>> {
        let mut names = Vec::new();
        for &(s, t) in self.sums.keys() {
            for (weighted, name) in [(true, "weighted"), (false, "unweighted")] {
                if (s, t) == LONGER && !weighted {
                    continue;
                }
                let file = if (s, t) == LONGER { LONGER_FILE.to_string() } else { format!("s{s}_t{t}_{name}.exr") };
                let image = self.image(s, t, weighted).expect("strategy present");
                out.exr(&dir.join(&file), self.width, self.height, &image)?;
                names.push(file);
            }
        }
        Ok(names)
    }
}

/// Refuses per-strategy images of paths up to `max_length` bounces (of at
/// most `max_depth`) at `width` x `height` that this machine could not hold
/// (`StrategyImages::most_bytes`).
pub fn check_memory(width: u32, height: u32, max_length: u32, max_depth: u32) -> Result<(), String> {
    let bytes = StrategyImages::most_bytes(width, height, max_length, max_depth);
    let what = format!("the images of every strategy of paths up to {max_length} bounces at {width}x{height}");
    crate::stats::check_fits(bytes, &what).map_err(|e| format!("{e} (choose fewer bounces or pixels)"))
}

/// Whether `name` is a file name `StrategyImages::stage_exrs` writes.
pub fn is_strategy_image(name: &str) -> bool {
    if name == LONGER_FILE {
        return true;
    }
    let number = |x: &str| !x.is_empty() && x.bytes().all(|b| b.is_ascii_digit());
    let Some(rest) = name.strip_prefix('s') else { return false };
    let Some((s, rest)) = rest.split_once("_t") else { return false };
    let Some((t, kind)) = rest.split_once('_') else { return false };
    number(s) && number(t) && (kind == "weighted.exr" || kind == "unweighted.exr")
}

/// A task's strategy records: per-(s, t) sums over its own pixels (t >= 2)
/// and splats (t = 1: pixel index, s, t, [weighted, unweighted]), those of
/// paths longer than `max_length` under `LONGER` already.
pub(crate) struct TaskStrategies {
    max_length: u32,
    pixels: BTreeMap<(u32, u32), Vec<[[f64; 3]; 2]>>,
    splats: Vec<(u32, u32, u32, [[f64; 3]; 2])>,
    dropped: DroppedSamples,
}

impl TaskStrategies {
    pub(crate) fn new(max_length: u32) -> Self {
        Self { max_length, pixels: BTreeMap::new(), splats: Vec::new(), dropped: DroppedSamples::default() }
    }

    /// A sample's strategy records: t >= 2 ones are summed into the task's
    /// pixel `local` (of `n`), t = 1 ones kept as splats.
    pub(crate) fn add(&mut self, records: &[StrategyRecord], local: usize, n: usize, cmf: &SampledCmf, image: UVec2) {
        for r in records {
            // Each image refuses its own value: an infinite unweighted
            // estimate must not take the weighted one (the film's share) away.
            let (w, u) = (self.dropped.admit(r.weighted, cmf), self.dropped.admit(r.unweighted, cmf));
            if w.is_none() && u.is_none() {
                continue;
            }
            let rgb = [w, u].map(|c| c.unwrap_or(Vec3::ZERO).to_array().map(f64::from));
            let (s, t) = key(r.s, r.t, self.max_length);
            if r.t == 1 {
                self.splats.push((splat_pixel(r.raster, image), s, t, rgb));
            } else {
                let sums = self.pixels.entry((s, t)).or_insert_with(|| vec![[[0.0; 3]; 2]; n]);
                add_pair(&mut sums[local], &rgb);
            }
        }
    }
}

/// `sum += v` for a [weighted, unweighted] pair of colours.
fn add_pair(sum: &mut [[f64; 3]; 2], v: &[[f64; 3]; 2]) {
    for (s, v) in sum.iter_mut().flatten().zip(v.iter().flatten()) {
        *s += v;
    }
}

impl StrategyImages {
    /// Adds a task's records: its pixel sums (the `size` tile at `origin`)
    /// and its splats.
    pub(crate) fn add_task(&mut self, origin: UVec2, size: UVec2, records: TaskStrategies) {
        let width = self.width;
        for (st, sums) in records.pixels {
            let buffers = self.buffers(st);
            for y in 0..size.y {
                for x in 0..size.x {
                    let i = ((origin.y + y) * width + origin.x + x) as usize;
                    add_to_buffers(buffers, i, &sums[(y * size.x + x) as usize]);
                }
            }
        }
        for (i, s, t, v) in records.splats {
            add_to_buffers(self.buffers((s, t)), i as usize, &v);
        }
        self.dropped.merge(&records.dropped);
    }
}

/// Adds a [weighted, unweighted] pair to pixel `i` of a strategy's buffers.
fn add_to_buffers(buffers: &mut [Vec<[f64; 3]>; 2], i: usize, v: &[[f64; 3]; 2]) {
    for (buffer, v) in buffers.iter_mut().zip(v) {
        for (s, v) in buffer[i].iter_mut().zip(v) {
            *s += v;
        }
    }
}
