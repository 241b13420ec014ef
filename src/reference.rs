//! Stored references (VALIDATION.md §3): K independent passes of a scene
//! rendered by one integrator, kept as the mean image (EXR) plus a JSON
//! sidecar with the per-block means and standard errors the z-tests need,
//! the relMSE its own noise adds to a measurement against it (`prism
//! converge` reads it), and where the numbers came from (integrator, spp, passes, seed, commit,
//! wall time). Made by `prism reference`; read by tests/agreement.rs.

use crate::film::{DroppedSamples, Film};
use crate::integrators::{effective_mis, Integrator, IntegratorOptions};
use crate::output::{read_exr, Outputs};
use crate::render::RenderOptions;
use crate::render_state::SceneFingerprint;
use crate::scene::Scene;
use crate::stats::{luminance, pixel_mean_variance, reference_noise, render_pass_films, BlockStats, ColourStats};
use anyhow::{ensure, Context, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// The sidecar of a stored reference.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ReferenceMeta {
    pub scene: String,
    /// FNV-1a 64 of the scene file's bytes, in hex (`SceneFingerprint`); None in
    /// references made before it was recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scene_hash: Option<String>,
    pub integrator: String,
    /// The path depth it rendered with; None in references made before it
    /// was recorded: `prism reference` then used the default depth, but
    /// `prism converge` the run's, so the sidecar cannot tell which.
    #[serde(default)]
    pub max_depth: Option<u32>,
    /// BDPT's MIS heuristic (`MisHeuristic::name`; the default for an
    /// estimator that reads none); None in references made before it was
    /// recorded, all of which used the default.
    #[serde(default)]
    pub mis: Option<String>,
    pub spp: u32,
    pub passes: u32,
    pub seed: u64,
    pub width: u32,
    pub height: u32,
    pub block: u32,
    pub commit: String,
    /// `crate::build_target` of the binary that made it (absent in
    /// references made before it was recorded).
    #[serde(default)]
    pub build_target: String,
    pub wall_seconds: f64,
    pub command: String,
    /// Samples the passes' films kept out, summed (absent in references
    /// made before it was recorded, and read as none).
    #[serde(default)]
    pub dropped_samples: DroppedSamples,
    /// Per-block mean and standard error of the mean (row-major blocks).
    pub block_mean: Vec<[f64; 3]>,
    pub block_stderr: Vec<[f64; 3]>,
    /// Per-block standard error of the mean of luminance Y, which the
    /// channels' own errors do not give (they are correlated; `Verdict`).
    /// Absent in references made before it was recorded.
    #[serde(default)]
    pub block_y_stderr: Vec<f64>,
    /// The relMSE its own noise adds to a measurement against it, from
    /// each pixel's variance over the passes (`stats::reference_noise`).
    /// Absent in references made before it was recorded (`prism converge`
    /// then estimates it from the block errors).
    #[serde(default)]
    pub noise_floor: Option<f64>,
}

impl ReferenceMeta {
    /// The block statistics the tests compare with (`stats::Verdict`); Y's
    /// mean is that of the block means, Y being linear in them. Refused
    /// for a reference that dropped samples (its means leave them out, as
    /// `stats::render_passes` refuses for the estimates compared with it).
    pub fn colour_stats(&self) -> Result<ColourStats> {
        ensure!(
            self.dropped_samples.total() == 0,
            "the reference of {} dropped {}; its means leave them out",
            self.scene,
            self.dropped_samples.describe("samples")
        );
        ensure!(
            self.block_y_stderr.len() == self.block_mean.len(),
            "the reference of {} has no luminance standard errors (made before they were recorded); remake it: {}",
            self.scene,
            self.command
        );
        let rgb = BlockStats {
            blocks_x: self.width / self.block,
            blocks_y: self.height / self.block,
            block: self.block,
            k: self.passes,
            mean: self.block_mean.clone(),
            stderr: self.block_stderr.clone(),
        };
        let y = BlockStats {
            mean: rgb.mean.iter().map(|&m| [luminance(m), 0.0, 0.0]).collect(),
            stderr: self.block_y_stderr.iter().map(|&s| [s, 0.0, 0.0]).collect(),
            ..rgb.clone()
        };
        Ok(ColourStats { rgb, y })
    }
}

