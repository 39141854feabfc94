//! Reading recorded runs: the JSON lines that `file.jsonl` sinks write (docs/streams.md), from
//! files or a run's output folder, into object streams.
//!
//! An **object stream** carries one snapshot per valid time: a list of records with an `id` and a
//! `pos` (`[x, y]`, metres): the tracker's percepts and its `truth`, the outputs of link processes.
//! A **world model** stream (`anchor.world_model`: records with `type` and `state.pos`) is split
//! into one object stream per type, named `STREAM[TYPE]`. Other streams (change records,
//! monitors, numbers) are listed but not scored. Besides `id` and `pos`, a record's `measured`
//! and `branch_of` (a branch object of a prediction split at a junction) are read.
//!
//! Bad lines and records are counted with `FILE:LINE: what is wrong` and left out; reading goes
//! on. Lines are limited to [`MAX_LINE_BYTES`] and folders to [`MAX_DEPTH`] levels, so a file
//! that is no recording (`/dev/zero`) ends in an error instead of filling the memory.

use std::collections::{BTreeMap, HashSet};
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use kpl_core::Time;
use serde_json::Value as Json;

use crate::error::{ReadError, SelectError};
use crate::sequence::Pos;
use crate::time::seconds;

/// The longest line read.
pub const MAX_LINE_BYTES: usize = 64 << 20;
/// The deepest folder nesting searched for recordings.
pub const MAX_DEPTH: usize = 16;
/// Problems kept as examples (all are counted).
const MAX_EXAMPLES: usize = 8;

/// One object of a snapshot.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedObject {
    pub id: String,
    pub pos: Pos,
    /// The record's `measured` field, when it has one.
    pub measured: Option<bool>,
    /// The record's `branch_of` field: the object is a branch object, one of the other
    /// hypotheses of the prediction of the object named (docs/anchoring.md).
    pub branch_of: Option<String>,
}

/// The objects of a stream at one valid time.
#[derive(Debug, Clone, PartialEq)]
pub struct Snapshot {
    pub time: Time,
    /// Where it was read (1-based).
    pub line: usize,
    pub objects: Vec<RecordedObject>,
}

/// A recorded object stream: its snapshots in increasing valid time.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectStream {
    pub name: String,
    /// The file it was read from.
    pub file: PathBuf,
    pub snapshots: Vec<Snapshot>,
    /// Some record says whether its state was measured (`measured`).
    pub has_measured: bool,
    /// Some record says which percept sees it (`seen_as`: the tracker's ground truth).
    pub has_seen_as: bool,
}

/// Lines or records that were left out, with the first few as `FILE:LINE: what`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Problems {
    pub count: usize,
    pub examples: Vec<String>,
}

impl Problems {
    fn add(&mut self, path: &Path, line: usize, what: impl std::fmt::Display) {
        self.count += 1;
        if self.examples.len() < MAX_EXAMPLES {
            self.examples.push(format!("{}:{line}: {what}", path.display()));
        }
    }
}

/// What a stream's values look like.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    /// Only empty lists so far.
    Undecided,
    Objects,
    WorldModel,
    Other,
}

/// A stream while it is read.
#[derive(Debug)]
struct Reading {
    file: PathBuf,
    kind: Kind,
    samples: usize,
    /// Snapshots of an object stream, or of each type of a world model.
    snapshots: BTreeMap<String, Vec<Snapshot>>,
    /// Valid times and lines of a world model's (or an undecided stream's) samples.
    times: Vec<(Time, usize)>,
    has_measured: bool,
    has_seen_as: bool,
}

/// Everything read from a run's recordings.
#[derive(Debug, Clone, Default)]
pub struct Recording {
    files: Vec<PathBuf>,
    streams: BTreeMap<String, ObjectStream>,
    /// Streams that are not object streams, with their sample counts.
    others: BTreeMap<String, usize>,
    problems: Problems,
    notes: Vec<String>,
}

