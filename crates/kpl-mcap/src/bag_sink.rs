//! `ros2.bag`: a sink that records a stream as a topic of a rosbag2 bag while the run goes (the
//! bag `kpl convert RECORDING BAG --spec SPEC` writes afterwards, straight from the run): each
//! sample mapped into a message as `ros2.publish` maps it (`topic`, `type`, `msgs`, `each`,
//! `map`; `header.stamp` the valid time) and encoded in CDR, its log and publish time the
//! sample's available time. Sinks with the same `path` write one bag, a topic each.
//!
//! ```kpl
//! sink bag = ros2.bag(onroad_car, path: "cars", topic: "/kpl/cars",
//!   type: "visualization_msgs/msg/MarkerArray", each: "markers",
//!   map: ["ns = symbol", "id = number", "pose.position = pos", "scale.x = size"])
//! ```
//!
//! The bag is written as samples arrive (uncompressed MCAP chunks, as rosbag2 writes them,
//! closed every second of log time, so a killed run leaves the chunks before its last); at
//! the end of the run, Ctrl-C and SIGTERM included, its last chunk, summary and `metadata.yaml`
//! are written when the last of its sinks ends. Works in simulated time too: nothing is
//! published.

use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;
use std::sync::{Arc, Mutex, OnceLock};

use kpl_core::{Value, ValueType};
use kpl_ros2::mapping::{MapError, OutMap};
use kpl_ros2::wire::{self, Qos};
use kpl_ros2::{Schema, cdr, topic};
use kpl_runtime::process::{Emitter, Input, ProcessError, SyncUnit, Unit};
use kpl_runtime::registry::{BuildContext, Registry};
use kpl_semantic::registry::{CallTypes, Entry, EntryKind, Param, ParamProblem, ParamType, TypeReq};

use crate::rosbag2::{BagWriter, Split, TopicId};

/// A bag that one or more sinks write: the writer (made at the first message or end), the
/// topics added so far by sink, and how many of its sinks have not ended.
#[derive(Default)]
struct Shared {
    writer: Option<BagWriter>,
    /// When the bag's files are split (the first sink's `max_bag_size` and `max_bag_duration`;
    /// the others must agree).
    split: Option<Split>,
    failed: Option<String>,
    open: usize,
}

type Bags = Mutex<HashMap<PathBuf, Arc<Mutex<Shared>>>>;

fn bags() -> &'static Bags {
    static BAGS: OnceLock<Bags> = OnceLock::new();
    BAGS.get_or_init(Default::default)
}

struct BagSink {
    dir: PathBuf,
    shared: Arc<Mutex<Shared>>,
    topic: String,
    schema: Arc<Schema>,
    qos: Qos,
    map: OutMap,
    id: Option<TopicId>,
    buffer: Vec<u8>,
}

impl BagSink {
    fn failed(&self, e: impl std::fmt::Display) -> ProcessError {
        ProcessError::failed(format!("bag {}: {e}", self.dir.display()))
    }

    /// The bag's writer (created the first time) and this sink's topic in it.
    fn with_writer<T>(
        &mut self,
        f: impl FnOnce(&mut BagWriter, TopicId) -> Result<T, String>,
    ) -> Result<T, ProcessError> {
        let shared = self.shared.clone();
        let mut shared = shared.lock().map_err(|_| self.failed("a sink of the bag failed"))?;
        if let Some(why) = &shared.failed {
            return Err(self.failed(why));
        }
        if shared.writer.is_none() {
            let split = shared.split.unwrap_or_default();
            shared.writer = Some(BagWriter::create_split(&self.dir, split).map_err(|e| self.failed(e))?);
        }
        let Some(writer) = shared.writer.as_mut() else { return Err(self.failed("no writer")) };
        let id = match self.id {
            Some(id) => id,
            None => {
                let id = writer.add_topic(&self.topic, &self.schema, self.qos).map_err(|e| self.failed(e))?;
                self.id = Some(id);
                id
            }
        };
        let result = f(writer, id);
        if let Err(why) = &result {
            shared.failed = Some(why.clone());
        }
        result.map_err(|e| self.failed(e))
    }
}

impl Unit for BagSink {
    fn on_input(&mut self, input: &Input<'_>, _out: &mut Emitter) -> Result<(), ProcessError> {
        let Some((_, sample)) = input.trigger_sample() else { return Ok(()) };
        let msg = self
            .map
            .apply(sample.valid, &sample.value)
            .map_err(|e| ProcessError::failed(format!("`{}`: {e}", self.topic)))?;
        let mut buffer = std::mem::take(&mut self.buffer);
        cdr::encode_into(&self.schema, &msg, &mut buffer)
            .map_err(|e| ProcessError::failed(format!("`{}`: {e}", self.topic)))?;
        let available = sample.available;
        let result =
            self.with_writer(|writer, id| writer.write(id, available, &buffer).map_err(|e| e.to_string()));
        self.buffer = buffer;
        result
    }

    fn on_end(&mut self, _out: &mut Emitter) -> Result<(), ProcessError> {
        // The topic is in the bag even when nothing arrived, so a run's outputs always exist.
        self.with_writer(|_, _| Ok(()))?;
        let mut shared = self.shared.lock().map_err(|_| self.failed("a sink of the bag failed"))?;
        shared.open = shared.open.saturating_sub(1);
        if shared.open > 0 {
            return Ok(());
        }
        if let Ok(mut bags) = bags().lock() {
            bags.remove(&self.dir);
        }
        match shared.writer.take() {
            Some(writer) => writer.finish().map(|_| ()).map_err(|e| self.failed(e)),
            None => Ok(()),
        }
    }
}

