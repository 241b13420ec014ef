//! The size of the colour rule (`stats::Verdict`, VALIDATION.md §1) for one
//! estimator on one scene: how often it fails an estimate that is right
//! (docs/validation.md, "The size of the rule, by bootstrap").
//!
//!   cargo run --release --example test_size -- SCENE INTEGRATOR SPP [--passes P] [--k K]
//!       [--mis H] [--res R] [--block B] [--family F] [--only M.. | --not M..]
//!
//! Renders P (default 1024) passes of SPP samples at R x R pixels (default
//! 32, the agreement matrix's and the stability tests') in B x B blocks
//! (default 8), takes their mean as the exact image, and draws K (default
//! 16, the suite's) of the passes with replacement, TRIALS times: each draw
//! is one test of the estimator against the exact image, as the suite makes
//! them against analytic values, and a proxy for its comparisons of two
//! estimates (which have both sides' errors). The fraction of draws that
//! fail, at the family sizes 1, 10 and F (a test's own: 10 is the agreement
//! matrix's, 4 integrators and the reference), is the rule's size for this
//! estimator, against the ~3 ALPHA / family it should not exceed. The
//! bootstrap keeps what the normal theory assumes away: skewed pass means
//! (rare bright paths) and blocks that move together (light tracing's and
//! BDPT's splats). It cannot draw a pass rarer than the P it has, so it
//! reads heavy tails low.

use clap::Parser;
use prism::integrators::{self, IntegratorOptions};
use prism::sampling::MisHeuristic;
use prism::sampling::Sampler;
use prism::scene::load_scene;
use prism::stats::{
    block_means, interior_pixels, luminance, masked, render_passes, ColourStats, Image, Verdict, ALPHA,
};
use rayon::prelude::*;
use std::path::Path;

const TRIALS: u32 = 200_000;
const CHUNK: u32 = 1000;

#[derive(Parser)]
struct Args {
    scene: String,
    integrator: String,
    spp: u32,
    /// Passes rendered: the population the draws come from.
    #[arg(long, default_value_t = 1024)]
    passes: u32,
    /// Passes per draw: the suite's K.
    #[arg(long, default_value_t = 16)]
    k: usize,
    /// MIS heuristic of bdpt: power, balance or uniform.
    #[arg(long, default_value = "power")]
    mis: MisHeuristic,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 32)]
    res: u32,
    /// Block side in pixels.
    #[arg(long, default_value_t = 8)]
    block: u32,
    /// A family size to report besides 1 and 10.
    #[arg(long)]
    family: Option<usize>,
    /// Compare only the pixels whose first hits are all on these materials
    /// (`stats::interior_pixels`, as the stability tests' regions).
    #[arg(long, num_args = 1.., conflicts_with = "not")]
    only: Vec<String>,
    /// Compare only the pixels whose first hits are all on surfaces of
    /// other materials than these.
    #[arg(long, num_args = 1..)]
    not: Vec<String>,
}

