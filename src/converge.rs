//! `prism converge`: the variance benchmark of VALIDATION.md §6. Each
//! integrator renders the scene progressively (consecutive sample ranges
//! through `render::render`) under a time budget and/or an spp cap; at
//! log-spaced checkpoints the image is compared with a reference: relMSE
//! (mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01)), MSE and
//! mean absolute error. Efficiency is 1 / (relMSE x seconds) at the last
//! checkpoint: the number to compare between estimators.
//!
//! Outputs (all in `--out DIR`): `results.csv` and `results.json` (every
//! checkpoint), `error-vs-time.{svg,png}` and `error-vs-spp.{svg,png}`
//! (log-log, one line per integrator; the spp chart adds a slope -1 line),
//! `images.png` (reference and final images side by side), `errors.png`
//! (false-colour per-pixel relative squared error) and `report.md` (all of
//! it, with the efficiency table, best first). Charts are plotters SVGs;
//! the PNGs are rasterised by resvg with the DejaVu Sans font embedded in
//! the binary (assets/fonts), so no system font library is needed.
//!
//! Checkpoints and determinism: sample ranges are cut at the spp grid
//! 1, 2, 3, 4, 5, 6, 7, 8, 10, 11, 13, 16, ... (round(2^(k/4))), so the image at a
//! grid checkpoint depends only on the scene, seed and spp: its relMSE is
//! bit-reproducible (`by_spp = true`). Wall time is measured, not
//! reproducible; when the time budget runs out between two grid points, the
//! last chunk is shortened to fit it (`by_spp = false` from there on). The
//! clock counts rendering only, not the evaluation of checkpoints.
//!
//! Clocks: every checkpoint records wall seconds and the process's CPU
//! seconds spent rendering (Linux /proc/self/stat, 10 ms ticks). `--clock`
//! picks the one the budget, the time chart and the efficiency use: `wall`
//! (default) is what a user waits; `cpu` is the work done, and stays fair
//! between integrators on a machine shared with other jobs, where wall time
//! depends on what else happened to run at the same moment. A run shorter
//! than ten ticks of its clock (`Clock::min_seconds`: 0.1 CPU seconds) gets
//! no efficiency and no rank, and a note says so.
//!
//! Notes (in report.md and results.json, and printed) also flag a reference
//! whose own noise is over 10 % of an integrator's measured relMSE (the
//! ratios are then pulled towards 1), a reference rendered from another
//! scene file, and one whose integrator cannot sample the whole scene (it is
//! biased, and every error measured against it). No output may replace the
//! scene, the reference or another output (`film::check_outputs`).
//!
//! Integrator specs: `name` or `name:heuristic` (`bdpt:uniform`), so one run
//! can compare MIS heuristics of the same estimator as separate lines;
//! `--mis a,b` expands a bare `bdpt` into `bdpt:a`, `bdpt:b`.
//!
//! The reference is either an EXR (with the sidecar of `prism reference`,
//! or of the `prism render` or `prism merge` that made it, if present) or
//! rendered here (`--reference-spp`) with seeds disjoint from the
//! run's (`REFERENCE_SEED_OFFSET`): a reference sharing sample streams with
//! the image it judges would correlate with it and flatter it.
//!
//! | option                   | default        | meaning                                             |
//! |--------------------------|----------------|-----------------------------------------------------|
//! | --integrators            | path,light,bdpt | comma-separated specs (`name[:heuristic]`)         |
//! | --mis                    | power          | heuristics for bare MIS-aware specs (bdpt)          |
//! | --reference              | -              | reference EXR (+ optional sidecar)                  |
//! | --reference-spp          | -              | render the reference here: total spp                |
//! | --reference-integrator   | bdpt           | its integrator (power heuristic)                    |
//! | --reference-passes       | 8              | independent passes it is made of (block errors)     |
//! | --reference-out          | DIR/reference.exr | where the rendered reference and sidecar go      |
//! | --time                   | -              | time budget per integrator, seconds (of `--clock`)  |
//! | --clock                  | wall           | `wall` or `cpu` (CPU seconds of all render threads) |
//! | --spp                    | -              | spp cap per integrator (deterministic runs)         |
//! | --width, --height        | the scene's    | resolution                                          |
//! | --seed                   | scene's, else 0 | base seed of the run                               |
//! | --exposure               | automatic      | PNG exposure in stops (default: log-average key 0.18) |
//! | --save-exr               | off            | also write each final image as `DIR/<label>.exr`    |

use crate::camera::Camera;
use crate::film::{
    check_outputs, check_writable, ensure_exr, read_exr, write_atomically, write_exr, write_json, DroppedSamples, Film,
};
use crate::integrators::{self, IntegratorOptions, MisHeuristic, INTEGRATORS};
use crate::reference::{make_reference, write_reference, ReferenceMeta};
use crate::render::{render, RenderOptions};
use crate::scene::{load_scene, Scene};
use crate::stats::rel_mse;
use anyhow::{bail, ensure, Context, Result};
use image::{Rgb, RgbImage};
use indicatif::{ProgressBar, ProgressStyle};
use plotters::prelude::*;
use serde::{Deserialize, Serialize};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};
use std::time::Duration;

/// Added to the run's seed for a reference rendered by `converge` itself, so
/// its passes (seeds offset .. offset + passes) never share sample streams
/// with the run.
pub const REFERENCE_SEED_OFFSET: u64 = 1 << 32;

/// The font chart text is rasterised with (see assets/fonts/LICENSE-DejaVu.txt).
const FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");
const FONT_FAMILY: &str = "DejaVu Sans";

/// Line colours (Tableau 10), one per integrator, in command-line order.
const PALETTE: [(u8, u8, u8); 8] = [
    (31, 119, 180),
    (214, 39, 40),
    (44, 160, 44),
    (255, 127, 14),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (23, 190, 207),
];

// ------------------------------------------------------------------ the CLI

/// `prism converge`: error against a reference vs time and spp, per integrator.
#[derive(clap::Args, Debug)]
pub struct ConvergeArgs {
    /// Scene file (JSON).
    pub scene: PathBuf,
    /// Comma-separated integrator specs, `name` or `name:heuristic` (e.g.
    /// `path,light,bdpt,bdpt:uniform`).
    #[arg(long, default_value = "path,light,bdpt")]
    pub integrators: String,
    /// MIS heuristics for bare `bdpt` specs: several expand it into one line each.
    #[arg(long, value_delimiter = ',', default_value = "power")]
    pub mis: Vec<MisHeuristic>,
    /// Reference EXR (its sidecar, from `prism reference`, `render` or
    /// `merge`, is used if present).
    #[arg(long, conflicts_with = "reference_spp")]
    pub reference: Option<PathBuf>,
    /// Render the reference here with this many samples per pixel in total.
    #[arg(long)]
    pub reference_spp: Option<u32>,
    /// Integrator of a reference rendered here.
    #[arg(long, default_value = "bdpt")]
    pub reference_integrator: String,
    /// Independent passes of a reference rendered here (its sidecar keeps
    /// per-block standard errors).
    #[arg(long, default_value_t = 8)]
    pub reference_passes: u32,
    /// Where a reference rendered here is written (default DIR/reference.exr).
    #[arg(long)]
    pub reference_out: Option<PathBuf>,
    /// Time budget per integrator, in seconds of `--clock`.
    #[arg(long, allow_negative_numbers = true)]
    pub time: Option<f64>,
    /// What seconds are: `wall` (elapsed) or `cpu` (CPU time of all render
    /// threads: fair on a machine shared with other jobs).
    #[arg(long, value_enum, default_value = "wall")]
    pub clock: Clock,
    /// Samples-per-pixel cap per integrator (with no --time: a fully
    /// deterministic run).
    #[arg(long)]
    pub spp: Option<u32>,
    /// Output directory (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long)]
    pub width: Option<u32>,
    #[arg(long)]
    pub height: Option<u32>,
    #[arg(long)]
    pub seed: Option<u64>,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// PNG exposure in stops (default: automatic, from the reference).
    #[arg(long, allow_negative_numbers = true)]
    pub exposure: Option<f32>,
    /// Also write each final image as DIR/<label>.exr.
    #[arg(long)]
    pub save_exr: bool,
    /// No progress bars.
    #[arg(long)]
    pub quiet: bool,
}

