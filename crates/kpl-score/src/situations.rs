//! Traffic situations scored against ground truth: the true situations computed from true
//! trajectories (each vehicle's lane, position along it and speed at each recorded time, as
//! SUMO's floating car data gives them), the recognised ones read from a recording (the `true`
//! episodes of situation monitors), and their matching through the anchoring's ground-truth
//! [`Mapping`]: a recognised situation is correct if a true one of the same kind is about the
//! true vehicles its symbols stood for, and their times overlap. Precision and recall per kind.
//!
//! The true situations follow the definitions of the monitors of `specs/traffic/`:
//! - `speeding`: over the lane's limit by [`TruthParams::speeding_margin_mps`] for at least
//!   [`TruthParams::speeding_min`], from the threshold's crossing to the next, each found by
//!   linear interpolation between the samples around it (the data's 0.5 s samples of a speed
//!   that changes every 0.1 s would otherwise shorten each episode by up to a sample period);
//! - `stopped`: under [`TruthParams::stop_speed_mps`] for at least [`TruthParams::stop_min`],
//!   not in a junction, more than [`TruthParams::junction_margin_m`] before the lane's end, and
//!   with no other standing vehicle in front within [`TruthParams::queue_gap_m`] on its lane;
//! - `overtake` (a overtakes b): a behind b within [`TruthParams::overtake_close_m`] on one road,
//!   then, staying within that distance, in front, within [`TruthParams::overtake_max`], on another
//!   lane than b at some time in between, both moving at least
//!   [`TruthParams::overtake_min_speed_mps`] when the run begins and when a is in front (a
//!   passing at standstill or in a queue is no overtake); from the first time of that run to the
//!   first time in front;
//! - `tailgating` (a follows b): on b's lane, behind it, with a gap under
//!   [`TruthParams::tailgating_gap_s`] seconds at a's speed, for at least
//!   [`TruthParams::tailgating_min`];
//! - `wrong_way`: moving (at least [`TruthParams::wrong_way_speed_mps`]) with a heading more than
//!   90 degrees off the direction of the lane it lies on, for at least
//!   [`TruthParams::wrong_way_min`].
//!
//! A vehicle is left out of the truth for its first [`TruthParams::settle`] on the road: no
//! tracker can anchor a vehicle the moment it appears, so what happens before (a fast car that
//! enters beside a slow one and passes it at once, a speeder slowed down a second after it
//! entered) is not observable. The situations that this leaves out are reported apart.
//!
//! Positions are the vehicles' centres along the lane (metres); "behind" means the centres are
//! more than half the summed lengths apart, as [`kpl_anchor`'s relations] say. Two vehicles are
//! in a pair situation only while they go one way (headings less than 90 degrees apart), as
//! the relations' `same_road` says: a wrong-way driver passing a car is no overtake.
//!
//! [`kpl_anchor`'s relations]: https://docs.rs/kpl-anchor

use std::collections::{BTreeMap, HashMap};
use std::io::BufRead;
use std::path::Path;

use kpl_core::Time;
use serde::Serialize;

use crate::mapping::Mapping;

/// A situation: its kind (the monitor's name), the objects it is about (in the order of the
/// monitor's variables' names: `a` before `b`), and its first and last time (microseconds).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Situation {
    pub kind: String,
    pub objects: Vec<String>,
    pub start: Time,
    pub end: Time,
}

/// One vehicle at one time, as the ground truth gives it.
#[derive(Debug, Clone, PartialEq)]
pub struct TrueVehicle {
    pub id: String,
    /// The road (SUMO edge) it is on; `None` inside a junction.
    pub road: Option<String>,
    pub lane: String,
    /// Its centre's distance along the lane (m).
    pub lane_pos: f64,
    pub lane_length: f64,
    pub speed: f64,
    pub speed_limit: f64,
    pub length: f64,
    /// Its direction of travel (radians counter-clockwise from east).
    pub heading: f64,
    /// The direction of the lane it lies on at its position (radians).
    pub lane_heading: f64,
}

/// Every vehicle at one time (microseconds, on the run's clock).
#[derive(Debug, Clone, PartialEq)]
pub struct TrueStep {
    pub time: Time,
    pub vehicles: Vec<TrueVehicle>,
}

/// The thresholds of the true situations (module doc); the defaults are those of
/// `specs/traffic/sumo_situations.kpl`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TruthParams {
    pub speeding_margin_mps: f64,
    pub speeding_min: Time,
    pub stop_speed_mps: f64,
    pub stop_min: Time,
    pub junction_margin_m: f64,
    pub queue_gap_m: f64,
    pub overtake_close_m: f64,
    pub overtake_max: Time,
    /// Both vehicles of an overtake move at least this fast (m/s) when it begins and when it ends:
    /// a passing at standstill or in a queue is no overtake.
    pub overtake_min_speed_mps: f64,
    pub tailgating_gap_s: f64,
    pub tailgating_min: Time,
    pub wrong_way_speed_mps: f64,
    pub wrong_way_min: Time,
    /// A vehicle is left out of the truth for this long after it first appeared (module doc).
    pub settle: Time,
}

