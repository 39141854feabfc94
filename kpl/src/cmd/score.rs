//! `kpl score`: compares recorded object streams (percepts, world objects, on-road objects, cars)
//! with the ground truth of the same run and prints MOT metrics and HOTA per stream, as a table
//! or JSON; optionally exports MOTChallenge-style files. The work is `kpl_score`'s.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args as ClapArgs, ValueEnum};
use kpl_camera::formats::Format as TruthFormat;
use kpl_score::{AlignOptions, Config, Missing, Options, Recording, ScoredStream, TruthFile, motchallenge};

const AFTER_HELP: &str = "\
Examples:
  kpl run specs/traffic/bridge.kpl --for 60s && kpl score out/bridge
  kpl score out/bridge --stream onroad_car --max-distance 2 --format json
  kpl score out/bridge/tracks.jsonl --truth tracker.truth --export out/mot
  kpl run specs/mot/image_plane.kpl --out out/mot && kpl score out/mot --gt specs/mot/gt.txt

Every object stream of the recording (lists of records with `id` and `pos`: percepts, link
outputs; a world model is scored per type) is compared with the ground truth (the stream named
`*.truth`, the tracker's `truth` port) at the same valid times. Metrics: MOTA, MOTP (metres), IDF1,
IDP, IDR, identity switches, fragmentations, mostly tracked / partially tracked / mostly lost
(py-motmetrics' definitions), HOTA, DetA, AssA, LocA (TrackEval's, similarity max(0, 1 - d / Z)
with Z twice the gate). Branch objects of predictions split at junctions (records with
`branch_of`) are hypotheses, not objects: they are left out and counted unless --branches.
With --gt, the ground truth is a data set's file (MOTChallenge's gt.txt, VisDrone, UA-DETRAC XML,
COCO JSON; frame f at (f - first) / fps) and every stream of boxes (records with `box`: [left,
top, width, height] in pixels) is scored by IoU as MOTChallenge's evaluation scores it (--iou,
0.5), on what each stream measured (records with `measured: false`, predicted states, are left
out as a tracker's file has none; --predicted scores them too). See docs/scoring.md.
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
    /// Ground truth from a data set's file (boxes in pixels, e.g. MOTChallenge's gt.txt) instead
    /// of a recorded stream; the streams of boxes are scored by IoU.
    #[arg(long, value_name = "FILE", conflicts_with = "truth")]
    gt: Option<PathBuf>,
    /// The format of --gt (default: by its name: `.xml` UA-DETRAC, `.json` COCO, else MOTChallenge).
    #[arg(long, value_enum, requires = "gt")]
    gt_format: Option<GtFormat>,
    /// Frames per second of --gt (default: `frameRate` of the sequence's seqinfo.ini, else 25).
    #[arg(long, value_name = "FPS", requires = "gt")]
    fps: Option<f64>,
    /// The frame of --gt at valid time 0.
    #[arg(long, value_name = "FRAME", default_value_t = 1, requires = "gt")]
    first_frame: i64,
    /// Boxes of --gt with a lower score are left out (MOTChallenge's ground truth flags boxes not
    /// to be considered with 0).
    #[arg(long, value_name = "SCORE", default_value_t = 1.0, requires = "gt")]
    min_score: f64,
    /// Score boxes (records with `box`) by intersection over union: a pair matches at this IoU or
    /// more (the default with --gt: 0.5, MOTChallenge's).
    #[arg(long, value_name = "THRESHOLD", conflicts_with_all = ["max_distance", "hota_zero_distance"])]
    iou: Option<f64>,
    /// With --gt: score predicted states too (records with `measured: false`); by default a run is
    /// scored against a data set's ground truth as a tracker's output is, on what it measured.
    #[arg(long, requires = "gt", conflicts_with = "measured_only")]
    predicted: bool,
    /// Leave out true objects out of the sensor's view (records with `in_view: false`) and the
    /// hypotheses closest to them within the gate: neither misses nor false positives.
    #[arg(long)]
    in_view_only: bool,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum GtFormat {
    /// MOTChallenge's text format (gt.txt).
    Motchallenge,
    /// VisDrone's MOT text format.
    Visdrone,
    /// UA-DETRAC's XML annotations.
    Detrac,
    /// COCO-style JSON.
    Coco,
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
    let iou = args.iou.or(args.gt.as_ref().map(|_| kpl_score::DEFAULT_IOU));
    let config = match iou.map_or_else(
        || {
            Config::new(args.max_distance)
                .and_then(|c| args.hota_zero_distance.map_or(Ok(c), |z| c.with_hota_zero_distance(z)))
        },
        Config::iou,
    ) {
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
    let external_truth = match args.gt.as_ref().map(|gt| truth_file(gt, &args)) {
        None => None,
        Some(Ok(truth)) => Some(truth),
        Some(Err(code)) => return code,
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
            measured_only: args.measured_only || (args.gt.is_some() && !args.predicted),
            score_branches: args.branches,
            boxes: iou.is_some(),
            whole_truth: args.gt.is_some(),
            in_view_only: args.in_view_only,
            ignore_gate: config.max_distance(),
        },
        external_truth,
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

/// The ground truth of --gt as a stream (its problems and the frame rate used printed as notes).
fn truth_file(gt: &Path, args: &Args) -> Result<kpl_score::ObjectStream, ExitCode> {
    let name = gt.to_string_lossy();
    let format = match args.gt_format {
        Some(GtFormat::Motchallenge) => TruthFormat::MotChallenge,
        Some(GtFormat::Visdrone) => TruthFormat::VisDrone,
        Some(GtFormat::Detrac) => TruthFormat::Detrac,
        Some(GtFormat::Coco) => TruthFormat::Coco,
        None if name.ends_with(".xml") => TruthFormat::Detrac,
        None if name.ends_with(".json") => TruthFormat::Coco,
        None => TruthFormat::MotChallenge,
    };
    let info = kpl_score::seqinfo(gt);
    let fps = match (args.fps, info.as_ref().and_then(|(_, i)| i.frame_rate)) {
        (Some(fps), _) => fps,
        (None, Some(fps)) => {
            eprintln!(
                "note: {fps} frames per second, from {}",
                info.as_ref().map_or(String::new(), |(f, _)| f.display().to_string())
            );
            fps
        }
        (None, None) => {
            eprintln!("note: 25 frames per second (no --fps and no seqinfo.ini beside {})", gt.display());
            25.0
        }
    };
    if !(fps.is_finite() && fps > 0.0 && fps <= 1e6) {
        eprintln!("error: --fps must be above 0 and at most 1000000, not {fps}");
        return Err(ExitCode::from(2));
    }
    let truth = TruthFile {
        path: gt.to_path_buf(),
        format,
        fps,
        first_frame: args.first_frame,
        last_frame: info.and_then(|(_, i)| i.seq_length).map(|n| args.first_frame + n - 1),
        min_score: args.min_score,
    };
    match kpl_score::read_truth_file(&truth, &format!("gt:{}", gt.display())) {
        Ok((stream, problems)) => {
            for p in problems.iter().take(8) {
                eprintln!("warning: {p}");
            }
            if problems.len() > 8 {
                eprintln!("warning: ... {} more problems in {}", problems.len() - 8, gt.display());
            }
            Ok(stream)
        }
        Err(e) => {
            eprintln!("error: {e}");
            Err(ExitCode::from(2))
        }
    }
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
