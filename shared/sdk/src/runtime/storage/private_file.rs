//! A small file of the run's private folder (on tmpfs, mode 0700) that one process rewrites and
//! another reads: written whole under another name and renamed into place, so a reader never
//! sees half of it (a writer killed mid-write leaves the previous one whole); owner-only, never
//! through a symbolic link.

use std::io::{Read, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;

use anyhow::{Context as _, Result};

fn options() -> std::fs::OpenOptions {
    let mut options = std::fs::OpenOptions::new();
    options.mode(0o600).custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC);
    options
}

/// Replaces `path` with `bytes`, whole or not at all.
pub fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    let fresh = path.with_extension("new");
    // Ours to truncate: the folder is private, so a file there was a writer's killed mid-write.
    let mut file = options()
        .write(true)
        .create(true)
        .truncate(true)
        .open(&fresh)
        .with_context(|| format!("create {}", fresh.display()))?;
    file.write_all(bytes).with_context(|| format!("write {}", fresh.display()))?;
    drop(file);
    std::fs::rename(&fresh, path).with_context(|| format!("rename {} to {}", fresh.display(), path.display()))
}

/// What `path` holds; None if nothing was written yet.
pub fn read(path: &Path) -> Result<Option<Vec<u8>>> {
    let mut file = match options().read(true).open(path) {
        Ok(file) => file,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e).with_context(|| format!("open {}", path.display())),
    };
    let mut bytes = vec![];
    file.read_to_end(&mut bytes).with_context(|| format!("read {}", path.display()))?;
    Ok(Some(bytes))
}