/// Runs `prism converge` with parsed arguments and prints the efficiency table.
pub fn command(a: ConvergeArgs) -> Result<()> {
    let specs = IntegratorSpec::parse_list(&a.integrators, &a.mis)?;
    let resolution = match (a.width, a.height) {
        (None, None) => None,
        (Some(w), Some(h)) if w > 0 && h > 0 => {
            Camera::check_resolution(w, h).map_err(|e| anyhow::anyhow!("--width, --height: {e}"))?;
            Some((w, h))
        }
        _ => bail!("--width and --height must be given together and be at least 1"),
    };
    crate::render::check_threads(a.threads)?;
    let reference = match (&a.reference, a.reference_spp) {
        (Some(p), None) => ReferenceSource::File(p.clone()),
        (None, Some(spp)) => ReferenceSource::Render {
            integrator: a.reference_integrator.clone(),
            spp,
            passes: a.reference_passes,
            out: a.reference_out.clone().unwrap_or_else(|| a.out.join("reference.exr")),
        },
        _ => bail!("give the reference: --reference REF.exr or --reference-spp N"),
    };
    let config = ConvergeConfig {
        scene: a.scene,
        integrators: specs,
        reference,
        time: a.time,
        clock: a.clock,
        max_spp: a.spp,
        out: a.out,
        resolution,
        seed: a.seed,
        threads: a.threads,
        max_depth: a.max_depth,
        progress: !a.quiet,
        exposure: a.exposure,
        save_exr: a.save_exr,
        command: std::env::args().collect::<Vec<_>>().join(" "),
    };
    let results = run(&config)?;
    for n in &results.notes {
        eprintln!("note: {n}");
    }
    eprintln!("{}", efficiency_table(&results));
    eprintln!("wrote {}", config.out.join("report.md").display());
    Ok(())
}

// ------------------------------------------------------------ configuration

/// One line of the comparison: an integrator and its MIS heuristic.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct IntegratorSpec {
    /// What charts and tables call it (`bdpt`, `bdpt:uniform`).
    pub label: String,
    /// Registry name.
    pub name: String,
    pub mis: MisHeuristic,
}

impl IntegratorSpec {
    /// Parses `path,light,bdpt:uniform`; a bare MIS-aware name takes each of
    /// `mis` (one line per heuristic; the power heuristic keeps the bare name).
    pub fn parse_list(list: &str, mis: &[MisHeuristic]) -> Result<Vec<IntegratorSpec>> {
        let mis = if mis.is_empty() { &[MisHeuristic::Power][..] } else { mis };
        let mut specs = Vec::new();
        for item in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (name, heuristic) = match item.split_once(':') {
                Some((n, h)) => (n, Some(h.parse::<MisHeuristic>().map_err(anyhow::Error::msg)?)),
                None => (item, None),
            };
            integrators::create(name, &IntegratorOptions::default()).map_err(anyhow::Error::msg)?;
            // A heuristic suffix on an integrator that ignores it would
            // label a line with a setting it does not use.
            let aware = integrators::reads_mis(name);
            match heuristic {
                Some(_) if !aware => {
                    let names: Vec<&str> = INTEGRATORS.iter().filter(|i| i.reads_mis).map(|i| i.name).collect();
                    bail!("\"{item}\": only {} take a MIS heuristic", names.join(", "))
                }
                Some(h) => specs.push(IntegratorSpec { label: item.to_string(), name: name.to_string(), mis: h }),
                None if aware && (mis.len() > 1 || mis[0] != MisHeuristic::Power) => {
                    for &h in mis {
                        let label = format!("{name}:{}", heuristic_name(h));
                        specs.push(IntegratorSpec { label, name: name.to_string(), mis: h });
                    }
                }
                // (Power: what a MIS-aware estimator takes by default, and
                // what the others record, since --mis does not reach them.)
                None => specs.push(IntegratorSpec {
                    label: name.to_string(),
                    name: name.to_string(),
                    mis: MisHeuristic::Power,
                }),
            }
        }
        ensure!(!specs.is_empty(), "no integrators given");
        // The same estimator twice (`bdpt,bdpt:power`) would be ranked
        // against itself.
        for (i, s) in specs.iter().enumerate() {
            match specs[..i].iter().find(|o| (&o.name, o.mis) == (&s.name, s.mis)) {
                Some(o) if o.label == s.label => bail!("integrator \"{}\" given twice", s.label),
                Some(o) => bail!("integrators \"{}\" and \"{}\" are the same estimator", o.label, s.label),
                None => {}
            }
        }
        Ok(specs)
    }

    /// The label made safe for a file name (`bdpt:uniform` -> `bdpt-uniform`).
    pub fn file_stem(&self) -> String {
        file_stem(&self.label)
    }
}

fn file_stem(label: &str) -> String {
    label.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' || c == '-' { c } else { '-' }).collect()
}

fn heuristic_name(h: MisHeuristic) -> &'static str {
    match h {
        MisHeuristic::Power => "power",
        MisHeuristic::Balance => "balance",
        MisHeuristic::Uniform => "uniform",
    }
}

/// The clock that budgets, charts and efficiencies use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Clock {
    /// Elapsed (wall-clock) seconds of rendering.
    #[default]
    Wall,
    /// CPU seconds of all rendering threads (Linux only).
    Cpu,
}

impl Clock {
    fn unit(self) -> &'static str {
        match self {
            Clock::Wall => "seconds",
            Clock::Cpu => "CPU seconds",
        }
    }

    /// The shortest time this clock measures well enough to rank a run by:
    /// ten of its ticks (/proc's CPU times advance in 10 ms ticks).
    pub fn min_seconds(self) -> f64 {
        match self {
            Clock::Wall => 1e-8,
            Clock::Cpu => 0.1,
        }
    }
}

/// CPU time (user + system) of this process so far, all threads, from
/// /proc/self/stat (in USER_HZ = 100 ticks per second on Linux).
pub fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name, which may contain spaces:
    // state is field 3, utime 14 and stime 15.
    let rest = &stat[stat.rfind(')')? + 1..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?;
    Some(ticks as f64 / 100.0)
}

/// Where the reference comes from.
#[derive(Clone, Debug)]
pub enum ReferenceSource {
    /// An EXR at the run's resolution; `prism reference`'s sidecar is used if present.
    File(PathBuf),
    /// Rendered before the run: `spp` samples per pixel in total, split into
    /// `passes` independent passes, written to `out` (EXR + sidecar).
    Render { integrator: String, spp: u32, passes: u32, out: PathBuf },
}

