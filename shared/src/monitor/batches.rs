//! A channel of batches between two threads: the sender fills a batch and hands it over when it
//! is full (or when asked), the receiver empties it and hands it back to be filled again. A
//! thread that produces a few hundred thousand items a second pays for one channel operation
//! (and at most one wake-up of the other thread) per batch instead of per item, and nothing is
//! allocated once the batches are made.

use std::time::Duration;

use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, bounded, unbounded};

/// The other end hung up (its thread ended, with an error or a panic).
#[derive(Debug)]
pub struct HungUp;

/// The filling end.
pub struct BatchSender<T> {
    batch: Vec<T>,
    size: usize,
    full: Sender<Vec<T>>,
    empty: Receiver<Vec<T>>,
}

/// The emptying end.
pub struct BatchReceiver<T> {
    full: Receiver<Vec<T>>,
    empty: Sender<Vec<T>>,
}

/// A channel of batches of `size` items. `in_flight`: the full batches the sender may hand over
/// before it waits for the receiver; None: it never waits, and the batches queue up instead.
pub fn batches<T>(size: usize, in_flight: Option<usize>) -> (BatchSender<T>, BatchReceiver<T>) {
    let ((full_tx, full_rx), (empty_tx, empty_rx)) = match in_flight {
        // Every batch is full, being filled or being emptied, so the empty ones always fit.
        Some(n) => (bounded(n), bounded(n + 2)),
        None => (unbounded(), unbounded()),
    };
    let sender = BatchSender { batch: Vec::with_capacity(size), size, full: full_tx, empty: empty_rx };
    (sender, BatchReceiver { full: full_rx, empty: empty_tx })
}

impl<T> BatchSender<T> {
    /// Adds an item; hands the batch over once it is full.
    pub fn push(&mut self, item: T) -> Result<(), HungUp> {
        self.batch.push(item);
        if self.batch.len() >= self.size { self.send() } else { Ok(()) }
    }

    /// Hands over what the batch holds now (nothing if it is empty).
    pub fn send(&mut self) -> Result<(), HungUp> {
        if self.batch.is_empty() {
            return Ok(());
        }
        let next = self.empty.try_recv().unwrap_or_else(|_| Vec::with_capacity(self.size));
        let batch = std::mem::replace(&mut self.batch, next);
        self.full.send(batch).map_err(|_| HungUp)
    }
}

impl<T> BatchReceiver<T> {
    /// The next batch, in order, waiting at most `timeout`: Ok(None) when none came by then,
    /// Err once the sender is gone and every batch has been read.
    pub fn recv_timeout(&self, timeout: Duration) -> Result<Option<Vec<T>>, HungUp> {
        match self.full.recv_timeout(timeout) {
            Ok(batch) => Ok(Some(batch)),
            Err(RecvTimeoutError::Timeout) => Ok(None),
            Err(RecvTimeoutError::Disconnected) => Err(HungUp),
        }
    }

    /// Hands an emptied batch back to be filled again.
    pub fn give_back(&self, mut batch: Vec<T>) {
        batch.clear();
        // Full only if the sender made extra batches; this one is then dropped.
        let _ = self.empty.try_send(batch);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn items_arrive_in_order_in_batches_that_are_reused() {
        let (mut tx, rx) = batches::<u32>(3, Some(4));
        let reader = std::thread::spawn(move || {
            let mut seen: Vec<u32> = vec![];
            let mut sizes = vec![];
            while let Ok(Some(batch)) = rx.recv_timeout(Duration::MAX) {
                sizes.push(batch.len());
                seen.extend(&batch);
                rx.give_back(batch);
            }
            (seen, sizes)
        });
        for i in 0..10 {
            tx.push(i).unwrap();
        }
        tx.send().unwrap();
        // Nothing left: nothing goes.
        tx.send().unwrap();
        drop(tx);
        let (seen, sizes) = reader.join().unwrap();
        assert_eq!(seen, (0..10).collect::<Vec<_>>());
        assert_eq!(sizes, [3, 3, 3, 1]);
    }

    #[test]
    fn a_receiver_that_hung_up_is_reported() {
        let (mut tx, rx) = batches::<u32>(1, None);
        drop(rx);
        assert!(tx.push(1).is_err());
    }
}
