//! `prism converge` (src/converge/): a small run writes every output and
//! its CSV parses; relMSE against an exact reference falls as 1/spp for an
//! unbiased estimator (the white room); grid checkpoints are reproducible;
//! a time budget is respected; bad arguments fail clearly.

#[path = "common/scenes.rs"]
mod scenes;

use scenes::temp_dir;

use prism::converge::{next_grid_spp, run, Clock, ConvergeConfig, ConvergeResults, IntegratorSpec, ReferenceSource};
use prism::output::write_exr;
use prism::spectrum::Spectrum;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn scene_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes").join(name)
}

fn prism(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_prism")).args(args).current_dir(env!("CARGO_MANIFEST_DIR")).output().unwrap()
}

fn config(scene: &str, integrators: &str, reference: ReferenceSource, out: &Path, res: u32) -> ConvergeConfig {
    ConvergeConfig {
        scene: scene_path(scene),
        integrators: IntegratorSpec::parse_list(integrators, &[]).unwrap(),
        reference,
        time: None,
        clock: Clock::Wall,
        max_spp: None,
        out: out.to_path_buf(),
        resolution: Some((res, res)),
        seed: Some(11),
        threads: 0,
        max_depth: None,
        progress: false,
        exposure: None,
        save_exr: false,
        command: "tests/converge.rs".to_string(),
    }
}

/// The white room's exact image (every pixel the colour of Le / (1 - rho) =
/// 2.5) as a reference EXR without sidecar.
fn white_room_reference(dir: &Path, res: u32) -> PathBuf {
    white_room_image(dir, res, 1.0)
}

/// The white room's exact image times `scale` (1: `white_room_reference`).
fn white_room_image(dir: &Path, res: u32, scale: f64) -> PathBuf {
    let v = scenes::srgb_of(&Spectrum::Constant(2.5)).map(|c| (c * scale) as f32);
    let path = dir.join(format!("white-room-x{scale}.exr"));
    write_exr(&path, res, res, &vec![v; (res * res) as usize]).unwrap();
    path
}

