//! Recorded traffic: vehicle trajectories read from a file and played back at the tracker's frame
//! times, in place of the simulator's own traffic. Two formats, told apart by their content (either
//! gzipped):
//!
//! - **SUMO FCD output** (`sumo --fcd-output`, `<fcd-export>` of `<timestep time="...">` with
//!   `<vehicle id x y angle type speed lane .../>`), read as SUMO writes it: `x`, `y` are the
//!   middle of the **front bumper**, `angle` is a compass heading (degrees clockwise from north),
//!   and lengths and widths come from the vehicle's `type`: the `vType`s of a SUMO route or
//!   additional file ([`VehicleTypes::read`]) or SUMO's defaults per vehicle class. `person` and
//!   `container` elements are not vehicles and are skipped.
//! - **Rows** of `time` (seconds), `id`, `x`, `y` and optionally `heading` (radians,
//!   counter-clockwise from east), `length` and `width` (metres): JSON lines (`{"time": 0.1,
//!   "id": "v1", "x": 3.0, "y": -1.6}`) or CSV with a header naming the columns. Positions are
//!   the vehicle's centre.
//!
//! Times must not decrease. Between two recorded times a vehicle present at both is interpolated
//! (position linearly, heading along the shorter arc); a vehicle is present from the first time it
//! is recorded to the last. The recording's first time is the playback's start. A malformed
//! vehicle or row is skipped and reported ([`Playback::take_problems`]); the playback goes on.
//! Nothing reads the whole file: it is read as the frames need it.

use std::collections::HashMap;
use std::io::{BufRead, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use kpl_core::Time;
use kpl_roads::geom::{self, Point};
use kpl_roads::{LaneId, RoadNetwork, SnapHint};
use quick_xml::Reader;
use quick_xml::events::{BytesStart, Event};

use crate::traffic::{CarId, CarState};

/// Largest line of a JSONL or CSV file, and most bytes of XML without a tag, accepted.
pub const MAX_LINE_BYTES: usize = 1 << 20;
/// Largest recorded time accepted, in seconds (about 31,700 years).
const MAX_TIME_S: f64 = 1.0e12;
/// Length and width of a vehicle whose size nothing gives: SUMO's default passenger car.
pub const DEFAULT_SIZE_M: (f64, f64) = (5.0, 1.8);

/// A recording could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    #[error("cannot read recorded traffic {path}: {source}")]
    Read { path: PathBuf, source: std::io::Error },
    #[error("cannot read vehicle types {path}: {message}")]
    VehicleTypes { path: PathBuf, message: String },
    #[error("recorded traffic {path}: {message}")]
    Format { path: PathBuf, message: String },
}

/// Something wrong in a recording that was skipped: where, and what.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    pub location: String,
    pub error: String,
}

/// SUMO's default length and width (metres) of vehicles of a class, as SUMO 1.28 gives them to a
/// `vType` that sets only `vClass` (checked against SUMO itself by the tests).
pub fn sumo_class_size(class: &str) -> Option<(f64, f64)> {
    Some(match class {
        "passenger" | "private" | "taxi" | "evehicle" | "army" | "authority" | "vip" | "hov" | "custom1"
        | "custom2" | "cable_car" => (5.0, 1.8),
        "bus" => (12.0, 2.5),
        "coach" => (14.0, 2.6),
        "delivery" | "emergency" => (6.5, 2.16),
        "truck" => (7.1, 2.4),
        "trailer" => (16.5, 2.55),
        "motorcycle" => (2.2, 0.9),
        "moped" => (2.1, 0.78),
        "bicycle" => (1.6, 0.65),
        "scooter" => (1.2, 0.5),
        "tram" => (22.0, 2.4),
        "rail_urban" | "subway" => (109.5, 3.0),
        "rail" => (135.0, 2.84),
        "rail_electric" | "rail_fast" => (200.0, 2.95),
        "ship" => (17.0, 4.0),
        "pedestrian" => (0.215, 0.478),
        "container" => (6.096, 2.438),
        "aircraft" => (72.7, 79.8),
        "wheelchair" => (1.2, 0.72),
        "drone" => (0.5, 0.5),
        _ => return None,
    })
}

