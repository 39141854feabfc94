//! Policies enforced for each consumer, as DyKnow's stream generators do: the duration window,
//! the order, the delay, the change policy (including resampling with `sample every`) and the
//! approximation that fills instants without a sample.
//!
//! A [`PolicyFilter`] sits between an edge and its consumer. It is synchronous and has no clock:
//! `now` is an argument, and a resampling filter with `max delay` says when it next needs to be
//! woken ([`PolicyFilter::deadline`]).

use std::sync::Arc;
use std::sync::atomic::Ordering;

use kpl_core::{Time, Value};
use kpl_semantic::hir::{Approximation, Change, Order, Policy};

use crate::sample::Sample;
use crate::stats::{DropReason, EdgeStats};

#[derive(Debug)]
pub struct PolicyFilter {
    policy: Policy,
    stats: Arc<EdgeStats>,
    /// Valid time of the last sample accepted (for the order policy).
    last_valid: Option<Time>,
    /// The last value delivered (for `any change`).
    last_value: Option<Value>,
    /// The most recent sample accepted (for approximation and resampling).
    most_recent: Option<Sample>,
    /// The next resampling instant (`sample every`).
    next_tick: Option<Time>,
    /// Whether `most_recent` has been emitted at some tick (else a newer sample supersedes it).
    recent_used: bool,
}

impl PolicyFilter {
    pub fn new(policy: Policy, stats: Arc<EdgeStats>) -> PolicyFilter {
        PolicyFilter {
            policy,
            stats,
            last_valid: None,
            last_value: None,
            most_recent: None,
            next_tick: None,
            recent_used: false,
        }
    }

    pub fn policy(&self) -> &Policy {
        &self.policy
    }

    /// The most recent sample accepted, whether delivered or not (for approximation).
    pub fn most_recent(&self) -> Option<&Sample> {
        self.most_recent.as_ref()
    }

    /// Applies the policy to one sample; what the consumer should see is pushed to `out`.
    pub fn on_sample(&mut self, sample: Sample, now: Time, out: &mut Vec<Sample>) {
        if let Some((from, to)) = self.policy.window
            && (sample.valid < from || to.is_some_and(|to| sample.valid > to))
        {
            self.stats.count_drop(DropReason::OutsideWindow);
            return;
        }
        if let Some(last) = self.last_valid {
            let out_of_order = match self.policy.order {
                Order::Any => false,
                Order::Monotone => sample.valid < last,
                Order::Strict => sample.valid <= last,
            };
            if out_of_order {
                self.stats.count_drop(DropReason::OutOfOrder);
                return;
            }
        }
        let late = self.policy.max_delay.is_some_and(|max| sample.delay() > max);
        if late && self.policy.approximation == Approximation::None {
            self.stats.count_drop(DropReason::Late);
            return;
        }
        self.last_valid = Some(self.last_valid.map_or(sample.valid, |l| l.max(sample.valid)));
        match self.policy.change {
            Change::SampleEvery(period) => self.resample(sample, period, now, out),
            _ if late => {
                // Too late to deliver, but it is the value to approximate with from now on.
                self.stats.count_drop(DropReason::Late);
                self.most_recent = Some(sample);
            }
            Change::AnyUpdate => {
                if self.policy.approximation == Approximation::UseMostRecent {
                    self.most_recent = Some(sample.clone());
                }
                self.deliver(sample, out);
            }
            Change::AnyChange => {
                if self.last_value.as_ref() == Some(&sample.value) {
                    self.stats.count_drop(DropReason::Unchanged);
                    self.most_recent = Some(sample);
                    return;
                }
                self.last_value = Some(sample.value.clone());
                self.most_recent = Some(sample.clone());
                self.deliver(sample, out);
            }
        }
    }

    fn deliver(&self, sample: Sample, out: &mut Vec<Sample>) {
        self.stats.delivered.fetch_add(1, Ordering::Relaxed);
        out.push(sample);
    }

