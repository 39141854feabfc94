//! Edges: the bounded in-process queue in front of each consumer of a stream. Every edge has an
//! explicit bound and overflow behaviour: `block` makes the producer wait, `drop oldest` makes
//! room by discarding the oldest queued sample (counted as [`DropReason::QueueFull`]).
//!
//! Samples move without copying their payload (values share it through `Arc`). The receiver
//! takes queued samples in batches, so a busy edge costs one lock per batch, not per sample.

use std::collections::VecDeque;
use std::future::poll_fn;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll, Waker};

use kpl_syntax::ast::Overflow;

use crate::sample::Sample;
use crate::stats::{DropReason, EdgeStats};

struct Inner {
    queue: VecDeque<Sample>,
    senders: usize,
    receiver_alive: bool,
    receiver: Option<Waker>,
    blocked: Vec<Waker>,
}

struct Shared {
    inner: Mutex<Inner>,
    capacity: usize,
    overflow: Overflow,
    stats: Arc<EdgeStats>,
}

/// The producer's end of an edge (cloneable: a stream may have several producing tasks).
pub struct EdgeSender {
    shared: Arc<Shared>,
}

/// The consumer's end of an edge.
pub struct EdgeReceiver {
    shared: Arc<Shared>,
}

impl std::fmt::Debug for EdgeSender {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EdgeSender").field("capacity", &self.shared.capacity).finish()
    }
}

impl std::fmt::Debug for EdgeReceiver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EdgeReceiver").field("capacity", &self.shared.capacity).finish()
    }
}

/// Creates an edge holding at most `capacity` samples (at least 1).
pub fn edge(capacity: usize, overflow: Overflow, stats: Arc<EdgeStats>) -> (EdgeSender, EdgeReceiver) {
    let shared = Arc::new(Shared {
        inner: Mutex::new(Inner {
            queue: VecDeque::with_capacity(capacity.clamp(1, 1024)),
            senders: 1,
            receiver_alive: true,
            receiver: None,
            blocked: Vec::new(),
        }),
        capacity: capacity.max(1),
        overflow,
        stats,
    });
    (EdgeSender { shared: shared.clone() }, EdgeReceiver { shared })
}

/// The consumer is gone; the sample was not delivered.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("the consumer of this stream has stopped")]
pub struct Closed;

fn lock(shared: &Shared) -> std::sync::MutexGuard<'_, Inner> {
    // A panic while holding the lock cannot leave the queue inconsistent (every critical section
    // is a few `VecDeque` operations), so a poisoned lock is used as is.
    shared.inner.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl EdgeSender {
    /// Queues a sample, waiting while the queue is full if the edge blocks.
    pub async fn send(&self, sample: Sample) -> Result<(), Closed> {
        let mut sample = Some(sample);
        poll_fn(|cx| self.poll_send(cx, &mut sample)).await
    }

    fn poll_send(&self, cx: &mut Context<'_>, sample: &mut Option<Sample>) -> Poll<Result<(), Closed>> {
        let Some(s) = sample.take() else { return Poll::Ready(Ok(())) };
        match self.try_send(s) {
            Ok(()) => Poll::Ready(Ok(())),
            Err(TrySendError::Closed) => Poll::Ready(Err(Closed)),
            Err(TrySendError::Full(s)) => {
                let mut inner = lock(&self.shared);
                if inner.queue.len() < self.shared.capacity || !inner.receiver_alive {
                    // Room was made (or the consumer left) since `try_send` looked: try again.
                    drop(inner);
                    *sample = Some(s);
                    cx.waker().wake_by_ref();
                    return Poll::Pending;
                }
                if !inner.blocked.iter().any(|w| w.will_wake(cx.waker())) {
                    inner.blocked.push(cx.waker().clone());
                }
                *sample = Some(s);
                Poll::Pending
            }
        }
    }

    /// Queues a sample without waiting: with a full blocking edge the sample is handed back.
    pub fn try_send(&self, sample: Sample) -> Result<(), TrySendError> {
        let mut inner = lock(&self.shared);
        if !inner.receiver_alive {
            return Err(TrySendError::Closed);
        }
        if inner.queue.len() >= self.shared.capacity {
            match self.shared.overflow {
                Overflow::DropOldest => {
                    inner.queue.pop_front();
                    self.shared.stats.count_drop(DropReason::QueueFull);
                }
                Overflow::Block => return Err(TrySendError::Full(sample)),
            }
        }
        inner.queue.push_back(sample);
        self.shared.stats.produced.fetch_add(1, Ordering::Relaxed);
        let waker = inner.receiver.take();
        drop(inner);
        if let Some(waker) = waker {
            waker.wake();
        }
        Ok(())
    }

    pub fn stats(&self) -> &Arc<EdgeStats> {
        &self.shared.stats
    }
}

