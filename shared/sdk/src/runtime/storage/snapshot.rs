//! A process's snapshot in shared memory: what a restarted process needs to go on where the
//! last one stopped. The plant keeps the truth in one (the physical system does not stop when
//! its simulator dies), the estimator its slow calibration states, the controller its integrators.
//!
//! The file is in the run's private folder on tmpfs ([`crate::runtime::storage::run_storage::run_folder`]), so no other
//! user can read or forge it, the launcher's leftover check covers it and its clean-up removes it.

use std::path::PathBuf;

use anyhow::Result;

use crate::runtime::storage::shared_file::{self, Open};

fn path(run_id: &str, process: &str) -> Result<PathBuf> {
    let folder = crate::runtime::storage::run_storage::run_folder(run_id);
    crate::runtime::storage::run_storage::check_private(&folder)?;
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
        // Only one process at a time writes it; it stays mapped for the life of `Snapshot`.
        let ptr = shared_file::map(&path(run_id, process)?, std::mem::size_of::<[Slot<T>; 2]>(), Open::OrCreate)?;
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
        unsafe { shared_file::unmap(self.slots.cast(), std::mem::size_of::<[Slot<T>; 2]>()) };
    }
}

/// The most bytes a stage's frozen state may take ([`FrozenSnapshot`] of a stage): room for a
/// real filter's state (a 9-state Kalman filter's mean and covariance take 720).
pub const MAX_FROZEN_BYTES: usize = 64 * 1024;

/// A stage's frozen state if it fits in its snapshot; more than [`MAX_FROZEN_BYTES`] is an
/// error that ends the stage's incarnation.
pub fn stage_frozen(frozen: Option<Vec<u8>>) -> Result<Option<Vec<u8>>> {
    match frozen {
        Some(bytes) if bytes.len() > MAX_FROZEN_BYTES => {
            anyhow::bail!("freeze returned {} bytes; a snapshot keeps at most {MAX_FROZEN_BYTES}", bytes.len())
        }
        frozen => Ok(frozen),
    }
}

/// The most bytes of a plant model's own state (an FMU's serialised state) the plant's
/// [`FrozenSnapshot`] keeps; a larger state is not kept, and a restart goes on from the state
/// vector.
pub const MAX_MODEL_BYTES: usize = 1 << 20;

/// What a part froze (`freeze`, whatever the part: an estimator, a controller, a stage of the
/// user's own, a plant model) as bytes, kept across a restart: two slots of `capacity` bytes
/// written in turn, each tagged with the loop it belongs to and between two copies of its
/// sequence number, so a kill in the middle of a write leaves the other slot whole. The plant
/// writes its model's before its [`Snapshot`] of the same tick, so whichever process death cuts
/// in between, one slot matches the snapshot's tick. On tmpfs, pages never written take no
/// memory.
pub struct FrozenSnapshot {
    base: *mut u8,
    capacity: usize,
    sequence: u64,
}

/// A slot's header: sequence, tick, length; the bytes follow, then the sequence again.
const HEADER: usize = 24;

impl FrozenSnapshot {
    /// Opens (or creates) the frozen state of `process` (a stage's role, `plant.model`) in run
    /// `run_id`, its slots `capacity` bytes each.
    pub fn open(run_id: &str, process: &str, capacity: usize) -> Result<Self> {
        let capacity = capacity.next_multiple_of(8);
        let ptr = shared_file::map(&path(run_id, process)?, 2 * Self::slot(capacity), Open::OrCreate)?;
        let mut snapshot = Self { base: ptr.cast(), capacity, sequence: 0 };
        snapshot.sequence = (0..2).map(|i| snapshot.header(i).0).max().unwrap_or(0);
        Ok(snapshot)
    }

    fn slot(capacity: usize) -> usize {
        HEADER + capacity + 8
    }

    /// Slot i's (sequence, tick, length, closing sequence).
    fn header(&self, i: usize) -> (u64, u64, usize, u64) {
        let slot_size = Self::slot(self.capacity);
        // SAFETY: inside the mapping; volatile because another process wrote it.
        unsafe {
            let slot = self.base.add(i * slot_size).cast::<u64>();
            let len = std::ptr::read_volatile(slot.add(2)) as usize;
            let end = std::ptr::read_volatile(self.base.add(i * slot_size + HEADER + self.capacity).cast::<u64>());
            (std::ptr::read_volatile(slot), std::ptr::read_volatile(slot.add(1)), len, end)
        }
    }