impl Recording {
    /// Reads files and folders (every `*.jsonl` below a folder, in name order).
    pub fn read(paths: &[PathBuf]) -> Result<Recording, ReadError> {
        if paths.is_empty() {
            return Err(ReadError::NoPaths);
        }
        let mut files = Vec::new();
        for path in paths {
            let meta =
                std::fs::metadata(path).map_err(|source| ReadError::Io { path: path.clone(), source })?;
            if meta.is_dir() {
                let before = files.len();
                collect(path, 0, &mut files)?;
                if files.len() == before {
                    return Err(ReadError::EmptyFolder { path: path.clone() });
                }
            } else if meta.is_file() || is_pipe(&meta) {
                files.push(path.clone());
            } else {
                return Err(ReadError::NotAFile { path: path.clone() });
            }
        }
        // A file named twice (a folder and a file in it) is read once.
        let mut seen = HashSet::new();
        files.retain(|f| seen.insert(std::fs::canonicalize(f).unwrap_or_else(|_| f.clone())));
        let mut reader = RecordingReader::default();
        for file in &files {
            let f =
                std::fs::File::open(file).map_err(|source| ReadError::Io { path: file.clone(), source })?;
            reader.read(file, BufReader::new(f))?;
        }
        Ok(reader.finish(files))
    }

    /// Reads one recording from any reader (`path` names it in messages).
    pub fn read_from(path: &Path, reader: impl Read) -> Result<Recording, ReadError> {
        let mut r = RecordingReader::default();
        r.read(path, BufReader::new(reader))?;
        Ok(r.finish(vec![path.to_path_buf()]))
    }

    /// The files read.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// The object streams, by name.
    pub fn streams(&self) -> impl Iterator<Item = &ObjectStream> {
        self.streams.values()
    }

    pub fn stream(&self, name: &str) -> Option<&ObjectStream> {
        self.streams.get(name)
    }

    /// The streams that are not object streams, with their sample counts.
    pub fn other_streams(&self) -> &BTreeMap<String, usize> {
        &self.others
    }

    /// Lines and records left out.
    pub fn problems(&self) -> &Problems {
        &self.problems
    }

    /// Things the reader decided that a user should know (a stream in several files).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// The ground-truth stream: `name`, or else the one stream called `truth` or `*.truth`, or
    /// else the one whose records have `seen_as`.
    pub fn truth(&self, name: Option<&str>) -> Result<&ObjectStream, SelectError> {
        if let Some(name) = name {
            return self.named(name);
        }
        let by_name: Vec<&ObjectStream> =
            self.streams().filter(|s| s.name == "truth" || s.name.ends_with(".truth")).collect();
        let candidates =
            if by_name.is_empty() { self.streams().filter(|s| s.has_seen_as).collect() } else { by_name };
        match candidates.as_slice() {
            [one] => Ok(one),
            [] => Err(SelectError::NoTruth { object_streams: self.streams.keys().cloned().collect() }),
            many => {
                Err(SelectError::AmbiguousTruth { candidates: many.iter().map(|s| s.name.clone()).collect() })
            }
        }
    }

    /// The streams to score against `truth`: the named ones (a world model's name stands for all
    /// its types), or every object stream but the truth.
    pub fn hypotheses(&self, names: &[String], truth: &str) -> Result<Vec<&ObjectStream>, SelectError> {
        if names.is_empty() {
            let all: Vec<&ObjectStream> = self.streams().filter(|s| s.name != truth).collect();
            if all.is_empty() {
                return Err(SelectError::NothingToScore {
                    truth: truth.to_string(),
                    others: self.others.keys().cloned().collect(),
                });
            }
            return Ok(all);
        }
        let mut chosen: Vec<&ObjectStream> = Vec::new();
        for name in names {
            let prefix = format!("{name}[");
            let parts: Vec<&ObjectStream> = self.streams().filter(|s| s.name.starts_with(&prefix)).collect();
            if parts.is_empty() {
                chosen.push(self.named(name)?);
            } else {
                chosen.extend(parts);
            }
        }
        let mut seen = HashSet::new();
        chosen.retain(|s| seen.insert(s.name.clone()));
        Ok(chosen)
    }

    fn named(&self, name: &str) -> Result<&ObjectStream, SelectError> {
        if let Some(s) = self.streams.get(name) {
            return Ok(s);
        }
        if self.others.contains_key(name) {
            return Err(SelectError::NotObjects { name: name.to_string() });
        }
        let known: Vec<&str> = self.streams.keys().chain(self.others.keys()).map(String::as_str).collect();
        Err(SelectError::UnknownStream {
            name: name.to_string(),
            suggestion: kpl_core::closest(name, &known).map(str::to_string),
            known: self.streams.keys().cloned().collect(),
        })
    }
}

/// A named pipe (`kpl score <(...)`): read like a file.
#[cfg(unix)]
fn is_pipe(meta: &std::fs::Metadata) -> bool {
    std::os::unix::fs::FileTypeExt::is_fifo(&meta.file_type())
}

