//! What KPL's streams look like in Foxglove: samples turned into messages of Foxglove's
//! well-known schemas (protobuf, from the `foxglove` SDK's own types), so that Foxglove's 3D
//! panel draws a recording or a live run without configuration. The stream's own channel (KPL's
//! sample envelopes, lossless) stays beside these views; readers of samples skip them
//! ([`crate::VIEW_KEY`]).
//!
//! | stream | topic | schema |
//! |---|---|---|
//! | objects of a link (one level of anchoring) | `/kpl/STREAM` | `foxglove.SceneUpdate`: a box sized like the object and turned by its heading, its symbol as text, its velocity as an arrow; measured solid, predicted hollow (a faint box in an outline), a branch of a split outlined in magenta with its likelihood |
//! | percepts (a list of records with `pos` from a source or unit) | `/kpl/STREAM` | `foxglove.PointCloud` (`x`, `y`, `z`) |
//! | monitor verdicts and situations | `/kpl/STREAM` | `foxglove.Log`: one per episode, `info` for a recognised situation (`true`), `debug` otherwise |
//! | the road network's lanes | `/kpl/roads` | `foxglove.SceneUpdate` of line entities, once |
//! | occluders | `/kpl/occluders` | `foxglove.SceneUpdate` of filled polygons, once |
//! | the camera footprint | `/kpl/camera` | `foxglove.SceneUpdate` polygon: once, or with every frame when it moves |
//! | frame transforms | `/tf` | `foxglove.FrameTransforms`: `map` to `uav`, the camera above its footprint's centre |
//!
//! Everything is in frame `map` (the network's metres). A message's log time is the sample's
//! available time and the entities' timestamps its valid time.

use std::collections::BTreeMap;
use std::sync::Arc;

use foxglove::Encode;
use foxglove::messages::{
    ArrowPrimitive, Color, CubePrimitive, FrameTransform, FrameTransforms, KeyValuePair, LinePrimitive, Log,
    PackedElementField, Point3, PointCloud, Pose, Quaternion, SceneEntity, SceneEntityDeletion, SceneUpdate,
    TextPrimitive, Timestamp, TriangleListPrimitive, Vector3, line_primitive, log, packed_element_field,
    scene_entity_deletion,
};
use kpl_core::{Record, Time, Value, ValueType};
use kpl_runtime::Sample;
use kpl_semantic::hir;

use crate::scene::{Point, Scene};

/// The frame every entity is in.
pub const FRAME: &str = "map";
/// The frame of the camera, above the footprint's centre.
pub const CAMERA_FRAME: &str = "uav";
/// How high the camera is drawn above the ground, metres.
const CAMERA_ALTITUDE_M: f64 = 100.0;

/// What a stream shows as.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Objects of a link process: one level of anchoring.
    Objects,
    /// Percepts (or other positions) as points.
    Points,
    /// Verdicts of a monitor.
    Verdicts,
    /// Not known yet: decided by the first sample that tells (records with `measured` are
    /// objects, records with `pos` points, records with `verdict` verdicts).
    Unknown,
    /// Not drawn.
    Nothing,
}

impl Role {
    /// What a stream of a spec shows as, from its producer and type.
    pub fn of_stream(spec: &hir::Spec, stream: &hir::StreamRef) -> Role {
        if stream.port.is_some() {
            return Role::Nothing; // `tracker.truth`, `link.changes`: not what is anchored
        }
        match spec.processes.get(stream.producer).map(|p| &p.kind) {
            Some(hir::ProcessKind::Link(_)) => Role::Objects,
            Some(hir::ProcessKind::Monitor(_)) => Role::Verdicts,
            _ => match &stream.ty {
                ValueType::List(item) => match &**item {
                    ValueType::Record(record) if record.field("pos").is_some() => Role::Points,
                    _ => Role::Nothing,
                },
                ValueType::Any => Role::Unknown,
                _ => Role::Nothing,
            },
        }
    }
}

/// A Foxglove schema of the views.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ViewSchema {
    SceneUpdate,
    PointCloud,
    Log,
    FrameTransforms,
}

