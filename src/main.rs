//! The `prism` command line.

use anyhow::{anyhow, bail, ensure, Context, Result};
use clap::{Parser, Subcommand};
use prism::accel::LANES;
use prism::camera::Camera;
use prism::film::{DroppedSamples, Film};
use prism::integrators::{self, Integrator, IntegratorOptions, INTEGRATORS};
use prism::output::{
    self, check_no_stale_state, check_outputs, check_sidecar_target, check_writable, ensure_exr, resolve_path, Outputs,
};
use prism::render::{check_threads, render_chunked, render_with_strategies, RenderOptions, RenderStats};
use prism::render_state::{Identity, Provenance, RenderState, SceneFingerprint};
use prism::sampling::MisHeuristic;
use prism::scene::{load_scene, RenderDefaults, Scene};
use prism::stats::{check_pass_memory, pixel_mean_variance, render_pass_films};
use prism::strategies::{self, is_strategy_image, StrategyImages, DEFAULT_MAX_LENGTH};
use serde::Serialize;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

#[derive(Parser)]
#[command(name = "prism", version, about = "A spectral bidirectional path tracer for light-transport research")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene to an EXR (linear sRGB), with an optional PNG preview and a JSON sidecar.
    Render(RenderArgs),
    /// List the registered integrators.
    Integrators,
    /// Render a stored reference: K independent passes, their mean (EXR) and
    /// per-block means and standard errors (JSON sidecar) for z-tests, with
    /// the relMSE its own noise adds to a measurement against it.
    Reference(ReferenceArgs),
    /// Add parts of one render (`render --sample-range`) into one image:
    /// OUT.exr, its sidecar OUT.json and state OUT.state, bit-identical to a
    /// single render of all their samples (docs/cluster.md).
    Merge {
        /// Output EXR.
        out: PathBuf,
        /// The parts' EXRs (their sums are read from the .state beside each).
        #[arg(required = true)]
        parts: Vec<PathBuf>,
    },
    /// Compare an image with a reference: relMSE, MSE, mean absolute error.
    Compare {
        /// The image (EXR).
        image: PathBuf,
        /// The reference it is measured against (EXR, the same size).
        reference: PathBuf,
    },
    /// Progressive renders against a reference: relMSE vs time and spp per
    /// integrator, charts, efficiency table and report (docs/results.md).
    Converge(prism::converge::ConvergeArgs),
    /// Export a scene for Mitsuba 3 (XML + PLY) to render it side by side (benches/peers).
    ExportMitsuba(prism::mitsuba::ExportMitsubaArgs),
    /// Regenerate the Jakob-Hanika RGB-to-spectrum coefficient table.
    RgbTable {
        /// Table resolution per axis (3 to 256: the table holds 9 res^3
        /// floats).
        #[arg(long, default_value_t = 32, value_parser = clap::value_parser!(u16).range(3..=256))]
        res: u16,
        /// Where the table is written (a .bin file; prism's own is
        /// src/spectrum/data/rgb_to_spectrum_srgb.bin).
        #[arg(long)]
        out: PathBuf,
    },
}

#[derive(clap::Args)]
struct ReferenceArgs {
    /// Scene file (JSON, or glTF: .gltf / .glb).
    scene: PathBuf,
    /// Estimator (see `prism integrators`).
    #[arg(long, default_value = "path")]
    integrator: String,
    #[command(flatten)]
    estimator: EstimatorArgs,
    /// Samples per pixel of each pass.
    #[arg(long)]
    spp: u32,
    /// Number of independent passes (seeds seed, seed+1, ...).
    #[arg(long, default_value_t = 16)]
    passes: u32,
    /// Seed of the first pass (not the scene's: a reference must be
    /// independent of the renders it is compared with).
    #[arg(long, default_value_t = 1000)]
    seed: u64,
    /// Image width in pixels.
    #[arg(long)]
    width: u32,
    /// Image height in pixels.
    #[arg(long)]
    height: u32,
    /// Block size (pixels) of the stored statistics.
    #[arg(long, default_value_t = 8)]
    block: u32,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Output EXR; the sidecar goes next to it (.json).
    #[arg(long)]
    out: PathBuf,
}

/// The options of the estimator, as `render` and `reference` take them.
#[derive(clap::Args)]
struct EstimatorArgs {
    /// Maximum scattering events (roulette ends most paths long before);
    /// default: the scene's, else 1024.
    #[arg(long)]
    max_depth: Option<u32>,
    /// MIS heuristic of bdpt: power (the default), balance or uniform.
    #[arg(long)]
    mis: Option<MisHeuristic>,
}