#[cfg(not(unix))]
fn is_pipe(_: &std::fs::Metadata) -> bool {
    false
}

/// Every `*.jsonl` below `dir`, in name order.
fn collect(dir: &Path, depth: usize, files: &mut Vec<PathBuf>) -> Result<(), ReadError> {
    if depth > MAX_DEPTH {
        return Err(ReadError::TooDeep { path: dir.to_path_buf() });
    }
    let io = |source| ReadError::Io { path: dir.to_path_buf(), source };
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(io)?
        .map(|e| e.map(|e| e.path()))
        .collect::<Result<_, _>>()
        .map_err(|source| ReadError::Io { path: dir.to_path_buf(), source })?;
    entries.sort();
    for path in entries {
        if path.is_dir() {
            collect(&path, depth + 1, files)?;
        } else if path.extension().is_some_and(|e| e == "jsonl") {
            files.push(path);
        }
    }
    Ok(())
}

#[derive(Debug, Default)]
struct RecordingReader {
    streams: BTreeMap<String, Reading>,
    problems: Problems,
    /// Streams met in a second file: (stream, file), reported once each.
    elsewhere: BTreeMap<(String, PathBuf), usize>,
}

impl RecordingReader {
    fn read(&mut self, path: &Path, mut reader: impl BufRead) -> Result<(), ReadError> {
        let mut buf = Vec::new();
        let mut line = 0;
        loop {
            buf.clear();
            let n = (&mut reader)
                .take(MAX_LINE_BYTES as u64 + 1)
                .read_until(b'\n', &mut buf)
                .map_err(|source| ReadError::Io { path: path.to_path_buf(), source })?;
            if n == 0 {
                return Ok(());
            }
            line += 1;
            if buf.len() > MAX_LINE_BYTES {
                return Err(ReadError::LineTooLong { path: path.to_path_buf(), line });
            }
            if buf.iter().all(u8::is_ascii_whitespace) {
                continue;
            }
            self.line(path, line, &buf);
        }
    }

    fn line(&mut self, path: &Path, line: usize, bytes: &[u8]) {
        let json: Json = match serde_json::from_slice(bytes) {
            Ok(j) => j,
            Err(e) => return self.problems.add(path, line, format_args!("not JSON: {e}")),
        };
        let (Some(stream), Some(valid), Some(value)) =
            (json.get("stream").and_then(Json::as_str), json.get("valid"), json.get("value"))
        else {
            return self.problems.add(
                path,
                line,
                "not a sample (an object with `stream`, `valid` and `value`)",
            );
        };
        let Some(time) = valid.as_i64() else {
            return self.problems.add(path, line, "`valid` is not an integer number of microseconds");
        };
        let reading = self.streams.entry(stream.to_string()).or_insert_with(|| Reading {
            file: path.to_path_buf(),
            kind: Kind::Undecided,
            samples: 0,
            snapshots: BTreeMap::new(),
            times: Vec::new(),
            has_measured: false,
            has_seen_as: false,
        });
        if reading.file != path {
            *self.elsewhere.entry((stream.to_string(), path.to_path_buf())).or_default() += 1;
            return;
        }
        reading.samples += 1;
        let Some(items) = value.as_array() else {
            if matches!(reading.kind, Kind::Objects | Kind::WorldModel) {
                self.problems.add(path, line, format_args!("`{stream}`: the value is not a list of objects"));
            } else {
                reading.kind = Kind::Other;
            }
            return;
        };
        if reading.kind == Kind::Undecided
            && let Some(first) = items.first()
        {
            reading.kind = if first.get("pos").is_some() {
                Kind::Objects
            } else if first.get("type").is_some() && first.get("status").is_some() {
                Kind::WorldModel
            } else {
                Kind::Other
            };
            if reading.kind == Kind::Objects {
                // The empty snapshots seen so far belong to it.
                let empty =
                    reading.times.drain(..).map(|(time, line)| Snapshot { time, line, objects: Vec::new() });
                reading.snapshots.entry(stream.to_string()).or_default().extend(empty);
            }
        }
        match reading.kind {
            Kind::Other => {}
            Kind::Undecided | Kind::WorldModel => {
                reading.times.push((time, line));
                if reading.kind == Kind::WorldModel {
                    world_model(stream, reading, &mut self.problems, path, line, time, items);
                }
            }
            Kind::Objects => {
                let objects = objects(stream, reading, &mut self.problems, path, line, items.iter());
                reading.snapshots.entry(stream.to_string()).or_default().push(Snapshot {
                    time,
                    line,
                    objects,
                });
            }
        }
    }