/// Vehicle sizes by SUMO type id.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct VehicleTypes {
    sizes: HashMap<String, (f64, f64)>,
}

impl VehicleTypes {
    /// SUMO's built-in types only (`DEFAULT_VEHTYPE`, `DEFAULT_BIKETYPE`, ...).
    pub fn builtin() -> VehicleTypes {
        let mut sizes = HashMap::new();
        for (id, class) in [
            ("DEFAULT_VEHTYPE", "passenger"),
            ("DEFAULT_BIKETYPE", "bicycle"),
            ("DEFAULT_TAXITYPE", "taxi"),
            ("DEFAULT_RAILTYPE", "rail"),
            ("DEFAULT_PEDTYPE", "pedestrian"),
            ("DEFAULT_CONTAINERTYPE", "container"),
        ] {
            sizes.insert(id.to_string(), sumo_class_size(class).unwrap_or(DEFAULT_SIZE_M));
        }
        VehicleTypes { sizes }
    }

    /// The built-in types and every `vType` of a SUMO route or additional file (also inside
    /// `vTypeDistribution`s): `length` and `width`, else the defaults of its `vClass` (default
    /// `passenger`).
    pub fn read(path: &Path) -> Result<VehicleTypes, RecordingError> {
        let error = |message: String| RecordingError::VehicleTypes { path: path.to_path_buf(), message };
        let reader = kpl_roads::load::open(path).map_err(|e| error(e.to_string()))?;
        let mut reader = Reader::from_reader(GuardedReader::new(reader));
        let mut types = VehicleTypes::builtin();
        let mut buf = Vec::new();
        loop {
            let event = reader.read_event_into(&mut buf).map_err(|e| error(e.to_string()))?;
            match &event {
                Event::Start(e) | Event::Empty(e) if e.name().as_ref() == b"vType" => {
                    let attributes = kpl_roads::sumo::attributes(e).map_err(error)?;
                    let Some(id) = attributes.get("id") else {
                        return Err(error("a vType has no id".to_string()));
                    };
                    let class = attributes.get("vClass").map_or("passenger", String::as_str);
                    let class_size = sumo_class_size(class).unwrap_or(DEFAULT_SIZE_M);
                    let number = |name: &str, default: f64| -> Result<f64, String> {
                        match attributes.get(name) {
                            None => Ok(default),
                            Some(text) => text
                                .parse::<f64>()
                                .ok()
                                .filter(|v| v.is_finite() && *v > 0.0 && *v < 1000.0)
                                .ok_or_else(|| {
                                    format!("vType {id}: `{name}` is not a size in metres: {text:?}")
                                }),
                        }
                    };
                    let size = (
                        number("length", class_size.0).map_err(error)?,
                        number("width", class_size.1).map_err(error)?,
                    );
                    types.sizes.insert(id.clone(), size);
                }
                Event::Eof => break,
                _ => {}
            }
            buf.clear();
        }
        Ok(types)
    }

    /// The size of vehicles of type `id`, if known.
    pub fn size(&self, id: &str) -> Option<(f64, f64)> {
        self.sizes.get(id).copied()
    }
}

/// A reader that fails when [`MAX_LINE_BYTES`] pass without a line break or an XML tag, so that
/// a file of one endless line (`/dev/zero`) is an error instead of a buffer that grows forever.
struct GuardedReader<R> {
    inner: R,
    since_break: usize,
}

impl<R: BufRead> GuardedReader<R> {
    fn new(inner: R) -> std::io::BufReader<GuardedReader<R>> {
        std::io::BufReader::with_capacity(1 << 16, GuardedReader { inner, since_break: 0 })
    }
}

