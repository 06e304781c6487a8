//! `[stages.<role>] build`: a stage's build command, run in the stage's folder before the run,
//! and skipped when nothing it names has changed since it last succeeded.
//!
//! ```toml
//! [stages.controller]
//! build = ["cc", "-O2", "my_controller.c", "-o", "my_controller"]   # run before the run
//! command = ["./my_controller"]
//! ```
//!
//! Its inputs are the files the command names (every argument that is a file in the stage's
//! folder: the sources, and the program it wrote) and the stage's program, by content. A build
//! that names none (`make`, which finds its own inputs) runs every time; so does one whose inputs
//! changed or whose program is gone. Launches that build the same stage at once take turns.

use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

/// What [`build`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Built {
    /// The command ran and succeeded.
    Ran,
    /// Nothing it names changed since it last succeeded: it did not run.
    Unchanged,
}

/// Runs `build` (the program, then its arguments) in `dir` unless its inputs are those of its
/// last success; `program` is the stage's program, which the build makes. Err: the command and
/// why it failed (its first line that names an error, else its last).
pub fn build(build: &[String], dir: &Path, program: Option<&Path>) -> Result<Built, String> {
    let text = build.join(" ");
    let stamps = stamp_folder().map_err(|e| format!("cannot keep the build's stamp: {e}"))?;
    let key = hex(&Sha256::digest(format!("{}\0{}", dir.display(), build.join("\0")))[..16]);
    // Concurrent launches of one stage (a sweep, tests) must not write one program at once.
    let _turn = Turn::take(&stamps.join(format!("{key}.lock")))?;
    let stamp = stamps.join(key);
    let (named, before) = inputs(build, dir, program);
    if named && std::fs::read_to_string(&stamp).is_ok_and(|last| last == before) {
        return Ok(Built::Unchanged);
    }
    let output = std::process::Command::new(&build[0])
        .args(&build[1..])
        .current_dir(dir)
        .stdin(std::process::Stdio::null())
        .output()
        .map_err(|e| format!("cannot run `{text}` in {}: {e}", dir.display()))?;
    if !output.status.success() {
        let said = String::from_utf8_lossy(&output.stderr) + String::from_utf8_lossy(&output.stdout);
        let lines = || said.lines().map(str::trim).filter(|l| !l.is_empty());
        // A compiler's first error says what is wrong; its last line is often a caret or a count.
        let why = lines().find(|l| l.contains("error")).or_else(|| lines().next_back()).unwrap_or("no output");
        return Err(format!("`{text}` failed ({}): {why}", output.status));
    }
    let (named, after) = inputs(build, dir, program);
    if named {
        std::fs::write(&stamp, after).map_err(|e| format!("cannot write {}: {e}", stamp.display()))?;
    }
    Ok(Built::Ran)
}

/// Whether the build names a file, and the hash of every file it names and of the program.
fn inputs(build: &[String], dir: &Path, program: Option<&Path>) -> (bool, String) {
    let mut hash = Sha256::new();
    hash.update(build.join("\0"));
    let mut named = false;
    for arg in &build[1..] {
        let path = dir.join(arg);
        if path.is_file()
            && let Ok(bytes) = std::fs::read(&path)
        {
            named = true;
            hash.update(format!("\0{arg}\0{}\0", bytes.len()));
            hash.update(bytes);
        }
    }
    match program.map(std::fs::read) {
        Some(Ok(bytes)) => hash.update(bytes),
        // A program that is gone must be made again.
        _ => hash.update("\0no program\0"),
    }
    (named, hex(&hash.finalize()))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// `$XDG_CACHE_HOME/looplab/builds`, else `~/.cache/looplab/builds`, else one in the temporary
/// folder of this user's own.
fn stamp_folder() -> std::io::Result<PathBuf> {
    let cache = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|home| PathBuf::from(home).join(".cache")))
        // SAFETY: geteuid has no preconditions.
        .unwrap_or_else(|| std::env::temp_dir().join(format!("looplab-cache-{}", unsafe { libc::geteuid() })));
    let folder = cache.join("looplab").join("builds");
    std::fs::create_dir_all(&folder)?;
    Ok(folder)
}

/// An exclusive lock on a file, held until dropped (closing the file lets it go).
struct Turn {
    _file: std::fs::File,
}

impl Turn {
    fn take(path: &Path) -> Result<Self, String> {
        use std::os::fd::AsRawFd;
        let file = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(path)
            .map_err(|e| format!("cannot open {}: {e}", path.display()))?;
        // SAFETY: a valid descriptor; the lock goes with it when the file closes.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX) } != 0 {
            return Err(format!("cannot lock {}: {}", path.display(), std::io::Error::last_os_error()));
        }
        Ok(Self { _file: file })
    }
}
