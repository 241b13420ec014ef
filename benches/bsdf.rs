//! BSDF throughput: `eval` and `sample` per BSDF, ns per call with four
//! wavelengths (`cargo bench --bench bsdf`). Inputs are built outside the
//! timed loop and cycled through (1024 random wo, wi, u), every argument and
//! result through `black_box`.

use criterion::{criterion_group, criterion_main, Criterion};
use glam::{Vec2, Vec3A};
use prism::materials::{Bsdf, Conductor, Dielectric, Diffuse, TransportMode};
use prism::sampling::{cosine_hemisphere, uniform_sphere, Sampler};
use prism::spectrum::{SampledWavelengths, Spectrum};
use std::hint::black_box;
use std::time::Duration;

const N: usize = 1024;

struct Inputs {
    wo: Vec<Vec3A>,
    wi: Vec<Vec3A>,
    uc: Vec<f32>,
    u2: Vec<Vec2>,
}

fn inputs() -> Inputs {
    let mut s = Sampler::new(1, 2, 3);
    Inputs {
        wo: (0..N).map(|_| cosine_hemisphere(s.get2d())).collect(),
        wi: (0..N).map(|_| uniform_sphere(s.get2d())).collect(),
        uc: (0..N).map(|_| s.get1d()).collect(),
        u2: (0..N).map(|_| s.get2d()).collect(),
    }
}

fn bsdfs() -> Vec<(&'static str, Bsdf)> {
    // A measured-looking (dense) spectrum, as a named metal would give.
    let eta = Spectrum::piecewise_linear(&[(400.0, 1.5), (550.0, 0.4), (700.0, 0.15)]);
    let k = Spectrum::piecewise_linear(&[(400.0, 1.9), (550.0, 2.3), (700.0, 4.0)]);
    vec![
        ("diffuse", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(0.5)))),
        ("rough_conductor", Bsdf::Conductor(Conductor::new(eta.clone(), k.clone(), 0.2, 0.2))),
        ("smooth_conductor", Bsdf::Conductor(Conductor::new(eta, k, 0.0, 0.0))),
        // The same with constant eta, k: the difference is the dense-spectrum lookups.
        (
            "smooth_conductor_constant",
            Bsdf::Conductor(Conductor::new(Spectrum::Constant(0.2), Spectrum::Constant(3.9), 0.0, 0.0)),
        ),
        ("smooth_dielectric", Bsdf::Dielectric(Dielectric::new(Spectrum::Constant(1.5), 0.0, 0.0))),
        ("rough_dielectric", Bsdf::Dielectric(Dielectric::new(Spectrum::Constant(1.5), 0.2, 0.2))),
    ]
}

fn bench(c: &mut Criterion) {
    let x = inputs();
    let lambda = SampledWavelengths::sample_visible(0.37);
    let mode = TransportMode::Radiance;
    for (name, bsdf) in bsdfs() {
        let mut g = c.benchmark_group(name);
        g.bench_function("eval", |b| {
            let mut i = 0;
            b.iter(|| {
                i = (i + 1) % N;
                black_box(bsdf.eval(black_box(x.wo[i]), black_box(x.wi[i]), &lambda, mode))
            })
        });
        g.bench_function("sample", |b| {
            let mut i = 0;
            b.iter(|| {
                i = (i + 1) % N;
                black_box(bsdf.sample(black_box(x.wo[i]), black_box(x.uc[i]), black_box(x.u2[i]), &lambda, mode))
            })
        });
        g.finish();
    }
}

fn config() -> Criterion {
    Criterion::default()
        .sample_size(20)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1))
}

criterion_group! { name = benches; config = config(); targets = bench }
criterion_main!(benches);
