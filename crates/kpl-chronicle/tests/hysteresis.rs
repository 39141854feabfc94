//! Hysteresis against raw thresholds: hand-worked cases, and the property that a fluent with an
//! entry threshold `e` and a leave threshold `l >= e` never changes more often than the raw
//! relation `x < c` for any `c` in `[e, l]`, on any signal.

use kpl_chronicle::fluent::step;
use proptest::prelude::*;

/// The values of `hysteresis(x < enter, x > leave)` along `xs`, from false.
fn fluent(xs: &[f64], enter: f64, leave: f64) -> Vec<bool> {
    let mut value = false;
    xs.iter()
        .map(|&x| {
            value = step(value, x < enter, x > leave);
            value
        })
        .collect()
}

/// Changes along a sequence of values, from false (a first true is a change).
fn changes(values: &[bool]) -> usize {
    let mut previous = false;
    values
        .iter()
        .filter(|&&v| {
            let changed = v != previous;
            previous = v;
            changed
        })
        .count()
}

#[test]
fn hand_worked() {
    // close: enter under 20 m, leave over 25 m; two cars jittering around 20 m.
    let d = [22.0, 19.8, 20.3, 19.9, 20.1, 24.9, 25.1, 19.0];
    assert_eq!(fluent(&d, 20.0, 25.0), [false, true, true, true, true, true, false, true]);
    let raw: Vec<bool> = d.iter().map(|&x| x < 20.0).collect();
    assert_eq!(raw, [false, true, false, true, false, false, false, true]);
    assert_eq!((changes(&fluent(&d, 20.0, 25.0)), changes(&raw)), (3, 5));
    // Equal thresholds: the raw relation itself.
    assert_eq!(fluent(&d, 20.0, 20.0), [false, true, false, true, false, false, false, true]);
    // enter wins from false, leave from true.
    assert!(step(false, true, true));
    assert!(!step(true, true, true));
    assert!(step(true, false, false));
    assert!(!step(false, false, false));
}

proptest! {
    #[test]
    fn hysteresis_changes_no_more_often_than_a_raw_threshold(
        xs in prop::collection::vec(-50.0f64..50.0, 0..200),
        enter in -20.0f64..20.0,
        width in 0.0f64..20.0,
        at in 0.0f64..=1.0,
    ) {
        let leave = enter + width;
        let c = enter + at * width;
        let raw: Vec<bool> = xs.iter().map(|&x| x < c).collect();
        let hyst = fluent(&xs, enter, leave);
        prop_assert!(changes(&hyst) <= changes(&raw), "{} > {}", changes(&hyst), changes(&raw));
        // And it is the raw relation wherever the signal is outside the band.
        for (x, h) in xs.iter().zip(&hyst) {
            if *x < enter { prop_assert!(*h); }
            if *x > leave { prop_assert!(!*h); }
        }
    }
}