#[test]
fn small_run_writes_every_output_and_the_csv_parses() {
    let d = temp_dir("outputs");
    let out = d.join("run");
    let o = prism(&[
        "converge",
        "scenes/cornell-box.json",
        "--integrators",
        "path,bdpt:uniform",
        "--reference-spp",
        "8",
        "--reference-integrator",
        "path",
        "--reference-passes",
        "2",
        "--spp",
        "6",
        "--width",
        "16",
        "--height",
        "16",
        "--out",
        out.to_str().unwrap(),
        "--save-exr",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in [
        "path.exr",
        "bdpt-uniform.exr",
        "results.csv",
        "results.json",
        "error-vs-time.svg",
        "error-vs-time.png",
        "error-vs-spp.svg",
        "error-vs-spp.png",
        "images.png",
        "errors.png",
        "report.md",
        "reference.exr",
        "reference.json",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }

    // CSV: header, then rows of 7 fields with spp rising to the cap per integrator.
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next().unwrap(), "integrator,spp,seconds,cpu_seconds,rel_mse,mse,mae,by_spp");
    let mut rows: Vec<(String, u32, f64, f64, bool)> = Vec::new();
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 8, "{line}");
        let nums: Vec<f64> = [f[2], f[4], f[5], f[6]].iter().map(|x| x.parse().unwrap()).collect();
        assert!(nums.iter().all(|x| x.is_finite() && *x >= 0.0), "{line}");
        assert!(f[3].is_empty() || f[3].parse::<f64>().unwrap() >= 0.0, "{line}");
        rows.push((f[0].to_string(), f[1].parse().unwrap(), nums[0], nums[1], f[7].parse().unwrap()));
    }
    for label in ["path", "bdpt:uniform"] {
        let spp: Vec<u32> = rows.iter().filter(|r| r.0 == label).map(|r| r.1).collect();
        assert_eq!(spp, [1, 2, 3, 4, 5, 6], "{label}");
        assert!(rows.iter().filter(|r| r.0 == label).all(|r| r.4), "an spp-limited run is deterministic throughout");
    }

    let results: ConvergeResults =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    assert_eq!(results.integrators.len(), 2);
    assert_eq!(results.integrators[1].mis, "uniform");
    assert_eq!(results.reference.integrator.as_deref(), Some("path"));
    assert!(results.integrators.iter().all(|x| x.efficiency.is_finite() && x.efficiency > 0.0));

    let svg = std::fs::read_to_string(out.join("error-vs-time.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("bdpt:uniform") && svg.contains("relMSE"));
    assert!(std::fs::read_to_string(out.join("error-vs-spp.svg")).unwrap().contains("slope -1"));
    let png = image::open(out.join("error-vs-time.png")).unwrap().to_rgb8();
    assert!(
        png.width() >= 800 && png.pixels().any(|p| p.0 == [0, 0, 0] || p.0[0] < 60),
        "chart PNG has no text or axes"
    );
    assert_eq!(
        image::open(out.join("images.png")).unwrap().width(),
        image::open(out.join("errors.png")).unwrap().width() + 264
    );

    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    for needle in
        ["| rank | integrator", "error-vs-time.svg", "images.png", "errors.png", "bdpt:uniform", "Determinism"]
    {
        assert!(report.contains(needle), "report.md lacks {needle:?}");
    }
    std::fs::remove_dir_all(&d).unwrap();
}

/// relMSE against the exact white-room image is pure variance, so it falls
/// as 1/spp: the fitted log-log slope over 4-4096 spp, the mean of two
/// seeds', must be close to -1. Control: against the exact image x1.02, a
/// 2 % bias, whose relMSE floor (~4e-4, against 1.8e-4 of variance at
/// 4096 spp) flattens the slope out of the window. Over 30 seeds one
/// seed's slope was -1.001 +- 0.017 (range -1.038 to -0.968) and with the
/// bias -0.853 +- 0.017 (-0.896 to -0.816); a mean of two has a standard
/// deviation of ~0.012, so the window's edges are ~6.5 and ~5.6 of them
/// from the two.
/// (Until session 60 it was -1.25 to -0.8 at 256 spp, where a 2 % or a 5 %
/// bias gave -0.96 and -0.84 and passed: a test audit.)
#[test]
fn rel_mse_falls_as_one_over_spp_in_the_white_room() {
    let d = temp_dir("slope");
    let res = 16;
    let fit = |reference: &PathBuf, seed: u64| {
        let mut cfg = config("white-room.json", "path", ReferenceSource::File(reference.clone()), &d.join("run"), res);
        cfg.max_spp = Some(4096);
        cfg.seed = Some(seed);
        let r = run(&cfg).unwrap();
        let x = &r.integrators[0];
        let (slope, first) = (x.slope.unwrap(), x.checkpoints.first().unwrap().rel_mse);
        eprintln!("seed {seed}: slope {slope:.3}, relMSE {first:.3e} at first, {:.3e} at {} spp", x.rel_mse, x.spp);
        (slope, first / x.rel_mse)
    };
    let (exact, biased) = (white_room_reference(&d, res), white_room_image(&d, res, 1.02));
    const WINDOW: std::ops::RangeInclusive<f64> = -1.08..=-0.92;
    let seeds = [scenes::seed(11), scenes::seed(12)];
    // The mean slope over the seeds, and the least fall of relMSE.
    let fits = |reference: &PathBuf| {
        let f = seeds.map(|seed| fit(reference, seed));
        ((f[0].0 + f[1].0) / 2.0, f[0].1.min(f[1].1))
    };
    let (slope, fall) = fits(&exact);
    assert!(WINDOW.contains(&slope), "slope {slope}");
    assert!(fall > 1000.0, "relMSE fell only {fall}x");
    let (slope, _) = fits(&biased);
    assert!(!WINDOW.contains(&slope), "against a 2 % bias the slope is still {slope}");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn grid_checkpoints_are_reproducible_and_a_time_budget_ends_the_run() {
    let d = temp_dir("determinism");
    let res = 16;
    let exact = white_room_reference(&d, res);
    let go = |out: &str, time: Option<f64>, clock: Clock, max_spp: Option<u32>| {
        let mut cfg = config("white-room.json", "path,light", ReferenceSource::File(exact.clone()), &d.join(out), res);
        cfg.time = time;
        cfg.clock = clock;
        cfg.max_spp = max_spp;
        run(&cfg).unwrap()
    };
    let a = go("a", None, Clock::Wall, Some(20));
    let b = go("b", Some(1000.0), Clock::Wall, Some(20));
    for (x, y) in a.integrators.iter().zip(&b.integrators) {
        let errs = |r: &prism::converge::IntegratorResult| {
            r.checkpoints.iter().map(|c| (c.spp, c.rel_mse)).collect::<Vec<_>>()
        };
        assert_eq!(errs(x), errs(y), "{}: checkpoints differ between identical runs", x.label);
    }

    for clock in [Clock::Wall, Clock::Cpu] {
        let t = go("t", Some(1.0), clock, None);
        for x in &t.integrators {
            eprintln!(
                "{clock:?} clock, {}: {} spp in {:.3} s ({:.3} s wall)",
                x.label, x.spp, x.seconds, x.wall_seconds
            );
            // What holds at any speed (a timing is no pass/fail criterion):
            // every checkpoint but the last began within the budget, and the
            // last ended where not one more sample fitted at the throughput
            // so far (n (1 - s) / s < 1, so s > n / (n + 1)).
            // (`next_target`'s own test checks its predictions.)
            let times: Vec<f64> = x.checkpoints.iter().map(|c| c.time(clock)).collect();
            assert!(times.windows(2).all(|w| w[0] <= w[1]));
            let (last, before) = times.split_last().unwrap();
            assert!(before.iter().all(|&t| t < 1.0), "{}: went on after the budget: {times:?}", x.label);
            let n = x.spp as f64;
            assert!(*last > n / (n + 1.0), "{}: stopped at {n} spp in {last} s of a 1 s budget", x.label);
            assert_eq!(x.seconds, *last);
            // And no slice past the grid's next point: one cut short by
            // the budget is off the grid, and every later one.
            for w in x.checkpoints.windows(2) {
                let (a, b) = (w[0], w[1]);
                assert!(a.spp < b.spp && b.spp <= next_grid_spp(a.spp), "{}: {} -> {} spp", x.label, a.spp, b.spp);
                assert_eq!(b.by_spp, a.by_spp && b.spp == next_grid_spp(a.spp), "{}: {} spp", x.label, b.spp);
            }
        }
    }
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn bad_arguments_fail_clearly() {
    let d = temp_dir("args");
    let out = d.join("o");
    let o = out.to_str().unwrap();
    let given = ["converge", "scenes/white-room.json", "--spp", "2", "--reference", "r.exr", "--out", o];
    let with_given = |more: [&'static str; 2]| -> Vec<&str> { given.iter().copied().chain(more).collect() };
    // A stored reference with the options of one rendered here, which
    // would be ignored (a review, session 54).
    let ignored = [
        with_given(["--reference-passes", "0"]),
        with_given(["--reference-integrator", "magic"]),
        with_given(["--reference-out", "x.exr"]),
    ];
    for args in &ignored {
        let r = prism(args);
        let e = String::from_utf8_lossy(&r.stderr);
        assert!(!r.status.success() && e.contains("cannot be used with"), "{args:?}: {e}");
    }
    let e = String::from_utf8_lossy(&prism(&given).stderr).to_string();
    assert!(!e.contains("cannot be used with"), "the stored reference alone was refused: {e}");
    let cases: [(&[&str], &str); 5] = [
        (&["converge", "scenes/white-room.json", "--reference-spp", "4", "--out", o], "give a budget"),
        (
            &[
                "converge",
                "scenes/white-room.json",
                "--integrators",
                "path,bdpt:uniform",
                "--mis",
                "balance",
                "--spp",
                "2",
                "--reference-spp",
                "2",
                "--out",
                o,
            ],
            "--mis applies to a bare MIS-aware integrator",
        ),
        (&["converge", "scenes/white-room.json", "--spp", "4", "--out", o], "give the reference"),
        (
            &[
                "converge",
                "scenes/white-room.json",
                "--integrators",
                "magic",
                "--spp",
                "2",
                "--reference-spp",
                "2",
                "--out",
                o,
            ],
            "unknown integrator",
        ),
        (
            &[
                "converge",
                "scenes/white-room.json",
                "--integrators",
                "path:uniform",
                "--spp",
                "2",
                "--reference-spp",
                "2",
                "--out",
                o,
            ],
            "MIS heuristic",
        ),
    ];
    for (args, message) in cases {
        let r = prism(args);
        let e = String::from_utf8_lossy(&r.stderr);
        assert!(!r.status.success() && e.contains(message), "{args:?}: {e}");
    }
    // Checked before anything is created or rendered: no output directory
    // is left behind, and no output replaces an input or another output.
    let scene = d.join("s.json");
    std::fs::copy(scene_path("white-room.json"), &scene).unwrap();
    let scene = scene.to_str().unwrap();
    let reference_in_out = out.join("path.exr");
    let other_scene = d.join("other.json");
    std::fs::copy(scene_path("white-room.json"), &other_scene).unwrap();
    let over_other_scene = d.join("other.exr").display().to_string();
    let cases: [(&[&str], &str); 5] = [
        (
            &["converge", scene, "--spp", "2", "--reference-spp", "2", "--reference-integrator", "magic", "--out", o],
            "unknown integrator \"magic\"",
        ),
        (&["converge", scene, "--spp", "2", "--reference-spp", "2", "--exposure", "NaN", "--out", o], "--exposure"),
        (
            &[
                "converge",
                scene,
                "--spp",
                "2",
                "--reference-spp",
                "2",
                "--reference-out",
                &scene.replace(".json", ".exr"),
                "--out",
                o,
            ],
            "would replace the scene",
        ),
        (
            &[
                "converge",
                scene,
                "--integrators",
                "path",
                "--save-exr",
                "--spp",
                "2",
                "--reference-spp",
                "2",
                "--reference-out",
                reference_in_out.to_str().unwrap(),
                "--out",
                o,
            ],
            "are the same file",
        ),
        (
            &[
                "converge",
                scene,
                "--spp",
                "2",
                "--reference-spp",
                "2",
                "--reference-out",
                &over_other_scene,
                "--out",
                o,
            ],
            "would replace a JSON file that is not a prism sidecar",
        ),
    ];
    for (args, message) in cases {
        let r = prism(args);
        let e = String::from_utf8_lossy(&r.stderr);
        assert!(!r.status.success() && e.contains(message), "{args:?}: {e}");
        assert!(!out.exists(), "{args:?}: left {} behind", out.display());
    }
    assert_eq!(std::fs::read(scene).unwrap(), std::fs::read(scene_path("white-room.json")).unwrap());
    assert_eq!(std::fs::read(&other_scene).unwrap(), std::fs::read(scene_path("white-room.json")).unwrap());
    std::fs::remove_dir_all(&d).unwrap();
}

/// More arguments refused before anything is rendered or created: the same
/// estimator twice under two labels, a reference written under a non-EXR
/// name, an exposure whose 2^stops overflows, a reference with a NaN pixel
/// (no error can be measured against it), a reference of another size
/// (no empty output directory left), and a directory where an output goes
/// (refused before rendering, not after with half the outputs written).
#[test]
fn more_bad_arguments_fail_before_rendering() {
    let d = temp_dir("args2");
    let out = d.join("o");
    let o = out.to_str().unwrap();
    let exact = white_room_reference(&d, 8);
    let exact = exact.to_str().unwrap();
    let reference_png = d.join("r.png").display().to_string();
    let mut nan = vec![[0.5f32; 3]; 64];
    nan[9][1] = f32::NAN;
    let nan_reference = d.join("nan.exr");
    write_exr(&nan_reference, 8, 8, &nan).unwrap();
    let nan_reference = nan_reference.to_str().unwrap();
    let run = |extra: &[&str]| {
        let mut args = vec!["converge", "scenes/white-room.json", "--spp", "2", "--height", "8"];
        args.extend_from_slice(extra);
        if !extra.contains(&"--width") {
            args.extend(["--width", "8"]);
        }
        prism(&args)
    };
    let cases: [(&[&str], &str); 5] = [
        (&["--integrators", "bdpt,bdpt:power", "--reference", exact, "--out", o], "are the same estimator"),
        (&["--reference", nan_reference, "--out", o], "1 pixels are not finite (the first at x 1, y 1)"),
        (&["--reference-spp", "2", "--reference-out", &reference_png, "--out", o], "--reference-out must name an .exr"),
        (&["--reference", exact, "--exposure", "130", "--out", o], "--exposure must be a number of stops"),
        (&["--reference", exact, "--width", "16", "--out", o], "but the run renders 16x8"),
    ];
    for (args, message) in cases {
        let r = run(args);
        let e = String::from_utf8_lossy(&r.stderr);
        assert!(!r.status.success() && e.contains(message), "{args:?}: {e}");
        assert!(!out.exists(), "{args:?}: left {} behind", out.display());
    }
    // An --out that cannot be made stops the run before the reference is
    // rendered and written.
    std::fs::write(d.join("afile"), b"").unwrap();
    let (rendered, blocked) = (d.join("r2.exr"), d.join("afile/o"));
    let r = run(&[
        "--reference-spp",
        "2",
        "--reference-out",
        rendered.to_str().unwrap(),
        "--out",
        blocked.to_str().unwrap(),
    ]);
    let e = String::from_utf8_lossy(&r.stderr);
    assert!(!r.status.success() && e.contains("cannot create"), "{e}");
    assert!(!rendered.exists(), "the reference was rendered before --out was known to work");
    std::fs::create_dir_all(out.join("report.md")).unwrap();
    let r = run(&["--integrators", "path", "--reference", exact, "--out", o]);
    let e = String::from_utf8_lossy(&r.stderr);
    assert!(!r.status.success() && e.contains("report.md: it is a directory"), "{e}");
    assert!(!out.join("results.csv").exists(), "outputs were written before the error");
    std::fs::remove_dir_all(&d).unwrap();
}

/// docs/cluster.md makes long references with `prism render` (and parts
/// merged by `prism merge`): their sidecars are not `prism reference`'s,
/// and converge takes them, with their integrator, spp, MIS heuristic and
/// max depth, and no noise estimate from block errors (one of `--passes`
/// has its noise from its variance image). One made of the
/// run's seed from sample 0 shares its sample streams and is refused (it
/// was only noted, though every error measured was too low); a merge of
/// later samples of that seed does not unless the run reaches them, and
/// is refused only then.
#[test]
fn a_rendered_reference_is_accepted() {
    let d = temp_dir("rendered-ref");
    let render = |extra: &[&str]| {
        let mut args = vec!["render", "scenes/white-room.json", "--width", "8", "--height", "8", "--quiet"];
        args.extend_from_slice(extra);
        let r = prism(&args);
        assert!(r.status.success(), "{extra:?}: {}", String::from_utf8_lossy(&r.stderr));
    };
    let path = |name: &str| d.join(name).display().to_string();
    let measure_to = |reference: &str, spp: u32| {
        let mut cfg = config("white-room.json", "path", ReferenceSource::File(d.join(reference)), &d.join("o"), 8);
        cfg.max_spp = Some(spp);
        let r = run(&cfg).unwrap();
        (r, std::fs::read_to_string(d.join("o/report.md")).unwrap())
    };
    let measure = |reference: &str| measure_to(reference, 2);
    let refused = |reference: &str, spp: u32| {
        let out = d.join("refused");
        let mut cfg = config("white-room.json", "path", ReferenceSource::File(d.join(reference)), &out, 8);
        cfg.max_spp = Some(spp);
        let e = format!("{:#}", run(&cfg).expect_err("a reference of the run's own samples was accepted"));
        assert!(e.contains(reference) && e.contains("which include the run's seed 11"), "{e}");
        assert!(!out.exists(), "the refused run wrote {}", out.display());
    };
    render(&["--integrator", "bdpt", "--mis", "balance", "--spp", "4", "--seed", "99", "--out", &path("ref.exr")]);
    let (r, report) = measure("ref.exr");
    assert_eq!((r.reference.integrator.as_deref(), r.reference.mis.as_deref()), (Some("bdpt"), Some("balance")));
    assert_eq!((r.reference.spp, r.reference.seed, r.reference.passes), (Some(4), Some(99), None));
    assert!(report.contains("bdpt, 4 spp (seed 99)"), "{report}");
    assert_eq!(r.reference.noise_floor, None);

    // With --passes, its variance image gives its noise, as a stored
    // reference's pixel variances do; a variance image that is gone is an
    // error that names it.
    render(&["--integrator", "bdpt", "--spp", "2", "--passes", "2", "--seed", "98", "--out", &path("passes.exr")]);
    let (r, _) = measure("passes.exr");
    assert_eq!(r.reference.noise_floor_method.as_deref(), Some("pixel variances"));
    assert!(r.reference.noise_floor.is_some_and(|f| f > 0.0), "{:?}", r.reference.noise_floor);
    std::fs::remove_file(d.join("passes.var.exr")).unwrap();
    let mut cfg = config("white-room.json", "path", ReferenceSource::File(d.join("passes.exr")), &d.join("o"), 8);
    cfg.max_spp = Some(2);
    let e = format!("{:#}", run(&cfg).expect_err("a reference without its variance image was taken"));
    assert!(e.contains("passes.json") && e.contains("passes.var.exr"), "{e}");

    render(&["--integrator", "path", "--spp", "4", "--seed", "11", "--out", &path("same.exr")]);
    refused("same.exr", 2);
    render(&["--integrator", "path", "--spp", "4", "--seed", "12", "--out", &path("other.exr")]);
    let (r, _) = measure("other.exr");
    assert!(r.reference.noise_floor_method.as_deref().is_some_and(|m| m.starts_with("same estimator")));
    // Another depth is another estimand: noted, and not the same estimator.
    render(&["--integrator", "path", "--max-depth", "2", "--spp", "4", "--seed", "5", "--out", &path("d2.exr")]);
    let (r, _) = measure("d2.exr");
    assert!(r.notes.iter().any(|n| n.contains("max depth 2")), "{:?}", r.notes);
    assert_eq!(r.reference.noise_floor, None);
    render(&["--integrator", "path", "--sample-range", "4..6", "--seed", "11", "--out", &path("p0.exr")]);
    render(&["--integrator", "path", "--sample-range", "6..8", "--seed", "11", "--out", &path("p1.exr")]);
    let m = prism(&["merge", &path("merged.exr"), &path("p0.exr"), &path("p1.exr")]);
    assert!(m.status.success(), "{}", String::from_utf8_lossy(&m.stderr));
    let (r, _) = measure("merged.exr");
    assert_eq!((r.reference.spp, r.reference.seed, r.reference.wall_seconds), (Some(4), Some(11), None));
    refused("merged.exr", 5);
    std::fs::remove_dir_all(&d).unwrap();
}

/// Checks of a reference's origin that an audit found missing (session
/// 42): another scene's content under the same file name (noted: render and
/// reference sidecars record the scene's hash), pass seeds that wrap past
/// 2^64 - 1 onto the run's (refused, as any shared seed is), and a
/// variance image that is not a variance (refused, naming it).
#[test]
fn a_reference_from_elsewhere_is_named() {
    let d = temp_dir("ref-origin");
    let ok = |args: &[&str]| {
        let r = prism(args);
        assert!(r.status.success(), "{args:?}: {}", String::from_utf8_lossy(&r.stderr));
    };
    let small = ["--width", "8", "--height", "8"];
    let out = |name: &str| d.join(name).display().to_string();
    let white_room = scene_path("white-room.json").display().to_string();
    let mut args = vec!["reference", &white_room, "--spp", "2", "--passes", "2", "--seed", "50"];
    let reference = out("ref.exr");
    args.extend(small.iter().chain(&["--out", &reference]));
    ok(&args);
    // The same file name, brighter walls: noted; the scene itself: not.
    let alt = d.join("alt");
    std::fs::create_dir_all(&alt).unwrap();
    let text = std::fs::read_to_string(scene_path("white-room.json")).unwrap();
    let brighter = text.replacen("\"emission\": 0.5", "\"emission\": 1.5", 1);
    assert_ne!(brighter, text);
    std::fs::write(alt.join("white-room.json"), brighter).unwrap();
    let notes = |scene: PathBuf, reference: &str| {
        let mut cfg = config("white-room.json", "path", ReferenceSource::File(d.join(reference)), &d.join("o"), 8);
        (cfg.scene, cfg.max_spp) = (scene, Some(2));
        run(&cfg).unwrap_or_else(|e| panic!("{e:#}")).notes
    };
    let other = "with other contents than this run's";
    let n = notes(alt.join("white-room.json"), "ref.exr");
    assert!(n.iter().any(|n| n.contains(other)), "{n:?}");
    let n = notes(scene_path("white-room.json"), "ref.exr");
    assert!(!n.iter().any(|n| n.contains(other)), "{n:?}");

    // Seeds 2^64 - 1 and 0: the run's seed 0 is the second pass's.
    let wrapped = out("wrapped.exr");
    let mut args = vec!["reference", &white_room, "--spp", "1", "--passes", "2", "--seed", "18446744073709551615"];
    args.extend(small.iter().chain(&["--out", &wrapped]));
    ok(&args);
    let mut cfg = config("white-room.json", "path", ReferenceSource::File(d.join("wrapped.exr")), &d.join("o"), 8);
    (cfg.seed, cfg.max_spp) = (Some(0), Some(1));
    let e = format!("{:#}", run(&cfg).expect_err("a reference that shares the run's seed was taken"));
    assert!(e.contains("seeds 18446744073709551615 to 0") && e.contains("the run's seed 0"), "{e}");

    // A --passes render's variance image with a negative value.
    let passes = out("passes.exr");
    let mut args = vec!["render", &white_room, "--spp", "1", "--passes", "2", "--seed", "60", "--quiet"];
    args.extend(small.iter().chain(&["--out", &passes]));
    ok(&args);
    let mut variance = vec![[0.5f32; 3]; 64];
    variance[9][1] = -1000.0;
    write_exr(&d.join("passes.var.exr"), 8, 8, &variance).unwrap();
    let mut cfg = config("white-room.json", "path", ReferenceSource::File(d.join("passes.exr")), &d.join("o"), 8);
    cfg.max_spp = Some(1);
    let e = format!("{:#}", run(&cfg).expect_err("a negative variance was taken"));
    assert!(e.contains("passes.var.exr: a variance is negative (the first at x 1, y 1)"), "{e}");
    std::fs::remove_dir_all(&d).unwrap();
}

/// A `prism reference` records the depth it rendered with (the scene's
/// `render.max_depth`, else the default 1024; it recorded none, and used
/// the default whatever the scene said): a run at another depth is told
/// that it estimates another image, and does not take the reference's
/// noise from its own line of the "same" estimator; nor does a run whose
/// reference predates the field.
#[test]
fn a_stored_reference_records_its_depth() {
    let d = temp_dir("ref-depth");
    let reference = |scene: &Path, out: &str| {
        let (scene, out) = (scene.display().to_string(), d.join(out).display().to_string());
        let args = ["reference", &scene, "--spp", "2", "--passes", "2", "--width", "8", "--height", "8", "--out", &out];
        let r = prism(&args);
        assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
        let sidecar: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(Path::new(&out).with_extension("json")).unwrap()).unwrap();
        sidecar["max_depth"].as_u64()
    };
    let white_room = scene_path("white-room.json");
    assert_eq!(reference(&white_room, "ref.exr"), Some(1024));
    let capped = d.join("capped.json");
    let text = std::fs::read_to_string(&white_room).unwrap().replace("\"spp\": 64,", "\"spp\": 64, \"max_depth\": 2,");
    std::fs::write(&capped, text).unwrap();
    assert_eq!(reference(&capped, "capped-ref.exr"), Some(2));

    let mut cfg = config("white-room.json", "path", ReferenceSource::File(d.join("ref.exr")), &d.join("o"), 8);
    cfg.max_spp = Some(2);
    let method = |cfg: &ConvergeConfig| {
        let r = run(cfg).unwrap();
        let other_depth = r.notes.iter().any(|n| n.contains("rendered with max depth 1024, this run uses 2"));
        (r.reference.max_depth, other_depth, r.reference.noise_floor_method.unwrap_or_default())
    };
    let (depth, other_depth, floor) = method(&cfg);
    assert_eq!((depth, other_depth), (Some(1024), false));
    assert!(floor.starts_with("same estimator"), "{floor}");
    cfg.max_depth = Some(2);
    let (depth, other_depth, floor) = method(&cfg);
    assert_eq!((depth, other_depth), (Some(1024), true));
    assert_eq!(floor, "pixel variances");

    // A sidecar from before the fields: the depth is unknown (it was read
    // as 1024, which a converge-made reference need not have used), the
    // run says so and takes no noise from its own line; with no pixel
    // variances, the noise comes from the block errors.
    let sidecar = d.join("ref.json");
    let mut json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&sidecar).unwrap()).unwrap();
    json.as_object_mut().unwrap().remove("max_depth").expect("the sidecar records its depth");
    json.as_object_mut().unwrap().remove("noise_floor").expect("the sidecar records its noise");
    std::fs::write(&sidecar, json.to_string()).unwrap();
    cfg.max_depth = None;
    let r = run(&cfg).unwrap();
    assert_eq!(r.reference.max_depth, None);
    assert!(r.notes.iter().any(|n| n.contains("does not record its max depth")), "{:?}", r.notes);
    assert_eq!(r.reference.noise_floor_method.as_deref(), Some("block errors"));
    std::fs::remove_dir_all(&d).unwrap();
}

/// A run whose every checkpoint has relMSE 0 (a black furnace against its
/// black reference) draws no slope -1 guide: there is no error for it to
/// go through (from an audit: ln 0 put it along the chart's bottom edge,
/// legend and all, for every line of the run). Its efficiency is unbounded:
/// it is not ranked, a note says why, and the report shows no inf or NaN
/// (it showed efficiency inf and "vs best" NaN).
#[test]
fn an_exact_run_draws_no_slope_guide() {
    let d = temp_dir("exact-run");
    let text = std::fs::read_to_string(scene_path("furnace.json")).unwrap();
    assert!(text.contains("\"radiance\": 1.0"));
    std::fs::write(d.join("black.json"), text.replace("\"radiance\": 1.0", "\"radiance\": 0.0")).unwrap();
    let reference = ReferenceSource::Render { integrator: "path".into(), spp: 2, passes: 2, out: d.join("ref.exr") };
    let mut cfg = config("furnace.json", "path", reference, &d.join("o"), 8);
    cfg.scene = d.join("black.json");
    cfg.max_spp = Some(2);
    let r = run(&cfg).unwrap();
    assert!(r.integrators[0].checkpoints.iter().all(|c| c.rel_mse == 0.0), "not an exact run");
    let svg = std::fs::read_to_string(d.join("o/error-vs-spp.svg")).unwrap();
    assert!(!svg.contains("slope -1"), "a slope guide with no error to go through");
    assert!(r.integrators[0].efficiency.is_nan(), "an exact run ranked: efficiency {}", r.integrators[0].efficiency);
    assert!(r.notes.iter().any(|n| n.contains("relMSE is 0")), "{:?}", r.notes);
    let report = std::fs::read_to_string(d.join("o/report.md")).unwrap();
    let words = report.split(|c: char| !c.is_alphanumeric()).map(str::to_lowercase).collect::<Vec<_>>();
    assert!(!words.iter().any(|w| w == "inf" || w == "nan"), "{report}");
    std::fs::remove_dir_all(&d).unwrap();
}

/// A run shorter than the clock can measure (CPU seconds tick every 10 ms)
/// has no efficiency and no rank, and says so; a reference whose own noise
/// is a large part of the measured error is named in a note.
/// With a reference of known noise, each result's `efficiency_net` takes
/// that noise out of relMSE, 1 / ((relMSE - floor) s), and the report shows
/// its ratio to the best's beside the plain one.
#[test]
fn efficiency_net_of_the_reference_noise_is_reported() {
    let d = temp_dir("net");
    let source = ReferenceSource::Render { integrator: "path".into(), spp: 2, passes: 2, out: d.join("ref.exr") };
    let mut cfg = config("white-room.json", "path,light", source, &d.join("o"), 8);
    cfg.max_spp = Some(4);
    let r = run(&cfg).unwrap();
    let floor = r.reference.noise_floor.expect("a rendered reference's noise is estimated");
    // The floor's value: path's relMSE m = V/n + V/N against a reference of
    // the same estimator, here n = 4 spp and N = 2 (its 2 spp over 2
    // passes), so V/N = m / 1.5 (a review, session 55: only that a floor
    // below relMSE was given was checked).
    let path = &r.integrators[0];
    assert_eq!((path.label.as_str(), path.spp, r.reference.spp), ("path", 4, Some(2)));
    assert_eq!(floor, path.rel_mse / 1.5);
    for x in &r.integrators {
        let want = 1.0 / ((x.rel_mse - floor) * x.seconds);
        assert!(
            x.rel_mse > floor && (x.efficiency_net / want - 1.0).abs() < 1e-12,
            "{}: {}",
            x.label,
            x.efficiency_net
        );
    }
    let json: ConvergeResults =
        serde_json::from_str(&std::fs::read_to_string(d.join("o/results.json")).unwrap()).unwrap();
    // (serde_json's default float parser may land one ulp off the shortest
    // decimal ryu wrote, as at seed offset 85: 2041.7504710327082 read back
    // as 2041.750471032708; its exact parser would change the scene
    // loader's range errors.)
    let (read, kept) = (json.integrators[0].efficiency_net, r.integrators[0].efficiency_net);
    assert!((read / kept - 1.0).abs() <= 2.0 * f64::EPSILON, "{read} vs {kept}");
    let report = std::fs::read_to_string(d.join("o/report.md")).unwrap();
    assert!(report.contains("| vs best, reference noise out |"), "{report}");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn unmeasurable_runs_and_noisy_references_are_flagged() {
    let d = temp_dir("flags");
    let mut cfg = config(
        "white-room.json",
        "path",
        ReferenceSource::Render { integrator: "path".into(), spp: 2, passes: 2, out: d.join("ref.exr") },
        &d.join("o"),
        8,
    );
    cfg.max_spp = Some(1);
    cfg.clock = Clock::Cpu;
    let r = run(&cfg).unwrap();
    let x = &r.integrators[0];
    assert!(x.efficiency.is_nan(), "a {} s run was ranked: efficiency {}", x.seconds, x.efficiency);
    assert!(r.notes.iter().any(|n| n.contains("too short to measure")), "{:?}", r.notes);
    assert!(r.notes.iter().any(|n| n.contains("the reference's own noise")), "{:?}", r.notes);
    let json: ConvergeResults =
        serde_json::from_str(&std::fs::read_to_string(d.join("o/results.json")).unwrap()).unwrap();
    assert!(json.integrators[0].efficiency.is_nan(), "NaN does not round-trip through results.json");
    std::fs::remove_dir_all(&d).unwrap();
}
