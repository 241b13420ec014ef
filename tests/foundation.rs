//! The foundation's proofs: the unidirectional path tracers agree on the
//! Cornell box, and renders are deterministic across thread counts (the
//! white furnaces of every integrator are in tests/furnace.rs). Statistics follow VALIDATION.md §1 (src/stats.rs); each
//! test carries a negative control that must be rejected.

#[path = "common/scenes.rs"]
mod scenes;

use glam::UVec2;
use prism::film::Film;
use prism::integrators::Integrator;
use prism::render::{render, RenderOptions, Workspace};
use prism::sampling::Sampler;
use prism::scene::Scene;
use prism::spectrum::{SampledSpectrum, SampledWavelengths};
use prism::stats::{render_passes, ColourStats, Verdict};
use scenes::{integrator, scene, seed};

const K: u32 = 16;

/// `path` (NEE + MIS) and `simple_path` (BSDF sampling only) estimate the
/// same image of the Cornell box; a 2% bias on either side is detected.
#[test]
fn path_and_simple_path_agree_on_the_cornell_box() {
    let s = scene("cornell-box.json", 32, 32);
    let a = ColourStats::from_passes(&render_passes(&s, integrator("path").as_ref(), 256, K, seed(10), 0), 32, 32, 8);
    let b = ColourStats::from_passes(
        &render_passes(&s, integrator("simple_path").as_ref(), 2048, K, seed(100), 0),
        32,
        32,
        8,
    );
    let c = Verdict::versus(&a, &b, 1);
    eprintln!("cornell path vs simple_path: {c}");
    assert!(c.passed(), "{c}");
    for biased in [a.scaled(1.02), a.scaled(0.98)] {
        let c = Verdict::versus(&biased, &b, 1);
        eprintln!("negative control: {c}");
        assert!(!c.passed(), "a 2% bias went undetected: {c}");
    }
}

/// Same scene, seed and spp give bit-identical images at 1, 2 and 3
/// threads. 72 tiles, more than the driver keeps in flight (its `WINDOW`),
/// so workers wait for the in-order merge; light tracing adds splats to
/// other tiles' pixels.
#[test]
fn renders_are_bit_identical_across_thread_counts() {
    let (w, h) = (144, 128);
    let s = scene("cornell-box.json", w, h);
    for name in ["path", "simple_path", "light"] {
        let images: Vec<Vec<[f32; 3]>> = [1, 2, 3]
            .iter()
            .map(|&threads| {
                let mut film = Film::new(w, h);
                render(
                    &s,
                    integrator(name).as_ref(),
                    &RenderOptions { seed: 7, threads, progress: false },
                    &mut film,
                    0..2,
                );
                film.image()
            })
            .collect();
        for (i, image) in images.iter().enumerate().skip(1) {
            let same = images[0].iter().zip(image).all(|(a, b)| a.map(f32::to_bits) == b.map(f32::to_bits));
            assert!(same, "{name}: images differ between 1 and {} threads", i + 1);
        }
    }
}

/// Sample ranges rendered one after another into one film give the bits
/// of one render of them all (the film's sums are exact). 35 tiles of 16 x
/// 16, 4 spp in one call or three: light tracing's and BDPT's splats are
/// held back and added to the film in batches of about as many as the
/// image has pixels, so every call ends with some held back, which must
/// still reach the film.
#[test]
fn sample_ranges_add_up_to_one_render() {
    let (w, h) = (112, 80);
    let s = scene("cornell-box.json", w, h);
    let opts = RenderOptions { seed: 5, threads: 2, progress: false };
    for name in ["light", "bdpt"] {
        let it = integrator(name);
        let film_of = |ranges: &[(u32, u32)]| {
            let mut film = Film::new(w, h);
            for &(start, end) in ranges {
                render(&s, it.as_ref(), &opts, &mut film, start..end);
            }
            film
        };
        let (whole, parts) = (film_of(&[(0, 4)]), film_of(&[(0, 1), (1, 3), (3, 4)]));
        assert_eq!(parts.spp, 4);
        assert!(whole.sums == parts.sums, "{name}: three sample ranges differ from one render of them");
    }
}

