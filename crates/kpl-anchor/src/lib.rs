//! Hierarchical anchoring for KPL, after DyKnow's stream-based hierarchical anchoring (Heintz,
//! Kvarnström and Doherty; the paper's section IV is the specification): link processes that
//! progress establish / reestablish / maintain conditions in metric temporal logic to create,
//! re-identify and drop links between objects of adjacent types, object linkage structures
//! (vision percept -> world object -> on-road object -> car) whose symbols are anchored while
//! they are grounded in a percept, prediction of the objects nothing is linked to, forgetting,
//! and top-down identification.
//!
//! The engine is pure: [`Anchoring::step`] takes the time and the snapshots of the percept
//! sources and returns the changes; the snapshots of every type ([`Anchoring::snapshot`]) and the
//! world model ([`Anchoring::world_model`]) are read after it. `docs/anchoring.md` describes the
//! semantics and the record shapes.
//!
//! ```
//! use kpl_anchor::{Anchoring, AnchorConfig, Snapshot};
//! use kpl_core::{Record, Value};
//! use std::sync::Arc;
//!
//! let text = r#"
//!     type VisionPercept symbol vp { pos: vec2, vel: vec2, size: float }
//!     type WorldObject   symbol wo { pos: vec2, vel: vec2 }
//!     source tracker : list<VisionPercept> = engine.input()
//!     link vision_world : VisionPercept -> WorldObject via anchor.world_from_percept {
//!       establish   eventually[1s, inf] true
//!       reestablish eventually[0, 1s] xydist(from.pos, to.pos) < 10.0
//!       maintain    true
//!     }
//!     predict WorldObject = constant_velocity
//!     forget after 30s
//! "#;
//! let spec = kpl_anchor::registry::check_text(text).unwrap();
//! let mut anchoring = Anchoring::from_spec(&spec, AnchorConfig::default()).unwrap();
//! for i in 0..=10 {
//!     let percept = Record {
//!         id: Some("vp1".into()),
//!         fields: vec![
//!             ("pos".into(), Value::vec2(i as f64, 0.0)),
//!             ("vel".into(), Value::vec2(10.0, 0.0)),
//!             ("size".into(), Value::Float(4.0)),
//!         ],
//!     };
//!     let snapshot = Value::List(vec![Value::Record(Arc::new(percept))].into());
//!     let input = Snapshot { source: "tracker", ty: "VisionPercept", objects: &snapshot };
//!     anchoring.step(i * 100_000, &[input]).unwrap();
//! }
//! // After one second the establish condition made a world object for vp1.
//! assert_eq!(anchoring.grounded_in("wo1"), vec![Arc::from("vp1")]);
//! ```
//!
//! Modules: [`engine`] (the engine and its step), [`link`] (link processes and their per-object
//! instances), [`branches`] (the objects of a prediction's branches), [`store`] (objects and
//! links), [`conditions`] (compiled conditions and their gate, `kpl_mtl::gate`), [`units`] (link units), [`stateful`] (what stateful units see: time, extra inputs,
//! memory), [`kalman`] (the Kalman units), [`predict`] (prediction models), [`implementations`]
//! (both by name), [`networks`] (road networks), [`change`] (change records), [`status`] (the
//! `measured` / `predicted_since` attributes of object records), [`views`] (outputs), [`records`]
//! (record helpers), [`relations`] (traffic relations), [`attributes`] (the road attributes),
//! [`registry`] (signatures for the checker).
//!
//! This crate is an engine: it knows nothing of the stream runtime, the simulators or the wire.
//! Its runtime adapter (link processes as knowledge processes, `anchor.world_model`,
//! `anchor.identify`) is `kpl_std::anchor`; `kpl_std::driver` feeds a spec's simulated trackers
//! straight into it.

pub mod attributes;
pub mod branches;
pub mod change;
pub mod conditions;
pub mod engine;
mod error;
pub mod handover;
pub mod implementations;
pub mod kalman;
pub mod link;
pub mod networks;
pub mod predict;
pub mod records;
pub mod regions;
pub mod registry;
pub mod relations;
pub mod smoother;
pub mod stateful;
pub mod status;
pub mod store;
pub mod units;
pub mod views;

pub use change::{Cause, Change, ChangeKind};
pub use engine::{AnchorConfig, Anchoring, FromSnapshot, Snapshot, StepOutput, Warning};
pub use error::{BuildError, IdentifyError, StepError};
pub use handover::{HandoverError, StructureHandover};
pub use implementations::Implementations;
pub use networks::Networks;
pub use views::{InstanceView, ObjectView, Status};
