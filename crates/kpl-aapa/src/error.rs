//! The errors AAPA reports: invalid parameters at construction, invalid input in a cycle. Input
//! that is merely unusable (an action naming an unknown object) is not an error; it is recorded in
//! the world state's notes.

use kpl_core::Time;

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AapaError {
    #[error("invalid parameter `{name}`: {reason}")]
    InvalidParam { name: &'static str, reason: String },
    #[error("percept `{label}` has an invalid box [{x1}, {y1}, {x2}, {y2}] (need finite x1 <= x2, y1 <= y2)")]
    InvalidBox { label: String, x1: f64, y1: f64, x2: f64, y2: f64 },
    #[error("cycle time {time} does not come after the previous cycle's {previous}")]
    TimeNotIncreasing { time: Time, previous: Time },
    #[error("action `{name}` has {got} argument(s), its rule needs {need}")]
    ActionArity { name: String, got: usize, need: usize },
    #[error("a camera pose was given but the parameters have no camera model")]
    NoCameraModel,
    #[error("camera pose has a non-finite coordinate or puts the work surface behind the camera")]
    InvalidCameraPose,
}
