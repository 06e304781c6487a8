//! Tells the crate the git commit it is built from (`LOOPLAB_GIT_COMMIT`, for `summary.json`):
//! `git rev-parse HEAD`, with "-dirty" when the work tree has changes, or "unknown" without git
//! or a repository.

use std::path::Path;
use std::process::Command;

/// What `git ARGS` prints, trimmed; None if git is missing or fails (no repository).
fn git(args: &[&str]) -> Option<String> {
    // No optional locks: `git status` must not rewrite the index while cargo builds.
    let output = Command::new("git").args(args).env("GIT_OPTIONAL_LOCKS", "0").output().ok()?;
    output.status.success().then(|| String::from_utf8_lossy(&output.stdout).trim().to_owned())
}

fn main() {
    let commit = match git(&["rev-parse", "HEAD"]) {
        Some(head) if !head.is_empty() => {
            let dirty = git(&["status", "--porcelain"]).is_some_and(|changes| !changes.is_empty());
            if dirty { format!("{head}-dirty") } else { head }
        }
        _ => "unknown".to_owned(),
    };
    println!("cargo:rustc-env=LOOPLAB_GIT_COMMIT={commit}");

    // Rerun when HEAD moves (a commit changes the branch it points to, a checkout HEAD itself)
    // and when this crate's sources change (which rebuilds it anyway, so "-dirty" follows edits
    // here for free). Git names the files, so that a worktree's own HEAD is the one watched.
    // Only files that exist: cargo would rerun on every build for a missing one.
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=src");
    let branch = git(&["symbolic-ref", "-q", "HEAD"]);
    for name in ["HEAD", "packed-refs"].into_iter().chain(branch.as_deref()) {
        if let Some(path) = git(&["rev-parse", "--git-path", name])
            && Path::new(&path).exists()
        {
            println!("cargo:rerun-if-changed={path}");
        }
    }
}