    /// `sample every T`: one sample at each multiple of `T`, carrying the most recent value at
    /// that instant. A tick is emitted once a later sample shows no more values for it can come
    /// (the stream is in order), or when its `max delay` has passed.
    fn resample(&mut self, sample: Sample, period: Time, now: Time, out: &mut Vec<Sample>) {
        let period = period.max(1);
        let mut tick = *self.next_tick.get_or_insert_with(|| ceil_to(sample.valid, period));
        let mut ticked = false;
        while tick < sample.valid {
            ticked |= self.emit_tick(tick, now, out);
            tick = tick.saturating_add(period);
        }
        if !ticked && !self.recent_used && self.most_recent.is_some() {
            // The previous sample fell between two ticks and a newer one replaces it.
            self.stats.count_drop(DropReason::Resampled);
        }
        self.recent_used = tick == sample.valid;
        if self.recent_used {
            self.deliver(sample.clone(), out);
            tick = tick.saturating_add(period);
        }
        self.next_tick = Some(tick);
        self.most_recent = Some(sample);
    }

    /// Emits the most recent value at `tick`; false when there is none yet.
    fn emit_tick(&mut self, tick: Time, now: Time, out: &mut Vec<Sample>) -> bool {
        let Some(recent) = &self.most_recent else { return false };
        self.stats.approximated.fetch_add(1, Ordering::Relaxed);
        self.stats.delivered.fetch_add(1, Ordering::Relaxed);
        out.push(Sample { valid: tick, available: now.max(recent.available), value: recent.value.clone() });
        self.recent_used = true;
        true
    }

    /// When the filter next needs [`PolicyFilter::on_timer`]: the next resampling tick plus its
    /// `max delay` (resampling without `max delay` waits for later samples or the end).
    pub fn deadline(&self) -> Option<Time> {
        match (self.policy.change, self.policy.max_delay, self.next_tick) {
            (Change::SampleEvery(_), Some(delay), Some(tick)) if self.most_recent.is_some() => {
                Some(tick.saturating_add(delay))
            }
            _ => None,
        }
    }

    /// Emits the resampling ticks whose `max delay` has passed, approximating them.
    pub fn on_timer(&mut self, now: Time, out: &mut Vec<Sample>) {
        let (Change::SampleEvery(period), Some(delay)) = (self.policy.change, self.policy.max_delay) else {
            return;
        };
        let period = period.max(1);
        while let Some(tick) = self.next_tick {
            if tick.saturating_add(delay) > now || self.most_recent.is_none() {
                break;
            }
            self.emit_tick(tick, now, out);
            if tick == Time::MAX {
                self.next_tick = None;
                break;
            }
            self.next_tick = Some(tick.saturating_add(period));
            // The value at later ticks is the same most recent one; the order policy now refers
            // to the tick emitted.
            self.last_valid = Some(self.last_valid.map_or(tick, |l| l.max(tick)));
        }
    }
}

