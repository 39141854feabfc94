//! Reading road networks and occluder files from disk: gzip is recognised by its magic bytes
//! (whatever the file is called), the format by its first character (`{`: the project's JSON,
//! `<`: SUMO's XML), looked at before the rest is read. Files are limited to [`MAX_FILE_BYTES`]
//! once decompressed (`kpl_core::read`), so a hostile or mistaken file (a gzip bomb, `/dev/zero`)
//! is refused instead of filling memory.
//!
//! ```no_run
//! use kpl_roads::RoadNetwork;
//! let net = RoadNetwork::load(std::path::Path::new("specs/traffic/sumo/grid/net.xml.gz")).unwrap();
//! println!("{} roads", net.roads().len());
//! ```

use std::io::{BufRead, BufReader, Read};
use std::path::Path;

use crate::build::{ProblemSink, occluder_of};
use crate::error::{NetworkError, NetworkProblem};
use crate::format::{NetworkFile, OccluderFile};
use crate::network::{RoadId, RoadNetwork};
use crate::occluders::Occluder;

/// Largest road network or occluder file accepted, decompressed: 1 GiB.
pub const MAX_FILE_BYTES: u64 = 1 << 30;

/// Opens a file for reading, decompressing it on the fly when it starts with gzip's magic bytes.
pub fn open(path: &Path) -> Result<Box<dyn BufRead + Send>, std::io::Error> {
    let file = kpl_core::read::open(path)?;
    let mut reader = BufReader::with_capacity(1 << 16, file);
    let gzipped = reader.fill_buf()?.starts_with(&[0x1f, 0x8b]);
    Ok(if gzipped {
        Box::new(BufReader::with_capacity(1 << 16, flate2::bufread::MultiGzDecoder::new(reader)))
    } else {
        Box::new(reader)
    })
}

/// The whole text of a file (gzipped or not), at most [`MAX_FILE_BYTES`] (read with
/// `kpl_core::read`, so memory never grows past the limit).
pub fn read_text(path: &Path) -> Result<String, NetworkError> {
    let reader = open(path).map_err(|source| NetworkError::Read { path: path.to_path_buf(), source })?;
    read_rest(path, reader)
}

fn read_rest(path: &Path, reader: impl Read) -> Result<String, NetworkError> {
    let read_error = |source| NetworkError::Read { path: path.to_path_buf(), source };
    let bytes = kpl_core::read::read_capped(reader, MAX_FILE_BYTES as usize)
        .map_err(read_error)?
        .ok_or_else(|| NetworkError::TooLarge { path: path.to_path_buf(), limit: MAX_FILE_BYTES })?;
    String::from_utf8(bytes).map_err(|e| {
        read_error(std::io::Error::new(std::io::ErrorKind::InvalidData, format!("not UTF-8 text: {e}")))
    })
}

/// The text of a network or occluder file and what it is. The kind is told from the first bytes
/// before the rest is read, so a file that is neither (`/dev/zero`, a picture) is refused at once.
fn read_network_text(path: &Path) -> Result<(Kind, String), NetworkError> {
    let mut reader = open(path).map_err(|source| NetworkError::Read { path: path.to_path_buf(), source })?;
    let start =
        reader.fill_buf().map_err(|source| NetworkError::Read { path: path.to_path_buf(), source })?;
    let start = String::from_utf8_lossy(&start[..start.len().min(512)]).into_owned();
    if !start.trim_start_matches('\u{feff}').trim().is_empty() {
        kind_of(path, &start)?;
    }
    let text = read_rest(path, reader)?;
    Ok((kind_of(path, &text)?, text))
}

/// What a file's text is, from its first character after white space and a byte order mark.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Json,
    Xml,
}

fn kind_of(path: &Path, text: &str) -> Result<Kind, NetworkError> {
    let start = text.trim_start_matches('\u{feff}').trim_start();
    match start.chars().next() {
        Some('{') => Ok(Kind::Json),
        Some('<') => Ok(Kind::Xml),
        _ => Err(NetworkError::UnknownFormat {
            path: path.to_path_buf(),
            start: start.chars().take(20).collect(),
        }),
    }
}

impl RoadNetwork {
    /// Reads a network: the project's JSON or a SUMO `.net.xml`, either of them gzipped.
    pub fn load(path: &Path) -> Result<RoadNetwork, NetworkError> {
        let (kind, text) = read_network_text(path)?;
        match kind {
            Kind::Json => RoadNetwork::from_json_str(&text),
            Kind::Xml => RoadNetwork::from_sumo_str(&text),
        }
    }

    /// Builds a network from the project's JSON form.
    pub fn from_json_str(text: &str) -> Result<RoadNetwork, NetworkError> {
        let file: NetworkFile = serde_json::from_str(text)?;
        RoadNetwork::build(&file)
    }

    /// Reads a SUMO network from the text of its `.net.xml`.
    pub fn from_sumo_str(text: &str) -> Result<RoadNetwork, NetworkError> {
        Ok(RoadNetwork::index(crate::sumo::parts_of(text)?))
    }

    /// The network's JSON form, pretty-printed (`None` for a network read from SUMO).
    pub fn to_json_string(&self) -> Option<String> {
        // Serialising plain structs of strings and finite numbers cannot fail.
        self.file().map(|file| serde_json::to_string_pretty(file).unwrap_or_default())
    }

    /// Writes the network's JSON form.
    pub fn save(&self, path: &Path) -> Result<(), NetworkError> {
        let text = self.to_json_string().ok_or(NetworkError::NoJsonForm)?;
        std::fs::write(path, text).map_err(|source| NetworkError::Write { path: path.to_path_buf(), source })
    }
}

/// Reads occluders for `net` from a file: the JSON form (`{"occluders": [...]}`, items as in a
/// network file) or a SUMO polygon file (`<poly>` elements of an additional file, as
/// `polyconvert` writes them). Road names refer to `net`'s roads.
pub fn read_occluders(path: &Path, net: &RoadNetwork) -> Result<Vec<Occluder>, NetworkError> {
    let (kind, text) = read_network_text(path)?;
    match kind {
        Kind::Json => {
            let file: OccluderFile = serde_json::from_str(&text)?;
            let mut problems: Vec<NetworkProblem> = Vec::new();
            let mut occluders = Vec::new();
            for spec in &file.occluders {
                let road_id = |name: &str, problems: &mut Vec<NetworkProblem>| -> Option<RoadId> {
                    let found = net.road_by_name(name).map(|r| r.id);
                    if found.is_none() {
                        problems.problem(NetworkProblem::UnknownRoad {
                            occluder: spec.id.clone(),
                            road: name.to_string(),
                        });
                    }
                    found
                };
                if let Some(occluder) = occluder_of(spec, net.roads(), &mut problems, road_id) {
                    occluders.push(occluder);
                }
            }
            if problems.is_empty() { Ok(occluders) } else { Err(NetworkError::Invalid(problems)) }
        }
        Kind::Xml => crate::sumo::read_polygons(&text, net),
    }
}
