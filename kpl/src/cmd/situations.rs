//! `kpl situations`: scores the traffic situations a run recognised (the `true` episodes of its
//! situation monitors) against the true situations in the recorded traffic it observed (SUMO's
//! floating car data with lanes and positions along them), through the anchoring's ground-truth
//! mapping of the car stream; prints precision and recall per kind. The work is `kpl_score`'s
//! (`situations`); this module reads the traffic and the network.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args as ClapArgs, ValueEnum};
use kpl_roads::{LaneKind, RoadNetwork, SnapHint};
use kpl_score::situations::{
    self, KindScore, MatchOptions, Situation, TRUE_KINDS, TrueStep, TrueVehicle, TruthParams,
};
use kpl_score::{Config, Options, Recording};
use kpl_sim::recorded::{VehicleTypes, read_steps};

const AFTER_HELP: &str = "\
Examples:
  kpl run specs/traffic/sumo_situations.kpl --clock sim --out out
  kpl situations out/sumo_situations --traffic specs/traffic/sumo/overtake/fcd.xml.gz

The recognised situations are the recorded verdict records with `verdict: true`, `start` and `end`
of the monitors and chronicles named overtake, speeding, stopped, tailgating, wrong_way, or a kind
of --situations-truth (others are listed without a truth). The true situations are computed from the traffic file (SUMO FCD with `lane` and
`pos`; a vehicle on a lane the network does not have is placed on its nearest lane), its first time
being the run's time 0. A recognised situation is correct when a true one of its
kind is about the vehicles its symbols stood for (the CLEAR MOT mapping of the car stream against
the tracker's ground truth) and their times overlap (within --slack). See docs/situations.md.
Exit status: 0 scored, 1 the recording or traffic cannot be scored, 2 usage or I/O errors.";

#[derive(Debug, ClapArgs)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// The run's output folder (every `*.jsonl` below it) or recorded `.jsonl` files.
    #[arg(required = true, value_name = "RUN_DIR_OR_FILES")]
    paths: Vec<PathBuf>,
    /// The recorded traffic the run observed: SUMO FCD output with `lane` and `pos` (gzipped or not).
    #[arg(long, value_name = "FILE")]
    traffic: PathBuf,
    /// The road network of the traffic (speed limits, lanes, junctions) [default: net.xml.gz
    /// beside the traffic file].
    #[arg(long, value_name = "FILE")]
    network: Option<PathBuf>,
    /// The vehicle types of the traffic (lengths), as for `sim.uav_tracker`'s `vtypes_file`
    /// [default: vtypes.xml beside the traffic file, if there is one; else SUMO's defaults].
    #[arg(long, value_name = "FILE")]
    vtypes: Option<PathBuf>,
    /// True situations computed elsewhere, of kinds this command does not compute (JSON lines:
    /// `kind`, `objects`, `start`, `end` in seconds; `scripts/sumo-scenarios.py` writes them for
    /// the reckless overtakes) [default: truth.jsonl beside the traffic file, if there is one].
    #[arg(long, value_name = "FILE")]
    situations_truth: Option<PathBuf>,
    /// The stream of cars whose symbols the situations name.
    #[arg(long, value_name = "STREAM", default_value = "onroad_car")]
    stream: String,
    /// The ground-truth stream (default: the one named `truth` or `*.truth`).
    #[arg(long, value_name = "STREAM")]
    truth: Option<String>,
    /// Gating distance of the mapping, metres.
    #[arg(long, value_name = "METRES", default_value_t = kpl_score::DEFAULT_MAX_DISTANCE, value_parser = super::score::parse_metres)]
    max_distance: f64,
    /// How far apart in time a recognised and a true situation may be and still overlap, seconds
    /// (0 to a day).
    #[arg(long, value_name = "SECONDS", default_value = "2", value_parser = parse_slack)]
    slack: kpl_core::Time,
    /// The truth's speeding margin: a vehicle speeds when it is more than this over its lane's
    /// limit, m/s (the shipped monitors' 3 m/s by default; `--speeding-margin 3.5
    /// --speeding-min 5` asks how many of the vehicles clearly over a monitor's threshold it
    /// finds).
    #[arg(long, value_name = "MPS", default_value_t = TruthParams::default().speeding_margin_mps, value_parser = parse_margin)]
    speeding_margin: f64,
    /// The truth's shortest speeding episode, seconds (2 by default).
    #[arg(long, value_name = "SECONDS", default_value = "2", value_parser = parse_slack)]
    speeding_min: kpl_core::Time,
    /// How to print the scores.
    #[arg(long, value_enum, default_value = "table")]
    format: Format,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum Format {
    /// A table per kind.
    Table,
    /// One JSON document: scores per kind, and the true and recognised situations.
    Json,
}

#[derive(serde::Serialize)]
struct Output<'a> {
    scores: &'a [KindScore],
    truth_params: &'a TruthParams,
    truth: &'a [TrueItem<'a>],
    /// True situations left out: they happen within the settle time of a vehicle's first appearance.
    entering: &'a [Situation],
    recognised: &'a [situations::Recognised],
}