impl Default for TruthParams {
    fn default() -> TruthParams {
        TruthParams {
            speeding_margin_mps: 3.0,
            speeding_min: 2_000_000,
            stop_speed_mps: 0.5,
            stop_min: 5_000_000,
            junction_margin_m: 30.0,
            queue_gap_m: 15.0,
            overtake_close_m: 50.0,
            overtake_max: 60_000_000,
            overtake_min_speed_mps: 3.0,
            tailgating_gap_s: 1.0,
            tailgating_min: 2_000_000,
            wrong_way_speed_mps: 2.0,
            wrong_way_min: 2_000_000,
            settle: 3_000_000,
        }
    }
}

/// The kinds [`true_situations`] computes.
pub const TRUE_KINDS: &[&str] = &["overtake", "speeding", "stopped", "tailgating", "wrong_way"];

/// The smallest angle between two headings, in [0, π].
fn angle_between(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    if d > std::f64::consts::PI { std::f64::consts::TAU - d } else { d }
}

/// Whether a vehicle moves against the direction of the lane it lies on.
fn against_lane(v: &TrueVehicle, params: &TruthParams) -> bool {
    v.speed >= params.wrong_way_speed_mps
        && angle_between(v.heading, v.lane_heading) > std::f64::consts::FRAC_PI_2
}

/// Runs of a speed over a threshold per vehicle, with their ends at the threshold's crossings:
/// floating car data samples a speed that SUMO changes every simulation step (0.1 s in
/// scripts/sumo-scenarios.py) every 0.5 s, so the first and last sample over the threshold
/// understate how long it was over by up to a sample period. A run begins where the speed,
/// interpolated linearly between the last sample under and the first over, crosses the
/// threshold, and ends at the crossing after the last sample over; a vehicle that appears (or
/// leaves) over it begins (ends) at its first (last) sample. Kept when at least `min` long.
#[derive(Debug, Default)]
struct Crossings {
    /// Per vehicle: the time and the excess over the threshold at its latest sample, and where
    /// its open run began (if the excess is positive).
    last: HashMap<String, (Time, f64, Option<f64>)>,
}

impl Crossings {
    /// Records each vehicle's excess over the threshold (positive: over it) at `time`; closes
    /// the runs of the vehicles under it, or gone.
    fn step(
        &mut self,
        time: Time,
        excess: Vec<(String, f64)>,
        min: Time,
        kind: &str,
        out: &mut Vec<Situation>,
    ) {
        let t = time as f64;
        let mut next = HashMap::with_capacity(excess.len());
        for (id, e) in excess {
            let previous = self.last.remove(&id);
            let start = match (previous, e > 0.0) {
                (_, false) => {
                    if let Some((t0, e0, Some(start))) = previous {
                        Self::close(&id, start, t0 as f64 + (t - t0 as f64) * e0 / (e0 - e), min, kind, out);
                    }
                    None
                }
                (Some((_, _, Some(start))), true) => Some(start),
                (Some((t0, e0, None)), true) => Some(t0 as f64 + (t - t0 as f64) * (-e0) / (e - e0)),
                (None, true) => Some(t),
            };
            next.insert(id, (time, e, start));
        }
        for (id, (t0, _, start)) in std::mem::replace(&mut self.last, next) {
            if let Some(start) = start {
                Self::close(&id, start, t0 as f64, min, kind, out);
            }
        }
    }

    fn finish(&mut self, min: Time, kind: &str, out: &mut Vec<Situation>) {
        for (id, (t0, _, start)) in std::mem::take(&mut self.last) {
            if let Some(start) = start {
                Self::close(&id, start, t0 as f64, min, kind, out);
            }
        }
    }

    fn close(id: &str, start: f64, end: f64, min: Time, kind: &str, out: &mut Vec<Situation>) {
        let (start, end) = (start.round() as Time, end.round() as Time);
        if end - start >= min {
            out.push(Situation { kind: kind.to_string(), objects: vec![id.to_string()], start, end });
        }
    }
}

/// Runs of a condition per key: from the first time it held to the last, kept when long enough.
#[derive(Debug, Default)]
struct Runs {
    open: BTreeMap<Vec<String>, (Time, Time)>,
}

impl Runs {
    /// Records the keys for which the condition holds at `time`; closes the runs of the others.
    fn step(
        &mut self,
        time: Time,
        holding: Vec<Vec<String>>,
        min: Time,
        kind: &str,
        out: &mut Vec<Situation>,
    ) {
        let mut next = BTreeMap::new();
        for key in holding {
            let start = self.open.get(&key).map_or(time, |(start, _)| *start);
            next.insert(key, (start, time));
        }
        let ended: Vec<(Vec<String>, (Time, Time))> =
            self.open.iter().filter(|(k, _)| !next.contains_key(*k)).map(|(k, v)| (k.clone(), *v)).collect();
        for (key, (start, end)) in ended {
            if end - start >= min {
                out.push(Situation { kind: kind.to_string(), objects: key, start, end });
            }
        }
        self.open = next;
    }

