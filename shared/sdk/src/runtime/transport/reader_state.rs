//! Whether a topic's reader may be asleep: one word in shared memory that lets the writer skip
//! the wake-up's syscall while its reader is polling, and the futex a sleeping reader waits on.
//!
//! The reader marks itself asleep before it dozes or blocks, then looks for a sample once more;
//! the writer, after delivering, looks at the mark and wakes the reader only if it is asleep.
//! Both put a full fence between their write and their read, so one of them always sees the
//! other: either the reader finds the sample, or the writer finds the reader asleep and wakes
//! it. The word starts zeroed, which means asleep: a writer whose reader never said otherwise
//! (or was restarted) always wakes it.
//!
//! A loop stage's reader sleeps on the word itself (a shared futex: the file is mapped by both
//! processes): the writer that finds it asleep marks it polling and wakes it, one syscall with
//! no data, where iceoryx2's event sends a datagram that the reader must then read back. A
//! reader that marks itself asleep after the writer looked finds the sample; one whose futex
//! wait starts after the writer marked it polling returns at once.
//!
//! The file is in the run's private folder (the ports open it there), removed with it.

use std::path::Path;
use std::sync::atomic::{AtomicU32, Ordering, fence};
use std::time::Duration;

use anyhow::Result;
use linux_futex::{AsFutex, Shared, TimedWaitError};

use crate::contract::clock::now_ns;
use crate::contract::role::Topic;
use crate::runtime::storage::shared_file::{self, Open};

/// How a writer wakes its topic's reader when the reader may be asleep.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wake {
    /// Never: the reader polls (or there is none that blocks).
    Never,
    /// A futex on the reader's state word: a loop stage's reader (one syscall, and only while
    /// the reader sleeps).
    Futex,
    /// iceoryx2's event (a datagram to the reader's socket): a bridge, which waits for all its
    /// topics in one WaitSet.
    Event,
}

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

    /// Reader, marked asleep and with no sample: sleeps until the writer wakes it or
    /// `deadline_ns` (CLOCK_MONOTONIC) passes. Returns whether it was woken (or the writer had
    /// already marked it polling) rather than reaching the deadline. A signal ends it early,
    /// which is harmless: the caller looks for input and waits again.
    pub fn sleep_until(&self, deadline_ns: u64) -> bool {
        let left = deadline_ns.saturating_sub(now_ns());
        if left == 0 {
            return false;
        }
        let futex = AsFutex::<Shared>::as_futex(self.word());
        !matches!(futex.wait_for(ASLEEP, Duration::from_nanos(left)), Err(TimedWaitError::TimedOut))
    }

    /// Writer, after delivering: wakes the reader if it may be asleep, marking it polling first
    /// so that a futex wait it has not started yet returns at once.
    pub fn wake(&self) {
        if self.needs_waking() && self.word().swap(POLLING, Ordering::SeqCst) == ASLEEP {
            AsFutex::<Shared>::as_futex(self.word()).wake(i32::MAX);
        }
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
        // Woken before it sleeps: its futex wait returns at once.
        writer.wake();
        assert!(!writer.needs_waking());
        assert!(reader.sleep_until(now_ns() + 3_600_000_000_000));
        drop((reader, writer));
        std::fs::remove_dir_all(&folder).unwrap();
    }

    /// A reader asleep on the word (in another thread here; the futex is a shared one, as
    /// between processes) is woken by its writer, long before its deadline of an hour.
    #[test]
    fn a_sleeping_reader_is_woken_by_its_writer() {
        let folder = std::env::temp_dir().join(format!("looplab-reader-wake-{}", std::process::id()));
        std::fs::create_dir_all(&folder).unwrap();
        let writer = ReaderState::open(&folder, Topic::Command).unwrap();
        let sleeper = {
            let folder = folder.clone();
            std::thread::spawn(move || {
                let reader = ReaderState::open(&folder, Topic::Command).unwrap();
                reader.asleep();
                reader.sleep_until(now_ns() + 3_600_000_000_000)
            })
        };
        // Until the reader has marked itself asleep, a wake finds nothing to do.
        while !sleeper.is_finished() {
            writer.wake();
            std::thread::yield_now();
        }
        assert!(sleeper.join().unwrap(), "the reader slept until its deadline");
        std::fs::remove_dir_all(&folder).unwrap();
    }
}
