//! Long renders (docs/cluster.md): `--passes` writes a mean and a variance
//! that agree with separately rendered passes; parts rendered with
//! `--sample-range` and merged, and renders killed (SIGKILL) and resumed
//! from checkpoints, are bit-identical to one uninterrupted render; merge
//! and resume refuse what does not belong together, and bad flags are
//! refused, with clear errors.

#[path = "common/scenes.rs"]
mod scenes;

use scenes::temp_dir;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

const SCENE: &str = "scenes/cornell-box.json";
const SMALL: [&str; 5] = ["--width", "32", "--height", "32", "--quiet"];

fn prism_command(args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_prism"));
    c.args(args).current_dir(env!("CARGO_MANIFEST_DIR"));
    c
}

fn prism(args: &[&str]) -> Output {
    prism_command(args).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

fn ok(args: &[&str]) {
    let o = prism(args);
    assert!(o.status.success(), "prism {args:?} failed: {}", stderr(&o));
}

/// Fails with the error message, which must be one `error:` line.
fn fails(args: &[&str]) -> String {
    let o = prism(args);
    assert!(!o.status.success(), "prism {args:?} succeeded but should not");
    let e = stderr(&o);
    assert_eq!(e.lines().filter(|l| l.starts_with("error:")).count(), 1, "{e}");
    e
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

fn render(integrator: &str, seed: u64, samples: &[&str], out: &Path) {
    let seed = seed.to_string();
    let mut args = vec!["render", SCENE, "--integrator", integrator, "--seed", &seed, "--out"];
    let out = s(out);
    args.push(&out);
    args.extend(SMALL);
    args.extend(samples);
    ok(&args);
}

fn read_exr(p: &Path) -> Vec<[f32; 3]> {
    prism::output::read_exr(p).unwrap().2
}

fn sidecar(exr: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(exr.with_extension("json")).unwrap()).unwrap()
}

/// `--passes K`: the mean and variance EXRs are those of K renders with
/// seeds seed..seed+K, and the variance predicts the spread of the mean
/// (two independent K-pass runs agree by a z-test built on it).
#[test]
fn passes_write_mean_and_consistent_variance() {
    const K: usize = 8;
    let d = temp_dir("passes");
    let run = |seed: u64, name: &str| {
        let out = d.join(name);
        render("path", seed, &["--spp", "4", "--passes", &K.to_string()], &out);
        let meta = sidecar(&out);
        let var_name = name.replace(".exr", ".var.exr");
        assert_eq!((meta["passes"].as_u64(), meta["variance"].as_str()), (Some(K as u64), Some(var_name.as_str())));
        (read_exr(&out), read_exr(&out.with_extension("var.exr")))
    };
    let (mean, var) = run(1, "a.exr");
    let passes: Vec<Vec<[f32; 3]>> = (0..K as u64)
        .map(|i| {
            let out = d.join(format!("pass{i}.exr"));
            render("path", 1 + i, &["--spp", "4"], &out);
            read_exr(&out)
        })
        .collect();
    for i in 0..mean.len() {
        for c in 0..3 {
            let xs = passes.iter().map(|p| p[i][c] as f64);
            let m = xs.clone().sum::<f64>() / K as f64;
            let v = xs.map(|x| (x - m).powi(2)).sum::<f64>() / (K - 1) as f64;
            assert!(
                (mean[i][c] as f64 - m).abs() <= 1e-6 * m.abs().max(1e-3),
                "mean at {i}.{c}: {} vs {m}",
                mean[i][c]
            );
            assert!(
                (var[i][c] as f64 - v).abs() <= 1e-5 * v.abs().max(1e-6),
                "variance at {i}.{c}: {} vs {v}",
                var[i][c]
            );
        }
    }
    // Pixels are independent, so the image mean of a K-pass mean has
    // variance sum(var) / (K N^2).
    let (mean2, var2) = run(1001, "b.exr");
    let n = mean.len() as f64;
    for c in 0..3 {
        let avg = |img: &[[f32; 3]]| img.iter().map(|p| p[c] as f64).sum::<f64>() / n;
        let se2 = |v: &[[f32; 3]]| v.iter().map(|p| p[c] as f64).sum::<f64>() / (K as f64 * n * n);
        let z = (avg(&mean) - avg(&mean2)) / (se2(&var) + se2(&var2)).sqrt();
        assert!(z.abs() < 4.0, "channel {c}: the two runs differ by z = {z:.2}");
        assert!(avg(&var) > 0.0, "channel {c}: zero variance: the passes are not independent");
    }
    let _ = std::fs::remove_dir_all(&d);
}

/// Renders `ranges` of one image as parts, on 1 and 2 threads in turn (the
/// parts of a cluster come from any machine), merges them (in shuffled
/// order) and returns the merged EXR's path.
fn merge_parts(d: &Path, integrator: &str, ranges: &[(u32, u32)]) -> PathBuf {
    let mut parts = Vec::new();
    for (i, &(a, b)) in ranges.iter().enumerate() {
        let out = d.join(format!("{integrator}_{a}_{b}.exr"));
        let threads = (1 + i % 2).to_string();
        render(integrator, 7, &["--sample-range", &format!("{a}..{b}"), "--threads", &threads], &out);
        assert_eq!(sidecar(&out)["spp"], b - a);
        parts.push(s(&out));
    }
    parts.reverse();
    let merged = d.join(format!("{integrator}_merged.exr"));
    let mut args = vec!["merge".to_string(), s(&merged)];
    args.extend(parts);
    ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    merged
}

/// Four parts of 16 spp merged are bit-identical to one 64-spp render, for
/// camera samples (path), splats (light) and both (bdpt); so is an uneven
/// split.
#[test]
fn merged_parts_are_bit_identical_to_one_render() {
    let d = temp_dir("merge");
    for integrator in ["path", "light", "bdpt"] {
        let full = d.join(format!("{integrator}_full.exr"));
        render(integrator, 7, &["--spp", "64"], &full);
        let merged = merge_parts(&d, integrator, &[(0, 16), (16, 32), (32, 48), (48, 64)]);
        assert_eq!(
            std::fs::read(&merged).unwrap(),
            std::fs::read(&full).unwrap(),
            "{integrator}: merged != one render"
        );
        let meta = sidecar(&merged);
        assert_eq!((meta["spp"].as_u64(), meta["sample_ranges"].to_string()), (Some(64), "[[0,64]]".to_string()));
    }
    let full = d.join("path_full.exr");
    let uneven = merge_parts(&d, "path", &[(0, 5), (5, 6), (6, 41), (41, 64)]);
    assert_eq!(std::fs::read(&uneven).unwrap(), std::fs::read(&full).unwrap(), "uneven split != one render");
    let _ = std::fs::remove_dir_all(&d);
}

/// Merge refuses parts of different scenes, seeds or integrators, and parts
/// whose samples overlap, naming the files and the field; it writes nothing.
#[test]
fn merge_refuses_mismatched_parts() {
    let d = temp_dir("refuse");
    let part = |name: &str, scene: &str, integrator: &str, seed: &str, range: &str| {
        let out = d.join(name);
        ok(&["render", scene, "--integrator", integrator, "--seed", seed, "--sample-range", range, "--out", &s(&out)]
            .into_iter()
            .chain(SMALL)
            .collect::<Vec<_>>());
        s(&out)
    };
    let other_scene = d.join("other.json");
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(SCENE)).unwrap();
    std::fs::write(&other_scene, text.replacen("39.3077", "39.4", 1)).unwrap();
    let a = part("a.exr", SCENE, "path", "1", "0..4");
    // (Neutral file names: the field must be named by the message, not by
    // the path in it; a review, session 55.)
    let cases = [
        (part("b1.exr", SCENE, "path", "2", "4..8"), "has seed 2 but"),
        (part("b2.exr", SCENE, "light", "1", "4..8"), "has integrator \"light\" but"),
        (part("b3.exr", &s(&other_scene), "path", "1", "4..8"), "has scene_hash"),
        (part("b4.exr", SCENE, "path", "1", "2..6"), "has samples 2..6, which overlap"),
    ];
    let out = d.join("merged.exr");
    for (b, what) in &cases {
        let e = fails(&["merge", &s(&out), &a, b]);
        let b_state = Path::new(b).with_extension("state");
        assert!(e.contains(what) && e.contains(&s(&b_state)), "{what}: {e}");
        assert!(!out.exists() && !out.with_extension("state").exists(), "{what}: merge wrote output");
    }
    // The control: a matching part merges.
    let good = part("good.exr", SCENE, "path", "1", "4..8");
    ok(&["merge", &s(&out), &a, &good]);
    let _ = std::fs::remove_dir_all(&d);
}

