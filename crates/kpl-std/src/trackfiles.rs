//! `source NAME : list<T> = file.tracker(path: "tracker.txt", format: "motchallenge", fps: 25)`:
//! a detector's or tracker's output file replayed as image percepts, one snapshot per frame
//! (frame `first_frame` at the run's start, then every `1 / fps`; frames without boxes are empty
//! snapshots, so anchoring sees a track end). Each box is a record `{id, box: [left, top, width,
//! height], pos: [cx, cy], vel: [vx, vy], score, class}` in pixels: `id` is `prefix` and the
//! tracker's id (a box without identity gets one of its own, `{prefix}d{frame}_{k}`), `pos` the
//! box's centre, `vel` its centre's velocity from the same id's box in the previous frame. The
//! formats and the columns each uses are `kpl_camera::formats`'s (docs/camera.md). A malformed
//! line is counted as a malformed input with its line (`--strict` stops the run) and the rest is
//! replayed. The file is read when the run is built (a missing file stops it before it starts).

use std::sync::Arc;

use kpl_camera::formats::{self, Format, FrameOptions, FrameSnapshot};
use kpl_core::{Record, Value, ValueType};
use kpl_runtime::context::SourceContext;
use kpl_runtime::process::{BoxFuture, ProcessError, Source};
use kpl_runtime::registry::{BuildContext, BuildError};
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};

struct TrackerFile {
    location: String,
    snapshots: Vec<FrameSnapshot>,
    problems: Vec<formats::Problem>,
}

fn percept(p: &formats::FramePercept) -> Value {
    let c = p.bbox.centre();
    let fields = vec![
        (
            Arc::from("box"),
            Value::List(p.bbox.to_array().iter().map(|v| Value::Float(*v)).collect::<Vec<_>>().into()),
        ),
        (Arc::from("pos"), Value::Vec2(c)),
        (Arc::from("vel"), Value::Vec2(p.vel)),
        (Arc::from("score"), Value::Float(p.score)),
        (Arc::from("class"), Value::Int(p.class.unwrap_or(-1))),
    ];
    Value::Record(Arc::new(Record { id: Some(Arc::from(p.id.as_str())), fields }))
}

impl Source for TrackerFile {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            for problem in std::mem::take(&mut self.problems) {
                let location = if problem.line > 0 {
                    format!("{}:{}", self.location, problem.line)
                } else {
                    self.location.clone()
                };
                ctx.malformed(location, problem.message)?;
            }
            let start = ctx.now();
            for snapshot in std::mem::take(&mut self.snapshots) {
                let valid = start.saturating_add(snapshot.time);
                if !ctx.wait_until(valid).await {
                    break;
                }
                let percepts: Vec<Value> = snapshot.percepts.iter().map(percept).collect();
                ctx.emit(valid, Value::List(percepts.into())).await;
                if ctx.unconsumed() {
                    break;
                }
            }
            Ok(())
        })
    }
}

fn entry() -> Entry {
    let list = |t: ParamType| ParamType::List(Box::new(t));
    Entry::new(
        EntryKind::Source,
        "file.tracker",
        "A detector's or tracker's output file (MOTChallenge, VisDrone, UA-DETRAC XML, COCO JSON) as image percepts, one snapshot per frame.",
    )
    .output(TypeReq::Objects(vec![("box".into(), ValueType::List(Box::new(ValueType::Float))), ("pos".into(), ValueType::Vec2)]))
    .param(Param::required("path", ParamType::Str, "the file, relative to the spec's folder"))
    .param(Param::optional(
        "format",
        ParamType::Choice(Format::NAMES.iter().map(|n| n.to_string()).collect()),
        Value::str("motchallenge"),
        "motchallenge (frame, id, box, score), visdrone, detrac (UA-DETRAC XML) or coco (JSON)",
    ))
    .param(Param::optional("fps", ParamType::Float, Value::Float(25.0), "frames per second"))
    .param(Param::optional("first_frame", ParamType::Int, Value::Int(1), "the frame number at the run's start"))
    .param(Param::optional("min_score", ParamType::Float, Value::Float(-1e9), "boxes with a lower score are left out (default: none)"))
    .param(Param::optional("classes", list(ParamType::Int), Value::List(Vec::new().into()), "only boxes of these classes (empty: all)"))
    .param(Param::optional("prefix", ParamType::Str, Value::str("t"), "percept ids are this followed by the tracker's id"))
}

fn build(ctx: &mut BuildContext<'_>) -> Result<Box<dyn Source>, BuildError> {
    let path = ctx.param("path").and_then(Value::as_str).ok_or_else(|| ctx.error("`path` is required"))?;
    let full = ctx.input_path(path);
    let format = ctx
        .param("format")
        .and_then(Value::as_str)
        .and_then(Format::from_name)
        .ok_or_else(|| ctx.error(format!("`format` is one of {}", Format::NAMES.join(", "))))?;
    let fps = ctx.param("fps").and_then(Value::as_f64).unwrap_or(25.0);
    if !(fps.is_finite() && fps > 0.0 && fps <= 1e6) {
        return Err(ctx.error(format!("`fps` must be above 0 and at most 1000000, not {fps}")));
    }
    let classes = match ctx.param("classes") {
        Some(Value::List(items)) => items.iter().filter_map(Value::as_i64).collect(),
        _ => Vec::new(),
    };
    let options = FrameOptions {
        fps,
        first_frame: ctx.param("first_frame").and_then(Value::as_i64).unwrap_or(1),
        prefix: ctx.param("prefix").and_then(Value::as_str).unwrap_or("t").to_string(),
        min_score: ctx.param("min_score").and_then(Value::as_f64).unwrap_or(f64::NEG_INFINITY),
        classes,
    };
    let parsed =
        formats::read_file(&full, format).map_err(|e| ctx.error(format!("{}: {e}", full.display())))?;
    let (snapshots, mut problems) = formats::frames(&parsed.detections, &options);
    problems.splice(0..0, parsed.problems);
    if snapshots.is_empty() && problems.is_empty() {
        ctx.stats.warn(format!("{} has no boxes", full.display()));
    }
    Ok(Box::new(TrackerFile { location: full.display().to_string(), snapshots, problems }))
}

pub(crate) fn register(registry: &mut kpl_runtime::Registry) {
    registry.add_source(entry(), build);
}