    fn finish(mut self, files: Vec<PathBuf>) -> Recording {
        let mut recording = Recording { files, ..Recording::default() };
        for ((stream, file), lines) in &self.elsewhere {
            let first = self.streams.get(stream).map(|r| r.file.display().to_string()).unwrap_or_default();
            recording.notes.push(format!(
                "`{stream}` is also recorded in {} ({lines} lines); scored from {first}",
                file.display()
            ));
        }
        for (name, mut reading) in std::mem::take(&mut self.streams) {
            match reading.kind {
                Kind::Other => {
                    recording.others.insert(name, reading.samples);
                }
                Kind::Undecided => {
                    // Only empty lists: an object stream that never had an object.
                    let snapshots = reading.times.iter().map(|&(time, line)| Snapshot {
                        time,
                        line,
                        objects: Vec::new(),
                    });
                    let snapshots = ordered(&name, &reading.file, snapshots.collect(), &mut self.problems);
                    recording.streams.insert(name.clone(), stream(name, &reading, snapshots));
                }
                Kind::Objects => {
                    let snapshots = reading.snapshots.remove(&name).unwrap_or_default();
                    let snapshots = ordered(&name, &reading.file, snapshots, &mut self.problems);
                    recording.streams.insert(name.clone(), stream(name, &reading, snapshots));
                }
                Kind::WorldModel => {
                    // Every type gets a snapshot at every time of the world model.
                    for (sub, per_type) in std::mem::take(&mut reading.snapshots) {
                        let mut by_line: BTreeMap<usize, Snapshot> =
                            per_type.into_iter().map(|s| (s.line, s)).collect();
                        let all = reading
                            .times
                            .iter()
                            .map(|&(time, line)| {
                                by_line.remove(&line).unwrap_or(Snapshot { time, line, objects: Vec::new() })
                            })
                            .collect();
                        let snapshots = ordered(&sub, &reading.file, all, &mut self.problems);
                        recording.streams.insert(sub.clone(), stream(sub, &reading, snapshots));
                    }
                }
            }
        }
        recording.problems = self.problems;
        recording
    }
}

fn stream(name: String, reading: &Reading, snapshots: Vec<Snapshot>) -> ObjectStream {
    ObjectStream {
        name,
        file: reading.file.clone(),
        snapshots,
        has_measured: reading.has_measured,
        has_seen_as: reading.has_seen_as,
    }
}

/// Sorts snapshots by valid time; of two at one time the later line is kept (a problem).
fn ordered(name: &str, file: &Path, mut snapshots: Vec<Snapshot>, problems: &mut Problems) -> Vec<Snapshot> {
    snapshots.sort_by_key(|s| (s.time, s.line));
    let mut out: Vec<Snapshot> = Vec::with_capacity(snapshots.len());
    for s in snapshots {
        if let Some(last) = out.last_mut()
            && last.time == s.time
        {
            problems.add(
                file,
                s.line,
                format_args!(
                    "a second sample of `{name}` at {} (line {}); the later one is scored",
                    seconds(s.time),
                    last.line
                ),
            );
            *last = s;
            continue;
        }
        out.push(s);
    }
    out
}

/// The objects of one snapshot of a plain object stream.
fn objects<'a>(
    stream: &str,
    reading: &mut Reading,
    problems: &mut Problems,
    path: &Path,
    line: usize,
    items: impl Iterator<Item = &'a Json>,
) -> Vec<RecordedObject> {
    let mut out: Vec<RecordedObject> = Vec::new();
    let mut ids = HashSet::new();
    for (k, item) in items.enumerate() {
        reading.has_seen_as |= item.get("seen_as").is_some();
        match object(item, item.get("pos")) {
            Ok(object) => {
                reading.has_measured |= object.measured.is_some();
                if ids.insert(object.id.clone()) {
                    out.push(object);
                } else {
                    problems.add(
                        path,
                        line,
                        format_args!("`{stream}` lists `{}` twice; the first is scored", object.id),
                    );
                }
            }
            Err(what) => problems.add(path, line, format_args!("`{stream}`, object {k}: {what}")),
        }
    }
    out
}

