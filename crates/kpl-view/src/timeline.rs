//! What the page shows, kept by time: for each stream its frames (the objects of each level, the
//! percepts), the situations recognised, and counters per level. A live run appends to it; a
//! recording is read into it whole. A frame at time `t` is, per stream, its last sample valid at
//! or before `t`.
//!
//! Memory is bounded: each stream keeps at most [`Timeline::FRAMES`] frames and
//! [`Timeline::ITEMS`] objects or points in them (a live run drops the oldest frames and counts
//! them), the situations at most [`Timeline::SITUATIONS`].

use std::collections::{HashMap, VecDeque};
use std::sync::Arc;

use kpl_core::{Time, Value};
use kpl_mcap::foxglove::{Drawn, Role, describe_verdict, level_colour, vec2};
use kpl_mcap::scene::{Point, Scene};
use kpl_runtime::Sample;
use serde::Serialize;

/// One object as the page draws it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Object {
    pub id: String,
    pub x: f64,
    pub y: f64,
    pub vx: f64,
    pub vy: f64,
    pub length: f64,
    pub width: f64,
    pub heading: f64,
    pub measured: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub branch_of: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub likelihood: Option<f64>,
    pub label: String,
}

impl From<Drawn> for Object {
    fn from(d: Drawn) -> Object {
        Object {
            label: d.label(),
            id: d.symbol,
            x: d.pos[0],
            y: d.pos[1],
            vx: d.vel[0],
            vy: d.vel[1],
            length: d.length,
            width: d.width,
            heading: d.heading,
            measured: d.measured,
            branch_of: d.branch_of,
            likelihood: d.likelihood,
        }
    }
}

/// Counters of one level at one frame: what it holds then, and what happened up to then.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct Counters {
    pub objects: u64,
    pub measured: u64,
    pub predicted: u64,
    pub branches: u64,
    /// Symbols seen so far (objects this level has made).
    pub symbols: u64,
    /// Gaps bridged: an object measured again after being only predicted, its symbol kept.
    pub gaps: u64,
    /// Samples of the stream so far.
    pub samples: u64,
}

#[derive(Debug, Clone)]
enum Content {
    Objects(Arc<Vec<Object>>, Counters),
    Points(Arc<Vec<Point>>),
}

#[derive(Debug, Clone)]
struct Frame {
    valid: Time,
    content: Content,
}

impl Frame {
    fn items(&self) -> usize {
        match &self.content {
            Content::Objects(objects, _) => objects.len(),
            Content::Points(points) => points.len(),
        }
    }
}

#[derive(Debug)]
struct Track {
    name: String,
    role: Role,
    level: usize,
    frames: VecDeque<Frame>,
    /// Objects or points in `frames`.
    items: usize,
    /// Frames dropped to keep the bound.
    dropped: u64,
    /// Per symbol: whether it was measured in its last frame (for `gaps`).
    last_measured: HashMap<String, bool>,
    totals: Counters,
}

/// A recognised situation (a `true` episode of a monitor) or a plain `true` verdict.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Situation {
    pub monitor: String,
    pub text: String,
    /// The objects it is about (`a: co7`), when it has bindings.
    pub objects: Vec<(String, String)>,
    pub start: Time,
    pub end: Time,
    /// When it was recognised.
    pub available: Time,
}

/// The timeline of a run or recording.
#[derive(Debug)]
pub struct Timeline {
    scene: Arc<Scene>,
    tracks: Vec<Track>,
    levels: usize,
    situations: VecDeque<Situation>,
    /// Episodes that were not situations (`false` verdicts), counted.
    other_verdicts: u64,
    dropped_situations: u64,
    first: Option<Time>,
    last: Option<Time>,
    /// A live run that has not ended.
    pub running: bool,
    pub live: bool,
    /// Shown as the page's title (the spec or recording).
    pub title: String,
}

/// A stream's place in a [`Timeline`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TrackId(usize);

