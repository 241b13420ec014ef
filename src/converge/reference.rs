//! The reference a run is measured against: read from a file (with
//! whichever prism sidecar it has) or rendered here, and what is known of
//! its origin and its own noise.

use super::{spinner, ConvergeConfig, ReferenceInfo, ReferenceSource, REFERENCE_SEED_OFFSET};
use crate::film::DroppedSamples;
use crate::integrators::{self, IntegratorOptions};
use crate::output::{ensure_finite, read_exr};
use crate::reference::{make_reference, write_reference, ReferenceMeta};
use crate::render_state::SceneFingerprint;
use crate::sampling::MisHeuristic;
use crate::scene::Scene;
use crate::stats;
use anyhow::{anyhow, bail, ensure, Context, Result};
use serde::Deserialize;
use std::path::Path;

pub(super) fn obtain_reference(
    cfg: &ConvergeConfig,
    scene: &Scene,
    file: &SceneFingerprint,
    seed: u64,
    max_depth: u32,
    notes: &mut Vec<String>,
) -> Result<(Vec<[f32; 3]>, ReferenceInfo)> {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let (image, origin, path, here) = match &cfg.reference {
        ReferenceSource::File(path) => {
            let (image, origin, width) = if path.with_extension("json").exists() {
                let (image, origin) = read_any_reference(path)?;
                let width = origin.width;
                (image, Some(origin), width)
            } else {
                let (rw, rh, image) = read_exr(path)?;
                ensure!((rw, rh) == (w, h), "{} is {rw}x{rh} but the run renders {w}x{h}", path.display());
                (image, None, rw)
            };
            // (A rendered reference's pixels are finite: the film keeps
            // other samples out.)
            ensure_finite(path, width, &image)?;
            (image, origin, path.clone(), false)
        }
        ReferenceSource::Render { integrator, spp, passes, out } => {
            let job = ReferenceJob { integrator, spp: *spp, passes: *passes, out };
            let (image, origin) = render_reference(cfg, scene, file, seed, max_depth, &job)?;
            (image, Some(origin), out.clone(), true)
        }
    };
    match &origin {
        Some(m) => {
            check_origin(cfg, scene, seed, m, &path)?;
            notes.extend(origin_notes(cfg, scene, file, max_depth, m));
        }
        None => notes.push("the reference has no sidecar: its integrator, spp and noise are unknown".to_string()),
    }
    Ok((image, reference_info(&path, here, origin.as_ref())))
}

/// What `--reference-integrator`, `--reference-spp`, `--reference-passes`
/// and `--reference-out` ask for.
struct ReferenceJob<'a> {
    integrator: &'a str,
    spp: u32,
    passes: u32,
    out: &'a Path,
}

