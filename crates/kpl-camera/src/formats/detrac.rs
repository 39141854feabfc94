//! UA-DETRAC's XML annotations, as the data set ships them (and py-motmetrics'
//! `load_detrac_xml` reads them): `<sequence name>` with `<ignored_region>` boxes, then
//! `<frame num density>` elements, each with a `<target_list>` of `<target id>`, each with a
//! `<box left top width height/>` and an `<attribute orientation speed trajectory_length
//! truncation_ratio vehicle_type/>`. A target's class is the index of its `vehicle_type` in
//! [`VEHICLE_TYPES`]; the ignored regions are not objects and are left out. A target without a
//! readable box is a problem (with its line); an XML error ends the reading with a problem, and
//! what was read before it is kept.
//!
//! ```
//! let xml = br#"<sequence name="MVI_1"><frame density="1" num="1"><target_list>
//!   <target id="1"><box left="745.6" top="357.33" width="148.2" height="115.14"/>
//!   <attribute vehicle_type="car"/></target></target_list></frame></sequence>"#;
//! let parsed = kpl_camera::formats::detrac::read(xml);
//! assert_eq!(parsed.detections[0].bbox.left, 745.6);
//! assert_eq!(parsed.detections[0].class, Some(0));
//! ```

use quick_xml::events::{BytesStart, Event};

use super::{Detection, Parsed, Problem};
use crate::boxes::PixelBox;

/// UA-DETRAC's vehicle types; a target's class is the index here.
pub const VEHICLE_TYPES: [&str; 4] = ["car", "bus", "van", "others"];

fn attribute(element: &BytesStart<'_>, name: &[u8]) -> Option<String> {
    element
        .attributes()
        .flatten()
        .find(|a| a.key.as_ref() == name)
        .and_then(|a| a.unescape_value().ok().map(|v| v.into_owned()))
}

fn number(element: &BytesStart<'_>, name: &str) -> Result<f64, String> {
    let text = attribute(element, name.as_bytes()).ok_or_else(|| format!("no `{name}`"))?;
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(format!("`{name}` is `{text}`, not a finite number")),
    }
}

fn whole(element: &BytesStart<'_>, name: &str) -> Result<i64, String> {
    let text = attribute(element, name.as_bytes()).ok_or_else(|| format!("no `{name}`"))?;
    text.trim().parse::<i64>().map_err(|_| format!("`{name}` is `{text}`, not a whole number"))
}

/// What is being read.
#[derive(Debug, Default)]
struct Target {
    id: Option<Result<i64, String>>,
    line: usize,
    bbox: Option<Result<PixelBox, String>>,
    class: Option<i64>,
}

/// Reads a UA-DETRAC XML annotation file.
pub fn read(bytes: &[u8]) -> Parsed {
    let mut parsed = Parsed::default();
    let mut reader = quick_xml::Reader::from_reader(bytes);
    let line_of = |position: u64| {
        bytes[..(position as usize).min(bytes.len())].iter().filter(|b| **b == b'\n').count() + 1
    };
    let mut frame: Option<i64> = None;
    let mut in_ignored = false;
    let mut target: Option<Target> = None;
    let mut buf = Vec::new();
    loop {
        let position = reader.buffer_position();
        let event = match reader.read_event_into(&mut buf) {
            Ok(event) => event,
            Err(e) => {
                parsed.problems.push(Problem {
                    line: line_of(reader.error_position()),
                    message: format!("not well-formed XML ({e}); the file is read up to here"),
                });
                break;
            }
        };
        let empty = matches!(event, Event::Empty(_));
        match &event {
            Event::Start(e) | Event::Empty(e) => match e.name().as_ref() {
                b"ignored_region" if !empty => in_ignored = true,
                b"frame" => match whole(e, "num") {
                    Ok(num) => frame = Some(num),
                    Err(message) => {
                        parsed.problems.push(Problem {
                            line: line_of(position),
                            message: format!("a frame with {message}"),
                        });
                        frame = None;
                    }
                },
                b"target" if !in_ignored => {
                    target = Some(Target {
                        id: Some(whole(e, "id")),
                        line: line_of(position),
                        ..Target::default()
                    });
                    if empty {
                        finish(&mut parsed, frame, target.take());
                    }
                }
                b"box" if !in_ignored => {
                    if let Some(t) = target.as_mut() {
                        let b = (|| {
                            let b = PixelBox::new(
                                number(e, "left")?,
                                number(e, "top")?,
                                number(e, "width")?,
                                number(e, "height")?,
                            );
                            if b.width < 0.0 || b.height < 0.0 {
                                Err("a negative width or height".to_string())
                            } else {
                                Ok(b)
                            }
                        })();
                        t.bbox = Some(b);
                    }
                }
                b"attribute" => {
                    if let (Some(t), Some(kind)) = (target.as_mut(), attribute(e, b"vehicle_type")) {
                        t.class = VEHICLE_TYPES.iter().position(|v| *v == kind).map(|i| i as i64);
                    }
                }
                _ => {}
            },
            Event::End(e) => match e.name().as_ref() {
                b"ignored_region" => in_ignored = false,
                b"target" => finish(&mut parsed, frame, target.take()),
                b"frame" => frame = None,
                _ => {}
            },
            Event::Eof => break,
            _ => {}
        }
        buf.clear();
    }
    parsed
}

fn finish(parsed: &mut Parsed, frame: Option<i64>, target: Option<Target>) {
    let Some(t) = target else { return };
    let problem = |message: String| Problem { line: t.line, message };
    let Some(frame) = frame else {
        parsed.problems.push(problem("a target outside a readable <frame>".to_string()));
        return;
    };
    let id = match t.id {
        Some(Ok(id)) => id,
        Some(Err(m)) => {
            parsed.problems.push(problem(format!("a target with {m}")));
            return;
        }
        None => {
            parsed.problems.push(problem("a target without an id".to_string()));
            return;
        }
    };
    match t.bbox {
        Some(Ok(bbox)) => parsed.detections.push(Detection {
            frame,
            id: Some(id),
            bbox,
            score: 1.0,
            class: t.class,
            visibility: None,
        }),
        Some(Err(m)) => parsed.problems.push(problem(format!("target {id}: a box with {m}"))),
        None => parsed.problems.push(problem(format!("target {id} has no <box>"))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ignored_regions_bad_targets_and_broken_xml() {
        let xml = br#"<?xml version="1.0"?>
<sequence name="MVI_39031">
   <ignored_region>
      <box left="335.75" top="52.75" width="256.5" height="117.5"/>
   </ignored_region>
   <frame density="2" num="7">
      <target_list>
         <target id="1"><box left="1" top="2" width="3" height="4"/><attribute vehicle_type="bus"/></target>
         <target id="x"><box left="1" top="2" width="3" height="4"/></target>
         <target id="3"><box left="1" top="2" width="oops" height="4"/></target>
         <target id="4"></target>
      </target_list>
   </frame>
   <frame density="1" num="8"><target_list><target id="1"><box left="2" top="2" width="3" height="4"/>
</sequence>"#;
        let p = read(xml);
        assert_eq!(p.detections.len(), 1, "{p:?}");
        assert_eq!((p.detections[0].frame, p.detections[0].id, p.detections[0].class), (7, Some(1), Some(1)));
        let lines: Vec<usize> = p.problems.iter().map(|p| p.line).collect();
        assert_eq!(lines[..3], [9, 10, 11], "{:?}", p.problems);
        assert!(p.problems[3].message.contains("not well-formed"), "{:?}", p.problems);
    }
}
