//! Fluents with hysteresis: a qualitative relation that a raw threshold would make flicker (two
//! cars 20 m apart measured with 1 m of noise are `close(a, b, 20.0)` one frame in two) is given
//! an entry condition and a leave condition instead, and keeps its value between them.
//!
//! `hysteresis(enter, leave)` in a chronicle's predicate is [`step`]: a fluent that is false
//! becomes true when `enter` holds; one that is true becomes false when `leave` holds. With a
//! quantity `x` and thresholds `e <= l`, `enter = x < e` and `leave = x > l` make a relation
//! that never changes more often than the raw `x < c` for any `c` in `[e, l]`
//! (`tests/hysteresis.rs` checks it), since between a rise (`x < e`) and the next fall (`x > l`)
//! `x` crosses every such `c`.
//!
//! ```
//! use kpl_chronicle::fluent::step;
//! // close: enter under 20 m, leave over 25 m
//! let mut close = false;
//! let mut values = Vec::new();
//! for d in [30.0, 21.0, 19.5, 20.5, 24.0, 19.0, 26.0, 22.0] {
//!     close = step(close, d < 20.0, d > 25.0);
//!     values.push(close);
//! }
//! assert_eq!(values, [false, false, true, true, true, true, false, false]);
//! ```

/// The fluent's next value: from false, `enter`; from true, `!leave`.
pub fn step(previous: bool, enter: bool, leave: bool) -> bool {
    if previous { !leave } else { enter }
}
