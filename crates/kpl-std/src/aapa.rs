//! Action-aware perceptual anchoring on the runtime (docs/aapa.md):
//!
//! - `compute world : W = aapa.anchor(percepts, actions, poses, previous, ...)`: one AAPA cycle
//!   (`kpl_aapa::Aapa::step`) per percept frame, with the actions reported since the last frame,
//!   the latest camera pose, and the previous cycle's world state read back from `previous`, a
//!   `feedback` stream of its own output (the AAPA paper's Fig. 2). It is a synchronized unit:
//!   it sees states whose inputs share a valid time.
//! - `source g : list<D> = sim.gearbox()`: the paper's gearbox assembly (`kpl_aapa::gearbox`) as a
//!   simulated scenario, with `actions`, `camera` and `truth` ports.
//! - `source v : list<D> = cater.video(data: DIR, video: NAME)`: one video of a `kpl cater
//!   generate` directory replayed as percepts, actions and a fixed camera pose.
//!
//! Every AAPA parameter is a named parameter of `aapa.anchor` with the paper's LA-CATER value as
//! its default ([`kpl_aapa::Params::default`]); `kpl list aapa.anchor` prints them.

mod cater;
mod gearbox;
mod values;

use kpl_aapa::{
    Aapa, Action, ActionRule, CameraModel, CameraPose, Extensions, ImageSize, MotionProfile, Params, Percept,
    WorldState,
};
use std::sync::Arc;

use kpl_core::{Time, Value, ValueType};
use kpl_runtime::context::SourceContext;
use kpl_runtime::process::{Emitter, Input, ProcessError, SyncUnit, Unit};
use kpl_runtime::registry::{BuildContext, BuildError};
use kpl_runtime::sample::Sample;
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};

use values::{
    action_value, actions_from_value, anchor_fields, percept_value, percepts_from_value, pose_from_value,
    relation_fields, world_from_value, world_scalar_fields, world_to_value,
};

/// The input ports of `aapa.anchor`, in order.
const PERCEPTS: usize = 0;
const ACTIONS: usize = 1;
const POSES: usize = 2;
const PREVIOUS: usize = 3;

/// The `aapa.anchor` unit. Its memory is the world state, which comes back through the feedback
/// input; it keeps its own last output only to cover a state released before the feedback edge
/// delivered the previous world (then the world carries a note saying so).
struct AnchorUnit {
    aapa: Aapa,
    /// Actions reported since the last frame: applied at the next one.
    pending_actions: Vec<Action>,
    /// The valid time of the last actions sample taken (a synchronized state repeats the most
    /// recent sample of an input that has none at its time; those are not taken again).
    actions_up_to: Option<Time>,
    /// The world this unit emitted last, and the value it emitted for it.
    last_world: WorldState,
    last_value: Option<Value>,
    /// Without a camera model the camera must stay still: the first pose seen.
    fixed_pose: Option<CameraPose>,
    /// What the unit achieved, reported as the run's result.
    tally: AnchorTally,
}

/// What `aapa.anchor` achieved: anchors created, and how many came back into view with their
/// symbol after being hidden (occluded, out of view, attached or lost for a while).
#[derive(Debug, Default)]
struct AnchorTally {
    stats: Option<Arc<kpl_runtime::stats::ProcessStats>>,
    symbols: std::collections::BTreeSet<kpl_aapa::Symbol>,
    hidden: std::collections::BTreeSet<kpl_aapa::Symbol>,
    seen_again: u64,
}

impl AnchorTally {
    fn count(&mut self, world: &WorldState) {
        use kpl_aapa::AnchorStatus;
        for anchor in &world.anchors {
            self.symbols.insert(anchor.symbol.clone());
            if anchor.status == AnchorStatus::Visible {
                if self.hidden.remove(&anchor.symbol) {
                    self.seen_again += 1;
                }
            } else {
                self.hidden.insert(anchor.symbol.clone());
            }
        }
        if let Some(stats) = &self.stats {
            stats.result("anchors created", self.symbols.len() as u64);
            stats.result("anchors seen again with their symbol after being hidden", self.seen_again);
        }
    }
}