    fn finish(&mut self, min: Time, kind: &str, out: &mut Vec<Situation>) {
        for (key, (start, end)) in std::mem::take(&mut self.open) {
            if end - start >= min {
                out.push(Situation { kind: kind.to_string(), objects: key, start, end });
            }
        }
    }
}

/// A pair on the way to an overtake: when its run began, and whether a was on another lane than
/// b at some time of it.
#[derive(Debug, Clone, Copy)]
struct Passing {
    start: Time,
    other_lane: bool,
}

/// The true situations of a trajectory set, and those left out as unobservable.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct TrueSituations {
    /// Ordered by kind, then start.
    pub situations: Vec<Situation>,
    /// Situations of the trajectories that are gone, or shorter than their minimum, once each
    /// vehicle is left out for its first [`TruthParams::settle`]: they happened as it entered.
    pub entering: Vec<Situation>,
}

/// The true situations of a trajectory set (module doc).
pub fn true_situations(steps: &[TrueStep], params: &TruthParams) -> TrueSituations {
    let mut first_seen: HashMap<&str, Time> = HashMap::new();
    for step in steps {
        for v in &step.vehicles {
            first_seen.entry(v.id.as_str()).or_insert(step.time);
        }
    }
    let settled: Vec<TrueStep> = steps
        .iter()
        .map(|step| TrueStep {
            time: step.time,
            vehicles: step
                .vehicles
                .iter()
                .filter(|v| first_seen.get(v.id.as_str()).is_none_or(|&t| step.time - t >= params.settle))
                .cloned()
                .collect(),
        })
        .collect();
    let situations = all_true_situations(&settled, params);
    let entering = all_true_situations(steps, params)
        .into_iter()
        .filter(|s| {
            !situations
                .iter()
                .any(|k| k.kind == s.kind && k.objects == s.objects && k.start <= s.end && s.start <= k.end)
        })
        .collect();
    TrueSituations { situations, entering }
}

fn all_true_situations(steps: &[TrueStep], params: &TruthParams) -> Vec<Situation> {
    let mut out = Vec::new();
    let mut speeding = Crossings::default();
    let (mut stopped, mut tailgating) = (Runs::default(), Runs::default());
    let mut wrong_way = Runs::default();
    let mut passing: HashMap<(String, String), Passing> = HashMap::new();
    for step in steps {
        let v = &step.vehicles;
        let over: Vec<(String, f64)> =
            v.iter().map(|x| (x.id.clone(), x.speed - x.speed_limit - params.speeding_margin_mps)).collect();
        speeding.step(step.time, over, params.speeding_min, "speeding", &mut out);
        let standing = |x: &TrueVehicle| x.speed < params.stop_speed_mps;
        let queued = |x: &TrueVehicle| {
            v.iter().any(|o| {
                o.id != x.id && o.lane == x.lane && standing(o) && {
                    let ahead = o.lane_pos - x.lane_pos;
                    ahead > 0.0 && ahead <= params.queue_gap_m
                }
            })
        };
        let stops: Vec<Vec<String>> = v
            .iter()
            .filter(|x| {
                standing(x)
                    && x.road.is_some()
                    && x.lane_length - x.lane_pos > params.junction_margin_m
                    && !queued(x)
            })
            .map(|x| vec![x.id.clone()])
            .collect();
        stopped.step(step.time, stops, params.stop_min, "stopped", &mut out);
        let against: Vec<Vec<String>> =
            v.iter().filter(|x| against_lane(x, params)).map(|x| vec![x.id.clone()]).collect();
        wrong_way.step(step.time, against, params.wrong_way_min, "wrong_way", &mut out);
        let mut follows = Vec::new();
        let mut seen_pairs = Vec::new();
        for a in v {
            let Some(road) = &a.road else { continue };
            for b in v {
                let one_way = angle_between(a.heading, b.heading) < std::f64::consts::FRAC_PI_2;
                if a.id == b.id || b.road.as_ref() != Some(road) || !one_way {
                    continue;
                }
                let ahead = b.lane_pos - a.lane_pos;
                let overlap = (a.length + b.length) / 2.0;
                if ahead.abs() > params.overtake_close_m + overlap {
                    continue;
                }
                if a.lane == b.lane
                    && ahead > overlap
                    && a.speed > 0.1
                    && (ahead - overlap) / a.speed < params.tailgating_gap_s
                {
                    follows.push(vec![a.id.clone(), b.id.clone()]);
                }
                let key = (a.id.clone(), b.id.clone());
                seen_pairs.push(key.clone());
                let moving =
                    a.speed >= params.overtake_min_speed_mps && b.speed >= params.overtake_min_speed_mps;
                if ahead < -overlap {
                    // In front: an overtake if a run was under way and both still move.
                    if let Some(p) = passing.remove(&key)
                        && p.other_lane
                        && moving
                        && step.time - p.start <= params.overtake_max
                    {
                        out.push(Situation {
                            kind: "overtake".to_string(),
                            objects: vec![a.id.clone(), b.id.clone()],
                            start: p.start,
                            end: step.time,
                        });
                    }
                } else if ahead <= params.overtake_close_m {
                    // A run begins with a behind b, and goes on beside it.
                    let other_lane = a.lane != b.lane;
                    if let Some(p) = passing.get_mut(&key) {
                        p.other_lane |= other_lane;
                    } else if ahead > overlap && moving {
                        passing.insert(key, Passing { start: step.time, other_lane });
                    }
                } else {
                    passing.remove(&key);
                }
            }
        }
        // A pair no longer on one road together, or apart, starts over.
        passing.retain(|key, _| seen_pairs.contains(key));
        tailgating.step(step.time, follows, params.tailgating_min, "tailgating", &mut out);
    }
    speeding.finish(params.speeding_min, "speeding", &mut out);
    stopped.finish(params.stop_min, "stopped", &mut out);
    tailgating.finish(params.tailgating_min, "tailgating", &mut out);
    wrong_way.finish(params.wrong_way_min, "wrong_way", &mut out);
    out.sort_by(|a, b| a.kind.cmp(&b.kind).then(a.start.cmp(&b.start)).then(a.objects.cmp(&b.objects)));
    out
}