impl ViewSchema {
    /// The schema as Foxglove's SDK describes it (name, `protobuf`, the descriptor set).
    pub fn schema(self) -> foxglove::Schema {
        let schema = match self {
            ViewSchema::SceneUpdate => SceneUpdate::get_schema(),
            ViewSchema::PointCloud => PointCloud::get_schema(),
            ViewSchema::Log => Log::get_schema(),
            ViewSchema::FrameTransforms => FrameTransforms::get_schema(),
        };
        schema.unwrap_or_else(|| foxglove::Schema::new("", "", &[] as &[u8]))
    }
}

/// One message of a view.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewMessage {
    pub topic: Arc<str>,
    pub schema: ViewSchema,
    /// The stream it shows ("" for the scene's own topics).
    pub stream: Arc<str>,
    /// When it was known (the sample's available time), microseconds.
    pub log_time: Time,
    /// When it holds (the sample's valid time), microseconds.
    pub publish_time: Time,
    /// The protobuf message.
    pub data: Vec<u8>,
}

#[derive(Debug)]
struct StreamView {
    name: Arc<str>,
    topic: Arc<str>,
    role: Role,
    /// The level of an object stream (its place among the object streams), for its colour.
    level: usize,
}

/// A stream's place in [`Views`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ViewId(usize);

/// Turns the samples of a run's streams into Foxglove messages.
#[derive(Debug)]
pub struct Views {
    scene: Arc<Scene>,
    streams: Vec<StreamView>,
    levels: usize,
    /// The valid time of the first sample (the run's start, for a moving camera).
    start: Option<Time>,
    /// The last time the moving camera was drawn.
    camera_drawn: Option<Time>,
}

/// The topic of a stream's view.
pub fn topic_of(stream: &str) -> String {
    format!("/kpl/{stream}")
}

