//! The foundation's proofs: the unidirectional path tracers agree on the
//! Cornell box, and renders are deterministic across thread counts (the
//! white furnaces of every integrator are in tests/furnace.rs). Statistics follow VALIDATION.md §1 (src/stats.rs); each
//! test carries a negative control that must be rejected.

#[path = "common/scenes.rs"]
mod scenes;

use prism::film::Film;
use prism::render::{render, RenderOptions};
use prism::stats::{compare, render_passes, BlockStats};
use scenes::{integrator, scene};

const K: u32 = 16;

/// `path` (NEE + MIS) and `simple_path` (BSDF sampling only) estimate the
/// same image of the Cornell box; a 2% bias on either side is detected.
#[test]
fn path_and_simple_path_agree_on_the_cornell_box() {
    let s = scene("cornell-box.json", 32, 32);
    let a = BlockStats::from_passes(&render_passes(&s, integrator("path").as_ref(), 64, K, 10, 0), 32, 32, 8);
    let b = BlockStats::from_passes(&render_passes(&s, integrator("simple_path").as_ref(), 512, K, 100, 0), 32, 32, 8);
    let c = compare(&a, &b);
    eprintln!("cornell path vs simple_path: {c}");
    assert!(c.passed, "{c}");
    for biased in [a.scaled(1.02), a.scaled(0.98)] {
        let c = compare(&biased, &b);
        eprintln!("negative control: {c}");
        assert!(!c.passed, "a 2% bias went undetected: {c}");
    }
}

/// Same scene, seed and spp give bit-identical images at 1 and 2 threads.
#[test]
fn renders_are_bit_identical_across_thread_counts() {
    let s = scene("cornell-box.json", 48, 40);
    for name in ["path", "simple_path"] {
        let images: Vec<Vec<[f32; 3]>> = [1, 2]
            .iter()
            .map(|&threads| {
                let mut film = Film::new(48, 40);
                render(
                    &s,
                    integrator(name).as_ref(),
                    &RenderOptions { seed: 7, threads, progress: false },
                    &mut film,
                    0..4,
                );
                film.image()
            })
            .collect();
        let same = images[0].iter().zip(&images[1]).all(|(a, b)| a.map(f32::to_bits) == b.map(f32::to_bits));
        assert!(same, "{name}: images differ between 1 and 2 threads");
    }
}
