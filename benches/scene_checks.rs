//! The checks a render runs on its scene before the first sample, on scenes
//! of many emitters: `Scene::emitters_on_surfaces` (the coplanar-emitter
//! warning, one BVH box query per emitting triangle) on the Cornell box with
//! an emitting icosphere and a plain one beside it, 2 x 20 x 4^s triangles.
//! Until session 31 it tested every triangle against every emitter, and
//! start-up took 3.2 s at s = 6 and 85 s at s = 7 (docs/performance-log.md).
//! Also an emitting disk cut as a fan of n triangles, each in the plane and
//! bounds of all the others: until session 44 the check tested every pair
//! of them (5.1 s at n = 16,000, 98 s at 64,000).
//!
//! `cargo bench --bench scene_checks`; criterion reports elements/s =
//! emitting triangles checked per second.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use prism::scene::parse_scene;
use serde_json::{json, Value};
use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

/// The Cornell box with two icospheres of `subdivisions`, the first emitting.
fn glowing_spheres(subdivisions: u32) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell-box.json");
    let mut scene: Value = serde_json::from_str(&std::fs::read_to_string(path).expect("scenes/cornell-box.json"))
        .expect("the Cornell box is JSON");
    let sphere = |center: [f32; 3], radius: f32| json!({"type": "sphere", "center": center, "radius": radius, "subdivisions": subdivisions});
    let objects = scene["objects"].as_array_mut().expect("objects");
    objects.push(json!({"name": "glow", "shape": sphere([278.0, 200.0, 278.0], 100.0), "material": "white", "emission": "light"}));
    objects.push(json!({"name": "ball", "shape": sphere([400.0, 100.0, 150.0], 80.0), "material": "white"}));
    scene.to_string()
}

/// The Cornell box with an emitting disk under its ceiling, cut as a fan of
/// `n` triangles.
fn glowing_fan(n: usize) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell-box.json");
    let mut scene: Value = serde_json::from_str(&std::fs::read_to_string(path).expect("scenes/cornell-box.json"))
        .expect("the Cornell box is JSON");
    let rim = |i: usize| {
        let a = std::f32::consts::TAU * i as f32 / n as f32;
        [278.0 + 100.0 * a.cos(), 500.0, 278.0 + 100.0 * a.sin()]
    };
    let positions: Vec<[f32; 3]> = std::iter::once([278.0, 500.0, 278.0]).chain((0..n).map(rim)).collect();
    let indices: Vec<[usize; 3]> = (0..n).map(|i| [0, i + 1, (i + 1) % n + 1]).collect();
    let fan = json!({"type": "mesh", "positions": positions, "indices": indices});
    let objects = scene["objects"].as_array_mut().expect("objects");
    objects.push(json!({"name": "fan", "shape": fan, "material": "white", "emission": "light"}));
    scene.to_string()
}

fn emitters_on_surfaces(c: &mut Criterion) {
    let mut g = c.benchmark_group("emitters_on_surfaces");
    g.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(4));
    for subdivisions in [5, 6] {
        let scene = parse_scene(&glowing_spheres(subdivisions), "glowing spheres", Path::new("."))
            .expect("the scene parses")
            .build();
        g.throughput(Throughput::Elements(scene.lights.len() as u64));
        g.bench_function(BenchmarkId::new("emitting_icosphere", 20 << (2 * subdivisions)), |b| {
            b.iter(|| black_box(&scene).emitters_on_surfaces())
        });
    }
    for n in [4000, 16000] {
        let scene = parse_scene(&glowing_fan(n), "glowing fan", Path::new(".")).expect("the scene parses").build();
        g.throughput(Throughput::Elements(scene.lights.len() as u64));
        g.bench_function(BenchmarkId::new("emitting_fan", n), |b| b.iter(|| black_box(&scene).emitters_on_surfaces()));
    }
    g.finish();
}

criterion_group!(benches, emitters_on_surfaces);
criterion_main!(benches);
