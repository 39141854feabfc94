//! `source NAME : TYPE = sim.uav_tracker(...)`: one snapshot per tracker frame of the percepts it
//! currently sees, as records `{id: "vp3", pos, vel, size}`; the `truth` output carries the
//! ground truth of the same frame (every vehicle, whether the camera could see it, and which
//! percept sees it; docs/simulator.md, "Ground truth records"); the `view` output what it could
//! see in that frame (its footprint and occluders), which the function `visible(view, pos)` reads
//! (`forget after 5s, after 1s when visible(view, this)`: docs/anchoring.md, "Forgetting").
//!
//! The simulation's seed is mixed with the run's `--seed`, so a run with a fixed seed is
//! reproducible and different seeds give different traffic. With recorded traffic
//! (`traffic_file`) the source ends with the recording; a malformed vehicle or row is counted as
//! a malformed input of the source and skipped.

use std::sync::Arc;

use kpl_core::{Time, Value, ValueType};
use kpl_runtime::context::SourceContext;
use kpl_runtime::process::{BoxFuture, ProcessError, Source};
use kpl_runtime::registry::BuildContext;
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};
use kpl_sim::{Frame, Params, PerceptSource, UavTrackerSim};

struct Tracker {
    sim: Option<UavTrackerSim>,
    params: Params,
    /// The seed of the simulated traffic: the tracker's own, or with `shared_traffic` one that
    /// every source with the same `seed` shares.
    traffic_seed: u64,
    network: Arc<kpl_roads::RoadNetwork>,
}

impl Source for Tracker {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let sim = match self.sim.take() {
                Some(sim) => sim,
                None => UavTrackerSim::with_traffic_seed(
                    &self.params,
                    self.network.clone(),
                    ctx.now(),
                    self.traffic_seed,
                )
                .map_err(|e| ProcessError::failed(e.to_string()))?,
            };
            let mut sim = sim;
            // The occluders do not change during a run: one value, shared by every frame's view.
            let occluders = occluders_value(sim.occluders());
            loop {
                if sim.finished() {
                    break;
                }
                let t: Time = sim.next_frame_time();
                if !ctx.wait_until(t).await {
                    break;
                }
                let frame = sim.next_frame();
                for problem in sim.take_problems() {
                    ctx.malformed(problem.location, problem.error)?;
                }
                let prefix = self.params.percept_prefix.as_str();
                let percepts: Vec<Value> = frame
                    .percepts
                    .iter()
                    .map(|p| Value::Record(Arc::new(p.to_record_prefixed(prefix))))
                    .collect();
                ctx.emit(frame.time, Value::List(percepts.into())).await;
                ctx.emit_port(1, frame.time, truth(&frame, prefix)).await;
                ctx.emit_port(2, frame.time, view_value(sim.footprint_at(frame.time), &occluders)).await;
                if ctx.unconsumed() {
                    break;
                }
            }
            Ok(())
        })
    }

    /// Recorded traffic ends with its recording; in simulated traffic a car that leaves the map
    /// is replaced by a new one, so it never ends.
    fn ends_by_itself(&self) -> bool {
        self.params.traffic_file.is_some()
    }
}

/// The occluders as a list of records `{area: list<vec2>, roads: list<int>}` (`roads` empty:
/// it hides everything under it; else only what is on those roads).
pub(crate) fn occluders_value(occluders: &kpl_roads::Occluders) -> Value {
    let list: Vec<Value> = occluders
        .list()
        .iter()
        .map(|o| {
            let area: Vec<Value> = o.area.iter().map(|p| Value::vec2(p[0], p[1])).collect();
            let roads: Vec<Value> = o.roads.iter().map(|r| Value::Int(i64::from(r.0))).collect();
            Value::Record(Arc::new(kpl_core::Record {
                id: None,
                fields: vec![
                    ("area".into(), Value::List(area.into())),
                    ("roads".into(), Value::List(roads.into())),
                ],
            }))
        })
        .collect();
    Value::List(list.into())
}

/// What the tracker could see in a frame: `{footprint: list<vec2>, occluders}` (an empty
/// footprint: the whole network).
pub(crate) fn view_value(footprint: Option<Vec<kpl_roads::geom::Point>>, occluders: &Value) -> Value {
    let corners: Vec<Value> = footprint.unwrap_or_default().iter().map(|p| Value::vec2(p[0], p[1])).collect();
    Value::Record(Arc::new(kpl_core::Record {
        id: None,
        fields: vec![
            ("footprint".into(), Value::List(corners.into())),
            ("occluders".into(), occluders.clone()),
        ],
    }))
}

