//! `kpl score`: compares recorded object streams (percepts, world objects, on-road objects, cars)
//! with the ground truth of the same run and prints MOT metrics and HOTA per stream, as a table
//! or JSON; optionally exports MOTChallenge-style files. The work is `kpl_score`'s.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args as ClapArgs, ValueEnum};
use kpl_score::{AlignOptions, Config, Missing, Options, Recording, ScoredStream, motchallenge};

const AFTER_HELP: &str = "\
Examples:
  kpl run specs/traffic/bridge.kpl --for 60s && kpl score out/bridge
  kpl score out/bridge --stream onroad_car --max-distance 2 --format json
  kpl score out/bridge/tracks.jsonl --truth tracker.truth --export out/mot

Every object stream of the recording (lists of records with `id` and `pos`: percepts, link
outputs; a world model is scored per type) is compared with the ground truth (the stream named
`*.truth`, the tracker's `truth` port) at the same valid times. Metrics: MOTA, MOTP (metres), IDF1,
IDP, IDR, identity switches, fragmentations, mostly tracked / partially tracked / mostly lost
(py-motmetrics' definitions), HOTA, DetA, AssA, LocA (TrackEval's, similarity max(0, 1 - d / Z)
with Z twice the gate). Branch objects of predictions split at junctions (records with
`branch_of`) are hypotheses, not objects: they are left out and counted unless --branches. See
docs/scoring.md.
Exit status: 0 every stream scored, 1 the recording cannot be scored as asked (no ground truth,
an unknown stream, times that do not match), 2 usage or I/O errors.";

#[derive(Debug, ClapArgs)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// A run's output folder (every `*.jsonl` below it) or recorded `.jsonl` files.
    #[arg(required = true, value_name = "RUN_DIR_OR_FILES")]
    paths: Vec<PathBuf>,
    /// The ground-truth stream (default: the one named `truth` or `*.truth`).
    #[arg(long, value_name = "STREAM")]
    truth: Option<String>,
    /// Score only this stream (repeatable; a world model's name stands for each of its types).
    #[arg(long = "stream", value_name = "STREAM")]
    streams: Vec<String>,
    /// Gating distance, metres: a true object and a hypothesis farther apart are never matched.
    #[arg(long, value_name = "METRES", default_value_t = kpl_score::DEFAULT_MAX_DISTANCE, value_parser = parse_metres)]
    max_distance: f64,
    /// The distance at which HOTA's similarity reaches zero, metres (default: twice --max-distance).
    #[arg(long, value_name = "METRES", value_parser = parse_metres)]
    hota_zero_distance: Option<f64>,
    /// Leave out states that were only predicted (records with `measured: false`).
    #[arg(long)]
    measured_only: bool,
    /// Score branch objects (records with `branch_of`: the other hypotheses of a prediction split
    /// at a junction) as tracks of their own; by default they are left out, and counted.
    #[arg(long)]
    branches: bool,
    /// What to do with ground-truth times at which a stream has no snapshot.
    #[arg(long, value_enum, default_value = "error")]
    missing: MissingArg,
    /// How to print the scores.
    #[arg(long, value_enum, default_value = "table")]
    format: Format,
    /// Also write MOTChallenge-style files (ground plane) of each scored stream into this folder.
    #[arg(long, value_name = "DIR")]
    export: Option<PathBuf>,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum MissingArg {
    /// Refuse to score the stream.
    Error,
    /// Score them as frames in which the stream saw nothing.
    Empty,
    /// Leave them out.
    Skip,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum Format {
    /// Two tables and notes.
    Table,
    /// One JSON document with every metric, per threshold for HOTA.
    Json,
}

pub fn run(args: Args) -> ExitCode {
    let config = match Config::new(args.max_distance)
        .and_then(|c| args.hota_zero_distance.map_or(Ok(c), |z| c.with_hota_zero_distance(z)))
    {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    let recording = match Recording::read(&args.paths) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(if e.is_data_error() { 1 } else { 2 });
        }
    };
    let options = Options {
        truth: args.truth.clone(),
        streams: args.streams.clone(),
        config,
        align: AlignOptions {
            missing: match args.missing {
                MissingArg::Error => Missing::Error,
                MissingArg::Empty => Missing::Empty,
                MissingArg::Skip => Missing::Skip,
            },
            measured_only: args.measured_only,
            score_branches: args.branches,
        },
    };
    let scored = match kpl_score::score_recording(&recording, &options) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(1);
        }
    };
    if let Some(dir) = &args.export {
        match export(dir, &scored.streams) {
            Ok(()) => eprintln!(
                "wrote MOTChallenge-style files of {} streams to {}",
                scored.streams.len(),
                dir.display()
            ),
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::from(2);
            }
        }
    }
    let output = match args.format {
        Format::Table => scored.report.to_text(),
        Format::Json => {
            for note in scored.report.notes.iter().cloned().chain(scored.report.stream_notes()) {
                eprintln!("note: {note}");
            }
            if scored.report.problems.count > 0 {
                eprintln!(
                    "warning: {} lines or records of the recording were left out (first: {})",
                    scored.report.problems.count,
                    scored.report.problems.examples.first().map_or("", String::as_str)
                );
            }
            match serde_json::to_string_pretty(&scored.report) {
                Ok(json) => json + "\n",
                Err(e) => {
                    eprintln!("error: {e}");
                    return ExitCode::from(2);
                }
            }
        }
    };
    let mut stdout = std::io::stdout().lock();
    if let Err(e) = stdout.write_all(output.as_bytes()).and_then(|()| stdout.flush()) {
        eprintln!("error: standard output: {e}");
        return ExitCode::from(2);
    }
    for failed in &scored.report.failed {
        eprintln!("error: {}", failed.error);
    }
    if scored.report.failed.is_empty() { ExitCode::SUCCESS } else { ExitCode::from(1) }
}