/// Reads the recognised situations of recorded JSON lines (`file.jsonl` sinks): every line whose
/// value is a monitor's verdict record with `verdict: true`, `start` and `end`; its kind is the
/// stream's name, its objects the record's string fields in the order of their names. Other
/// lines are skipped; a line that is not JSON is counted in the second result. A line longer than
/// `kpl_core::read::MAX_RECORDING_LINE` ends reading with an error that names it.
pub fn read_situations(reader: impl BufRead) -> std::io::Result<(Vec<Situation>, usize)> {
    let mut out = Vec::new();
    let mut bad = 0;
    let mut lines = kpl_core::read::LineReader::new(reader, kpl_core::read::MAX_RECORDING_LINE);
    loop {
        let line = match lines.next_line() {
            Ok(Some(line)) => String::from_utf8_lossy(line),
            Ok(None) => break,
            Err(kpl_core::read::LineError::Io { source, .. }) => return Err(source),
            Err(error) => {
                return Err(std::io::Error::new(std::io::ErrorKind::InvalidData, error.to_string()));
            }
        };
        // Cheap test first: a recording's object streams are far larger than its situations.
        if !line.contains("\"verdict\"") {
            continue;
        }
        let Ok(json) = serde_json::from_str::<serde_json::Value>(&line) else {
            bad += 1;
            continue;
        };
        let (Some(kind), Some(value)) = (json.get("stream").and_then(|s| s.as_str()), json.get("value"))
        else {
            continue;
        };
        let Some(fields) = value.as_object() else { continue };
        let (Some(true), Some(start), Some(end)) = (
            fields.get("verdict").and_then(serde_json::Value::as_bool),
            fields.get("start").and_then(serde_json::Value::as_i64),
            fields.get("end").and_then(serde_json::Value::as_i64),
        ) else {
            continue;
        };
        let mut vars: Vec<(&String, &str)> =
            fields.iter().filter_map(|(name, v)| v.as_str().map(|s| (name, s))).collect();
        vars.sort();
        out.push(Situation {
            kind: kind.to_string(),
            objects: vars.into_iter().map(|(_, s)| s.to_string()).collect(),
            start,
            end,
        });
    }
    Ok((out, bad))
}

/// Reads [`read_situations`] from a file (gzipped or not is not detected: plain JSON lines).
pub fn read_situations_file(path: &Path) -> std::io::Result<(Vec<Situation>, usize)> {
    read_situations(std::io::BufReader::new(kpl_core::read::open(path)?))
}

/// Reads true situations computed elsewhere (a scenario's `truth.jsonl`, as
/// `scripts/sumo-scenarios.py` writes it for situations whose truth is not computed here): one
/// JSON object a line with `kind`, `objects` (the true vehicles' names), `start` and `end` in
/// seconds from the recording's first time, and optionally `entering: true` for one left out as
/// its vehicles entered; other fields are ignored, blank lines skipped. Adds them to `truth`
/// (kept ordered by kind, then start) and returns their kinds. A malformed line is an error that
/// names its line number.
pub fn add_true_situations(reader: impl BufRead, truth: &mut TrueSituations) -> Result<Vec<String>, String> {
    let mut kinds: Vec<String> = Vec::new();
    let mut lines = kpl_core::read::LineReader::new(reader, kpl_core::read::MAX_RECORDING_LINE);
    let mut number = 0usize;
    loop {
        number += 1;
        let line = match lines.next_line() {
            Ok(Some(line)) => String::from_utf8_lossy(line).into_owned(),
            Ok(None) => break,
            Err(error) => return Err(format!("line {number}: {error}")),
        };
        if line.trim().is_empty() {
            continue;
        }
        let json: serde_json::Value =
            serde_json::from_str(&line).map_err(|e| format!("line {number}: not JSON: {e}"))?;
        let seconds = |field: &str| -> Result<Time, String> {
            let s = json
                .get(field)
                .and_then(serde_json::Value::as_f64)
                .filter(|s| s.is_finite() && s.abs() < 1e9);
            s.map(|s| (s * 1e6).round() as Time)
                .ok_or_else(|| format!("line {number}: `{field}` is not a number of seconds"))
        };
        let kind = json
            .get("kind")
            .and_then(serde_json::Value::as_str)
            .ok_or_else(|| format!("line {number}: no `kind`"))?
            .to_string();
        let objects: Option<Vec<String>> = json
            .get("objects")
            .and_then(serde_json::Value::as_array)
            .and_then(|a| a.iter().map(|o| o.as_str().map(str::to_string)).collect());
        let objects = objects.ok_or_else(|| format!("line {number}: `objects` is not a list of names"))?;
        let (start, end) = (seconds("start")?, seconds("end")?);
        if end < start {
            return Err(format!("line {number}: `end` is before `start`"));
        }
        if !kinds.contains(&kind) {
            kinds.push(kind.clone());
        }
        let situation = Situation { kind, objects, start, end };
        if json.get("entering").and_then(serde_json::Value::as_bool) == Some(true) {
            truth.entering.push(situation);
        } else {
            truth.situations.push(situation);
        }
    }
    truth.situations.sort_by(|a, b| (&a.kind, a.start).cmp(&(&b.kind, b.start)));
    Ok(kinds)
}