/// Everything a run needs (`command` builds it from the CLI).
#[derive(Clone, Debug)]
pub struct ConvergeConfig {
    pub scene: PathBuf,
    pub integrators: Vec<IntegratorSpec>,
    pub reference: ReferenceSource,
    /// Time budget per integrator (seconds of rendering on `clock`).
    pub time: Option<f64>,
    pub clock: Clock,
    /// Samples-per-pixel cap per integrator.
    pub max_spp: Option<u32>,
    pub out: PathBuf,
    pub resolution: Option<(u32, u32)>,
    /// Base seed; `None`: the scene's, else 0.
    pub seed: Option<u64>,
    pub threads: usize,
    pub max_depth: Option<u32>,
    pub progress: bool,
    /// PNG exposure in stops; `None`: automatic.
    pub exposure: Option<f32>,
    pub save_exr: bool,
    /// The command line, recorded in the outputs.
    pub command: String,
}

// ------------------------------------------------------------------ results

/// The error of one image against the reference.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct Checkpoint {
    pub spp: u32,
    /// Wall seconds of rendering so far (checkpoint evaluation excluded).
    pub seconds: f64,
    /// CPU seconds of rendering so far, all threads (None where unavailable).
    pub cpu_seconds: Option<f64>,
    pub rel_mse: f64,
    pub mse: f64,
    pub mae: f64,
    /// True when the image is fixed by (scene, seed, spp): the checkpoint's
    /// errors are bit-reproducible (its seconds are not).
    pub by_spp: bool,
}

