//! Pictures of recorded runs: the road network, the tracker's percepts as dots, the objects of
//! link processes (world objects, on-road objects, cars) as squares, hollow where their state was
//! only predicted, labelled with their symbols, the ground truth as thin lines, and recognised
//! situations (interval events naming objects) highlighted on the map and drawn on a timeline.
//! `kpl plot RUN_DIR` is its command; see `docs/plot.md`.
//!
//! - [`Plot::from_recording`] turns a recording (read by `kpl_score::Recording`) into
//!   [`Series`] of [`Track`]s, inside an optional time window.
//! - [`events`] reads interval events (situations) from recorded streams.
//! - [`render`] draws a plot over a network as SVG.
//!
//! The crate is pure: no clock, no threads; the only I/O is reading recordings.
//!
//! ```
//! use kpl_plot::{DrawOptions, Event, Plot, Role, Series, Track, TrackPoint, render};
//! let point = |t: i64, x: f64, measured| TrackPoint { time: t, pos: [x, 0.0], measured, starts_segment: t == 0 };
//! let mut plot = Plot::default();
//! plot.series.push(Series::new("world_onroad", Role::Objects, vec![Track {
//!     id: "oo1".into(),
//!     points: vec![point(0, 0.0, true), point(100_000, 1.0, false)],
//! }]));
//! plot.events.push(Event { name: "moving".into(), stream: "situations".into(), from: 0, to: Some(100_000), objects: vec!["oo1".into()] });
//! let svg = render(&plot, None, &[], &DrawOptions::default());
//! assert!(svg.contains(">oo1</text>") && svg.contains("fill=\"none\""));
//! ```

mod draw;
mod error;
pub mod events;
mod plot;

pub use draw::{DrawOptions, render};
pub use error::PlotError;
pub use events::Event;
pub use plot::{LABEL_GAP, Plot, PlotOptions, Role, Series, Track, TrackPoint, Window};
