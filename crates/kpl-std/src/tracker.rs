//! `source NAME : TYPE = sim.uav_tracker(...)`: one snapshot per tracker frame of the percepts it
//! currently sees, as records `{id: "vp3", pos, vel, size}`; the `truth` output carries the
//! ground truth of the same frame (every car, and which percept sees it).
//!
//! The simulation's seed is mixed with the run's `--seed`, so a run with a fixed seed is
//! reproducible and different seeds give different traffic.

use std::sync::Arc;

use kpl_core::{Record, Time, Value, ValueType};
use kpl_runtime::context::SourceContext;
use kpl_runtime::process::{BoxFuture, ProcessError, Source};
use kpl_runtime::registry::BuildContext;
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};
use kpl_sim::{Params, PerceptSource, UavTrackerSim};

struct Tracker {
    sim: Option<UavTrackerSim>,
    params: Params,
    network: Arc<kpl_sim::RoadNetwork>,
}

impl Source for Tracker {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let sim = match self.sim.take() {
                Some(sim) => sim,
                None => UavTrackerSim::new(&self.params, self.network.clone(), ctx.now())
                    .map_err(|e| ProcessError::failed(e.to_string()))?,
            };
            let mut sim = sim;
            loop {
                let t: Time = sim.next_frame_time();
                if !ctx.wait_until(t).await {
                    break;
                }
                let frame = sim.next_frame();
                let percepts: Vec<Value> = frame.percepts.iter().map(kpl_sim::Percept::to_value).collect();
                ctx.emit(frame.time, Value::List(percepts.into())).await;
                let mut seen_as = std::collections::BTreeMap::new();
                for p in &frame.percepts {
                    if let PerceptSource::Car(car) = p.source {
                        seen_as.insert(car, p.id.to_string());
                    }
                }
                let truth: Vec<Value> = frame
                    .cars
                    .iter()
                    .map(|car| {
                        let mut record = match car.to_value() {
                            Value::Record(r) => (*r).clone(),
                            _ => Record::default(),
                        };
                        let seen = seen_as.get(&car.id).cloned().unwrap_or_default();
                        record.fields.push(("seen_as".into(), Value::str(&seen)));
                        Value::Record(Arc::new(record))
                    })
                    .collect();
                ctx.emit_port(1, frame.time, Value::List(truth.into())).await;
                if ctx.unconsumed() {
                    break;
                }
            }
            Ok(())
        })
    }

    /// A car that leaves the map is replaced by a new one: the traffic never ends.
    fn ends_by_itself(&self) -> bool {
        false
    }
}

fn params(ctx: &BuildContext<'_>) -> Result<Params, kpl_runtime::registry::BuildError> {
    let call = ctx.call().ok_or_else(|| ctx.error("no parameters"))?;
    let spec_dir = ctx.spec_dir.to_path_buf();
    let mut args: Vec<(String, Value)> = Vec::new();
    for (name, value) in &call.params {
        match (name.as_str(), value) {
            // An empty file name means the built-in scenario.
            ("network_file", Value::Str(s)) if s.is_empty() => {}
            ("network_file", Value::Str(s)) => {
                args.push((name.clone(), Value::str(&spec_dir.join(&**s).to_string_lossy())))
            }
            _ => args.push((name.clone(), value.clone())),
        }
    }
    let mut params =
        Params::from_args(args.iter().map(|(n, v)| (n.as_str(), v))).map_err(|e| ctx.error(e.to_string()))?;
    // Mix the run's seed in (a fixed --seed gives the same traffic every run).
    params.seed ^= ctx.seed();
    Ok(params)
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
        "ground truth per frame: every car, with `seen_as` the percept that sees it",
    );
    for info in Params::describe() {
        let ty = match info.ty {
            "int" => ParamType::Int,
            "float" => ParamType::Float,
            "bool" => ParamType::Bool,
            _ => ParamType::Str,
        };
        let ty = if info.name == "scenario" {
            ParamType::Choice(vec!["crossing".into(), "bridge".into(), "grid_town".into()])
        } else {
            ty
        };
        let default = serde_json::from_str::<serde_json::Value>(&info.default)
            .ok()
            .and_then(|j| Value::from_json_untyped(&j).ok())
            .unwrap_or_else(|| Value::str(""));
        entry = entry.param(Param::optional(info.name, ty, default, info.doc));
    }
    registry.add_source(entry, |ctx| {
        let params = params(ctx)?;
        let network = Arc::new(params.load_network().map_err(|e| ctx.error(e.to_string()))?);
        Ok(Box::new(Tracker { sim: None, params, network }))
    });
}