/// An image of one tile is cut into runs of sample indices so that every
/// thread has work (render.rs `Tasks`); the cut must not change the image.
/// A 16 x 16 image, 64 spp in one call at 1 and 2 threads, against 64
/// one-sample calls (a call of one sample is not cut).
#[test]
fn a_one_tile_image_cut_into_runs_is_the_same_image() {
    let (w, h) = (16, 16);
    let s = scene("cornell-box.json", w, h);
    for name in ["path", "light", "bdpt"] {
        let it = integrator(name);
        let film_of = |threads: usize, ranges: &mut dyn Iterator<Item = std::ops::Range<u32>>| {
            let mut film = Film::new(w, h);
            for r in ranges {
                render(&s, it.as_ref(), &RenderOptions { seed: 11, threads, progress: false }, &mut film, r);
            }
            film
        };
        let reference = film_of(1, &mut (0..64).map(|i| i..i + 1));
        for threads in [1, 2] {
            let cut = film_of(threads, &mut std::iter::once(0..64));
            assert!(cut.sums == reference.sums, "{name}, {threads} threads: the cut changed the image");
            assert_eq!(cut.spp, reference.spp, "{name}, {threads} threads: the cut changed the sample count");
        }
    }
}

/// The last sample indices a u32 holds render like any others: every one
/// of the top 7, alone, puts light on the Cornell box's film, and one call
/// of all 7 is their sum (a packet's end once wrapped past u32::MAX, so a
/// packet at the top rendered nothing while the film counted its samples).
#[test]
fn the_top_sample_indices_render() {
    let (w, h) = (16, 16);
    let s = scene("cornell-box.json", w, h);
    let opts = RenderOptions { seed: 3, threads: 1, progress: false };
    let top = u32::MAX - 7..u32::MAX;
    for name in ["path", "light"] {
        let it = integrator(name);
        let mut alone = Film::new(w, h);
        for i in top.clone() {
            let mut film = Film::new(w, h);
            render(&s, it.as_ref(), &opts, &mut film, i..i + 1);
            assert!(film.sums.iter().any(|p| p.iter().any(|&c| c > 0)), "{name}: sample {i} is black");
            alone.add(&film).unwrap();
        }
        let mut together = Film::new(w, h);
        render(&s, it.as_ref(), &opts, &mut together, top.clone());
        assert_eq!(together.spp, 7);
        assert!(together.sums == alone.sums, "{name}: samples {top:?} in one call differ from one by one");
    }
}

/// What an estimator has planted at one pixel (its samples are 1 elsewhere).
enum Plant {
    Panic,
    Value(f32),
}

struct PlantedAt(UVec2, Plant);

impl Integrator for PlantedAt {
    fn sample(
        &self,
        _: &Scene,
        pixel: UVec2,
        _: &mut Sampler,
        _: &mut SampledWavelengths,
        _: &mut Workspace,
    ) -> SampledSpectrum {
        match self.1 {
            _ if pixel != self.0 => SampledSpectrum::ONE,
            Plant::Panic => panic!("planted panic"),
            Plant::Value(v) => SampledSpectrum::splat(v),
        }
    }
}

/// The statistical tests' passes refuse a dropped sample (the film leaves
/// it out, which biases the image by less than their controls can see);
/// the control, a pixel of 0, renders.
#[test]
fn statistics_refuse_passes_that_dropped_samples() {
    let s = scene("cornell-box.json", 8, 8);
    let pixel = UVec2::new(5, 2);
    for value in [f32::NAN, f32::INFINITY, -1.0] {
        let result = std::panic::catch_unwind(|| render_passes(&s, &PlantedAt(pixel, Plant::Value(value)), 1, 2, 7, 1));
        assert!(result.is_err(), "a sample of {value} went unreported");
    }
    let images = render_passes(&s, &PlantedAt(pixel, Plant::Value(0.0)), 1, 2, 7, 1);
    assert_eq!(images[1][(2 * 8 + 5) as usize], [0.0; 3]);
}

/// A sample that panics on one pixel: the render must re-raise the panic,
/// not wait forever for the lost tile's merge.
#[test]
fn a_panicking_sample_stops_the_render() {
    let (w, h) = (160, 160);
    let s = scene("cornell-box.json", w, h);
    // In the first tile (the others wait for its merge), and in the last.
    for pixel in [UVec2::new(3, 5), UVec2::new(w - 1, h - 1)] {
        let result = std::panic::catch_unwind(|| {
            let mut film = Film::new(w, h);
            let opts = RenderOptions { seed: 1, threads: 2, progress: false };
            render(&s, &PlantedAt(pixel, Plant::Panic), &opts, &mut film, 0..64);
        });
        assert!(result.is_err(), "no panic for {pixel}");
    }
}
