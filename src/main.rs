//! The `prism` command line.

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use prism::film::{self, DroppedSamples, Film};
use prism::integrators::{self, IntegratorOptions, MisHeuristic, INTEGRATORS};
use prism::render::{render, render_with_strategies, RenderOptions, StrategyImages};
use prism::scene::load_scene;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

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
    /// per-block means and standard errors (JSON sidecar) for z-tests.
    Reference(ReferenceArgs),
    /// Compare an image with a reference: relMSE, MSE, mean absolute error.
    Compare { image: PathBuf, reference: PathBuf },
    /// Progressive renders against a reference: relMSE vs time and spp per
    /// integrator, charts, efficiency table and report (VALIDATION.md §6).
    Converge(prism::converge::ConvergeArgs),
    /// Export a scene for Mitsuba 3 (XML + PLY) to render it side by side (benches/peers).
    ExportMitsuba(prism::mitsuba::ExportMitsubaArgs),
    /// Regenerate the Jakob-Hanika RGB-to-spectrum coefficient table.
    RgbTable {
        /// Table resolution per axis.
        #[arg(long, default_value_t = 32)]
        res: usize,
        #[arg(long)]
        out: PathBuf,
    },
}

#[derive(clap::Args)]
struct ReferenceArgs {
    scene: PathBuf,
    #[arg(long, default_value = "path")]
    integrator: String,
    /// Samples per pixel of each pass.
    #[arg(long)]
    spp: u32,
    /// Number of independent passes (seeds seed, seed+1, ...).
    #[arg(long, default_value_t = 16)]
    passes: u32,
    #[arg(long, default_value_t = 1000)]
    seed: u64,
    #[arg(long)]
    width: u32,
    #[arg(long)]
    height: u32,
    /// Block size (pixels) of the stored statistics.
    #[arg(long, default_value_t = 8)]
    block: u32,
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Output EXR; the sidecar goes next to it (.json).
    #[arg(long)]
    out: PathBuf,
}

#[derive(clap::Args)]
struct RenderArgs {
    /// Scene file (JSON).
    scene: PathBuf,
    /// Estimator (see `prism integrators`); default: the scene's, else `path`.
    #[arg(long)]
    integrator: Option<String>,
    /// Samples per pixel (light tracing: light paths per pixel).
    #[arg(long)]
    spp: Option<u32>,
    /// Output EXR.
    #[arg(long)]
    out: PathBuf,
    /// Optional PNG preview (sRGB, clamped).
    #[arg(long)]
    png: Option<PathBuf>,
    /// PNG exposure in stops.
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    exposure: f32,
    #[arg(long)]
    width: Option<u32>,
    #[arg(long)]
    height: Option<u32>,
    #[arg(long)]
    seed: Option<u64>,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Maximum scattering events (roulette ends most paths long before).
    #[arg(long)]
    max_depth: Option<u32>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
    /// MIS heuristic of bdpt: power, balance or uniform.
    #[arg(long, default_value = "power")]
    mis: MisHeuristic,
    /// Also write one EXR per BDPT strategy (s, t), weighted and unweighted,
    /// into this directory (created if missing; bdpt only).
    #[arg(long, value_name = "DIR")]
    strategies: Option<PathBuf>,
}

/// The JSON sidecar written next to every EXR.
#[derive(Serialize)]
struct Sidecar {
    scene: String,
    integrator: String,
    spp: u64,
    seed: u64,
    width: u32,
    height: u32,
    max_depth: u32,
    threads: usize,
    wall_seconds: f64,
    samples_per_second: f64,
    rays: u64,
    mrays_per_second: f64,
    dropped_samples: DroppedSamples,
    prism_version: &'static str,
    commit: &'static str,
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
        Command::RgbTable { res, out } => rgb_table(res, &out),
        Command::Reference(args) => reference_command(args),
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
    if a.spp == 0 || a.passes < 2 || a.block == 0 || a.width % a.block != 0 || a.height % a.block != 0 {
        bail!("need --spp >= 1, --passes >= 2, and --width/--height multiples of --block");
    }
    let mut builder = load_scene(&a.scene)?;
    builder.set_resolution(a.width, a.height);
    let integrator = integrators::create(&a.integrator, &IntegratorOptions::default()).map_err(anyhow::Error::msg)?;
    check_writable(&a.out)?;
    let scene = builder.build();
    let name = a.scene.display().to_string();
    let (image, meta) = prism::reference::make_reference(
        &scene,
        &name,
        integrator.as_ref(),
        &a.integrator,
        a.spp,
        a.passes,
        a.seed,
        a.block,
        a.threads,
        command,
    );
    prism::reference::write_reference(&a.out, &image, &meta)?;
    eprintln!("{} passes x {} spp in {:.1} s", a.passes, a.spp, meta.wall_seconds);
    Ok(())
}