impl<R: BufRead> Read for GuardedReader<R> {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(out)?;
        for &b in &out[..n] {
            if b == b'\n' || b == b'<' || b == b'>' {
                self.since_break = 0;
            } else {
                self.since_break += 1;
            }
        }
        if self.since_break > MAX_LINE_BYTES {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("more than {MAX_LINE_BYTES} bytes without a line break or a tag"),
            ));
        }
        Ok(n)
    }
}

/// One vehicle at one recorded time.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    pub name: Arc<str>,
    /// The vehicle's centre.
    pub pos: Point,
    /// Radians, counter-clockwise from east.
    pub heading: Option<f64>,
    pub speed_mps: Option<f64>,
    pub length_m: f64,
    pub width_m: f64,
    /// The network lane the recording names (SUMO's `lane`).
    pub lane: Option<Arc<str>>,
    /// The front bumper's distance along that lane from its start (SUMO's `pos`), metres.
    pub lane_pos: Option<f64>,
}

/// Every vehicle at one recorded time.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Recorded time, microseconds.
    pub time: Time,
    pub vehicles: Vec<Observation>,
}

/// Where recorded steps come from.
trait StepReader: Send {
    /// The next step, `None` at the end; problems found on the way go to `problems`.
    fn next_step(&mut self, problems: &mut Vec<Problem>) -> Option<Step>;
}

fn time_us(seconds: f64) -> Option<Time> {
    (seconds.is_finite() && seconds.abs() <= MAX_TIME_S).then(|| (seconds * 1e6).round() as Time)
}

/// SUMO's FCD output.
struct FcdReader {
    reader: Reader<std::io::BufReader<GuardedReader<Box<dyn BufRead + Send>>>>,
    buf: Vec<u8>,
    types: VehicleTypes,
    /// Types already reported as unknown.
    unknown_types: std::collections::HashSet<String>,
    last_time: Option<Time>,
    done: bool,
}

impl FcdReader {
    fn vehicle(
        &mut self,
        e: &BytesStart<'_>,
        time_s: &str,
        problems: &mut Vec<Problem>,
    ) -> Option<Observation> {
        let location = |id: &str| format!("timestep {time_s}, vehicle {id:?}");
        let attributes = match kpl_roads::sumo::attributes(e) {
            Ok(a) => a,
            Err(error) => {
                problems.push(Problem { location: location("?"), error });
                return None;
            }
        };
        let id = attributes.get("id").cloned().unwrap_or_default();
        let mut bad = |error: String| problems.push(Problem { location: location(&id), error });
        if id.is_empty() {
            bad("a vehicle without an id".to_string());
            return None;
        }
        let number =
            |name: &str| attributes.get(name).map(|t| t.trim().parse::<f64>().ok().filter(|v| v.is_finite()));
        let (x, y) = match (number("x"), number("y")) {
            (Some(Some(x)), Some(Some(y))) if x.abs() < 1e7 && y.abs() < 1e7 => (x, y),
            _ => {
                bad("`x` and `y` must be numbers (coordinates of the network)".to_string());
                return None;
            }
        };
        let heading = match number("angle") {
            None => None,
            Some(Some(angle)) => Some(compass_to_heading(angle)),
            Some(None) => {
                bad("`angle` is not a number".to_string());
                return None;
            }
        };
        let speed_mps = number("speed").flatten().filter(|s| *s >= 0.0);
        let type_id = attributes.get("type").map_or("DEFAULT_VEHTYPE", String::as_str);
        let (length_m, width_m) = match self.types.size(type_id) {
            Some(size) => size,
            None => {
                if self.unknown_types.insert(type_id.to_string()) {
                    bad(format!(
                        "vehicle type {type_id:?} is not defined (give the file with its vType as `vtypes_file`); \
                         using SUMO's passenger car, {} m x {} m",
                        DEFAULT_SIZE_M.0, DEFAULT_SIZE_M.1
                    ));
                }
                DEFAULT_SIZE_M
            }
        };
        let front = [x, y];
        // FCD positions are the middle of the front bumper: the centre is half a length behind.
        let pos = match heading {
            Some(h) => geom::sub(front, geom::scale(geom::unit(h), length_m / 2.0)),
            None => front,
        };
        Some(Observation {
            name: id.into(),
            pos,
            heading,
            speed_mps,
            length_m,
            width_m,
            lane: attributes.get("lane").map(|l| Arc::from(l.as_str())),
            lane_pos: number("pos").flatten(),
        })
    }
}

