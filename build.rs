//! Records the git commit the binary was built from (for render sidecars).
fn main() {
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