fn compare_command(image: &Path, reference: &Path) -> Result<()> {
    let (w, h, a) = film::read_exr(image)?;
    let (rw, rh, b) = film::read_exr(reference)?;
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

fn rgb_table(res: usize, out: &Path) -> Result<()> {
    let table = prism::spectrum::RgbToSpectrumTable::generate(res);
    table.write(out).with_context(|| format!("cannot write {}", out.display()))
}

/// Fails early (before any rendering) if `path` cannot be written.
fn check_writable(path: &Path) -> Result<()> {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !dir.is_dir() {
        bail!("cannot write {}: directory {} does not exist", path.display(), dir.display());
    }
    let probe = dir.join(format!(".prism-write-probe-{}", std::process::id()));
    std::fs::write(&probe, b"")
        .with_context(|| format!("cannot write {}: directory is not writable", path.display()))?;
    let _ = std::fs::remove_file(probe);
    if path.is_dir() {
        bail!("cannot write {}: it is a directory", path.display());
    }
    Ok(())
}

fn render_command(a: RenderArgs) -> Result<()> {
    let mut builder = load_scene(&a.scene)?;
    let defaults = builder.defaults.clone();
    let name = a.integrator.or(defaults.integrator).unwrap_or_else(|| "path".to_string());
    let spp = a.spp.or(defaults.spp).unwrap_or(16);
    if spp == 0 {
        bail!("--spp must be at least 1");
    }
    let seed = a.seed.or(defaults.seed).unwrap_or(0);
    let max_depth = a.max_depth.or(defaults.max_depth).unwrap_or(IntegratorOptions::default().max_depth);
    let integrator =
        integrators::create(&name, &IntegratorOptions { max_depth, mis: a.mis }).map_err(anyhow::Error::msg)?;
    if let Some(dir) = &a.strategies {
        if name != "bdpt" {
            bail!("--strategies needs --integrator bdpt (got {name})");
        }
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        check_writable(&dir.join("s0_t2_weighted.exr"))?;
    }
    if a.width.is_some() || a.height.is_some() {
        let (w, h) = (a.width.unwrap_or(0), a.height.unwrap_or(0));
        if w == 0 || h == 0 {
            bail!("--width and --height must be given together and be at least 1");
        }
        builder.set_resolution(w, h);
    }
    if a.out.extension().and_then(|e| e.to_str()) != Some("exr") {
        bail!("--out must name an .exr file, got {}", a.out.display());
    }
    check_writable(&a.out)?;
    if let Some(png) = &a.png {
        check_writable(png)?;
    }
    let scene = builder.build();
    for w in integrator.unsamplable(&scene) {
        eprintln!("warning: {w}");
    }
    let (w, h) = (scene.camera.width, scene.camera.height);
    let mut film = Film::new(w, h);
    let opts = RenderOptions { seed, threads: a.threads, progress: !a.quiet };
    let mut strategies = a.strategies.as_ref().map(|_| StrategyImages::new(w, h));
    let stats = match strategies.as_mut() {
        Some(images) => render_with_strategies(&scene, integrator.as_ref(), &opts, &mut film, 0..spp, images),
        None => render(&scene, integrator.as_ref(), &opts, &mut film, 0..spp),
    };
    let image = film.image();
    film::write_exr(&a.out, w, h, &image)?;
    if let (Some(dir), Some(images)) = (&a.strategies, &strategies) {
        let written = images.write_exrs(dir)?;
        eprintln!("wrote {} per-strategy images to {}", written.len(), dir.display());
    }
    if let Some(png) = &a.png {
        film::write_png(png, w, h, &image, a.exposure)?;
    }
    let secs = stats.wall.as_secs_f64();
    let sidecar = Sidecar {
        scene: a.scene.display().to_string(),
        integrator: name,
        spp: film.spp,
        seed,
        width: w,
        height: h,
        max_depth,
        threads: rayon::current_num_threads().max(a.threads),
        wall_seconds: secs,
        samples_per_second: stats.samples as f64 / secs,
        rays: stats.rays,
        mrays_per_second: stats.rays as f64 / secs / 1e6,
        dropped_samples: film.dropped,
        prism_version: env!("CARGO_PKG_VERSION"),
        commit: env!("PRISM_COMMIT"),
    };
    film::write_json(&a.out.with_extension("json"), &sidecar)?;
    eprintln!(
        "{}x{} {} spp in {:.2} s: {:.2} Msamples/s, {:.1} Mrays/s",
        w,
        h,
        film.spp,
        secs,
        sidecar.samples_per_second / 1e6,
        sidecar.mrays_per_second
    );
    if film.dropped.total() > 0 {
        let d = film.dropped;
        eprintln!(
            "warning: dropped {} samples ({} NaN, {} infinite, {} negative); see the sidecar",
            d.total(),
            d.nan,
            d.infinite,
            d.negative
        );
    }
    Ok(())
}