impl Views {
    pub fn new(scene: Arc<Scene>) -> Views {
        Views { scene, streams: Vec::new(), levels: 0, start: None, camera_drawn: None }
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Adds a stream; its samples are drawn as `role` says.
    pub fn add_stream(&mut self, name: &str, role: Role) -> ViewId {
        let level = self.level_for(role);
        self.streams.push(StreamView { name: name.into(), topic: topic_of(name).into(), role, level });
        ViewId(self.streams.len() - 1)
    }

    /// The level of a new stream of objects (the next one); 0 for other roles.
    fn level_for(&mut self, role: Role) -> usize {
        if role != Role::Objects {
            return 0;
        }
        self.levels += 1;
        self.levels - 1
    }

    /// The messages that show one sample of a stream (and, with the first sample, the scene).
    pub fn messages(&mut self, id: ViewId, sample: &Sample, out: &mut Vec<ViewMessage>) {
        if self.start.is_none() {
            self.start = Some(sample.valid);
            self.scene_messages(sample, out);
        }
        let Some(role) = self.streams.get(id.0).map(|s| s.role) else { return };
        if role == Role::Unknown {
            let Some(role) = guess_role(&sample.value) else { return };
            let level = self.level_for(role);
            let view = &mut self.streams[id.0];
            (view.role, view.level) = (role, level);
        }
        let view = &self.streams[id.0];
        let message = |schema, data| ViewMessage {
            topic: view.topic.clone(),
            schema,
            stream: view.name.clone(),
            log_time: sample.available,
            publish_time: sample.valid,
            data,
        };
        match view.role {
            Role::Objects => out.push(message(ViewSchema::SceneUpdate, encode(&objects(view.level, sample)))),
            Role::Points => {
                out.push(message(ViewSchema::PointCloud, encode(&points(sample))));
                if self.scene.camera_moves() && self.camera_drawn.is_none_or(|t| sample.valid > t) {
                    self.camera_drawn = Some(sample.valid);
                    self.camera_messages(sample, out);
                }
            }
            Role::Verdicts => {
                for log in verdicts(&view.name, sample) {
                    out.push(message(ViewSchema::Log, encode(&log)));
                }
            }
            Role::Unknown | Role::Nothing => {}
        }
    }

    /// The scene's messages (roads, occluders, a camera that does not move), at a sample's time.
    fn scene_messages(&mut self, sample: &Sample, out: &mut Vec<ViewMessage>) {
        let still = |topic: &str, schema, data| ViewMessage {
            topic: topic.into(),
            schema,
            stream: "".into(),
            log_time: sample.available,
            publish_time: sample.valid,
            data,
        };
        let stamp = timestamp(sample.valid);
        if !self.scene.lanes.is_empty() {
            out.push(still("/kpl/roads", ViewSchema::SceneUpdate, encode(&roads(&self.scene, stamp))));
        }
        if !self.scene.occluders.is_empty() {
            out.push(still(
                "/kpl/occluders",
                ViewSchema::SceneUpdate,
                encode(&occluders(&self.scene, stamp)),
            ));
        }
        if self.scene.camera.is_some() && !self.scene.camera_moves() {
            self.camera_messages(sample, out);
        } else if self.scene.camera.is_none()
            && let Some((lo, hi)) = self.scene.bounds
        {
            let centre = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
            out.push(still("/tf", ViewSchema::FrameTransforms, encode(&camera_transform(centre, stamp))));
        }
    }

    /// The camera footprint and the camera's transform at a sample's time.
    fn camera_messages(&self, sample: &Sample, out: &mut Vec<ViewMessage>) {
        let elapsed = sample.valid - self.start.unwrap_or(sample.valid);
        let Some(footprint) = self.scene.footprint_at(elapsed) else { return };
        let stamp = timestamp(sample.valid);
        let message = |topic: &str, schema, data| ViewMessage {
            topic: topic.into(),
            schema,
            stream: "".into(),
            log_time: sample.available,
            publish_time: sample.valid,
            data,
        };
        let centre = centroid(&footprint);
        out.push(message("/kpl/camera", ViewSchema::SceneUpdate, encode(&camera(&footprint, stamp))));
        out.push(message("/tf", ViewSchema::FrameTransforms, encode(&camera_transform(centre, stamp))));
    }
}

/// What a sample says its stream is, when the spec did not.
fn guess_role(value: &Value) -> Option<Role> {
    match value {
        Value::List(items) => {
            let record = items.iter().find_map(Value::as_record)?;
            Some(if record.get("measured").is_some() {
                Role::Objects
            } else if record.get("pos").and_then(vec2).is_some() {
                Role::Points
            } else {
                Role::Nothing
            })
        }
        Value::Record(record) if record.get("verdict").is_some() => Some(Role::Verdicts),
        _ => Some(Role::Nothing),
    }
}

/// The channels of the views in a recording, created as their first message comes.
#[derive(Debug, Default)]
pub struct ViewChannels {
    ids: std::collections::HashMap<Arc<str>, crate::write::StreamId>,
}

impl ViewChannels {
    /// Writes a view's message to its channel (topic), adding the channel first if needed.
    pub fn write(
        &mut self,
        recorder: &mut crate::write::Recorder,
        message: &ViewMessage,
    ) -> Result<(), crate::write::WriteError> {
        let id = match self.ids.get(&message.topic) {
            Some(id) => *id,
            None => {
                let schema = message.schema.schema();
                let shows = if message.stream.is_empty() { "scene" } else { &*message.stream };
                let metadata = BTreeMap::from([(crate::VIEW_KEY.to_string(), shows.to_string())]);
                let id = recorder.add_channel(
                    &message.topic,
                    (&schema.name, &schema.encoding, &schema.data),
                    "protobuf",
                    metadata,
                )?;
                self.ids.insert(message.topic.clone(), id);
                id
            }
        };
        recorder.write_raw(id, message.log_time, message.publish_time, &message.data)
    }
}

fn encode<T: Encode>(message: &T) -> Vec<u8> {
    let mut data = Vec::with_capacity(message.encoded_len().unwrap_or(256));
    // Encoding into a Vec grows it as needed: it cannot fail.
    let _ = message.encode(&mut data);
    data
}

/// A KPL time (microseconds) as Foxglove's timestamp (times before 0 as 0).
pub fn timestamp(t: Time) -> Timestamp {
    let t = t.max(0);
    let sec = u32::try_from(t / 1_000_000).unwrap_or(u32::MAX);
    Timestamp::new(sec, ((t % 1_000_000) * 1000) as u32)
}

/// The colour of a level of anchoring.
pub fn level_colour(level: usize) -> [f64; 3] {
    const PALETTE: [[f64; 3]; 6] = [
        [0.27, 0.55, 0.96],
        [0.98, 0.60, 0.20],
        [0.30, 0.78, 0.40],
        [0.72, 0.42, 0.92],
        [0.94, 0.33, 0.36],
        [0.20, 0.80, 0.80],
    ];
    PALETTE[level % PALETTE.len()]
}

fn colour([r, g, b]: [f64; 3], a: f64) -> Color {
    Color { r, g, b, a }
}

fn point(p: Point, z: f64) -> Point3 {
    Point3 { x: p[0], y: p[1], z }
}

fn yaw(angle: f64) -> Quaternion {
    Quaternion { x: 0.0, y: 0.0, z: (angle / 2.0).sin(), w: (angle / 2.0).cos() }
}

fn pose(p: Point, z: f64, angle: f64) -> Pose {
    Pose { position: Some(Vector3 { x: p[0], y: p[1], z }), orientation: Some(yaw(angle)) }
}

/// A `vec2` value, or a list of two numbers (what untyped JSON gives: a recording read without
/// its spec).
pub fn vec2(value: &Value) -> Option<[f64; 2]> {
    match value {
        Value::Vec2(v) => Some(*v),
        Value::List(items) if items.len() == 2 => Some([items[0].as_f64()?, items[1].as_f64()?]),
        _ => None,
    }
}

fn number(record: &Record, name: &str) -> Option<f64> {
    record.get(name).and_then(Value::as_f64).filter(|v| v.is_finite())
}

/// What a viewer draws of one anchored object.
#[derive(Debug, Clone, PartialEq)]
pub struct Drawn {
    pub symbol: String,
    pub pos: Point,
    pub vel: Point,
    /// Length and width of the box, metres.
    pub length: f64,
    pub width: f64,
    /// Radians from the x axis.
    pub heading: f64,
    pub measured: bool,
    pub branch_of: Option<String>,
    pub likelihood: Option<f64>,
}

impl Drawn {
    /// An object record as drawn (`None` without a position).
    pub fn of(record: &Record, index: usize) -> Option<Drawn> {
        let pos = record.get("pos").and_then(vec2).filter(|p| p.iter().all(|c| c.is_finite()))?;
        let vel = record.get("vel").and_then(vec2).filter(|v| v.iter().all(|c| c.is_finite()));
        let vel = vel.unwrap_or([0.0, 0.0]);
        let size = number(record, "size").filter(|s| *s > 0.0).unwrap_or(4.5).min(50.0);
        let speed = vel[0].hypot(vel[1]);
        let heading =
            number(record, "heading").unwrap_or(if speed > 0.5 { vel[1].atan2(vel[0]) } else { 0.0 });
        let branch_of = record.get("branch_of").and_then(Value::as_str).filter(|s| !s.is_empty());
        Some(Drawn {
            symbol: record.id.as_deref().map_or_else(|| format!("#{index}"), str::to_string),
            pos,
            vel,
            length: size,
            width: (size * 0.42).clamp(0.8, 2.6),
            heading,
            measured: record.get("measured").and_then(Value::as_bool).unwrap_or(true),
            branch_of: branch_of.map(str::to_string),
            likelihood: number(record, "likelihood"),
        })
    }