/// The scores of one kind of situation.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct KindScore {
    pub kind: String,
    pub recognised: usize,
    /// Recognised situations that match a true one.
    pub correct: usize,
    pub truth: usize,
    /// True situations matched by a recognised one.
    pub found: usize,
    pub precision: Option<f64>,
    pub recall: Option<f64>,
    /// Recognised situations none of whose objects stood for a true vehicle then.
    pub unmapped: usize,
}

/// What matching situations needs besides the two lists.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MatchOptions {
    /// Times may miss each other by this much and still overlap (microseconds): the monitors
    /// decide at frame times, and a situation's edges depend on thresholds over noisy values.
    pub slack: Time,
}

impl Default for MatchOptions {
    fn default() -> MatchOptions {
        MatchOptions { slack: 2_000_000 }
    }
}

/// The true vehicles a recognised situation's symbols stood for: at its end, else its start,
/// else its middle (`None` for a symbol that stood for no true vehicle at any of them).
fn truths_of(situation: &Situation, mapping: &Mapping) -> Vec<Option<String>> {
    let probes = [situation.end, situation.start, situation.start + (situation.end - situation.start) / 2];
    situation
        .objects
        .iter()
        .map(|symbol| probes.iter().find_map(|&t| mapping.truth_of(symbol, t)).map(str::to_string))
        .collect()
}

fn overlaps(a: &Situation, b: &Situation, slack: Time) -> bool {
    a.start - slack <= b.end && b.start - slack <= a.end
}

/// A recognised situation as matched: the true vehicles its symbols stood for, and whether a
/// true situation matched it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Recognised {
    #[serde(flatten)]
    pub situation: Situation,
    pub truth_objects: Vec<Option<String>>,
    pub correct: bool,
    /// Correct, and what it matched is a situation left out of the truth
    /// ([`TrueSituations::entering`]): it happened, though recall does not ask for it.
    pub left_out: bool,
}

/// The result of [`match_situations`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Matched {
    pub scores: Vec<KindScore>,
    pub recognised: Vec<Recognised>,
    /// Per true situation (in the order given): whether a recognised one matched it.
    pub found: Vec<bool>,
}