/// Splits one world-model sample by type.
fn world_model(
    stream: &str,
    reading: &mut Reading,
    problems: &mut Problems,
    path: &Path,
    line: usize,
    time: Time,
    items: &[Json],
) {
    let mut by_type: BTreeMap<String, Vec<RecordedObject>> = BTreeMap::new();
    for (k, item) in items.iter().enumerate() {
        let Some(ty) = item.get("type").and_then(Json::as_str) else {
            problems.add(path, line, format_args!("`{stream}`, object {k}: no `type`"));
            continue;
        };
        let objects = by_type.entry(ty.to_string()).or_default();
        // Partial objects (of identifications) have no state yet.
        let Some(pos) = item.get("state").and_then(|s| s.get("pos")) else { continue };
        match object(item, Some(pos)) {
            Ok(object) => {
                reading.has_measured |= object.measured.is_some();
                if objects.iter().any(|o| o.id == object.id) {
                    problems.add(
                        path,
                        line,
                        format_args!("`{stream}` lists `{}` twice; the first is scored", object.id),
                    );
                } else {
                    objects.push(object);
                }
            }
            Err(what) => problems.add(path, line, format_args!("`{stream}`, object {k}: {what}")),
        }
    }
    for (ty, objects) in by_type {
        reading.snapshots.entry(format!("{stream}[{ty}]")).or_default().push(Snapshot {
            time,
            line,
            objects,
        });
    }
}

