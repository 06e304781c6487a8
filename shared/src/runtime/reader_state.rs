//! Whether a topic's reader may be asleep: one word in shared memory that lets the writer skip
//! the notifier's syscall while its reader is polling (a futex's idea, over iceoryx2's event).
//!
//! The reader marks itself asleep before it dozes or blocks, then looks for a sample once more;
//! the writer, after delivering, looks at the mark and wakes the reader only if it is asleep.
//! Both put a full fence between their write and their read, so one of them always sees the
//! other: either the reader finds the sample, or the writer finds the reader asleep and wakes
//! it. The word starts zeroed, which means asleep: a writer whose reader never said otherwise
//! (or was restarted) always wakes it.
//!
//! The file is in the run's private folder (the ports open it there), removed with it.

use std::path::Path;
use std::sync::atomic::{AtomicU32, Ordering, fence};

use anyhow::{Context as _, Result, anyhow};

use crate::contract::role::Topic;

const ASLEEP: u32 = 0;
const POLLING: u32 = 1;

pub struct ReaderState {
    word: *const AtomicU32,
}

impl ReaderState {
    /// Opens (or creates) the state of `topic`'s reader in the run's private `folder`.
    pub fn open(folder: &Path, topic: Topic) -> Result<Self> {
        use std::os::fd::AsRawFd;
        use std::os::unix::fs::OpenOptionsExt;
        let path = folder.join(format!("{}.reader", topic.name()));
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .mode(0o600)
            .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
            .open(&path)
            .with_context(|| format!("open {}", path.display()))?;
        let size = std::mem::size_of::<AtomicU32>();
        file.set_len(size as u64).with_context(|| format!("size {}", path.display()))?;
        // SAFETY: a shared mapping of a file sized to hold the word, only ever accessed
        // atomically, and mapped for the life of `ReaderState`.
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
        Ok(Self { word: ptr.cast() })
    }

    fn word(&self) -> &AtomicU32 {
        // SAFETY: mapped for the life of self.
        unsafe { &*self.word }
    }

    /// Reader: about to sleep. Look for a sample after this, before sleeping.
    pub fn asleep(&self) {
        self.word().store(ASLEEP, Ordering::SeqCst);
        fence(Ordering::SeqCst);
    }

    /// Reader: awake and looking for samples itself.
    pub fn polling(&self) {
        self.word().store(POLLING, Ordering::Relaxed);
    }

    /// Writer, after delivering: whether the reader may be asleep and needs waking.
    pub fn needs_waking(&self) -> bool {
        fence(Ordering::SeqCst);
        self.word().load(Ordering::SeqCst) == ASLEEP
    }
}

impl Drop for ReaderState {
    fn drop(&mut self) {
        // SAFETY: unmaps what `open` mapped.
        unsafe { libc::munmap(self.word as *mut libc::c_void, std::mem::size_of::<AtomicU32>()) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Writer and reader share the word through the file: a fresh one needs waking, a polling
    /// reader does not, and one about to sleep does again.
    #[test]
    fn the_writer_wakes_only_a_reader_that_may_sleep() {
        let folder = std::env::temp_dir().join(format!("looplab-reader-state-{}", std::process::id()));
        std::fs::create_dir_all(&folder).unwrap();
        let reader = ReaderState::open(&folder, Topic::Estimate).unwrap();
        let writer = ReaderState::open(&folder, Topic::Estimate).unwrap();
        assert!(writer.needs_waking());
        reader.polling();
        assert!(!writer.needs_waking());
        reader.asleep();
        assert!(writer.needs_waking());
        drop((reader, writer));
        std::fs::remove_dir_all(&folder).unwrap();
    }
}
