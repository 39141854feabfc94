//! Action-aware perceptual anchoring (AAPA, Kaur et al.): a pure library that maintains a world
//! model of anchored objects from per-frame detections, agent actions and camera poses.
//!
//! - [`Aapa::step`] runs one cycle: camera movement alignment, consecutive frame alignment (eq. 1,
//!   optimal assignment, threshold θ), confidence (conf+, conf-, θ_anch, θ_inf), hypothesis
//!   reasoning (attached, occluded, out of view, lost) and attachments from actions.
//! - [`WorldState`] is its output and its memory: the caller feeds it back each cycle (Fig. 2).
//! - [`Params`] holds every parameter, with the paper's values ([`Params::cater`],
//!   [`Params::paper_cater`], [`Params::gearbox`]).
//! - [`gearbox`] simulates the paper's gearbox assembly as per-cycle inputs.
//!
//! No clock, no I/O, no threads: time is an argument, so runs are reproducible from traces.

mod aapa;
mod align;
mod error;
pub mod gearbox;
mod geometry;
mod params;
mod types;

pub use aapa::Aapa;
pub use error::AapaError;
pub use geometry::{alignment_cost, intersects};
pub use params::{
    ActionRule, CameraModel, ChildPlacement, Effect, Extensions, ImageSize, MotionProfile, Params,
    RelationRule,
};
pub use types::{
    Action, ActionPhase, Anchor, AnchorStatus, Attachment, Binding, CameraPose, Candidate, Percept, Relation,
    StillBox, Symbol, WorldState, bbox_array,
};
