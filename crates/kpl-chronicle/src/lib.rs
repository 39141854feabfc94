//! Chronicle recognition (DyKnow's recognition of complex events such as reckless overtakes) as a
//! pure library: time is an argument, nothing is spawned, nothing reads a clock.
//!
//! A chronicle is a parameterised class of complex events: a simple temporal network whose nodes
//! are occurrences of events (a predicate over objects becoming true or false, a monitor's
//! verdict changing, another chronicle recognised) and whose edges are metric constraints between
//! their times, plus conditions that must hold or must not happen in between.
//!
//! - [`stn`]: consistency and minimal networks (Floyd-Warshall; a negative cycle names its
//!   constraints). `kpl check` uses it for its diagnostics.
//! - [`model`]: a chronicle with numbered parameters, nodes and conditions; [`model::Chronicle::compile`].
//! - [`fluent`]: fluents with hysteresis (an entry and a leave condition), for relations that a
//!   raw threshold would make flicker.
//! - [`recognise`]: the incremental recogniser, a partial instance per candidate binding,
//!   dropped when its deadline passes.
//! - [`merge`]: one report per situation, where several recognitions tell of the same one.
//!
//! ```
//! use kpl_chronicle::model::{Chronicle, Event, Pattern, SourceId};
//! use kpl_chronicle::recognise::{Config, Recogniser};
//! use kpl_chronicle::stn::Constraint;
//! let (behind, ahead) = (SourceId(0), SourceId(1));
//! // behind(a, b) becomes true, then in_front(a, b) becomes true 1 to 10 s later
//! let overtake = Chronicle {
//!     name: "overtake".into(),
//!     source: SourceId(2),
//!     params: 2,
//!     events: vec![
//!         Pattern { source: behind, args: vec![0, 1], value: true },
//!         Pattern { source: ahead, args: vec![0, 1], value: true },
//!     ],
//!     constraints: vec![Constraint { later: 1, earlier: 0, lo: Some(1_000_000), hi: Some(10_000_000) }],
//!     holds: vec![],
//!     nevers: vec![],
//! };
//! let mut r = Recogniser::new(vec![overtake.compile().unwrap()], Config::default()).unwrap();
//! let event = |source, value| Event { source, args: vec!["car1", "car2"], value, time: 0 };
//! assert!(r.step(0, vec![event(behind, true)]).unwrap().is_empty());
//! let found = r.step(4_000_000, vec![event(ahead, true)]).unwrap();
//! assert_eq!(found[0].binding, ["car1", "car2"]);
//! assert_eq!(found[0].times, [0, 4_000_000]);
//! ```

pub mod fluent;
pub mod merge;
pub mod model;
pub mod recognise;
pub mod stn;
