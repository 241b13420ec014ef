//! Chi-square goodness of fit of every non-delta BSDF's `sample` against its
//! own `pdf` (VALIDATION.md §4), over a grid of parameters and outgoing
//! directions (both sides of the surface, grazing), at significance 0.01
//! Sidak-corrected over all of them; plus negative controls (a pdf off by 5%
//! in one lobe, a pdf of the wrong shape) that the same routine must reject.
//!
//! Lobes too narrow for the equal-area grid (reflection with alpha < 0.075,
//! transmission close to eta = 1) are histogrammed on a grid refined around
//! the lobe's axis (`SphereGrid::for_lobe`); a dielectric with two narrow
//! lobes gets one test per lobe (separate samples, both counted in the Sidak
//! correction). Run with `--nocapture` for the p-value table.

mod common;

use common::chi2::{chi2_test, sidak, Chi2Outcome, SphereGrid};
use common::{conductor, dielectric, diffuse, dir, lambda, seed};
use glam::Vec3A;
use prism::materials::fresnel::refract;
use prism::materials::{Bsdf, TransportMode, TrowbridgeReitz};
use std::time::Instant;

const N_SAMPLES: usize = 1_000_000;
/// pbrt-v4's resolution (80 x 160 cells): ~80 samples per cell on average.
const N_T: usize = 80;
const N_PHI: usize = 160;
/// Family-wise significance (VALIDATION.md §4).
const SIGNIFICANCE: f64 = 0.01;
/// A lobe narrower than this (radians) gets a refined grid.
const NARROW: f64 = 0.15;

struct Case {
    name: String,
    bsdf: Bsdf,
    wo: Vec3A,
    grid: SphereGrid,
}

fn mirror_dir(wo: Vec3A) -> Vec3A {
    Vec3A::new(-wo.x, -wo.y, wo.z)
}

/// Angular radius (roughly) of the reflection lobe: about 2 alpha.
fn reflection_width(alpha_min: f32) -> f64 {
    2.0 * alpha_min as f64
}

/// One case per grid that the lobes need (see the module doc): the
/// equal-area grid when no lobe is narrow, else one grid refined around each
/// narrow lobe's axis (named after the lobe, with its exponent k).
fn cases_for(name: &str, bsdf: Bsdf, wo: Vec3A, lobes: &[(&str, Vec3A, f64)]) -> Vec<Case> {
    let narrow: Vec<_> = lobes.iter().filter(|(_, _, w)| *w < NARROW).collect();
    if narrow.is_empty() {
        let grid = SphereGrid::equal_area(N_T, N_PHI);
        return vec![Case { name: name.to_string(), bsdf, wo, grid }];
    }
    narrow
        .iter()
        .map(|(lobe, axis, width)| {
            let grid = SphereGrid::for_lobe(*axis, *width, N_T, N_PHI);
            Case { name: format!("{name} [{lobe} k={:.1}]", grid.k), bsdf: bsdf.clone(), wo, grid }
        })
        .collect()
}

fn diffuse_cases() -> Vec<Case> {
    [(0.8, 0.3), (-0.5, 1.0), (0.03, 2.0)]
        .iter()
        .flat_map(|&(c, p)| cases_for(&format!("diffuse wo.z={c}"), diffuse(0.7), dir(c, p), &[]))
        .collect()
}

const CONDUCTOR_ALPHAS: [(f32, f32); 7] =
    [(0.01, 0.01), (0.05, 0.05), (0.2, 0.2), (0.5, 0.5), (1.0, 1.0), (0.3, 0.1), (0.02, 0.5)];
const CONDUCTOR_WO: [(f32, f32); 4] = [(0.95, 0.2), (0.5, 1.1), (0.05, 2.2), (-0.7, -0.5)];

fn conductor_cases() -> Vec<Case> {
    let mut v = Vec::new();
    for &(ax, ay) in &CONDUCTOR_ALPHAS {
        for &(c, p) in &CONDUCTOR_WO {
            let wo = dir(c, p);
            let name = format!("conductor a=({ax},{ay}) wo.z={c}");
            let lobes = [("R", mirror_dir(wo), reflection_width(ax.min(ay)))];
            v.extend(cases_for(&name, conductor(ax, ay), wo, &lobes));
        }
    }
    v
}