/// A compass angle (degrees clockwise from north) as a heading (radians counter-clockwise from east).
pub fn compass_to_heading(angle_deg: f64) -> f64 {
    (90.0 - angle_deg).to_radians().rem_euclid(std::f64::consts::TAU)
}

impl StepReader for FcdReader {
    fn next_step(&mut self, problems: &mut Vec<Problem>) -> Option<Step> {
        let mut step: Option<(Step, String)> = None;
        while !self.done {
            self.buf.clear();
            let event = match self.reader.read_event_into(&mut self.buf) {
                Ok(event) => event.into_owned(),
                Err(e) => {
                    problems.push(Problem {
                        location: format!("byte {}", self.reader.error_position()),
                        error: format!("the FCD file is not well-formed XML ({e}); the recording ends here"),
                    });
                    self.done = true;
                    break;
                }
            };
            match &event {
                Event::Start(e) | Event::Empty(e) if e.name().as_ref() == b"timestep" => {
                    let attributes = kpl_roads::sumo::attributes(e).unwrap_or_default();
                    let text = attributes.get("time").cloned().unwrap_or_default();
                    let time = text.trim().parse::<f64>().ok().and_then(time_us);
                    let Some(time) = time.filter(|t| self.last_time.is_none_or(|last| *t > last)) else {
                        problems.push(Problem {
                            location: format!("timestep {text:?}"),
                            error: "`time` must be a number of seconds after the previous timestep's; the \
                                    timestep is skipped"
                                .to_string(),
                        });
                        // Skip its vehicles: read on to its end.
                        if matches!(event, Event::Start(_)) {
                            let _ = self.reader.read_to_end_into(e.name(), &mut Vec::new());
                        }
                        continue;
                    };
                    self.last_time = Some(time);
                    let step_now = Step { time, vehicles: Vec::new() };
                    if matches!(event, Event::Empty(_)) {
                        return Some(step_now);
                    }
                    step = Some((step_now, text));
                }
                Event::Start(e) | Event::Empty(e) if e.name().as_ref() == b"vehicle" => {
                    if let Some((current, time_s)) = &mut step {
                        let time_s = time_s.clone();
                        if let Some(obs) = self.vehicle(e, &time_s, problems) {
                            current.vehicles.push(obs);
                        }
                    }
                }
                Event::End(e) if e.name().as_ref() == b"timestep" => {
                    if let Some((current, _)) = step.take() {
                        return Some(current);
                    }
                }
                Event::Eof => self.done = true,
                _ => {}
            }
        }
        step.map(|(s, _)| s)
    }
}

/// Which column of a row holds what.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Column {
    Time,
    Id,
    X,
    Y,
    Heading,
    Length,
    Width,
    Unknown,
}

fn column_of(name: &str) -> Column {
    match name.trim().trim_matches('"') {
        "time" => Column::Time,
        "id" => Column::Id,
        "x" => Column::X,
        "y" => Column::Y,
        "heading" => Column::Heading,
        "length" => Column::Length,
        "width" => Column::Width,
        _ => Column::Unknown,
    }
}

/// One row of a JSONL or CSV recording.
struct Row {
    time: Time,
    obs: Observation,
}

/// JSON lines or CSV rows, grouped into steps by time.
struct RowReader {
    lines: Box<dyn BufRead + Send>,
    line_number: usize,
    csv_header: Option<Vec<Column>>,
    reported_columns: std::collections::HashSet<String>,
    pending: Option<Row>,
    last_time: Option<Time>,
    done: bool,
}