impl Timeline {
    /// Frames a stream keeps at most (50 minutes at 10 Hz).
    pub const FRAMES: usize = 30_000;
    /// Objects or points a stream keeps at most in its frames (some 250 MB).
    pub const ITEMS: usize = 2_000_000;
    /// Situations kept at most.
    pub const SITUATIONS: usize = 100_000;
    /// Symbols a level remembers for its counters at most.
    const SYMBOLS: usize = 1_000_000;

    pub fn new(scene: Arc<Scene>, title: &str, live: bool) -> Timeline {
        Timeline {
            scene,
            tracks: Vec::new(),
            levels: 0,
            situations: VecDeque::new(),
            other_verdicts: 0,
            dropped_situations: 0,
            first: None,
            last: None,
            running: live,
            live,
            title: title.to_string(),
        }
    }

    pub fn scene(&self) -> &Arc<Scene> {
        &self.scene
    }

    /// Adds a stream, drawn as `role` says (`Role::Unknown`: as its first telling sample says).
    pub fn add_stream(&mut self, name: &str, role: Role) -> TrackId {
        let mut track = Track {
            name: name.to_string(),
            role: Role::Unknown,
            level: 0,
            frames: VecDeque::new(),
            items: 0,
            dropped: 0,
            last_measured: HashMap::new(),
            totals: Counters::default(),
        };
        (track.role, track.level) = (role, self.level_for(role));
        self.tracks.push(track);
        TrackId(self.tracks.len() - 1)
    }

    /// The level of a new stream of objects (the next one); 0 for other roles.
    fn level_for(&mut self, role: Role) -> usize {
        if role != Role::Objects {
            return 0;
        }
        self.levels += 1;
        self.levels - 1
    }

    /// The stream of that name, added as `role` if it is new.
    pub fn stream(&mut self, name: &str, role: Role) -> TrackId {
        match self.tracks.iter().position(|t| t.name == name) {
            Some(i) => TrackId(i),
            None => self.add_stream(name, role),
        }
    }

    /// Takes one sample of a stream.
    pub fn push(&mut self, id: TrackId, sample: &Sample) {
        let Some(role) = self.tracks.get(id.0).map(|t| t.role) else { return };
        if role == Role::Unknown {
            let Some(role) = guess(&sample.value) else { return };
            let level = self.level_for(role);
            let track = &mut self.tracks[id.0];
            (track.role, track.level) = (role, level);
        }
        self.first = Some(self.first.map_or(sample.valid, |t| t.min(sample.valid)));
        self.last = Some(self.last.map_or(sample.valid, |t| t.max(sample.valid)));
        let track = &mut self.tracks[id.0];
        let items: &[Value] = match &sample.value {
            Value::List(items) => items,
            other => std::slice::from_ref(other),
        };
        match track.role {
            Role::Objects => {
                let objects: Vec<Object> = items
                    .iter()
                    .filter_map(Value::as_record)
                    .enumerate()
                    .filter_map(|(i, r)| Drawn::of(r, i))
                    .map(Object::from)
                    .collect();
                let counters = track.count(&objects);
                track.keep(Frame {
                    valid: sample.valid,
                    content: Content::Objects(Arc::new(objects), counters),
                });
            }
            Role::Points => {
                let points: Vec<Point> =
                    items.iter().filter_map(|v| vec2(v.as_record()?.get("pos")?)).collect();
                track.totals.samples += 1;
                track.keep(Frame { valid: sample.valid, content: Content::Points(Arc::new(points)) });
            }
            Role::Verdicts => {
                track.totals.samples += 1;
                let name = track.name.clone();
                for value in items {
                    self.verdict(&name, value, sample);
                }
            }
            Role::Unknown | Role::Nothing => {}
        }
    }

    fn verdict(&mut self, monitor: &str, value: &Value, sample: &Sample) {
        let Some((true, text)) = describe_verdict(monitor, value) else {
            self.other_verdicts += 1;
            return;
        };
        let record = value.as_record();
        let time = |name| record.and_then(|r| r.get(name)).and_then(Value::as_i64);
        let objects = record
            .map(|r| {
                r.fields
                    .iter()
                    .filter(|(n, _)| !matches!(&**n, "verdict" | "start" | "end"))
                    .filter_map(|(n, v)| Some((n.to_string(), v.as_str()?.to_string())))
                    .collect()
            })
            .unwrap_or_default();
        if self.situations.len() >= Timeline::SITUATIONS {
            self.situations.pop_front();
            self.dropped_situations += 1;
        }
        self.situations.push_back(Situation {
            monitor: monitor.to_string(),
            text,
            objects,
            start: time("start").unwrap_or(sample.valid),
            end: time("end").unwrap_or(sample.valid),
            available: sample.available,
        });
    }