const DIELECTRIC_ETAS: [f32; 4] = [1.01, 1.5, 3.0, 1.0 / 1.5];
const DIELECTRIC_ALPHAS: [(f32, f32); 4] = [(0.05, 0.05), (0.3, 0.3), (0.8, 0.8), (0.3, 0.1)];
const DIELECTRIC_WO: [(f32, f32); 4] = [(0.8, 0.4), (-0.6, 2.0), (0.05, -1.0), (-0.1, 3.0)];

/// The dielectric cases for one outgoing direction `DIELECTRIC_WO[which]`.
fn dielectric_cases(which: usize) -> Vec<Case> {
    let mut v = Vec::new();
    for &eta in &DIELECTRIC_ETAS {
        for &(ax, ay) in &DIELECTRIC_ALPHAS {
            for &(c, p) in &DIELECTRIC_WO[which..=which] {
                let wo = dir(c, p);
                let name = format!("dielectric eta={eta:.3} a=({ax},{ay}) wo.z={c}");
                let a = ax.min(ay) as f64;
                let mut lobes = vec![("R", mirror_dir(wo), reflection_width(ax.min(ay)))];
                // Transmission spreads by about (1 - 1/eta') per unit of
                // microfacet tilt (Snell's law linearised at the macro normal).
                if let Some((wt, etap)) = refract(wo, Vec3A::Z, eta) {
                    lobes.push(("T", wt, 2.0 * a * (1.0 - 1.0 / etap as f64).abs()));
                }
                v.extend(cases_for(&name, dielectric(eta, ax, ay), wo, &lobes));
            }
        }
    }
    v
}

/// Every positive case: the Sidak correction is over all of them.
fn all_cases() -> Vec<Case> {
    let mut v = diffuse_cases();
    v.extend(conductor_cases());
    for which in 0..DIELECTRIC_WO.len() {
        v.extend(dielectric_cases(which));
    }
    v
}

fn corrected_alpha() -> f64 {
    sidak(SIGNIFICANCE, all_cases().len())
}

/// The same seed for every case would correlate their samples; mix in the name.
fn case_seed(name: &str) -> u64 {
    name.bytes().fold(seed(), |h, b| prism::sampling::mix64(h ^ b as u64))
}

fn run_with_pdf(case: &Case, pdf: &dyn Fn(Vec3A) -> f64) -> Chi2Outcome {
    let l = lambda();
    let sample = |uc, u2| {
        let s = case.bsdf.sample(case.wo, uc, u2, &l, TransportMode::Radiance)?;
        (!s.is_specular()).then_some(s.wi)
    };
    chi2_test(sample, pdf, &case.grid, N_SAMPLES, case_seed(&case.name))
}

fn run(case: &Case) -> Chi2Outcome {
    let l = lambda();
    run_with_pdf(case, &|wi| case.bsdf.pdf(case.wo, wi, &l, TransportMode::Radiance) as f64)
}

fn report(name: &str, o: &Chi2Outcome, secs: f64, alpha: f64) -> bool {
    let rejected = o.rejected(alpha);
    println!(
        "{:<58} p={:<10.4e} chi2={:<9.1} dof={:<6} p_total={:<10.4e} sampled={:.4} pdf_int={:.4} {:.2}s {}",
        name,
        o.p_value,
        o.chi2,
        o.dof,
        o.p_total,
        o.sampled as f64 / N_SAMPLES as f64,
        o.pdf_integral,
        secs,
        if rejected { "REJECTED" } else { "ok" }
    );
    if rejected {
        if let Some(e) = &o.error {
            println!("    error: {e}");
        }
        for (obs, exp, w) in &o.worst {
            println!("    obs {obs:>9.0} exp {exp:>11.2} at {w:?}");
        }
    }
    rejected
}

fn run_family(cases: Vec<Case>) {
    let alpha = corrected_alpha();
    println!("Sidak-corrected significance {alpha:.3e} over {} tests", all_cases().len());
    let failed: Vec<String> = cases
        .iter()
        .filter_map(|case| {
            let t = Instant::now();
            let o = run(case);
            report(&case.name, &o, t.elapsed().as_secs_f64(), alpha).then(|| case.name.clone())
        })
        .collect();
    assert!(failed.is_empty(), "chi-square rejected: {failed:#?}");
}

