//! The checks a render runs on its scene before the first sample, on scenes
//! of many emitters: `Scene::emitters_on_surfaces` (the coplanar-emitter
//! warning, one BVH box query per emitting triangle) on the Cornell box with
//! an emitting icosphere and a plain one beside it, 2 x 20 x 4^s triangles.
//! Until session 31 it tested every triangle against every emitter, and
//! start-up took 3.2 s at s = 6 and 85 s at s = 7 (docs/performance-log.md).
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
    g.finish();
}

criterion_group!(benches, emitters_on_surfaces);
criterion_main!(benches);