#[derive(serde::Serialize)]
struct TrueItem<'a> {
    #[serde(flatten)]
    situation: &'a Situation,
    found: bool,
}

pub fn run(args: Args) -> ExitCode {
    match score(&args) {
        Ok(code) => code,
        Err((code, message)) => {
            eprintln!("error: {message}");
            ExitCode::from(code)
        }
    }
}

fn score(args: &Args) -> Result<ExitCode, (u8, String)> {
    let slack = args.slack;
    let config = Config::new(args.max_distance).map_err(|e| (2, e.to_string()))?;
    let beside = |name: &str| args.traffic.parent().map_or_else(|| PathBuf::from(name), |dir| dir.join(name));
    if !args.traffic.exists() {
        return Err((
            2,
            format!("{}: no such traffic file (SUMO's floating car data)", args.traffic.display()),
        ));
    }
    let network_path = args.network.clone().unwrap_or_else(|| beside("net.xml.gz"));
    let network = RoadNetwork::load(&network_path).map_err(|e| {
        let hint = if args.network.is_none() {
            " (looked for beside the traffic file; --network names it)"
        } else {
            ""
        };
        (2, format!("{}: {e}{hint}", network_path.display()))
    })?;
    let vtypes = args.vtypes.clone().or_else(|| Some(beside("vtypes.xml")).filter(|p| p.is_file()));
    let types = match &vtypes {
        Some(path) => VehicleTypes::read(path).map_err(|e| (2, e.to_string()))?,
        None => VehicleTypes::builtin(),
    };
    let (steps, problems) = read_steps(&args.traffic, types).map_err(|e| (2, e.to_string()))?;
    if let Some(p) = problems.first() {
        eprintln!(
            "warning: {} problems in the traffic file, left out (first: {}: {})",
            problems.len(),
            p.location,
            p.error
        );
    }
    let true_steps = true_steps(&steps, &network, &args.traffic)?;
    let params = TruthParams {
        speeding_margin_mps: args.speeding_margin,
        speeding_min: args.speeding_min,
        ..TruthParams::default()
    };
    let mut true_situations = situations::true_situations(&true_steps, &params);
    let mut truth_kinds: Vec<String> = TRUE_KINDS.iter().map(ToString::to_string).collect();
    let extra = args.situations_truth.clone().or_else(|| Some(beside("truth.jsonl")).filter(|p| p.is_file()));
    if let Some(path) = extra {
        let file = kpl_core::read::open(&path).map_err(|e| (2, format!("{}: {e}", path.display())))?;
        let kinds = situations::add_true_situations(std::io::BufReader::new(file), &mut true_situations)
            .map_err(|e| (1, format!("{}: {e}", path.display())))?;
        truth_kinds.extend(kinds.into_iter().filter(|k| !TRUE_KINDS.contains(&k.as_str())));
    }
    let truth_kinds: Vec<&str> = truth_kinds.iter().map(String::as_str).collect();
    let truth = &true_situations.situations;

    let recording =
        Recording::read(&args.paths).map_err(|e| (if e.is_data_error() { 1 } else { 2 }, e.to_string()))?;
    let options = Options {
        truth: args.truth.clone(),
        streams: vec![args.stream.clone()],
        config,
        ..Options::default()
    };
    let scored = kpl_score::score_recording(&recording, &options).map_err(|e| (1, e.to_string()))?;
    let Some(cars) = scored.streams.first() else {
        let why = scored.report.failed.first().map_or(String::new(), |f| format!(": {}", f.error));
        return Err((1, format!("the stream `{}` could not be scored{why}", args.stream)));
    };
    let mapping = &cars.evaluation.mapping;
    let mut recognised = Vec::new();
    for file in jsonl_files(&args.paths).map_err(|e| (2, e))? {
        let (found, bad) =
            situations::read_situations_file(&file).map_err(|e| (2, format!("{}: {e}", file.display())))?;
        if bad > 0 {
            eprintln!("warning: {}: {bad} lines that are not JSON, left out", file.display());
        }
        recognised.extend(found);
    }
    let matched = situations::match_situations(
        &recognised,
        &true_situations,
        &truth_kinds,
        mapping,
        &MatchOptions { slack },
    );
    let text = match args.format {
        Format::Table => {
            let left_out = matched.recognised.iter().filter(|r| r.left_out).count();
            let kinds: Vec<&str> = recognised.iter().map(|r| r.kind.as_str()).collect();
            let streams = run_streams(&args.paths, &kinds);
            let (shown, absent): (Vec<KindScore>, Vec<KindScore>) =
                matched.scores.iter().cloned().partition(|s| {
                    s.recognised > 0 || streams.as_ref().is_some_and(|names| names.contains(&s.kind))
                });
            let mut text = table(&shown, true_situations.entering.len(), left_out, &params, &truth_kinds);
            text.push_str(&not_in_run(&absent, streams.is_some()));
            text
        }
        Format::Json => {
            let truth: Vec<TrueItem<'_>> = truth
                .iter()
                .zip(&matched.found)
                .map(|(situation, &found)| TrueItem { situation, found })
                .collect();
            let output = Output {
                scores: &matched.scores,
                truth_params: &params,
                truth: &truth,
                entering: &true_situations.entering,
                recognised: &matched.recognised,
            };
            serde_json::to_string_pretty(&output).map_err(|e| (2, e.to_string()))? + "\n"
        }
    };
    let mut stdout = std::io::stdout().lock();
    if let Err(e) = stdout.write_all(text.as_bytes()).and_then(|()| stdout.flush()) {
        return Err((2, format!("standard output: {e}")));
    }
    Ok(ExitCode::SUCCESS)
}

