//! The command line: clear errors with a non-zero exit for bad input, no
//! output file left behind (or clobbered) on failure, and a working render.

#[path = "common/scenes.rs"]
mod scenes;

use scenes::temp_dir;

use std::path::Path;
use std::process::{Command, Output};

fn prism(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_prism")).args(args).current_dir(env!("CARGO_MANIFEST_DIR")).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

/// `prism render SCENE` on one thread with `args`.
fn render_one(scene: &str, args: &[&str]) -> Output {
    prism(&[&["render", scene, "--threads", "1", "--quiet"], args].concat())
}

/// `render_one`, which must succeed: its stderr.
fn render_ok(scene: &str, args: &[&str]) -> String {
    let o = render_one(scene, args);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    stderr(&o)
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn renders_exr_png_and_sidecar() {
    let d = temp_dir("ok");
    let scene = write(&d, "s.json", scenes::TINY_SCENE);
    let out = d.join("img.exr");
    let png = d.join("img.png");
    let o = prism(&[
        "render",
        &scene,
        "--spp",
        "2",
        "--threads",
        "1",
        "--out",
        out.to_str().unwrap(),
        "--png",
        png.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.exists() && png.exists());
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("img.json")).unwrap()).unwrap();
    assert_eq!(sidecar["spp"], 2);
    assert_eq!(sidecar["integrator"], "path");
    assert!(sidecar["rays"].as_u64().unwrap() > 0);
    // The render's own pool, not the process's global one (all cores).
    assert_eq!(sidecar["threads"], 1);
    assert_eq!(sidecar["dropped_samples"]["nan"], 0);
    // What the image is bit-identical within: the commit and the build target.
    assert_eq!(sidecar["build_target"], prism::build_target().as_str());
    assert!(prism::build_target().starts_with(std::env::consts::ARCH));
    assert_eq!(cfg!(target_feature = "fma"), prism::build_target().contains("+fma"));
    let _ = std::fs::remove_dir_all(&d);
}

/// Samples the films keep out are reported by the commands that render: a
/// point light of intensity 1e30 makes infinite samples; `render` and
/// `reference` warn on stderr and count them in the sidecar, and `converge`
/// notes the dropped samples of a reference it renders. (`reference` and
/// converge's reference dropped them silently, and converge ranked the
/// integrators against the black image left.)
#[test]
fn dropped_samples_are_reported_by_render_reference_and_converge() {
    let d = temp_dir("dropped");
    let bright = r#"{"type": "point", "position": [0, 2, -2], "intensity": 1e30}"#;
    let text = scenes::TINY_SCENE.replace(r#"{"type": "environment", "radiance": 1.0}"#, bright);
    assert_ne!(text, scenes::TINY_SCENE);
    let scene = write(&d, "s.json", &text);
    let sidecar = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(d.join(name)).unwrap()).unwrap()
    };
    // (The temporary directory's path has no spaces.)
    let run = |line: String| prism(&line.split_whitespace().collect::<Vec<_>>());
    let (img, reference, runs) = (d.join("img.exr"), d.join("ref.exr"), d.join("converge"));
    let o = run(format!("render {scene} --spp 2 --quiet --out {}", img.display()));
    assert!(o.status.success() && stderr(&o).contains("warning: dropped"), "{}", stderr(&o));
    assert!(sidecar("img.json")["dropped_samples"]["infinite"].as_u64().unwrap() > 0);
    // BDPT's per-strategy images count what they refuse apart (they were
    // never reported; a review, session 39).
    let (strategies, bd) = (d.join("st"), d.join("bd.exr"));
    let o = run(format!(
        "render {scene} --integrator bdpt --spp 2 --quiet --strategies {} --out {}",
        strategies.display(),
        bd.display()
    ));
    assert!(o.status.success() && stderr(&o).contains("values of the per-strategy images"), "{}", stderr(&o));
    assert!(sidecar("bd.json")["strategy_records_dropped"]["infinite"].as_u64().unwrap() > 0);
    let o = run(format!("reference {scene} --spp 1 --passes 2 --width 8 --height 8 --out {}", reference.display()));
    assert!(o.status.success() && stderr(&o).contains("warning: dropped"), "{}", stderr(&o));
    assert!(sidecar("ref.json")["dropped_samples"]["infinite"].as_u64().unwrap() > 0);
    let o = run(format!(
        "converge {scene} --integrators path --spp 1 --reference-spp 2 --width 8 --height 8 --quiet --out {}",
        runs.display()
    ));
    let text = std::fs::read_to_string(runs.join("report.md")).unwrap_or_default();
    assert!(text.contains("the reference's films dropped"), "{}\n{text}", stderr(&o));
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn unknown_integrator_lists_the_valid_ones() {
    let d = temp_dir("integrator");
    let scene = write(&d, "s.json", scenes::TINY_SCENE);
    let out = d.join("x.exr");
    let o = prism(&["render", &scene, "--integrator", "magic", "--out", out.to_str().unwrap(), "--quiet"]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("unknown integrator \"magic\" (valid: simple_path, path, light, bdpt)"), "{e}");
    assert!(!out.exists());
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn missing_scene_file_names_it() {
    let o = prism(&["render", "no/such/scene.json", "--out", "/tmp/never.exr"]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("no/such/scene.json") && e.contains("cannot read"), "{e}");
}

/// Each bad scene gives file:line:col: field: message, and a non-zero exit.
#[test]
fn bad_scenes_name_file_line_and_field() {
    let cases: &[(&str, &str, &str)] = &[
        // (scene text, expected position, expected words)
        ("{\n  \"camera\": {\"position\": [0, 0, -3],,}\n}", ":2:", "camera: key must be a string"),
        (&scenes::TINY_SCENE.replace("\"fov\": 40", "\"fov\": \"wide\""), ":2:", "camera.fov"),
        (
            &scenes::TINY_SCENE.replace("\"material\": \"white\"", "\"material\": \"whte\""),
            ":4:",
            "objects[0].material: unknown material \"whte\"",
        ),
        (
            &scenes::TINY_SCENE.replace("\"reflectance\": 0.5", "\"reflectance\": \"nosuch\""),
            ":3:",
            "materials.white.reflectance: unknown spectrum \"nosuch\"",
        ),
        (
            &scenes::TINY_SCENE.replace("\"reflectance\": 0.5", "\"reflectanse\": 0.5"),
            ":3:",
            "unknown field `reflectanse`",
        ),
        (&scenes::TINY_SCENE.replace("\"radius\": 1", "\"radius\": 1e999"), ":4:", "objects[0].shape"),
        (&scenes::TINY_SCENE.replace("\"radius\": 1", "\"radius\": -1"), ":4:", "objects[0].shape.radius"),
    ];
    let d = temp_dir("bad");
    for (i, (text, pos, words)) in cases.iter().enumerate() {
        let scene = write(&d, &format!("bad{i}.json"), text);
        let out = d.join(format!("bad{i}.exr"));
        let o = prism(&["render", &scene, "--out", out.to_str().unwrap(), "--quiet"]);
        let e = stderr(&o);
        assert!(!o.status.success(), "case {i} succeeded");
        assert!(e.contains(&format!("bad{i}.json{pos}")), "case {i}: position missing in {e}");
        assert!(e.contains(words), "case {i}: expected {words:?} in {e}");
        assert!(!out.exists(), "case {i} left an output file");
    }
    // A byte that is not UTF-8 is located by line and column too.
    let scene = d.join("latin1.json");
    std::fs::write(&scene, b"{\n  \"camera\": \xff\n}\n").unwrap();
    let o = prism(&["render", scene.to_str().unwrap(), "--out", d.join("latin1.exr").to_str().unwrap(), "--quiet"]);
    assert!(!o.status.success() && stderr(&o).contains("latin1.json:2:13: not UTF-8 text"), "{}", stderr(&o));
    let _ = std::fs::remove_dir_all(&d);
}

/// `prism reference` names the one flag at fault and its value (it said
/// "need --spp >= 1, --passes >= 2, and --width/--height multiples of
/// --block" whichever it was), and writes nothing.
#[test]
fn reference_flags_are_checked_one_by_one() {
    let d = temp_dir("reference-flags");
    let out = d.join("r.exr").display().to_string();
    let flags = ["--spp", "--passes", "--width", "--height", "--block"];
    // Each case breaks one condition; the other values are valid.
    let cases = [
        (["4", "2", "8", "8", "0"], "--block must be at least 1, got 0"),
        (["0", "2", "8", "8", "8"], "--spp must be at least 1, got 0"),
        (["4", "1", "8", "8", "8"], "--passes must be at least 2 (a variance needs two passes), got 1"),
        (["4", "2", "10", "8", "8"], "--width 10 is not a multiple of --block 8"),
        (["4", "2", "8", "12", "8"], "--height 12 is not a multiple of --block 8"),
    ];
    let reference = |values: [&str; 5]| {
        let mut args = vec!["reference", "scenes/cornell-box.json", "--out", &out];
        args.extend(flags.iter().zip(values).flat_map(|(f, v)| [*f, v]));
        prism(&args)
    };
    for (values, words) in cases {
        let o = reference(values);
        let e = stderr(&o);
        assert!(!o.status.success(), "{values:?} succeeded");
        assert!(e.lines().filter(|l| l.starts_with("error:")).count() == 1 && e.contains(words), "{values:?}: {e}");
        assert!(!d.join("r.exr").exists() && !d.join("r.json").exists(), "{values:?} wrote an output");
    }
    // Control: the valid values render.
    let o = reference(["4", "2", "8", "8", "8"]);
    assert!(o.status.success() && d.join("r.exr").exists(), "{}", stderr(&o));
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn failed_render_leaves_existing_output_untouched() {
    let d = temp_dir("keep");
    let out = d.join("keep.exr");
    std::fs::write(&out, b"previous").unwrap();
    let scene = write(&d, "bad.json", "{ not json");
    let o = prism(&["render", &scene, "--out", out.to_str().unwrap(), "--quiet"]);
    assert!(!o.status.success());
    assert_eq!(std::fs::read(&out).unwrap(), b"previous");
    let o = prism(&["render", &write(&d, "s.json", scenes::TINY_SCENE), "--out", "/no/such/dir/x.exr", "--quiet"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("/no/such/dir"), "{}", stderr(&o));
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn integrators_are_listed() {
    let o = prism(&["integrators"]);
    assert!(o.status.success());
    let s = String::from_utf8_lossy(&o.stdout);
    // Every registered estimator, one per line, by the name `--integrator`
    // takes (a review, session 55: `path` and `simple_path` alone were
    // checked, the first inside the second).
    let names: Vec<&str> = s.lines().filter_map(|l| l.split_whitespace().next()).collect();
    assert_eq!(names, ["simple_path", "path", "light", "bdpt"], "{s}");
}

/// No output may replace an input or another output: `render s.json --out
/// s.exr` would write its sidecar over the scene; `--png` must name a .png
/// (so neither `--out` nor the sidecar); a merge's state may not be a part's; `reference` writes
/// a sidecar too. Each is one error, and the inputs are untouched.
#[test]
fn outputs_never_replace_the_scene_or_each_other() {
    let d = temp_dir("collide");
    let scene = write(&d, "s.json", scenes::TINY_SCENE);
    std::fs::create_dir_all(d.join("sub")).unwrap();
    let path = |name: &str| d.join(name).display().to_string();
    let render = |extra: &[&str]| {
        let mut args = vec!["render", scene.as_str(), "--spp", "1", "--threads", "1", "--quiet"];
        args.extend_from_slice(extra);
        prism(&args)
    };
    let fails_with = |o: Output, words: &str| {
        assert!(!o.status.success(), "succeeded: expected an error with {words:?}");
        let e = stderr(&o);
        assert!(e.lines().filter(|l| l.starts_with("error:")).count() == 1 && e.contains(words), "{e}");
    };
    fails_with(render(&["--out", &path("s.exr")]), "its sidecar");
    fails_with(render(&["--out", &path("sub/../s.exr")]), "would replace the scene");
    fails_with(render(&["--out", &path("a.exr"), "--png", &path("a.exr")]), "--png");
    fails_with(render(&["--out", &path("a.exr"), "--png", &path("a.json")]), "--png must name a .png file");
    fails_with(
        prism(&[
            "reference",
            &scene,
            "--spp",
            "1",
            "--passes",
            "2",
            "--width",
            "8",
            "--height",
            "8",
            "--out",
            &path("s.exr"),
        ]),
        "would replace the scene",
    );
    assert_eq!(std::fs::read_to_string(&scene).unwrap(), scenes::TINY_SCENE, "the scene changed");
    assert!(!d.join("a.exr").exists(), "an output was written");

    let part = prism(&["render", &scene, "--sample-range", "0..1", "--quiet", "--out", &path("p1.exr")]);
    assert!(part.status.success(), "{}", stderr(&part));
    let state = std::fs::read(d.join("p1.state")).unwrap();
    fails_with(prism(&["merge", &path("p1.exr"), &path("p1.exr")]), "would replace the part state");
    assert_eq!(std::fs::read(d.join("p1.state")).unwrap(), state, "the part's state changed");
    // Its .state would be read: a checkpoint's name is refused.
    fails_with(prism(&["merge", &path("m.exr"), &path("p1.ckpt")]), "a part must name its .exr image or its .state");
    let by_state = prism(&["merge", &path("m.exr"), &path("p1.state")]);
    assert!(by_state.status.success(), "a part named by its state: {}", stderr(&by_state));
    // The output name forgotten (`prism merge parts/*.exr`): the first part
    // would be the output, its sums replaced by the others'. Refused, as is
    // a merge over a state of samples it does not hold, or of another
    // render; merging again with more parts is not.
    let p2 = prism(&["render", &scene, "--sample-range", "1..2", "--quiet", "--out", &path("p2.exr")]);
    assert!(p2.status.success(), "{}", stderr(&p2));
    let p2_state = std::fs::read(d.join("p2.state")).unwrap();
    let replaced = "the merge would replace";
    fails_with(prism(&["merge", &path("p2.exr"), &path("p1.exr")]), replaced);
    assert_eq!(std::fs::read(d.join("p2.state")).unwrap(), p2_state, "the first part's state changed");
    let again = prism(&["merge", &path("m.exr"), &path("p1.exr"), &path("p2.exr")]);
    assert!(again.status.success(), "the control, a merge again with more parts: {}", stderr(&again));
    fails_with(prism(&["merge", &path("m.exr"), &path("p2.exr")]), replaced);
    let q = prism(&["render", &scene, "--seed", "5", "--sample-range", "0..1", "--quiet", "--out", &path("q.exr")]);
    assert!(q.status.success(), "{}", stderr(&q));
    fails_with(prism(&["merge", &path("q.exr"), &path("p1.exr"), &path("p2.exr")]), replaced);

    // A sidecar replaces an earlier sidecar, never another JSON file: here a
    // second scene, which no input names (found by a review, session 39:
    // `prism merge other.exr ...` wrote over other.json).
    let other = write(&d, "other.json", scenes::TINY_SCENE);
    let foreign = "would replace a JSON file that is not a prism sidecar";
    fails_with(render(&["--out", &path("other.exr")]), foreign);
    fails_with(prism(&["merge", &path("other.exr"), &path("p1.exr")]), foreign);
    let reference = ["reference", &scene, "--spp", "1", "--passes", "2", "--width", "8", "--height", "8", "--out"];
    fails_with(prism(&[&reference[..], &[&path("other.exr")]].concat()), foreign);
    assert_eq!(std::fs::read_to_string(&other).unwrap(), scenes::TINY_SCENE, "the second scene changed");
    assert!(!d.join("other.exr").exists(), "an output was written");
    for _ in 0..2 {
        let o = render(&["--out", &path("again.exr")]);
        assert!(o.status.success(), "a render over its own earlier sidecar: {}", stderr(&o));
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// No output may replace a file the scene reads beside itself: a glTF
/// file's texture, rendered directly or included by a JSON scene (`--png
/// albedo.png` overwrote the texture; an audit, session 49). The control:
/// the same render with another PNG name succeeds.
#[test]
fn outputs_never_replace_a_file_the_scene_reads() {
    let d = temp_dir("collide-inputs");
    let path = |name: &str| d.join(name).display().to_string();
    let box_gltf = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/gltf/BoxTextured.gltf");
    let mut gltf: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(box_gltf).unwrap()).unwrap();
    gltf["images"][0]["uri"] = "albedo.png".into();
    write(&d, "box.gltf", &gltf.to_string());
    image::RgbImage::from_pixel(2, 2, image::Rgb([200, 100, 50])).save(d.join("albedo.png")).unwrap();
    let texture = std::fs::read(d.join("albedo.png")).unwrap();
    let including = r#"{
  "camera": {"position": [0, 1, 4], "look_at": [0, 0, 0], "fov": 40, "width": 8, "height": 8},
  "materials": {},
  "objects": [{"shape": {"type": "gltf", "file": "box.gltf"}}],
  "lights": [{"type": "point", "position": [2, 4, 3], "intensity": 20}]
}"#;
    write(&d, "s.json", including);
    for scene in ["box.gltf", "s.json"] {
        let render = |png: &str| {
            let (scene, out, png) = (path(scene), path("a.exr"), path(png));
            prism(&[
                "render", &scene, "--spp", "1", "--width", "8", "--height", "8", "--quiet", "--out", &out, "--png",
                &png,
            ])
        };
        let o = render("albedo.png");
        let e = stderr(&o);
        assert!(!o.status.success() && e.contains("would replace a file the scene reads"), "{scene}: {e}");
        assert_eq!(std::fs::read(d.join("albedo.png")).unwrap(), texture, "{scene}: the texture changed");
        assert!(!d.join("a.exr").exists(), "{scene}: an output was written");
        let o = render("preview.png");
        assert!(o.status.success(), "the control, {scene}: {}", stderr(&o));
        std::fs::remove_file(d.join("a.exr")).unwrap();
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// Sums rendered by two builds (another target, say a node without AVX2,
/// or another commit) still add up, into an unbiased image that neither
/// may render: merge and resume say so, and the sidecar lists both (it
/// named only the merging binary's; found by a review, session 39).
#[test]
fn sums_of_two_builds_are_reported() {
    use prism::render_state::{Provenance, RenderState};
    let d = temp_dir("builds");
    let scene = write(&d, "s.json", scenes::TINY_SCENE);
    let path = |name: &str| d.join(name).display().to_string();
    let run = |args: &[&str]| render_ok(&scene, args);
    let other = Provenance { commit: "0ther".into(), build_target: "elsewhere".into() };
    let elsewhere = |from: &str, to: &str| {
        let st = RenderState::load(&d.join(from)).unwrap();
        let bytes = RenderState::encode(&st.identity, &st.sample_ranges, &st.film, &other).unwrap();
        std::fs::write(d.join(to), bytes).unwrap();
    };
    let this = Provenance::this();
    let both = this.combined(&other);
    assert!(both.commit.contains("0ther; ") || both.commit.contains("; 0ther"), "{both:?}");
    let made_by = |name: &str| {
        let v = read_json(&d.join(name));
        Provenance {
            commit: v["commit"].as_str().unwrap().into(),
            build_target: v["build_target"].as_str().unwrap().into(),
        }
    };
    run(&["--sample-range", "0..1", "--out", &path("p0.exr")]);
    run(&["--sample-range", "1..2", "--out", &path("p1.exr")]);
    let o = prism(&["merge", &path("same.exr"), &path("p0.exr"), &path("p1.exr")]);
    assert!(o.status.success() && !stderr(&o).contains("different prism"), "{}", stderr(&o));
    assert_eq!(made_by("same.json"), this);
    elsewhere("p1.state", "p1.state");
    let o = prism(&["merge", &path("mixed.exr"), &path("p0.exr"), &path("p1.exr")]);
    assert!(o.status.success() && stderr(&o).contains("different prism commits or builds"), "{}", stderr(&o));
    assert_eq!(made_by("mixed.json"), both);
    elsewhere("p0.state", "r.ckpt");
    let e = run(&["--spp", "2", "--resume", &path("r.ckpt"), "--out", &path("r.exr")]);
    assert!(e.contains(&format!("(commits [{}], builds [{}])", both.commit, both.build_target)), "{e}");
    assert_eq!(made_by("r.json"), both);
    assert_eq!(RenderState::load(&d.join("r.state")).unwrap().provenance, both, "the resumed render's state");
    // A resume that renders nothing adds no build of its own.
    elsewhere("p0.state", "n.ckpt");
    let e = run(&["--sample-range", "0..1", "--resume", &path("n.ckpt"), "--out", &path("n.exr")]);
    assert!(!e.contains("different prism"), "{e}");
    assert_eq!(made_by("n.json"), other);
    let _ = std::fs::remove_dir_all(&d);
}

/// A resume that finds every sample in its checkpoint renders nothing:
/// its sidecar has no performance figures (it had 0 threads and 0 s, as if
/// measured; found by a review, session 39), and its image is the part's.
#[test]
fn a_resume_with_nothing_left_claims_no_performance() {
    let d = temp_dir("nothing-left");
    let scene = write(&d, "s.json", scenes::TINY_SCENE);
    let path = |name: &str| d.join(name).display().to_string();
    render_ok(&scene, &["--sample-range", "0..2", "--out", &path("p.exr")]);
    let e = render_ok(&scene, &["--sample-range", "0..2", "--resume", &path("p.state"), "--out", &path("q.exr")]);
    assert!(e.contains("none left to render"), "{e}");
    let sidecar = read_json(&d.join("q.json"));
    for field in ["threads", "wall_seconds", "samples_per_second", "rays", "mrays_per_second"] {
        assert!(sidecar.get(field).is_none(), "{field} in {sidecar}");
    }
    assert_eq!(sidecar["spp"], 2);
    assert_eq!(std::fs::read(d.join("p.exr")).unwrap(), std::fs::read(d.join("q.exr")).unwrap());
    let _ = std::fs::remove_dir_all(&d);
}

/// A thread count the process may not start (here, 1024 stacks over a
/// 1.5 GB address-space limit) is an error before the render, not a
/// panic inside it (exit 101; found by a review, session 39).
#[test]
fn threads_the_process_cannot_start_are_an_error() {
    let d = temp_dir("threads");
    let scene = write(&d, "s.json", scenes::TINY_SCENE);
    let out = d.join("t.exr").display().to_string();
    let command = format!(
        "ulimit -v 1500000 && exec '{}' render '{scene}' --spp 1 --threads 1024 --quiet --out '{out}'",
        env!("CARGO_BIN_EXE_prism")
    );
    let o = Command::new("sh").args(["-c", &command]).output().unwrap();
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("--threads 1024: cannot start the worker threads"), "{e}");
    assert!(!d.join("t.exr").exists(), "an output was written");
    let _ = std::fs::remove_dir_all(&d);
}

/// A part grown from its own state (`--resume p.state` with a larger
/// `--spp`) writes its state again, so `merge` sees every sample the grown
/// part's image holds (it used to keep the old state: 4 of 16 samples); so
/// does one resumed from a checkpoint (same format as a state: a copy
/// stands in for a killed render's); and `--mis`, which path ignores (with
/// a warning), does not stop its parts from merging.
#[test]
fn grown_parts_and_ignored_options_merge() {
    let d = temp_dir("grow");
    let scene = write(&d, "s.json", scenes::TINY_SCENE);
    let path = |name: &str| d.join(name).display().to_string();
    let render = |extra: &[&str]| {
        let mut args = vec!["render", scene.as_str(), "--threads", "1", "--quiet"];
        args.extend_from_slice(extra);
        let o = prism(&args);
        assert!(o.status.success(), "{extra:?}: {}", stderr(&o));
    };
    render(&["--sample-range", "0..1", "--out", &path("p0.exr")]);
    render(&["--spp", "2", "--resume", &path("p0.state"), "--out", &path("p0.exr")]);
    std::fs::copy(d.join("p0.state"), d.join("p0.ckpt")).unwrap();
    render(&["--spp", "3", "--resume", &path("p0.ckpt"), "--checkpoint-every", "100", "--out", &path("p0.exr")]);
    assert!(!d.join("p0.ckpt").exists(), "the finished render kept its checkpoint");
    let o = render_one(&scene, &["--sample-range", "3..5", "--mis", "balance", "--out", &path("p1.exr")]);
    assert!(
        o.status.success() && stderr(&o).contains("warning: --mis sets bdpt's heuristic; path reads none"),
        "{}",
        stderr(&o)
    );
    let o = prism(&["merge", &path("all.exr"), &path("p0.exr"), &path("p1.exr")]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("5 spp (samples [0..5])"), "{}", stderr(&o));
    // The merge is the single render of samples 0..5, bit for bit.
    render(&["--spp", "5", "--out", &path("one.exr")]);
    assert_eq!(std::fs::read(d.join("all.exr")).unwrap(), std::fs::read(d.join("one.exr")).unwrap());
    let _ = std::fs::remove_dir_all(&d);
}

/// A glTF scene that names an image it cannot read renders, warning of
/// it (the loader uses the material's factor alone): the scene's identity,
/// which hashes the files a scene names, counts such a file as missing
/// rather than refusing the render (it did for a few commits of session
/// 50; found by a review).
#[test]
fn a_gltf_naming_a_missing_image_still_renders() {
    let d = temp_dir("missing-image");
    let box_gltf = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/gltf/BoxTextured.gltf");
    let mut gltf: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(box_gltf).unwrap()).unwrap();
    gltf["images"][0]["uri"] = "missing.png".into();
    let scene = write(&d, "box.gltf", &gltf.to_string());
    let out = d.join("a.exr").display().to_string();
    let e = render_ok(&scene, &["--spp", "1", "--width", "8", "--height", "8", "--out", &out]);
    assert!(e.contains("missing.png"), "no warning names the image: {e}");
    let _ = std::fs::remove_dir_all(&d);
}

/// Parts of a render merge into the bits of the whole render where its
/// surfaces tie: two coincident quads, one red and one green, meet every
/// camera ray at one distance. A lone sample (a part of one sample per
/// pixel) and a packet of samples (the whole render) must settle the tie
/// alike (`accel::Closest`; they took different quads until session 50).
#[test]
fn parts_of_coincident_faces_merge_into_the_whole_render() {
    let d = temp_dir("ties");
    let path = |name: &str| d.join(name).display().to_string();
    let scene = write(&d, "s.json", &scenes::coincident_quads(4));
    render_ok(&scene, &["--sample-range", "0..1", "--out", &path("p0.exr")]);
    render_ok(&scene, &["--sample-range", "1..2", "--out", &path("p1.exr")]);
    let o = prism(&["merge", &path("parts.exr"), &path("p0.exr"), &path("p1.exr")]);
    assert!(o.status.success(), "{}", stderr(&o));
    render_ok(&scene, &["--spp", "2", "--out", &path("whole.exr")]);
    assert_eq!(std::fs::read(d.join("parts.exr")).unwrap(), std::fs::read(d.join("whole.exr")).unwrap());
    let _ = std::fs::remove_dir_all(&d);
}

/// A part or a resume of a scene whose mesh file changed is another
/// scene's: merge and resume refuse it by `scene_hash`, which covers the
/// files the scene reads, not only the scene file (only that was hashed;
/// from an audit, session 50). Control: unchanged, the parts merge.
#[test]
fn parts_of_a_scene_whose_mesh_changed_do_not_merge() {
    let d = temp_dir("mesh-changed");
    let path = |name: &str| d.join(name).display().to_string();
    let quad = |z: f32| format!("v -1 -1 {z}\nv 1 -1 {z}\nv 1 1 {z}\nv -1 1 {z}\nf 1 2 3\nf 1 3 4\n");
    write(&d, "m.obj", &quad(0.0));
    let scene = write(
        &d,
        "s.json",
        r#"{
  "camera": {"position": [0, 0, -3], "look_at": [0, 0, 0], "fov": 40, "width": 4, "height": 4},
  "materials": {"white": {"type": "diffuse", "reflectance": 0.5}},
  "objects": [{"shape": {"type": "obj", "file": "m.obj"}, "material": "white"}],
  "lights": [{"type": "environment", "radiance": 1.0}]
}"#,
    );
    let part = |range: &str, out: &str| render_ok(&scene, &["--sample-range", range, "--out", &path(out)]);
    part("0..1", "p0.exr");
    part("1..2", "p1.exr");
    let merge = || prism(&["merge", &path("all.exr"), &path("p0.exr"), &path("p1.exr")]);
    let o = merge();
    assert!(o.status.success(), "the control: {}", stderr(&o));
    std::fs::remove_file(d.join("all.exr")).unwrap();
    write(&d, "m.obj", &quad(0.5));
    part("1..2", "p1.exr");
    let o = merge();
    let e = stderr(&o);
    assert!(!o.status.success() && e.contains("scene_hash"), "{e}");
    assert!(!d.join("all.exr").exists(), "a merge was written");
    let o = render_one(&scene, &["--spp", "2", "--resume", &path("p0.state"), "--out", &path("p0.exr")]);
    let e = stderr(&o);
    assert!(!o.status.success() && e.contains("scene_hash"), "the resume: {e}");
    let _ = std::fs::remove_dir_all(&d);
}

/// A render that checkpoints does not replace, and then remove, a
/// checkpoint it was not asked to resume: that holds an interrupted
/// render's samples (from an audit: it went without a word). Resumed, it is
/// read, grown and removed once the outputs are written.
#[test]
fn a_checkpoint_not_resumed_is_kept() {
    let d = temp_dir("ckpt-kept");
    let scene = write(&d, "s.json", scenes::TINY_SCENE);
    let path = |name: &str| d.join(name).display().to_string();
    let render = |extra: &[&str]| {
        let mut args = vec!["render", scene.as_str(), "--threads", "1", "--quiet"];
        args.extend_from_slice(extra);
        prism(&args)
    };
    let o = render(&["--sample-range", "0..1", "--out", &path("p.exr")]);
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::copy(d.join("p.state"), d.join("c.ckpt")).unwrap();
    let held = std::fs::read(d.join("c.ckpt")).unwrap();
    let o = render(&["--spp", "2", "--checkpoint-every", "0", "--out", &path("c.exr")]);
    let e = stderr(&o);
    assert!(!o.status.success() && e.contains("c.ckpt holds the samples of an interrupted render"), "{e}");
    assert_eq!(std::fs::read(d.join("c.ckpt")).unwrap(), held, "the checkpoint changed");
    assert!(!d.join("c.exr").exists());
    // Resumed under another spelling of the same file.
    std::fs::create_dir(d.join("sub")).unwrap();
    let other_spelling = d.join("sub/../c.ckpt").display().to_string();
    let o = render(&["--spp", "2", "--checkpoint-every", "0", "--resume", &other_spelling, "--out", &path("c.exr")]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(d.join("c.exr").exists() && !d.join("c.ckpt").exists());
    let _ = std::fs::remove_dir_all(&d);
}

/// `--strategies DIR` leaves exactly one render's strategy images there,
/// the ones its sidecar lists: a shallower render over a deeper one's
/// removes the images of strategies it has not (they were left, and a sum
/// over the directory mixed two renders). Other files stay, and an output
/// named like a strategy image in DIR is refused before rendering.
#[test]
fn strategy_images_are_one_renders() {
    let d = temp_dir("strategies");
    let scene = "scenes/cornell-box.json";
    let (dir, out) = (d.join("st").display().to_string(), d.join("img.exr").display().to_string());
    let render_with = |depth: &str, extra: &[&str]| {
        let args = ["render", scene, "--integrator", "bdpt", "--max-depth", depth, "--spp", "1", "--quiet"];
        let args = [&args[..], &["--width", "8", "--height", "8"], extra].concat();
        let o = prism(&[&args[..], &["--strategies", &dir, "--out", &out]].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        let sidecar: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join("img.json")).unwrap()).unwrap();
        let mut listed: Vec<String> =
            sidecar["strategy_images"].as_array().unwrap().iter().map(|v| v.as_str().unwrap().to_string()).collect();
        listed.sort();
        let mut here: Vec<String> = std::fs::read_dir(d.join("st"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n != "notes.txt")
            .collect();
        here.sort();
        assert_eq!(here, listed, "depth {depth}");
        assert_eq!(sidecar["strategy_records_dropped"]["infinite"], 0, "depth {depth}");
        listed
    };
    let render = |depth: &str| render_with(depth, &[]);
    let deep = render("3");
    std::fs::write(d.join("st/notes.txt"), b"not ours").unwrap();
    let shallow = render("1");
    assert!(shallow.len() < deep.len() && shallow.iter().all(|n| deep.contains(n)), "{shallow:?} / {deep:?}");
    assert!(d.join("st/notes.txt").exists());
    let clash = d.join("st/s0_t2_weighted.exr").display().to_string();
    let o = prism(&["render", scene, "--integrator", "bdpt", "--strategies", &dir, "--out", &clash, "--quiet"]);
    let e = stderr(&o);
    assert!(!o.status.success() && e.contains("is where --strategies writes a strategy's image"), "{e}");
    assert!(!e.contains("spp in"), "it rendered first: {e}");
    // The same clash named relative to the working directory.
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join(scene).display().to_string();
    let args = ["render", &scene, "--integrator", "bdpt", "--strategies", ".", "--out", "s0_t2_weighted.exr"];
    let o = Command::new(env!("CARGO_BIN_EXE_prism")).args(args).current_dir(d.join("st")).output().unwrap();
    let e = stderr(&o);
    assert!(!o.status.success() && e.contains("is where --strategies writes a strategy's image"), "{e}");
    // Paths longer than --strategies-max-length share one weighted image
    // (an audit, session 49: every length had its own, without bound), and
    // a bound whose images could not fit in memory is refused.
    let bounded = render_with("1024", &["--strategies-max-length", "1"]);
    let short = |n: &String| {
        let numbers = n.split(|c: char| !c.is_ascii_digit()).filter(|x| !x.is_empty());
        let st: Vec<u32> = numbers.map(|x| x.parse().unwrap()).collect();
        n == "longer_paths_weighted.exr" || (st.len() == 2 && st[0] + st[1] <= 3)
    };
    assert!(bounded.contains(&"longer_paths_weighted.exr".to_string()) && bounded.iter().all(short), "{bounded:?}");
    let refused = d.join("refused").display().to_string();
    let args = ["render", &scene, "--integrator", "bdpt", "--strategies", &refused, "--out", &out, "--quiet"];
    let o = prism(&[&args[..], &["--strategies-max-length", "4000000000"]].concat());
    let e = stderr(&o);
    assert!(!o.status.success() && e.contains("--strategies-max-length: the images of every strategy"), "{e}");
    assert!(!e.contains("spp in"), "it rendered first: {e}");
    assert!(!d.join("refused").exists(), "the refused render made its directory");
    let _ = std::fs::remove_dir_all(&d);
}

/// An export over an earlier one leaves exactly the meshes its scene.xml
/// names: an earlier export's higher-numbered `meshes/NNN.ply` are removed
/// (also past 999, which has four digits)
/// (Mitsuba would not read them, but a reader of the directory would), and
/// files the exporter does not name that way are kept.
#[test]
fn export_mitsuba_leaves_exactly_its_meshes() {
    let d = temp_dir("export-stale");
    let dir = d.join("export");
    let o = prism(&["export-mitsuba", "scenes/cornell-box.json", &dir.display().to_string()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let xml = std::fs::read_to_string(dir.join("scene.xml")).unwrap();
    let named = xml.matches("meshes/").count();
    assert!(named > 1, "{xml}");
    for stray in ["999.ply", "1000.ply", "notes.txt", "0001.ply"] {
        std::fs::write(dir.join("meshes").join(stray), b"not ours").unwrap();
    }
    let o = prism(&["export-mitsuba", "scenes/cornell-box.json", &dir.display().to_string()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let mut left: Vec<String> = std::fs::read_dir(dir.join("meshes"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    let mut want: Vec<String> = (0..named).map(|k| format!("{k:03}.ply")).collect();
    want.extend(["0001.ply".to_string(), "notes.txt".to_string()]);
    want.sort();
    assert_eq!(left, want);
    let _ = std::fs::remove_dir_all(&d);
}

/// The smaller subcommands refuse what they cannot do before writing
/// anything (from an audit): `export-mitsuba` of a non-diffuse scene used
/// to write some meshes first (over an earlier export's), and took a zero
/// width, zero spp and a scene depth cap it does not export; `compare` of
/// an image with NaN printed NaN with exit 0; `rgb-table --res 2` panicked.
#[test]
fn small_subcommands_refuse_before_writing() {
    let d = temp_dir("subcommands");
    let path = |name: &str| d.join(name).display().to_string();
    let fails_with = |args: &[&str], words: &str| {
        let o = prism(args);
        assert!(!o.status.success() && stderr(&o).contains(words), "{args:?}: {}", stderr(&o));
    };
    let export = path("export");
    let ok = prism(&["export-mitsuba", "scenes/cornell-box.json", &export, "--width", "8", "--height", "8"]);
    assert!(ok.status.success(), "{}", stderr(&ok));
    let mesh = std::fs::read(d.join("export/meshes/000.ply")).unwrap();
    fails_with(&["export-mitsuba", "scenes/cornell-glossy.json", &export], "only diffuse materials are exported");
    assert_eq!(std::fs::read(d.join("export/meshes/000.ply")).unwrap(), mesh, "a refused export replaced a mesh");
    let fresh = path("fresh");
    fails_with(&["export-mitsuba", "scenes/cornell-glossy.json", &fresh], "cannot export scenes/cornell-glossy.json");
    assert!(!d.join("fresh").exists(), "a refused export created its directory");
    fails_with(&["export-mitsuba", "scenes/cornell-box.json", &fresh, "--width", "0", "--height", "8"], "--width");
    fails_with(&["export-mitsuba", "scenes/cornell-box.json", &fresh, "--spp", "0"], "--spp must be at least 1");
    let capped = std::fs::read_to_string("scenes/cornell-box.json").unwrap().replacen(
        "\"render\": {",
        "\"render\": {\"max_depth\": 2, ",
        1,
    );
    let capped = write(&d, "capped.json", &capped);
    fails_with(&["export-mitsuba", &capped, &fresh], "render.max_depth 2 is not exported");
    assert!(!d.join("fresh").exists());

    let image = |name: &str, v: f32| {
        prism::output::write_exr(&d.join(name), 2, 1, &[[0.5; 3], [v; 3]]).unwrap();
        path(name)
    };
    let (one, nan) = (image("one.exr", 1.0), image("nan.exr", f32::NAN));
    fails_with(&["compare", &nan, &one], "nan.exr: 1 pixels are not finite (the first at x 1, y 0)");
    fails_with(&["compare", &one, &image("inf.exr", f32::INFINITY)], "inf.exr: 1 pixels are not finite");
    assert!(prism(&["compare", &one, &one]).status.success());
    fails_with(&["rgb-table", "--res", "2", "--out", &path("t.bin")], "2 is not in 3..=256");
    let scene = write(&d, "kept.json", "{}");
    fails_with(&["rgb-table", "--res", "3", "--out", &scene], "--out must name a .bin file, got");
    assert_eq!(std::fs::read_to_string(&scene).unwrap(), "{}", "rgb-table replaced a scene");
    // Checked before the fitting (minutes at --res 256), by the message
    // every other command gives.
    fails_with(&["rgb-table", "--res", "3", "--out", &path("nodir/t.bin")], "nodir does not exist");
    // A reference image beside a part's state would leave it stale.
    std::fs::write(d.join("r.state"), b"a part").unwrap();
    let out = path("r.exr");
    let reference = [
        "reference",
        "scenes/white-room.json",
        "--spp",
        "1",
        "--passes",
        "2",
        "--width",
        "8",
        "--height",
        "8",
        "--out",
        &out,
    ];
    fails_with(&reference, "r.state holds the samples of a part or a merge");
    assert!(!d.join("r.exr").exists());
    assert!(!d.join("t.bin").exists());
    let _ = std::fs::remove_dir_all(&d);
}

/// `prism reference` takes `--max-depth` and `--mis` as `render` does (it
/// took the depth from the scene alone, an audit found) and records both: the white room
/// (Le 0.5, albedo 0.8) cut at 2 scattering events reads
/// 0.5 (1 - 0.8^3) / 0.2 = 1.22, not its unbounded 2.5, and the sidecar
/// says so; a `--mis` for `path`, which reads none, is a warning.
#[test]
fn references_take_the_estimators_options() {
    let d = temp_dir("reference-depth");
    let out = d.join("r.exr");
    let small = ["--width", "8", "--height", "8", "--threads", "1", "--passes", "2"];
    let depth_2 = ["reference", "scenes/white-room.json", "--spp", "64", "--max-depth", "2", "--mis", "balance"];
    let o = prism(&[&depth_2[..], &small, &["--out", out.to_str().unwrap()]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("--mis sets bdpt's heuristic; path reads none"), "{}", stderr(&o));
    assert_eq!(read_json(&out.with_extension("json"))["max_depth"], 2);
    let (_, _, pixels) = prism::output::read_exr(&out).unwrap();
    // Luminance: the room's spectra are constant.
    let y = |p: &[f32; 3]| prism::stats::luminance(p.map(f64::from));
    let mean = pixels.iter().map(y).sum::<f64>() / pixels.len() as f64;
    assert!((mean - 1.22).abs() < 0.02, "the white room at depth 2 reads {mean}, not 1.22");
    assert_eq!(read_json(&out.with_extension("json"))["mis"], "power", "path reads no heuristic: the default");

    // bdpt's heuristic is recorded, and `converge` takes the reference's
    // noise floor from the line of that heuristic (it assumed the default).
    let bal = d.join("bal.exr");
    let reference = ["reference", "scenes/cornell-box.json", "--integrator", "bdpt", "--mis", "balance", "--spp", "2"];
    let o = prism(&[&reference[..], &small, &["--out", bal.to_str().unwrap()]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(read_json(&bal.with_extension("json"))["mis"], "balance");
    let conv = d.join("conv");
    let converge = ["converge", "scenes/cornell-box.json", "--integrators", "bdpt,bdpt:balance", "--reference"];
    let run = ["--spp", "2", "--width", "8", "--height", "8", "--threads", "1", "--out", conv.to_str().unwrap()];
    let o = prism(&[&converge[..], &[bal.to_str().unwrap()], &run].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let results = read_json(&conv.join("results.json"));
    assert_eq!(results["reference"]["mis"], "balance");
    assert_eq!(results["reference"]["noise_floor_method"], "same estimator (bdpt:balance)");
    let _ = std::fs::remove_dir_all(&d);
}