/// The smallest multiple of `period` that is `>= t` (the largest time when there is none).
fn ceil_to(t: Time, period: Time) -> Time {
    let r = t.rem_euclid(period);
    if r == 0 { t } else { (t - r).saturating_add(period) }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use kpl_semantic::hir::Queue;

    fn policy(f: impl FnOnce(&mut Policy)) -> Policy {
        let mut p = Policy::default();
        f(&mut p);
        p
    }

    fn run(policy: Policy, samples: &[(Time, Time, i64)]) -> (Vec<(Time, i64)>, Arc<EdgeStats>) {
        let stats = Arc::new(EdgeStats::default());
        let mut filter = PolicyFilter::new(policy, stats.clone());
        let mut out = Vec::new();
        for &(valid, available, v) in samples {
            filter.on_sample(Sample::new(valid, available, Value::Int(v)), available, &mut out);
        }
        (out.iter().map(|s| (s.valid, s.value.as_i64().unwrap())).collect(), stats)
    }

    #[test]
    fn order_policies_drop_and_count() {
        let samples = [(0, 0, 0), (10, 10, 1), (5, 11, 2), (10, 12, 3), (20, 20, 4)];
        let (out, stats) = run(policy(|p| p.order = Order::Monotone), &samples);
        assert_eq!(out, [(0, 0), (10, 1), (10, 3), (20, 4)]);
        assert_eq!(stats.dropped(DropReason::OutOfOrder), 1);
        let (out, stats) = run(policy(|p| p.order = Order::Strict), &samples);
        assert_eq!(out, [(0, 0), (10, 1), (20, 4)]);
        assert_eq!(stats.dropped(DropReason::OutOfOrder), 2);
        let (out, _) = run(Policy::default(), &samples);
        assert_eq!(out.len(), 5);
    }

    #[test]
    fn any_change_drops_repeats() {
        let (out, stats) = run(
            policy(|p| p.change = Change::AnyChange),
            &[(0, 0, 1), (1, 1, 1), (2, 2, 2), (3, 3, 2), (4, 4, 1)],
        );
        assert_eq!(out, [(0, 1), (2, 2), (4, 1)]);
        assert_eq!(stats.dropped(DropReason::Unchanged), 2);
    }

    #[test]
    fn late_samples_are_dropped_or_approximated() {
        let samples = [(0, 0, 0), (10, 100, 1), (20, 25, 2)];
        let (out, stats) = run(policy(|p| p.max_delay = Some(50)), &samples);
        assert_eq!(out, [(0, 0), (20, 2)]);
        assert_eq!(stats.dropped(DropReason::Late), 1);
        // With approximation the late value is kept as the most recent one for resampling.
        let (out, _) = run(
            policy(|p| {
                p.max_delay = Some(50);
                p.approximation = Approximation::UseMostRecent;
                p.change = Change::SampleEvery(10);
                p.order = Order::Monotone;
            }),
            &[(0, 0, 0), (10, 100, 1), (25, 30, 2)],
        );
        assert_eq!(out, [(0, 0), (10, 1), (20, 1)]);
    }

    #[test]
    fn window_keeps_only_valid_times_inside() {
        let (out, stats) = run(
            policy(|p| p.window = Some((10, Some(20)))),
            &[(5, 5, 0), (10, 10, 1), (20, 20, 2), (21, 21, 3)],
        );
        assert_eq!(out, [(10, 1), (20, 2)]);
        assert_eq!(stats.dropped(DropReason::OutsideWindow), 2);
    }

    #[test]
    fn sample_every_resamples_on_the_grid() {
        let p = policy(|p| {
            p.change = Change::SampleEvery(100);
            p.approximation = Approximation::UseMostRecent;
            p.order = Order::Monotone;
        });
        // Samples at 30, 60, 250, 300: ticks 100 and 200 carry the value of 60, tick 300 its own.
        let (out, stats) = run(p, &[(30, 30, 1), (60, 60, 2), (250, 250, 3), (300, 300, 4)]);
        assert_eq!(out, [(100, 2), (200, 2), (300, 4)]);
        assert_eq!(stats.approximated.load(Ordering::Relaxed), 2);
    }

    #[test]
    fn sample_every_with_max_delay_emits_on_time() {
        let p = policy(|p| {
            p.change = Change::SampleEvery(100);
            p.approximation = Approximation::UseMostRecent;
            p.order = Order::Monotone;
            p.max_delay = Some(20);
            p.queue = Queue::default();
        });
        let stats = Arc::new(EdgeStats::default());
        let mut filter = PolicyFilter::new(p, stats);
        let mut out = Vec::new();
        filter.on_sample(Sample::new(50, 50, Value::Int(7)), 50, &mut out);
        assert_eq!(filter.deadline(), Some(120));
        filter.on_timer(119, &mut out);
        assert!(out.is_empty());
        filter.on_timer(125, &mut out);
        assert_eq!(out.iter().map(|s| (s.valid, s.available)).collect::<Vec<_>>(), [(100, 125)]);
        assert_eq!(filter.deadline(), Some(220));
    }
}
