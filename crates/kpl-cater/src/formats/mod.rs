//! LA-CATER's files, read as CATER's renderer and OPNet's scripts write them (and written the same
//! way by the generator):
//!
//! - [`GroundTruth`]: `<video>_bb.json`, every object's whole box `[x, y, w, h]` per frame;
//! - [`Scene`]: CATER's scene JSON (objects with Blender instance names and per-frame `locations`,
//!   `movements` with `_no_op` records, the camera as a location list);
//! - [`PerceptionFile`]: what a perception module reported per frame, from OPNet's per-video
//!   pickles ([`pickle`]) or this project's JSON;
//! - [`annotations`]: OPNet's frame annotation text files (`video<TAB>frame,frame,...`);
//! - predictions `<video>_bb.json`: a snitch box `[x1, y1, x2, y2]` per frame.
//!
//! Every number is checked on reading: a box with a coordinate beyond ±[`MAX_COORDINATE`] pixels, a
//! negative size, a frame number out of range or a movement of an object the scene does not have is
//! a data error naming the file and the place, never a silently wrong score.

mod annotations_file;
mod ground_truth;
mod perception;
pub mod pickle;
mod pickle_guard;
mod scene;

use std::path::Path;

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::error::CaterError;

pub use annotations_file::{Annotations, read_annotation_file, write_annotation_file};
pub use ground_truth::GroundTruth;
pub use perception::{Detection, Dropped, MAX_DROPPED_SHARE, PerceptionFile};
pub use scene::{CameraField, Directions, Locations, Movement, MovementKind, Scene, SceneObject};

/// Frames per video (LA-CATER's labels cover the first 300 of the 301 rendered frames).
pub const FRAMES: usize = 300;
/// The last frame CATER's movements may name (Blender renders frames 0 to 300).
pub const LAST_KEYFRAME: i64 = 300;
/// Frame size in pixels.
pub const WIDTH: f64 = 320.0;
pub const HEIGHT: f64 = 240.0;
/// The snitch's instance name in scene JSON.
pub const SNITCH_INSTANCE: &str = "Spl_0";
pub use crate::classes::SNITCH_CLASS;
/// The snitch's key in `<video>_bb.json`.
pub const SNITCH_KEY: &str = "small_gold_spl_metal_Spl_0";
/// Boxes are pixels of a 320x240 video: a coordinate beyond this is not a box but bad data.
pub const MAX_COORDINATE: f64 = 100_000.0;

/// An integer box `[x1, y1, x2, y2]`, OPNet's convention (inclusive pixel corners).
pub type IntBox = [i32; 4];

/// The most bytes a scene JSON, `_bb.json`, perception or prediction file may have. LA-CATER's are
/// well under 1 MiB; a larger input (a device such as `/dev/zero`, a wrong file) is refused before
/// it can fill the memory.
pub const MAX_JSON_BYTES: u64 = 64 << 20;
/// The most bytes an annotation file or a list of videos may have (OPNet's annotation files for
/// all 14,000 videos of LA-CATER would be about 17 MiB).
pub const MAX_LIST_BYTES: u64 = 64 << 20;
/// The most bytes a perception pickle may have (OPNet's are about 100 KiB).
pub const MAX_PICKLE_BYTES: u64 = 16 << 20;

/// Reads a whole file through `kpl_core::read` (the workspace's one capped reader), refusing one
/// larger than `cap` bytes (a data error naming the file): a regular file that large is refused
/// before it is read, a device or pipe is read to one byte past the cap and no further, so neither
/// can exhaust the memory. A directory is refused too.
pub fn read_capped(path: &Path, cap: u64) -> Result<Vec<u8>, CaterError> {
    use kpl_core::read::{ReadError, read_file};
    let limit = usize::try_from(cap).unwrap_or(usize::MAX);
    read_file(path, limit).map_err(|e| match e {
        ReadError::Io { path, source } => CaterError::Io { path, source },
        ReadError::TooLarge { path, limit } => CaterError::invalid(
            &path,
            format!(
                "larger than {}, the most this kind of file may have (is it the right file, not a device?)",
                kpl_core::read::size_in_words(limit)
            ),
        ),
        ReadError::Directory { path } => CaterError::invalid(&path, "a directory, not a file"),
    })
}

/// [`read_capped`] as UTF-8 text.
pub fn read_capped_text(path: &Path, cap: u64) -> Result<String, CaterError> {
    String::from_utf8(read_capped(path, cap)?)
        .map_err(|e| CaterError::invalid(path, format!("not UTF-8 text: {e}")))
}

pub(crate) fn read_json<T: DeserializeOwned>(path: &Path) -> Result<T, CaterError> {
    let bytes = read_capped(path, MAX_JSON_BYTES)?;
    serde_json::from_slice(&bytes).map_err(|source| CaterError::Json { path: path.to_owned(), source })
}

pub(crate) fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), CaterError> {
    let text =
        serde_json::to_vec(value).map_err(|source| CaterError::Json { path: path.to_owned(), source })?;
    std::fs::write(path, text).map_err(|source| CaterError::Io { path: path.to_owned(), source })
}

/// Whether a coordinate is a finite number within ±[`MAX_COORDINATE`].
pub(crate) fn coordinate_ok(v: f64) -> bool {
    v.is_finite() && v.abs() <= MAX_COORDINATE
}

/// A snitch prediction file: per frame `[x1, y1, x2, y2]` (OPNet's `write_bb_predictions_to_file`).
pub fn read_predictions(path: &Path) -> Result<Vec<IntBox>, CaterError> {
    let raw: Vec<[f64; 4]> = read_json(path)?;
    raw.iter()
        .enumerate()
        .map(|(frame, b)| {
            if b.iter().all(|v| coordinate_ok(*v)) {
                Ok(b.map(|v| v as i32))
            } else {
                Err(CaterError::invalid(path, format!("frame {frame}: box {b:?} is not a pixel box")))
            }
        })
        .collect()
}

pub fn write_predictions(path: &Path, boxes: &[IntBox]) -> Result<(), CaterError> {
    write_json(path, &boxes)
}