/// `visible(view, pos)`: whether a tracker's `view` sample shows a position: inside the footprint
/// (an empty one is everything) and under no occluder. `pos` is a vec2, or an object with `pos`;
/// an occluder that hides only some roads (a bridge hides the road below it) hides an object on
/// one of them, and one whose road is not known (no `road`, or -1): negative information is only
/// taken where the object should surely be visible.
fn visible(args: &[Value]) -> Result<Value, String> {
    let Value::Record(view) = &args[0] else {
        return Err(format!("visible needs a tracker's `view` sample, found {}", args[0].kind()));
    };
    let (pos, road) = match &args[1] {
        Value::Vec2(p) => (*p, None),
        Value::Record(r) => match r.get("pos") {
            Some(Value::Vec2(p)) => (*p, r.get("road").and_then(Value::as_i64).filter(|r| *r >= 0)),
            _ => return Err("visible needs a position (vec2) or an object with `pos`".into()),
        },
        other => return Err(format!("visible needs a position (vec2), found {}", other.kind())),
    };
    let points = |v: Option<&Value>| -> Result<Vec<[f64; 2]>, String> {
        match v {
            Some(Value::List(items)) => items
                .iter()
                .map(|p| match p {
                    Value::Vec2(p) => Ok(*p),
                    _ => Err("visible: a view's polygons are lists of vec2".to_string()),
                })
                .collect(),
            _ => Err("visible: the view lacks `footprint` or an occluder's `area`".into()),
        }
    };
    let footprint = points(view.get("footprint"))?;
    if footprint.len() >= 3 && !kpl_roads::geom::point_in_polygon(pos, &footprint) {
        return Ok(Value::Bool(false));
    }
    let Some(Value::List(occluders)) = view.get("occluders") else {
        return Err("visible: the view lacks `occluders`".into());
    };
    for occluder in occluders.iter() {
        let Value::Record(o) = occluder else { continue };
        let area = points(o.get("area"))?;
        let hides_this = match o.get("roads") {
            Some(Value::List(roads)) if !roads.is_empty() => {
                road.is_none_or(|r| roads.iter().any(|x| x.as_i64() == Some(r)))
            }
            _ => true,
        };
        if hides_this && kpl_roads::geom::point_in_polygon(pos, &area) {
            return Ok(Value::Bool(false));
        }
    }
    Ok(Value::Bool(true))
}

/// The ground truth of a frame: every vehicle's record (`CarState::to_record`) with `visible`
/// (the camera could see it: in the footprint and not occluded), `in_view` (in the footprint,
/// occluded or not) and `seen_as` (the percept that shows it, "" when none).
fn truth(frame: &Frame, prefix: &str) -> Value {
    let mut seen_as = std::collections::BTreeMap::new();
    for p in &frame.percepts {
        if let PerceptSource::Car(car) = p.source {
            seen_as.insert(car, format!("{prefix}{}", p.id.0));
        }
    }
    let records: Vec<Value> = frame
        .cars
        .iter()
        .zip(&frame.visibility)
        .map(|(car, visibility)| {
            let mut record = car.to_record();
            record.fields.push(("visible".into(), Value::Bool(visibility.in_view())));
            // In the camera's footprint, occluded or not (`kpl score --in-view-only`).
            record
                .fields
                .push(("in_view".into(), Value::Bool(*visibility != kpl_sim::Visibility::OutOfView)));
            let seen = seen_as.get(&car.id).cloned().unwrap_or_default();
            record.fields.push(("seen_as".into(), Value::str(&seen)));
            Value::Record(Arc::new(record))
        })
        .collect();
    Value::List(records.into())
}

/// The parameters that name files, read relative to the spec's directory.
macro_rules! FILE_PARAMS {
    () => {
        "network_file" | "traffic_file" | "vtypes_file" | "occluders_file"
    };
}

/// The parameters, with the run's seed mixed in, and the seed of the simulated traffic.
fn params(ctx: &BuildContext<'_>) -> Result<(Params, u64), kpl_runtime::registry::BuildError> {
    params_where(ctx, |_| true)
}