#[test]
fn chi2_diffuse_and_conductor() {
    let mut cases = diffuse_cases();
    cases.extend(conductor_cases());
    run_family(cases);
}

#[test]
fn chi2_dielectric_wo_outside() {
    run_family(dielectric_cases(0));
}

#[test]
fn chi2_dielectric_wo_inside() {
    run_family(dielectric_cases(1));
}

#[test]
fn chi2_dielectric_wo_grazing_outside() {
    run_family(dielectric_cases(2));
}

#[test]
fn chi2_dielectric_wo_grazing_inside() {
    run_family(dielectric_cases(3));
}

/// The same routine at the same corrected significance must reject a pdf that
/// is 5% off in one lobe, pdfs of a slightly wrong shape, a pdf of 0
/// where the sampler goes, and a sampler that loses 1% of its samples.
#[test]
fn chi2_negative_controls() {
    let alpha = corrected_alpha();
    let l = lambda();
    let glass = cases_for("glass", dielectric(1.5, 0.3, 0.3), dir(0.8, 0.4), &[]).remove(0);
    let in_transmission = |wi: Vec3A| wi.z * glass.wo.z < 0.0;
    let pdf = |wi: Vec3A| glass.bsdf.pdf(glass.wo, wi, &l, TransportMode::Radiance) as f64;
    let mut rows: Vec<(String, Chi2Outcome)> = Vec::new();
    for scale in [1.05, 0.95] {
        let wrong = |wi: Vec3A| pdf(wi) * if in_transmission(wi) { scale } else { 1.0 };
        rows.push((format!("NEG glass a=0.3 transmission pdf x{scale}"), run_with_pdf(&glass, &wrong)));
    }
    let metal = cases_for("metal", conductor(0.3, 0.3), dir(0.6, 0.7), &[]).remove(0);
    // The sampler uses alpha = 0.3, the pdf claims 0.315.
    let d = TrowbridgeReitz::new(0.315, 0.315);
    let wrong = |wi: Vec3A| {
        let wm = (metal.wo + wi).normalize();
        if wi.z <= 0.0 || wm.z <= 0.0 {
            0.0
        } else {
            d.pdf_reflected(metal.wo, wm) as f64
        }
    };
    rows.push(("NEG conductor a=0.3 pdf of a=0.315".into(), run_with_pdf(&metal, &wrong)));
    let lambert = cases_for("lambert", diffuse(0.5), dir(0.7, 0.0), &[]).remove(0);
    // cos^n / normalisation with n = 1.1 instead of 1.
    let n = 1.1f64;
    let wrong =
        |wi: Vec3A| if wi.z > 0.0 { (n + 1.0) / (2.0 * std::f64::consts::PI) * (wi.z as f64).powf(n) } else { 0.0 };
    rows.push(("NEG diffuse pdf cos^1.1".into(), run_with_pdf(&lambert, &wrong)));
    // A pdf of 0 where samples land: the cells found empty are looked at
    // again with the fine cubature, which must still find them empty.
    let wrong = |wi: Vec3A| if wi.z > 0.0 && wi.x < 0.5 { wi.z as f64 / std::f64::consts::PI } else { 0.0 };
    rows.push(("NEG diffuse pdf 0 where x > 0.5".into(), run_with_pdf(&lambert, &wrong)));
    // Directions of the right shape, but 1 % of the samples lost (a bias of
    // 1 % in every render): only the absent samples' cell sees it.
    let lossy = |uc: f32, u2| {
        let s = (uc >= 0.01).then(|| lambert.bsdf.sample(lambert.wo, uc, u2, &l, TransportMode::Radiance))??;
        Some(s.wi)
    };
    let lambert_pdf = |wi: Vec3A| lambert.bsdf.pdf(lambert.wo, wi, &l, TransportMode::Radiance) as f64;
    let o = chi2_test(lossy, &lambert_pdf, &lambert.grid, N_SAMPLES, case_seed("lossy"));
    rows.push(("NEG diffuse sampler losing 1% of its samples".into(), o));
    let accepted: Vec<&String> =
        rows.iter().filter(|(name, o)| !report(name, o, 0.0, alpha)).map(|(name, _)| name).collect();
    assert!(accepted.is_empty(), "negative controls NOT rejected: {accepted:?}");
}