impl Checkpoint {
    /// Seconds on `clock` (CPU falls back to wall where CPU time is unknown).
    pub fn time(&self, clock: Clock) -> f64 {
        match clock {
            Clock::Wall => self.seconds,
            Clock::Cpu => self.cpu_seconds.unwrap_or(self.seconds),
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct IntegratorResult {
    pub label: String,
    pub integrator: String,
    pub mis: String,
    /// Path classes of the scene the integrator cannot sample (its image
    /// then converges to something else than the reference).
    pub warnings: Vec<String>,
    pub checkpoints: Vec<Checkpoint>,
    /// The last checkpoint's values (`seconds` on the run's clock).
    pub spp: u32,
    pub seconds: f64,
    pub wall_seconds: f64,
    pub rel_mse: f64,
    pub mse: f64,
    pub mae: f64,
    /// 1 / (relMSE x seconds) at the last checkpoint, seconds on the run's
    /// clock; NaN (null in the JSON) for a run too short to measure.
    #[serde(deserialize_with = "null_as_nan")]
    pub efficiency: f64,
    /// Samples per wall second.
    pub samples_per_second: f64,
    /// Least-squares slope of ln relMSE against ln spp over the grid
    /// checkpoints with spp >= 4 (-1 for an unbiased estimator, flatter once
    /// bias or the reference's own noise dominates).
    pub slope: Option<f64>,
    pub dropped: DroppedSamples,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ReferenceInfo {
    pub path: String,
    pub rendered_here: bool,
    pub integrator: Option<String>,
    /// Total samples per pixel (passes x spp per pass).
    pub spp: Option<u64>,
    pub passes: Option<u32>,
    pub seed: Option<u64>,
    pub wall_seconds: Option<f64>,
    /// Expected relMSE of the reference itself: the floor under every
    /// measured curve (see `noise_floor_method`).
    pub noise_floor: Option<f64>,
    /// How `noise_floor` was estimated: `same estimator` (the reference's
    /// integrator is one of the run's lines: measured relMSE at n spp is
    /// V/n + V/N, solved for V/N) or `block errors` (the sidecar's per-block
    /// standard errors; a rough upper estimate, since variance concentrates in
    /// bright pixels that relMSE weights less).
    pub noise_floor_method: Option<String>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ConvergeResults {
    pub scene: String,
    pub scene_comment: Option<String>,
    pub width: u32,
    pub height: u32,
    pub seed: u64,
    pub budget_seconds: Option<f64>,
    pub clock: Clock,
    pub max_spp: Option<u32>,
    pub threads: usize,
    pub max_depth: u32,
    pub reference: ReferenceInfo,
    pub notes: Vec<String>,
    pub command: String,
    pub commit: String,
    /// `crate::build_target` (absent in results written before it was
    /// recorded).
    #[serde(default)]
    pub build_target: String,
    pub prism_version: String,
    /// In command-line order.
    pub integrators: Vec<IntegratorResult>,
}

impl ConvergeResults {
    /// Indices of `integrators`, most efficient first.
    pub fn ranking(&self) -> Vec<usize> {
        let mut order: Vec<usize> = (0..self.integrators.len()).collect();
        // Unmeasurable (NaN) efficiencies last.
        let key = |i: usize| Some(self.integrators[i].efficiency).filter(|e| !e.is_nan());
        order.sort_by(|&a, &b| key(b).partial_cmp(&key(a)).unwrap_or(std::cmp::Ordering::Equal));
        order
    }
}

// ---------------------------------------------------------------------- run

/// The spp grid: round(2^(k/4)), k = 0, 1, ...: the smallest grid point above `n`.
pub fn next_grid_spp(n: u32) -> u32 {
    (0..)
        .map(|k| 2f64.powf(k as f64 / 4.0).round() as u64)
        .find(|&g| g > n as u64)
        .map_or(u32::MAX, |g| g.min(u32::MAX as u64) as u32)
}

/// relMSE, MSE and mean absolute error of `image` against `reference`.
pub fn errors(image: &[[f32; 3]], reference: &[[f32; 3]]) -> (f64, f64, f64) {
    let n = (image.len() * 3) as f64;
    let pairs = || image.iter().zip(reference).flat_map(|(x, r)| (0..3).map(move |c| (x[c] as f64, r[c] as f64)));
    let mse = pairs().map(|(x, r)| (x - r).powi(2)).sum::<f64>() / n;
    let mae = pairs().map(|(x, r)| (x - r).abs()).sum::<f64>() / n;
    (rel_mse(image, reference), mse, mae)
}

/// Renders every integrator progressively, writes all outputs into
/// `cfg.out`, and returns what they show.
pub fn run(cfg: &ConvergeConfig) -> Result<ConvergeResults> {
    ensure!(cfg.time.is_some() || cfg.max_spp.is_some(), "give a budget: --time SECONDS and/or --spp N");
    if let Some(t) = cfg.time {
        ensure!(t.is_finite() && t > 0.0, "--time must be a positive number of seconds");
    }
    ensure!(cfg.max_spp != Some(0), "--spp must be at least 1");
    // 2^exposure must be a normal f32: 0 or infinity would make black panels.
    ensure!(
        cfg.exposure.is_none_or(|e| 2f32.powf(e).is_normal()),
        "--exposure must be a number of stops in [-126, 127]"
    );
    if let ReferenceSource::Render { integrator, spp, passes, out } = &cfg.reference {
        ensure_exr("--reference-out", out)?;
        ensure!(*passes >= 2, "--reference-passes must be at least 2");
        ensure!(*spp >= 1, "--reference-spp must be at least 1");
        integrators::create(integrator, &IntegratorOptions::default()).map_err(anyhow::Error::msg)?;
    }
    check_converge_outputs(cfg)?;
    let mut builder = load_scene(&cfg.scene)?;
    if let Some((w, h)) = cfg.resolution {
        builder.set_resolution(w, h);
    }
    let defaults = builder.defaults.clone();
    let seed = cfg.seed.or(defaults.seed).unwrap_or(0);
    let max_depth = cfg.max_depth.or(defaults.max_depth).unwrap_or(IntegratorOptions::default().max_depth);
    let scene = builder.build();
    let (w, h) = (scene.camera.width, scene.camera.height);
    let estimators = cfg
        .integrators
        .iter()
        .map(|s| integrators::create(&s.name, &IntegratorOptions { max_depth, mis: s.mis }).map_err(anyhow::Error::msg))
        .collect::<Result<Vec<_>>>()?;
    let scene_name = cfg.scene.display().to_string();
    let mut notes = Vec::new();

    let (reference, info) = obtain_reference(cfg, &scene, &scene_name, seed, max_depth, &mut notes)?;
    ensure!(
        reference.len() == (w * h) as usize,
        "the reference has {} pixels but the run renders {w}x{h}: give --width/--height to match",
        reference.len()
    );
    std::fs::create_dir_all(&cfg.out).with_context(|| format!("cannot create {}", cfg.out.display()))?;
    check_converge_outputs(cfg)?;

    let mut results = Vec::new();
    let mut finals = Vec::new();
    for (spec, integrator) in cfg.integrators.iter().zip(&estimators) {
        let warnings = integrator.unsamplable(&scene);
        for warn in &warnings {
            eprintln!("warning: {}: {warn}", spec.label);
        }
        let (result, image) = converge_one(cfg, &scene, spec, integrator.as_ref(), seed, &reference, warnings)?;
        if result.dropped.total() > 0 {
            notes.push(format!(
                "{}: dropped {} samples ({} NaN, {} infinite, {} negative)",
                spec.label,
                result.dropped.total(),
                result.dropped.nan,
                result.dropped.infinite,
                result.dropped.negative
            ));
        }
        if cfg.save_exr {
            write_exr(&cfg.out.join(format!("{}.exr", spec.file_stem())), w, h, &image)?;
        }
        results.push(result);
        finals.push(image);
    }

    let mut info = info;
    let same = results.iter().find(|x| Some(&x.integrator) == info.integrator.as_ref() && x.mis == "power");
    if let (Some(x), Some(n_ref)) = (same, info.spp) {
        // m = V/n + V/N at the last checkpoint (independent seeds), so V/N = m / (N/n + 1).
        info.noise_floor = Some(x.rel_mse / (n_ref as f64 / x.spp as f64 + 1.0));
        info.noise_floor_method = Some(format!("same estimator ({})", x.label));
    }
    for x in &results {
        if x.efficiency.is_nan() {
            notes.push(format!(
                "{}: {:.3} {} is below {} s, too short to measure (the CPU clock ticks every 10 ms): not \
                 ranked; give a larger --time or --spp",
                x.label,
                x.seconds,
                cfg.clock.unit(),
                cfg.clock.min_seconds()
            ));
        }
        if let Some(floor) = info.noise_floor.filter(|&f| f > 0.1 * x.rel_mse) {
            notes.push(format!(
                "{}: the reference's own noise (relMSE ~{floor:.2e}) is {:.0} % of the measured {:.2e}: its \
                 efficiency ratios are pulled towards 1; render a reference with more samples",
                x.label,
                100.0 * floor / x.rel_mse,
                x.rel_mse
            ));
        }
    }
    let scene_comment = std::fs::read_to_string(&cfg.scene)
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| v.get("comment").and_then(|c| c.as_str()).map(str::to_string));
    let out = ConvergeResults {
        scene: scene_name,
        scene_comment,
        width: w,
        height: h,
        seed,
        budget_seconds: cfg.time,
        clock: cfg.clock,
        max_spp: cfg.max_spp,
        threads: if cfg.threads == 0 { rayon::current_num_threads() } else { cfg.threads },
        max_depth,
        reference: info,
        notes,
        command: cfg.command.clone(),
        commit: env!("PRISM_COMMIT").to_string(),
        build_target: crate::build_target(),
        prism_version: env!("CARGO_PKG_VERSION").to_string(),
        integrators: results,
    };
    write_outputs(cfg, &out, &reference, &finals)?;
    Ok(out)
}

/// Every file the run writes, by role, against its inputs (`check_outputs`),
/// and writable where its directory exists (`check_writable`):
/// a reference rendered to `DIR/<label>.exr` would be replaced by
/// `--save-exr`, and `--reference-out s.exr` would write its sidecar over a
/// scene `s.json`.
fn check_converge_outputs(cfg: &ConvergeConfig) -> Result<()> {
    let mut inputs = vec![("the scene", cfg.scene.clone())];
    let mut outputs: Vec<(&str, PathBuf)> = ["results.csv", "results.json", "report.md", "images.png", "errors.png"]
        .into_iter()
        .map(|n| ("an output", cfg.out.join(n)))
        .collect();
    for chart in ["error-vs-time", "error-vs-spp"] {
        for ext in ["svg", "png"] {
            outputs.push(("a chart", cfg.out.join(format!("{chart}.{ext}"))));
        }
    }
    if cfg.save_exr {
        outputs
            .extend(cfg.integrators.iter().map(|s| ("a final image", cfg.out.join(format!("{}.exr", s.file_stem())))));
    }
    match &cfg.reference {
        ReferenceSource::File(p) => {
            inputs.extend([("the reference", p.clone()), ("its sidecar", p.with_extension("json"))])
        }
        ReferenceSource::Render { out, .. } => {
            outputs.extend([("the reference", out.clone()), ("its sidecar", out.with_extension("json"))])
        }
    }
    // (Run again once `DIR` exists: a directory left where an output goes
    // must stop the run before it renders, not after.)
    for (_, path) in &outputs {
        if path.parent().is_none_or(|d| d.as_os_str().is_empty() || d.is_dir()) {
            check_writable(path)?;
        }
    }
    let inputs: Vec<(&str, &Path)> = inputs.iter().map(|(r, p)| (*r, p.as_path())).collect();
    let outputs: Vec<(&str, &Path)> = outputs.iter().map(|(r, p)| (*r, p.as_path())).collect();
    check_outputs(&inputs, &outputs)
}

fn obtain_reference(
    cfg: &ConvergeConfig,
    scene: &Scene,
    scene_name: &str,
    seed: u64,
    max_depth: u32,
    notes: &mut Vec<String>,
) -> Result<(Vec<[f32; 3]>, ReferenceInfo)> {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let (image, origin, path, here) = match &cfg.reference {
        ReferenceSource::File(path) => {
            if path.with_extension("json").exists() {
                let (image, origin) = read_any_reference(path)?;
                (image, Some(origin), path.clone(), false)
            } else {
                let (rw, rh, image) = read_exr(path)?;
                ensure!((rw, rh) == (w, h), "{} is {rw}x{rh} but the run renders {w}x{h}", path.display());
                (image, None, path.clone(), false)
            }
        }
        ReferenceSource::Render { integrator, spp, passes, out } => {
            if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
            }
            let estimator = integrators::create(integrator, &IntegratorOptions { max_depth, mis: MisHeuristic::Power })
                .map_err(anyhow::Error::msg)?;
            let per_pass = spp.div_ceil(*passes);
            // The largest block (for the sidecar's z-test statistics) that tiles the image.
            let block = [8, 4, 2, 1].into_iter().find(|b| w % b == 0 && h % b == 0).unwrap_or(1);
            let ref_seed = seed.wrapping_add(REFERENCE_SEED_OFFSET);
            let bar = spinner(cfg.progress, format!("reference: {integrator}, {passes} passes x {per_pass} spp"));
            let (image, meta) = make_reference(
                scene,
                scene_name,
                estimator.as_ref(),
                integrator,
                per_pass,
                *passes,
                ref_seed,
                block,
                cfg.threads,
                cfg.command.clone(),
            );
            bar.finish_and_clear();
            eprintln!(
                "reference: {integrator}, {passes} passes x {per_pass} spp in {:.1} s -> {}",
                meta.wall_seconds,
                out.display()
            );
            write_reference(out, &image, &meta)?;
            (image, Some(Origin::of_reference(&meta)), out.clone(), true)
        }
    };
    if let Some(m) = &origin {
        if Path::new(&m.scene).file_name() != cfg.scene.file_name() {
            notes.push(format!("the reference was rendered from {}, this run renders {scene_name}", m.scene));
        }
        // A reference from an estimator that cannot sample the whole scene
        // is biased, and so is every error measured against it.
        if let Ok(estimator) =
            integrators::create(&m.integrator, &IntegratorOptions { max_depth, ..Default::default() })
        {
            for w in estimator.unsamplable(scene) {
                notes.push(format!("the reference's integrator {} cannot sample this scene fully: {w}", m.integrator));
            }
        }
        ensure!(
            (m.width, m.height) == (w, h),
            "{} is {}x{} but the run renders {w}x{h}",
            path.display(),
            m.width,
            m.height
        );
        let seeds = m.seed..m.seed.saturating_add(m.passes.unwrap_or(1) as u64);
        if seeds.contains(&seed) {
            notes.push(format!(
                "the reference's passes used seeds {}..{} which include the run's seed {seed}: its samples are \
                 correlated with the run's, and the errors measured are too low",
                seeds.start, seeds.end
            ));
        }
    } else {
        notes.push("the reference has no sidecar: its integrator, spp and noise are unknown".to_string());
    }
    let noise_floor = origin.as_ref().and_then(|m| m.noise_floor);
    let info = ReferenceInfo {
        path: path.display().to_string(),
        rendered_here: here,
        integrator: origin.as_ref().map(|m| m.integrator.clone()),
        spp: origin.as_ref().map(|m| m.spp),
        passes: origin.as_ref().and_then(|m| m.passes),
        seed: origin.as_ref().map(|m| m.seed),
        wall_seconds: origin.as_ref().and_then(|m| m.wall_seconds),
        noise_floor,
        noise_floor_method: noise_floor.map(|_| "block errors".to_string()),
    };
    Ok((image, info))
}

/// Where a reference image came from, as its sidecar says: a `prism
/// reference` sidecar, or the sidecar of a `prism render` or `prism merge`
/// (docs/cluster.md makes long references that way), which has no block
/// errors and so no noise estimate.
struct Origin {
    scene: String,
    integrator: String,
    seed: u64,
    width: u32,
    height: u32,
    /// Total samples per pixel (over all passes).
    spp: u64,
    passes: Option<u32>,
    wall_seconds: Option<f64>,
    noise_floor: Option<f64>,
}

/// The fields of a render or merge sidecar that `Origin` needs (the rest
/// is ignored).
#[derive(Deserialize)]
struct RenderSidecar {
    scene: String,
    integrator: String,
    seed: u64,
    width: u32,
    height: u32,
    spp: u64,
    passes: Option<u32>,
    wall_seconds: Option<f64>,
}

impl Origin {
    fn of_reference(m: &ReferenceMeta) -> Self {
        Origin {
            scene: m.scene.clone(),
            integrator: m.integrator.clone(),
            seed: m.seed,
            width: m.width,
            height: m.height,
            spp: m.spp as u64 * m.passes as u64,
            passes: Some(m.passes),
            wall_seconds: Some(m.wall_seconds),
            noise_floor: Some(noise_floor(m)),
        }
    }

    fn of_render(r: RenderSidecar) -> Self {
        Origin {
            scene: r.scene,
            integrator: r.integrator,
            seed: r.seed,
            width: r.width,
            height: r.height,
            spp: r.spp * r.passes.unwrap_or(1) as u64,
            passes: r.passes,
            wall_seconds: r.wall_seconds,
            noise_floor: None,
        }
    }
}

/// A reference EXR and its sidecar, of either kind (`Origin`).
fn read_any_reference(exr: &Path) -> Result<(Vec<[f32; 3]>, Origin)> {
    let json = exr.with_extension("json");
    let text = std::fs::read_to_string(&json).with_context(|| format!("cannot read {}", json.display()))?;
    let origin = match serde_json::from_str::<ReferenceMeta>(&text) {
        Ok(m) => Origin::of_reference(&m),
        Err(_) => serde_json::from_str::<RenderSidecar>(&text).map(Origin::of_render).with_context(|| {
            format!("{}: neither a reference sidecar nor a render or merge sidecar", json.display())
        })?,
    };
    let (w, h, image) = read_exr(exr)?;
    ensure!((w, h) == (origin.width, origin.height), "{}: size {w}x{h} differs from its sidecar", exr.display());
    Ok((image, origin))
}

/// The relMSE the reference's own noise adds to every measurement: the
/// per-pixel variance of its mean is about block^2 x (block standard error)^2
/// when neighbouring pixels are independent, divided by ref^2 + 0.01 as relMSE is.
fn noise_floor(m: &ReferenceMeta) -> f64 {
    let b2 = (m.block * m.block) as f64;
    let terms = m
        .block_mean
        .iter()
        .zip(&m.block_stderr)
        .flat_map(|(mean, se)| (0..3).map(move |c| b2 * se[c] * se[c] / (mean[c] * mean[c] + 0.01)));
    let (sum, n) = terms.fold((0.0, 0usize), |(s, n), t| (s + t, n + 1));
    if n == 0 {
        0.0
    } else {
        sum / n as f64
    }
}

fn spinner(visible: bool, message: String) -> ProgressBar {
    if !visible {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new_spinner();
    bar.set_style(ProgressStyle::with_template("{spinner} [{elapsed_precise}] {msg}").expect("spinner template"));
    bar.set_message(message);
    bar.enable_steady_tick(Duration::from_millis(200));
    bar
}

fn progress_bar(visible: bool, label: &str, len: u64, unit: &str) -> ProgressBar {
    if !visible {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    let template = format!("{{prefix:>14}} [{{elapsed_precise}}] {{bar:30}} {{pos}}/{{len}} {unit}  {{msg}}");
    bar.set_style(ProgressStyle::with_template(&template).expect("progress template"));
    bar.set_prefix(label.to_string());
    bar
}

/// Renders one integrator progressively; returns its result and final image.
fn converge_one(
    cfg: &ConvergeConfig,
    scene: &Scene,
    spec: &IntegratorSpec,
    integrator: &dyn integrators::Integrator,
    seed: u64,
    reference: &[[f32; 3]],
    warnings: Vec<String>,
) -> Result<(IntegratorResult, Vec<[f32; 3]>)> {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let mut film = Film::new(w, h);
    let opts = RenderOptions { seed, threads: cfg.threads, progress: false };
    let bar = match cfg.time {
        Some(t) => progress_bar(cfg.progress, &spec.label, (t * 1000.0).ceil() as u64, "ms"),
        None => progress_bar(cfg.progress, &spec.label, cfg.max_spp.unwrap_or(1) as u64, "spp"),
    };
    let mut n = 0u32;
    let (mut wall, mut cpu) = (0.0f64, Some(0.0f64));
    let mut by_spp = true;
    let mut checkpoints: Vec<Checkpoint> = Vec::new();
    loop {
        let seconds = match cfg.clock {
            Clock::Wall => wall,
            Clock::Cpu => cpu.unwrap_or(wall),
        };
        if cfg.max_spp.is_some_and(|m| n >= m) || cfg.time.is_some_and(|t| seconds >= t) {
            break;
        }
        let mut target = next_grid_spp(n);
        if let Some(m) = cfg.max_spp {
            target = target.min(m);
        }
        if let (Some(t), true) = (cfg.time, n > 0) {
            // Throughput so far predicts how many more samples fit the budget.
            let fit = n as f64 + (n as f64 / seconds.max(1e-9) * (t - seconds)).floor();
            if fit < n as f64 + 1.0 {
                break;
            }
            if fit < target as f64 {
                target = fit as u32;
                by_spp = false;
            }
        }
        let cpu0 = process_cpu_seconds();
        let stats = render(scene, integrator, &opts, &mut film, n..target);
        cpu = match (cpu, cpu0, process_cpu_seconds()) {
            (Some(c), Some(a), Some(b)) => Some(c + (b - a)),
            _ => None,
        };
        n = target;
        wall += stats.wall.as_secs_f64();
        let image = film.image();
        let (rel, mse, mae) = errors(&image, reference);
        let c = Checkpoint { spp: n, seconds: wall, cpu_seconds: cpu, rel_mse: rel, mse, mae, by_spp };
        checkpoints.push(c);
        let seconds = c.time(cfg.clock);
        bar.set_position(match cfg.time {
            Some(_) => (seconds * 1000.0) as u64,
            None => n as u64,
        });
        bar.set_message(format!("{n} spp, {seconds:.2} {}, relMSE {rel:.3e}", cfg.clock.unit()));
    }
    let last = *checkpoints.last().context("no checkpoint rendered")?;
    bar.finish();
    let slope = fit_slope(checkpoints.iter().filter(|c| c.by_spp && c.spp >= 4).map(|c| (c.spp as f64, c.rel_mse)));
    let result = IntegratorResult {
        label: spec.label.clone(),
        integrator: spec.name.clone(),
        mis: heuristic_name(spec.mis).to_string(),
        warnings,
        spp: last.spp,
        seconds: last.time(cfg.clock),
        wall_seconds: last.seconds,
        rel_mse: last.rel_mse,
        mse: last.mse,
        mae: last.mae,
        efficiency: efficiency(last.rel_mse, last.time(cfg.clock), cfg.clock),
        samples_per_second: last.spp as f64 * (w * h) as f64 / last.seconds,
        slope,
        dropped: film.dropped,
        checkpoints,
    };
    Ok((result, film.image()))
}

fn null_as_nan<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// 1 / (relMSE x seconds), NaN (unranked) for a time the clock cannot
/// measure well (`Clock::min_seconds`).
fn efficiency(rel_mse: f64, seconds: f64, clock: Clock) -> f64 {
    if seconds >= clock.min_seconds() {
        1.0 / (rel_mse * seconds)
    } else {
        f64::NAN
    }
}

/// Least-squares slope of ln y against ln x (None with fewer than 3 points).
pub fn fit_slope(points: impl Iterator<Item = (f64, f64)>) -> Option<f64> {
    let pts: Vec<(f64, f64)> = points.filter(|&(x, y)| x > 0.0 && y > 0.0).map(|(x, y)| (x.ln(), y.ln())).collect();
    if pts.len() < 3 {
        return None;
    }
    let n = pts.len() as f64;
    let (mx, my) = (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

// ------------------------------------------------------------------ outputs

fn write_outputs(
    cfg: &ConvergeConfig,
    r: &ConvergeResults,
    reference: &[[f32; 3]],
    finals: &[Vec<[f32; 3]>],
) -> Result<()> {
    let dir = &cfg.out;
    write_text(&dir.join("results.csv"), &results_csv(r))?;
    write_json(&dir.join("results.json"), r)?;
    let time_svg = chart_svg(r, Axis::Seconds)?;
    let spp_svg = chart_svg(r, Axis::Spp)?;
    for (name, svg) in [("error-vs-time", &time_svg), ("error-vs-spp", &spp_svg)] {
        write_text(&dir.join(format!("{name}.svg")), svg)?;
        write_png(&dir.join(format!("{name}.png")), &svg_to_png(svg, 1.0)?)?;
    }
    let scale = match cfg.exposure {
        Some(e) => 2f32.powf(e),
        None => auto_exposure(reference),
    };
    let ref_caption = match (&r.reference.integrator, r.reference.spp) {
        (Some(i), Some(spp)) => format!("reference ({i}, {spp} spp)"),
        _ => "reference".to_string(),
    };
    let mut panels = vec![(ref_caption, tonemap(reference, r.width, r.height, scale))];
    for (res, img) in r.integrators.iter().zip(finals) {
        panels.push((format!("{} ({} spp)", res.label, res.spp), tonemap(img, r.width, r.height, scale)));
    }
    write_png(&dir.join("images.png"), &compose(&panels, None)?)?;
    let maps: Vec<Vec<f64>> = finals.iter().map(|img| pixel_errors(img, reference)).collect();
    let (lo, hi) = error_range(&maps);
    let panels: Vec<(String, RgbImage)> = r
        .integrators
        .iter()
        .zip(&maps)
        .map(|(res, m)| {
            (format!("{}: relMSE {:.2e}", res.label, res.rel_mse), false_colour(m, r.width, r.height, lo, hi))
        })
        .collect();
    write_png(&dir.join("errors.png"), &compose(&panels, Some((lo, hi)))?)?;
    write_text(&dir.join("report.md"), &report_md(r))
}

/// Each output appears whole or not at all (`write_atomically`).
fn write_text(path: &Path, text: &str) -> Result<()> {
    write_atomically(path, |tmp| std::fs::write(tmp, text).with_context(|| format!("cannot write {}", path.display())))
}

fn write_png(path: &Path, image: &RgbImage) -> Result<()> {
    write_atomically(path, |tmp| image.save(tmp).with_context(|| format!("cannot write {}", path.display())))
}

/// One row per checkpoint: `integrator,spp,seconds,cpu_seconds,rel_mse,mse,mae,by_spp`
/// (seconds: wall; cpu_seconds: empty where unavailable).
pub fn results_csv(r: &ConvergeResults) -> String {
    let mut s = String::from("integrator,spp,seconds,cpu_seconds,rel_mse,mse,mae,by_spp\n");
    for res in &r.integrators {
        for c in &res.checkpoints {
            let cpu = c.cpu_seconds.map_or(String::new(), |v| format!("{v:.2}"));
            let _ = writeln!(
                s,
                "{},{},{:.6},{cpu},{:.6e},{:.6e},{:.6e},{}",
                res.label, c.spp, c.seconds, c.rel_mse, c.mse, c.mae, c.by_spp
            );
        }
    }
    s
}

/// The efficiency table in Markdown, best first.
pub fn efficiency_table(r: &ConvergeResults) -> String {
    let unit = r.clock.unit();
    let mut s = format!(
        "| rank | integrator | spp | {unit} | Msamples/s (wall) | relMSE | MSE | MAE | efficiency 1/(relMSE x s) | vs best | slope (spp) |\n\
         |---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    let order = r.ranking();
    let best = order.first().map_or(1.0, |&i| r.integrators[i].efficiency);
    for (rank, &i) in order.iter().enumerate() {
        let x = &r.integrators[i];
        let flag = if x.warnings.is_empty() { "" } else { " (!)" };
        // An unmeasurably short run has no efficiency and no rank.
        let measured = !x.efficiency.is_nan();
        let or_dash = |v: String| if measured { v } else { "-".to_string() };
        let _ = writeln!(
            s,
            "| {} | {}{flag} | {} | {:.2} | {:.3} | {:.3e} | {:.3e} | {:.3e} | {} | {} | {} |",
            or_dash((rank + 1).to_string()),
            x.label,
            x.spp,
            x.seconds,
            x.samples_per_second / 1e6,
            x.rel_mse,
            x.mse,
            x.mae,
            or_dash(format!("{:.3e}", x.efficiency)),
            or_dash(format!("{:.3}", x.efficiency / best)),
            x.slope.map_or("-".to_string(), |v| format!("{v:.2}"))
        );
    }
    s
}

fn report_md(r: &ConvergeResults) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Convergence: {}\n", r.scene);
    if let Some(c) = &r.scene_comment {
        let _ = writeln!(s, "> {c}\n");
    }
    let unit = r.clock.unit();
    let budget = match (r.budget_seconds, r.max_spp) {
        (Some(t), Some(n)) => format!("{t} {unit} or {n} spp per integrator, whichever comes first"),
        (Some(t), None) => format!("{t} {unit} per integrator"),
        (None, Some(n)) => format!("{n} spp per integrator"),
        (None, None) => "-".to_string(),
    };
    let _ = writeln!(
        s,
        "- resolution {}x{}, seed {}, max depth {}, {} threads\n- budget: {budget}\n- prism {} (commit {}, built for {})",
        r.width, r.height, r.seed, r.max_depth, r.threads, r.prism_version, r.commit, r.build_target
    );
    let rf = &r.reference;
    let _ = write!(s, "- reference: `{}`", rf.path);
    match (&rf.integrator, rf.spp, rf.passes) {
        (Some(i), Some(spp), Some(p)) => {
            let _ = write!(s, ", {i}, {spp} spp in {p} passes (seeds from {})", rf.seed.unwrap_or(0));
        }
        (Some(i), Some(spp), None) => {
            let _ = write!(s, ", {i}, {spp} spp (seed {})", rf.seed.unwrap_or(0));
        }
        _ => {}
    }
    if let Some(t) = rf.wall_seconds {
        let _ = write!(s, ", {t:.1} s{}", if rf.rendered_here { ", rendered by this run" } else { "" });
    }
    if let Some(f) = rf.noise_floor {
        let how = rf.noise_floor_method.as_deref().unwrap_or("-");
        let _ =
            write!(s, "; its own noise adds about {f:.2e} to every relMSE (grey dashed line; estimated from: {how})");
    }
    let _ = writeln!(s, "\n- command: `{}`\n", r.command);
    let _ = writeln!(s, "## Efficiency (last checkpoint, best first)\n\n{}", efficiency_table(r));
    let _ = writeln!(
        s,
        "Efficiency = 1 / (relMSE x {unit} of rendering). Slope: least-squares slope of log relMSE against log spp \
         over the checkpoints from 4 spp (-1 for an unbiased estimator until the reference's own noise or a bias \
         flattens it).\n"
    );
    if r.integrators.iter().any(|x| !x.warnings.is_empty()) {
        let _ = writeln!(s, "(!) marks integrators that cannot sample some paths of this scene:\n");
    }
    for x in r.integrators.iter().filter(|x| !x.warnings.is_empty()) {
        for w in &x.warnings {
            let _ = writeln!(s, "- {}: {w}", x.label);
        }
    }
    if !r.notes.is_empty() {
        let _ = writeln!(s, "\nNotes:\n");
    }
    for n in &r.notes {
        let _ = writeln!(s, "- {n}");
    }
    let _ = writeln!(
        s,
        "\n## Error against time and spp\n\n![relMSE vs time](error-vs-time.svg)\n\n![relMSE vs spp](error-vs-spp.svg)\n\n\
         PNG versions: [error-vs-time.png](error-vs-time.png), [error-vs-spp.png](error-vs-spp.png). \
         Every checkpoint is in [results.csv](results.csv) and [results.json](results.json).\n\n\
         ## Final images\n\n![final images](images.png)\n\n\
         ## Per-pixel error\n\nmean over channels of (x - ref)^2 / (ref^2 + 0.01), log colour scale shared by all \
         panels (the mean of each map is the integrator's relMSE):\n\n![per-pixel error](errors.png)\n\n\
         ## Determinism\n\nThe image at a grid checkpoint (1, 2, 3, 4, 5, 6, 7, 8, 10, 11, 13, 16, ... spp; `by_spp = \
         true` in the CSV) depends only on the scene, the seed and spp, so its errors are reproduced bit for bit by \
         the same command. Seconds are wall-clock measurements and vary from run to run and machine to machine; \
         the last checkpoint of a time-limited run ends where the budget ran out (`by_spp = false`), so its spp, \
         and the efficiency computed from it, vary too."
    );
    s
}

// ------------------------------------------------------------------- charts

#[derive(Clone, Copy, PartialEq, Eq)]
enum Axis {
    Seconds,
    Spp,
}

/// Tick labels: plain numbers in a readable range, else scientific.
fn tick(v: f64) -> String {
    if v == 0.0 {
        return "0".to_string();
    }
    if (1e-3..1e5).contains(&v.abs()) {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.0e}")
    }
}

fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if !lo.is_finite() {
        return (1e-3, 1.0);
    }
    let (lo, hi) = if hi / lo < 10.0 { ((lo * hi).sqrt() / 3.2, (lo * hi).sqrt() * 3.2) } else { (lo, hi) };
    (lo / 1.3, hi * 1.3)
}

fn chart_svg(r: &ConvergeResults, axis: Axis) -> Result<String> {
    let x_of = |c: &Checkpoint| match axis {
        Axis::Seconds => c.time(r.clock),
        Axis::Spp => c.spp as f64,
    };
    let all = || r.integrators.iter().flat_map(|x| x.checkpoints.iter());
    let (x0, x1) = log_range(all().map(x_of));
    let floor = r.reference.noise_floor.filter(|f| *f > 0.0);
    let (y0, y1) = log_range(all().map(|c| c.rel_mse).chain(floor));
    let title = match axis {
        Axis::Seconds => format!("{}: relMSE vs time ({}x{})", scene_stem(&r.scene), r.width, r.height),
        Axis::Spp => format!("{}: relMSE vs samples per pixel ({}x{})", scene_stem(&r.scene), r.width, r.height),
    };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 560)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(14)
            .x_label_area_size(48)
            .y_label_area_size(72)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc(match axis {
                Axis::Seconds => match r.clock {
                    Clock::Wall => "seconds of rendering (log)",
                    Clock::Cpu => "CPU seconds of rendering, all threads (log)",
                },
                Axis::Spp => "samples per pixel (log)",
            })
            .y_desc("relMSE (log)")
            .x_label_formatter(&|v| tick(*v))
            .y_label_formatter(&|v| tick(*v))
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(200, 200, 200))
            .draw()
            .map_err(plot_err)?;
        for (i, x) in r.integrators.iter().enumerate() {
            let (cr, cg, cb) = PALETTE[i % PALETTE.len()];
            let colour = RGBColor(cr, cg, cb);
            let pts: Vec<(f64, f64)> = x
                .checkpoints
                .iter()
                .filter(|c| c.rel_mse > 0.0 && x_of(c) > 0.0)
                .map(|c| (x_of(c), c.rel_mse))
                .collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                .map_err(plot_err)?
                .label(x.label.clone())
                .legend(move |(lx, ly)| PathElement::new(vec![(lx, ly), (lx + 24, ly)], colour.stroke_width(3)));
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, colour.filled()))).map_err(plot_err)?;
        }
        if axis == Axis::Spp {
            // Slope -1 through the geometric mean of the first checkpoints.
            let firsts: Vec<f64> = r
                .integrators
                .iter()
                .filter_map(|x| x.checkpoints.first())
                .map(|c| (c.rel_mse * c.spp as f64).ln())
                .collect();
            if !firsts.is_empty() {
                let k = (firsts.iter().sum::<f64>() / firsts.len() as f64).exp();
                let line: Vec<(f64, f64)> = [x0, x1].into_iter().map(|x| (x, k / x)).collect();
                chart
                    .draw_series(DashedLineSeries::new(line, 8, 6, BLACK.stroke_width(1)))
                    .map_err(plot_err)?
                    .label("slope -1")
                    .legend(|(lx, ly)| PathElement::new(vec![(lx, ly), (lx + 24, ly)], BLACK.stroke_width(1)));
            }
        }
        if let Some(f) = floor {
            let grey = RGBColor(120, 120, 120);
            chart
                .draw_series(DashedLineSeries::new(vec![(x0, f), (x1, f)], 4, 4, grey.stroke_width(1)))
                .map_err(plot_err)?
                .label("reference noise (est.)")
                .legend(move |(lx, ly)| PathElement::new(vec![(lx, ly), (lx + 24, ly)], grey.stroke_width(1)));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font(("sans-serif", 15))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(160, 160, 160))
            .draw()
            .map_err(plot_err)?;
        root.present().map_err(plot_err)?;
    }
    Ok(svg)
}

