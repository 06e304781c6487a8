//! The run folder: creating it, naming the run, and writing its files whole or not at all.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result, bail};

use crate::config::launch::{LaunchConfig, run_vectors};
use crate::contract::run_format::files;
use crate::model::scenario::Scenario;
use crate::runtime::storage::run_file;

/// Begins a run in its folder: writes the resolved `launch.toml` (the file the processes load)
/// and returns its path and the wall-clock start (UTC, RFC 3339) for the summary.
pub fn begin_run(run_dir: &Path, config: &LaunchConfig, scenario: &dyn Scenario) -> Result<(PathBuf, String)> {
    let launch_file = run_dir.join(files::LAUNCH);
    write_atomically(&launch_file, &run_vectors::run_toml(config, &scenario.input_limits(), run_dir))?;
    Ok((launch_file, chrono::Utc::now().to_rfc3339_opts(chrono::SecondsFormat::Secs, true)))
}

/// Creates the run folder with its `logs/`: `out` if given (new or empty), else a new
/// `runs/<time>-<scenario>`, which `runs/latest` then points at.
pub fn create_run_dir(out: Option<&Path>, scenario: &str) -> Result<PathBuf> {
    let dir = match out {
        Some(dir) => {
            check_own_folder(dir, "--out")?;
            check_folders_above(dir, "--out")?;
            if dir.exists() && !dir.is_dir() {
                bail!("--out {}: is a file, not a folder; give a new or empty folder", dir.display());
            }
            if dir.exists() && std::fs::read_dir(dir).map(|mut d| d.next().is_some()).unwrap_or(true) {
                bail!("--out {}: the folder exists and is not empty; give a new or empty folder", dir.display());
            }
            std::fs::create_dir_all(dir).with_context(|| format!("cannot create the run folder {}", dir.display()))?;
            dir.to_path_buf()
        }
        None => {
            let stamp = chrono::Local::now().format("%Y%m%d-%H%M%S");
            let base = PathBuf::from("runs").join(format!("{stamp}-{scenario}"));
            std::fs::create_dir_all("runs").context("cannot create the runs folder")?;
            check_own_folder(Path::new("runs"), "the runs folder")?;
            check_folders_above(Path::new("runs"), "the runs folder")?;
            // Claim a new folder atomically: two runs started in the same second get two.
            let mut n = 1;
            loop {
                let dir = if n == 1 { base.clone() } else { PathBuf::from(format!("{}-{n}", base.display())) };
                match std::fs::create_dir(&dir) {
                    Ok(()) => {
                        point_latest_at(&dir)?;
                        break dir;
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => n += 1,
                    Err(e) => return Err(e).with_context(|| format!("cannot create the run folder {}", dir.display())),
                }
            }
        }
    };
    // The run claims its folder by making `logs/` in it, which only one can: a second run given
    // the same empty `--out` at the same moment is refused, not mixed in.
    match std::fs::create_dir(dir.join(files::LOGS)) {
        Ok(()) => Ok(dir),
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            bail!(
                "--out {}: another run took the folder as this one started; give a new or empty folder",
                dir.display()
            )
        }
        Err(e) => Err(e).with_context(|| format!("cannot create the run folder {}", dir.display())),
    }
}

/// An existing `--out` folder (or `runs/`, `what` says which) must be the user's own, and no one
/// else's to write in: another user could put links there (`trajectory.csv` → a file of ours)
/// between our check and our writes, or swap a run's folder for one of their own.
/// `runs/` may be a link of the user's own to a folder elsewhere; that folder is checked then.
fn check_own_folder(dir: &Path, what: &str) -> Result<()> {
    use std::os::unix::fs::MetadataExt;
    let Ok(mut meta) = std::fs::symlink_metadata(dir) else { return Ok(()) };
    // SAFETY: geteuid has no preconditions.
    let me = unsafe { libc::geteuid() };
    if meta.file_type().is_symlink() {
        if what == "--out" || meta.uid() != me {
            bail!("{what} {}: is a symbolic link; give the folder itself", dir.display());
        }
        meta = std::fs::metadata(dir).with_context(|| format!("{what} {}", dir.display()))?;
    }
    if meta.uid() != me {
        bail!(
            "{what} {}: the folder belongs to another user (uid {}); give a folder of your own",
            dir.display(),
            meta.uid()
        );
    }
    if meta.mode() & 0o022 != 0 {
        bail!(
            "{what} {}: others may write in the folder (mode {:o}); give a folder only you can write in",
            dir.display(),
            meta.mode() & 0o777
        );
    }
    Ok(())
}