/// Renders `passes` passes (seeds seed, seed+1, ...) and returns the mean
/// image with its sidecar (`options`: the integrator's, for the record).
#[allow(clippy::too_many_arguments)]
pub fn make_reference(
    scene: &Scene,
    file: &SceneFingerprint,
    integrator: &dyn Integrator,
    integrator_name: &str,
    options: &IntegratorOptions,
    spp: u32,
    passes: u32,
    seed: u64,
    block: u32,
    threads: usize,
    command: String,
) -> (Vec<[f32; 3]>, ReferenceMeta) {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let start = Instant::now();
    let opts = RenderOptions { seed, threads, progress: false };
    let (films, _) = render_pass_films(scene, integrator, &opts, spp, passes);
    let wall_seconds = start.elapsed().as_secs_f64();
    let dropped_samples = films.iter().map(|f| f.dropped).sum();
    let images: Vec<_> = films.iter().map(Film::image).collect();
    let stats = ColourStats::from_passes(&images, w, h, block);
    let (mean, variance) = pixel_mean_variance(&images);
    let meta = ReferenceMeta {
        scene: file.name.clone(),
        scene_hash: Some(file.hash.clone()),
        integrator: integrator_name.to_string(),
        max_depth: Some(options.max_depth),
        mis: Some(effective_mis(integrator_name, options.mis).name().to_string()),
        spp,
        passes,
        seed,
        width: w,
        height: h,
        block,
        commit: env!("PRISM_COMMIT").to_string(),
        build_target: crate::build_target(),
        wall_seconds,
        command,
        dropped_samples,
        block_mean: stats.rgb.mean,
        block_stderr: stats.rgb.stderr,
        block_y_stderr: stats.y.stderr.iter().map(|s| s[0]).collect(),
        noise_floor: reference_noise(&mean, &variance, passes as usize),
    };
    (mean, meta)
}

/// Writes `<out>.exr` and its sidecar `<out>.json`, moved into place together.
pub fn write_reference(out: &Path, image: &[[f32; 3]], meta: &ReferenceMeta) -> Result<()> {
    let mut files = Outputs::default();
    files.exr(out, meta.width, meta.height, image)?;
    files.json(&out.with_extension("json"), meta)?;
    files.commit()
}

/// Reads a reference's sidecar (and checks its EXR matches it).
pub fn read_reference(exr: &Path) -> Result<(Vec<[f32; 3]>, ReferenceMeta)> {
    let json = exr.with_extension("json");
    let text = std::fs::read_to_string(&json).with_context(|| format!("cannot read {}", json.display()))?;
    let meta: ReferenceMeta =
        serde_json::from_str(&text).with_context(|| format!("{}: not a reference sidecar", json.display()))?;
    let (w, h, image) = read_exr(exr)?;
    ensure!((w, h) == (meta.width, meta.height), "{}: size {w}x{h} differs from its sidecar", exr.display());
    Ok((image, meta))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stored reference gives its statistics; the same one with a
    /// dropped sample is refused, naming it.
    #[test]
    fn a_reference_that_dropped_samples_is_refused() {
        let json = include_str!("../tests/references/cornell-box.json");
        let mut meta: ReferenceMeta = serde_json::from_str(json).unwrap();
        // The statistics are the file's: its blocks' means and standard
        // errors, the luminance's from its own column (a review, session
        // 55: only that they were given was checked).
        let stats = meta.colour_stats().unwrap();
        assert_eq!(
            (stats.rgb.blocks_x, stats.rgb.blocks_y, stats.rgb.k),
            (meta.width / meta.block, meta.height / meta.block, meta.passes)
        );
        assert_eq!((&stats.rgb.mean, &stats.rgb.stderr), (&meta.block_mean, &meta.block_stderr));
        let y_stderr: Vec<f64> = stats.y.stderr.iter().map(|s| s[0]).collect();
        assert_eq!(y_stderr, meta.block_y_stderr);
        let b = meta.block_mean.len() / 2;
        assert_eq!(stats.y.mean[b][0], luminance(meta.block_mean[b]));
        meta.dropped_samples.nan = 1;
        let e = meta.colour_stats().unwrap_err().to_string();
        assert!(e.contains("dropped 1 samples (1 NaN"), "{e}");
    }
}