/// The longest --slack, seconds: a day (a longer one lets any two situations of a recording
/// overlap, and times near the ends of 64 bits would overflow).
const MAX_SLACK_S: f64 = 86_400.0;

/// A slack in seconds, from 0 to [`MAX_SLACK_S`], as microseconds.
fn parse_slack(text: &str) -> Result<kpl_core::Time, String> {
    let seconds: f64 = text.trim().parse().map_err(|_| format!("`{text}` is not a number of seconds"))?;
    if !(0.0..=MAX_SLACK_S).contains(&seconds) {
        return Err(format!("{text} s is out of range: the slack is 0 to {MAX_SLACK_S} s"));
    }
    Ok((seconds * 1e6).round() as kpl_core::Time)
}

/// A speeding margin, m/s: 0 to 100.
fn parse_margin(text: &str) -> Result<f64, String> {
    let mps: f64 = text.trim().parse().map_err(|_| format!("`{text}` is not a speed in m/s"))?;
    if !(0.0..=100.0).contains(&mps) {
        return Err(format!("{text} m/s is out of range: the speeding margin is 0 to 100 m/s"));
    }
    Ok(mps)
}

/// The traffic's vehicles on the network: road, lane, centre along the lane, the lane's limit
/// and direction. A vehicle on a lane the network does not have (a recording simulated on
/// another network, as the `wrong_way` scenario's) is placed on the network's lane nearest to its
/// centre, whatever its direction.
fn true_steps(
    steps: &[kpl_sim::recorded::Step],
    network: &RoadNetwork,
    path: &Path,
) -> Result<Vec<TrueStep>, (u8, String)> {
    let origin = steps.first().map_or(0, |s| s.time);
    let mut out = Vec::with_capacity(steps.len());
    let mut missing = 0usize;
    for step in steps {
        let mut vehicles = Vec::with_capacity(step.vehicles.len());
        for v in &step.vehicles {
            let (Some(lane_name), Some(front), Some(speed)) = (&v.lane, v.lane_pos, v.speed_mps) else {
                missing += 1;
                continue;
            };
            let at = match network.lane_by_name(lane_name) {
                Some(lane) => Some((lane.id, front - v.length_m / 2.0)),
                None => network
                    .snap(v.pos, &SnapHint::default())
                    .filter(|s| s.lateral_m.abs() <= network.lane(s.lane).width_m / 2.0)
                    .map(|s| (s.lane, s.offset_m)),
            };
            let Some((lane_id, lane_pos)) = at else {
                missing += 1;
                continue;
            };
            let lane = network.lane(lane_id);
            let road = match lane.kind {
                LaneKind::Road { road, .. } => Some(network.road(road).name.clone()),
                LaneKind::Connector { .. } => None,
            };
            let lane_heading = lane.path.heading_at(lane_pos);
            vehicles.push(TrueVehicle {
                id: v.name.to_string(),
                road,
                lane: lane.name.to_string(),
                lane_pos,
                lane_length: lane.path.length(),
                speed,
                speed_limit: lane.speed_limit_mps,
                length: v.length_m,
                heading: v.heading.unwrap_or(lane_heading),
                lane_heading,
            });
        }
        out.push(TrueStep { time: step.time - origin, vehicles });
    }
    if missing > 0 && out.iter().all(|s| s.vehicles.is_empty()) {
        return Err((
            1,
            format!(
                "{}: no vehicle has `lane`, `pos` and `speed` on the network's lanes (make FCD with --fcd-output.attributes x,y,angle,type,speed,lane,pos)",
                path.display()
            ),
        ));
    }
    if missing > 0 {
        eprintln!(
            "warning: {missing} vehicle records without `lane`, `pos` or `speed` on the network, left out"
        );
    }
    Ok(out)
}