/// A render checkpointing after every chunk (8 samples per pixel), killed (SIGKILL) at
/// random times and resumed until it finishes, gives the bits of an
/// uninterrupted render. The kill times come from the clock, as fractions
/// of the time the uninterrupted render took on this host (they were fixed
/// times, 20-250 ms, which a host slow enough to take its first checkpoint
/// after 250 ms turned into a failure; from an audit, session 50); the
/// seed is printed so that a failure can be replayed. A render that
/// finished before its kill without being interrupted starts again.
#[test]
fn killed_and_resumed_render_is_bit_identical() {
    let d = temp_dir("kill");
    let full = d.join("full.exr");
    let started = Instant::now();
    render("bdpt", 3, &["--spp", "128"], &full);
    let whole = started.elapsed();
    let out = d.join("killed.exr");
    let checkpoint = out.with_extension("ckpt");
    let mut rng = SystemTime::now().duration_since(UNIX_EPOCH).unwrap().as_nanos() as u64 | 1;
    eprintln!("kill-time seed {rng}; the whole render took {whole:?}");
    let (mut kills, mut resumes, mut restarts) = (0, 0, 0);
    loop {
        let mut args = vec!["render", SCENE, "--integrator", "bdpt", "--seed", "3", "--spp", "128"];
        args.extend(SMALL);
        let (out_s, ckpt_s) = (s(&out), s(&checkpoint));
        args.extend(["--out", &out_s, "--checkpoint-every", "0"]);
        if checkpoint.exists() {
            args.extend(["--resume", &ckpt_s]);
            resumes += 1;
        }
        let mut child = prism_command(&args).stderr(std::process::Stdio::piped()).spawn().unwrap();
        // xorshift64: a kill time in 5-55 % of the whole render's time, or
        // none after 30 kills.
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        let delay = whole.mul_f64(0.05 + 0.5 * (rng % 1024) as f64 / 1024.0);
        let kill_at = (kills < 30).then(|| Instant::now() + delay);
        let finished = loop {
            if let Some(status) = child.try_wait().unwrap() {
                let o = child.wait_with_output().unwrap();
                assert!(status.success(), "run {} failed: {}", kills + 1, stderr(&o));
                break true;
            }
            if kill_at.is_some_and(|t| Instant::now() >= t) {
                child.kill().unwrap();
                child.wait().unwrap();
                kills += 1;
                // Removing the checkpoint is a render's last act: a kill
                // that lands after it (or after the exit) finds the
                // outputs complete, and a rerun would rightly refuse them.
                break !checkpoint.exists() && out.exists();
            }
            std::thread::sleep(Duration::from_millis(2));
        };
        if finished && resumes == 0 {
            // Nothing was interrupted: start again.
            restarts += 1;
            assert!(restarts < 20, "the render always finished before its kill time");
            for f in [out.clone(), out.with_extension("json")] {
                std::fs::remove_file(f).unwrap();
            }
            continue;
        }
        if finished {
            break;
        }
    }
    eprintln!("{kills} kills, {resumes} resumes");
    assert!(kills >= 1 && resumes >= 1, "{kills} kills and {resumes} resumes: nothing was tested");
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&full).unwrap(), "resumed render != uninterrupted one");
    assert_eq!(sidecar(&out)["spp"], 128);
    assert!(!checkpoint.exists(), "the checkpoint outlived the finished render");
    let _ = std::fs::remove_dir_all(&d);
}

