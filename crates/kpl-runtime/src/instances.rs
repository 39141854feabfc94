//! Process instances created at run time, as DyKnow's link processes create one process per
//! object. A process makes an [`Instances`] table, spawns an instance per key (an object's
//! symbol), sends them messages and gathers their replies; each instance is its own task, counted
//! in the run's statistics (created / removed) under its parent.
//!
//! Calls are scatter-gather: [`Instances::call`] sends one message to each named instance and
//! returns the replies in the order of the messages, so a run with simulated time stays
//! deterministic.
//!
//! ```
//! # tokio_test_block_on(async {
//! use kpl_runtime::instances::{Instance, Instances};
//!
//! struct Counter(u32);
//! impl Instance for Counter {
//!     type In = u32;
//!     type Out = u32;
//!     fn on_message(&mut self, add: u32) -> u32 {
//!         self.0 += add;
//!         self.0
//!     }
//! }
//!
//! let mut counters = Instances::new("demo", Default::default());
//! counters.spawn("a", Counter(0));
//! counters.spawn("b", Counter(10));
//! let replies = counters.call(vec![("a".into(), 1), ("b".into(), 2), ("a".into(), 5)]).await;
//! assert_eq!(replies, vec![("a".into(), 1), ("b".into(), 12), ("a".into(), 6)]);
//! # });
//! # fn tokio_test_block_on<F: std::future::Future>(f: F) -> F::Output {
//! #     tokio::runtime::Builder::new_current_thread().build().unwrap().block_on(f)
//! # }
//! ```

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::Ordering;

use tokio::sync::mpsc;

use crate::stats::ProcessStats;

/// The behaviour of one instance: it handles messages one at a time, in order.
pub trait Instance: Send + 'static {
    type In: Send + 'static;
    type Out: Send + 'static;
    fn on_message(&mut self, message: Self::In) -> Self::Out;
}

type Request<I> = (u64, <I as Instance>::In);

/// The instances of one parent process, by key.
pub struct Instances<I: Instance> {
    parent: String,
    senders: BTreeMap<String, mpsc::UnboundedSender<Request<I>>>,
    reply_tx: mpsc::UnboundedSender<(u64, I::Out)>,
    reply_rx: mpsc::UnboundedReceiver<(u64, I::Out)>,
    stats: Arc<ProcessStats>,
}

impl<I: Instance> std::fmt::Debug for Instances<I> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Instances").field("parent", &self.parent).field("alive", &self.senders.len()).finish()
    }
}

impl<I: Instance> Instances<I> {
    /// A table for the instances of process `parent`, counted in `stats`.
    pub fn new(parent: &str, stats: Arc<ProcessStats>) -> Instances<I> {
        let (reply_tx, reply_rx) = mpsc::unbounded_channel();
        Instances { parent: parent.to_string(), senders: BTreeMap::new(), reply_tx, reply_rx, stats }
    }

    /// Creates an instance (a task) under `key`, replacing one of the same key.
    pub fn spawn(&mut self, key: &str, mut instance: I) {
        let (tx, mut rx) = mpsc::unbounded_channel::<Request<I>>();
        let replies = self.reply_tx.clone();
        let name = format!("{}/{key}", self.parent);
        tokio::spawn(async move {
            while let Some((id, message)) = rx.recv().await {
                let out = instance.on_message(message);
                if replies.send((id, out)).is_err() {
                    break;
                }
            }
            tracing::trace!(instance = %name, "instance ended");
        });
        self.stats.instances_created.fetch_add(1, Ordering::Relaxed);
        if self.senders.insert(key.to_string(), tx).is_some() {
            self.stats.instances_removed.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Ends the instance under `key` (its task finishes).
    pub fn remove(&mut self, key: &str) -> bool {
        let removed = self.senders.remove(key).is_some();
        if removed {
            self.stats.instances_removed.fetch_add(1, Ordering::Relaxed);
        }
        removed
    }

    pub fn contains(&self, key: &str) -> bool {
        self.senders.contains_key(key)
    }

    pub fn len(&self) -> usize {
        self.senders.len()
    }

    pub fn is_empty(&self) -> bool {
        self.senders.is_empty()
    }

    pub fn keys(&self) -> impl Iterator<Item = &str> {
        self.senders.keys().map(String::as_str)
    }

    /// Sends each message to its instance and waits for all replies, returned in the order of
    /// `messages`. Messages to unknown keys are skipped.
    pub async fn call(&mut self, messages: Vec<(String, I::In)>) -> Vec<(String, I::Out)> {
        let mut keys: Vec<Option<String>> = Vec::with_capacity(messages.len());
        let mut expected = 0;
        for (id, (key, message)) in messages.into_iter().enumerate() {
            match self.senders.get(&key) {
                Some(tx) if tx.send((id as u64, message)).is_ok() => {
                    keys.push(Some(key));
                    expected += 1;
                }
                _ => keys.push(None),
            }
        }
        let mut replies: Vec<Option<I::Out>> = (0..keys.len()).map(|_| None).collect();
        while expected > 0 {
            let Some((id, out)) = self.reply_rx.recv().await else { break };
            if let Some(slot) = replies.get_mut(id as usize) {
                *slot = Some(out);
                expected -= 1;
            }
        }
        keys.into_iter().zip(replies).filter_map(|(k, r)| Some((k?, r?))).collect()
    }
}