fn plot_err<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow::anyhow!("chart: {e:?}")
}

fn scene_stem(scene: &str) -> String {
    Path::new(scene).file_stem().map_or(scene.to_string(), |s| s.to_string_lossy().to_string())
}

// --------------------------------------------------------- rasterising SVG

fn usvg_options() -> &'static resvg::usvg::Options<'static> {
    static OPTIONS: OnceLock<resvg::usvg::Options<'static>> = OnceLock::new();
    OPTIONS.get_or_init(|| {
        let mut db = resvg::usvg::fontdb::Database::new();
        db.load_font_data(FONT.to_vec());
        db.set_sans_serif_family(FONT_FAMILY);
        resvg::usvg::Options { font_family: FONT_FAMILY.to_string(), fontdb: Arc::new(db), ..Default::default() }
    })
}

/// Rasterises an SVG (on white) with the embedded font.
pub fn svg_to_png(svg: &str, scale: f32) -> Result<RgbImage> {
    let tree = resvg::usvg::Tree::from_str(svg, usvg_options()).context("cannot parse the chart SVG")?;
    let size = tree.size();
    let (w, h) = ((size.width() * scale).ceil() as u32, (size.height() * scale).ceil() as u32);
    let mut pixmap = resvg::tiny_skia::Pixmap::new(w, h).context("empty SVG")?;
    pixmap.fill(resvg::tiny_skia::Color::WHITE);
    resvg::render(&tree, resvg::tiny_skia::Transform::from_scale(scale, scale), &mut pixmap.as_mut());
    // Opaque background: premultiplied RGBA equals straight RGBA.
    let rgb: Vec<u8> = pixmap.data().chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
    RgbImage::from_raw(w, h, rgb).context("pixmap size")
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

// ------------------------------------------------------------------- images

/// Scale that maps the reference's log-average luminance to 0.18 (Reinhard's key).
fn auto_exposure(reference: &[[f32; 3]]) -> f32 {
    let lum = |p: &[f32; 3]| (0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]).max(0.0) as f64;
    let n = reference.len().max(1) as f64;
    let log_avg = (reference.iter().map(|p| (lum(p) + 1e-4).ln()).sum::<f64>() / n).exp();
    if log_avg > 1e-6 {
        (0.18 / log_avg) as f32
    } else {
        1.0
    }
}

