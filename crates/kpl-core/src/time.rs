//! Instants and durations as integer microseconds, and the units the language accepts.

use serde::{Deserialize, Serialize};

/// An instant or a duration in microseconds. Valid and available times of samples, formula
/// interval bounds and the simulated clock all use it, so no conversion happens between layers.
pub type Time = i64;

/// A unit a duration may be written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum TimeUnit {
    /// microseconds (`us`)
    Us,
    /// milliseconds (`ms`)
    Ms,
    /// seconds (`s`)
    S,
    /// minutes (`min`)
    Min,
    /// hours (`h`)
    H,
}

impl TimeUnit {
    /// All units, smallest first.
    pub const ALL: [TimeUnit; 5] = [TimeUnit::Us, TimeUnit::Ms, TimeUnit::S, TimeUnit::Min, TimeUnit::H];

    /// Microseconds in one of this unit.
    pub const fn micros(self) -> i64 {
        match self {
            TimeUnit::Us => 1,
            TimeUnit::Ms => 1_000,
            TimeUnit::S => 1_000_000,
            TimeUnit::Min => 60_000_000,
            TimeUnit::H => 3_600_000_000,
        }
    }

    /// The suffix as written in KPL (`ms`, `s`, ...).
    pub const fn suffix(self) -> &'static str {
        match self {
            TimeUnit::Us => "us",
            TimeUnit::Ms => "ms",
            TimeUnit::S => "s",
            TimeUnit::Min => "min",
            TimeUnit::H => "h",
        }
    }

    /// Parses a suffix as written in KPL or on the command line.
    pub fn from_suffix(s: &str) -> Option<TimeUnit> {
        TimeUnit::ALL.into_iter().find(|u| u.suffix() == s)
    }

    /// `n` of this unit in microseconds, or `None` on overflow.
    pub fn to_micros(self, n: i64) -> Option<Time> {
        n.checked_mul(self.micros())
    }

    /// A fractional amount of this unit in microseconds, rounded to the nearest microsecond;
    /// `None` when it is not finite, negative or out of range.
    pub fn float_to_micros(self, x: f64) -> Option<Time> {
        let us = (x * self.micros() as f64).round();
        // 2^62 keeps sums of two such durations from overflowing.
        (us.is_finite() && (0.0..4.6e18).contains(&us)).then_some(us as i64)
    }
}

/// Formats microseconds in the largest unit that divides them exactly (`1500ms`, `2s`, `0s`).
pub fn format_micros(us: Time) -> String {
    if us == 0 {
        return "0s".to_string();
    }
    for unit in TimeUnit::ALL.iter().rev() {
        if us % unit.micros() == 0 {
            return format!("{}{}", us / unit.micros(), unit.suffix());
        }
    }
    format!("{us}us")
}

/// A positive duration written as a number and a unit, as the command line takes it (`60s`,
/// `1.5min`, `250ms`), in microseconds.
pub fn parse_duration(text: &str) -> Result<Time, String> {
    let split = text.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(text.len());
    let (number, unit) = text.split_at(split);
    let unit = TimeUnit::from_suffix(unit)
        .ok_or_else(|| format!("`{text}`: write a number and a unit (us, ms, s, min, h), e.g. 60s"))?;
    let value: f64 = number.parse().map_err(|_| format!("`{text}` is not a duration"))?;
    unit.float_to_micros(value)
        .filter(|us| *us > 0)
        .ok_or_else(|| format!("`{text}` is not a positive duration"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_in_largest_exact_unit() {
        assert_eq!(format_micros(1_500_000), "1500ms");
        assert_eq!(format_micros(2_000_000), "2s");
        assert_eq!(format_micros(120_000_000), "2min");
        assert_eq!(format_micros(7), "7us");
        assert_eq!(format_micros(0), "0s");
    }

    #[test]
    fn fractional_units_round_and_reject_nonsense() {
        assert_eq!(TimeUnit::S.float_to_micros(1.5), Some(1_500_000));
        assert_eq!(TimeUnit::S.float_to_micros(f64::NAN), None);
        assert_eq!(TimeUnit::S.float_to_micros(-1.0), None);
        assert_eq!(TimeUnit::H.to_micros(i64::MAX), None);
    }
}
