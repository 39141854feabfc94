//! MOTChallenge's and VisDrone's text formats: one box per line, fields separated by commas or
//! white space (as py-motmetrics' `load_motchallenge` splits them), blank lines skipped.
//!
//! - **MOTChallenge** (MOT15-2D results and detections, MOT16/17/20 ground truth):
//!   `frame, id, bb_left, bb_top, bb_width, bb_height, conf, ...`. Results and detections have
//!   `x, y, z` (world coordinates, -1) after `conf`; MOT16+ ground truth has `class, visibility`
//!   there, with `conf` a flag (1 considered, 0 not). The reader takes the first seven, and the
//!   eighth and ninth as class and visibility when the line has exactly nine fields. An id of -1
//!   (detection files) is a box without identity.
//! - **VisDrone** (VisDrone2018-MOT toolkit): `frame_index, target_id, bbox_left, bbox_top,
//!   bbox_width, bbox_height, score, object_category, truncation, occlusion`; the score of ground
//!   truth is the same flag. Category 0 marks ignored regions and 11 "others": neither is an
//!   object (the toolkit's `dropObjects` removes them), so the reader leaves them out.
//!
//! ```
//! use kpl_camera::formats::mot::read_motchallenge;
//! let parsed = read_motchallenge(b"1,3,113.84,274.5,57.307,130.05,-1,-1,-1,-1\n1,6,273,203,77,175,0.9,-1,-1,-1\nbad\n");
//! assert_eq!(parsed.detections.len(), 2);
//! assert_eq!(parsed.detections[0].id, Some(3));
//! assert_eq!(parsed.problems[0].line, 3);
//! ```

use super::{Detection, Parsed, Problem, lines};
use crate::boxes::PixelBox;

/// Lines longer than this are problems (a box is some 60 characters).
const MAX_LINE: usize = 4096;

fn fields(line: &str) -> Vec<&str> {
    line.split(|c: char| c == ',' || c.is_whitespace()).filter(|f| !f.is_empty()).collect()
}

/// A whole number written as an integer or a float with no fraction (`3`, `3.0`).
fn whole(field: &str, name: &str) -> Result<i64, String> {
    if let Ok(v) = field.parse::<i64>() {
        return Ok(v);
    }
    match field.parse::<f64>() {
        Ok(v) if v.is_finite() && v.fract() == 0.0 && v.abs() < 9e15 => Ok(v as i64),
        _ => Err(format!("{name} `{field}` is not a whole number")),
    }
}

fn number(field: &str, name: &str) -> Result<f64, String> {
    match field.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(format!("{name} `{field}` is not a finite number")),
    }
}

/// The common first seven columns.
fn row(f: &[&str]) -> Result<Detection, String> {
    if f.len() < 7 {
        return Err(format!(
            "{} fields; a box needs at least 7 (frame, id, left, top, width, height, score)",
            f.len()
        ));
    }
    let frame = whole(f[0], "frame")?;
    let id = whole(f[1], "id")?;
    let bbox = PixelBox::new(
        number(f[2], "left")?,
        number(f[3], "top")?,
        number(f[4], "width")?,
        number(f[5], "height")?,
    );
    if bbox.width < 0.0 || bbox.height < 0.0 {
        return Err(format!("a negative width or height ({} x {})", bbox.width, bbox.height));
    }
    Ok(Detection {
        frame,
        id: (id >= 0).then_some(id),
        bbox,
        score: number(f[6], "score")?,
        class: None,
        visibility: None,
    })
}

fn read(bytes: &[u8], parse: impl Fn(&[&str]) -> Result<Option<Detection>, String>) -> Parsed {
    let mut parsed = Parsed::default();
    for (n, line) in lines(bytes) {
        if line.len() > MAX_LINE {
            parsed.problems.push(Problem { line: n, message: format!("a line of {} bytes", line.len()) });
            continue;
        }
        let f = fields(&line);
        if f.is_empty() {
            continue;
        }
        match parse(&f) {
            Ok(Some(d)) => parsed.detections.push(d),
            Ok(None) => {}
            Err(message) => parsed.problems.push(Problem { line: n, message }),
        }
    }
    parsed
}

/// Reads a MOTChallenge text file.
pub fn read_motchallenge(bytes: &[u8]) -> Parsed {
    read(bytes, |f| {
        let mut d = row(f)?;
        if f.len() == 9 {
            d.class = Some(whole(f[7], "class")?);
            d.visibility = Some(number(f[8], "visibility")?);
        }
        Ok(Some(d))
    })
}

/// VisDrone's categories: 0 ignored regions, 1 pedestrian, 2 people, 3 bicycle, 4 car, 5 van,
/// 6 truck, 7 tricycle, 8 awning-tricycle, 9 bus, 10 motor, 11 others.
pub const VISDRONE_CATEGORIES: [&str; 12] = [
    "ignored",
    "pedestrian",
    "people",
    "bicycle",
    "car",
    "van",
    "truck",
    "tricycle",
    "awning-tricycle",
    "bus",
    "motor",
    "others",
];

/// Reads a VisDrone MOT text file (ignored regions and "others" left out).
pub fn read_visdrone(bytes: &[u8]) -> Parsed {
    read(bytes, |f| {
        if f.len() < 8 {
            return Err(format!(
                "{} fields; VisDrone's MOT format has 10 (frame, id, box, score, category, ...)",
                f.len()
            ));
        }
        let mut d = row(f)?;
        let category = whole(f[7], "category")?;
        if !(0..=11).contains(&category) {
            return Err(format!("category {category} is not one of VisDrone's (0 to 11)"));
        }
        if category == 0 || category == 11 {
            return Ok(None);
        }
        d.class = Some(category);
        Ok(Some(d))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn motchallenge_lines_and_problems() {
        let text = b"1, 1, 399, 182, 121, 229, 1, 1, 0.83\n\n2\t2\t269\t202\t87\t182\t0\t7\t0.1\r\n3,4,1,2,3,-4,1,-1,-1,-1\n3,x,1,2,3,4,1\n4,5,1,2,3,4,inf\n5.0,-1,1,2,3,4,0.5,-1,-1,-1\n";
        let p = read_motchallenge(text);
        assert_eq!(p.detections.len(), 3, "{p:?}");
        let d = &p.detections[0];
        assert_eq!((d.frame, d.id, d.class, d.visibility), (1, Some(1), Some(1), Some(0.83)));
        assert_eq!(d.bbox, PixelBox::new(399.0, 182.0, 121.0, 229.0));
        assert_eq!(p.detections[1].score, 0.0);
        assert_eq!((p.detections[2].frame, p.detections[2].id), (5, None), "a detection without identity");
        let lines: Vec<usize> = p.problems.iter().map(|p| p.line).collect();
        assert_eq!(lines, [4, 5, 6], "{:?}", p.problems);
        assert!(p.problems[0].message.contains("negative"));
        assert!(p.problems[1].message.contains("`x`"));
    }

    #[test]
    fn visdrone_leaves_out_ignored_regions_and_others() {
        let text = b"1,0,10,10,5,5,0,0,0,0\n1,1,20,20,5,5,1,4,0,1\n1,2,30,30,5,5,1,11,0,0\n1,3,1,1,1,1,1,12,0,0\n1,4,1,1,1,1\n";
        let p = read_visdrone(text);
        assert_eq!(p.detections.len(), 1);
        assert_eq!(p.detections[0].class, Some(4));
        assert_eq!(p.problems.len(), 2, "{:?}", p.problems);
    }
}