fn main() {
    let a = Args::parse();
    let (res, block) = (a.res, a.block);
    let mut b = load_scene(Path::new(&a.scene)).unwrap_or_else(|e| panic!("{e}"));
    b.set_resolution(res, res).unwrap();
    let scene_built = b.build();
    let options = IntegratorOptions { mis: a.mis, ..Default::default() };
    let estimator = integrators::create(&a.integrator, &options).unwrap();
    let mut images = render_passes(&scene_built, estimator.as_ref(), a.spp, a.passes, 1 << 40, 0);
    if !(a.only.is_empty() && a.not.is_empty()) {
        let keep = |n: &str| match a.only.is_empty() {
            true => !n.is_empty() && !a.not.iter().any(|m| m == n),
            false => a.only.iter().any(|m| m == n),
        };
        let mask = interior_pixels(&scene_built, 4, keep);
        println!("{} of {} pixels compared", mask.iter().filter(|&&m| m).count(), mask.len());
        images = masked(&images, &mask);
    }
    let exact = ColourStats::from_passes(&images, res, res, block).rgb.mean;
    println!(
        "{} {} (mis {:?}) {} spp, {res}x{res} in {block}x{block} blocks, {} passes, tests of {}:",
        a.scene, a.integrator, a.mis, a.spp, a.passes, a.k
    );
    block_correlation(&images, res, block);
    let families: Vec<usize> = [1, 10].into_iter().chain(a.family).collect();
    // Chunks of draws in parallel, each from its own stream.
    let failed = (0..TRIALS / CHUNK)
        .into_par_iter()
        .map(|chunk| {
            let mut sampler = Sampler::new(35, chunk as u64, 0);
            let mut failed = vec![[0u32; 3]; families.len()];
            for _ in 0..CHUNK {
                let draw: Vec<Image> =
                    (0..a.k).map(|_| images[(sampler.get_bits() % a.passes as u64) as usize].clone()).collect();
                let stats = ColourStats::from_passes(&draw, res, res, block);
                for (f, &family) in families.iter().enumerate() {
                    let v = Verdict::versus_values(&stats, &exact, family);
                    failed[f][0] += !v.passed() as u32;
                    failed[f][1] += (v.y.chi2_p < ALPHA / family as f64) as u32;
                    failed[f][2] += (v.y.worst_z > v.y.threshold || v.rgb.worst_z > v.rgb.threshold) as u32;
                }
            }
            failed
        })
        .reduce(
            || vec![[0; 3]; families.len()],
            |a, b| a.iter().zip(&b).map(|(a, b)| std::array::from_fn(|i| a[i] + b[i])).collect(),
        );
    for (f, family) in families.iter().enumerate() {
        let rate = |n: u32| format!("{:.1e} ({n})", n as f64 / TRIALS as f64);
        println!(
            "  family {family:>2}: Verdict fails {} of {TRIALS}; by the Y chi-square {}, by a worst z {}",
            rate(failed[f][0]),
            rate(failed[f][1]),
            rate(failed[f][2])
        );
    }
}

/// Correlation across passes of the blocks' luminance: the pairs beyond
/// 0.5, the largest |r|, and tr(R^2) / n (the chi-square's variance is
/// 2 tr(R^2) for Gaussian z, so this is the factor by which correlation
/// widens it; 1 for independent blocks), less the n (n - 1) / (P - 1)
/// that P passes give uncorrelated blocks. Blocks that do not vary (black
/// in every pass) are left out.
fn block_correlation(images: &[Image], res: u32, block: u32) {
    let n = ((res / block) * (res / block)) as usize;
    let y: Vec<Vec<f64>> =
        images.iter().map(|img| block_means(img, res, res, block).into_iter().map(luminance).collect()).collect();
    let p = y.len() as f64;
    let mean: Vec<f64> = (0..n).map(|b| y.iter().map(|v| v[b]).sum::<f64>() / p).collect();
    let cov = |a: usize, b: usize| y.iter().map(|v| (v[a] - mean[a]) * (v[b] - mean[b])).sum::<f64>() / (p - 1.0);
    let varying: Vec<usize> = (0..n).filter(|&b| cov(b, b) > 0.0).collect();
    let (mut sum_r2, mut largest) = (0.0, 0.0f64);
    for (i, &a) in varying.iter().enumerate() {
        for &b in &varying[i + 1..] {
            let r = cov(a, b) / (cov(a, a) * cov(b, b)).sqrt();
            sum_r2 += 2.0 * r * r;
            largest = largest.max(r.abs());
            if r.abs() > 0.5 {
                println!("  blocks {a} and {b} (row-major, {} per row): correlation {r:.2}", res / block);
            }
        }
    }
    let m = varying.len();
    let null = (m * m.saturating_sub(1)) as f64 / (p - 1.0);
    println!("  largest |r| {largest:.3}; tr(R^2) / n = {:.3}", 1.0 + (sum_r2 - null) / m as f64);
}