impl RowReader {
    fn read_line(&mut self, problems: &mut Vec<Problem>) -> Option<String> {
        let mut bytes = Vec::new();
        let n = (&mut self.lines).take(MAX_LINE_BYTES as u64 + 1).read_until(b'\n', &mut bytes);
        self.line_number += 1;
        match n {
            Ok(0) => None,
            Ok(_) if bytes.len() > MAX_LINE_BYTES && !bytes.ends_with(b"\n") => {
                problems.push(Problem {
                    location: format!("line {}", self.line_number),
                    error: format!("longer than {MAX_LINE_BYTES} bytes; the recording ends here"),
                });
                None
            }
            Ok(_) => Some(String::from_utf8_lossy(&bytes).trim().to_string()),
            Err(e) => {
                problems.push(Problem {
                    location: format!("line {}", self.line_number),
                    error: format!("{e}; the recording ends here"),
                });
                None
            }
        }
    }

    fn row(&mut self, line: &str, problems: &mut Vec<Problem>) -> Option<Row> {
        let location = format!("line {}", self.line_number);
        let mut fields: Vec<(Column, String, serde_json::Value)> = Vec::new();
        match &self.csv_header {
            Some(header) => {
                let cells: Vec<&str> = line.split(',').collect();
                if cells.len() != header.len() {
                    problems.push(Problem {
                        location,
                        error: format!("{} cells where the header has {}", cells.len(), header.len()),
                    });
                    return None;
                }
                for (&column, cell) in header.iter().zip(cells) {
                    let cell = cell.trim().trim_matches('"');
                    let value = match cell.parse::<f64>() {
                        Ok(v) if column != Column::Id => serde_json::json!(v),
                        _ => serde_json::Value::String(cell.to_string()),
                    };
                    fields.push((column, String::new(), value));
                }
            }
            None => {
                let object: serde_json::Map<String, serde_json::Value> = match serde_json::from_str(line) {
                    Ok(object) => object,
                    Err(e) => {
                        problems.push(Problem { location, error: format!("not a JSON object: {e}") });
                        return None;
                    }
                };
                for (key, value) in object {
                    let column = column_of(&key);
                    if column == Column::Unknown && self.reported_columns.insert(key.clone()) {
                        problems.push(Problem {
                            location: location.clone(),
                            error: format!(
                                "unknown field `{key}` is ignored (rows have time, id, x, y, heading, length, width)"
                            ),
                        });
                    }
                    fields.push((column, key, value));
                }
            }
        }
        let get = |column: Column| fields.iter().find(|(c, _, _)| *c == column).map(|(_, _, v)| v);
        let number = |column: Column| get(column).map(|v| v.as_f64().filter(|x| x.is_finite()));
        let mut bad = |what: &str| {
            problems.push(Problem { location: location.clone(), error: what.to_string() });
        };
        let Some(time) = number(Column::Time).flatten().and_then(time_us) else {
            bad("`time` must be a number of seconds");
            return None;
        };
        let name: Arc<str> = match get(Column::Id) {
            Some(serde_json::Value::String(s)) if !s.is_empty() => s.as_str().into(),
            Some(serde_json::Value::Number(n)) => n.to_string().into(),
            _ => {
                bad("`id` must be a non-empty string");
                return None;
            }
        };
        let (Some(Some(x)), Some(Some(y))) = (number(Column::X), number(Column::Y)) else {
            bad("`x` and `y` must be numbers");
            return None;
        };
        let optional = |column: Column, ok: fn(f64) -> bool| -> Result<Option<f64>, ()> {
            match number(column) {
                None => Ok(None),
                Some(Some(v)) if ok(v) => Ok(Some(v)),
                Some(_) => Err(()),
            }
        };
        let heading = optional(Column::Heading, |_| true);
        let length = optional(Column::Length, |v| v > 0.0 && v < 1000.0);
        let width = optional(Column::Width, |v| v > 0.0 && v < 1000.0);
        let (Ok(heading), Ok(length), Ok(width)) = (heading, length, width) else {
            bad("`heading` must be a number of radians, `length` and `width` sizes in metres");
            return None;
        };
        Some(Row {
            time,
            obs: Observation {
                name,
                pos: [x, y],
                heading,
                speed_mps: None,
                length_m: length.unwrap_or(DEFAULT_SIZE_M.0),
                width_m: width.unwrap_or(DEFAULT_SIZE_M.1),
                lane: None,
                lane_pos: None,
            },
        })
    }

