//! A small file mapped into memory and shared between processes: the snapshots, a reader's
//! sleep mark, the bench's raw floor. On tmpfs (the run's private folder), it is shared memory.

use std::path::Path;

use anyhow::{Context as _, Result, anyhow};

/// How the file is opened.
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum Open {
    /// Created if missing; kept (not truncated) if there.
    OrCreate,
    /// Created; an existing file is an error.
    New,
    /// Must exist.
    Existing,
}

/// A mapping of `len` bytes of the file at `path`, read-write and shared, never through a
/// symbolic link, the owner's alone. The file is zero-filled where new. The caller unmaps it
/// ([`unmap`]) when done.
pub fn map(path: &Path, len: usize, open: Open) -> Result<*mut libc::c_void> {
    use std::os::fd::AsRawFd;
    use std::os::unix::fs::OpenOptionsExt;
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(open == Open::OrCreate)
        .create_new(open == Open::New)
        .truncate(false)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(path)
        .with_context(|| format!("open {}", path.display()))?;
    if open != Open::Existing {
        file.set_len(len as u64).with_context(|| format!("size {}", path.display()))?;
    }
    // SAFETY: a shared mapping of a file we opened and sized; the mapping outlives the file
    // descriptor, which is closed on return.
    let ptr = unsafe {
        libc::mmap(std::ptr::null_mut(), len, libc::PROT_READ | libc::PROT_WRITE, libc::MAP_SHARED, file.as_raw_fd(), 0)
    };
    if ptr == libc::MAP_FAILED {
        return Err(anyhow!("cannot map {}: {}", path.display(), std::io::Error::last_os_error()));
    }
    Ok(ptr)
}

/// Unmaps what [`map`] mapped.
///
/// # Safety
/// `ptr` and `len` are a mapping from [`map`] that nothing uses any more.
pub unsafe fn unmap(ptr: *mut libc::c_void, len: usize) {
    // SAFETY: as the caller promises.
    unsafe { libc::munmap(ptr, len) };
}
