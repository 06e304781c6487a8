//! A process's snapshot in shared memory: what a restarted process needs to go on where the
//! last one stopped. The plant keeps the truth in one (the physical system does not stop when
//! its simulator dies), the estimator its slow calibration states.
//!
//! The file is in the run's private folder on tmpfs ([`crate::ipc::run_folder`]), so no other
//! user can read or forge it, the launcher's leftover check covers it and its clean-up removes it.

use std::path::PathBuf;

use anyhow::{Context as _, Result, anyhow};

fn path(run_id: &str, process: &str) -> Result<PathBuf> {
    let folder = crate::ipc::run_folder(run_id);
    crate::ipc::check_private(&folder)?;
    Ok(folder.join(format!("{process}.snapshot")))
}

/// Two slots written in turn, each between two copies of its sequence number: a kill in the
/// middle of a write leaves the other slot whole, and the reader takes the newest whole one.
#[repr(C)]
struct Slot<T> {
    begin: u64,
    data: T,
    end: u64,
}

pub struct Snapshot<T> {
    slots: *mut [Slot<T>; 2],
    sequence: u64,
}

impl<T: Copy> Snapshot<T> {
    /// Opens (or creates) the snapshot of `process` in run `run_id`.
    pub fn open(run_id: &str, process: &str) -> Result<Self> {
        use std::os::fd::AsRawFd;
        use std::os::unix::fs::OpenOptionsExt;
        let path = &path(run_id, process)?;
        // Never through a symbolic link, and the owner's alone.
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .mode(0o600)
            .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
            .open(path)
            .with_context(|| format!("open {}", path.display()))?;
        let size = std::mem::size_of::<[Slot<T>; 2]>();
        file.set_len(size as u64).with_context(|| format!("size {}", path.display()))?;
        // SAFETY: a shared mapping of a file we sized to hold the slots; only one process at a
        // time writes it, and it stays mapped for the life of `Snapshot`.
        let ptr = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                size,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_SHARED,
                file.as_raw_fd(),
                0,
            )
        };
        if ptr == libc::MAP_FAILED {
            return Err(anyhow!("cannot map {}: {}", path.display(), std::io::Error::last_os_error()));
        }
        let mut snapshot = Self { slots: ptr.cast(), sequence: 0 };
        snapshot.sequence = snapshot.newest().map_or(0, |(seq, _)| seq);
        Ok(snapshot)
    }

    /// The newest whole slot and its sequence number.
    fn newest(&self) -> Option<(u64, T)> {
        // SAFETY: the mapping holds two slots; volatile reads because another process wrote them.
        let slots = unsafe { std::ptr::read_volatile(self.slots) };
        slots.iter().filter(|s| s.begin == s.end && s.begin > 0).max_by_key(|s| s.begin).map(|s| (s.begin, s.data))
    }

    /// The newest whole snapshot, if one was ever written.
    pub fn read(&self) -> Option<T> {
        self.newest().map(|(_, data)| data)
    }

    pub fn write(&mut self, data: &T) {
        use std::sync::atomic::{Ordering, compiler_fence};
        self.sequence += 1;
        let seq = self.sequence;
        // SAFETY: the slot is inside our mapping; the fences keep `begin`, the data and `end` in
        // that order, so a slot whose two numbers match was written whole.
        unsafe {
            let slot = &raw mut (*self.slots)[(seq % 2) as usize];
            std::ptr::write_volatile(&raw mut (*slot).begin, seq);
            compiler_fence(Ordering::SeqCst);
            std::ptr::write_volatile(&raw mut (*slot).data, *data);
            compiler_fence(Ordering::SeqCst);
            std::ptr::write_volatile(&raw mut (*slot).end, seq);
        }
    }
}

impl<T> Drop for Snapshot<T> {
    fn drop(&mut self) {
        // SAFETY: unmaps what `open` mapped.
        unsafe { libc::munmap(self.slots.cast(), std::mem::size_of::<[Slot<T>; 2]>()) };
    }
}