    fn next_row(&mut self, problems: &mut Vec<Problem>) -> Option<Row> {
        while !self.done {
            let Some(line) = self.read_line(problems) else {
                self.done = true;
                break;
            };
            if line.is_empty() {
                continue;
            }
            if let Some(row) = self.row(&line, problems) {
                if self.last_time.is_some_and(|last| row.time < last) {
                    problems.push(Problem {
                        location: format!("line {}", self.line_number),
                        error: "time goes backwards; rows must be sorted by time. The row is skipped"
                            .to_string(),
                    });
                    continue;
                }
                self.last_time = Some(row.time);
                return Some(row);
            }
        }
        None
    }
}

impl StepReader for RowReader {
    fn next_step(&mut self, problems: &mut Vec<Problem>) -> Option<Step> {
        let first = match self.pending.take() {
            Some(row) => row,
            None => self.next_row(problems)?,
        };
        let mut step = Step { time: first.time, vehicles: vec![first.obs] };
        while let Some(row) = self.next_row(problems) {
            if row.time != step.time {
                self.pending = Some(row);
                break;
            }
            step.vehicles.push(row.obs);
        }
        Some(step)
    }
}

/// Opens a recording: SUMO FCD (XML) or rows (JSONL, CSV), either gzipped. Vehicle sizes of FCD
/// come from `types`.
fn open_steps(path: &Path, types: VehicleTypes) -> Result<Box<dyn StepReader>, RecordingError> {
    let read_error = |source| RecordingError::Read { path: path.to_path_buf(), source };
    let mut reader = kpl_roads::load::open(path).map_err(read_error)?;
    let start: Vec<u8> = reader.fill_buf().map_err(read_error)?.iter().take(512).copied().collect();
    let text = String::from_utf8_lossy(&start);
    let first = text.trim_start_matches('\u{feff}').trim_start().chars().next();
    Ok(match first {
        Some('<') => Box::new(FcdReader {
            reader: Reader::from_reader(GuardedReader::new(reader)),
            buf: Vec::new(),
            types,
            unknown_types: Default::default(),
            last_time: None,
            done: false,
        }),
        Some('{') => Box::new(RowReader {
            lines: reader,
            line_number: 0,
            csv_header: None,
            reported_columns: Default::default(),
            pending: None,
            last_time: None,
            done: false,
        }),
        Some(_) => {
            let mut rows = RowReader {
                lines: reader,
                line_number: 0,
                csv_header: None,
                reported_columns: Default::default(),
                pending: None,
                last_time: None,
                done: false,
            };
            let mut problems = Vec::new();
            let header = rows.read_line(&mut problems).unwrap_or_default();
            let columns: Vec<Column> = header.split(',').map(column_of).collect();
            for needed in [Column::Time, Column::Id, Column::X, Column::Y] {
                if !columns.contains(&needed) {
                    return Err(RecordingError::Format {
                        path: path.to_path_buf(),
                        message: format!(
                            "not SUMO FCD (XML) nor JSON lines, and as CSV its header {header:?} lacks a column \
                             `{}` (columns: time, id, x, y[, heading, length, width])",
                            match needed {
                                Column::Time => "time",
                                Column::Id => "id",
                                Column::X => "x",
                                _ => "y",
                            }
                        ),
                    });
                }
            }
            if let Some(unknown) = header.split(',').find(|c| column_of(c) == Column::Unknown) {
                return Err(RecordingError::Format {
                    path: path.to_path_buf(),
                    message: format!(
                        "unknown CSV column {unknown:?} (columns: time, id, x, y, heading, length, width)"
                    ),
                });
            }
            rows.csv_header = Some(columns);
            Box::new(rows)
        }
        None => {
            return Err(RecordingError::Format {
                path: path.to_path_buf(),
                message: "the file is empty".to_string(),
            });
        }
    })
}