    /// The first and last valid times seen.
    pub fn span(&self) -> Option<(Time, Time)> {
        Some((self.first?, self.last?))
    }

    pub fn situations(&self) -> impl Iterator<Item = &Situation> {
        self.situations.iter()
    }

    /// The frame at `t` (the latest when `None`): per stream its last sample valid at or before.
    pub fn frame(&self, t: Option<Time>) -> FrameView {
        let t = t.or(self.last).unwrap_or(0);
        let mut view = FrameView { t, levels: Vec::new(), points: Vec::new(), footprint: None };
        for track in &self.tracks {
            let index = track.frames.partition_point(|f| f.valid <= t);
            let frame = index.checked_sub(1).and_then(|i| track.frames.get(i));
            match (track.role, frame.map(|f| &f.content)) {
                (Role::Objects, content) => {
                    let (objects, counters) = match content {
                        Some(Content::Objects(objects, counters)) => (objects.clone(), counters.clone()),
                        _ => (Arc::default(), Counters::default()),
                    };
                    let [r, g, b] = level_colour(track.level);
                    view.levels.push(LevelView {
                        stream: track.name.clone(),
                        level: track.level,
                        colour: format!(
                            "rgb({},{},{})",
                            (r * 255.0) as u8,
                            (g * 255.0) as u8,
                            (b * 255.0) as u8
                        ),
                        valid: frame.map(|f| f.valid),
                        objects,
                        counters,
                        dropped_frames: track.dropped,
                    });
                }
                (Role::Points, Some(Content::Points(points))) => {
                    view.points.push(PointsView { stream: track.name.clone(), points: points.clone() });
                }
                _ => {}
            }
        }
        view.levels.sort_by_key(|l| l.level);
        let elapsed = t - self.first.unwrap_or(t);
        view.footprint = self.scene.footprint_at(elapsed);
        view
    }

    /// What the page needs to know first: the mode, the time span, the levels.
    pub fn state(&self) -> State {
        State {
            title: self.title.clone(),
            live: self.live,
            running: self.running,
            start: self.first,
            end: self.last,
            situations: self.situations.len() as u64,
            other_verdicts: self.other_verdicts,
            dropped_situations: self.dropped_situations,
            streams: self
                .tracks
                .iter()
                .map(|t| StreamState {
                    stream: t.name.clone(),
                    role: role_name(t.role),
                    samples: t.totals.samples,
                    frames: t.frames.len() as u64,
                    dropped_frames: t.dropped,
                })
                .collect(),
        }
    }
}

fn role_name(role: Role) -> &'static str {
    match role {
        Role::Objects => "objects",
        Role::Points => "points",
        Role::Verdicts => "verdicts",
        Role::Unknown => "unknown",
        Role::Nothing => "nothing",
    }
}

impl Track {
    fn keep(&mut self, frame: Frame) {
        self.items += frame.items();
        self.frames.push_back(frame);
        while self.frames.len() > Timeline::FRAMES || (self.items > Timeline::ITEMS && self.frames.len() > 1)
        {
            let Some(old) = self.frames.pop_front() else { break };
            self.items -= old.items();
            self.dropped += 1;
        }
    }

    /// Counts a frame of objects into the totals, and returns the counters as of this frame.
    fn count(&mut self, objects: &[Object]) -> Counters {
        let totals = &mut self.totals;
        totals.samples += 1;
        for object in objects {
            match self.last_measured.get_mut(&object.id) {
                Some(was) => {
                    if object.measured && !*was {
                        totals.gaps += 1;
                    }
                    *was = object.measured;
                }
                None => {
                    totals.symbols += 1;
                    if self.last_measured.len() < Timeline::SYMBOLS {
                        self.last_measured.insert(object.id.clone(), object.measured);
                    }
                }
            }
        }
        let measured = objects.iter().filter(|o| o.measured).count() as u64;
        Counters {
            objects: objects.len() as u64,
            measured,
            predicted: objects.len() as u64 - measured,
            branches: objects.iter().filter(|o| o.branch_of.is_some()).count() as u64,
            ..totals.clone()
        }
    }
}

