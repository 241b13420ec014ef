//! Throughput of every registered integrator: samples per second on the
//! Cornell box at 64x64, one sample per pixel per iteration, through the
//! same driver as `prism render` (src/render.rs), on one worker thread so
//! the number is per core and does not depend on what else the machine runs
//! in parallel. Light tracing's "sample" is one light path (see its file).
//!
//! `cargo bench --bench integrators`; criterion reports elements/s = samples/s.
//! Each iteration renders the next sample index, so no two iterations repeat
//! the same paths.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use prism::film::Film;
use prism::integrators::{self, IntegratorOptions, INTEGRATORS};
use prism::render::{render, RenderOptions};
use prism::scene::load_scene;
use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

const RES: u32 = 64;

fn integrators(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/cornell-box.json");
    let mut builder = load_scene(&path).expect("scenes/cornell-box.json");
    builder.set_resolution(RES, RES).unwrap();
    let scene = builder.build();
    let opts = RenderOptions { seed: 7, threads: 1, progress: false };
    let mut group = c.benchmark_group("cornell-box-64x64-1spp");
    group.throughput(Throughput::Elements((RES * RES) as u64));
    group.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(4));
    for info in INTEGRATORS {
        let integrator = integrators::create(info.name, &IntegratorOptions::default()).expect("registered");
        let mut film = Film::new(RES, RES);
        let mut index = 0u32;
        group.bench_function(BenchmarkId::from_parameter(info.name), |b| {
            b.iter(|| {
                let stats = render(black_box(&scene), integrator.as_ref(), &opts, &mut film, index..index + 1);
                index = index.wrapping_add(1);
                black_box(stats.rays)
            })
        });
        black_box(film.image());
    }
    group.finish();
}

criterion_group!(benches, integrators);
criterion_main!(benches);
