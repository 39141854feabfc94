//! Valid times in messages and tables: microseconds shown as seconds.

use kpl_core::Time;

/// `59900000` as `59.9 s`.
pub fn seconds(t: Time) -> String {
    format!("{} s", t as f64 / 1e6)
}

#[cfg(test)]
mod tests {
    #[test]
    fn shows_seconds() {
        assert_eq!(super::seconds(59_900_000), "59.9 s");
        assert_eq!(super::seconds(0), "0 s");
        assert_eq!(super::seconds(-1_500_000), "-1.5 s");
    }
}
