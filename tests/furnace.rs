//! White furnaces for every registered integrator (VALIDATION.md §2): in a
//! constant environment of radiance 1, an object that loses no energy
//! vanishes, and a rough surface shows exactly its directional albedo.
//!
//! - Lossless BSDFs (diffuse albedo 1, smooth glass, dispersive glass, a
//!   perfect mirror), each on a sphere that fills the view: every pixel reads
//!   the colour of radiance 1. An integrator that declares the object out of
//!   its reach (`Integrator::unsamplable`: light tracing cannot see glass or
//!   a mirror through the pinhole) is skipped there, and only there.
//! - The same BSDFs on a large sphere over a diffuse albedo-1 floor that
//!   fills the view, the sphere out of view: the light the floor receives
//!   through and off it is still radiance 1, so this case is within every
//!   integrator's reach, light tracing included (its caustic paths L S D E).
//!   The sphere covers ~37 % of the floor's sky, so a lossy sphere is seen
//!   (`a_lossy_mirror_over_the_floor_is_rejected`).
//! - Rough BSDFs (GGX conductor and dielectric) on a single quad, seen from
//!   two angles: each block reads the BSDF's radiance-mode directional
//!   albedo at the block's viewing direction, integrated by quadrature
//!   (tests/common/albedo.rs), which must not exceed 1. Light tracing is
//!   left out of this one case (see there).
//!
//! Every case also runs its negative control: the same statistics x1.02 must
//! be rejected, so each case has the power to see a 2% bias. The colour rule
//! is `prism::stats::Verdict`'s; the Bonferroni family spans the whole test.

// The BSDF helpers and the scene helpers each mount tests/common/seeds.rs.
#![allow(clippy::duplicate_mod)]

mod common;
#[path = "common/scenes.rs"]
mod scenes;

use common::albedo::{albedo_quadrature, Rough};
use common::{conductor, dielectric, dir, dispersive_dielectric, seed};
use glam::{Vec2, Vec3A};
use prism::camera::Camera;
use prism::integrators::{self, IntegratorOptions, INTEGRATORS};
use prism::materials::{Bsdf, Diffuse, Mirror, TransportMode};
use prism::scene::{Scene, SceneBuilder};
use prism::shapes::Mesh;
use prism::spectrum::Spectrum;
use prism::stats::{render_passes, ColourStats, Verdict};
use scenes::srgb_of;

const K: u32 = 16;
const RES: u32 = 16;
const BLOCK: u32 = 8;
/// The bias of the negative control every case must reject.
const CONTROL: f64 = 1.02;

/// Light paths per pixel for light tracing, samples per pixel for the others:
/// enough for each to reject the x1.02 control. A dispersive BSDF keeps one
/// wavelength of four, and its colour noise needs 16x the samples where the
/// camera sees it directly, 4x over the floor (where ~37 % of the light has
/// passed through it); light tracing there needs only 2x, as its splats
/// over the wide view are many (x1.02 at z 18-22 with 4x, session 56).
fn spp(integrator: &str, dispersive: bool, view: View) -> u32 {
    let base = match integrator {
        "light" => 4096,
        "bdpt" => 16,
        _ => 32,
    };
    match (dispersive, view, integrator) {
        (true, View::Direct, _) => 16 * base,
        (true, View::OverFloor, "light") => 2 * base,
        (true, View::OverFloor, _) => 4 * base,
        _ => base,
    }
}

/// Where the camera sees the light of the object under test.
#[derive(Clone, Copy, PartialEq, Debug)]
enum View {
    /// The object fills the view.
    Direct,
    /// Only its light, on a white floor.
    OverFloor,
}

fn grey(v: f64) -> [f64; 3] {
    srgb_of(&Spectrum::Constant(v as f32))
}

fn lossless() -> Vec<(&'static str, Bsdf)> {
    vec![
        ("diffuse albedo 1", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(1.0)))),
        ("glass eta 1.5", dielectric(1.5, 0.0, 0.0)),
        ("dispersive glass", dispersive_dielectric(0.0)),
        ("mirror", Bsdf::Mirror(Mirror::new(Spectrum::Constant(1.0)))),
    ]
}

