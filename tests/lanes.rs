//! Estimators that take a pixel's samples together (`Integrator::sample_lanes`)
//! must compute each sample exactly as `Integrator::sample` does: the render
//! driver uses the lanes whenever an estimator offers them, so this is what
//! keeps its images those of the one-sample-at-a-time estimator.

#[path = "common/scenes.rs"]
mod scenes;

use glam::UVec2;
use prism::integrators::{IntegratorOptions, INTEGRATORS};
use prism::render::Workspace;
use prism::sampling::Sampler;
use prism::scene::{load_scene, parse_scene};
use prism::spectrum::{SampledSpectrum, SampledWavelengths};
use std::path::Path;

/// The sample (seed 7, stream `pixel`, index `s`) as the driver starts it.
fn start(pixel: u64, s: u64) -> (Sampler, SampledWavelengths) {
    let mut sampler = Sampler::new(7, pixel, s);
    let lambda = SampledWavelengths::sample_visible(sampler.get1d());
    (sampler, lambda)
}

/// `path` in lanes, full and partial packets (1 to 8 samples): every lane's
/// estimate and wavelengths equal those of the same sample taken alone, bit
/// for bit, and lanes past the samples are zero. On the Cornell box, and on
/// its dispersive variant, where a lane's glass hit terminates its
/// secondary wavelengths and the packet must hand them back per lane (the
/// film converts each sample with its own). (Controls: with the camera rays
/// made in reverse lane order, every multi-sample packet differs, and this
/// test failed; with each lane tracing a copy of its wavelengths, it failed
/// on the dispersive box.)
#[test]
fn path_lanes_equal_samples_taken_alone() {
    let info = INTEGRATORS.iter().find(|i| i.name == "path").expect("path is registered");
    let path = (info.create)(&IntegratorOptions::default());
    let mut ws = Workspace::default();
    // (scene, dispersive, 1 / the least share of non-zero samples: 637
    // of the dispersive box's 1342 are, against 1069 of the plain box's)
    for (file, dispersive, share) in [("cornell-box", false, 2), ("cornell-dispersion", true, 4)] {
        let scene = load_scene(Path::new(&format!("scenes/{file}.json"))).unwrap_or_else(|e| panic!("{e}")).build();
        let (w, h) = (scene.camera.width as u64, scene.camera.height as u64);
        let (mut samples, mut nonzero, mut terminated) = (0, 0, 0);
        for k in 0..300u64 {
            let pixel = UVec2::new((k * 37 % w) as u32, (k * 101 % h) as u32);
            let n = 1 + k as usize % 8;
            let (mut samplers, mut lambdas): (Vec<_>, Vec<_>) = (0..n as u64).map(|s| start(k, s)).unzip();
            let lanes = path.sample_lanes(&scene, pixel, &mut samplers, &mut lambdas).expect("path takes lanes");
            for (s, (l, lambda)) in lanes.iter().zip(&lambdas).enumerate().take(n) {
                let (mut sampler, mut alone_lambda) = start(k, s as u64);
                let alone = path.sample(&scene, pixel, &mut sampler, &mut alone_lambda, &mut ws);
                let bits = |v: &SampledSpectrum| v.0.to_array().map(f32::to_bits);
                assert_eq!((bits(l), lambda), (bits(&alone), &alone_lambda), "{file}: pixel {pixel}, sample {s}");
                samples += 1;
                nonzero += (alone.0 != glam::Vec4::ZERO) as u32;
                terminated += alone_lambda.secondary_terminated() as u32;
            }
            assert!(lanes[n..].iter().all(|l| *l == SampledSpectrum::ZERO), "{file}: lanes past the samples");
        }
        assert!(nonzero > samples / share, "{file}: {nonzero} of {samples} samples non-zero: too few to test");
        if dispersive {
            assert!(terminated >= 20, "{file}: {terminated} of {samples} samples met the glass: too few");
        }
        eprintln!("{file}: {samples} samples, {nonzero} non-zero, {terminated} with terminated secondaries");
    }
}

/// Exact ties: two coincident quads (the same corners, in the same order),
/// one red and one green, meet every camera ray at the same distance, bit
/// for bit. The packet and the lone ray must settle the tie alike, or a
/// pixel's colour depends on whether its samples went in packets, which
/// depends on where a render's sample range starts (a part of a render, a
/// resume; from an audit, session 50: the lone ray's test took the last of
/// a block's tied triangles, the packet's the first).
#[test]
fn lanes_settle_exact_ties_as_samples_taken_alone() {
    let text = scenes::coincident_quads(16);
    let scene = parse_scene(&text, "ties.json", Path::new(".")).unwrap_or_else(|e| panic!("{e}")).build();
    let info = INTEGRATORS.iter().find(|i| i.name == "path").expect("path is registered");
    let path = (info.create)(&IntegratorOptions::default());
    let mut ws = Workspace::default();
    let bits = |v: &SampledSpectrum| v.0.to_array().map(f32::to_bits);
    let mut differ = 0;
    for y in 0..16 {
        for x in 0..16 {
            let pixel = UVec2::new(x, y);
            let k = (y * 16 + x) as u64;
            let (mut samplers, mut lambdas): (Vec<_>, Vec<_>) = (0..8).map(|s| start(k, s)).unzip();
            let lanes = path.sample_lanes(&scene, pixel, &mut samplers, &mut lambdas).expect("path takes lanes");
            for (s, l) in lanes.iter().enumerate() {
                let (mut sampler, mut lambda) = start(k, s as u64);
                let alone = path.sample(&scene, pixel, &mut sampler, &mut lambda, &mut ws);
                differ += (bits(l) != bits(&alone)) as u32;
            }
        }
    }
    assert_eq!(differ, 0, "{differ} of {} samples differ", 16 * 16 * 8);
}
