//! BVH build time and traversal throughput (rays/s) on incoherent rays:
//! a Cornell-box-sized scene and a ~1.3M-triangle icosphere; one ray at a
//! time and eight to a packet (`closest8`), and a pixel's camera rays, the
//! coherent case packets are for.
//!
//! `cargo bench --bench bvh`; criterion reports elements/s = rays/s.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use glam::{Affine3A, Vec3A};
use prism::accel::{Accel, LANES};
use prism::geometry::Ray;
use prism::shapes::Mesh;
use rand_xoshiro::rand_core::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::hint::black_box;
use std::time::Duration;

const RAYS: usize = 1 << 16;
/// 20 * 4^8 = 1,310,720 triangles.
const BIG_SUBDIVISIONS: u32 = 8;

fn uniform(rng: &mut Xoshiro256PlusPlus) -> f32 {
    (rng.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

fn unit_vector(rng: &mut Xoshiro256PlusPlus) -> Vec3A {
    let z = 2.0 * uniform(rng) - 1.0;
    let phi = std::f32::consts::TAU * uniform(rng);
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3A::new(r * phi.cos(), r * phi.sin(), z)
}

/// Rays from uniform points in the box [lo, hi] toward uniform directions.
fn incoherent_rays(lo: Vec3A, hi: Vec3A, seed: u64) -> Vec<Ray> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    (0..RAYS)
        .map(|_| {
            let u = Vec3A::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng));
            Ray::new(lo + (hi - lo) * u, unit_vector(&mut rng))
        })
        .collect()
}

/// Cornell box proportions: a unit room (closed, so every ray from inside
/// hits), a light quad under the ceiling, two rotated boxes.
fn cornell_box() -> Vec<[Vec3A; 3]> {
    let v = Vec3A::new;
    let mut m = vec![
        Mesh::quad([v(0., 0., 0.), v(1., 0., 0.), v(1., 0., 1.), v(0., 0., 1.)]), // floor
        Mesh::quad([v(0., 1., 0.), v(0., 1., 1.), v(1., 1., 1.), v(1., 1., 0.)]), // ceiling
        Mesh::quad([v(0., 0., 1.), v(1., 0., 1.), v(1., 1., 1.), v(0., 1., 1.)]), // back
        Mesh::quad([v(0., 0., 0.), v(0., 1., 0.), v(1., 1., 0.), v(1., 0., 0.)]), // front
        Mesh::quad([v(0., 0., 0.), v(0., 0., 1.), v(0., 1., 1.), v(0., 1., 0.)]), // left
        Mesh::quad([v(1., 0., 0.), v(1., 1., 0.), v(1., 1., 1.), v(1., 0., 1.)]), // right
        Mesh::quad([v(0.4, 0.999, 0.4), v(0.4, 0.999, 0.6), v(0.6, 0.999, 0.6), v(0.6, 0.999, 0.4)]),
    ];
    let mut tall = Mesh::cuboid(v(-0.15, 0.0, -0.15), v(0.15, 0.6, 0.15));
    tall.transform(Affine3A::from_translation(glam::Vec3::new(0.33, 0.0, 0.65)) * Affine3A::from_rotation_y(0.3));
    let mut short = Mesh::cuboid(v(-0.15, 0.0, -0.15), v(0.15, 0.3, 0.15));
    short.transform(Affine3A::from_translation(glam::Vec3::new(0.67, 0.0, 0.35)) * Affine3A::from_rotation_y(-0.3));
    m.push(tall);
    m.push(short);
    m.iter().flat_map(|m| m.triangles()).collect()
}