fn srgb8(c: f32) -> u8 {
    let c = if c.is_finite() { c.clamp(0.0, 1.0) } else { 0.0 };
    let v = if c <= 0.003_130_8 { 12.92 * c } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
    (v * 255.0 + 0.5) as u8
}

fn tonemap(image: &[[f32; 3]], w: u32, h: u32, scale: f32) -> RgbImage {
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
fn error_range(maps: &[Vec<f64>]) -> (f64, f64) {
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

fn false_colour(errors: &[f64], w: u32, h: u32, lo: f64, hi: f64) -> RgbImage {
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
fn compose(panels: &[(String, RgbImage)], colour_bar: Option<(f64, f64)>) -> Result<RgbImage> {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spp_grid_is_quarter_octaves() {
        let mut n = 0;
        let mut grid = Vec::new();
        while n < 64 {
            n = next_grid_spp(n);
            grid.push(n);
        }
        assert_eq!(grid, [1, 2, 3, 4, 5, 6, 7, 8, 10, 11, 13, 16, 19, 23, 27, 32, 38, 45, 54, 64]);
    }

    #[test]
    fn specs_parse_and_expand() {
        let p = |s: &str, m: &[MisHeuristic]| {
            IntegratorSpec::parse_list(s, m).map(|v| v.into_iter().map(|s| s.label).collect::<Vec<_>>())
        };
        assert_eq!(p("path, light,bdpt", &[]).unwrap(), ["path", "light", "bdpt"]);
        assert_eq!(p("bdpt,bdpt:uniform", &[]).unwrap(), ["bdpt", "bdpt:uniform"]);
        let both = [MisHeuristic::Power, MisHeuristic::Uniform];
        assert_eq!(p("path,bdpt", &both).unwrap(), ["path", "bdpt:power", "bdpt:uniform"]);
        let uniform = IntegratorSpec::parse_list("path,bdpt", &[MisHeuristic::Uniform]).unwrap();
        let mis: Vec<_> = uniform.iter().map(|s| (s.label.as_str(), s.mis)).collect();
        assert_eq!(mis, [("path", MisHeuristic::Power), ("bdpt:uniform", MisHeuristic::Uniform)], "--mis reached path");
        assert!(p("path:uniform", &[]).is_err());
        assert!(p("bdpt:magic", &[]).is_err());
        assert!(p("nosuch", &[]).is_err());
        assert!(p("path,path", &[]).is_err());
    }

    #[test]
    fn slope_of_a_power_law() {
        let s = fit_slope((1..20).map(|n| (n as f64, 3.0 / n as f64))).unwrap();
        assert!((s + 1.0).abs() < 1e-9);
    }

    #[test]
    fn svg_text_is_rasterised_with_the_embedded_font() {
        let blank = r#"<svg xmlns="http://www.w3.org/2000/svg" width="60" height="30"><rect width="60" height="30" fill="white"/></svg>"#;
        let text =
            blank.replace("</svg>", r#"<text x="5" y="20" font-family="sans-serif" font-size="16">Ag</text></svg>"#);
        let dark = |img: &RgbImage| img.pixels().filter(|p| p.0[0] < 128).count();
        assert_eq!(dark(&svg_to_png(blank, 1.0).unwrap()), 0);
        assert!(dark(&svg_to_png(&text, 1.0).unwrap()) > 20, "no glyphs drawn");
    }
}
