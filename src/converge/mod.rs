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
//! 1, 2, 3, 4, 5, 6, 7, 8, 16, 24, 32, 40, 48, 56, 64, 80, 88, 104, 128, ...
//! (round(2^(k/4)), and past 8 the multiple of 8 nearest it, so that
//! `path`'s packets of 8 camera rays are whole: `next_grid_spp`), so the image at a
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
//! no efficiency and no rank, and a note says so; so does a run whose
//! relMSE is 0 (its image equals the reference: the efficiency is unbounded).
//!
//! Notes (in report.md and results.json, and printed) also flag a reference
//! whose own noise is over 10 % of an integrator's measured relMSE (the
//! ratios are then pulled towards 1), a reference rendered from another
//! scene file, and one whose integrator cannot sample the whole scene (it is
//! biased, and every error measured against it). No output may replace the
//! scene, the reference or another output (`output::check_outputs`).
//!
//! Integrator specs: `name` or `name:heuristic` (`bdpt:uniform`), so one run
//! can compare MIS heuristics of the same estimator as separate lines;
//! `--mis a,b` expands a bare `bdpt` into `bdpt:a`, `bdpt:b`.
//!
//! The reference is either an EXR (with the sidecar of `prism reference`,
//! or of the `prism render` or `prism merge` that made it, if present) or
//! rendered here (`--reference-spp`) with seeds disjoint from the
//! run's (`REFERENCE_SEED_OFFSET`): a reference sharing sample streams with
//! the image it judges would correlate with it and flatter it, so a stored
//! one whose sidecar shows such seeds is refused.
//!
//! Files: this one runs the measurement; `reference` obtains the reference,
//! `report` writes the outputs, `chart` draws the charts and `images` the
//! image panels.
//!
//! | option                   | default        | meaning                                             |
//! |--------------------------|----------------|-----------------------------------------------------|
//! | --integrators            | path,light,bdpt | comma-separated specs (`name[:heuristic]`)         |
//! | --mis                    | power          | heuristics for bare MIS-aware specs (bdpt)          |
//! | --reference              | -              | reference EXR (+ optional sidecar)                  |
//! | --reference-spp          | -              | render the reference here: total spp                |
//! | --reference-integrator   | bdpt           | its integrator (power heuristic)                    |
//! | --reference-passes       | 8              | independent passes (block errors, noise floor)      |
//! | --reference-out          | DIR/reference.exr | where the rendered reference and sidecar go      |
//! | --time                   | -              | time budget per integrator, seconds (of `--clock`)  |
//! | --clock                  | wall           | `wall` or `cpu` (CPU seconds of all render threads) |
//! | --spp                    | -              | spp cap per integrator (deterministic runs)         |
//! | --width, --height        | the scene's    | resolution                                          |
//! | --seed                   | scene's, else 0 | base seed of the run                               |
//! | --exposure               | automatic      | PNG exposure in stops (default: log-average key 0.18) |
//! | --save-exr               | off            | also write each final image as `DIR/<label>.exr`    |