/// Every recorded step of a file as it is written (no interpolation), with the problems found
/// on the way: for tools that compute something from the whole recording (the true traffic
/// situations of `kpl situations`).
pub fn read_steps(path: &Path, types: VehicleTypes) -> Result<(Vec<Step>, Vec<Problem>), RecordingError> {
    let mut steps = open_steps(path, types)?;
    let mut problems = Vec::new();
    let mut out = Vec::new();
    while let Some(step) = steps.next_step(&mut problems) {
        out.push(step);
    }
    Ok((out, problems))
}

/// A recording played back at given times: the vehicles present at each, interpolated between
/// recorded times, with their place on the network.
pub struct Playback {
    steps: Box<dyn StepReader>,
    network: Arc<RoadNetwork>,
    /// Recorded time of the playback's start.
    origin: Time,
    /// The last recorded step at or before the current time, and the next one after it.
    before: Option<Step>,
    after: Option<Step>,
    ids: HashMap<Arc<str>, CarId>,
    /// Each vehicle's lane at the last time it was placed, and its last heading.
    lanes: HashMap<CarId, LaneId>,
    headings: HashMap<CarId, f64>,
    present: Vec<CarId>,
    problems: Vec<Problem>,
}

impl std::fmt::Debug for Playback {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Playback").field("origin", &self.origin).field("vehicles", &self.ids.len()).finish()
    }
}

impl Playback {
    /// Opens a recording; its first recorded time is the start.
    pub fn open(
        path: &Path,
        types: VehicleTypes,
        network: Arc<RoadNetwork>,
    ) -> Result<Playback, RecordingError> {
        let mut steps = open_steps(path, types)?;
        let mut problems = Vec::new();
        let Some(first) = steps.next_step(&mut problems) else {
            let detail =
                problems.first().map(|p| format!(" ({}: {})", p.location, p.error)).unwrap_or_default();
            return Err(RecordingError::Format {
                path: path.to_path_buf(),
                message: format!("it has no vehicle positions{detail}"),
            });
        };
        let next = steps.next_step(&mut problems);
        Ok(Playback {
            steps,
            network,
            origin: first.time,
            before: Some(first),
            after: next,
            ids: HashMap::new(),
            lanes: HashMap::new(),
            headings: HashMap::new(),
            present: Vec::new(),
            problems,
        })
    }

    /// Problems found since the last call.
    pub fn take_problems(&mut self) -> Vec<Problem> {
        std::mem::take(&mut self.problems)
    }

    /// Whether nothing is recorded at or after `elapsed` (microseconds since the start).
    pub fn finished(&self, elapsed: Time) -> bool {
        let now = self.origin.saturating_add(elapsed);
        self.after.is_none() && self.before.as_ref().is_none_or(|b| b.time < now)
    }

    /// The vehicles present `elapsed` microseconds after the start, in the order of the
    /// recording, and the vehicles that were present before and are not any more.
    pub fn states_at(&mut self, elapsed: Time) -> (Vec<CarState>, Vec<CarId>) {
        let now = self.origin.saturating_add(elapsed);
        while self.after.as_ref().is_some_and(|a| a.time <= now) {
            self.before = self.after.take();
            self.after = self.steps.next_step(&mut self.problems);
        }
        let mut states = Vec::new();
        // Taken out while the states are made (`state_of` updates the vehicles' memory).
        let (before, after) = (self.before.take(), self.after.take());
        if let Some(before) = &before {
            let next: HashMap<&str, &Observation> = after
                .as_ref()
                .map(|a| a.vehicles.iter().map(|o| (&*o.name, o)).collect())
                .unwrap_or_default();
            let after_time = after.as_ref().map_or(before.time, |a| a.time);
            for obs in &before.vehicles {
                let later = next.get(&*obs.name).copied();
                if before.time != now && later.is_none() {
                    continue; // it left after `before`
                }
                states.push(self.state_of(obs, before.time, later, after_time, now));
            }
        }
        (self.before, self.after) = (before, after);
        let mut gone: Vec<CarId> = Vec::new();
        let mut now_present: Vec<CarId> = states.iter().map(|s| s.id).collect();
        now_present.sort_unstable();
        for &id in &self.present {
            if now_present.binary_search(&id).is_err() {
                gone.push(id);
                self.lanes.remove(&id);
                self.headings.remove(&id);
            }
        }
        self.present = now_present;
        (states, gone)
    }

