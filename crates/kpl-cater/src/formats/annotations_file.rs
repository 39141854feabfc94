//! OPNet's frame annotation files: one line per video, `<video>\t<frame>,<frame>,...` (the list may
//! be empty), for the frames in which the snitch is contained (`containment_annotations.txt`),
//! contained and moving (`containment_with_move_annotations.txt`) or visible
//! (`visibility_rate_gt_0.txt`); OPNet's `get_frames_mask` reads them.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use super::{LAST_KEYFRAME, MAX_LIST_BYTES, read_capped_text};
use crate::error::CaterError;

/// Video name -> annotated frames (sorted, as written).
pub type Annotations = BTreeMap<String, Vec<usize>>;

/// Reads an annotation file. A frame number that is not a number, or is past frame 300, is a data
/// error naming the line.
pub fn read_annotation_file(path: &Path) -> Result<Annotations, CaterError> {
    let text = read_capped_text(path, MAX_LIST_BYTES)?;
    let mut out = Annotations::new();
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let bad = |reason: String| CaterError::invalid(path, format!("line {}: {reason}", n + 1));
        let (video, frames) =
            line.split_once('\t').ok_or_else(|| bad("expected `<video><TAB><frames>`".into()))?;
        let mut list = Vec::new();
        for item in frames.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let frame: usize = item.parse().map_err(|_| bad(format!("`{item}` is not a frame number")))?;
            if frame as i64 > LAST_KEYFRAME {
                return Err(bad(format!("frame {frame} is past the last frame ({LAST_KEYFRAME})")));
            }
            list.push(frame);
        }
        if out.insert(video.to_owned(), list).is_some() {
            return Err(bad(format!("`{video}` appears twice")));
        }
    }
    Ok(out)
}

/// Writes an annotation file in OPNet's layout.
pub fn write_annotation_file(path: &Path, annotations: &Annotations) -> Result<(), CaterError> {
    let mut text = String::new();
    for (video, frames) in annotations {
        let list: Vec<String> = frames.iter().map(usize::to_string).collect();
        let _ = writeln!(text, "{video}\t{}", list.join(","));
    }
    std::fs::write(path, text).map_err(|source| CaterError::Io { path: path.to_owned(), source })
}
