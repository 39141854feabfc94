//! COCO-style JSON detections, in the two shapes detectors write:
//!
//! - **results** (what COCO's evaluation takes from a detector): a list of
//!   `{"image_id": 3, "category_id": 1, "bbox": [x, y, width, height], "score": 0.9}`;
//! - **a data set** (COCO's annotation files, and the video variants of TAO and mmtracking's
//!   CocoVID): `{"images": [...], "annotations": [...]}` with the same entries (without `score`:
//!   1) in `annotations`.
//!
//! The frame of an entry is its image's `frame_id` or `frame_index` (video data sets; `images`
//! gives them by `id`), else its `image_id`. An entry's `track_id` (or `instance_id`) is its
//! identity; without one every box is a detection of its own. `bbox` is COCO's
//! `[left, top, width, height]` in pixels. An entry that lacks these or has the wrong types is a
//! problem (its position in the list, from 1), and the others are read.
//!
//! ```
//! let json = br#"[{"image_id": 1, "category_id": 3, "bbox": [10, 20, 30, 40], "score": 0.8},
//!                 {"image_id": 2, "category_id": 3, "bbox": [11, 20, 30, 40], "score": 0.7, "track_id": 5}]"#;
//! let parsed = kpl_camera::formats::coco::read(json).unwrap();
//! assert_eq!(parsed.detections[1].id, Some(5));
//! assert_eq!(parsed.detections[0].bbox.width, 30.0);
//! ```

use std::collections::HashMap;

use serde_json::Value;

use super::{Detection, FormatError, Parsed, Problem};
use crate::boxes::PixelBox;

fn whole(v: &Value) -> Option<i64> {
    v.as_i64().or_else(|| v.as_f64().filter(|f| f.fract() == 0.0 && f.abs() < 9e15).map(|f| f as i64))
}

fn entry(e: &Value, frames: &HashMap<i64, i64>) -> Result<Detection, String> {
    let object = e.as_object().ok_or("not an object")?;
    let image = object.get("image_id").ok_or("no `image_id`")?;
    let image = whole(image).ok_or_else(|| format!("`image_id` {image} is not a whole number"))?;
    let frame = frames.get(&image).copied().unwrap_or(image);
    let bbox = object.get("bbox").ok_or("no `bbox`")?;
    let numbers: Vec<f64> = bbox
        .as_array()
        .filter(|a| a.len() == 4)
        .and_then(|a| a.iter().map(Value::as_f64).collect::<Option<Vec<f64>>>())
        .filter(|n| n.iter().all(|v| v.is_finite()))
        .ok_or_else(|| format!("`bbox` {bbox} is not four finite numbers [x, y, width, height]"))?;
    let bbox = PixelBox::new(numbers[0], numbers[1], numbers[2], numbers[3]);
    if bbox.width < 0.0 || bbox.height < 0.0 {
        return Err("`bbox` has a negative width or height".to_string());
    }
    let score = match object.get("score") {
        None => 1.0,
        Some(s) => {
            s.as_f64().filter(|v| v.is_finite()).ok_or_else(|| format!("`score` {s} is not a number"))?
        }
    };
    let id = match object.get("track_id").or_else(|| object.get("instance_id")) {
        None | Some(Value::Null) => None,
        Some(v) => Some(whole(v).ok_or_else(|| format!("`track_id` {v} is not a whole number"))?),
    };
    let class = object.get("category_id").and_then(whole);
    Ok(Detection { frame, id, bbox, score, class, visibility: None })
}

/// Reads COCO-style detections (a results list or a data set).
pub fn read(bytes: &[u8]) -> Result<Parsed, FormatError> {
    let document: Value = serde_json::from_slice(bytes).map_err(|e| FormatError::Json(e.to_string()))?;
    let mut frames = HashMap::new();
    let entries = match &document {
        Value::Array(entries) => entries,
        Value::Object(data) => {
            if let Some(Value::Array(images)) = data.get("images") {
                for image in images {
                    let id = image.get("id").and_then(whole);
                    let frame = image.get("frame_id").or_else(|| image.get("frame_index")).and_then(whole);
                    if let (Some(id), Some(frame)) = (id, frame) {
                        frames.insert(id, frame);
                    }
                }
            }
            match data.get("annotations") {
                Some(Value::Array(entries)) => entries,
                _ => {
                    return Err(FormatError::Shape(
                        "a COCO data set needs an `annotations` list (or give a list of results)".to_string(),
                    ));
                }
            }
        }
        _ => {
            return Err(FormatError::Shape(
                "COCO detections are a list of results or a data set object".to_string(),
            ));
        }
    };
    let mut parsed = Parsed::default();
    for (i, e) in entries.iter().enumerate() {
        match entry(e, &frames) {
            Ok(d) => parsed.detections.push(d),
            Err(message) => {
                parsed.problems.push(Problem { line: 0, message: format!("entry {}: {message}", i + 1) })
            }
        }
    }
    Ok(parsed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn data_sets_with_frames_and_bad_entries() {
        let json = br#"{"images": [{"id": 10, "frame_id": 1}, {"id": 11, "frame_index": 2}, {"id": 12}],
            "annotations": [
              {"image_id": 10, "bbox": [1, 2, 3, 4], "category_id": 1, "instance_id": 4},
              {"image_id": 11, "bbox": [1, 2, 3], "category_id": 1},
              {"image_id": 12, "bbox": [1, 2, 3, 4], "score": "high"},
              {"image_id": 12, "bbox": [1, 2, 3, 4], "track_id": null},
              {"bbox": [1, 2, 3, 4]}, 7]}"#;
        let p = read(json).unwrap();
        assert_eq!(p.detections.len(), 2, "{p:?}");
        assert_eq!((p.detections[0].frame, p.detections[0].id, p.detections[0].score), (1, Some(4), 1.0));
        assert_eq!((p.detections[1].frame, p.detections[1].id), (12, None), "no frame_id: the image id");
        let messages: Vec<&str> = p.problems.iter().map(|p| p.message.as_str()).collect();
        assert_eq!(messages.len(), 4, "{messages:?}");
        assert!(messages[0].starts_with("entry 2: `bbox`"));
        assert!(messages[3].starts_with("entry 6: not an object"));
        assert!(matches!(read(b"{\"images\": []}"), Err(FormatError::Shape(_))));
        assert!(matches!(read(b"[{"), Err(FormatError::Json(_))));
    }
}