/// `kpl check` of `ros2.bag`: its type and mapping, as `ros2.publish`'s.
fn check(call: &CallTypes<'_>) -> Vec<ParamProblem> {
    let Some(input) = call.inputs.first() else { return Vec::new() };
    topic::check_out(call.params, input, call.dir).err().map(topic::param_problem).into_iter().collect()
}

fn params<'c>(ctx: &'c BuildContext<'_>) -> &'c BTreeMap<String, Value> {
    static NONE: BTreeMap<String, Value> = BTreeMap::new();
    ctx.call().map_or(&NONE, |c| &c.params)
}

/// `max_bag_size` and `max_bag_duration` (0: no limit).
fn split_of(params: &BTreeMap<String, Value>) -> Result<Split, String> {
    let bytes = params.get("max_bag_size").and_then(Value::as_i64).unwrap_or(0);
    let duration = match params.get("max_bag_duration") {
        Some(Value::Duration(us) | Value::Int(us)) => *us,
        _ => 0,
    };
    if bytes < 0 {
        return Err(format!("`max_bag_size`: {bytes} is not a size in bytes (0 for no limit)"));
    }
    if duration < 0 {
        return Err("`max_bag_duration`: a negative duration (0s for no limit)".to_string());
    }
    Ok(Split {
        max_bytes: (bytes > 0).then_some(bytes.unsigned_abs()),
        max_duration: (duration > 0).then_some(duration),
    })
}

/// Registers `ros2.bag`.
pub fn register(registry: &mut Registry) {
    registry.add_unit(
        Entry::new(
            EntryKind::Sink,
            "ros2.bag",
            "Records a stream as a topic of a rosbag2 bag (MCAP storage), mapped as ros2.publish maps it (docs/ros2.md). Sinks with the same `path` write one bag.",
        )
        .input("in", TypeReq::Any, "the stream to record")
        .param(Param::required("path", ParamType::Str, "the bag's folder, relative to the run's --out directory"))
        .param(Param::required("topic", ParamType::Str, "the topic (`/kpl/cars`; relative names are in `namespace`)"))
        .param(Param::required("type", ParamType::Str, "the message type, `package/msg/Name` (shipped, or in `msgs`)"))
        .param(Param::optional("each", ParamType::Str, Value::str(""), "an array of the message whose elements are the objects of a list stream (`markers`)"))
        .param(Param::optional("map", ParamType::List(Box::new(ParamType::Str)), Value::List(Arc::from(Vec::new())), "the mapping, one entry per field (docs/ros2.md)"))
        .param(Param::optional("namespace", ParamType::Str, Value::str("/"), "the namespace of a relative topic"))
        .param(Param::optional("msgs", ParamType::Str, Value::str(""), "a folder of the user's own `.msg` files (`<package>/msg/<Name>.msg`), relative to the spec"))
        .param(Param::optional("reliability", ParamType::Choice(vec!["reliable".into(), "best_effort".into()]), Value::str("reliable"), "the QoS the bag says the topic was offered with"))
        .param(Param::optional("durability", ParamType::Choice(vec!["volatile".into(), "transient_local".into()]), Value::str("volatile"), "the QoS the bag says the topic was offered with"))
        .param(Param::optional("depth", ParamType::Int, Value::Int(10), "the QoS history depth the bag says the topic was offered with"))
        .param(Param::optional("max_bag_size", ParamType::Int, Value::Int(0), "split the bag: a new file once a file's messages reach this many bytes (0: never; `ros2 bag record --max-bag-size`)"))
        .param(Param::optional("max_bag_duration", ParamType::Duration, Value::Duration(0), "split the bag: a new file once a message comes this long after the file's first (0s: never; `ros2 bag record --max-bag-duration`)"))
        .checked_by(check),
        |ctx| {
            let params = params(ctx);
            let describe = |e: MapError| ctx.error(topic::describe(params, &e));
            let schema = topic::schema_in(params, ctx.spec_dir).map_err(describe)?;
            let input = ctx.process.inputs.first().map_or(ValueType::Any, |i| i.stream.ty.clone());
            let map = OutMap::compile(schema.clone(), &topic::out_spec(params), &input).map_err(describe)?;
            let name = topic::text(params, "topic");
            wire::check_topic(name).map_err(|e| ctx.error(format!("`topic`: {e}")))?;
            let namespace = topic::text(params, "namespace");
            let depth = params.get("depth").and_then(Value::as_i64).unwrap_or(10);
            let qos = Qos {
                reliable: topic::text(params, "reliability") != "best_effort",
                transient_local: topic::text(params, "durability") == "transient_local",
                depth: Some(
                    u32::try_from(depth)
                        .ok()
                        .filter(|d| *d > 0)
                        .ok_or_else(|| ctx.error(format!("`depth`: {depth} is not a history depth (1 or more)")))?,
                ),
            };
            let dir = ctx.output_path(topic::text(params, "path"));
            let split = split_of(params).map_err(|e| ctx.error(e))?;
            let shared = {
                let mut bags = bags().lock().map_err(|_| ctx.error("the bags of the run are unusable"))?;
                bags.entry(dir.clone()).or_default().clone()
            };
            if let Ok(mut shared) = shared.lock() {
                match shared.split {
                    Some(first) if first != split => {
                        return Err(ctx.error(format!(
                            "the sinks of the bag {} split it differently (`max_bag_size`, `max_bag_duration`): give them the same values",
                            dir.display()
                        )));
                    }
                    _ => shared.split = Some(split),
                }
                shared.open += 1;
            }
            Ok(Box::new(SyncUnit(BagSink {
                dir,
                shared,
                topic: wire::qualify(if namespace.is_empty() { "/" } else { namespace }, name),
                schema,
                qos,
                map,
                id: None,
                buffer: Vec::new(),
            })))
        },
    );
}
