//! `ros2.replay`: a ROS 2 topic of a rosbag2 bag (or its MCAP file) replayed as a stream, through
//! the same mapping as `ros2.subscribe` (`each`, `identity`, `stamp`, `map`; docs/ros2.md), in
//! simulated time or real time. A `ros2 bag record` of a robot goes through a spec as its topic
//! would have live.
//!
//! ```kpl
//! source markers : list<VisionPercept> = ros2.replay(
//!   path: "tracker", topic: "/tracker/markers", type: "visualization_msgs/msg/MarkerArray",
//!   each: "markers", identity: "id", map: ["pos = pose.position", "size = scale.x"])
//! ```
//!
//! The valid time is the mapping's stamp (`header.stamp` by default), else the message's publish
//! time; the available time is its log time (when the recorder received it). A message that
//! does not decode as the declared type, or that the mapping cannot take, is counted as malformed
//! with where it is, and the replay goes on.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use kpl_core::{Value, ValueType};
use kpl_ros2::mapping::{InMap, MapError};
use kpl_ros2::{Schema, topic};
use kpl_runtime::Sample;
use kpl_runtime::builtins::{ReplayTimes, StreamFilter};
use kpl_runtime::clock::ClockKind;
use kpl_runtime::context::SourceContext;
use kpl_runtime::process::{BoxFuture, ProcessError, Source};
use kpl_runtime::registry::{BuildContext, Registry};
use kpl_semantic::registry::{CallTypes, Entry, EntryKind, Param, ParamProblem, ParamType, TypeReq};

use crate::read::{RawEvent, Reader};
use crate::rosbag2::bag_files;

struct Replay {
    display: String,
    files: Vec<PathBuf>,
    topic: String,
    schema: Arc<Schema>,
    /// The declared type's RIHS01 hash, and whether the type is the spec's own (`msgs`).
    hash: String,
    user_msgs: bool,
    /// The type hash the bag's `metadata.yaml` records for the topic, when it records one.
    metadata_hash: Option<String>,
    map: InMap,
    clock: ClockKind,
}

impl Replay {
    /// The error for a message of a topic that `recorded_in` records with another type hash than
    /// the declared type's, if it does.
    fn hash_differs(&self, recorded_in: &str, recorded: &str) -> Option<String> {
        (recorded != self.hash).then(|| {
            format!(
                "{recorded_in} records `{}` with type hash {recorded}, but `{}` as kpl reads it (the spec's `type`{}) has type hash {}: the message definitions differ",
                self.topic,
                self.schema.name(),
                if self.user_msgs { " from `msgs`" } else { ", shipped" },
                self.hash
            )
        })
    }

    /// A message as the mapping takes it: valid time and value.
    fn map(&self, valid: i64, json: &serde_json::Value) -> Result<(i64, Value), String> {
        let msg = kpl_ros2::json::from_json(&self.schema, json)
            .map_err(|e| format!("not a `{}`: {e}", self.schema.name()))?;
        let value = self.map.apply(&msg)?;
        Ok((self.map.valid_time(&msg).unwrap_or(valid), value))
    }
}

impl Source for Replay {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let mut times = ReplayTimes::new(self.clock);
            let mut filter = StreamFilter::new(&self.topic);
            'files: for path in &self.files {
                let mut reader = Reader::open(path)
                    .map_err(|e| ProcessError::failed(format!("cannot open {}: {e}", path.display())))?;
                while let Some(event) = reader.next_raw(&mut filter) {
                    let (valid, available, json, location) = match event {
                        RawEvent::Message { valid, available, value, location, .. } => {
                            let differs = reader
                                .type_hash(&self.topic)
                                .and_then(|recorded| self.hash_differs("the bag", recorded))
                                .or_else(|| {
                                    let recorded = self.metadata_hash.as_deref()?;
                                    self.hash_differs("the bag's metadata.yaml", recorded)
                                });
                            if let Some(error) = differs {
                                ctx.malformed(&location, error)?;
                                continue;
                            }
                            (valid, available, value, location)
                        }
                        RawEvent::Malformed { location, error } => {
                            ctx.malformed(&location, error)?;
                            continue;
                        }
                    };
                    let (valid, value) = match self.map(valid, &json) {
                        Ok(mapped) => mapped,
                        Err(error) => {
                            ctx.malformed(&location, error)?;
                            continue;
                        }
                    };
                    let Some(sample) = times.admit(ctx, &location, Sample::new(valid, available, value))?
                    else {
                        continue;
                    };
                    if !ctx.wait_until(sample.available).await {
                        break 'files;
                    }
                    ctx.emit_sample(sample).await;
                    if ctx.unconsumed() {
                        break 'files;
                    }
                }
            }
            if let Some(warning) = filter.warning(&self.display) {
                ctx.warn(warning);
            }
            Ok(())
        })
    }
}

