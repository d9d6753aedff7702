//! The per-stream keep-latest slot: a bounded mailbox of one frame.
//!
//! The transport callback [`LatestSlot::put`]s every received frame; the
//! stream's worker [`LatestSlot::take`]s the newest one when it is free. A
//! frame that is replaced before it was taken is dropped and counted, so a
//! stream that receives faster than it computes holds at most one pending
//! frame (memory stays bounded) and always processes the newest data.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;
use tokio::sync::Notify;

/// A keep-latest mailbox with drop counting and a wake-up for the consumer.
#[derive(Debug)]
pub struct LatestSlot<T> {
    pending: Mutex<Option<T>>,
    notify: Notify,
    received: AtomicU64,
    dropped: AtomicU64,
    last_seen_ns: std::sync::atomic::AtomicI64,
    closed: AtomicBool,
}

impl<T> Default for LatestSlot<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T> LatestSlot<T> {
    /// An empty slot.
    pub fn new() -> Self {
        Self {
            pending: Mutex::new(None),
            notify: Notify::new(),
            received: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
            last_seen_ns: std::sync::atomic::AtomicI64::new(0),
            closed: AtomicBool::new(false),
        }
    }

    /// Store `item` (received at `now_ns`), replacing and counting any
    /// pending one, and wake the consumer. Returns `false` (and drops the
    /// item) when the slot is closed.
    pub fn put(&self, item: T, now_ns: i64) -> bool {
        if self.closed.load(Ordering::Acquire) {
            return false;
        }
        self.received.fetch_add(1, Ordering::Relaxed);
        self.last_seen_ns.fetch_max(now_ns, Ordering::Relaxed);
        let old = match self.pending.lock() {
            Ok(mut g) => g.replace(item),
            Err(poisoned) => poisoned.into_inner().replace(item),
        };
        if old.is_some() {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
        self.notify.notify_one();
        true
    }

    /// Whether an item is waiting to be taken.
    pub fn has_pending(&self) -> bool {
        match self.pending.lock() {
            Ok(g) => g.is_some(),
            Err(poisoned) => poisoned.into_inner().is_some(),
        }
    }

    /// Take the pending item, if any.
    pub fn take(&self) -> Option<T> {
        match self.pending.lock() {
            Ok(mut g) => g.take(),
            Err(poisoned) => poisoned.into_inner().take(),
        }
    }

    /// Wait until an item is put or the slot is closed.
    pub async fn wait(&self) {
        self.notify.notified().await;
    }

    /// Close the slot: later puts are refused; the consumer is woken.
    pub fn close(&self) {
        self.closed.store(true, Ordering::Release);
        self.notify.notify_one();
    }

    /// Whether [`LatestSlot::close`] was called.
    pub fn is_closed(&self) -> bool {
        self.closed.load(Ordering::Acquire)
    }

    /// Items put so far.
    pub fn received(&self) -> u64 {
        self.received.load(Ordering::Relaxed)
    }

    /// Items replaced before they were taken.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// Mark the consumer active at `now_ns` (when it finishes an item), so
    /// that silence counts from the later of the last put and the end of the
    /// last processing: a stream whose frames take long to process, or whose
    /// publisher waits for each result, is not silent.
    pub fn touch(&self, now_ns: i64) {
        self.last_seen_ns.fetch_max(now_ns, Ordering::Relaxed);
    }

    /// Time of the last put or [`touch`](Self::touch) (ns since the epoch;
    /// 0 before any).
    pub fn last_seen_ns(&self) -> i64 {
        self.last_seen_ns.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn newest_wins_and_drops_are_counted() {
        let s = LatestSlot::new();
        assert!(s.take().is_none());
        for i in 0..10 {
            assert!(s.put(i, i64::from(i)));
        }
        assert_eq!(s.take(), Some(9));
        assert_eq!(s.take(), None);
        assert_eq!(s.received(), 10);
        assert_eq!(s.dropped(), 9);
        assert_eq!(s.last_seen_ns(), 9);
        s.put(10, 10);
        assert_eq!(s.take(), Some(10));
        assert_eq!(s.dropped(), 9);
        s.close();
        assert!(!s.put(11, 11));
        assert!(s.take().is_none());
    }

    #[tokio::test]
    async fn a_put_before_the_wait_is_not_lost() {
        let s = LatestSlot::new();
        s.put(1u8, 0);
        tokio::time::timeout(std::time::Duration::from_secs(10), s.wait())
            .await
            .unwrap();
        assert_eq!(s.take(), Some(1));
    }
}
