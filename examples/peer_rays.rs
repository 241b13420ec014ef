//! prism's half of the ray-throughput comparison with Mitsuba 3
//! (benches/peers/run.sh, step 5; docs/performance-log.md, "Session 22").
//!
//!   cargo run --release --example peer_rays -- SCENE RAYS_OUT THREADS
//!
//! Writes 2^22 incoherent rays in SCENE (origins uniform in the middle 98 %
//! of its bounding box, directions uniform on the sphere) to RAYS_OUT as
//! little-endian f32 (ox, oy, oz, dx, dy, dz per ray), which
//! benches/peers/mitsuba_rays.py traces in Mitsuba, and times prism on the
//! same rays: the fastest of `PASSES` passes of each query, on THREADS
//! threads. Prints one JSON object, with the fraction of rays that hit and
//! the mean t of the closest hits, by which compare.py checks that both
//! renderers traced the same rays in the same triangles.

use glam::Vec3A;
use prism::geometry::Ray;
use prism::sampling::{uniform_sphere, Sampler};
use rayon::prelude::*;
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

const RAYS: usize = 1 << 22;
const PASSES: usize = 7;
/// Any fixed seed: the rays only have to be the same in both renderers,
/// which the file guarantees.
const SEED: u64 = 22;

fn incoherent_rays(lo: Vec3A, hi: Vec3A) -> Vec<Ray> {
    let mut s = Sampler::new(SEED, 0, 0);
    let (lo, extent) = (lo + 0.01 * (hi - lo), 0.98 * (hi - lo));
    (0..RAYS)
        .map(|_| {
            let o = lo + extent * Vec3A::new(s.get1d(), s.get1d(), s.get1d());
            Ray::new(o, uniform_sphere(s.get2d()))
        })
        .collect()
}

fn write_rays(path: &str, rays: &[Ray]) -> std::io::Result<()> {
    let coordinates = rays.iter().flat_map(|r| r.o.to_array().into_iter().chain(r.d.to_array()));
    std::fs::write(path, coordinates.flat_map(f32::to_le_bytes).collect::<Vec<u8>>())
}

/// The fastest of `PASSES` passes over `rays` in parallel chunks, and the
/// fraction of rays for which `query` is true.
fn fastest_pass(rays: &[Ray], query: impl Fn(&Ray) -> bool + Sync) -> (f64, f64) {
    let mut best = f64::INFINITY;
    let mut hits = 0;
    for _ in 0..PASSES {
        let start = Instant::now();
        hits = rays.par_chunks(4096).map(|c| c.iter().filter(|r| query(r)).count()).sum::<usize>();
        best = best.min(start.elapsed().as_secs_f64());
    }
    (best, hits as f64 / rays.len() as f64)
}

fn op_json(name: &str, (seconds, hit): (f64, f64)) -> String {
    format!(r#"{{"op": "{name}", "seconds": {seconds:.6}, "hit_fraction": {hit:.6}}}"#)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, scene_path, out, threads] = &args[..] else {
        return Err("usage: peer_rays SCENE RAYS_OUT THREADS".into());
    };
    let threads: usize = threads.parse()?;
    if threads == 0 {
        return Err("THREADS must be at least 1".into());
    }
    rayon::ThreadPoolBuilder::new().num_threads(threads).build_global()?;
    let scene = prism::scene::load_scene(Path::new(scene_path))?.build();
    let accel = &scene.accel;
    let (lo, hi) = accel.bounds();
    let rays = incoherent_rays(lo, hi);
    write_rays(out, &rays)?;
    // Summed in f64 in ray order: the same value at any thread count.
    let hit_ts: Vec<f64> = rays.iter().filter_map(|r| accel.intersect(r, f32::INFINITY)).map(|h| h.t as f64).collect();
    let mean_hit_t = hit_ts.iter().sum::<f64>() / hit_ts.len().max(1) as f64;
    // The queries, named as Mitsuba's counterparts, each compiled into its
    // own loop (no call through a pointer per ray). Each result goes
    // through `black_box`, so none of what a query computes is left out
    // because only whether it hit is counted.
    let ops = [
        op_json("closest", fastest_pass(&rays, |r| black_box(accel.intersect(r, f32::INFINITY)).is_some())),
        op_json("shadow", fastest_pass(&rays, |r| accel.occluded(r, f32::INFINITY))),
        op_json("surface", fastest_pass(&rays, |r| black_box(scene.intersect(r)).is_some())),
    ];
    println!(
        r#"{{"renderer": "prism", "threads": {threads}, "rays": {RAYS}, "passes": {PASSES}, "triangles": {}, "mean_hit_t": {mean_hit_t:.6}, "ops": [{}]}}"#,
        accel.len(),
        ops.join(", ")
    );
    Ok(())
}