/// `kpl check` of `ros2.replay`: its type and mapping, as `ros2.subscribe`'s.
fn check(call: &CallTypes<'_>) -> Vec<ParamProblem> {
    let Some(output) = call.output else { return Vec::new() };
    topic::check_in(call.params, output, call.dir).err().map(topic::param_problem).into_iter().collect()
}

fn params<'c>(ctx: &'c BuildContext<'_>) -> &'c BTreeMap<String, Value> {
    static NONE: BTreeMap<String, Value> = BTreeMap::new();
    ctx.call().map_or(&NONE, |c| &c.params)
}

/// Registers `ros2.replay`.
pub fn register(registry: &mut Registry) {
    registry.add_source(
        Entry::new(
            EntryKind::Source,
            "ros2.replay",
            "Replays a ROS 2 topic of a rosbag2 bag through a mapping, as ros2.subscribe takes it live (docs/ros2.md).",
        )
        .param(Param::required("path", ParamType::Str, "the bag: its folder (metadata.yaml and the .mcap files) or an .mcap file, relative to the spec"))
        .param(Param::required("topic", ParamType::Str, "the topic (`/tracker/markers`)"))
        .param(Param::required("type", ParamType::Str, "the message type, `package/msg/Name` (shipped, or in `msgs`)"))
        .param(Param::optional("msgs", ParamType::Str, Value::str(""), "a folder of the user's own `.msg` files (`<package>/msg/<Name>.msg`), relative to the spec"))
        .param(Param::optional("each", ParamType::Str, Value::str(""), "an array of the message whose elements are the objects of a list stream (`markers`)"))
        .param(Param::optional("identity", ParamType::Str, Value::str(""), "the field that identifies an object (a track id): the record's symbol is the type's prefix and its value"))
        .param(Param::optional("stamp", ParamType::Str, Value::str(""), "the valid time: a builtin_interfaces/Time field (default `header.stamp`, else the message's publish time)"))
        .param(Param::optional("map", ParamType::List(Box::new(ParamType::Str)), Value::List(Arc::from(Vec::new())), "the mapping, one entry per field (docs/ros2.md)"))
        .output(TypeReq::Any)
        .checked_by(check),
        |ctx| {
            let params = params(ctx);
            let describe = |e: MapError| ctx.error(topic::describe(params, &e));
            let schema = topic::schema_in(params, ctx.spec_dir).map_err(describe)?;
            let output = ctx.process.output.clone().unwrap_or(ValueType::Any);
            let map = InMap::compile(&schema, &topic::in_spec(params), &output).map_err(describe)?;
            let path = ctx.input_path(topic::text(params, "path"));
            let files = bag_files(&path).map_err(|e| ctx.error(format!("cannot read the bag {}: {e}", path.display())))?;
            let name = topic::text(params, "topic");
            kpl_ros2::wire::check_topic(name).map_err(|e| ctx.error(format!("`topic`: {e}")))?;
            let user_msgs = !topic::text(params, "msgs").is_empty();
            let hash = schema.type_hash();
            let metadata_hash = crate::rosbag2::recorded_hashes(&path).map_err(|e| ctx.error(e))?.remove(name);
            Ok(Box::new(Replay { display: path.display().to_string(), files, topic: name.to_string(), schema, hash, user_msgs, metadata_hash, map, clock: ctx.clock }))
        },
    );
}