/// Renders the reference a run asked for and writes it (with its sidecar).
fn render_reference(
    cfg: &ConvergeConfig,
    scene: &Scene,
    file: &SceneFingerprint,
    seed: u64,
    max_depth: u32,
    job: &ReferenceJob,
) -> Result<(Vec<[f32; 3]>, Origin)> {
    let ReferenceJob { integrator, spp, passes, out } = *job;
    let (w, h) = (scene.camera.width, scene.camera.height);
    stats::check_pass_memory(passes, w, h).map_err(|e| anyhow!("--reference-passes: {e}"))?;
    // Both directories now, so that one that cannot be made stops
    // the run before the reference is rendered.
    for dir in out.parent().filter(|d| !d.as_os_str().is_empty()).into_iter().chain([cfg.out.as_path()]) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let options = IntegratorOptions { max_depth, mis: MisHeuristic::Power };
    let estimator = integrators::create(integrator, &options).map_err(anyhow::Error::msg)?;
    let per_pass = spp.div_ceil(passes);
    let total = per_pass as u64 * passes as u64;
    if total != spp as u64 {
        eprintln!("note: --reference-spp {spp} over {passes} passes: {per_pass} spp per pass, {total} in all");
    }
    // The largest block (for the sidecar's z-test statistics) that tiles the image.
    let block = [8, 4, 2, 1].into_iter().find(|b| w % b == 0 && h % b == 0).unwrap_or(1);
    let ref_seed = seed.wrapping_add(REFERENCE_SEED_OFFSET);
    let bar = spinner(cfg.progress, format!("reference: {integrator}, {passes} passes x {per_pass} spp"));
    let (image, meta) = make_reference(
        scene,
        file,
        estimator.as_ref(),
        integrator,
        &options,
        per_pass,
        passes,
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
    Ok((image, Origin::of_reference(&meta)))
}

/// Notes on a reference's origin against the run: another scene, an
/// estimator that misses paths, dropped samples, another depth.
fn origin_notes(
    cfg: &ConvergeConfig,
    scene: &Scene,
    file: &SceneFingerprint,
    max_depth: u32,
    m: &Origin,
) -> Vec<String> {
    let mut notes = Vec::new();
    match &m.scene_hash {
        // Another file's content: an edit (a comment, a render default)
        // may leave the image as it was, so a note, not a refusal.
        Some(hash) if *hash != file.hash => notes.push(format!(
            "the reference was rendered from {} with other contents than this run's {} (scene hash {hash}, this \
             run's {}): if the scene changed, every error is measured against another scene's image",
            m.scene, file.name, file.hash
        )),
        Some(_) => {}
        None if Path::new(&m.scene).file_name() != cfg.scene.file_name() => {
            notes.push(format!("the reference was rendered from {}, this run renders {}", m.scene, file.name));
        }
        None => {}
    }
    // A reference from an estimator that cannot sample the whole scene
    // is biased, and so is every error measured against it.
    if let Ok(estimator) = integrators::create(&m.integrator, &IntegratorOptions { max_depth, ..Default::default() }) {
        for warning in estimator.unsamplable(scene) {
            notes
                .push(format!("the reference's integrator {} cannot sample this scene fully: {warning}", m.integrator));
        }
    }
    let d = &m.dropped;
    if d.total() > 0 {
        notes.push(format!(
            "the reference's films dropped {d}: it lacks what they carried, and the errors measured against it \
             are off by that much"
        ));
    }
    match m.max_depth {
        Some(d) if d != max_depth => notes.push(format!(
            "the reference was rendered with max depth {d}, this run uses {max_depth}: they estimate different images"
        )),
        Some(_) => {}
        None => notes.push(format!(
            "the reference's sidecar does not record its max depth (it predates the field): if it is not this \
             run's {max_depth}, they estimate different images"
        )),
    }
    notes
}

/// What makes a reference unusable for the run: another image size, or
/// random streams shared with the run's.
fn check_origin(cfg: &ConvergeConfig, scene: &Scene, seed: u64, m: &Origin, path: &Path) -> Result<()> {
    let (w, h) = (scene.camera.width, scene.camera.height);
    ensure!(
        (m.width, m.height) == (w, h),
        "{} is {}x{} but the run renders {w}x{h}",
        path.display(),
        m.width,
        m.height
    );
    // The run renders samples 0..spp of seed `seed` (the sampler is keyed
    // by seed, pixel and sample index; a run to a time may reach any
    // sample): a reference shares its streams if it used that seed for
    // one of those samples. Its errors would then be too low (the line of
    // the reference's own estimator by a factor (N - n) / (N + n), the
    // others through the shared wavelengths and pixel positions), so the
    // run is refused, not noted (an audit, session 36).
    // Pass i used seed + i, wrapping (`stats::render_pass_films`).
    let passes = m.passes.unwrap_or(1) as u64;
    if seed.wrapping_sub(m.seed) < passes && m.first_sample < cfg.max_spp.unwrap_or(u32::MAX) {
        bail!(
            "{}: the reference's {passes} pass(es) used seeds {} to {} (wrapping past 2^64 - 1), which include the \
             run's seed {seed}: its samples would be correlated with the run's and every error measured too low; \
             give the run another --seed",
            path.display(),
            m.seed,
            m.seed.wrapping_add(passes - 1),
        );
    }
    Ok(())
}

/// What the run's results say of the reference.
fn reference_info(path: &Path, here: bool, origin: Option<&Origin>) -> ReferenceInfo {
    let (noise_floor, method) = origin.and_then(|m| m.noise_floor).unzip();
    ReferenceInfo {
        path: path.display().to_string(),
        rendered_here: here,
        integrator: origin.map(|m| m.integrator.clone()),
        spp: origin.map(|m| m.spp),
        passes: origin.and_then(|m| m.passes),
        seed: origin.map(|m| m.seed),
        mis: origin.map(|m| m.mis.clone()),
        max_depth: origin.and_then(|m| m.max_depth),
        wall_seconds: origin.and_then(|m| m.wall_seconds),
        noise_floor,
        noise_floor_method: method.map(str::to_string),
    }
}

/// Where a reference image came from, as its sidecar says: a `prism
/// reference` sidecar, or the sidecar of a `prism render` or `prism merge`
/// (docs/cluster.md makes long references that way), which has no block
/// errors and so no noise estimate.
struct Origin {
    scene: String,
    /// The scene file's content (`SceneFingerprint::hash`), if the sidecar has it.
    scene_hash: Option<String>,
    integrator: String,
    seed: u64,
    width: u32,
    height: u32,
    /// Total samples per pixel (over all passes).
    spp: u64,
    passes: Option<u32>,
    /// Its MIS heuristic, as its integrator records it.
    mis: String,
    /// None: not recorded (`ReferenceMeta::max_depth`).
    max_depth: Option<u32>,
    /// The first sample index it rendered (a part or a merge of parts may
    /// start later): a run of n samples shares one iff this is below n.
    first_sample: u32,
    wall_seconds: Option<f64>,
    /// The relMSE its own noise adds, and how that was estimated.
    noise_floor: Option<(f64, &'static str)>,
    /// Samples its films kept out (none recorded: none).
    dropped: DroppedSamples,
}

/// The fields of a render or merge sidecar that `Origin` needs (the rest
/// is ignored; `render_state::Identity`, which holds most of them, refuses
/// unknown fields, and a sidecar has many).
#[derive(Deserialize)]
struct RenderSidecar {
    scene: String,
    #[serde(default)]
    scene_hash: Option<String>,
    integrator: String,
    seed: u64,
    width: u32,
    height: u32,
    spp: u64,
    passes: Option<u32>,
    mis: String,
    max_depth: u32,
    sample_ranges: Vec<[u32; 2]>,
    #[serde(default)]
    dropped_samples: DroppedSamples,
    /// The per-pixel variance EXR of a `--passes` render, beside it
    /// (docs/cluster.md).
    #[serde(default)]
    variance: Option<String>,
}

impl Origin {
    fn of_reference(m: &ReferenceMeta) -> Self {
        Origin {
            scene: m.scene.clone(),
            scene_hash: m.scene_hash.clone(),
            integrator: m.integrator.clone(),
            seed: m.seed,
            width: m.width,
            height: m.height,
            spp: m.spp as u64 * m.passes as u64,
            passes: Some(m.passes),
            // (References made before it was recorded used the default.)
            mis: m.mis.clone().unwrap_or_else(|| MisHeuristic::default().name().to_string()),
            max_depth: m.max_depth,
            first_sample: 0,
            wall_seconds: Some(m.wall_seconds),
            noise_floor: Some(match m.noise_floor {
                Some(floor) => (floor, PIXEL_VARIANCES),
                None => (block_noise_floor(m.block, &m.block_mean, &m.block_stderr), "block errors"),
            }),
            dropped: m.dropped_samples,
        }
    }

    fn of_render(r: RenderSidecar) -> Self {
        Origin {
            scene: r.scene,
            scene_hash: r.scene_hash,
            integrator: r.integrator,
            seed: r.seed,
            width: r.width,
            height: r.height,
            spp: r.spp * r.passes.unwrap_or(1) as u64,
            passes: r.passes,
            mis: r.mis,
            max_depth: Some(r.max_depth),
            first_sample: r.sample_ranges.first().map_or(0, |r| r[0]),
            // (A render's sidecar times only its last process, if it was
            // resumed, and a merge's none: the reference's cost is unknown.)
            wall_seconds: None,
            // (From its variance image, if it has one: `read_any_reference`.)
            noise_floor: None,
            dropped: r.dropped_samples,
        }
    }
}

/// How a floor from the reference's per-pixel variances is reported.
const PIXEL_VARIANCES: &str = "pixel variances";

/// A reference EXR and its sidecar, of either kind (`Origin`).
fn read_any_reference(exr: &Path) -> Result<(Vec<[f32; 3]>, Origin)> {
    let json = exr.with_extension("json");
    let text = std::fs::read_to_string(&json).with_context(|| format!("cannot read {}", json.display()))?;
    let (mut origin, variance) = match serde_json::from_str::<ReferenceMeta>(&text) {
        Ok(m) => (Origin::of_reference(&m), None),
        Err(_) => {
            let r = serde_json::from_str::<RenderSidecar>(&text).with_context(|| {
                format!("{}: neither a reference sidecar nor a render or merge sidecar", json.display())
            })?;
            let variance = r.variance.clone();
            (Origin::of_render(r), variance)
        }
    };
    let (w, h, image) = read_exr(exr)?;
    ensure!((w, h) == (origin.width, origin.height), "{}: size {w}x{h} differs from its sidecar", exr.display());
    if let (Some(name), Some(k)) = (variance, origin.passes) {
        let var = exr.with_file_name(&name);
        let (vw, vh, variance) = read_exr(&var)
            .with_context(|| format!("{}: its \"variance\" names {name}, which cannot be read", json.display()))?;
        ensure!((vw, vh) == (w, h), "{}: size {vw}x{vh} differs from {}'s {w}x{h}", var.display(), exr.display());
        ensure_finite(&var, w, &variance)?;
        if let Some(i) = variance.iter().position(|p| p.iter().any(|c| *c < 0.0)) {
            let (x, y) = (i % w as usize, i / w as usize);
            bail!("{}: a variance is negative (the first at x {x}, y {y})", var.display());
        }
        origin.noise_floor = stats::reference_noise(&image, &variance, k as usize).map(|f| (f, PIXEL_VARIANCES));
    }
    Ok((image, origin))
}

/// The relMSE a reference's own noise adds to every measurement, for a
/// sidecar made before it recorded the exact value (`stats::
/// reference_noise`): the per-pixel variance of its mean is about block^2 x
/// (block standard error)^2 when neighbouring pixels are independent,
/// divided by (block mean)^2 + 0.01. It weighs every pixel of a block by
/// the block's mean, so a block mixing bright pixels with noisy dark ones
/// reads low (`the_pixel_variances_predict_the_reference_noise`).
fn block_noise_floor(block: u32, block_mean: &[[f64; 3]], block_stderr: &[[f64; 3]]) -> f64 {
    let b2 = (block * block) as f64;
    let terms = block_mean
        .iter()
        .zip(block_stderr)
        .flat_map(|(mean, se)| (0..3).map(move |c| b2 * se[c] * se[c] / (mean[c] * mean[c] + 0.01)));
    let (sum, n) = terms.fold((0.0, 0usize), |(s, n), t| (s + t, n + 1));
    if n == 0 {
        0.0
    } else {
        sum / n as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Sampler;
    use crate::stats::{pixel_mean_variance, reference_noise, rel_mse, BlockStats, Image};

    /// A reference of K = 8 passes of a checkerboard of bright pixels (10,
    /// standard deviation 1 per pass) and dark ones (0.3, deviation 0.1: a
    /// dimly lit, noisy wall beside a lamp) in red and blue, and a flat 1
    /// (deviation 0.05) in green, with Gaussian noise. Its noise floor is
    /// what it adds to the relMSE of an exact image measured against it,
    /// rel_mse(truth, reference). The estimate from each pixel's variance
    /// finds it (0.90-0.98 of it over six seeds: relMSE's denominator, the
    /// reference's own square, bends it by ~5 % at a dark pixel's 12 %
    /// relative error), and only by averaging the channels as relMSE does
    /// (green alone would read 0.06 of it, red alone 1.4x); the estimate
    /// from block errors weighs the dark pixels by their block's mean and
    /// reads it 3x low.
    #[test]
    fn the_pixel_variances_predict_the_reference_noise() {
        let (w, h, k, block) = (64u32, 64u32, 8usize, 8u32);
        let contrast = |i: u32| if (i % w + i / w) % 2 == 0 { (10.0, 1.0) } else { (0.3, 0.1) };
        let truth: Image = (0..w * h).map(|i| [contrast(i).0, 1.0, contrast(i).0]).collect();
        let deviation: Image = (0..w * h).map(|i| [contrast(i).1, 0.05, contrast(i).1]).collect();
        let mut rng = Sampler::new(7, 0, 0);
        let mut gauss = || {
            let (u1, u2) = (1.0 - rng.get1d(), rng.get1d());
            (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
        };
        let mut pass = || -> Image {
            truth.iter().zip(&deviation).map(|(t, s)| std::array::from_fn(|c| t[c] + s[c] * gauss())).collect()
        };
        let passes: Vec<Image> = (0..k).map(|_| pass()).collect();
        let (mean, variance) = pixel_mean_variance(&passes);
        let measured = rel_mse(&truth, &mean);
        let pixels = reference_noise(&mean, &variance, k).expect("a finite floor");
        let b = BlockStats::from_passes(&passes, w, h, block);
        let blocks = block_noise_floor(block, &b.mean, &b.stderr);
        assert!((0.85..1.15).contains(&(pixels / measured)), "pixel variances {pixels:.3e}, measured {measured:.3e}");
        assert!(blocks < 0.5 * measured, "block errors {blocks:.3e} found the floor {measured:.3e}");
    }
}
