//! Every error this crate returns: loading and checking road networks, and checking parameters.

use std::path::PathBuf;

/// A road network could not be read, written or built.
#[derive(Debug, thiserror::Error)]
pub enum NetworkError {
    #[error("cannot read road network {path}: {source}")]
    Read { path: PathBuf, source: std::io::Error },
    #[error("cannot write road network {path}: {source}")]
    Write { path: PathBuf, source: std::io::Error },
    #[error("road network is not valid JSON of the expected shape: {0}")]
    Json(#[from] serde_json::Error),
    #[error("road network has {} problem(s):\n{}", .0.len(), list(.0))]
    Invalid(Vec<NetworkProblem>),
}

fn list(problems: &[NetworkProblem]) -> String {
    problems.iter().map(|p| format!("  - {p}")).collect::<Vec<_>>().join("\n")
}

/// One thing wrong with a road network file; building reports all of them at once.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NetworkProblem {
    #[error("format is {found:?}, expected \"kpl-road-network\"")]
    WrongFormat { found: String },
    #[error("version {found} is not supported (this build reads version 1)")]
    UnsupportedVersion { found: u32 },
    #[error("{what} id {id:?} is used twice")]
    DuplicateId { what: &'static str, id: String },
    #[error("{what} {id:?}: {field} must be {expected}, found {found}")]
    BadNumber { what: &'static str, id: String, field: &'static str, expected: &'static str, found: f64 },
    #[error("road {road:?} refers to node {node:?}, which does not exist")]
    UnknownNode { road: String, node: String },
    #[error("road {road:?} has no length (its points coincide)")]
    ZeroLength { road: String },
    #[error("road {road:?} has no lanes")]
    NoLanes { road: String },
    #[error(
        "road {road:?} is {length:.1} m long, too short for the crossings at its ends \
         ({trim:.1} m of it lies inside them); move the nodes apart or give them a smaller radius_m"
    )]
    TooShort { road: String, length: f64, trim: f64 },
    #[error("occluder {occluder:?} refers to road {road:?}, which does not exist")]
    UnknownRoad { occluder: String, road: String },
    #[error(
        "occluder {occluder:?} covers {from_m} m to {to_m} m, which is not inside road {road:?} (0 to {length:.1} m)"
    )]
    OccluderOutsideRoad { occluder: String, road: String, from_m: f64, to_m: f64, length: f64 },
    #[error("the network has no roads")]
    Empty,
}

/// Simulator parameters that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ParamsError {
    #[error("invalid simulator parameters: {0}")]
    Json(#[from] serde_json::Error),
    #[error("parameter `{name}` must be {expected}, found {found}")]
    OutOfRange { name: &'static str, expected: &'static str, found: String },
    #[error("unknown scenario {name:?}; the built-in scenarios are {}", crate::scenarios::NAMES.join(", "))]
    UnknownScenario { name: String },
    #[error(
        "{n_cars} cars do not fit on this road network ({lane_km:.1} km of lanes holds at most {capacity})"
    )]
    TooManyCars { n_cars: u32, lane_km: f64, capacity: u64 },
    #[error(transparent)]
    Network(#[from] NetworkError),
}
