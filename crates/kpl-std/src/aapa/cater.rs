//! `source v : list<Detection> = cater.video(data: DIR, video: NAME, perception: "perfect")`: one
//! video of a CATER-style data directory (`kpl cater generate`, docs/cater.md) replayed frame by
//! frame at 30 fps, as `kpl cater eval` feeds it to AAPA:
//!
//! - default output: the frame's detections (`{label, type, box}`: the class as type, labels
//!   `shapeN` numbered left to right within the frame);
//! - `actions`: CATER's movements as action events (`started` at a move's first frame with its
//!   expected end, `completed` at its last; arguments are object classes), one list per frame;
//! - `camera`: a constant pose `{x: 0, y: 0, z: 0}`: CATER's camera does not move.
//!
//! The files are read when the process is built, so a missing or malformed file stops the run
//! before it starts, with the file's name.

use std::path::PathBuf;

use kpl_aapa::CameraPose;
use kpl_cater::formats::{PerceptionFile, Scene};
use kpl_cater::layout::{self, Perception};
use kpl_cater::models::{FRAME_US, actions_per_frame};
use kpl_core::{Time, Value};
use kpl_runtime::context::SourceContext;
use kpl_runtime::process::{BoxFuture, ProcessError, Source};
use kpl_runtime::registry::{BuildContext, BuildError};
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType};

use super::emit_frame;
use super::values::pose_value;

struct Video {
    scene: Scene,
    perception: PerceptionFile,
}

impl Source for Video {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let start: Time = ctx.now();
            let frames = self.perception.frames.len();
            let actions = actions_per_frame(&self.scene, frames);
            let pose = pose_value(&CameraPose::default());
            for (frame, frame_actions) in actions.iter().enumerate() {
                let t = start + frame as Time * FRAME_US;
                if !ctx.wait_until(t).await {
                    break;
                }
                let percepts = self.perception.percepts(frame);
                emit_frame(ctx, t, start, &percepts, frame_actions, pose.clone()).await;
                if ctx.unconsumed() {
                    break;
                }
            }
            Ok(())
        })
    }
}

fn build(ctx: &mut BuildContext<'_>) -> Result<Box<dyn Source>, BuildError> {
    let text = |name: &str| ctx.param(name).and_then(Value::as_str).unwrap_or("").to_string();
    let dir: PathBuf = ctx.input_path(&text("data"));
    let video = text("video");
    let perception = match text("perception").as_str() {
        "detector" => Perception::Detector,
        _ => Perception::Perfect,
    };
    let scene = Scene::read(&layout::scene_path(&dir, &video)).map_err(|e| ctx.error(e.to_string()))?;
    let perception = PerceptionFile::read(&layout::perception_path(&dir, &video, perception))
        .map_err(|e| ctx.error(e.to_string()))?;
    Ok(Box::new(Video { scene, perception }))
}

pub(super) fn register(registry: &mut kpl_runtime::Registry) {
    registry.add_source(
        Entry::new(
            EntryKind::Source,
            "cater.video",
            "One video of a CATER-style data directory (kpl cater generate) replayed at 30 fps: detections, \
             CATER's movements as actions, and the fixed camera's pose (docs/aapa.md).",
        )
        .param(Param::required("data", ParamType::Str, "the data directory, relative to the spec"))
        .param(Param::required("video", ParamType::Str, "the video's name, e.g. CATER_new_000000"))
        .param(Param::optional(
            "perception",
            ParamType::Choice(vec!["perfect".into(), "detector".into()]),
            Value::str("perfect"),
            "which perception file to replay: the visible ground-truth boxes, or the simulated detector",
        ))
        .output(super::percepts_req())
        .port("actions", super::actions_req(), "CATER's movements as action events, one list per frame")
        .port("camera", super::pose_req(), "the camera pose, constant {x: 0, y: 0, z: 0}"),
        build,
    );
}
