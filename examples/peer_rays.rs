//! prism's half of the ray-throughput comparison with Mitsuba 3
//! (benches/peers/run.sh, step 6; docs/performance.md, "Session 22").
//!
//!   cargo run --release --example peer_rays -- SCENE RAYS_OUT THREADS
//!
//! Writes 2^22 incoherent rays in SCENE (origins uniform in the middle 98 %
//! of its bounding box, directions uniform on the sphere) to RAYS_OUT as
//! little-endian f32 (ox, oy, oz, dx, dy, dz per ray), which
//! benches/peers/mitsuba_rays.py traces in Mitsuba, and times prism on the
//! same rays: the fastest of 7 passes of each query, on THREADS threads.
//! Prints one JSON object.

use glam::Vec3A;
use prism::geometry::Ray;
use prism::sampling::{uniform_sphere, Sampler};
use rayon::prelude::*;
use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

const RAYS: usize = 1 << 22;
const PASSES: usize = 7;

fn rays(lo: Vec3A, hi: Vec3A) -> Vec<Ray> {
    let mut s = Sampler::new(22, 0, 0);
    let (lo, extent) = (lo + 0.01 * (hi - lo), 0.98 * (hi - lo));
    (0..RAYS)
        .map(|_| {
            let o = lo + extent * Vec3A::new(s.get1d(), s.get1d(), s.get1d());
            Ray::new(o, uniform_sphere(s.get2d()))
        })
        .collect()
}

/// The fastest of `PASSES` passes over `rays` in parallel chunks, and the
/// fraction of rays for which `query` is true.
fn time(rays: &[Ray], query: impl Fn(&Ray) -> bool + Sync) -> (f64, f64) {
    let mut best = f64::INFINITY;
    let mut hits = 0;
    for _ in 0..PASSES {
        let start = Instant::now();
        hits = rays.par_chunks(4096).map(|c| c.iter().filter(|r| query(r)).count()).sum::<usize>();
        best = best.min(start.elapsed().as_secs_f64());
    }
    (best, hits as f64 / rays.len() as f64)
}

fn op(name: &str, (seconds, hit): (f64, f64)) -> String {
    format!(r#"{{"op": "{name}", "seconds": {seconds:.6}, "hit_fraction": {hit:.6}}}"#)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, scene_path, out, threads] = &args[..] else {
        return Err("usage: peer_rays SCENE RAYS_OUT THREADS".into());
    };
    let threads: usize = threads.parse()?;
    rayon::ThreadPoolBuilder::new().num_threads(threads).build_global()?;
    let scene = prism::scene::load_scene(Path::new(scene_path))?.build();
    let (lo, hi) = scene.accel.bounds();
    let rays = rays(lo, hi);
    let bytes: Vec<u8> =
        rays.iter().flat_map(|r| r.o.to_array().into_iter().chain(r.d.to_array())).flat_map(f32::to_le_bytes).collect();
    std::fs::write(out, bytes)?;
    // The queries, named as Mitsuba's counterparts, each compiled into its
    // own loop (no call through a pointer per ray). Each result goes
    // through `black_box`, so none of what a query computes is left out
    // because only whether it hit is counted.
    let accel = &scene.accel;
    let ops = [
        op("closest", time(&rays, |r| black_box(accel.intersect(r, f32::INFINITY)).is_some())),
        op("shadow", time(&rays, |r| accel.occluded(r, f32::INFINITY))),
        op("surface", time(&rays, |r| black_box(scene.intersect(r)).is_some())),
    ];
    println!(
        r#"{{"renderer": "prism", "threads": {threads}, "rays": {RAYS}, "triangles": {}, "ops": [{}]}}"#,
        accel.len(),
        ops.join(", ")
    );
    Ok(())
}