#[derive(Debug)]
pub enum TrySendError {
    Full(Sample),
    Closed,
}

impl Clone for EdgeSender {
    fn clone(&self) -> EdgeSender {
        lock(&self.shared).senders += 1;
        EdgeSender { shared: self.shared.clone() }
    }
}

impl Drop for EdgeSender {
    fn drop(&mut self) {
        let mut inner = lock(&self.shared);
        inner.senders -= 1;
        if inner.senders == 0
            && let Some(waker) = inner.receiver.take()
        {
            drop(inner);
            waker.wake();
        }
    }
}

/// What a receive found.
#[derive(Debug, PartialEq)]
pub enum Received {
    /// At least one sample was moved into the buffer.
    Samples,
    /// Every sender is gone and the queue is empty: the stream has ended.
    Ended,
}

impl EdgeReceiver {
    /// Moves up to `max` queued samples into `buf`, or registers to be woken.
    pub fn poll_recv_many(
        &mut self,
        cx: &mut Context<'_>,
        buf: &mut Vec<Sample>,
        max: usize,
    ) -> Poll<Received> {
        let mut inner = lock(&self.shared);
        if inner.queue.is_empty() {
            if inner.senders == 0 {
                return Poll::Ready(Received::Ended);
            }
            match &inner.receiver {
                Some(w) if w.will_wake(cx.waker()) => {}
                _ => inner.receiver = Some(cx.waker().clone()),
            }
            return Poll::Pending;
        }
        let n = inner.queue.len().min(max.max(1));
        buf.extend(inner.queue.drain(..n));
        let blocked = std::mem::take(&mut inner.blocked);
        drop(inner);
        for waker in blocked {
            waker.wake();
        }
        Poll::Ready(Received::Samples)
    }

    /// Moves up to `max` queued samples into `buf` without waiting (and without registering to
    /// be woken); returns how many.
    pub fn try_recv_many(&mut self, buf: &mut Vec<Sample>, max: usize) -> usize {
        let mut inner = lock(&self.shared);
        let n = inner.queue.len().min(max);
        buf.extend(inner.queue.drain(..n));
        let blocked = if n > 0 { std::mem::take(&mut inner.blocked) } else { Vec::new() };
        drop(inner);
        for waker in blocked {
            waker.wake();
        }
        n
    }

    /// Waits for samples; `None` when the stream has ended.
    pub async fn recv(&mut self) -> Option<Sample> {
        let mut buf = Vec::with_capacity(1);
        match poll_fn(|cx| self.poll_recv_many(cx, &mut buf, 1)).await {
            Received::Samples => buf.pop(),
            Received::Ended => None,
        }
    }

    pub fn stats(&self) -> &Arc<EdgeStats> {
        &self.shared.stats
    }
}

impl Drop for EdgeReceiver {
    fn drop(&mut self) {
        let mut inner = lock(&self.shared);
        inner.receiver_alive = false;
        inner.queue.clear();
        let blocked = std::mem::take(&mut inner.blocked);
        drop(inner);
        for waker in blocked {
            waker.wake();
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use kpl_core::Value;

    fn s(i: i64) -> Sample {
        Sample::new(i, i, Value::Int(i))
    }

    #[tokio::test]
    async fn drop_oldest_keeps_the_newest_and_counts() {
        let stats = Arc::new(EdgeStats::default());
        let (tx, mut rx) = edge(3, Overflow::DropOldest, stats.clone());
        for i in 0..10 {
            tx.send(s(i)).await.unwrap();
        }
        drop(tx);
        let mut got = Vec::new();
        while let Some(sample) = rx.recv().await {
            got.push(sample.valid);
        }
        assert_eq!(got, [7, 8, 9]);
        assert_eq!(stats.dropped(DropReason::QueueFull), 7);
        assert_eq!(stats.produced.load(Ordering::Relaxed), 10);
    }

    #[tokio::test]
    async fn block_makes_the_producer_wait() {
        let stats = Arc::new(EdgeStats::default());
        let (tx, mut rx) = edge(2, Overflow::Block, stats.clone());
        let producer = tokio::spawn(async move {
            for i in 0..100 {
                tx.send(s(i)).await.unwrap();
            }
        });
        let mut got = Vec::new();
        while let Some(sample) = rx.recv().await {
            got.push(sample.valid);
        }
        producer.await.unwrap();
        assert_eq!(got, (0..100).collect::<Vec<_>>());
        assert_eq!(stats.dropped(DropReason::QueueFull), 0);
    }

    #[tokio::test]
    async fn a_gone_consumer_is_reported_to_the_producer() {
        let (tx, rx) = edge(1, Overflow::Block, Arc::default());
        tx.send(s(1)).await.unwrap();
        drop(rx);
        assert_eq!(tx.send(s(2)).await, Err(Closed));
    }
}