/// [`params`] from the call's parameters whose names `keep` (the camera mode's own are left to it).
pub(crate) fn params_where(
    ctx: &BuildContext<'_>,
    keep: impl Fn(&str) -> bool,
) -> Result<(Params, u64), kpl_runtime::registry::BuildError> {
    let call = ctx.call().ok_or_else(|| ctx.error("no parameters"))?;
    let spec_dir = ctx.spec_dir.to_path_buf();
    let mut args: Vec<(String, Value)> = Vec::new();
    for (name, value) in call.params.iter().filter(|(name, _)| keep(name)) {
        match (name.as_str(), value) {
            (FILE_PARAMS!(), Value::Str(s)) if !s.is_empty() => {
                args.push((name.clone(), Value::str(&spec_dir.join(&**s).to_string_lossy())))
            }
            _ => args.push((name.clone(), value.clone())),
        }
    }
    let mut params =
        Params::from_args(args.iter().map(|(n, v)| (n.as_str(), v))).map_err(|e| ctx.error(e.to_string()))?;
    // Shared traffic: the spec's seed and the run's, not the process name, so every tracker of
    // the run with the same seed draws the same cars.
    let traffic_seed = if params.shared_traffic {
        params.seed ^ ctx.run_seed.wrapping_mul(0x9e37_79b9_7f4a_7c15)
    } else {
        params.seed ^ ctx.seed()
    };
    // Mix the run's seed in (a fixed --seed gives the same traffic every run).
    params.seed ^= ctx.seed();
    Ok((params, traffic_seed))
}

/// The parameter type a type name of `Params::describe` stands for (`list<list<float>>`).
fn param_type(name: &str) -> ParamType {
    match name {
        "int" => ParamType::Int,
        "float" => ParamType::Float,
        "bool" => ParamType::Bool,
        _ => match name.strip_prefix("list<").and_then(|rest| rest.strip_suffix('>')) {
            Some(item) => ParamType::List(Box::new(param_type(item))),
            None => ParamType::Str,
        },
    }
}

/// A simulator parameter as a registry parameter (its type, default and description).
pub(crate) fn param_from_info(info: &kpl_sim::ParamInfo) -> Param {
    let ty = param_type(info.ty);
    let ty = if info.name == "scenario" {
        ParamType::Choice(vec!["crossing".into(), "bridge".into(), "grid_town".into()])
    } else if info.name == "flight" {
        ParamType::Choice(vec!["hover".into(), "circle".into()])
    } else {
        ty
    };
    let default = serde_json::from_str::<serde_json::Value>(&info.default)
        .ok()
        .and_then(|j| Value::from_json_untyped(&j).ok())
        .unwrap_or_else(|| Value::str(""));
    Param::optional(info.name, ty, default, info.doc)
}

pub(crate) fn register(registry: &mut kpl_runtime::Registry) {
    let mut entry = Entry::new(
        EntryKind::Source,
        "sim.uav_tracker",
        "Vision percepts of cars from a simulated UAV tracker (one snapshot per frame).",
    )
    .output(TypeReq::Objects(vec![
        ("pos".into(), ValueType::Vec2),
        ("vel".into(), ValueType::Vec2),
        ("size".into(), ValueType::Float),
    ]))
    .port(
        "truth",
        TypeReq::Any,
        "ground truth per frame: every vehicle (id, pos, vel, heading, speed, road, lane, node, length, width), `visible`, and `seen_as` the percept that sees it",
    )
    .port(
        "view",
        TypeReq::Any,
        "what the tracker could see per frame: `footprint` (list<vec2>, empty: everything) and `occluders` (`area`, `roads`); read with `visible(view, pos)`",
    );
    registry.add_function(
        kpl_semantic::registry::Function::new(
            "visible",
            vec![ValueType::Any, ValueType::Any],
            ValueType::Bool,
            "whether a simulated tracker's `view` sample shows a position (or an object's `pos`, on its `road`): in the footprint and under no occluder",
        ),
        kpl_mtl::Function::new("visible", (2, Some(2)), visible),
    );
    for info in Params::describe() {
        entry = entry.param(param_from_info(&info));
    }
    registry.add_source(entry, |ctx| {
        let (params, traffic_seed) = params(ctx)?;
        let network = Arc::new(params.load_network().map_err(|e| ctx.error(e.to_string()))?);
        // Opened now so that a missing or unreadable recording, vehicle-type or occluder file
        // stops the run before it starts; the run opens it again at its start time.
        UavTrackerSim::with_traffic_seed(&params, network.clone(), 0, traffic_seed)
            .map_err(|e| ctx.error(e.to_string()))?;
        Ok(Box::new(Tracker { sim: None, params, traffic_seed, network }))
    });
}
