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
}
