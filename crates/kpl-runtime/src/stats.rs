//! Counters of a run: per stream edge (produced, delivered, dropped by reason, policy
//! violations), per process (malformed input, process instances), and the run's progress. Shared
//! atomics, so the progress line can be printed from another thread without disturbing a
//! simulated run.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use kpl_core::Time;
use serde::Serialize;

/// Why a sample did not reach its consumer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum DropReason {
    /// The queue was full and its policy is `drop oldest`.
    QueueFull,
    /// Valid time went back (`monotone order`) or did not advance (`strict order`).
    OutOfOrder,
    /// Available more than `max delay` after its valid time, with `no approximation`.
    Late,
    /// Valid time outside the `from T to T` window.
    OutsideWindow,
    /// The same value as the previous sample, with `any change`.
    Unchanged,
    /// Replaced by resampling (`sample every`): only the most recent value per period is kept.
    Resampled,
    /// Arrived after the state for its valid time was already emitted (state synchronization).
    LateForState,
}

impl DropReason {
    pub const ALL: [DropReason; 7] = [
        DropReason::QueueFull,
        DropReason::OutOfOrder,
        DropReason::Late,
        DropReason::OutsideWindow,
        DropReason::Unchanged,
        DropReason::Resampled,
        DropReason::LateForState,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            DropReason::QueueFull => "queue_full",
            DropReason::OutOfOrder => "out_of_order",
            DropReason::Late => "late",
            DropReason::OutsideWindow => "outside_window",
            DropReason::Unchanged => "unchanged",
            DropReason::Resampled => "resampled",
            DropReason::LateForState => "late_for_state",
        }
    }

    /// Whether the drop means the stream broke its policy (rather than the policy filtering).
    pub fn is_violation(self) -> bool {
        matches!(self, DropReason::OutOfOrder | DropReason::Late | DropReason::LateForState)
    }
}

/// Counters of one edge (a stream as one consumer sees it).
#[derive(Debug, Default)]
pub struct EdgeStats {
    pub produced: AtomicU64,
    pub delivered: AtomicU64,
    /// Samples made up by approximation (`use most recent`, `sample every`).
    pub approximated: AtomicU64,
    dropped: [AtomicU64; 7],
}

impl EdgeStats {
    pub fn count_drop(&self, reason: DropReason) {
        self.dropped[reason as usize].fetch_add(1, Ordering::Relaxed);
    }

    pub fn dropped(&self, reason: DropReason) -> u64 {
        self.dropped[reason as usize].load(Ordering::Relaxed)
    }
}

/// A malformed input: where it came from and what was wrong.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Malformed {
    /// `file.jsonl:17`, a zenoh key, ...
    pub location: String,
    pub error: String,
}

/// Counters of one process.
#[derive(Debug, Default)]
pub struct ProcessStats {
    pub malformed: AtomicU64,
    /// The first malformed inputs (at most [`ProcessStats::KEEP`]).
    pub malformed_examples: Mutex<Vec<Malformed>>,
    pub errors: AtomicU64,
    pub error_examples: Mutex<Vec<String>>,
    /// Process instances created and removed at run time (link processes: one per object).
    pub instances_created: AtomicU64,
    pub instances_removed: AtomicU64,
    /// Things the process could do but that are probably not what the spec meant (a replay
    /// filter that matched nothing), each said once.
    pub warnings: Mutex<Vec<String>>,
    /// What the process achieved, in its own words and counts (`new Car objects (establish)`:
    /// 4), in the order first reported; `kpl run` prints them as the run's result.
    pub results: Mutex<Vec<Outcome>>,
}

/// One count of what a process achieved.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Outcome {
    pub what: String,
    pub count: u64,
}

impl ProcessStats {
    pub const KEEP: usize = 5;

    /// Sets the count of one thing the process achieved (a total so far, not an increment).
    pub fn result(&self, what: &str, count: u64) {
        let Ok(mut results) = self.results.lock() else { return };
        match results.iter_mut().find(|o| o.what == what) {
            Some(outcome) => outcome.count = count,
            None => results.push(Outcome { what: what.to_string(), count }),
        }
    }

    pub fn malformed(&self, malformed: Malformed) {
        count(&self.malformed, &self.malformed_examples, malformed);
    }

    pub fn error(&self, error: String) {
        count(&self.errors, &self.error_examples, error);
    }

    /// Keeps a warning for the end-of-run summary (at most [`ProcessStats::KEEP`]).
    pub fn warn(&self, warning: String) {
        if let Ok(mut warnings) = self.warnings.lock()
            && warnings.len() < ProcessStats::KEEP
            && !warnings.contains(&warning)
        {
            warnings.push(warning);
        }
    }
}

/// Counts one more and keeps it as an example if fewer than [`ProcessStats::KEEP`] are kept.
fn count<T>(counter: &AtomicU64, examples: &Mutex<Vec<T>>, example: T) {
    counter.fetch_add(1, Ordering::Relaxed);
    if let Ok(mut examples) = examples.lock()
        && examples.len() < ProcessStats::KEEP
    {
        examples.push(example);
    }
}

/// Times from a year after the UNIX epoch on are dates (a recording's `header.stamp`), not
/// simulated time from 0.
pub const DATES: Time = 365 * 24 * 3600 * 1_000_000;