/// A unit sphere of `bsdf` filling the view, in a constant environment of 1.
fn sphere_in_view(bsdf: &Bsdf) -> Scene {
    let camera = Camera::new(Vec3A::new(0.0, 0.0, -2.2), Vec3A::ZERO, Vec3A::Y, 34.0, RES, RES);
    let mut b = SceneBuilder::new(camera);
    let m = b.material("object", bsdf.clone());
    b.mesh("sphere", Mesh::sphere(Vec3A::ZERO, 1.0, 4, false), m, None);
    b.environment("sky", Spectrum::Constant(1.0));
    b.build()
}

/// A diffuse albedo-1 floor filling the view, under a sphere of `bsdf`
/// (radius 2, 3 above the floor) that hangs over the camera, out of its
/// view: from the floor in view the sphere covers cosine-weighted sky
/// (about 26 % at the corners of the view, 44 % at its centre, 37 % on
/// average), so that much of every block's light has passed through or off
/// it, and a 10 % loss there moves every block by about 4 % (see
/// `a_lossy_mirror_over_the_floor_is_rejected`). A wide field of view
/// (120 degrees), so that light tracing's environment paths land on the
/// floor in view often: at 90 degrees (a sixth of the floor in view; half
/// at 120) its x1.02 controls were at sRGB z 6.8-12.4, chi-square 82-100,
/// with twice the light paths it has now (session 56).
fn sphere_over_floor(bsdf: &Bsdf) -> Scene {
    let camera = Camera::new(Vec3A::new(0.0, 0.8, 0.0), Vec3A::ZERO, Vec3A::Z, 120.0, RES, RES);
    let mut b = SceneBuilder::new(camera);
    let white = b.material("white", Bsdf::Diffuse(Diffuse::new(Spectrum::Constant(1.0))));
    let m = b.material("object", bsdf.clone());
    let corners = [
        Vec3A::new(-2.0, 0.0, -2.0),
        Vec3A::new(-2.0, 0.0, 2.0),
        Vec3A::new(2.0, 0.0, 2.0),
        Vec3A::new(2.0, 0.0, -2.0),
    ];
    b.mesh("white floor", Mesh::quad(corners), white, None);
    b.mesh("sphere above", Mesh::sphere(Vec3A::new(0.0, 3.0, 0.0), 2.0, 3, false), m, None);
    b.environment("sky", Spectrum::Constant(1.0));
    b.build()
}

struct Case {
    what: String,
    scene: Scene,
    integrator: &'static str,
    spp: u32,
    /// Exact colour per block.
    expected: Vec<[f64; 3]>,
}