impl EstimatorArgs {
    /// Estimator `name` with these options over the scene's `defaults`,
    /// and the options it renders with (the heuristic the one it reads,
    /// which sidecars and states record). A `--mis` for an estimator that
    /// reads none is a warning, not an error: a script may pass one --mis
    /// to every integrator, and such parts still merge.
    fn create(&self, name: &str, defaults: &RenderDefaults) -> Result<(Box<dyn Integrator>, IntegratorOptions)> {
        let max_depth = self.max_depth.or(defaults.max_depth).unwrap_or(IntegratorOptions::default().max_depth);
        let mis = self.mis.unwrap_or_default();
        let integrator =
            integrators::create(name, &IntegratorOptions { max_depth, mis }).map_err(anyhow::Error::msg)?;
        if self.mis.is_some() && !integrators::reads_mis(name) {
            eprintln!("warning: --mis sets bdpt's heuristic; {name} reads none and ignores it");
        }
        Ok((integrator, IntegratorOptions { max_depth, mis: integrators::effective_mis(name, mis) }))
    }
}

#[derive(clap::Args)]
struct RenderArgs {
    /// Scene file (JSON, or glTF: .gltf / .glb).
    scene: PathBuf,
    /// Estimator (see `prism integrators`); default: the scene's, else `path`.
    #[arg(long)]
    integrator: Option<String>,
    /// Samples per pixel (light tracing: light paths per pixel); default:
    /// the scene's, else 16.
    #[arg(long)]
    spp: Option<u32>,
    /// Output EXR.
    #[arg(long)]
    out: PathBuf,
    /// Optional PNG preview (sRGB, clamped).
    #[arg(long)]
    png: Option<PathBuf>,
    /// PNG exposure in stops (with --png).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true, requires = "png")]
    exposure: f32,
    /// Image width in pixels, with --height; default: the scene's camera.
    #[arg(long)]
    width: Option<u32>,
    /// Image height in pixels, with --width.
    #[arg(long)]
    height: Option<u32>,
    /// Seed of the samples; default: the scene's, else 0.
    #[arg(long)]
    seed: Option<u64>,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    #[command(flatten)]
    estimator: EstimatorArgs,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
    /// Also write one EXR per BDPT strategy (s, t), weighted and unweighted,
    /// for paths of up to --strategies-max-length bounces, and the weighted
    /// sum of all longer ones, into this directory (created if missing; bdpt
    /// only), listed in the sidecar; an earlier render's other strategy
    /// images there are removed.
    #[arg(long, value_name = "DIR")]
    strategies: Option<PathBuf>,
    /// With --strategies: the longest paths, in bounces (s + t - 2), whose
    /// strategies get images of their own; longer ones share one weighted
    /// image, longer_paths_weighted.exr [default: 8]
    #[arg(long, value_name = "N", requires = "strategies")]
    strategies_max_length: Option<u32>,
    /// Render K independent passes of --spp samples (seeds seed, seed+1, ...):
    /// --out gets their mean, OUT.var.exr the per-pixel sample variance of
    /// one pass (divide by K for the variance of the mean).
    #[arg(long, value_name = "K", conflicts_with_all = ["sample_range", "checkpoint_every", "resume", "strategies"])]
    passes: Option<u32>,
    /// Render only the sample indices A..B (A included, B not) of every
    /// pixel, a part for `prism merge`; also writes the part's sums to OUT.state.
    #[arg(long, value_name = "A..B", value_parser = parse_range, conflicts_with_all = ["spp", "strategies"])]
    sample_range: Option<Range<u32>>,
    /// Write the accumulation state to OUT.ckpt (durably) whenever SECONDS
    /// have passed since the last one, between runs of 8 samples per pixel;
    /// removed when the render completes.
    #[arg(long, value_name = "SECONDS", conflicts_with = "strategies")]
    checkpoint_every: Option<f64>,
    /// Continue from a checkpoint (or a part's .state) of the same render:
    /// the same scene, integrator, seed, resolution, --max-depth and --mis,
    /// holding its first samples; --spp may grow (docs/cluster.md).
    #[arg(long, value_name = "CHECKPOINT", conflicts_with = "strategies")]
    resume: Option<PathBuf>,
}

fn parse_range(s: &str) -> Result<Range<u32>, String> {
    let bad = || format!("expected A..B with integers 0 <= A < B, got \"{s}\"");
    let (a, b) = s.split_once("..").ok_or_else(bad)?;
    let (a, b): (u32, u32) = (a.parse().map_err(|_| bad())?, b.parse().map_err(|_| bad())?);
    if a >= b {
        return Err(bad());
    }
    Ok(a..b)
}