fn sample<'a>(input: &'a Input<'_>, port: usize) -> Option<&'a Sample> {
    input.values.get(port)?.as_ref()
}

impl AnchorUnit {
    fn new(aapa: Aapa) -> AnchorUnit {
        AnchorUnit {
            aapa,
            pending_actions: Vec::new(),
            actions_up_to: None,
            last_world: WorldState::default(),
            last_value: None,
            fixed_pose: None,
            tally: AnchorTally::default(),
        }
    }

    /// The pose to compensate with: the pose itself with a camera model; without one, none, after
    /// checking that the camera has not moved (a move cannot be compensated without a model).
    fn camera(&mut self, pose: Option<CameraPose>) -> Result<Option<CameraPose>, String> {
        if self.aapa.params().camera.is_some() {
            return Ok(pose);
        }
        if let Some(pose) = pose {
            match self.fixed_pose {
                None => self.fixed_pose = Some(pose),
                Some(first) if first == pose => {}
                Some(first) => {
                    return Err(format!(
                        "the camera moved from {first:?} to {pose:?}, but aapa.anchor has no camera model \
                         to compensate with (set `focal_px`, `surface_z` and `image`)"
                    ));
                }
            }
        }
        Ok(None)
    }

    /// The world of the previous cycle: the fed-back one if it is at least as recent as the last
    /// world this unit emitted, else that last world (with a note saying why).
    fn previous_world(
        &self,
        fed_back: Option<&Sample>,
    ) -> Result<(WorldState, Option<String>), ProcessError> {
        let expected = self.last_world.time;
        if let Some(sample) = fed_back {
            // The very value this unit emitted (values travel shared, not copied): no need to
            // decode it again.
            if let (Value::Record(back), Some(Value::Record(sent))) = (&sample.value, &self.last_value)
                && Arc::ptr_eq(back, sent)
            {
                return Ok((self.last_world.clone(), None));
            }
            let world = world_from_value(&sample.value).map_err(ProcessError::failed)?;
            if world.time >= expected {
                return Ok((world, None));
            }
        }
        match expected {
            None => Ok((WorldState::default(), None)),
            Some(t) => Ok((
                self.last_world.clone(),
                Some(format!(
                    "the world of the previous cycle (t={t}) had not come back through the feedback \
                     stream; used the unit's own copy"
                )),
            )),
        }
    }
}

impl Unit for AnchorUnit {
    fn synchronized(&self) -> bool {
        true
    }

    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        if let Some(actions) = sample(input, ACTIONS)
            && self.actions_up_to.is_none_or(|t| actions.valid > t)
        {
            self.actions_up_to = Some(actions.valid);
            let decoded = actions_from_value(&actions.value)
                .map_err(|e| ProcessError::failed(format!("t={}: {e}", actions.valid)))?;
            self.pending_actions.extend(decoded);
        }
        // A cycle per frame: a state without a frame at its own time (only actions or a pose
        // arrived) runs none.
        let Some(frame) = sample(input, PERCEPTS) else { return Ok(()) };
        if frame.valid != input.valid {
            return Ok(());
        }
        let time = input.valid;
        let at = |e: String| ProcessError::failed(format!("t={time}: {e}"));
        let percepts = percepts_from_value(&frame.value).map_err(at)?;
        let actions = std::mem::take(&mut self.pending_actions);
        let pose = sample(input, POSES).map(|s| pose_from_value(&s.value)).transpose().map_err(at)?;
        let camera = self.camera(pose).map_err(at)?;
        let (previous, note) = self.previous_world(sample(input, PREVIOUS))?;
        if note.is_some() {
            tracing::debug!(time, "aapa.anchor: the previous world had not come back yet");
        }
        let mut world = self
            .aapa
            .step_from(time, &percepts, &actions, camera.as_ref(), previous)
            .map_err(|e| at(e.to_string()))?;
        world.notes.extend(note);
        self.tally.count(&world);
        let value = world_to_value(&world);
        out.emit(value.clone());
        self.last_world = world;
        self.last_value = Some(value);
        Ok(())
    }
}