fn guess(value: &Value) -> Option<Role> {
    match value {
        Value::List(items) => {
            let record = items.iter().find_map(Value::as_record)?;
            Some(if record.get("measured").is_some() {
                Role::Objects
            } else if record.get("pos").is_some() {
                Role::Points
            } else {
                Role::Nothing
            })
        }
        Value::Record(r) if r.get("verdict").is_some() => Some(Role::Verdicts),
        _ => Some(Role::Nothing),
    }
}

/// One level's objects in a frame.
#[derive(Debug, Clone, Serialize)]
pub struct LevelView {
    pub stream: String,
    pub level: usize,
    pub colour: String,
    /// The valid time of the sample shown (`None`: nothing yet).
    pub valid: Option<Time>,
    pub objects: Arc<Vec<Object>>,
    pub counters: Counters,
    pub dropped_frames: u64,
}

#[derive(Debug, Clone, Serialize)]
pub struct PointsView {
    pub stream: String,
    pub points: Arc<Vec<Point>>,
}

/// What the page draws at one time.
#[derive(Debug, Clone, Serialize)]
pub struct FrameView {
    pub t: Time,
    pub levels: Vec<LevelView>,
    pub points: Vec<PointsView>,
    pub footprint: Option<Vec<Point>>,
}

#[derive(Debug, Clone, Serialize)]
pub struct StreamState {
    pub stream: String,
    pub role: &'static str,
    pub samples: u64,
    pub frames: u64,
    pub dropped_frames: u64,
}

#[derive(Debug, Clone, Serialize)]
pub struct State {
    pub title: String,
    pub live: bool,
    pub running: bool,
    pub start: Option<Time>,
    pub end: Option<Time>,
    pub situations: u64,
    pub other_verdicts: u64,
    pub dropped_situations: u64,
    pub streams: Vec<StreamState>,
}

#[cfg(test)]
mod tests {
    use kpl_core::Record;

    use super::*;

    fn cars(list: &[(&str, bool)]) -> Value {
        let items: Vec<Value> = list
            .iter()
            .map(|(id, measured)| {
                Value::Record(Arc::new(Record {
                    id: Some((*id).into()),
                    fields: vec![
                        ("pos".into(), Value::Vec2([1.0, 2.0])),
                        ("measured".into(), Value::Bool(*measured)),
                    ],
                }))
            })
            .collect();
        Value::List(items.into())
    }

    #[test]
    fn a_frame_is_each_streams_last_sample_at_or_before_its_time_with_counters_as_of_then() {
        let mut timeline = Timeline::new(Arc::new(Scene::default()), "t", true);
        let id = timeline.add_stream("cars", Role::Objects);
        timeline.push(id, &Sample::new(0, 0, cars(&[("co1", true)])));
        timeline.push(id, &Sample::new(100, 100, cars(&[("co1", false), ("co2", true)])));
        timeline.push(id, &Sample::new(200, 200, cars(&[("co1", true), ("co2", true)])));
        let at = |t| timeline.frame(Some(t)).levels[0].clone();
        assert_eq!(at(50).valid, Some(0));
        assert_eq!(at(50).objects.len(), 1);
        let middle = at(150);
        assert_eq!((middle.valid, middle.counters.objects, middle.counters.predicted), (Some(100), 2, 1));
        assert_eq!((middle.counters.symbols, middle.counters.gaps), (2, 0));
        let last = timeline.frame(None).levels[0].clone();
        assert_eq!(
            (last.valid, last.counters.gaps, last.counters.samples),
            (Some(200), 1, 3),
            "co1 came back"
        );
        assert!(timeline.frame(Some(-1)).levels[0].objects.is_empty(), "nothing before the first sample");
    }
}