/// A record as an object: `id` (a string or an integer), `pos`, an optional `measured` and an
/// optional `branch_of`.
fn object(item: &Json, pos: Option<&Json>) -> Result<RecordedObject, String> {
    let id = match item.get("id") {
        Some(Json::String(s)) => s.clone(),
        Some(Json::Number(n)) if n.is_i64() || n.is_u64() => n.to_string(),
        Some(other) => return Err(format!("`id` is {other}, not a string")),
        None => return Err("no `id`".to_string()),
    };
    let pos = match pos {
        None => return Err(format!("`{id}` has no `pos`")),
        Some(Json::Array(xy)) if xy.len() == 2 => match (xy[0].as_f64(), xy[1].as_f64()) {
            (Some(x), Some(y)) if x.is_finite() && y.is_finite() => [x, y],
            _ => return Err(format!("`{id}`: `pos` is not two finite numbers")),
        },
        Some(other) => return Err(format!("`{id}`: `pos` is {other}, not [x, y]")),
    };
    let measured = match item.get("measured") {
        None => None,
        Some(Json::Bool(b)) => Some(*b),
        Some(other) => return Err(format!("`{id}`: `measured` is {other}, not true or false")),
    };
    let branch_of = match item.get("branch_of") {
        None => None,
        Some(Json::String(owner)) => Some(owner.clone()),
        Some(other) => return Err(format!("`{id}`: `branch_of` is {other}, not a symbol")),
    };
    Ok(RecordedObject { id, pos, measured, branch_of })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> Recording {
        Recording::read_from(Path::new("rec.jsonl"), text.as_bytes()).unwrap()
    }

    #[test]
    fn object_streams_world_models_and_others() {
        let rec = read(concat!(
            r#"{"stream":"cars","valid":0,"value":[]}"#,
            "\n",
            r#"{"stream":"tracker.truth","valid":0,"value":[{"id":"car1","pos":[1.0,2.0],"seen_as":"vp1"}]}"#,
            "\n",
            r#"{"stream":"cars","valid":100000,"value":[{"id":"co1","pos":[1.5,2.0]}]}"#,
            "\n",
            r#"{"stream":"cars.changes","valid":100000,"value":[{"kind":"created","symbol":"co1"}]}"#,
            "\n",
            r#"{"stream":"world","valid":100000,"value":[{"id":"wo1","type":"WorldObject","status":"anchored","measured":true,"state":{"pos":[1.0,2.0]}},{"id":"co9","type":"Car","status":"partial","measured":false}]}"#,
            "\n",
            r#"{"stream":"world","valid":200000,"value":[{"id":"co1","type":"Car","status":"predicted","measured":false,"state":{"pos":[3.0,2.0]}}]}"#,
            "\n",
        ));
        assert_eq!(rec.problems().count, 0, "{:?}", rec.problems());
        let names: Vec<&str> = rec.streams().map(|s| s.name.as_str()).collect();
        assert_eq!(names, ["cars", "tracker.truth", "world[Car]", "world[WorldObject]"]);
        assert_eq!(rec.other_streams().keys().collect::<Vec<_>>(), ["cars.changes"]);
        let cars = rec.stream("cars").unwrap();
        assert_eq!(cars.snapshots.len(), 2, "the empty snapshot before the first object is kept");
        assert!(!cars.has_measured);
        let world_car = rec.stream("world[Car]").unwrap();
        assert_eq!(world_car.snapshots.iter().map(|s| s.objects.len()).collect::<Vec<_>>(), [0, 1]);
        assert!(world_car.has_measured);
        assert_eq!(rec.stream("world[WorldObject]").unwrap().snapshots.len(), 2);
        assert_eq!(rec.truth(None).unwrap().name, "tracker.truth");
        let all = rec.hypotheses(&[], "tracker.truth").unwrap();
        assert_eq!(all.len(), 3);
        assert_eq!(rec.hypotheses(&["world".into()], "tracker.truth").unwrap().len(), 2);
    }

    #[test]
    fn bad_lines_are_counted_and_skipped() {
        let rec = read(concat!(
            "not json\n",
            r#"{"stream":"cars","valid":"soon","value":[]}"#,
            "\n",
            r#"{"stream":"cars","valid":0,"value":[{"id":"co1","pos":[1.0,"x"]},{"id":"co2","pos":[0,0]},{"id":"co2","pos":[1,1]}]}"#,
            "\n\n",
            r#"{"stream":"cars","valid":0,"value":[{"id":"co3","pos":[0,0]}]}"#,
            "\n",
        ));
        assert_eq!(rec.problems().count, 5, "{:#?}", rec.problems());
        assert!(rec.problems().examples[0].starts_with("rec.jsonl:1: not JSON"));
        let cars = rec.stream("cars").unwrap();
        assert_eq!(cars.snapshots.len(), 1);
        assert_eq!(cars.snapshots[0].objects[0].id, "co3", "the later of two samples at one time");
    }

    #[test]
    fn unknown_names_get_a_suggestion() {
        let rec = read(r#"{"stream":"onroad_car","valid":0,"value":[{"id":"co1","pos":[1.0,2.0]}]}"#);
        let err = rec.hypotheses(&["onroad_cars".into()], "t").unwrap_err();
        assert!(err.to_string().contains("did you mean `onroad_car`?"), "{err}");
        assert!(matches!(rec.truth(None), Err(SelectError::NoTruth { .. })));
    }

    #[test]
    fn branch_objects_are_read_with_their_owner() {
        // As the engine writes them: a link output (oo9 a branch object of oo3) and a world
        // model (`branch_of` beside `type`, the state inside `state`).
        let rec = read(concat!(
            r#"{"stream":"world_onroad","valid":17100000,"value":[{"id":"oo3","lane":":259_4_0","likelihood":0.503,"measured":false,"pos":[725.06,633.29],"predicted_since":17100000},{"branch_of":"oo3","id":"oo9","lane":":259_3_0","likelihood":0.497,"measured":false,"pos":[725.24,633.38],"predicted_since":17100000}]}"#,
            "\n",
            r#"{"stream":"world","valid":17100000,"value":[{"id":"oo9","type":"OnRoadObject","status":"predicted","measured":false,"likelihood":0.497,"branch_of":"oo3","state":{"pos":[725.24,633.38],"branch_of":"oo3"}}]}"#,
            "\n",
            r#"{"stream":"world_onroad","valid":17200000,"value":[{"id":"oo3","pos":[725.5,634.0]},{"id":"oo9","pos":[725.6,634.1],"branch_of":9}]}"#,
            "\n",
        ));
        let onroad = rec.stream("world_onroad").unwrap();
        let owners: Vec<Option<&str>> =
            onroad.snapshots[0].objects.iter().map(|o| o.branch_of.as_deref()).collect();
        assert_eq!(owners, [None, Some("oo3")]);
        let world = rec.stream("world[OnRoadObject]").unwrap();
        assert_eq!(world.snapshots[0].objects[0].branch_of.as_deref(), Some("oo3"));
        assert_eq!(rec.problems().count, 1, "{:?}", rec.problems());
        assert!(
            rec.problems().examples[0].contains("`branch_of` is 9, not a symbol"),
            "{:?}",
            rec.problems()
        );
        assert_eq!(onroad.snapshots[1].objects.len(), 1, "the bad record is left out");
    }

    #[test]
    fn endless_lines_are_refused() {
        let zeros = std::io::repeat(0).take(MAX_LINE_BYTES as u64 + 10);
        let err = Recording::read_from(Path::new("/dev/zero"), zeros).unwrap_err();
        assert!(matches!(err, ReadError::LineTooLong { line: 1, .. }), "{err}");
    }
}
