//! Samples: a value with the time it holds in the world (valid time) and the time the process
//! could use it (available time). `delay = available - valid`.

use kpl_core::{Time, Value};

/// One element of a stream. Cloning is cheap: the value's payload is shared (`Arc`), so a sample
/// fanned out to several consumers is not copied.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// When the value holds in the world (microseconds of the run's clock).
    pub valid: Time,
    /// When the value became available to its consumer's producer.
    pub available: Time,
    pub value: Value,
}

impl Sample {
    pub fn new(valid: Time, available: Time, value: Value) -> Sample {
        Sample { valid, available, value }
    }

    /// `available - valid`.
    pub fn delay(&self) -> Time {
        self.available.saturating_sub(self.valid)
    }
}