    /// Slot i's bytes, if it was written whole: (sequence, tick, bytes).
    fn whole(&self, i: usize) -> Option<(u64, u64, Vec<u8>)> {
        let (begin, tick, len, end) = self.header(i);
        (begin > 0 && begin == end && len <= self.capacity).then(|| {
            // SAFETY: `len` bytes inside the slot.
            let bytes =
                unsafe { std::slice::from_raw_parts(self.base.add(i * Self::slot(self.capacity) + HEADER), len) };
            (begin, tick, bytes.to_vec())
        })
    }

    /// The bytes written whole for tick `k`, if any.
    pub fn read(&self, k: u64) -> Option<Vec<u8>> {
        (0..2).filter_map(|i| self.whole(i)).find(|(_, tick, _)| *tick == k).map(|(_, _, bytes)| bytes)
    }

    /// The newest bytes written whole, if any were.
    pub fn newest(&self) -> Option<Vec<u8>> {
        (0..2).filter_map(|i| self.whole(i)).max_by_key(|(seq, _, _)| *seq).map(|(_, _, bytes)| bytes)
    }

    /// Keeps `bytes` as tick `k`'s; false (nothing written) where they exceed the capacity.
    pub fn write(&mut self, k: u64, bytes: &[u8]) -> bool {
        use std::sync::atomic::{Ordering, compiler_fence};
        if bytes.len() > self.capacity {
            return false;
        }
        self.sequence += 1;
        let seq = self.sequence;
        // SAFETY: the slot is inside our mapping; the fences order begin, the data and end, as
        // in `Snapshot::write`.
        unsafe {
            let slot = self.base.add((seq % 2) as usize * Self::slot(self.capacity));
            std::ptr::write_volatile(slot.cast::<u64>(), seq);
            compiler_fence(Ordering::SeqCst);
            std::ptr::write_volatile(slot.cast::<u64>().add(1), k);
            std::ptr::write_volatile(slot.cast::<u64>().add(2), bytes.len() as u64);
            std::ptr::copy_nonoverlapping(bytes.as_ptr(), slot.add(HEADER), bytes.len());
            compiler_fence(Ordering::SeqCst);
            std::ptr::write_volatile(slot.add(HEADER + self.capacity).cast::<u64>(), seq);
        }
        true
    }
}

impl Drop for FrozenSnapshot {
    fn drop(&mut self) {
        // SAFETY: unmaps what `open` mapped.
        unsafe { shared_file::unmap(self.base.cast(), 2 * Self::slot(self.capacity)) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runtime::storage::run_storage::*;

    #[test]
    fn frozen_state_of_64_kib_comes_back_whole_and_a_torn_write_leaves_the_last_one() {
        let id = format!("test{}frozen", std::process::id());
        let lock = create_run_storage(&id).unwrap();
        let bytes = |k: u64| (0..MAX_FROZEN_BYTES).map(|i| (i as u64 * 31 + k) as u8).collect::<Vec<_>>();
        {
            let mut frozen = FrozenSnapshot::open(&id, "controller", MAX_FROZEN_BYTES).unwrap();
            assert_eq!(frozen.newest(), None, "nothing written yet");
            for k in 1..=3 {
                assert!(frozen.write(k, &bytes(k)));
            }
            assert!(!frozen.write(4, &vec![0; MAX_FROZEN_BYTES + 1]), "more than the capacity is not kept");
            // A kill in the middle of the fourth write, into slot 0 (tick 2's): its opening
            // number is written, its closing one never comes.
            // SAFETY: slot 0's first header word, inside the mapping.
            unsafe { std::ptr::write_volatile(frozen.base.cast::<u64>(), 4) };
        }
        let reopened = FrozenSnapshot::open(&id, "controller", MAX_FROZEN_BYTES).unwrap();
        assert!(reopened.newest() == Some(bytes(3)), "the newest whole slot, all 64 KiB of it");
        assert!(reopened.read(3) == Some(bytes(3)) && reopened.read(2).is_none(), "the torn slot held tick 2");
        drop(reopened);
        let e = stage_frozen(Some(vec![0; MAX_FROZEN_BYTES + 1])).unwrap_err().to_string();
        assert_eq!(e, "freeze returned 65537 bytes; a snapshot keeps at most 65536");
        assert_eq!(stage_frozen(Some(vec![1; MAX_FROZEN_BYTES])).unwrap().map(|b| b.len()), Some(MAX_FROZEN_BYTES));
        assert!(clean_up_run(&id).unwrap().leftover.is_empty());
        drop(lock);
    }
}