/// The JSON sidecar written next to every EXR.
#[derive(Serialize)]
struct Sidecar {
    #[serde(flatten)]
    identity: Identity,
    /// Samples per pixel (per pass with --passes).
    spp: u64,
    /// The sample indices rendered, as [start, end) ranges.
    sample_ranges: Vec<[u32; 2]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    passes: Option<u32>,
    /// The per-pixel variance EXR (--passes).
    #[serde(skip_serializing_if = "Option::is_none")]
    variance: Option<String>,
    /// The film's exact sums, for `prism merge` (--sample-range, merge).
    #[serde(skip_serializing_if = "Option::is_none")]
    state: Option<String>,
    /// The per-strategy images written to --strategies DIR (file names).
    #[serde(skip_serializing_if = "Option::is_none")]
    strategy_images: Option<Vec<String>>,
    /// The values those images refused, counted apart from the film's.
    #[serde(skip_serializing_if = "Option::is_none")]
    strategy_records_dropped: Option<DroppedSamples>,
    /// This process's work (a resumed render counts only its own; none, and
    /// no field, when the checkpoint held every sample).
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    performance: Option<Performance>,
    dropped_samples: DroppedSamples,
    prism_version: &'static str,
    commit: String,
    /// `prism::build_target`: images are bit-identical within one.
    build_target: String,
}

#[derive(Serialize)]
struct Performance {
    threads: usize,
    wall_seconds: f64,
    samples_per_second: f64,
    rays: u64,
    mrays_per_second: f64,
}

impl Sidecar {
    fn new(identity: Identity, spp: u64, ranges: &[Range<u32>], dropped: DroppedSamples) -> Self {
        Sidecar {
            identity,
            spp,
            sample_ranges: ranges.iter().map(|r| [r.start, r.end]).collect(),
            passes: None,
            variance: None,
            state: None,
            strategy_images: None,
            strategy_records_dropped: None,
            performance: None,
            dropped_samples: dropped,
            prism_version: env!("CARGO_PKG_VERSION"),
            commit: env!("PRISM_COMMIT").to_string(),
            build_target: prism::build_target(),
        }
    }