/// The `.jsonl` files of the paths (folders searched recursively), sorted.
fn jsonl_files(paths: &[PathBuf]) -> Result<Vec<PathBuf>, String> {
    let mut out = Vec::new();
    for path in paths {
        if path.is_dir() {
            let mut stack = vec![path.clone()];
            while let Some(dir) = stack.pop() {
                let entries = std::fs::read_dir(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
                for entry in entries {
                    let p = entry.map_err(|e| format!("{}: {e}", dir.display()))?.path();
                    if p.is_dir() {
                        stack.push(p);
                    } else if p.extension().is_some_and(|e| e == "jsonl") {
                        out.push(p);
                    }
                }
            }
        } else {
            out.push(path.clone());
        }
    }
    out.sort();
    Ok(out)
}

/// The stream names of the run that made the recording, from its `summary.json` (in a recording
/// directory or the one above it, where `kpl run --out DIR` writes it), if that summary names
/// every stream whose situations are recorded (else it is another run's, or there is none).
fn run_streams(paths: &[PathBuf], recorded: &[&str]) -> Option<std::collections::BTreeSet<String>> {
    const SUMMARY_LIMIT: usize = 64 << 20;
    for path in paths.iter().filter(|p| p.is_dir()) {
        for dir in [Some(path.as_path()), path.parent()].into_iter().flatten() {
            let Ok(bytes) = kpl_core::read::read_file(&dir.join("summary.json"), SUMMARY_LIMIT) else {
                continue;
            };
            let Ok(json) = serde_json::from_slice::<serde_json::Value>(&bytes) else { continue };
            let names: std::collections::BTreeSet<String> = json["summary"]["streams"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|s| s["stream"].as_str().map(str::to_string))
                .collect();
            if recorded.iter().all(|k| names.contains(*k)) {
                return Some(names);
            }
        }
    }
    None
}

/// The line under the table for the kinds with true situations that the run recognised none of
/// and had no stream for (a spec without that monitor or chronicle): they are not scored as a
/// recall of 0.
fn not_in_run(absent: &[KindScore], known: bool) -> String {
    let with_truth: Vec<String> =
        absent.iter().filter(|s| s.truth > 0).map(|s| format!("{} ({} true)", s.kind, s.truth)).collect();
    if with_truth.is_empty() {
        return String::new();
    }
    let why =
        if known { "the run has no stream of these kinds" } else { "no summary.json of this run names them" };
    format!("not recognised in this recording, not scored ({why}): {}\n", with_truth.join(", "))
}

fn table(
    scores: &[KindScore],
    entering: usize,
    left_out: usize,
    params: &TruthParams,
    truth_kinds: &[&str],
) -> String {
    // The kind column is as wide as the longest kind (13 at least: `tailgating` and the header).
    let width = scores.iter().map(|s| s.kind.len()).max().unwrap_or(0).max(13);
    let mut out =
        format!("{:<width$} recognised  correct  precision   true  found  recall  unmapped\n", "kind");
    let ratio = |r: Option<f64>| r.map_or_else(|| "-".to_string(), |x| format!("{x:.3}"));
    for s in scores {
        out.push_str(&format!(
            "{:<width$} {:>10} {:>8} {:>10} {:>6} {:>6} {:>7} {:>9}\n",
            s.kind,
            s.recognised,
            s.correct,
            ratio(s.precision),
            s.truth,
            s.found,
            ratio(s.recall),
            s.unmapped
        ));
    }
    if entering > 0 {
        out.push_str(&format!(
            "{entering} true situations left out: they happen within {} s of a vehicle's first appearance\n",
            params.settle as f64 / 1e6
        ));
    }
    if left_out > 0 {
        out.push_str(&format!(
            "{left_out} recognised situations match true ones left out (correct, not in recall)\n"
        ));
    }
    let uncovered: Vec<&str> =
        scores.iter().filter(|s| !truth_kinds.contains(&s.kind.as_str())).map(|s| s.kind.as_str()).collect();
    if !uncovered.is_empty() {
        out.push_str(&format!(
            "no truth for: {} (only {} are computed from the traffic or given by --situations-truth)\n",
            uncovered.join(", "),
            truth_kinds.join(", ")
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_slack_is_from_zero_to_a_day() {
        assert_eq!(parse_slack("2"), Ok(2_000_000));
        assert_eq!(parse_slack("0"), Ok(0));
        assert_eq!(parse_slack("0.5"), Ok(500_000));
        for bad in ["-1", "1e300", "86401", "NaN", "inf", "soon"] {
            assert!(parse_slack(bad).is_err(), "{bad}");
        }
    }
}
