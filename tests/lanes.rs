//! Estimators that take a pixel's samples together (`Integrator::sample_lanes`)
//! must compute each sample exactly as `Integrator::sample` does: the render
//! driver uses the lanes whenever an estimator offers them, so this is what
//! keeps its images those of the one-sample-at-a-time estimator.

use glam::UVec2;
use prism::integrators::{IntegratorOptions, INTEGRATORS};
use prism::render::Workspace;
use prism::sampling::Sampler;
use prism::scene::load_scene;
use prism::spectrum::{SampledSpectrum, SampledWavelengths};
use std::path::Path;

/// The sample (seed 7, stream `pixel`, index `s`) as the driver starts it.
fn start(pixel: u64, s: u64) -> (Sampler, SampledWavelengths) {
    let mut sampler = Sampler::new(7, pixel, s);
    let lambda = SampledWavelengths::sample_visible(sampler.get1d());
    (sampler, lambda)
}

/// `path` in lanes, full and partial packets (1 to 8 samples), on the
/// Cornell box: every lane's estimate and wavelengths equal those of the
/// same sample taken alone, bit for bit, and lanes past the samples are
/// zero. (Control: with the camera rays made in reverse lane order, every
/// multi-sample packet differs, and this test failed.)
#[test]
fn path_lanes_equal_samples_taken_alone() {
    let scene = load_scene(Path::new("scenes/cornell-box.json")).unwrap_or_else(|e| panic!("{e}")).build();
    let info = INTEGRATORS.iter().find(|i| i.name == "path").expect("path is registered");
    let path = (info.create)(&IntegratorOptions::default());
    let mut ws = Workspace::default();
    let (mut samples, mut nonzero) = (0, 0);
    for k in 0..300u64 {
        let pixel = UVec2::new((k * 37 % 256) as u32, (k * 101 % 256) as u32);
        let n = 1 + k as usize % 8;
        let (mut samplers, mut lambdas): (Vec<_>, Vec<_>) = (0..n as u64).map(|s| start(k, s)).unzip();
        let lanes = path.sample_lanes(&scene, pixel, &mut samplers, &mut lambdas).expect("path takes lanes");
        for (s, (l, lambda)) in lanes.iter().zip(&lambdas).enumerate().take(n) {
            let (mut sampler, mut alone_lambda) = start(k, s as u64);
            let alone = path.sample(&scene, pixel, &mut sampler, &mut alone_lambda, &mut ws);
            let bits = |v: &SampledSpectrum| v.0.to_array().map(f32::to_bits);
            assert_eq!((bits(l), lambda), (bits(&alone), &alone_lambda), "pixel {pixel}, sample {s}");
            samples += 1;
            nonzero += (alone.0 != glam::Vec4::ZERO) as u32;
        }
        assert!(lanes[n..].iter().all(|l| *l == SampledSpectrum::ZERO), "lanes past the samples");
    }
    assert!(nonzero > samples / 2, "{nonzero} of {samples} samples non-zero: too few to test");
}