    /// The label: the symbol, and the object it branched from with its likelihood.
    pub fn label(&self) -> String {
        match (&self.branch_of, self.likelihood) {
            (Some(of), Some(p)) => format!("{} \u{2442} {of} {:.0}%", self.symbol, p * 100.0),
            (Some(of), None) => format!("{} \u{2442} {of}", self.symbol),
            _ => self.symbol.clone(),
        }
    }

    /// The box's corners on the ground.
    pub fn corners(&self) -> [Point; 4] {
        let (c, s) = (self.heading.cos(), self.heading.sin());
        let (l, w) = (self.length / 2.0, self.width / 2.0);
        [[l, w], [-l, w], [-l, -w], [l, -w]]
            .map(|[x, y]| [self.pos[0] + x * c - y * s, self.pos[1] + x * s + y * c])
    }
}

/// The objects of a sample as a scene update: everything of the level's topic replaced.
fn objects(level: usize, sample: &Sample) -> SceneUpdate {
    let stamp = timestamp(sample.valid);
    let rgb = level_colour(level);
    let items: &[Value] = match &sample.value {
        Value::List(items) => items,
        _ => &[],
    };
    let entities = items
        .iter()
        .filter_map(Value::as_record)
        .enumerate()
        .filter_map(|(i, record)| Drawn::of(record, i).map(|d| (record, d)))
        .map(|(record, drawn)| object_entity(record, &drawn, rgb, level, stamp))
        .collect();
    SceneUpdate {
        deletions: vec![SceneEntityDeletion {
            timestamp: Some(stamp),
            r#type: scene_entity_deletion::Type::All as i32,
            id: String::new(),
        }],
        entities,
    }
}

const BOX_HEIGHT_M: f64 = 1.5;

fn object_entity(
    record: &Record,
    drawn: &Drawn,
    rgb: [f64; 3],
    level: usize,
    stamp: Timestamp,
) -> SceneEntity {
    let mut lines = Vec::new();
    let fill = if drawn.measured { 0.85 } else { 0.12 };
    if !drawn.measured || drawn.branch_of.is_some() {
        // Hollow: the outline of the box on the ground (magenta for a branch of a split).
        let outline = if drawn.branch_of.is_some() { [0.95, 0.2, 0.85] } else { rgb };
        lines.push(LinePrimitive {
            r#type: line_primitive::Type::LineLoop as i32,
            pose: None,
            thickness: 0.25,
            scale_invariant: false,
            points: drawn.corners().iter().map(|c| point(*c, 0.05)).collect(),
            color: Some(colour(outline, 1.0)),
            colors: Vec::new(),
            indices: Vec::new(),
        });
    }
    let speed = drawn.vel[0].hypot(drawn.vel[1]);
    let arrows = if speed > 0.1 {
        vec![ArrowPrimitive {
            pose: Some(pose(drawn.pos, BOX_HEIGHT_M + 0.2, drawn.vel[1].atan2(drawn.vel[0]))),
            shaft_length: speed.min(60.0),
            shaft_diameter: 0.25,
            head_length: 1.0,
            head_diameter: 0.8,
            color: Some(colour(rgb, if drawn.measured { 1.0 } else { 0.5 })),
        }]
    } else {
        Vec::new()
    };
    let mut metadata = vec![
        KeyValuePair { key: "level".into(), value: level.to_string() },
        KeyValuePair { key: "measured".into(), value: drawn.measured.to_string() },
    ];
    for name in ["predicted_since", "branch_of", "likelihood", "speed", "lane", "road"] {
        if let Some(value) = record.get(name) {
            let value = match value.to_json() {
                serde_json::Value::String(s) => s,
                other => other.to_string(),
            };
            metadata.push(KeyValuePair { key: name.into(), value });
        }
    }
    SceneEntity {
        timestamp: Some(stamp),
        frame_id: FRAME.into(),
        id: drawn.symbol.clone(),
        lifetime: None,
        frame_locked: false,
        metadata,
        arrows,
        cubes: vec![CubePrimitive {
            pose: Some(pose(drawn.pos, BOX_HEIGHT_M / 2.0, drawn.heading)),
            size: Some(Vector3 { x: drawn.length, y: drawn.width, z: BOX_HEIGHT_M }),
            color: Some(colour(rgb, fill)),
        }],
        spheres: Vec::new(),
        cylinders: Vec::new(),
        lines,
        triangles: Vec::new(),
        texts: vec![TextPrimitive {
            pose: Some(pose(drawn.pos, BOX_HEIGHT_M + 1.5, 0.0)),
            billboard: true,
            font_size: 14.0,
            scale_invariant: true,
            color: Some(colour([1.0, 1.0, 1.0], 1.0)),
            text: drawn.label(),
        }],
        models: Vec::new(),
    }
}

/// The positions of a sample's records as a point cloud (`x`, `y`, `z` as 32-bit floats).
fn points(sample: &Sample) -> PointCloud {
    let items: &[Value] = match &sample.value {
        Value::List(items) => items,
        _ => &[],
    };
    let mut data = Vec::with_capacity(items.len() * 12);
    for pos in items.iter().filter_map(|v| vec2(v.as_record()?.get("pos")?)) {
        for c in [pos[0], pos[1], 0.3] {
            data.extend_from_slice(&(c as f32).to_le_bytes());
        }
    }
    let field = |name: &str, offset| PackedElementField {
        name: name.into(),
        offset,
        r#type: packed_element_field::NumericType::Float32 as i32,
    };
    PointCloud {
        timestamp: Some(timestamp(sample.valid)),
        frame_id: FRAME.into(),
        pose: Some(pose([0.0, 0.0], 0.0, 0.0)),
        point_stride: 12,
        fields: vec![field("x", 0), field("y", 4), field("z", 8)],
        data: data.into(),
    }
}

/// One log message per verdict: an episode (`{x: co3, verdict, start, end}`) or a plain verdict.
fn verdicts(stream: &str, sample: &Sample) -> Vec<Log> {
    let items: Vec<&Value> = match &sample.value {
        Value::List(items) => items.iter().collect(),
        other => vec![other],
    };
    items
        .into_iter()
        .filter_map(|value| {
            let (verdict, text) = describe_verdict(stream, value)?;
            Some(Log {
                timestamp: Some(timestamp(sample.valid)),
                level: if verdict { log::Level::Info } else { log::Level::Debug } as i32,
                message: text,
                name: stream.into(),
                file: String::new(),
                line: 0,
            })
        })
        .collect()
}

/// A verdict's truth and its words (`overtake: a=co7 b=co6 from 26.5 s to 31.0 s`).
pub fn describe_verdict(stream: &str, value: &Value) -> Option<(bool, String)> {
    match value {
        Value::Bool(b) => Some((*b, format!("{stream}: {b}"))),
        Value::Record(record) => {
            let verdict = record.get("verdict").and_then(Value::as_bool)?;
            let bindings: BTreeMap<&str, String> = record
                .fields
                .iter()
                .filter(|(name, _)| !matches!(&**name, "verdict" | "start" | "end"))
                .map(|(name, value)| {
                    let text = value.as_str().map_or_else(|| value.to_json().to_string(), str::to_string);
                    (&**name, text)
                })
                .collect();
            let bindings: Vec<String> = bindings.iter().map(|(k, v)| format!("{k}={v}")).collect();
            let seconds = |name| record.get(name).and_then(Value::as_i64).map(|t| t as f64 / 1e6);
            let when = match (seconds("start"), seconds("end")) {
                (Some(start), Some(end)) => format!(" from {start:.1} s to {end:.1} s"),
                _ => String::new(),
            };
            let truth = if verdict { "" } else { " (false)" };
            Some((verdict, format!("{stream}{truth}: {}{when}", bindings.join(" "))))
        }
        _ => None,
    }
}

fn still_entity(id: &str, stamp: Timestamp) -> SceneEntity {
    SceneEntity {
        timestamp: Some(stamp),
        frame_id: FRAME.into(),
        id: id.into(),
        lifetime: None,
        frame_locked: false,
        metadata: Vec::new(),
        arrows: Vec::new(),
        cubes: Vec::new(),
        spheres: Vec::new(),
        cylinders: Vec::new(),
        lines: Vec::new(),
        triangles: Vec::new(),
        texts: Vec::new(),
        models: Vec::new(),
    }
}

fn line(kind: line_primitive::Type, points: &[Point], z: f64, thickness: f64, rgba: Color) -> LinePrimitive {
    LinePrimitive {
        r#type: kind as i32,
        pose: None,
        thickness,
        scale_invariant: false,
        points: points.iter().map(|p| point(*p, z)).collect(),
        color: Some(rgba),
        colors: Vec::new(),
        indices: Vec::new(),
    }
}

/// The lanes: a band as wide as the lane, and its middle line.
fn roads(scene: &Scene, stamp: Timestamp) -> SceneUpdate {
    let mut entity = still_entity("roads", stamp);
    for lane in &scene.lanes {
        let grey = if lane.connector { 0.30 } else { 0.24 };
        entity.lines.push(line(
            line_primitive::Type::LineStrip,
            &lane.shape,
            0.0,
            lane.width.max(0.5),
            colour([grey, grey, grey + 0.02], 1.0),
        ));
        entity.lines.push(line(
            line_primitive::Type::LineStrip,
            &lane.shape,
            0.02,
            0.12,
            colour([0.55; 3], 1.0),
        ));
    }
    SceneUpdate { deletions: Vec::new(), entities: vec![entity] }
}

/// Occluders: dark translucent polygons two metres up (a bridge over the road) with outlines.
fn occluders(scene: &Scene, stamp: Timestamp) -> SceneUpdate {
    let mut entity = still_entity("occluders", stamp);
    for polygon in scene.occluders.iter().filter(|p| p.len() >= 3) {
        let mut triangles = Vec::new();
        for i in 1..polygon.len() - 1 {
            triangles.extend([point(polygon[0], 2.0), point(polygon[i], 2.0), point(polygon[i + 1], 2.0)]);
        }
        entity.triangles.push(TriangleListPrimitive {
            pose: None,
            points: triangles,
            color: Some(colour([0.12, 0.12, 0.14], 0.55)),
            colors: Vec::new(),
            indices: Vec::new(),
        });
        entity.lines.push(line(line_primitive::Type::LineLoop, polygon, 2.0, 0.3, colour([0.0; 3], 1.0)));
    }
    SceneUpdate { deletions: Vec::new(), entities: vec![entity] }
}

fn camera(footprint: &[Point], stamp: Timestamp) -> SceneUpdate {
    let mut entity = still_entity("footprint", stamp);
    entity.lines.push(line(
        line_primitive::Type::LineLoop,
        footprint,
        0.1,
        0.6,
        colour([1.0, 0.85, 0.1], 1.0),
    ));
    SceneUpdate {
        deletions: vec![SceneEntityDeletion {
            timestamp: Some(stamp),
            r#type: scene_entity_deletion::Type::All as i32,
            id: String::new(),
        }],
        entities: vec![entity],
    }
}

fn camera_transform(centre: Point, stamp: Timestamp) -> FrameTransforms {
    FrameTransforms {
        transforms: vec![FrameTransform {
            timestamp: Some(stamp),
            parent_frame_id: FRAME.into(),
            child_frame_id: CAMERA_FRAME.into(),
            translation: Some(Vector3 { x: centre[0], y: centre[1], z: CAMERA_ALTITUDE_M }),
            rotation: Some(yaw(0.0)),
        }],
    }
}

fn centroid(points: &[Point]) -> Point {
    let n = points.len().max(1) as f64;
    let (x, y) = points.iter().fold((0.0, 0.0), |(x, y), p| (x + p[0], y + p[1]));
    [x / n, y / n]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn car(id: &str, pos: Point, measured: bool, branch_of: &str) -> Value {
        let mut fields: Vec<(Arc<str>, Value)> = vec![
            ("pos".into(), Value::Vec2(pos)),
            ("vel".into(), Value::Vec2([10.0, 0.0])),
            ("size".into(), Value::Float(4.0)),
            ("measured".into(), Value::Bool(measured)),
        ];
        if !branch_of.is_empty() {
            fields.push(("branch_of".into(), Value::str(branch_of)));
            fields.push(("likelihood".into(), Value::Float(0.4)));
        }
        Value::Record(Arc::new(Record { id: Some(id.into()), fields }))
    }

    #[test]
    fn objects_are_boxes_with_symbols_and_arrows_measured_solid_and_predicted_hollow() {
        let mut views = Views::new(Arc::new(Scene::default()));
        let cars = views.add_stream("cars", Role::Objects);
        let value = Value::List(
            vec![
                car("co1", [1.0, 2.0], true, ""),
                car("co2", [5.0, 2.0], false, ""),
                car("co3", [9.0, 2.0], false, "co2"),
            ]
            .into(),
        );
        let mut out = Vec::new();
        views.messages(cars, &Sample::new(2_500_000, 2_600_000, value), &mut out);
        assert_eq!(out.len(), 1, "no scene without a network or camera");
        let message = &out[0];
        assert_eq!((&*message.topic, message.schema), ("/kpl/cars", ViewSchema::SceneUpdate));
        assert_eq!((message.log_time, message.publish_time), (2_600_000, 2_500_000));
        let update = <SceneUpdate as prost::Message>::decode(&message.data[..]).unwrap();
        assert_eq!(update.deletions.len(), 1);
        let ids: Vec<&str> = update.entities.iter().map(|e| e.id.as_str()).collect();
        assert_eq!(ids, ["co1", "co2", "co3"]);
        let measured = &update.entities[0];
        assert_eq!(measured.texts[0].text, "co1");
        assert_eq!(measured.arrows[0].shaft_length, 10.0);
        assert!(measured.lines.is_empty(), "measured: solid");
        assert!(measured.cubes[0].color.unwrap().a > 0.5);
        let predicted = &update.entities[1];
        assert!(predicted.cubes[0].color.unwrap().a < 0.2, "predicted: hollow");
        assert_eq!(predicted.lines.len(), 1);
        let branch = &update.entities[2];
        assert_eq!(branch.texts[0].text, "co3 \u{2442} co2 40%");
        assert_eq!(update.entities[0].timestamp, Some(timestamp(2_500_000)));
    }

    #[test]
    fn episodes_are_log_messages() {
        let episode = Value::Record(Arc::new(Record {
            id: None,
            fields: vec![
                ("a".into(), Value::str("co7")),
                ("b".into(), Value::str("co6")),
                ("end".into(), Value::Int(31_000_000)),
                ("start".into(), Value::Int(26_500_000)),
                ("verdict".into(), Value::Bool(true)),
            ],
        }));
        assert_eq!(
            describe_verdict("overtake", &episode),
            Some((true, "overtake: a=co7 b=co6 from 26.5 s to 31.0 s".into()))
        );
        let mut views = Views::new(Arc::new(Scene::default()));
        let id = views.add_stream("overtake", Role::Unknown);
        let mut out = Vec::new();
        views.messages(id, &Sample::new(31_000_000, 31_100_000, episode), &mut out);
        let log = <Log as prost::Message>::decode(&out[0].data[..]).unwrap();
        assert_eq!(log.level, log::Level::Info as i32);
        assert_eq!(log.name, "overtake");
    }

    #[test]
    fn percepts_are_points_of_three_floats() {
        let mut views = Views::new(Arc::new(Scene::default()));
        let id = views.add_stream("percepts", Role::Points);
        let percept = Value::Record(Arc::new(Record {
            id: Some("vp1".into()),
            fields: vec![("pos".into(), Value::Vec2([3.0, -4.0]))],
        }));
        let mut out = Vec::new();
        views.messages(id, &Sample::new(0, 0, Value::List(vec![percept].into())), &mut out);
        let cloud = <PointCloud as prost::Message>::decode(&out[0].data[..]).unwrap();
        assert_eq!(cloud.point_stride, 12);
        assert_eq!(&cloud.data[..8], [3.0f32.to_le_bytes(), (-4.0f32).to_le_bytes()].concat());
    }

    #[test]
    fn untyped_json_records_are_drawn_as_typed_ones() {
        // A recording read without its spec: positions are lists of two numbers.
        let json = serde_json::json!([{"id": "co1", "pos": [1.5, 2.0], "vel": [0.0, 3.0], "size": 4.0, "measured": false}]);
        let value = Value::from_json_untyped(&json).unwrap();
        assert_eq!(guess_role(&value), Some(Role::Objects));
        let Value::List(items) = &value else { panic!("{value:?}") };
        let drawn = Drawn::of(items[0].as_record().unwrap(), 0).unwrap();
        assert_eq!((drawn.pos, drawn.vel, drawn.measured), ([1.5, 2.0], [0.0, 3.0], false));
        assert!((drawn.heading - std::f64::consts::FRAC_PI_2).abs() < 1e-12, "along the velocity");
    }
}
