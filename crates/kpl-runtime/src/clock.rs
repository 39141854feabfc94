//! The one source of time of a run. Every process asks the [`Clock`]; nothing reads the system
//! time directly, so a simulated run is reproducible.
//!
//! - `Wall` runs in real time; `now()` counts microseconds since the UNIX epoch, so hosts of one
//!   deployment agree on times.
//! - `Sim` runs on tokio's paused clock in a single-threaded runtime: time jumps to the next timer
//!   as soon as every task is idle, so simulated time runs as fast as the work allows and the order
//!   of events depends only on the spec, the inputs and the seed. `now()` starts at 0.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use kpl_core::Time;
use serde::Serialize;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ClockKind {
    Wall,
    Sim,
}

#[derive(Debug, Clone)]
pub struct Clock {
    kind: ClockKind,
    origin: tokio::time::Instant,
    /// `now()` at `origin`.
    epoch: Time,
    /// The wall clock when the run started, for the report's wall time (whatever the kind).
    wall_origin: std::time::Instant,
}

impl Clock {
    /// Creates the clock. Must be called inside the run's tokio runtime (for `Sim`, one started
    /// with paused time).
    #[allow(clippy::disallowed_methods)] // the one place that reads the system's clocks
    pub fn new(kind: ClockKind) -> Clock {
        let epoch = match kind {
            ClockKind::Sim => 0,
            ClockKind::Wall => SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0, |d| i64::try_from(d.as_micros()).unwrap_or(i64::MAX)),
        };
        Clock { kind, origin: tokio::time::Instant::now(), epoch, wall_origin: std::time::Instant::now() }
    }

    /// Wall-clock microseconds since the clock was made: how long a run took, whatever its kind
    /// (the report's `wall_elapsed`; never a time stamp of a sample).
    pub fn wall_elapsed(&self) -> Time {
        i64::try_from(self.wall_origin.elapsed().as_micros()).unwrap_or(i64::MAX)
    }

    pub fn kind(&self) -> ClockKind {
        self.kind
    }

    /// The current time in microseconds.
    pub fn now(&self) -> Time {
        self.epoch + i64::try_from(self.origin.elapsed().as_micros()).unwrap_or(i64::MAX / 2)
    }

    /// The time the run started (0 for simulated time).
    pub fn start(&self) -> Time {
        self.epoch
    }

    /// Microseconds since the run started.
    pub fn elapsed(&self) -> Time {
        self.now() - self.epoch
    }

    /// Waits until `now() >= t` (returns at once if it already is).
    pub async fn sleep_until(&self, t: Time) {
        let offset = u64::try_from(t.saturating_sub(self.epoch)).unwrap_or(0);
        tokio::time::sleep_until(self.origin + Duration::from_micros(offset)).await;
    }

    /// The tokio instant of clock time `t`.
    pub fn instant(&self, t: Time) -> tokio::time::Instant {
        self.origin + Duration::from_micros(u64::try_from(t.saturating_sub(self.epoch)).unwrap_or(0))
    }
}

/// Where `--for D` ends a run. On the wall clock, and on the simulated clock when the run's
/// samples are times from 0, the end is the run's start plus `D`. A simulated run whose sources
/// replay dated stamps (a rosbag2 bag's `header.stamp`) jumps from 0 to its first date at once,
/// so `D` counts from that date instead: the end is fixed by the first time a source waits for,
/// if that is a date ([`crate::stats::DATES`]). Shared by the sources and the run's end watcher.
#[derive(Debug)]
pub struct RunEnd {
    duration: Time,
    start: Time,
    /// The end, once fixed: at once on the wall clock, by the first wait on the simulated one.
    at: std::sync::OnceLock<Time>,
}

impl RunEnd {
    pub fn new(clock: &Clock, duration: Time) -> RunEnd {
        let end = RunEnd { duration, start: clock.start(), at: std::sync::OnceLock::new() };
        if clock.kind() == ClockKind::Wall {
            end.fixed(clock.start());
        }
        end
    }

    /// The end, fixing it if nothing has: `first` is the first time a source waits for (a
    /// date on the simulated clock moves the end to `first + D`).
    pub fn fixed(&self, first: Time) -> Time {
        *self.at.get_or_init(|| {
            let from = if self.start == 0 && first >= crate::stats::DATES { first } else { self.start };
            from.saturating_add(self.duration)
        })
    }

    /// The end if it is fixed; otherwise the earliest it can be (the start plus `D`).
    pub fn earliest(&self) -> Time {
        self.at.get().copied().unwrap_or_else(|| self.start.saturating_add(self.duration))
    }

    /// Waits until the clock reaches the end. On the simulated clock, time only jumps when
    /// every task waits, so by the time the earliest end comes every source has asked for its
    /// first time: if none fixed the end by then, it is the earliest.
    pub async fn reached(&self, clock: &Clock) {
        loop {
            let end = self.earliest();
            clock.sleep_until(end).await;
            let fixed = *self.at.get_or_init(|| end);
            if fixed <= clock.now() {
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test(start_paused = true)]
    async fn simulated_time_jumps_to_timers() {
        let clock = Clock::new(ClockKind::Sim);
        assert_eq!(clock.now(), 0);
        clock.sleep_until(3_600_000_000).await; // an hour, instantly
        assert_eq!(clock.now(), 3_600_000_000);
        clock.sleep_until(10).await; // in the past: returns at once
        assert_eq!(clock.now(), 3_600_000_000);
    }

    #[tokio::test(start_paused = true)]
    async fn a_dated_replay_s_end_counts_from_its_first_date() {
        let clock = Clock::new(ClockKind::Sim);
        let end = RunEnd::new(&clock, 10_000_000);
        assert_eq!(end.earliest(), 10_000_000, "not fixed yet: from the start");
        let first = 1_700_000_000_000_000;
        assert_eq!(end.fixed(first), first + 10_000_000);
        assert_eq!(end.fixed(0), first + 10_000_000, "fixed once");
        end.reached(&clock).await;
        assert_eq!(clock.now(), first + 10_000_000);
    }

    #[tokio::test(start_paused = true)]
    async fn a_run_from_zero_ends_at_its_duration_and_the_watcher_fixes_it() {
        let clock = Clock::new(ClockKind::Sim);
        let end = RunEnd::new(&clock, 2_000_000);
        assert_eq!(end.fixed(500_000), 2_000_000, "a time from 0 is not a date");
        let other = RunEnd::new(&clock, 3_000_000);
        other.reached(&clock).await; // no source asked: the end is the start plus D
        assert_eq!(clock.now(), 3_000_000);
        assert_eq!(other.fixed(1_700_000_000_000_000), 3_000_000, "too late to move it");
    }
}