/// Precision and recall per kind, for the kinds that have true situations or recognised ones;
/// ordered by kind. `truth_kinds` are the kinds the truth covers: a recognised kind outside it is
/// reported with no truth (recall and precision `None`). Recall is over `truth.situations`; a
/// recognised situation is correct if it matches one of them or one left out as its vehicles
/// entered (`truth.entering`: it happened, so recognising it is no mistake).
pub fn match_situations(
    recognised: &[Situation],
    true_situations: &TrueSituations,
    truth_kinds: &[&str],
    mapping: &Mapping,
    options: &MatchOptions,
) -> Matched {
    let truth = &true_situations.situations;
    let mut kinds: Vec<String> =
        recognised.iter().map(|s| s.kind.clone()).chain(truth.iter().map(|s| s.kind.clone())).collect();
    kinds.sort();
    kinds.dedup();
    let mut found = vec![false; truth.len()];
    let mut scores = Vec::new();
    let mut details: Vec<Option<Recognised>> = vec![None; recognised.len()];
    for kind in kinds {
        let covered = truth_kinds.contains(&kind.as_str());
        let mut score = KindScore {
            kind: kind.clone(),
            recognised: 0,
            correct: 0,
            truth: truth.iter().filter(|t| t.kind == kind).count(),
            found: 0,
            precision: None,
            recall: None,
            unmapped: 0,
        };
        for (i, r) in recognised.iter().enumerate().filter(|(_, r)| r.kind == kind) {
            score.recognised += 1;
            let truths = truths_of(r, mapping);
            if truths.iter().all(Option::is_none) {
                score.unmapped += 1;
            }
            let matches = |t: &Situation| {
                t.kind == kind
                    && t.objects.len() == truths.len()
                    && t.objects.iter().zip(&truths).all(|(o, m)| m.as_deref() == Some(o.as_str()))
                    && overlaps(r, t, options.slack)
            };
            let mut correct = false;
            for (k, t) in truth.iter().enumerate() {
                if matches(t) {
                    found[k] = true;
                    correct = true;
                }
            }
            let left_out = !correct && true_situations.entering.iter().any(matches);
            correct |= left_out;
            score.correct += usize::from(correct);
            details[i] = Some(Recognised { situation: r.clone(), truth_objects: truths, correct, left_out });
        }
        score.found = truth.iter().zip(&found).filter(|(t, f)| t.kind == kind && **f).count();
        if covered {
            score.precision = (score.recognised > 0).then(|| score.correct as f64 / score.recognised as f64);
            score.recall = (score.truth > 0).then(|| score.found as f64 / score.truth as f64);
        }
        scores.push(score);
    }
    Matched { scores, recognised: details.into_iter().flatten().collect(), found }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;

    #[test]
    fn true_situations_from_a_file_join_the_computed_ones() {
        let mut truth = TrueSituations::default();
        let text = "{\"kind\": \"reckless_overtake\", \"objects\": [\"r.1\", \"t.0\"], \"start\": 51.0, \"end\": 53.5, \"headway_s\": 0.4}\n\n\
            {\"kind\": \"reckless_overtake\", \"objects\": [\"r.2\", \"t.0\"], \"start\": 1.0, \"end\": 2.0, \"entering\": true}\n";
        let kinds = add_true_situations(text.as_bytes(), &mut truth).unwrap();
        assert_eq!(kinds, ["reckless_overtake"]);
        assert_eq!(truth.situations.len(), 1);
        assert_eq!(truth.situations[0].objects, ["r.1", "t.0"]);
        assert_eq!((truth.situations[0].start, truth.situations[0].end), (51_000_000, 53_500_000));
        assert_eq!(truth.entering.len(), 1);
        for (bad, why) in [
            ("{\"kind\": \"x\", \"objects\": [\"a\"], \"start\": 2, \"end\": 1}", "line 1: `end` is before"),
            ("{\"objects\": [], \"start\": 1, \"end\": 2}", "line 1: no `kind`"),
            ("\n{\"kind\": \"x\", \"objects\": [1], \"start\": 1, \"end\": 2}", "line 2: `objects`"),
            ("{\"kind\": \"x\", \"objects\": [], \"start\": \"soon\", \"end\": 2}", "line 1: `start`"),
            ("not json", "line 1: not JSON"),
        ] {
            let error = add_true_situations(bad.as_bytes(), &mut TrueSituations::default()).unwrap_err();
            assert!(error.starts_with(why), "{bad}: {error}");
        }
    }

    fn vehicle(id: &str, lane: &str, lane_pos: f64, speed: f64) -> TrueVehicle {
        TrueVehicle {
            id: id.to_string(),
            road: Some("e".to_string()),
            lane: lane.to_string(),
            lane_pos,
            lane_length: 1000.0,
            speed,
            speed_limit: 25.0,
            length: 5.0,
            heading: 0.0,
            lane_heading: 0.0,
        }
    }

    /// One car's speeds every 0.5 s (the limit is 25 m/s, the margin 3).
    fn speeds(speeds: &[f64]) -> Vec<TrueStep> {
        (speeds.iter().enumerate())
            .map(|(k, &v)| TrueStep {
                time: k as Time * 500_000,
                vehicles: vec![vehicle("car", "e_0", 0.0, v)],
            })
            .collect()
    }

    fn speeding(steps: &[TrueStep]) -> Vec<(Time, Time)> {
        let params = TruthParams { settle: 0, ..TruthParams::default() };
        let truth = true_situations(steps, &params).situations;
        truth.iter().filter(|s| s.kind == "speeding").map(|s| (s.start, s.end)).collect()
    }

    #[test]
    fn a_speeding_episode_runs_between_the_threshold_s_crossings() {
        // Over 28 m/s in the samples at 0.5, 1.0, 1.5 and 2.0 s (1.5 s apart); the speed crosses
        // 28 m/s half way to the samples around them: over from 0.25 s to 2.25 s, 2 s.
        assert_eq!(speeding(&speeds(&[27.0, 29.0, 29.0, 29.0, 29.0, 27.0])), [(250_000, 2_250_000)]);
        // Falling faster at the end: under 28 at 2.125 s, 1.875 s over: not speeding.
        assert_eq!(speeding(&speeds(&[27.0, 29.0, 29.0, 29.0, 29.0, 25.0])), []);
        // Over from its first sample (it appeared speeding) to its last (it left).
        assert_eq!(speeding(&speeds(&[30.0, 30.0, 30.0, 30.0, 30.0])), [(0, 2_000_000)]);
        // Exactly at the threshold is not over it.
        assert_eq!(speeding(&speeds(&[28.0; 10])), []);
    }

    /// A fast car (30 m/s) passes a truck (15 m/s) on the other lane; 0.5 s steps.
    fn passing() -> Vec<TrueStep> {
        (0..60)
            .map(|k| {
                let t = k as f64 * 0.5;
                let fast_lane = if (4.0..12.0).contains(&t) { "e_1" } else { "e_0" };
                TrueStep {
                    time: (t * 1e6) as Time,
                    vehicles: vec![
                        vehicle("car", fast_lane, 100.0 + 30.0 * t, 30.0),
                        vehicle("truck", "e_0", 200.0 + 15.0 * t, 15.0),
                    ],
                }
            })
            .collect()
    }

    #[test]
    fn a_pass_on_the_other_lane_is_an_overtake_and_the_fast_car_speeds() {
        let params = TruthParams { settle: 0, ..TruthParams::default() };
        let truth = true_situations(&passing(), &params).situations;
        let overtakes: Vec<&Situation> = truth.iter().filter(|s| s.kind == "overtake").collect();
        assert_eq!(overtakes.len(), 1, "{truth:?}");
        assert_eq!(overtakes[0].objects, ["car", "truck"]);
        // Within 50 m from t = 3.33 s (gap 100 - 15 t ≤ 50): the step at 3.5 s; in front (gap <
        // -5 m) from 7 s on: the step at 7 s is the first with 100 - 15 t < -5.
        assert_eq!((overtakes[0].start, overtakes[0].end), (3_500_000, 7_500_000));
        let speeding: Vec<&Situation> = truth.iter().filter(|s| s.kind == "speeding").collect();
        assert_eq!(speeding.len(), 1);
        assert_eq!(
            (speeding[0].objects[0].as_str(), speeding[0].start, speeding[0].end),
            ("car", 0, 29_500_000)
        );
        // The car follows the truck closely only while it changes back in front: never behind
        // it on one lane within a second, so no tailgating.
        assert!(truth.iter().all(|s| s.kind != "tailgating"), "{truth:?}");
    }

    /// Two cars in a queue on two lanes: the left one creeps past the right one at 1 m/s, the
    /// right one at 0.4 m/s. Not an overtake (a passing at standstill or in a queue); the same pass
    /// at 10 and 4 m/s is one.
    #[test]
    fn a_passing_in_a_queue_is_no_overtake() {
        let queue = |speed: f64| -> Vec<TrueStep> {
            (0..40)
                .map(|k| {
                    let t = k as f64 * 0.5;
                    // The left car stops 30 m on; the right one moves at 0.4 times its speed.
                    let moved = (speed * t).min(30.0);
                    TrueStep {
                        time: (t * 1e6) as Time,
                        vehicles: vec![
                            vehicle("left", "e_1", 500.0 + moved, if moved < 30.0 { speed } else { 0.0 }),
                            vehicle("right", "e_0", 506.0 + 0.4 * speed * t, 0.4 * speed),
                        ],
                    }
                })
                .collect()
        };
        let params = TruthParams { settle: 0, ..TruthParams::default() };
        let creeping = true_situations(&queue(1.0), &params).situations;
        assert!(creeping.iter().all(|s| s.kind != "overtake"), "{creeping:?}");
        let moving = true_situations(&queue(10.0), &params).situations;
        assert_eq!(moving.iter().filter(|s| s.kind == "overtake").count(), 1, "{moving:?}");
    }

    #[test]
    fn situations_as_vehicles_enter_are_left_out() {
        // The truck enters at 3 s: the pass ends at 7.5 s; the car is 10 m behind it at 6 s
        // (kept with a 3 s settle time) and in front at 8 s (left out with 5 s).
        let mut steps = passing();
        for s in &mut steps {
            if s.time < 3_000_000 {
                s.vehicles.retain(|v| v.id != "truck");
            }
        }
        let kept = true_situations(&steps, &TruthParams::default());
        assert!(kept.situations.iter().any(|s| s.kind == "overtake"));
        // The car, there from 0 s, speeds in the truth from 3 s on.
        let speeding = kept.situations.iter().find(|s| s.kind == "speeding").unwrap();
        assert_eq!((speeding.start, speeding.end), (3_000_000, 29_500_000));
        let params = TruthParams { settle: 5_000_000, ..TruthParams::default() };
        let left = true_situations(&steps, &params);
        assert!(left.situations.iter().all(|s| s.kind != "overtake"));
        assert_eq!(left.entering.len(), 1);
    }

    #[test]
    fn a_pass_on_the_same_lane_is_not_an_overtake() {
        let mut steps = passing();
        for s in &mut steps {
            for v in &mut s.vehicles {
                v.lane = "e_0".to_string();
            }
        }
        let truth = true_situations(&steps, &TruthParams::default()).situations;
        assert!(truth.iter().all(|s| s.kind != "overtake"), "{truth:?}");
    }

    #[test]
    fn a_car_against_its_lane_drives_the_wrong_way_and_overtakes_nobody() {
        // A ghost driver at 20 m/s on lane e_1 against its direction passes a car on e_0 going
        // the lane's way; it slows to a stop at the end (not wrong-way while standing).
        let steps: Vec<TrueStep> = (0..40)
            .map(|k| {
                let t = k as f64 * 0.5;
                let ghost_speed = if t < 15.0 { 20.0 } else { 0.0 };
                let mut ghost = vehicle("ghost", "e_1", 700.0 - 20.0 * t.min(15.0), ghost_speed);
                ghost.heading = std::f64::consts::PI;
                TrueStep {
                    time: (t * 1e6) as Time,
                    vehicles: vec![ghost, vehicle("car", "e_0", 400.0 + 20.0 * t, 20.0)],
                }
            })
            .collect();
        let params = TruthParams { settle: 0, ..TruthParams::default() };
        let truth = true_situations(&steps, &params).situations;
        let kinds: Vec<&str> = truth.iter().map(|s| s.kind.as_str()).collect();
        assert_eq!(kinds, ["wrong_way"], "{truth:?}");
        assert_eq!(truth[0].objects, ["ghost"]);
        assert_eq!((truth[0].start, truth[0].end), (0, 14_500_000));
    }

    #[test]
    fn a_standing_car_is_stopped_unless_queued_or_at_the_end() {
        let steps: Vec<TrueStep> = (0..30)
            .map(|k| TrueStep {
                time: k * 500_000,
                vehicles: vec![
                    vehicle("broken", "e_0", 500.0, 0.0),
                    vehicle("behind", "e_0", 490.0, 0.0),
                    vehicle("at_light", "e_1", 990.0, 0.0),
                ],
            })
            .collect();
        let params = TruthParams { settle: 0, ..TruthParams::default() };
        let truth = true_situations(&steps, &params).situations;
        let stopped: Vec<&Situation> = truth.iter().filter(|s| s.kind == "stopped").collect();
        assert_eq!(stopped.len(), 1, "{truth:?}");
        assert_eq!(stopped[0].objects, ["broken"]);
        assert_eq!((stopped[0].start, stopped[0].end), (0, 14_500_000));
    }

    #[test]
    fn recognised_situations_are_read_and_matched_through_the_mapping() {
        let text = r#"{"stream":"overtake","valid":3,"value":{"a":"co1","b":"co2","end":7400000,"start":3000000,"verdict":true}}
{"stream":"overtake","valid":3,"value":{"a":"co2","b":"co1","end":7400000,"start":3000000,"verdict":false}}
{"stream":"speeding","valid":3,"value":{"c":"co2","end":9000000,"start":1000000,"verdict":true}}
{"stream":"tracks","valid":3,"value":[{"id":"co1","pos":[0,0]}]}
not json "verdict"
"#;
        let (recognised, bad) = read_situations(text.as_bytes()).unwrap();
        assert_eq!(bad, 1);
        assert_eq!(recognised.len(), 2);
        assert_eq!(recognised[0].objects, ["co1", "co2"]);
        // co1 is the car, co2 the truck throughout.
        let mut seq = crate::Sequence::new();
        for k in 0..60 {
            let t = k as f64 * 0.5;
            let car = [100.0 + 30.0 * t, 0.0];
            let truck = [200.0 + 15.0 * t, 0.0];
            seq.push_frame(
                (t * 1e6) as Time,
                [("car", car), ("truck", truck)],
                [("co1", car), ("co2", truck)],
            )
            .unwrap();
        }
        let mapping = crate::mapping(&seq, &crate::Config::new(2.0).unwrap());
        let truth = true_situations(&passing(), &TruthParams::default());
        let matched = match_situations(&recognised, &truth, TRUE_KINDS, &mapping, &MatchOptions::default());
        assert_eq!(matched.recognised.len(), 2);
        assert!(matched.recognised[0].correct && !matched.recognised[1].correct);
        let scores = matched.scores;
        let overtake = scores.iter().find(|s| s.kind == "overtake").unwrap();
        assert_eq!((overtake.recognised, overtake.correct, overtake.truth, overtake.found), (1, 1, 1, 1));
        // co2 (the truck) was not speeding: a false recognition, and the car's speeding is missed.
        let speeding = scores.iter().find(|s| s.kind == "speeding").unwrap();
        assert_eq!((speeding.precision, speeding.recall), (Some(0.0), Some(0.0)));
        // With 8 s to settle the pass (3.5 s to 7.5 s) is left out of the truth: recognising it
        // is still correct, and recall does not ask for it.
        let params = TruthParams { settle: 8_000_000, ..TruthParams::default() };
        let truth = true_situations(&passing(), &params);
        assert!(truth.situations.iter().all(|s| s.kind != "overtake"));
        let matched = match_situations(&recognised, &truth, TRUE_KINDS, &mapping, &MatchOptions::default());
        assert!(matched.recognised[0].correct && matched.recognised[0].left_out);
        let overtake = matched.scores.iter().find(|s| s.kind == "overtake").unwrap();
        assert_eq!(
            (overtake.correct, overtake.truth, overtake.precision, overtake.recall),
            (1, 0, Some(1.0), None)
        );
    }
}