    /// The commit(s) and build(s) of the sums written (a merge's parts', a
    /// resumed render's and its checkpoint's), with a warning when they are
    /// several: such sums make an unbiased image, but not (knowingly) the
    /// bit-identical one that any of them renders.
    fn set_provenance(&mut self, p: &Provenance) {
        self.commit.clone_from(&p.commit);
        self.build_target.clone_from(&p.build_target);
        if p.is_mixed() {
            eprintln!(
                "warning: these sums were rendered by different prism commits or builds, or ones not recorded \
                 (commits [{}], builds [{}]): the image is unbiased, but may not be bit-identical to a render by \
                 any one of them (docs/cluster.md)",
                p.commit, p.build_target
            );
        }
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Render(args) => render_command(args),
        Command::Integrators => {
            for i in INTEGRATORS {
                println!("{:<12} {}", i.name, i.description);
            }
            Ok(())
        }
        Command::RgbTable { res, out } => rgb_table(res.into(), &out),
        Command::Reference(args) => reference_command(args),
        Command::Merge { out, parts } => merge_command(&out, &parts),
        Command::Compare { image, reference } => compare_command(&image, &reference),
        Command::Converge(args) => prism::converge::command(args),
        Command::ExportMitsuba(args) => prism::mitsuba::command(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn reference_command(a: ReferenceArgs) -> Result<()> {
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    check_reference_counts(&a)?;
    Camera::check_resolution(a.width, a.height).map_err(|e| anyhow!("--width, --height: {e}"))?;
    check_pass_memory(a.passes, a.width, a.height).map_err(|e| anyhow!("--passes: {e}"))?;
    check_threads(a.threads)?;
    let mut builder = load_scene(&a.scene)?;
    builder.set_resolution(a.width, a.height).map_err(|e| anyhow!("--width, --height: {e}"))?;
    let (integrator, options) = a.estimator.create(&a.integrator, &builder.defaults)?;
    ensure_exr("--out", &a.out)?;
    check_no_stale_state(&a.out, "")?;
    check_new_outputs(
        &scene_inputs(&a.scene, &builder.inputs),
        &[("--out", &a.out), ("its sidecar", &a.out.with_extension("json"))],
    )?;
    let file = SceneFingerprint::read(&a.scene, &builder.inputs)?;
    let scene = builder.build();
    let (image, meta) = prism::reference::make_reference(
        &scene,
        &file,
        integrator.as_ref(),
        &a.integrator,
        &options,
        a.spp,
        a.passes,
        a.seed,
        a.block,
        a.threads,
        command,
    );
    prism::reference::write_reference(&a.out, &image, &meta)?;
    eprintln!("{} passes x {} spp in {:.1} s", a.passes, a.spp, meta.wall_seconds);
    warn_dropped("samples", &meta.dropped_samples);
    Ok(())
}

/// `prism reference`'s counts one at a time, so the message names the flag
/// at fault and its value.
fn check_reference_counts(a: &ReferenceArgs) -> Result<()> {
    at_least("--spp", a.spp, 1, "")?;
    at_least("--passes", a.passes, 2, TWO_PASSES)?;
    at_least("--block", a.block, 1, "")?;
    // The sidecar's statistics are of whole blocks of --block x --block pixels.
    for (flag, n) in [("--width", a.width), ("--height", a.height)] {
        ensure!(n % a.block == 0, "{flag} {n} is not a multiple of --block {}", a.block);
    }
    Ok(())
}

/// Why `--passes` must be at least 2, for `at_least`.
const TWO_PASSES: &str = " (a variance needs two passes)";

/// `flag` must be at least `min`; `why` (empty, or " (reason)") follows the
/// bound in the message.
fn at_least(flag: &str, value: u32, min: u32, why: &str) -> Result<()> {
    ensure!(value >= min, "{flag} must be at least {min}{why}, got {value}");
    Ok(())
}

fn compare_command(image: &Path, reference: &Path) -> Result<()> {
    let (w, h, a) = output::read_exr(image)?;
    let (rw, rh, b) = output::read_exr(reference)?;
    output::ensure_finite(image, w, &a)?;
    output::ensure_finite(reference, rw, &b)?;
    if (w, h) != (rw, rh) {
        bail!("{} is {w}x{h} but {} is {rw}x{rh}", image.display(), reference.display());
    }
    let n = (a.len() * 3) as f64;
    let diffs = || a.iter().zip(&b).flat_map(|(x, r)| (0..3).map(move |c| (x[c] as f64, r[c] as f64)));
    let mse = diffs().map(|(x, r)| (x - r).powi(2)).sum::<f64>() / n;
    let mae = diffs().map(|(x, r)| (x - r).abs()).sum::<f64>() / n;
    println!("relMSE {:.6e}  MSE {mse:.6e}  MAE {mae:.6e}", prism::stats::rel_mse(&a, &b));
    Ok(())
}

/// The table's file must be a .bin: `--out scene.json` replaced a scene
/// with binary data.
fn rgb_table(res: usize, out: &Path) -> Result<()> {
    output::ensure_extension("--out", out, "bin")?;
    // Before the minutes of fitting, not after.
    check_new_outputs(&[], &[("--out", out)])?;
    prism::spectrum::RgbToSpectrumTable::generate(res).write(out)
}

/// What every kind of render shares: the scene, its estimator, the options
/// and what identifies the render (for checkpoints, parts and sidecars).
struct Setup {
    scene: Scene,
    integrator: Box<dyn Integrator>,
    identity: Identity,
    spp: u32,
    opts: RenderOptions,
}

/// Loads the scene and checks every argument before anything is rendered.
fn set_up(a: &RenderArgs) -> Result<Setup> {
    let mut builder = load_scene(&a.scene)?;
    let defaults = builder.defaults.clone();
    let name = a.integrator.clone().or(defaults.integrator.clone()).unwrap_or_else(|| "path".to_string());
    let spp = a.spp.or(defaults.spp).unwrap_or(16);
    at_least("--spp", spp, 1, "")?;
    if let Some(k) = a.passes {
        at_least("--passes", k, 2, TWO_PASSES)?;
    }
    if a.checkpoint_every.is_some_and(|s| Duration::try_from_secs_f64(s).is_err()) {
        bail!("--checkpoint-every must be a number of seconds >= 0 (below 2^64)");
    }
    // 2^exposure must be a normal f32: 0 or infinity would write a black PNG.
    if !2f32.powf(a.exposure).is_normal() {
        bail!("--exposure must be a number of stops in [-126, 128), got {}", a.exposure);
    }
    check_threads(a.threads)?;
    let seed = a.seed.or(defaults.seed).unwrap_or(0);
    let (integrator, IntegratorOptions { max_depth, mis }) = a.estimator.create(&name, &defaults)?;
    if a.strategies.is_some() && name != "bdpt" {
        bail!("--strategies needs --integrator bdpt (got {name})");
    }
    if a.width.is_some() || a.height.is_some() {
        let (w, h) = (a.width.unwrap_or(0), a.height.unwrap_or(0));
        if w == 0 || h == 0 {
            bail!("--width and --height must be given together and be at least 1");
        }
        builder.set_resolution(w, h).map_err(|e| anyhow!("--width, --height: {e}"))?;
    }
    if a.strategies.is_some() {
        // (Before `check_render_outputs`, which creates the directory.)
        let ((width, height), max_length) =
            (builder.resolution(), a.strategies_max_length.unwrap_or(DEFAULT_MAX_LENGTH));
        strategies::check_memory(width, height, max_length, max_depth)
            .map_err(|e| anyhow!("--strategies-max-length: {e}"))?;
    }
    check_render_outputs(a, &builder.inputs)?;
    let file = SceneFingerprint::read(&a.scene, &builder.inputs)?;
    let scene = builder.build();
    let identity = Identity {
        scene: file.name,
        scene_hash: file.hash,
        integrator: name,
        seed,
        width: scene.camera.width,
        height: scene.camera.height,
        max_depth,
        mis: mis.name().to_string(),
    };
    let opts = RenderOptions { seed, threads: a.threads, progress: !a.quiet };
    Ok(Setup { scene, integrator, identity, spp, opts })
}

/// The files a render will write, checked before it starts: their
/// extensions, no interrupted render's state or checkpoint replaced, none
/// of them the scene, a file it reads (`files`), the checkpoint it resumes
/// or a strategy's image.
fn check_render_outputs(a: &RenderArgs, files: &[PathBuf]) -> Result<()> {
    ensure_exr("--out", &a.out)?;
    if let Some(png) = &a.png {
        output::ensure_extension("--png", png, "png")?;
    }
    if !writes_state(a) {
        check_no_stale_state(&a.out, ", or render the part with --sample-range A..B")?;
    }
    let checkpoint = a.out.with_extension("ckpt");
    if a.checkpoint_every.is_some() && checkpoint.exists() && !resumes(a, &checkpoint) {
        bail!(
            "{} holds the samples of an interrupted render, which this one would replace: continue it with \
             --resume {0}, or remove it",
            checkpoint.display()
        );
    }
    let outputs = render_outputs(a);
    let outputs: Vec<(&str, &Path)> = outputs.iter().map(|(r, p)| (*r, p.as_path())).collect();
    check_new_outputs(&scene_inputs(&a.scene, files), &outputs)?;
    if let Some(resume) = &a.resume {
        // It may be replaced only by its own successor, once it is read:
        // the checkpoint or the state file.
        let (ckpt, state) = (a.out.with_extension("ckpt"), a.out.with_extension("state"));
        let others: Vec<_> = outputs.iter().copied().filter(|&(_, p)| p != ckpt && p != state).collect();
        check_outputs(&[("the checkpoint (--resume)", resume)], &others)?;
    }
    if let Some(dir) = &a.strategies {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        check_writable(&dir.join("s0_t2_weighted.exr"))?;
        let dir = resolve_path(dir);
        let in_dir = |p: &Path| resolve_path(p).parent() == Some(dir.as_path());
        let name = |p: &Path| p.file_name().and_then(|n| n.to_str()).unwrap_or_default().to_string();
        if let Some((role, path)) = outputs.iter().find(|(_, p)| in_dir(p) && is_strategy_image(&name(p))) {
            bail!("{role} {} is where --strategies writes a strategy's image: choose another name", path.display());
        }
    }
    Ok(())
}

/// Every file a render writes beside --out, by role (not the per-strategy
/// images, which go to their own directory).
fn render_outputs(a: &RenderArgs) -> Vec<(&'static str, PathBuf)> {
    let mut outs = vec![("--out", a.out.clone()), ("its sidecar", a.out.with_extension("json"))];
    outs.extend(a.png.clone().map(|p| ("--png", p)));
    if a.passes.is_some() {
        outs.push(("its variance image", a.out.with_extension("var.exr")));
    }
    if writes_state(a) {
        outs.push(("its state file", a.out.with_extension("state")));
    }
    if a.checkpoint_every.is_some() {
        outs.push(("its checkpoint", a.out.with_extension("ckpt")));
    }
    outs
}

/// Whether the render resumes from `checkpoint`, however either is spelt.
fn resumes(a: &RenderArgs, checkpoint: &Path) -> bool {
    a.resume.as_deref().is_some_and(|r| resolve_path(r) == resolve_path(checkpoint))
}

/// Whether the render writes OUT.state, the sums `prism merge` reads: a
/// part (--sample-range), or any resumed render (from a part's .state it
/// grows, or from a checkpoint of a part or of a grown part), whose old
/// state would otherwise be left behind holding fewer samples. A resumed
/// whole render gets one too: it is a valid part of samples 0..spp.
fn writes_state(a: &RenderArgs) -> bool {
    a.sample_range.is_some() || a.resume.is_some()
}

/// The scene file and the files it reads (`SceneBuilder::inputs`), as
/// inputs no output may replace.
fn scene_inputs<'a>(scene: &'a Path, files: &'a [PathBuf]) -> Vec<(&'static str, &'a Path)> {
    let files = files.iter().map(|f| ("a file the scene reads", f.as_path()));
    std::iter::once(("the scene", scene)).chain(files).collect()
}

/// Before anything is rendered: every output writable (its directory
/// exists, it is not a directory), none replacing an input or another, and
/// the JSON ones (the sidecars) replacing no JSON file but a sidecar.
fn check_new_outputs(inputs: &[(&str, &Path)], outputs: &[(&str, &Path)]) -> Result<()> {
    for (_, path) in outputs {
        check_writable(path)?;
    }
    check_outputs(inputs, outputs)?;
    for (_, path) in outputs.iter().filter(|(_, p)| p.extension().is_some_and(|e| e == "json")) {
        check_sidecar_target(path)?;
    }
    Ok(())
}

fn render_command(a: RenderArgs) -> Result<()> {
    let s = set_up(&a)?;
    for w in s.scene.geometry_warnings().into_iter().chain(s.integrator.unsamplable(&s.scene)) {
        eprintln!("warning: {w}");
    }
    // Every file this render writes, moved into place together at the end.
    let mut out = Outputs::default();
    let (image, mut sidecar, stats) = match (a.passes, &a.strategies) {
        (Some(k), _) => render_pass_mode(&a, &s, k, &mut out)?,
        (None, Some(dir)) => render_strategies(&s, dir, a.strategies_max_length, &mut out)?,
        (None, None) => render_samples(&a, &s, &mut out)?,
    };
    let (w, h) = (s.identity.width, s.identity.height);
    out.exr(&a.out, w, h, &image)?;
    if let Some(png) = &a.png {
        out.png(png, w, h, &image, a.exposure)?;
    }
    let secs = stats.wall.as_secs_f64();
    let per_second = |x: f64| if secs > 0.0 { x / secs } else { 0.0 };
    sidecar.performance = (stats.samples > 0).then(|| Performance {
        threads: stats.threads,
        wall_seconds: secs,
        samples_per_second: per_second(stats.samples as f64),
        rays: stats.rays,
        mrays_per_second: per_second(stats.rays as f64) / 1e6,
    });
    out.json(&a.out.with_extension("json"), &sidecar)?;
    out.commit()?;
    if let (Some(dir), Some(names)) = (&a.strategies, &sidecar.strategy_images) {
        remove_stale_strategy_images(dir, names)?;
        eprintln!("wrote the per-strategy images to {}", dir.display());
    }
    let checkpoint = a.out.with_extension("ckpt");
    if a.checkpoint_every.is_some() || resumes(&a, &checkpoint) {
        // The outputs are complete: this render's checkpoint has done its job.
        let _ = std::fs::remove_file(checkpoint);
    }
    if stats.samples == 0 {
        eprintln!("{w}x{h} {} spp: every sample was in the checkpoint, none left to render", sidecar.spp);
    } else {
        eprintln!(
            "{w}x{h} {} spp{} in {secs:.2} s: {:.2} Msamples/s, {:.1} Mrays/s",
            sidecar.spp,
            a.passes.map(|k| format!(" x {k} passes")).unwrap_or_default(),
            per_second(stats.samples as f64) / 1e6,
            per_second(stats.rays as f64) / 1e6
        );
    }
    warn_dropped("samples", &sidecar.dropped_samples);
    Ok(())
}

/// Renders sample indices 0..spp, or --sample-range, possibly resumed from a
/// checkpoint and checkpointed on the way.
fn render_samples(a: &RenderArgs, s: &Setup, out: &mut Outputs) -> Result<(Vec<[f32; 3]>, Sidecar, RenderStats)> {
    let range = a.sample_range.clone().unwrap_or(0..s.spp);
    let (mut film, resumed) = match &a.resume {
        Some(path) => resume(path, &s.identity, &range).map(|(film, made_by)| (film, Some(made_by)))?,
        None => (Film::new(s.identity.width, s.identity.height), None),
    };
    // Who rendered the sums once this render has added to them.
    let this = Provenance::this();
    let made_by = resumed.as_ref().map_or(this.clone(), |r| this.combined(r));
    let done = range.start + film.spp as u32;
    // Checkpoints are taken between chunks of one packet of samples per
    // pixel (`LANES`): a chunk of one sample per pixel, as until session
    // 39, traced no camera rays as packets and took 22 % longer.
    let chunk = if a.checkpoint_every.is_some() { LANES as u32 } else { range.len().max(1) as u32 };
    let checkpoint = a.out.with_extension("ckpt");
    let mut last = Instant::now();
    let stats = render_chunked(&s.scene, s.integrator.as_ref(), &s.opts, &mut film, done..range.end, chunk, |film| {
        if a.checkpoint_every.is_some_and(|every| last.elapsed() >= Duration::from_secs_f64(every)) {
            let held = range.start..range.start + film.spp as u32;
            RenderState::save(&checkpoint, &s.identity, std::slice::from_ref(&held), film, &made_by)?;
            last = Instant::now();
        }
        Ok(())
    })?;
    // A resume that found every sample in its checkpoint added nothing.
    let made_by = if stats.samples == 0 { resumed.unwrap_or(this) } else { made_by };
    let mut sidecar = Sidecar::new(s.identity.clone(), film.spp, std::slice::from_ref(&range), film.dropped);
    sidecar.set_provenance(&made_by);
    if writes_state(a) {
        // Staged before the image: see `merge_command`.
        let path = a.out.with_extension("state");
        out.bytes(&path, &RenderState::encode(&s.identity, std::slice::from_ref(&range), &film, &made_by)?)?;
        sidecar.state = Some(file_name(&path));
    }
    Ok((film.image(), sidecar, stats))
}

/// Loads a checkpoint's film, and who rendered it, after
/// checking it belongs to this render and holds the first samples of
/// `range`.
fn resume(path: &Path, identity: &Identity, range: &Range<u32>) -> Result<(Film, Provenance)> {
    let state = RenderState::load(path)?;
    let name = path.display().to_string();
    identity.ensure_same("this render", &state.identity, &name)?;
    match state.contiguous_range() {
        Some(h) if h.start == range.start && h.end <= range.end => {}
        Some(h) if h.start == range.start => bail!(
            "{name} holds samples {h:?}, more than this render's {range:?}: ask for samples up to {} at least",
            h.end
        ),
        _ => bail!(
            "{name} holds samples {:?}, which are not the first samples of this render's {range:?}",
            state.sample_ranges
        ),
    }
    Ok((state.film, state.provenance))
}

/// --passes: K independent renders, their mean and per-pixel variance.
fn render_pass_mode(
    a: &RenderArgs,
    s: &Setup,
    k: u32,
    out: &mut Outputs,
) -> Result<(Vec<[f32; 3]>, Sidecar, RenderStats)> {
    check_pass_memory(k, s.identity.width, s.identity.height).map_err(|e| anyhow!("--passes: {e}"))?;
    let (films, stats) = render_pass_films(&s.scene, s.integrator.as_ref(), &s.opts, s.spp, k);
    let (mean, variance) = pixel_mean_variance(&films.iter().map(Film::image).collect::<Vec<_>>());
    let path = a.out.with_extension("var.exr");
    out.exr(&path, s.identity.width, s.identity.height, &variance)?;
    let dropped = films.iter().map(|f| f.dropped).sum();
    let mut sidecar = Sidecar::new(s.identity.clone(), s.spp as u64, std::slice::from_ref(&(0..s.spp)), dropped);
    sidecar.passes = Some(k);
    sidecar.variance = Some(file_name(&path));
    Ok((mean, sidecar, stats))
}

/// Removes the strategy images in `dir` an earlier render left and this one
/// did not write (`written`), so the directory holds one render's images.
fn remove_stale_strategy_images(dir: &Path, written: &[String]) -> Result<()> {
    let listing = std::fs::read_dir(dir).with_context(|| format!("cannot list {}", dir.display()))?;
    for entry in listing {
        let path = entry.with_context(|| format!("cannot list {}", dir.display()))?.path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        if is_strategy_image(name) && !written.iter().any(|w| w == name) {
            std::fs::remove_file(&path).with_context(|| format!("cannot remove {}", path.display()))?;
        }
    }
    Ok(())
}

/// --strategies: the image plus the per-strategy images (`StrategyImages`).
fn render_strategies(
    s: &Setup,
    dir: &Path,
    max_length: Option<u32>,
    out: &mut Outputs,
) -> Result<(Vec<[f32; 3]>, Sidecar, RenderStats)> {
    let mut film = Film::new(s.identity.width, s.identity.height);
    let max_length = max_length.unwrap_or(DEFAULT_MAX_LENGTH);
    let mut images = StrategyImages::new(film.width, film.height, max_length);
    let stats = render_with_strategies(&s.scene, s.integrator.as_ref(), &s.opts, &mut film, 0..s.spp, &mut images);
    let names = images.stage_exrs(dir, out)?;
    let mut sidecar = Sidecar::new(s.identity.clone(), film.spp, std::slice::from_ref(&(0..s.spp)), film.dropped);
    sidecar.strategy_images = Some(names);
    sidecar.strategy_records_dropped = Some(images.dropped);
    warn_dropped("values of the per-strategy images", &images.dropped);
    Ok((film.image(), sidecar, stats))
}

fn merge_command(out: &Path, parts: &[PathBuf]) -> Result<()> {
    ensure_exr("the merge output", out)?;
    for part in parts {
        // Its .state is read: a checkpoint's name would read a stale one.
        let named = |ext: &str| part.extension().is_some_and(|e| e.eq_ignore_ascii_case(ext));
        ensure!(
            named("exr") || named("state"),
            "a part must name its .exr image or its .state file, got {}",
            part.display()
        );
    }
    let inputs: Vec<PathBuf> = parts.iter().map(|p| p.with_extension("state")).collect();
    let (state, sidecar) = (out.with_extension("state"), out.with_extension("json"));
    check_new_outputs(
        &inputs.iter().map(|p| ("the part state", p.as_path())).collect::<Vec<_>>(),
        &[("the merged image", out), ("its sidecar", &sidecar), ("its state file", &state)],
    )?;
    let merged =
        RenderState::merge(inputs.iter().map(|path| Ok((path.display().to_string(), RenderState::load(path)?))))?;
    check_merge_keeps_samples(&state, out, &merged)?;
    let (id, film) = (&merged.identity, &merged.film);
    // The state first, as a render writes it: it is what `merge` reads, and
    // if the process dies in between, a new state beside an old image is
    // merged correctly where the reverse would be merged stale.
    let mut outputs = Outputs::default();
    outputs.bytes(&state, &RenderState::encode(id, &merged.sample_ranges, film, &merged.provenance)?)?;
    outputs.exr(out, id.width, id.height, &film.image())?;
    let mut meta = Sidecar::new(id.clone(), film.spp, &merged.sample_ranges, film.dropped);
    meta.state = Some(file_name(&state));
    // The parts' commits and builds, not this one's: merging only adds
    // their sums.
    meta.set_provenance(&merged.provenance);
    outputs.json(&sidecar, &meta)?;
    outputs.commit()?;
    eprintln!("merged {} parts: {} spp (samples {:?})", parts.len(), film.spp, merged.sample_ranges);
    warn_dropped("samples", &film.dropped);
    Ok(())
}

/// A merge may replace an earlier merge of the same render whose samples it
/// holds again (merging again as parts arrive), never sums it does not
/// hold: `prism merge parts/part-*.exr`, the output name forgotten, would
/// have written the other parts' sum over the first part's (a review,
/// session 53).
fn check_merge_keeps_samples(state: &Path, out: &Path, merged: &RenderState) -> Result<()> {
    if !state.exists() {
        return Ok(());
    }
    let name = state.display().to_string();
    let way_out = format!("the first path names the output ({}): choose another, or remove {name}", out.display());
    let old = RenderState::load(state).with_context(|| format!("the merge would replace {name}; {way_out}"))?;
    merged
        .identity
        .ensure_same("the merge", &old.identity, &name)
        .with_context(|| format!("the merge would replace {name}, another render's samples; {way_out}"))?;
    let held =
        |r: &Range<u32>| r.is_empty() || merged.sample_ranges.iter().any(|m| m.start <= r.start && r.end <= m.end);
    if let Some(r) = old.sample_ranges.iter().find(|r| !held(r)) {
        bail!("the merge would replace {name}, which holds samples {r:?} that the parts do not all hold; {way_out}");
    }
    Ok(())
}

/// A sidecar names the files beside it by file name, so that the set can be
/// moved (from cluster scratch space, say) without breaking it.
fn file_name(path: &Path) -> String {
    path.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default()
}

/// `what`: "samples", or what else was dropped.
fn warn_dropped(what: &str, d: &DroppedSamples) {
    if d.total() > 0 {
        eprintln!("warning: dropped {}; see the sidecar", d.describe(what));
    }
}