/// Every folder above `dir` must be out of other users' reach: owned by the user or root, and
/// writable by no one else unless sticky (as /tmp), where only an entry's owner may rename it.
/// Else another user could rename the run folder (or a folder above it) mid-run and put a link
/// to a folder of their choosing in its place, and the run would write its files there.
fn check_folders_above(dir: &Path, what: &str) -> Result<()> {
    use std::os::unix::fs::MetadataExt;
    let absolute = std::path::absolute(dir).with_context(|| format!("{what} {}", dir.display()))?;
    // SAFETY: geteuid has no preconditions.
    let me = unsafe { libc::geteuid() };
    for folder in absolute.ancestors().skip(1) {
        // Not there yet: made by this run, as the user.
        let Ok(meta) = std::fs::metadata(folder) else { continue };
        let others_write = meta.mode() & 0o022 != 0 && meta.mode() & 0o1000 == 0;
        if (meta.uid() != me && meta.uid() != 0) || others_write {
            bail!(
                "{what} {}: {} is {}; another user could swap the run folder for a link mid-run; give a folder \
                 under folders only you (or root) can write in",
                dir.display(),
                folder.display(),
                if others_write {
                    format!("writable by others without the sticky bit (mode {:o})", meta.mode() & 0o7777)
                } else {
                    format!("another user's (uid {})", meta.uid())
                }
            );
        }
    }
    Ok(())
}

/// Points `runs/latest` at `dir`, a folder in `runs/`: a relative link, replaced atomically
/// (a new link renamed over the old), so it always names a whole run folder.
fn point_latest_at(dir: &Path) -> Result<()> {
    let runs = dir.parent().context("a run folder in runs/")?;
    let name = dir.file_name().context("a run folder in runs/")?;
    let link = runs.join("latest");
    let next = runs.join(format!(".latest-{}", std::process::id()));
    let _ = std::fs::remove_file(&next);
    std::os::unix::fs::symlink(name, &next)
        .and_then(|()| std::fs::rename(&next, &link))
        .with_context(|| format!("cannot point {} at {}", link.display(), dir.display()))
}

/// A new run id: 64 random bits from the kernel, so that no one can guess the names of a run's
/// files before it creates them.
pub fn new_run_id() -> String {
    let mut bytes = [0u8; 8];
    // SAFETY: getrandom writes at most `bytes.len()` bytes into the buffer.
    let n = unsafe { libc::getrandom(bytes.as_mut_ptr().cast(), bytes.len(), 0) };
    assert_eq!(n, bytes.len() as isize, "the kernel's random source failed");
    format!("{:016x}", u64::from_ne_bytes(bytes))
}

/// Writes a file whole or not at all: a failed write (a full disk) leaves no truncated file
/// behind that a script could take for the real one, and says which file it was.
pub fn write_atomically(path: &Path, contents: &str) -> Result<()> {
    let partial = path.with_extension("partial");
    // A link planted as `partial` is refused (and left), never written through; one planted as
    // `path` is replaced by the rename, which does not follow it. Any other failure (a full
    // disk, a removed folder) names the file the user knows.
    let written = run_file::open_io(&partial, run_file::Existing::Replace)
        .and_then(|mut file| std::io::Write::write_all(&mut file, contents.as_bytes()));
    if let Err(e) = written {
        if e.raw_os_error() == Some(libc::ELOOP) {
            return Err(run_file::refused(&partial, e));
        }
        let _ = std::fs::remove_file(&partial);
        bail!("cannot write {}: {e}", path.display());
    }
    if let Err(e) = std::fs::rename(&partial, path) {
        let _ = std::fs::remove_file(&partial);
        bail!("cannot write {}: {e}", path.display());
    }
    Ok(())
}
