//! `source g : list<Detection> = sim.gearbox()`: the AAPA paper's gearbox assembly (section V) as a
//! simulated scenario (`kpl_aapa::gearbox`), one cycle every 100 ms of clock time:
//!
//! - default output: the detector's percepts of the cycle (`{label, type, box}`; labels are the
//!   detector's own `typeN`, numbered left to right in each frame, so they swap);
//! - `actions`: the actions reported this cycle (`{name, args, phase, expected_end?}`), an empty list
//!   when nothing happened;
//! - `camera`: the eye-in-hand camera's pose `{x, y, z}` (metres);
//! - `truth`: `{step, objects}`, the assembly step (0-5) and every object's true box, whether the
//!   detector saw it, and its name (the symbol its anchor should keep).
//!
//! The scenario is deterministic; cycle times start at the run's start. The camera it simulates is
//! 640x480 pixels with a focal length of 600 px and the principal point at the centre, looking at a
//! table at z = 0.6 m (`aapa.anchor(..., image: [640.0, 480.0], focal_px: 600.0, surface_z: 0.6)`).

use kpl_aapa::gearbox::{self, Cycle};
use kpl_core::{Time, Value, ValueType};
use kpl_runtime::context::SourceContext;
use kpl_runtime::process::{BoxFuture, ProcessError, Source};
use kpl_semantic::registry::{Entry, EntryKind, TypeReq};

use super::emit_frame;
use super::values::{pose_value, record};

/// The output port after `actions` and `camera` (see [`emit_frame`]).
const TRUTH_PORT: usize = 3;

struct Gearbox {
    cycles: Vec<Cycle>,
}

fn truth_value(cycle: &Cycle) -> Value {
    let objects = cycle
        .truth
        .iter()
        .map(|t| {
            record(vec![
                ("name", Value::str(&t.name)),
                ("type", Value::str(&t.object_type)),
                ("box", Value::bbox(t.bbox)),
                ("detected", Value::Bool(t.detected)),
            ])
        })
        .collect();
    record(vec![("step", Value::Int(i64::from(cycle.step))), ("objects", Value::List(objects))])
}

impl Source for Gearbox {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let start: Time = ctx.now();
            for cycle in std::mem::take(&mut self.cycles) {
                let t = start + cycle.time;
                if !ctx.wait_until(t).await {
                    break;
                }
                emit_frame(ctx, t, start, &cycle.percepts, &cycle.actions, pose_value(&cycle.camera)).await;
                ctx.emit_port(TRUTH_PORT, t, truth_value(&cycle)).await;
                if ctx.unconsumed() {
                    break;
                }
            }
            Ok(())
        })
    }
}

pub(super) fn register(registry: &mut kpl_runtime::Registry) {
    let any_list = ValueType::List(Box::new(ValueType::Any));
    registry.add_source(
        Entry::new(
            EntryKind::Source,
            "sim.gearbox",
            "The AAPA paper's gearbox assembly, simulated: an eye-in-hand camera's detections, the robot's \
             and human's actions and the camera pose, every 100 ms (docs/aapa.md).",
        )
        .output(super::percepts_req())
        .port(
            "actions",
            super::actions_req(),
            "the actions of each cycle (an empty list when there are none)",
        )
        .port("camera", super::pose_req(), "the camera pose of each cycle, metres")
        .port(
            "truth",
            TypeReq::Fields(vec![("step".into(), ValueType::Int), ("objects".into(), any_list)]),
            "the assembly step and every object's true box, `detected` flag and name",
        ),
        |_| Ok(Box::new(Gearbox { cycles: gearbox::scenario() })),
    );
}