    fn state_of(
        &mut self,
        a: &Observation,
        ta: Time,
        b: Option<&Observation>,
        tb: Time,
        now: Time,
    ) -> CarState {
        let next_id = CarId(self.ids.len() as u32 + 1);
        let id = *self.ids.entry(a.name.clone()).or_insert(next_id);
        let span = (tb - ta) as f64 / 1e6;
        let u = if span > 0.0 { ((now - ta) as f64 / 1e6 / span).clamp(0.0, 1.0) } else { 0.0 };
        let (pos, moved) = match b {
            Some(b) => (geom::add(a.pos, geom::scale(geom::sub(b.pos, a.pos), u)), geom::sub(b.pos, a.pos)),
            None => (a.pos, [0.0, 0.0]),
        };
        let finite_difference = (span > 0.0 && b.is_some()).then(|| geom::scale(moved, 1.0 / span));
        let heading = match (a.heading, b.and_then(|b| b.heading)) {
            (Some(ha), Some(hb)) => Some(ha + signed_turn(ha, hb) * u),
            (Some(h), None) | (None, Some(h)) => Some(h),
            (None, None) => finite_difference.filter(|v| geom::norm(*v) > 0.1).map(geom::heading_of),
        }
        .or_else(|| self.headings.get(&id).copied())
        .unwrap_or(0.0)
        .rem_euclid(std::f64::consts::TAU);
        self.headings.insert(id, heading);
        let speed = match (a.speed_mps, b.and_then(|b| b.speed_mps)) {
            (Some(sa), Some(sb)) => Some(sa + (sb - sa) * u),
            (Some(s), None) => Some(s),
            _ => None,
        };
        let vel = match (speed, finite_difference) {
            (Some(s), _) => geom::scale(geom::unit(heading), s),
            (None, Some(v)) => v,
            (None, None) => [0.0, 0.0],
        };
        let lane_name =
            if u < 0.5 { a.lane.clone() } else { b.and_then(|b| b.lane.clone()).or(a.lane.clone()) };
        let named = lane_name.as_deref().and_then(|name| self.network.lane_by_name(name)).map(|l| l.id);
        let snapped = self
            .network
            .snap(pos, &SnapHint { heading: Some(heading), previous: self.lanes.get(&id).copied() });
        let on_lane = match (named, snapped) {
            (Some(lane), _) => {
                let projection = self.network.lane(lane).path.project(pos);
                Some(self.network.lane_position(lane, projection.offset))
            }
            (None, Some(s)) if s.lateral_m.abs() <= self.network.lane(s.lane).width_m => Some(s),
            _ => None,
        };
        if let Some(p) = &on_lane {
            self.lanes.insert(id, p.lane);
        }
        CarState {
            id,
            name: a.name.clone(),
            pos,
            vel,
            heading,
            speed_mps: geom::norm(vel),
            lane: on_lane.map(|p| p.lane),
            place: on_lane.map(|p| p.place),
            offset_m: on_lane.map_or(0.0, |p| p.offset_m),
            length_m: a.length_m,
            width_m: a.width_m,
        }
    }
}

/// The signed angle (radians, in (-pi, pi]) that turns heading `from` into heading `to`.
fn signed_turn(from: f64, to: f64) -> f64 {
    let d = (to - from).rem_euclid(std::f64::consts::TAU);
    if d > std::f64::consts::PI { d - std::f64::consts::TAU } else { d }
}
