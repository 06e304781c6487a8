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

use anyhow::Result;

use crate::contract::role::Topic;
use crate::runtime::shared_file::{self, Open};

const ASLEEP: u32 = 0;
const POLLING: u32 = 1;

pub struct ReaderState {
    word: *const AtomicU32,
}

impl ReaderState {
    /// Opens (or creates) the state of `topic`'s reader in the run's private `folder`.
    pub fn open(folder: &Path, topic: Topic) -> Result<Self> {
        let path = folder.join(format!("{}.reader", topic.name()));
        let ptr = shared_file::map(&path, std::mem::size_of::<AtomicU32>(), Open::OrCreate)?;
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
        unsafe { shared_file::unmap(self.word as *mut libc::c_void, std::mem::size_of::<AtomicU32>()) };
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