/// Runs every case and its x1.02 control; the family spans all cases.
fn run(cases: &[Case]) {
    let mut failures = Vec::new();
    for c in cases {
        let integ = integrators::create(c.integrator, &IntegratorOptions::default()).unwrap();
        let passes = render_passes(&c.scene, integ.as_ref(), c.spp, K, seed(), 0);
        let stats = ColourStats::from_passes(&passes, RES, RES, BLOCK);
        let v = Verdict::versus_values(&stats, &c.expected, cases.len());
        let control = Verdict::versus_values(&stats.scaled(CONTROL), &c.expected, cases.len());
        eprintln!("{}, {}: {v}\n  negative control x{CONTROL}: {control}", c.what, c.integrator);
        if !v.passed() {
            failures.push(format!("{}, {}: {v}", c.what, c.integrator));
        }
        if control.passed() {
            failures.push(format!("{}, {}: a bias x{CONTROL} went undetected: {control}", c.what, c.integrator));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn lossless_objects_vanish_for_every_integrator() {
    let blocks = ((RES / BLOCK) * (RES / BLOCK)) as usize;
    let mut cases = Vec::new();
    let mut skipped = Vec::new();
    for (what, bsdf) in lossless() {
        type MakeScene = fn(&Bsdf) -> Scene;
        let views: [(&str, View, MakeScene); 2] = [
            ("seen directly", View::Direct, sphere_in_view),
            ("over a white floor", View::OverFloor, sphere_over_floor),
        ];
        for (view, kind, make) in views {
            for i in INTEGRATORS {
                let scene = make(&bsdf);
                let integ = integrators::create(i.name, &IntegratorOptions::default()).unwrap();
                if !integ.unsamplable(&scene).is_empty() {
                    skipped.push(format!("{} on {what} {view}", i.name));
                    continue;
                }
                let expected = vec![grey(1.0); blocks];
                let spp = spp(i.name, what.contains("dispersive"), kind);
                cases.push(Case { what: format!("{what} {view}"), scene, integrator: i.name, spp, expected });
            }
        }
    }
    eprintln!("skipped (unsamplable by the integrator's own account): {skipped:?}");
    // Only light tracing, and only where the camera sees a delta BSDF.
    let expected_skips: Vec<String> = ["glass eta 1.5", "dispersive glass", "mirror"]
        .iter()
        .map(|what| format!("light on {what} seen directly"))
        .collect();
    assert_eq!(skipped, expected_skips);
    run(&cases);
}

/// VALIDATION.md §2, glass from inside: a pinhole at the centre of a closed,
/// smooth, non-absorbing glass sphere in the furnace. Radiance crossing into
/// a denser medium grows by eta^2 (Veach 1997 §5.2) and every path leaves
/// the glass in the end, so every pixel reads eta^2 = 2.25 times the
/// environment: an analytic answer for radiance-mode refraction, whose
/// factors cancel when glass is seen from outside (the lossless cases above
/// would pass with them wrong). The dispersive glass reads eta(lambda)^2 at
/// each wavelength: the colour of that spectrum, from the glass's own index
/// table. Light tracing cannot reach a pinhole inside glass; it must say so.
#[test]
fn glass_seen_from_inside_reads_eta_squared() {
    let blocks = ((RES / BLOCK) * (RES / BLOCK)) as usize;
    let inside = |bsdf: &Bsdf| {
        let camera = Camera::new(Vec3A::ZERO, Vec3A::Z, Vec3A::Y, 60.0, RES, RES);
        let mut b = SceneBuilder::new(camera);
        let m = b.material("glass", bsdf.clone());
        b.mesh("sphere around the camera", Mesh::sphere(Vec3A::ZERO, 1.0, 4, false), m, None);
        b.environment("sky", Spectrum::Constant(1.0));
        b.build()
    };
    let eta_squared = |bsdf: &Bsdf| match bsdf {
        Bsdf::Dielectric(d) => Spectrum::from_fn(|l| d.eta.eval(l).powi(2)),
        _ => unreachable!("glass only"),
    };
    let mut cases = Vec::new();
    for (what, bsdf, spp) in
        [("glass eta 1.5", dielectric(1.5, 0.0, 0.0), 16), ("dispersive glass", dispersive_dielectric(0.0), 256)]
    {
        let scene = inside(&bsdf);
        let light = integrators::create("light", &IntegratorOptions::default()).unwrap();
        assert!(!light.unsamplable(&scene).is_empty(), "light tracing does not warn of the pinhole inside {what}");
        let expected = vec![srgb_of(&eta_squared(&bsdf)); blocks];
        for integrator in ["simple_path", "path", "bdpt"] {
            let scene = inside(&bsdf);
            cases.push(Case {
                what: format!("{what} from inside"),
                scene,
                integrator,
                spp,
                expected: expected.clone(),
            });
        }
    }
    run(&cases);
}

/// A 0.6 x 0.6 quad of `bsdf` in the z = 0 plane, normal +z, seen from 0.6
/// away at `theta_deg` (at most 60) from its normal with a 12-degree field
/// of view, which the quad fills. Small and close, so that light tracing's
/// environment paths (from a disk as wide as the scene) often reach the part
/// of the quad in view.
fn quad_seen_at(bsdf: &Bsdf, theta_deg: f32) -> Scene {
    let t = theta_deg.to_radians();
    let eye = Vec3A::new(t.sin(), 0.0, t.cos()) * 0.6;
    let camera = Camera::new(eye, Vec3A::ZERO, Vec3A::Y, 12.0, RES, RES);
    let mut b = SceneBuilder::new(camera);
    let m = b.material("surface", bsdf.clone());
    let h = 0.3;
    let corners = [Vec3A::new(-h, -h, 0.0), Vec3A::new(h, -h, 0.0), Vec3A::new(h, h, 0.0), Vec3A::new(-h, h, 0.0)];
    b.mesh("quad", Mesh::quad(corners), m, None);
    b.environment("sky", Spectrum::Constant(1.0));
    b.build()
}

/// The radiance-mode albedo towards the camera through each block's centre.
fn albedo_per_block(scene: &Scene, rough: &Rough) -> Vec<[f64; 3]> {
    let n = RES / BLOCK;
    let mut out = Vec::new();
    for by in 0..n {
        for bx in 0..n {
            let centre = Vec2::new((bx as f32 + 0.5) * BLOCK as f32, (by as f32 + 0.5) * BLOCK as f32);
            let ray = scene.camera.generate_ray(centre);
            let cos_o = (-ray.d.normalize()).dot(Vec3A::Z);
            // Isotropic BSDFs: only the angle to the normal matters.
            let a = albedo_quadrature(rough, &rough.bsdf, dir(cos_o, 0.0), TransportMode::Radiance, 1);
            assert!(a <= 1.0 + 1e-3, "{}: brighter than the environment: albedo {a} at cos {cos_o}", rough.name);
            out.push(grey(a));
        }
    }
    out
}

/// The power of the "over a white floor" view for light reaching the camera
/// by specular paths: a mirror of reflectance 0.9 (10 % lost per bounce)
/// must fail the furnace for every integrator, at a quarter of the spp of
/// the lossless cases. A sphere seen only in a small part of the floor's sky would pass.
#[test]
fn a_lossy_mirror_over_the_floor_is_rejected() {
    let blocks = ((RES / BLOCK) * (RES / BLOCK)) as usize;
    let lossy = Bsdf::Mirror(Mirror::new(Spectrum::Constant(0.9)));
    // The mirror covers part of some blocks, which read ~0.95 (0.952-0.957
    // at seed offset 0; a 10 % loss where it is seen).
    const DARKER: f64 = 0.99;
    let mut passed = Vec::new();
    for i in INTEGRATORS {
        let integ = integrators::create(i.name, &IntegratorOptions::default()).unwrap();
        let scene = sphere_over_floor(&lossy);
        // A quarter of the lossless cases' samples suffice for a 10 % loss.
        let spp = spp(i.name, false, View::OverFloor).div_ceil(4);
        let passes = render_passes(&scene, integ.as_ref(), spp, K, seed(), 0);
        let stats = ColourStats::from_passes(&passes, RES, RES, BLOCK);
        let v = Verdict::versus_values(&stats, &vec![grey(1.0); blocks], INTEGRATORS.len());
        // The loss must show as light lost: the darkest block, where the
        // mirror is seen, reads under the environment's 1.
        let darkest = stats.y.mean.iter().map(|m| m[0]).fold(f64::INFINITY, f64::min);
        eprintln!("lossy mirror over a white floor, {}: {v}; darkest block {darkest:.4}", i.name);
        if v.passed() || darkest >= DARKER {
            passed.push(format!("{}: {v}; darkest block {darkest:.4}", i.name));
        }
    }
    assert!(passed.is_empty(), "a 10 % loss off the mirror went undetected:\n{}", passed.join("\n"));
}

#[test]
fn rough_surfaces_show_their_directional_albedo() {
    let rough = [
        Rough { name: "GGX conductor alpha 0.3".into(), bsdf: conductor(0.3, 0.3), alpha_min: 0.3, eta: None },
        Rough { name: "GGX conductor alpha 0.05".into(), bsdf: conductor(0.05, 0.05), alpha_min: 0.05, eta: None },
        Rough {
            name: "GGX dielectric eta 1.5 alpha 0.3".into(),
            bsdf: dielectric(1.5, 0.3, 0.3),
            alpha_min: 0.3,
            eta: Some(1.5),
        },
    ];
    let mut cases = Vec::new();
    for r in &rough {
        for theta in [20.0, 60.0] {
            let expected = albedo_per_block(&quad_seen_at(&r.bsdf, theta), r);
            eprintln!(
                "{} at {theta} degrees: albedo by quadrature (G of sRGB) {:?}",
                r.name,
                expected.iter().map(|c| c[1]).collect::<Vec<_>>()
            );
            for i in INTEGRATORS {
                // Light tracing is left out here: its environment paths
                // rarely land on the patch in view (about 1% of them), and at
                // 4096 light paths per pixel it still misses a 5% bias on the
                // dielectric. Its rough BSDFs are proven by the agreement on
                // the glossy Cornell box (tests/agreement.rs, whose matrix
                // rejects a 5% bias of each estimator there).
                if i.name == "light" {
                    continue;
                }
                let what = format!("{} at {theta} degrees", r.name);
                let (scene, expected) = (quad_seen_at(&r.bsdf, theta), expected.clone());
                cases.push(Case { what, scene, integrator: i.name, spp: spp(i.name, false, View::Direct), expected });
            }
        }
    }
    run(&cases);
}
