//! Every error this crate returns: checking parameters, and what goes wrong building what they
//! name (road networks, recorded traffic).

/// Simulator parameters that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ParamsError {
    #[error("invalid simulator parameters: {0}")]
    Json(#[from] serde_json::Error),
    #[error("parameter `{name}` must be {expected}, found {found}")]
    OutOfRange { name: &'static str, expected: &'static str, found: String },
    #[error("unknown scenario {name:?}; the built-in scenarios are {}", kpl_roads::scenarios::NAMES.join(", "))]
    UnknownScenario { name: String },
    #[error(
        "{n_cars} cars do not fit on this road network ({lane_km:.1} km of lanes holds at most {capacity})"
    )]
    TooManyCars { n_cars: u32, lane_km: f64, capacity: u64 },
    #[error("parameter `{name}` has no effect here: {reason}")]
    NoEffect { name: &'static str, reason: &'static str },
    #[error("parameter `{name}` needs `{needs}`: {reason}")]
    Needs { name: &'static str, needs: &'static str, reason: &'static str },
    #[error(transparent)]
    Camera(#[from] crate::camera::CameraError),
    #[error(transparent)]
    Network(#[from] kpl_roads::NetworkError),
    #[error(transparent)]
    Recording(#[from] crate::recorded::RecordingError),
}
