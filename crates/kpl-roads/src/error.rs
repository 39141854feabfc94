//! Every error this crate returns: reading, checking and writing road networks (JSON or SUMO) and
//! occluder files.

use std::path::PathBuf;

/// A road network or an occluder file could not be read, written or built.
#[derive(Debug, thiserror::Error)]
pub enum NetworkError {
    #[error("cannot read {path}: {source}")]
    Read { path: PathBuf, source: std::io::Error },
    #[error("cannot write road network {path}: {source}")]
    Write { path: PathBuf, source: std::io::Error },
    #[error(
        "{path} is larger than {} (decompressed), the limit of road network and occluder files; is it the right file?",
        kpl_core::read::size_in_words(*limit)
    )]
    TooLarge { path: PathBuf, limit: u64 },
    #[error(
        "{path} is neither a KPL road network (JSON) nor a SUMO network (.net.xml): it starts with {start:?}"
    )]
    UnknownFormat { path: PathBuf, start: String },
    #[error("road network is not valid JSON of the expected shape: {0}")]
    Json(#[from] serde_json::Error),
    #[error("{what} is not well-formed XML at line {line}, column {column}: {message}")]
    Xml { what: &'static str, line: usize, column: usize, message: String },
    #[error("road network has {} problem(s):\n{}", .0.len(), list(.0))]
    Invalid(Vec<NetworkProblem>),
    #[error("this road network was read from a SUMO file and has no KPL JSON form to write")]
    NoJsonForm,
}

fn list(problems: &[NetworkProblem]) -> String {
    problems.iter().map(|p| format!("  - {p}")).collect::<Vec<_>>().join("\n")
}

/// One thing wrong with a road network (or occluder) file; reading reports all of them at once.
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
    #[error(
        "occluder {occluder:?} must give either `polygon` (at least 3 points) or `road` with `from_m` and `to_m`"
    )]
    OccluderShape { occluder: String },
    #[error("the network has no roads")]
    Empty,
    #[error("line {line}: {element} {id:?}: attribute `{attribute}` is missing")]
    MissingAttribute { line: usize, element: &'static str, id: String, attribute: &'static str },
    #[error("line {line}: {element} {id:?}: attribute `{attribute}` is not {expected}: {found:?}")]
    BadAttribute {
        line: usize,
        element: &'static str,
        id: String,
        attribute: &'static str,
        expected: &'static str,
        found: String,
    },
    #[error("line {line}: {element} {id:?} refers to {what} {name:?}, which is not in the network")]
    UnknownReference { line: usize, element: &'static str, id: String, what: &'static str, name: String },
    #[error("the file has no <net> element: it is not a SUMO network")]
    NotASumoNetwork,
}
