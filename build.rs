//! Records the git commit the binary was built from (for render sidecars),
//! and warns of an x86-64 build without the x86-64-v3 level that
//! `.cargo/config.toml` asks for.
fn main() {
    warn_without_x86_64_v3();
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    let commit = git(&["rev-parse", "--short=12", "HEAD"]).unwrap_or_else(|| "unknown".to_string());
    println!("cargo:rustc-env=PRISM_COMMIT={commit}");
    // Rerun when HEAD moves. In a worktree `.git` is a file and HEAD lives
    // in the worktree's own git directory, the branch refs in the common
    // one: asking git for both, and watching only paths that exist, keeps
    // cargo from watching a missing path (which would rerun this script,
    // and rebuild the crate, on every build).
    if let (Some(dir), Some(common)) = (git(&["rev-parse", "--git-dir"]), git(&["rev-parse", "--git-common-dir"])) {
        for path in [format!("{dir}/HEAD"), format!("{common}/refs/heads"), format!("{common}/packed-refs")] {
            if std::path::Path::new(&path).exists() {
                println!("cargo:rerun-if-changed={path}");
            }
        }
    }
}

/// Cargo reads `.cargo/config.toml` from the directory it runs in and its
/// parents, so `cargo build --manifest-path .../Cargo.toml` run from
/// elsewhere (or a RUSTFLAGS that replaces the file's flags) builds for
/// baseline x86-64: `light` ran 33 % more instructions so (session 60),
/// and its images are not the x86-64-v3 build's bit for bit (the
/// sidecar's `build_target`).
fn warn_without_x86_64_v3() {
    let arch = std::env::var("CARGO_CFG_TARGET_ARCH").unwrap_or_default();
    let features = std::env::var("CARGO_CFG_TARGET_FEATURE").unwrap_or_default();
    let has = |f: &str| features.split(',').any(|x| x == f);
    if arch == "x86_64" && !(has("avx2") && has("fma")) {
        println!(
            "cargo:warning=prism is being built without AVX2/FMA (x86-64-v3): .cargo/config.toml was not read \
             (cargo reads it from the directory it runs in) or RUSTFLAGS replaced it; expect a slower binary \
             whose images differ in rounding from the x86-64-v3 build's (intended on a CPU without AVX2)"
        );
    }
}