/// Camera rays of a 128x64 image from inside the Cornell room toward its
/// back wall, eight per pixel in a row (a pixel's samples: coherent).
fn camera_rays() -> Vec<Ray> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
    let o = Vec3A::new(0.5, 0.5, 0.02);
    (0..RAYS)
        .map(|i| {
            let (px, py) = ((i / 8) % 128, (i / 8) / 128);
            let x = (px as f32 + uniform(&mut rng)) / 128.0 - 0.5;
            let y = (py as f32 + uniform(&mut rng)) / 64.0 - 0.5;
            Ray::new(o, Vec3A::new(x * 1.2, y * 0.6, 1.0).normalize())
        })
        .collect()
}

fn build(c: &mut Criterion) {
    let tris: Vec<_> = Mesh::sphere(Vec3A::ZERO, 1.0, BIG_SUBDIVISIONS, false).triangles().collect();
    let mut g = c.benchmark_group("bvh_build");
    g.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(8));
    g.throughput(Throughput::Elements(tris.len() as u64));
    g.bench_function(BenchmarkId::new("icosphere", tris.len()), |b| b.iter(|| Accel::build(black_box(&tris))));
    g.finish();
}

fn traverse(c: &mut Criterion) {
    let big: Vec<_> = Mesh::sphere(Vec3A::ZERO, 1.0, BIG_SUBDIVISIONS, false).triangles().collect();
    let scenes = [
        ("cornell", Accel::build(&cornell_box()), incoherent_rays(Vec3A::splat(0.01), Vec3A::splat(0.99), 1)),
        ("icosphere_1.3M", Accel::build(&big), incoherent_rays(Vec3A::splat(-0.5), Vec3A::splat(0.5), 2)),
    ];
    drop(big);
    let mut g = c.benchmark_group("bvh_trace");
    g.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(3));
    g.throughput(Throughput::Elements(RAYS as u64));
    for (name, accel, rays) in &scenes {
        // Every ray starts inside a closed room / sphere: all must hit.
        assert!(rays.iter().all(|r| accel.occluded(r, f32::INFINITY)), "{name}");
        g.bench_function(BenchmarkId::new("closest", name), |b| {
            b.iter(|| {
                let mut sum = 0.0f32;
                for r in black_box(rays) {
                    if let Some(h) = accel.intersect(r, f32::INFINITY) {
                        sum += h.t;
                    }
                }
                sum
            })
        });
        g.bench_function(BenchmarkId::new("closest8", name), |b| {
            b.iter(|| {
                let mut sum = 0.0f32;
                for r in black_box(rays).chunks_exact(LANES) {
                    let r: &[Ray; LANES] = r.try_into().unwrap();
                    for h in accel.intersect8(r, [f32::INFINITY; LANES], 0xff).into_iter().flatten() {
                        sum += h.t;
                    }
                }
                sum
            })
        });
        // Shadow-ray-like: half the rays end before the first surface.
        let t_max: Vec<f32> = rays
            .iter()
            .enumerate()
            .map(|(i, r)| accel.intersect(r, f32::INFINITY).unwrap().t * if i % 2 == 0 { 0.5 } else { 2.0 })
            .collect();
        g.bench_function(BenchmarkId::new("occluded", name), |b| {
            b.iter(|| black_box(rays).iter().zip(&t_max).filter(|(r, &t)| accel.occluded(r, t)).count())
        });
    }
    // A pixel's camera rays, as `path` traces them: alone, and as packets.
    let (accel, camera) = (&scenes[0].1, camera_rays());
    g.bench_function(BenchmarkId::new("closest", "cornell_camera"), |b| {
        b.iter(|| black_box(&camera).iter().filter_map(|r| accel.intersect(r, f32::INFINITY)).count())
    });
    g.bench_function(BenchmarkId::new("closest8", "cornell_camera"), |b| {
        b.iter(|| {
            let mut n = 0;
            for r in black_box(&camera).chunks_exact(LANES) {
                n += accel.intersect8(r.try_into().unwrap(), [f32::INFINITY; LANES], 0xff).iter().flatten().count();
            }
            n
        })
    });
    g.finish();
}

criterion_group!(benches, build, traverse);
criterion_main!(benches);
