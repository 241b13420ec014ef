// Scratch program of session 23 (docs/performance-log.md, "Session 23"), kept as a record, not built: a
// binary of the same Cargo project as prism_render_rays.rs; arguments: the ray log, the kind, the passes.
// One query kind in a loop, for perf annotate: one.rs FILE KIND(0 bounce, 1 shadow, 2 camera) REPS
use glam::Vec3A;
use prism::accel::{Accel, TriangleHit};
use prism::geometry::Ray;
use std::hint::black_box;

#[inline(never)]
fn closest(accel: &Accel, r: &Ray) -> Option<TriangleHit> {
    accel.intersect(r, f32::INFINITY)
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let scene = prism::scene::load_scene(std::path::Path::new("/work/main/scenes/cornell-box.json")).unwrap().build();
    let bytes = std::fs::read(&a[1]).unwrap();
    let kind: f32 = a[2].parse().unwrap();
    let reps: usize = a[3].parse().unwrap();
    let f: Vec<f32> = bytes.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
    let rays: Vec<(Ray, f32)> = f.chunks_exact(10).filter(|r| r[0] == kind).map(|r| (Ray { o: Vec3A::new(r[1], r[2], r[3]), d: Vec3A::new(r[4], r[5], r[6]), skip: [r[8].to_bits(), r[9].to_bits()] }, r[7])).collect();
    let t = std::time::Instant::now();
    let mut n = 0;
    for _ in 0..reps {
        for (r, tm) in &rays {
            n += if kind == 1.0 { black_box(scene.accel.occluded(r, *tm)) as usize } else { black_box(closest(&scene.accel, r)).is_some() as usize };
        }
    }
    let dt = t.elapsed().as_secs_f64();
    println!("{} rays x {reps}: {:.1} ns/ray ({n} hits)", rays.len(), dt / (rays.len() * reps) as f64 * 1e9);
}