/// The largest distance option accepted, metres: a gate wider than a country matches anything
/// with anything, and is a mistake of units.
const MAX_METRES: f64 = 1e6;

/// A distance in metres: positive, at most [`MAX_METRES`].
pub(super) fn parse_metres(text: &str) -> Result<f64, String> {
    let metres: f64 = text.trim().parse().map_err(|_| format!("`{text}` is not a number of metres"))?;
    if !(metres > 0.0 && metres <= MAX_METRES) {
        return Err(format!(
            "{text} m is out of range: a distance is more than 0 and at most {MAX_METRES:e} m"
        ));
    }
    Ok(metres)
}

/// Writes each stream's files into a folder named after it.
fn export(dir: &Path, streams: &[ScoredStream]) -> Result<(), String> {
    let mut used = std::collections::HashSet::new();
    for s in streams {
        let mut name = folder_name(&s.stream);
        while !used.insert(name.clone()) {
            name.push('_');
        }
        let folder = dir.join(&name);
        std::fs::create_dir_all(&folder).map_err(|e| format!("{}: {e}", folder.display()))?;
        for file in motchallenge::export(&s.aligned.sequence, Some(&s.evaluation.mapping)) {
            let path = folder.join(file.name);
            std::fs::write(&path, file.contents).map_err(|e| format!("{}: {e}", path.display()))?;
        }
    }
    Ok(())
}

/// A stream name as a folder name: `world[Car]` -> `world_Car_` (never `.` or `..`).
fn folder_name(stream: &str) -> String {
    let name: String = stream
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_') { c } else { '_' })
        .collect();
    if name.chars().all(|c| c == '.') { name.replace('.', "_") + "_" } else { name }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances_are_positive_and_bounded() {
        assert_eq!(parse_metres("2.5"), Ok(2.5));
        assert_eq!(parse_metres("1e6"), Ok(1e6));
        for bad in ["0", "-1", "1e9", "NaN", "inf", "far"] {
            assert!(parse_metres(bad).is_err(), "{bad}");
        }
        assert_eq!(
            parse_metres("0").unwrap_err(),
            "0 m is out of range: a distance is more than 0 and at most 1e6 m"
        );
    }
}