/// Whether values of type `produced` fit a declared `declared` (ints widen to floats).
fn fits(produced: &ValueType, declared: &ValueType) -> bool {
    match (produced, declared) {
        (_, ValueType::Any) | (ValueType::Int, ValueType::Float) => true,
        (ValueType::List(p), ValueType::List(d)) => fits(p, d),
        (p, d) => p == d,
    }
}

/// Checks a declared `list<T>` of records against the fields the unit fills in.
fn check_record_list(
    declared: &ValueType,
    what: &str,
    produced: &[(&'static str, ValueType)],
) -> Result<(), String> {
    let names = || produced.iter().map(|(n, t)| format!("{n}: {t}")).collect::<Vec<_>>().join(", ");
    let item = match declared {
        ValueType::Any => return Ok(()),
        ValueType::List(item) => item,
        other => return Err(format!("`{what}` is declared {other}; it is a list of records ({})", names())),
    };
    let record = match &**item {
        ValueType::Any => return Ok(()),
        ValueType::Record(r) => r,
        other => {
            return Err(format!("`{what}` is declared list<{other}>; its items are records ({})", names()));
        }
    };
    for field in &record.fields {
        match produced.iter().find(|(n, _)| **n == *field.name) {
            Some((_, ty)) if fits(ty, &field.ty) => {}
            Some((_, ty)) => {
                return Err(format!(
                    "`{}.{}` is declared {}, but aapa.anchor gives {what} a `{}` of type {ty}",
                    record.name, field.name, field.ty, field.name
                ));
            }
            None => {
                return Err(format!(
                    "`{}` declares `{}`, which aapa.anchor's {what} do not have (they have {})",
                    record.name,
                    field.name,
                    names()
                ));
            }
        }
    }
    Ok(())
}

/// The declared output type must name only what the world state has, in types it fits
/// (`kpl check` checks the top level; the items of the lists are checked here).
fn check_output_type(declared: &ValueType) -> Result<(), String> {
    let ValueType::Record(world) = declared else { return Ok(()) };
    for field in &world.fields {
        match &*field.name {
            "anchors" => check_record_list(&field.ty, "anchors", &anchor_fields())?,
            "relations" => check_record_list(&field.ty, "relations", &relation_fields())?,
            name => match world_scalar_fields().into_iter().find(|(n, _)| *n == name) {
                Some((_, ty)) if fits(&ty, &field.ty) => {}
                Some((_, ty)) => {
                    return Err(format!("`{}.{name}` is declared {}, but it is {ty}", world.name, field.ty));
                }
                None => {
                    return Err(format!(
                        "`{}` declares `{name}`, which aapa.anchor's world state does not have (it has time, \
                         anchors, relations, notes)",
                        world.name
                    ));
                }
            },
        }
    }
    Ok(())
}

/// A declared detection type may have a `colour` of type string (`#rrggbb`) or list<float> (RGB).
fn check_percepts_type(declared: &ValueType) -> Result<(), String> {
    let ValueType::List(item) = declared else { return Ok(()) };
    let ValueType::Record(r) = &**item else { return Ok(()) };
    match r.field("colour").map(|f| &f.ty) {
        None | Some(ValueType::Str | ValueType::Any) => Ok(()),
        Some(ValueType::List(c)) if matches!(**c, ValueType::Float | ValueType::Any) => Ok(()),
        Some(other) => Err(format!(
            "`{}.colour` is declared {other}; a colour is a string \"#rrggbb\" or a list<float> [r, g, b]",
            r.name
        )),
    }
}

fn float(ctx: &BuildContext<'_>, name: &str) -> Result<f64, BuildError> {
    ctx.param(name).and_then(Value::as_f64).ok_or_else(|| ctx.error(format!("`{name}` must be a number")))
}

fn boolean(ctx: &BuildContext<'_>, name: &str) -> Result<bool, BuildError> {
    ctx.param(name)
        .and_then(Value::as_bool)
        .ok_or_else(|| ctx.error(format!("`{name}` must be true or false")))
}

fn floats(ctx: &BuildContext<'_>, name: &str) -> Result<Vec<f64>, BuildError> {
    match ctx.param(name) {
        Some(Value::List(items)) => items
            .iter()
            .map(|v| v.as_f64().ok_or_else(|| ctx.error(format!("`{name}` must be a list of numbers"))))
            .collect(),
        _ => Err(ctx.error(format!("`{name}` must be a list of numbers"))),
    }
}

/// AAPA's parameters from the call's (defaults are filled in by the checker).
fn params(ctx: &BuildContext<'_>) -> Result<Params, BuildError> {
    let image = match floats(ctx, "image")?.as_slice() {
        [] => None,
        [width, height] => Some(ImageSize { width: *width, height: *height }),
        _ => return Err(ctx.error("`image` is [width, height] in pixels, or [] for no field of view")),
    };
    let focal_px = float(ctx, "focal_px")?;
    let camera = if focal_px == 0.0 {
        None
    } else {
        let principal = match (floats(ctx, "principal")?.as_slice(), image) {
            ([cx, cy], _) => [*cx, *cy],
            ([], Some(img)) => [img.width / 2.0, img.height / 2.0],
            ([], None) => {
                return Err(ctx.error("`principal` is needed for the camera model when `image` is []"));
            }
            _ => return Err(ctx.error("`principal` is [cx, cy] in pixels, or [] for the image centre")),
        };
        Some(CameraModel { focal_px, principal, surface_z: float(ctx, "surface_z")? })
    };
    let motion_profile = match ctx.param("motion_profile").and_then(Value::as_str) {
        Some("constant_velocity") => MotionProfile::ConstantVelocity,
        Some("ease_in_out") => MotionProfile::EaseInOut,
        _ => MotionProfile::Fitted,
    };
    let action_rules = match ctx.param("action_rules").and_then(Value::as_str).unwrap_or("") {
        "" => ActionRule::defaults(),
        file => {
            let path = ctx.input_path(file);
            let text = kpl_core::read::read_file(&path, kpl_core::read::MAX_TEXT_FILE)
                .map_err(|e| ctx.error(e.to_string()))?;
            serde_json::from_slice::<Vec<ActionRule>>(&text)
                .map_err(|e| ctx.error(format!("{}: not a list of action rules: {e}", path.display())))?
        }
    };
    Ok(Params {
        theta: float(ctx, "theta")?,
        type_mismatch: float(ctx, "type_mismatch")?,
        theta_anch: float(ctx, "theta_anch")?,
        theta_inf: float(ctx, "theta_inf")?,
        conf_plus: float(ctx, "conf_plus")?,
        conf_minus: float(ctx, "conf_minus")?,
        image,
        camera,
        action_rules,
        spatial_relations: boolean(ctx, "spatial_relations")?,
        extensions: Extensions {
            predict_motion: boolean(ctx, "predict_motion")?,
            reacquire: boolean(ctx, "reacquire")?,
            scale_attached: boolean(ctx, "scale_attached")?,
            motion_profile,
            restore_partial_boxes: boolean(ctx, "restore_partial_boxes")?,
            established_first: boolean(ctx, "established_first")?,
            infer_hidden: boolean(ctx, "infer_hidden")?,
            infer_hidden_box: Extensions::default().infer_hidden_box,
            average_still: boolean(ctx, "average_still")?,
            still_stays: boolean(ctx, "still_stays")?,
            merge_duplicates: boolean(ctx, "merge_duplicates")?,
            identity_by_place: boolean(ctx, "identity_by_place")?,
            keep_lost: float(ctx, "keep_lost")?,
        },
    })
}

fn build(ctx: &mut BuildContext<'_>) -> Result<Box<dyn kpl_runtime::process::AsyncUnit>, BuildError> {
    if let Some(input) = ctx.process.inputs.get(PREVIOUS)
        && !input.stream.policy.feedback
    {
        return Err(ctx.error(format!(
            "input `previous` ({}) must be a feedback stream of the world state, as in \
             `stream previous = {} with feedback, use most recent`",
            input.stream.name, ctx.process.name
        )));
    }
    if let Some(ty) = &ctx.process.output {
        check_output_type(ty).map_err(|e| ctx.error(e))?;
    }
    if let Some(input) = ctx.process.inputs.get(PERCEPTS) {
        check_percepts_type(&input.stream.ty).map_err(|e| ctx.error(e))?;
    }
    let aapa = Aapa::new(params(ctx)?).map_err(|e| ctx.error(e.to_string()))?;
    let mut unit = AnchorUnit::new(aapa);
    unit.tally.stats = Some(ctx.stats.clone());
    Ok(Box::new(SyncUnit(unit)))
}

/// The ports of the replay sources (`sim.gearbox`, `cater.video`) after the default one, which
/// carries the percepts.
const SOURCE_ACTIONS_PORT: usize = 1;
const SOURCE_CAMERA_PORT: usize = 2;

/// Emits one frame of a replay source at `t`: its percepts, its actions (expected ends moved onto
/// the run's clock by `start`) and the camera pose.
async fn emit_frame(
    ctx: &mut SourceContext,
    t: Time,
    start: Time,
    percepts: &[Percept],
    actions: &[Action],
    pose: Value,
) {
    ctx.emit(t, Value::List(percepts.iter().map(percept_value).collect())).await;
    let actions = actions.iter().map(|a| action_value(a, start)).collect();
    ctx.emit_port(SOURCE_ACTIONS_PORT, t, Value::List(actions)).await;
    ctx.emit_port(SOURCE_CAMERA_PORT, t, pose).await;
}

fn fields(list: &[(&str, ValueType)]) -> Vec<(String, ValueType)> {
    list.iter().map(|(n, t)| (n.to_string(), t.clone())).collect()
}

/// What a percept stream must carry: a list of detections per frame.
pub(crate) fn percepts_req() -> TypeReq {
    TypeReq::Objects(fields(&[("label", ValueType::Str), ("type", ValueType::Str), ("box", ValueType::BBox)]))
}

/// What an action stream must carry: a list of actions per sample.
pub(crate) fn actions_req() -> TypeReq {
    TypeReq::Objects(fields(&[("name", ValueType::Str), ("args", ValueType::List(Box::new(ValueType::Str)))]))
}

/// What a camera pose stream must carry.
pub(crate) fn pose_req() -> TypeReq {
    TypeReq::Fields(fields(&[("x", ValueType::Float), ("y", ValueType::Float), ("z", ValueType::Float)]))
}

fn world_req() -> TypeReq {
    let any_list = ValueType::List(Box::new(ValueType::Any));
    TypeReq::Fields(fields(&[("anchors", any_list.clone()), ("relations", any_list)]))
}

fn anchor_entry() -> Entry {
    let defaults = Params::default();
    let ext = Extensions::default();
    let f =
        |name: &str, value: f64, doc: &str| Param::optional(name, ParamType::Float, Value::Float(value), doc);
    let b =
        |name: &str, value: bool, doc: &str| Param::optional(name, ParamType::Bool, Value::Bool(value), doc);
    let floats = ParamType::List(Box::new(ParamType::Float));
    Entry::new(
        EntryKind::Compute,
        "aapa.anchor",
        "Action-aware perceptual anchoring (AAPA): a world state of anchored objects from detections, \
         actions, camera poses and its previous world (docs/aapa.md).",
    )
    .input("percepts", percepts_req(), "the detections of each frame (an AAPA cycle per frame); `colour` optional")
    .input(
        "actions",
        actions_req(),
        "actions reported since the last frame, e.g. pick_up(gripper0, gear0); optional `phase` \
         (\"started\" | \"completed\") and `expected_end` (microseconds); emit one list per frame, \
         empty when nothing happened, or give the stream a `max delay`",
    )
    .input("poses", pose_req(), "the camera position (metres, camera axes) for camera movement alignment")
    .input(
        "previous",
        world_req(),
        "this unit's own world state fed back (`stream previous = world with feedback, use most recent`)",
    )
    .output(world_req())
    .param(f("theta", defaults.theta, "θ: a percept aligns with an anchor only if the cost of eq. (1) is below this (paper: 6500)"))
    .param(f(
        "type_mismatch",
        defaults.type_mismatch,
        "the type mismatch constant of eq. (1): the cost factor when percept and anchor types differ (the paper gives no value)",
    ))
    .param(f(
        "theta_anch",
        defaults.theta_anch,
        "θ_anch: confidence from which an unseen anchor is kept by hypothesis reasoning (paper: 0.1 LA-CATER, 0.5 gearbox)",
    ))
    .param(f(
        "theta_inf",
        defaults.theta_inf,
        "θ_inf ≥ θ_anch: confidence from which an anchor is passed on for inference (`for_inference`, spatial relations) (paper: 0.1 LA-CATER, 0.8 gearbox)",
    ))
    .param(f("conf_plus", defaults.conf_plus, "conf+: confidence gained per aligned cycle, capped at 1 (paper: 0.1 LA-CATER, 0.05 gearbox)"))
    .param(f("conf_minus", defaults.conf_minus, "conf-: confidence lost per cycle by an unexplained lost anchor; below 0 it is removed (paper: 0.1)"))
    .param(Param::optional(
        "image",
        floats.clone(),
        Value::List(Vec::new().into()),
        "[width, height] of the image in pixels: unseen anchors outside it are out of view; [] for no field of view",
    ))
    .param(f("focal_px", 0.0, "camera model for camera movement alignment: focal length in pixels; 0 for none (the camera must then stay still: a pose that changes is an error)"))
    .param(Param::optional(
        "principal",
        floats,
        Value::List(Vec::new().into()),
        "camera model: principal point [cx, cy] in pixels; [] for the image centre",
    ))
    .param(f("surface_z", 0.0, "camera model: z of the work surface in the pose frame (the camera looks along +z), metres"))
    .param(b("spatial_relations", defaults.spatial_relations, "infer left_of and behind among anchors passed on for inference"))
    .param(b("predict_motion", ext.predict_motion, "extension: an unseen object an action is moving continues its move until the action's expected end"))
    .param(Param::optional(
        "motion_profile",
        ParamType::Choice(vec!["fitted".into(), "ease_in_out".into(), "constant_velocity".into()]),
        Value::str("fitted"),
        "extension: how an unseen move proceeds (with predict_motion): fitted to the positions seen (smooth, linear, ease-in or ease-out), ease_in_out, or constant_velocity",
    ))
    .param(b("reacquire", ext.reacquire, "extension: a confirmed new anchor takes over an unseen older anchor of its type"))
    .param(b("scale_attached", ext.scale_attached, "extension: a carried child scales its offset and size with its parent's box"))
    .param(b(
        "restore_partial_boxes",
        ext.restore_partial_boxes,
        "extension: restore the size of a detection cut by an overlapping one (for detectors that box the visible part)",
    ))
    .param(b(
        "established_first",
        ext.established_first,
        "extension: alignment costs to tentative anchors (confidence below 0.5) count double",
    ))
    .param(b(
        "infer_hidden",
        ext.infer_hidden,
        "extension: an object a containing action hides but never perceived gets an anchor inside its container",
    ))
    .param(b(
        "average_still",
        ext.average_still,
        "extension: the box of an object no action moves is the mean of its boxes since it last moved",
    ))
    .param(b(
        "still_stays",
        ext.still_stays,
        "extension: an object no action moves takes a percept away from it only at ten times the cost (H1: every move is an action)",
    ))
    .param(b(
        "merge_duplicates",
        ext.merge_duplicates,
        "extension: two anchors of one type on the same spot, neither moving, are one object: the younger is merged into the older",
    ))
    .param(b(
        "identity_by_place",
        ext.identity_by_place,
        "extension: which of identical objects an action means is decided by where things are (a contain by the object it covers)",
    ))
    .param(f(
        "keep_lost",
        ext.keep_lost,
        "extension: seconds for which an established anchor that vanishes unexplained keeps its confidence (0: the paper's decay)",
    ))
    .param(Param::optional(
        "action_rules",
        ParamType::Str,
        Value::str(""),
        "JSON file of action rules (relative to the spec) replacing the built-in table of docs/aapa.md; empty for the built-in table",
    ))
}

pub(crate) fn register(registry: &mut kpl_runtime::Registry) {
    registry.add_unit(anchor_entry(), build);
    gearbox::register(registry);
    cater::register(registry);
}

#[cfg(test)]
mod tests;