/// A checkpointed render of the most samples a pixel can take (2^32 - 1)
/// starts, and takes its first checkpoint: its chunks (8 samples each) are made
/// as they come. (A list of them all, 32 GiB, was refused by the allocator
/// and the process aborted before rendering.)
#[test]
fn checkpointed_render_of_2_pow_32_samples_starts() {
    let d = temp_dir("huge-spp");
    let out = d.join("huge.exr");
    let checkpoint = out.with_extension("ckpt");
    let out_s = s(&out);
    let mut args = vec!["render", SCENE, "--spp", "4294967295", "--checkpoint-every", "0", "--out", &out_s];
    args.extend(["--width", "8", "--height", "8", "--quiet"]);
    let mut child = prism_command(&args).stderr(std::process::Stdio::piped()).spawn().unwrap();
    let deadline = Instant::now() + Duration::from_secs(60);
    while !checkpoint.exists() {
        if let Some(status) = child.try_wait().unwrap() {
            let o = child.wait_with_output().unwrap();
            panic!("the render ended ({status}) before its first checkpoint: {}", stderr(&o));
        }
        assert!(Instant::now() < deadline, "no checkpoint after 60 s");
        std::thread::sleep(Duration::from_millis(10));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let _ = std::fs::remove_dir_all(&d);
}

/// A truncated, corrupt, foreign or mismatched checkpoint is one clear error
/// naming the file, and nothing is written; the intact file resumes (a
/// part's .state is a checkpoint too) to the bits of a full render.
#[test]
fn bad_checkpoints_are_clear_errors() {
    let d = temp_dir("corrupt");
    let part = d.join("part.exr");
    render("path", 4, &["--sample-range", "0..16"], &part);
    let later = d.join("later.exr");
    render("path", 4, &["--sample-range", "16..32"], &later);
    let full = d.join("full.exr");
    render("path", 4, &["--spp", "64"], &full);
    let good = std::fs::read(part.with_extension("state")).unwrap();
    let out = d.join("out.exr");
    let resume = |checkpoint: &Path, seed: &str| {
        let (c, o) = (s(checkpoint), s(&out));
        let mut args = vec!["render", SCENE, "--seed", seed, "--spp", "64", "--resume", &c, "--out", &o];
        args.extend(SMALL);
        args.into_iter().map(String::from).collect::<Vec<_>>()
    };
    let mut future = good.clone();
    future[8] = 9;
    let mut flipped = good.clone();
    flipped[good.len() / 2] ^= 0x10;
    let damaged: [(&str, &[u8], &str); 5] = [
        ("truncated", &good[..good.len() - 100], "checksum"),
        ("flipped", &flipped, "checksum"),
        ("empty", b"", "magic"),
        ("foreign", &std::fs::read(&full).unwrap(), "magic"),
        ("future", &future, "version 9"),
    ];
    let check = |args: Vec<String>, file: &Path, what: &str| {
        let e = fails(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert!(e.contains(&s(file)) && e.contains(what), "{what}: {e}");
        assert!(!out.exists(), "{what}: an output was written");
    };
    for (name, bytes, what) in damaged {
        let path = d.join(format!("{name}.ckpt"));
        std::fs::write(&path, bytes).unwrap();
        check(resume(&path, "4"), &path, what);
    }
    check(resume(&part.with_extension("state"), "5"), &part.with_extension("state"), "seed");
    check(resume(&later.with_extension("state"), "4"), &later.with_extension("state"), "not the first samples");
    // More samples than the render asks for is said as such, not as a gap.
    let mut fewer = resume(&part.with_extension("state"), "4");
    let spp = fewer.iter().position(|a| a == "--spp").unwrap() + 1;
    fewer[spp] = "8".to_string();
    check(fewer, &part.with_extension("state"), "more than this render's 0..8: ask for samples up to 16");
    let args = resume(&part.with_extension("state"), "4");
    ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&full).unwrap(), "resumed part != full render");
    let _ = std::fs::remove_dir_all(&d);
}

/// Bad long-render flags are one clear error each, before anything is
/// rendered or written.
#[test]
fn bad_flags_are_clear_errors() {
    let d = temp_dir("flags");
    let out = s(&d.join("out.exr"));
    let cases: [(&[&str], &str); 6] = [
        (&["--passes", "1"], "--passes must be at least 2"),
        (&["--sample-range", "8..8"], "expected A..B"),
        (&["--sample-range", "0-8"], "expected A..B"),
        (&["--sample-range", "0..8", "--spp", "8"], "cannot be used with"),
        (&["--passes", "4", "--sample-range", "0..8"], "cannot be used with"),
        (&["--checkpoint-every", "NaN"], "--checkpoint-every must be"),
    ];
    for (flags, what) in cases {
        let mut args = vec!["render", SCENE, "--out", &out];
        args.extend(SMALL);
        args.extend(flags);
        let e = fails(&args);
        assert!(e.contains(what), "{flags:?}: {e}");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 0, "{flags:?}: something was written");
    }
    let _ = std::fs::remove_dir_all(&d);
}