use crate::accel::LANES;
use crate::camera::Camera;
use crate::film::{DroppedSamples, Film};
use crate::integrators::{self, IntegratorOptions, INTEGRATORS};
use crate::output::{check_no_stale_state, check_outputs, check_writable, ensure_exr};
use crate::render::{render, RenderOptions};
use crate::render_state::SceneFingerprint;
use crate::sampling::MisHeuristic;
use crate::scene::{load_scene, Scene};
use crate::stats::rel_mse;
use anyhow::{bail, ensure, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Duration;

mod chart;
mod images;
mod reference;
mod report;

pub use chart::svg_to_png;
pub use images::pixel_errors;
use reference::obtain_reference;
use report::write_outputs;
pub use report::{efficiency_table, results_csv};

/// Added to the run's seed for a reference rendered by `converge` itself, so
/// its passes (seeds offset .. offset + passes) never share sample streams
/// with the run.
pub const REFERENCE_SEED_OFFSET: u64 = 1 << 32;

// ------------------------------------------------------------------ the CLI

/// `prism converge`: error against a reference vs time and spp, per integrator.
#[derive(clap::Args, Debug)]
pub struct ConvergeArgs {
    /// Scene file (JSON, or glTF: .gltf / .glb).
    pub scene: PathBuf,
    /// Comma-separated integrator specs, `name` or `name:heuristic` (e.g.
    /// `path,light,bdpt,bdpt:uniform`).
    #[arg(long, default_value = "path,light,bdpt")]
    pub integrators: String,
    /// MIS heuristics for bare `bdpt` specs: several expand it into one line each.
    #[arg(long, value_delimiter = ',', default_value = "power")]
    pub mis: Vec<MisHeuristic>,
    /// Reference EXR (its sidecar, from `prism reference`, `render` or
    /// `merge`, is used if present). The options of a reference rendered
    /// here are refused with it (they would be ignored).
    #[arg(long, conflicts_with_all = ["reference_spp", "reference_integrator", "reference_passes", "reference_out"])]
    pub reference: Option<PathBuf>,
    /// Render the reference here with this many samples per pixel in total.
    #[arg(long)]
    pub reference_spp: Option<u32>,
    /// Integrator of a reference rendered here.
    #[arg(long, default_value = "bdpt")]
    pub reference_integrator: String,
    /// Independent passes of a reference rendered here (its sidecar keeps
    /// per-block standard errors, and its noise floor from each pixel's
    /// variance).
    #[arg(long, default_value_t = 8)]
    pub reference_passes: u32,
    /// Where a reference rendered here is written (default DIR/reference.exr).
    #[arg(long)]
    pub reference_out: Option<PathBuf>,
    /// Time budget per integrator, in seconds of `--clock`. A run needs a
    /// budget: --time, --spp, or both.
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
    /// Image width in pixels, with --height; default: the scene's camera.
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels, with --width.
    #[arg(long)]
    pub height: Option<u32>,
    /// Seed of the renders; default: the scene's, else 0.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Maximum scattering events; default: the scene's, else 1024.
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// PNG exposure in stops (default: automatic, from the reference).
    #[arg(long, allow_negative_numbers = true)]
    pub exposure: Option<f32>,
    /// Also write each final image as DIR/<label>.exr (a label's characters
    /// other than letters, digits, '_' and '-' written as '-':
    /// bdpt-uniform.exr).
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
        let mut bare_aware = false;
        for item in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (name, heuristic) = match item.split_once(':') {
                Some((n, h)) => (n, Some(h.parse::<MisHeuristic>().map_err(anyhow::Error::msg)?)),
                None => (item, None),
            };
            integrators::create(name, &IntegratorOptions::default()).map_err(anyhow::Error::msg)?;
            // A heuristic suffix on an integrator that ignores it would
            // label a line with a setting it does not use.
            let aware = integrators::reads_mis(name);
            bare_aware |= aware && heuristic.is_none();
            match heuristic {
                Some(_) if !aware => {
                    let names: Vec<&str> = INTEGRATORS.iter().filter(|i| i.reads_mis).map(|i| i.name).collect();
                    bail!("\"{item}\": only {} take a MIS heuristic", names.join(", "))
                }
                Some(h) => specs.push(IntegratorSpec { label: item.to_string(), name: name.to_string(), mis: h }),
                None if aware && (mis.len() > 1 || mis[0] != MisHeuristic::Power) => {
                    for &h in mis {
                        let label = format!("{name}:{}", h.name());
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
        // As a heuristic suffix on an integrator that ignores it: a --mis
        // that no line takes would be ignored (a review, session 54).
        ensure!(
            bare_aware || mis == [MisHeuristic::Power],
            "--mis applies to a bare MIS-aware integrator (bdpt) in --integrators, and none is given"
        );
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
    /// clock; NaN (null in the JSON) for a run too short to measure or an
    /// exact one (relMSE 0).
    #[serde(deserialize_with = "null_as_nan")]
    pub efficiency: f64,
    /// `efficiency` with the reference's own noise
    /// (`ReferenceInfo::noise_floor`) taken out of relMSE: 1 / ((relMSE -
    /// floor) x seconds), as benches/peers/compare.py counts it. Noise in
    /// the reference adds the same to every integrator's relMSE and pulls
    /// the ratios of `efficiency` towards 1 (over 40 % of an integrator's
    /// relMSE in docs/results.md's runs). NaN (null) where the floor is not
    /// known, relMSE is not above it, or `efficiency` is NaN; absent before
    /// session 50.
    #[serde(default = "nan", deserialize_with = "null_as_nan")]
    pub efficiency_net: f64,
    /// Samples per wall second.
    pub samples_per_second: f64,
    /// Least-squares slope of ln relMSE against ln spp over the grid
    /// checkpoints with spp >= 4 and, where the reference's own noise is
    /// known, a relMSE of at least ten times it (`spp_slope`): -1 for an
    /// unbiased estimator, flatter where a bias dominates.
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
    /// Its integrator's MIS heuristic (absent in results written before it
    /// was recorded).
    #[serde(default)]
    pub mis: Option<String>,
    /// Its max depth, where known (a reference without a sidecar has none).
    #[serde(default)]
    pub max_depth: Option<u32>,
    pub wall_seconds: Option<f64>,
    /// Expected relMSE of the reference itself: the floor under every
    /// measured curve (see `noise_floor_method`).
    pub noise_floor: Option<f64>,
    /// How `noise_floor` was estimated: `same estimator` (the reference's
    /// integrator is one of the run's lines: measured relMSE at n spp is
    /// V/n + V/N, solved for V/N), else `pixel variances` (recorded by
    /// `prism reference` from its passes, or from the variance image of a
    /// `prism render --passes` reference; `stats::reference_noise`), else
    /// `block errors` (an older sidecar's per-block standard errors: rough,
    /// as they weigh a block's pixels by its mean).
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

/// The spp grid, the smallest point above `n`: round(2^(k/4)), k = 0, 1,
/// ..., up to `LANES` (8) spp, and past it the multiple of `LANES` nearest
/// 2^(k/4). The slices between checkpoints are then whole packets of
/// `LANES` samples, as a render traces `path`'s camera rays: a slice of 2
/// to 7 samples goes in a partial packet, and of one alone, at more time a
/// sample (the quarter-octave grid past 8 charged `path`, and only it, up
/// to ~20 % more time at 16 spp and ~4 % at 256; from an audit, session 50).
pub fn next_grid_spp(n: u32) -> u32 {
    let lanes = LANES as f64;
    (0..)
        .map(|k| 2f64.powf(k as f64 / 4.0))
        .map(|g| if g < lanes { g.round() } else { (g / lanes).round() * lanes } as u64)
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
    check_config(cfg)?;
    check_converge_outputs(cfg, &[])?;
    let mut builder = load_scene(&cfg.scene)?;
    // The files the scene reads beside itself, known once it is loaded.
    let files = std::mem::take(&mut builder.inputs);
    check_converge_outputs(cfg, &files)?;
    if let Some((w, h)) = cfg.resolution {
        builder.set_resolution(w, h).map_err(|e| anyhow::anyhow!("--width, --height: {e}"))?;
    }
    let defaults = builder.defaults.clone();
    let scene_comment = builder.comment.take();
    let seed = cfg.seed.or(defaults.seed).unwrap_or(0);
    let max_depth = cfg.max_depth.or(defaults.max_depth).unwrap_or(IntegratorOptions::default().max_depth);
    let scene = builder.build();
    let (w, h) = (scene.camera.width, scene.camera.height);
    let estimators = cfg
        .integrators
        .iter()
        .map(|s| integrators::create(&s.name, &IntegratorOptions { max_depth, mis: s.mis }).map_err(anyhow::Error::msg))
        .collect::<Result<Vec<_>>>()?;
    let scene_file = SceneFingerprint::read(&cfg.scene, &files)?;
    // What no estimator can get right: a note on every chart of the run.
    let mut notes: Vec<String> = scene.geometry_warnings();
    for n in &notes {
        eprintln!("warning: {n}");
    }

    let (reference, info) = obtain_reference(cfg, &scene, &scene_file, seed, max_depth, &mut notes)?;
    ensure!(
        reference.len() == (w * h) as usize,
        "the reference has {} pixels but the run renders {w}x{h}: give --width/--height to match",
        reference.len()
    );
    std::fs::create_dir_all(&cfg.out).with_context(|| format!("cannot create {}", cfg.out.display()))?;
    check_converge_outputs(cfg, &files)?;

    let mut results = Vec::new();
    let mut finals = Vec::new();
    for (spec, integrator) in cfg.integrators.iter().zip(&estimators) {
        let warnings = integrator.unsamplable(&scene);
        for warn in &warnings {
            eprintln!("warning: {}: {warn}", spec.label);
        }
        let (result, image) = converge_one(cfg, &scene, spec, integrator.as_ref(), seed, &reference, warnings)?;
        notes.extend(dropped_note(&result));
        results.push(result);
        finals.push(image);
    }

    let info = with_noise_floor(info, &results, max_depth);
    for x in &mut results {
        x.slope = spp_slope(&x.checkpoints, info.noise_floor);
        x.efficiency_net = efficiency_net(x.efficiency, x.rel_mse, info.noise_floor);
    }
    notes.extend(results.iter().flat_map(|x| result_notes(cfg, x, &info)));
    let out = ConvergeResults {
        scene: scene_file.name,
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

/// The command line's own checks, before the scene is loaded.
fn check_config(cfg: &ConvergeConfig) -> Result<()> {
    ensure!(cfg.time.is_some() || cfg.max_spp.is_some(), "give a budget: --time SECONDS and/or --spp N");
    if let Some(t) = cfg.time {
        ensure!(t.is_finite() && t > 0.0, "--time must be a positive number of seconds");
    }
    ensure!(cfg.max_spp != Some(0), "--spp must be at least 1");
    // Budgets, charts and efficiencies in CPU seconds need them read (they
    // fell back to wall seconds without a word; a review, session 54).
    ensure!(
        cfg.clock == Clock::Wall || process_cpu_seconds().is_some(),
        "--clock cpu: this system gives no CPU time of the process (/proc/self/stat); use --clock wall"
    );
    // 2^exposure must be a normal f32: 0 or infinity would make black panels.
    ensure!(
        cfg.exposure.is_none_or(|e| 2f32.powf(e).is_normal()),
        "--exposure must be a number of stops in [-126, 128)"
    );
    if let ReferenceSource::Render { integrator, spp, passes, out } = &cfg.reference {
        ensure_exr("--reference-out", out)?;
        check_no_stale_state(out, "")?;
        ensure!(*passes >= 2, "--reference-passes must be at least 2");
        ensure!(*spp >= 1, "--reference-spp must be at least 1");
        integrators::create(integrator, &IntegratorOptions::default()).map_err(anyhow::Error::msg)?;
    }
    Ok(())
}

/// `info` with the reference's own noise estimated from the run of the same
/// estimator (integrator, MIS heuristic and depth), if any: that measures
/// it at the reference's own noise, where the first-order estimate from
/// its pixel variances reads low once a pixel's relative error nears 1
/// (relMSE divides by the noisy reference's square; a white room of 2
/// passes of 1 spp: 0.14 against 0.54).
fn with_noise_floor(mut info: ReferenceInfo, results: &[IntegratorResult], max_depth: u32) -> ReferenceInfo {
    let same = results.iter().find(|x| {
        Some(&x.integrator) == info.integrator.as_ref()
            && Some(&x.mis) == info.mis.as_ref()
            && info.max_depth == Some(max_depth)
    });
    if let (Some(x), Some(n_ref)) = (same, info.spp) {
        // m = V/n + V/N at the last checkpoint (independent seeds), so V/N = m / (N/n + 1).
        info.noise_floor = Some(x.rel_mse / (n_ref as f64 / x.spp as f64 + 1.0));
        info.noise_floor_method = Some(format!("same estimator ({})", x.label));
    }
    info
}

/// A note of the samples an integrator's film kept out, if any.
fn dropped_note(x: &IntegratorResult) -> Option<String> {
    let d = &x.dropped;
    (d.total() > 0).then(|| format!("{}: dropped {d}", x.label))
}

/// Notes on how far a result can be trusted: an exact run or one too short
/// to time, a reference whose own noise is a large part of the measured
/// error (not said of an exact run, where it would read as infinite).
fn result_notes(cfg: &ConvergeConfig, x: &IntegratorResult, info: &ReferenceInfo) -> Vec<String> {
    let mut notes = Vec::new();
    if x.rel_mse == 0.0 {
        notes.push(format!(
            "{}: relMSE is 0, the image equals the reference: its efficiency 1/(relMSE x s) is \
             unbounded: not ranked",
            x.label
        ));
    } else if x.efficiency.is_nan() {
        notes.push(format!(
            "{}: {:.3} {} is below {} s, too short to measure (the CPU clock ticks every 10 ms): not \
             ranked; give a larger --time or --spp",
            x.label,
            x.seconds,
            cfg.clock.unit(),
            cfg.clock.min_seconds()
        ));
    }
    if let Some(floor) = info.noise_floor.filter(|&f| f > 0.1 * x.rel_mse && x.rel_mse > 0.0) {
        notes.push(format!(
            "{}: the reference's own noise (relMSE ~{floor:.2e}) is {:.0} % of the measured {:.2e}: its \
             efficiency ratios are pulled towards 1; render a reference with more samples",
            x.label,
            100.0 * floor / x.rel_mse,
            x.rel_mse
        ));
    }
    notes
}

/// Every file the run writes, by role, against its inputs (`check_outputs`),
/// and writable where its directory exists (`check_writable`):
/// a reference rendered to `DIR/<label>.exr` would be replaced by
/// `--save-exr`, and `--reference-out s.exr` would write its sidecar over a
/// scene `s.json`; nor may any replace a file the scene reads (`files`:
/// `SceneBuilder::inputs`, such as a glTF file's texture, `images.png`).
fn check_converge_outputs(cfg: &ConvergeConfig, files: &[PathBuf]) -> Result<()> {
    let mut inputs = vec![("the scene", cfg.scene.clone())];
    inputs.extend(files.iter().map(|f| ("a file the scene reads", f.clone())));
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
    check_outputs(&inputs, &outputs)?;
    if let ReferenceSource::Render { out, .. } = &cfg.reference {
        crate::output::check_sidecar_target(&out.with_extension("json"))?;
    }
    Ok(())
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

/// The sample count to render to next, from `n` samples in `seconds`, and
/// whether it is on the spp grid (`next_grid_spp`, capped at `max_spp`) or
/// cut short by the time budget `time`; None when the run is done: at
/// `max_spp`, past the budget, or with no whole sample left in it. A slice
/// cut short ends on whole packets of `LANES` samples where one fits
/// (`next_grid_spp` says why).
fn next_target(max_spp: Option<u32>, time: Option<f64>, n: u32, seconds: f64) -> Option<(u32, bool)> {
    if max_spp.is_some_and(|m| n >= m) || time.is_some_and(|t| seconds >= t) {
        return None;
    }
    let target = max_spp.map_or(next_grid_spp(n), |m| next_grid_spp(n).min(m));
    if let (Some(t), true) = (time, n > 0) {
        // Throughput so far predicts how many more samples fit the budget.
        let fit = n as f64 + (n as f64 / seconds.max(1e-9) * (t - seconds)).floor();
        if fit < n as f64 + 1.0 {
            return None;
        }
        if fit < target as f64 {
            let fit = fit as u32;
            let packed = n + (fit - n) / LANES as u32 * LANES as u32;
            return Some((if packed > n { packed } else { fit }, false));
        }
    }
    Some((target, true))
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
        let Some((target, on_grid)) = next_target(cfg.max_spp, cfg.time, n, seconds) else {
            break;
        };
        // Once off the grid, every later checkpoint is too.
        by_spp &= on_grid;
        let cpu0 = process_cpu_seconds();
        let stats = render(scene, integrator, &opts, &mut film, n..target);
        cpu = match (cpu, cpu0, process_cpu_seconds()) {
            (Some(c), Some(a), Some(b)) => Some(c + (b - a)),
            // A curve half in CPU and half in wall seconds would be wrong.
            _ if cfg.clock == Clock::Cpu => {
                bail!("--clock cpu: the process's CPU time could not be read at {target} spp")
            }
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
    let result = IntegratorResult {
        label: spec.label.clone(),
        integrator: spec.name.clone(),
        mis: spec.mis.name().to_string(),
        warnings,
        spp: last.spp,
        seconds: last.time(cfg.clock),
        wall_seconds: last.seconds,
        rel_mse: last.rel_mse,
        mse: last.mse,
        mae: last.mae,
        efficiency: efficiency(last.rel_mse, last.time(cfg.clock), cfg.clock),
        // Set by `run` once the reference's noise floor is known.
        efficiency_net: f64::NAN,
        samples_per_second: last.spp as f64 * (w * h) as f64 / last.seconds,
        // Set by `run` once the reference's noise floor is known.
        slope: None,
        dropped: film.dropped,
        checkpoints,
    };
    Ok((result, film.image()))
}

fn null_as_nan<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// 1 / (relMSE x seconds), NaN (unranked) for a time the clock cannot
/// measure well (`Clock::min_seconds`) and for relMSE 0 (an exact image:
/// infinite efficiency, which no ratio or ranking can use).
fn efficiency(rel_mse: f64, seconds: f64, clock: Clock) -> f64 {
    if seconds >= clock.min_seconds() && rel_mse > 0.0 {
        1.0 / (rel_mse * seconds)
    } else {
        f64::NAN
    }
}

/// `efficiency` (1 / (relMSE x s)) with the reference's noise `floor`
/// taken out of relMSE; NaN where it cannot be.
fn efficiency_net(efficiency: f64, rel_mse: f64, floor: Option<f64>) -> f64 {
    match floor {
        Some(f) if rel_mse > f && efficiency.is_finite() => efficiency * rel_mse / (rel_mse - f),
        _ => f64::NAN,
    }
}

fn nan() -> f64 {
    f64::NAN
}

/// The slope of ln relMSE against ln spp over the grid checkpoints from 4
/// spp whose relMSE is at least ten times `floor`, the reference's own
/// noise, where that is known: measured against a noisy reference relMSE
/// is V/n + floor, which flattens towards slope 0 near the floor whatever
/// the estimator (at ten times the floor its local slope is -0.9).
fn spp_slope(checkpoints: &[Checkpoint], floor: Option<f64>) -> Option<f64> {
    let clear = |c: &Checkpoint| floor.is_none_or(|f| c.rel_mse >= 10.0 * f);
    fit_slope(checkpoints.iter().filter(|c| c.by_spp && c.spp >= 4 && clear(c)).map(|c| (c.spp as f64, c.rel_mse)))
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
        assert_eq!(grid, [1, 2, 3, 4, 5, 6, 7, 8, 16, 24, 32, 40, 48, 56, 64]);
        // Past 8, whole packets, each within half a packet of a quarter
        // octave, and every octave reached.
        let mut n = 64;
        while n < 100_000 {
            n = next_grid_spp(n);
            let k = (4.0 * (n as f64).log2()).round();
            assert!(n % 8 == 0 && (n as f64 - 2f64.powf(k / 4.0)).abs() <= 4.0, "{n}");
        }
        assert!([128, 1024, 65536].iter().all(|&p| next_grid_spp(p - 1) == p));
    }

    /// A time budget stops the run once spent, and predicts from the
    /// throughput so far how many samples fit: a grid point if it fits,
    /// else a slice cut short (`false`) of whole packets where one fits.
    #[test]
    fn a_time_budget_cuts_slices_to_what_fits() {
        let budget = |n, seconds| next_target(None, Some(1.0), n, seconds);
        assert_eq!(budget(0, 0.0), Some((1, true)));
        assert_eq!(budget(16, 0.25), Some((24, true)), "64 fit");
        assert_eq!(budget(16, 0.5), Some((24, true)), "32 fit");
        assert_eq!(budget(24, 0.875), Some((27, false)), "27 fit: no whole packet more");
        assert_eq!(budget(64, 0.875), Some((72, false)), "73 fit, short of the grid's 80");
        assert_eq!(budget(64, 0.75), Some((80, true)));
        assert_eq!(budget(65, 0.875), Some((73, false)), "74 fit: one whole packet from 65");
        assert_eq!(budget(64, 0.99), None, "no whole sample fits");
        assert_eq!(budget(64, 1.0), None, "spent");
        assert_eq!(next_target(Some(20), Some(1.0), 16, 0.1), Some((20, true)), "the cap");
        assert_eq!(next_target(Some(20), None, 20, 0.1), None);
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
        // A --mis that no line takes; power, the default, goes unnoticed.
        assert!(p("path,bdpt:uniform", &[MisHeuristic::Balance]).is_err());
        assert!(p("path,light", &[MisHeuristic::Power]).is_ok());
    }

    /// Against a noisy reference relMSE is V/n + floor: the fit over every
    /// checkpoint flattens (here, 4 to 4096 spp with the floor reached at
    /// 300, to -0.64); the one over checkpoints at ten times the floor and
    /// more stays within 0.1 of -1 (-0.96 here).
    #[test]
    fn the_spp_slope_leaves_out_the_reference_noise_floor() {
        let checkpoint = |spp: u32| Checkpoint {
            spp,
            seconds: 1.0,
            cpu_seconds: None,
            rel_mse: 3.0 / spp as f64 + 1e-2,
            mse: 0.0,
            mae: 0.0,
            by_spp: true,
        };
        let grid = std::iter::successors(Some(1), |&n| (n < 4096).then(|| next_grid_spp(n)));
        let checkpoints: Vec<Checkpoint> = grid.map(checkpoint).collect();
        let all = spp_slope(&checkpoints, None).unwrap();
        let clear = spp_slope(&checkpoints, Some(1e-2)).unwrap();
        eprintln!("slope over every checkpoint {all:.3}, at ten times the floor {clear:.3}");
        assert!(all > -0.8, "{all}");
        assert!((-1.0..=-0.88).contains(&clear), "{clear}");
    }

    /// 1 / ((relMSE - floor) s), and NaN without a floor, at or under it,
    /// or without an efficiency.
    #[test]
    fn efficiency_net_of_the_reference_noise() {
        let e = efficiency(4e-3, 2.0, Clock::Wall);
        assert!((efficiency_net(e, 4e-3, Some(1e-3)) - 1.0 / (3e-3 * 2.0)).abs() < 1e-9);
        assert!(efficiency_net(e, 4e-3, None).is_nan());
        assert!(efficiency_net(e, 4e-3, Some(4e-3)).is_nan());
        assert!(efficiency_net(f64::NAN, 4e-3, Some(1e-3)).is_nan());
    }

    #[test]
    fn slope_of_a_power_law() {
        let s = fit_slope((1..20).map(|n| (n as f64, 3.0 / n as f64))).unwrap();
        assert!((s + 1.0).abs() < 1e-9);
    }
}