/// Everything counted in a run.
#[derive(Debug, Default)]
pub struct RunStats {
    /// By `(stream, consumer)` name, in graph order.
    pub edges: Mutex<Vec<(String, String, Arc<EdgeStats>)>>,
    pub processes: Mutex<BTreeMap<String, Arc<ProcessStats>>>,
    /// The clock time the run started at (0 for simulated time, the UNIX time in microseconds
    /// for the wall clock).
    pub start: AtomicI64,
    /// The latest clock time any process reported (for the progress line).
    pub now: AtomicI64,
    /// The clock time of the first sample a source emitted (or another host sent): where a
    /// replay's simulated time begins when its stamps are dates.
    pub first_sample: std::sync::OnceLock<Time>,
    /// Samples produced on every stream of this host: by sources, units, links and monitors,
    /// and received from other hosts. Each sample counts once, however many consume it.
    pub samples: AtomicU64,
    /// The sources that do not end by themselves (set once the processes are built); a run with
    /// one of them and no `--for` goes on until it is interrupted.
    pub endless: Mutex<Option<Vec<String>>>,
    /// A source stopped because its next sample would be past the end of the run (`--for`).
    pub reached_end: std::sync::atomic::AtomicBool,
}

impl RunStats {
    pub fn edge(&self, stream: &str, consumer: &str) -> Arc<EdgeStats> {
        let stats = Arc::new(EdgeStats::default());
        if let Ok(mut edges) = self.edges.lock() {
            edges.push((stream.to_string(), consumer.to_string(), stats.clone()));
        }
        stats
    }

    pub fn process(&self, name: &str) -> Arc<ProcessStats> {
        let Ok(mut processes) = self.processes.lock() else { return Arc::default() };
        processes.entry(name.to_string()).or_default().clone()
    }

    /// Records which sources never end by themselves (see [`RunStats::endless`]).
    pub fn set_endless(&self, sources: Vec<String>) {
        if let Ok(mut endless) = self.endless.lock() {
            *endless = Some(sources);
        }
    }

    /// Counts samples produced on a stream.
    pub fn count_samples(&self, n: u64) {
        self.samples.fetch_add(n, Ordering::Relaxed);
    }

    pub fn observe_time(&self, t: Time) {
        self.now.fetch_max(t, Ordering::Relaxed);
    }

    /// A source (or another host) produced a sample at clock time `t`: counts it, and keeps the
    /// time of the first.
    pub fn source_sample(&self, t: Time) {
        self.first_sample.get_or_init(|| t);
        self.observe_time(t);
        self.count_samples(1);
    }

    /// Clock time from the run's start to `end`, or from the first sample when that is a date
    /// in simulated time (a replayed bag's clock jumps to its first stamp): the span a progress
    /// line reports.
    pub fn span_to(&self, end: Time, start: Time) -> Time {
        match self.first_sample.get() {
            Some(&first) if start == 0 && first >= DATES => end - first,
            _ => end - start,
        }
    }

    /// A snapshot for the end-of-run summary.
    pub fn summary(&self) -> Summary {
        let edges = snapshot(&self.edges);
        let streams = edges
            .iter()
            .map(|(stream, consumer, s)| {
                let dropped: BTreeMap<&'static str, u64> = DropReason::ALL
                    .iter()
                    .map(|r| (r.as_str(), s.dropped(*r)))
                    .filter(|(_, n)| *n > 0)
                    .collect();
                let violations =
                    DropReason::ALL.iter().filter(|r| r.is_violation()).map(|r| s.dropped(*r)).sum();
                StreamSummary {
                    stream: stream.clone(),
                    consumer: consumer.clone(),
                    produced: s.produced.load(Ordering::Relaxed),
                    delivered: s.delivered.load(Ordering::Relaxed),
                    approximated: s.approximated.load(Ordering::Relaxed),
                    dropped,
                    policy_violations: violations,
                }
            })
            .collect();
        let processes = self
            .processes
            .lock()
            .map(|p| {
                p.iter()
                    .map(|(name, s)| ProcessSummary {
                        process: name.clone(),
                        malformed: s.malformed.load(Ordering::Relaxed),
                        malformed_examples: snapshot(&s.malformed_examples),
                        errors: s.errors.load(Ordering::Relaxed),
                        error_examples: snapshot(&s.error_examples),
                        instances_created: s.instances_created.load(Ordering::Relaxed),
                        instances_removed: s.instances_removed.load(Ordering::Relaxed),
                        warnings: snapshot(&s.warnings),
                        results: snapshot(&s.results),
                    })
                    .filter(|p| {
                        p.malformed + p.errors + p.instances_created > 0
                            || !p.warnings.is_empty()
                            || !p.results.is_empty()
                    })
                    .collect()
            })
            .unwrap_or_default();
        Summary { streams, processes }
    }
}

/// A copy of what a shared list holds now.
fn snapshot<T: Clone>(list: &Mutex<Vec<T>>) -> Vec<T> {
    list.lock().map(|l| l.clone()).unwrap_or_default()
}

#[derive(Debug, Clone, Serialize)]
pub struct StreamSummary {
    pub stream: String,
    pub consumer: String,
    pub produced: u64,
    pub delivered: u64,
    pub approximated: u64,
    pub dropped: BTreeMap<&'static str, u64>,
    pub policy_violations: u64,
}

#[derive(Debug, Clone, Serialize)]
pub struct ProcessSummary {
    pub process: String,
    pub malformed: u64,
    pub malformed_examples: Vec<Malformed>,
    pub errors: u64,
    pub error_examples: Vec<String>,
    pub instances_created: u64,
    pub instances_removed: u64,
    /// What the process warned about (`kpl run` prints them even with `--quiet`).
    pub warnings: Vec<String>,
    pub results: Vec<Outcome>,
}

/// The end-of-run summary (`kpl run` prints it and writes it as `summary.json`).
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    pub streams: Vec<StreamSummary>,
    pub processes: Vec<ProcessSummary>,
}
