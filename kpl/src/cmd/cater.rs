//! `kpl cater`: generate CATER videos in LA-CATER's layout and evaluate snitch localisation (the AAPA
//! paper's Table I) on them or on LA-CATER's own files. Exit codes: 0 done, 1 the data is bad (or,
//! with `--strict`, a video was skipped), 2 usage or I/O errors.
#![allow(clippy::print_stderr, reason = "the kpl binary is the one crate that prints")]

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use clap::{Args, Subcommand, ValueEnum};
use kpl_cater::CaterError;
use kpl_cater::dataset::{self, GeneratorConfig, Layout, Manifest};
use kpl_cater::eval::{self, Boxes, EvalOptions, PerceptionSource, Report, VisibleFrom, per_video_csv};
use kpl_cater::formats;
use kpl_cater::layout::{self, Perception};
use kpl_cater::models::Model;
use kpl_cater::score::{Category, CategoryTable, FramesScored};
use kpl_cater::sim::Motion;

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Generate videos by CATER's procedure: scene JSON, `<video>_bb.json`, perfect and detector
    /// perception, OPNet's annotation files.
    #[command(after_help = "Examples:\n  kpl cater generate --videos 20 --seed 1 --out out/cater\n  \
                      kpl cater generate --videos 20 --seed 2 --motion all --out out/cater-all\n  \
                      kpl cater generate --videos 20 --seed 3 --motion hard --layout la-cater --out out/la-hard\n\n\
                      LA-CATER's test set has 1371 videos (docs/cater.md).")]
    Generate(GenerateArgs),
    /// Run a model over a data directory and print mean IoU and L2 per category (Table I's layout).
    #[command(after_help = "Examples (after `kpl cater generate --videos 20 --seed 1 --out out/cater`):\n  \
                      kpl cater eval --data out/cater --model aapa --perception perfect\n  \
                      kpl cater eval --data out/cater --model heuristic --perception detector --json out/h.json\n  \
                      kpl cater eval --data out/cater --model aapa --frames from-first-detection\n  \
                      kpl cater eval --data out/cater --model aapa --per-video out/aapa.csv\n\n\
                      LA-CATER's own files: --pickles DIR reads OPNet's perception pickles, --videos FILE a split, \
                      --annotations DIR its annotation files (docs/cater.md).")]
    Eval(EvalArgs),
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum MotionArg {
    /// At most two objects or stacks move per segment, as LA-CATER was made.
    MaxTwo,
    /// Every object or stack moves in every segment (CATER's all_actions).
    All,
    /// This project's hard scenes: any number of moves per slot at different frames, contains onto
    /// the snitch's stack (nested cones), moving targets, four motion profiles, a winged snitch
    /// that rotates, identical objects, occlusion by the union of nearer boxes (docs/cater.md).
    Hard,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum LayoutArg {
    /// This project's: scenes/, perception/ as JSON.
    Kpl,
    /// LA-CATER's as OPNet's code reads it: scenes/, labels/, perfect_perception/, od_perception/,
    /// od_perception_b/ (OPNet's pickles), samples.txt.
    LaCater,
}

#[derive(Debug, Args)]
pub struct GenerateArgs {
    /// Number of videos.
    #[arg(long)]
    videos: usize,
    /// Random seed; the same seed gives the same files.
    #[arg(long)]
    seed: u64,
    /// Output directory (created if missing).
    #[arg(long)]
    out: PathBuf,
    /// How many objects move per segment, and how.
    #[arg(long, value_enum, default_value = "max-two")]
    motion: MotionArg,
    /// Which files to write.
    #[arg(long, value_enum, default_value = "kpl")]
    layout: LayoutArg,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum ModelArg {
    /// AAPA with CATER's actions (this implementation's extensions on).
    Aapa,
    /// OPNet's programmed heuristic, as its code outputs it.
    Heuristic,
    /// AAPA without actions (the ablation).
    AapaNoActions,
    /// AAPA as published: no extensions, attachments from `_contain` only.
    AapaPaper,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum PerceptionArg {
    /// Ground-truth boxes of the visible objects.
    Perfect,
    /// The simulated detector (calibrated against the AAPA paper's Faster R-CNN).
    Detector,
    /// The second, independent simulated detector.
    DetectorB,
}

impl PerceptionArg {
    fn perception(self) -> Perception {
        match self {
            PerceptionArg::Perfect => Perception::Perfect,
            PerceptionArg::Detector => Perception::Detector,
            PerceptionArg::DetectorB => Perception::DetectorB,
        }
    }
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum FramesArg {
    /// Every frame, as OPNet's analysis scores.
    All,
    /// From the first frame the snitch is perceived in, as the AAPA paper scores (IV-C).
    FromFirstDetection,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum VisibleArg {
    /// OPNet's definition: not in a cone and not covered by a nearer, larger object's box.
    Opnet,
    /// The snitch is in the perfect perception.
    Perception,
}

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Data directory, in this project's layout or LA-CATER's as it comes: `scenes/` (scene JSON,
    /// and `<video>_bb.json` there or in `labels/`), the perception in `perception/` (this
    /// project's JSON) or `perfect_perception/` and `od_perception/` (OPNet's pickles), OPNet's
    /// annotation files in `containment_and_occlusions/`.
    #[arg(long)]
    data: PathBuf,
    #[arg(long, value_enum)]
    model: ModelArg,
    /// Which perception (default: perfect). With --pickles it says what the pickles are; without,
    /// their boxes are measured: exact if every box is the ground truth's.
    #[arg(long, value_enum)]
    perception: Option<PerceptionArg>,
    /// Read OPNet's per-video perception pickles (`<video>.pkl`) from this directory instead.
    #[arg(long, value_name = "DIR")]
    pickles: Option<PathBuf>,
    /// Evaluate only the videos this file lists (one name or path per line, OPNet's samples file).
    #[arg(long, value_name = "FILE")]
    videos: Option<PathBuf>,
    /// OPNet's annotation files (containment, containment with move, visibility > 0); default
    /// `DATA/containment_and_occlusions` when it exists, else computed from the scenes.
    #[arg(long, value_name = "DIR")]
    annotations: Option<PathBuf>,
    /// Which frames are scored.
    #[arg(long, value_enum, default_value = "all")]
    frames: FramesArg,
    /// How the visible category is decided.
    #[arg(long, value_enum, default_value = "opnet")]
    visible: VisibleArg,
    /// Also write the results as JSON to this file.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// Write each video's results as CSV to this file.
    #[arg(long, value_name = "FILE")]
    per_video: Option<PathBuf>,
    /// AAPA parameters as JSON (missing fields keep the model's defaults).
    #[arg(long, value_name = "FILE")]
    params: Option<PathBuf>,
    /// Write each video's predictions as `<video>_bb.json` into this directory.
    #[arg(long, value_name = "DIR")]
    predictions: Option<PathBuf>,
    /// Also write this video's world state in every frame (AAPA's anchors, attachments, bindings)
    /// as `<video>_worlds.jsonl` into the --predictions directory; may be given several times.
    #[arg(long, value_name = "VIDEO", requires = "predictions")]
    trace: Vec<String>,
    /// Exit with 1 if any video was skipped (they are always listed).
    #[arg(long)]
    strict: bool,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

pub fn run(command: Command) -> ExitCode {
    let result = match command {
        Command::Generate(args) => generate(args),
        Command::Eval(args) => evaluate(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure::Data(message)) => {
            eprintln!("error: {message}");
            ExitCode::from(1)
        }
        Err(Failure::Usage(message)) => {
            eprintln!("error: {message}");
            ExitCode::from(2)
        }
    }
}

enum Failure {
    /// The input data is bad: exit 1.
    Data(String),
    /// Usage or I/O: exit 2.
    Usage(String),
}

impl From<CaterError> for Failure {
    fn from(e: CaterError) -> Failure {
        if e.is_data_error() { Failure::Data(e.to_string()) } else { Failure::Usage(e.to_string()) }
    }
}

/// The most bytes a `--params` file may have (it holds a few dozen parameters).
const MAX_PARAMS_BYTES: u64 = 1 << 20;

fn threads(requested: Option<usize>) -> usize {
    requested.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())).max(1)
}

fn generate(args: GenerateArgs) -> Result<(), Failure> {
    #[allow(clippy::disallowed_methods)] // how long the command took, reported beside its results
    let started = Instant::now();
    let config = GeneratorConfig {
        motion: match args.motion {
            MotionArg::MaxTwo => Motion::MaxTwo,
            MotionArg::All => Motion::All,
            MotionArg::Hard => Motion::Hard,
        },
        layout: match args.layout {
            LayoutArg::Kpl => Layout::Kpl,
            LayoutArg::LaCater => Layout::LaCater,
        },
        ..GeneratorConfig::default()
    };
    let manifest = dataset::generate(&args.out, args.videos, args.seed, threads(args.threads), &config)?;
    eprintln!(
        "generated {} videos (seed {}, motion {}) in {} in {:.1} s",
        manifest.videos,
        manifest.seed,
        manifest.motion,
        args.out.display(),
        started.elapsed().as_secs_f64()
    );
    eprintln!("{}", frame_mix(&manifest));
    Ok(())
}

fn frame_mix(manifest: &Manifest) -> String {
    let m = &manifest.frame_mix;
    format!(
        "frames: {:.1} % visible, {:.1} % occluded, {:.1} % contained ({:.1} % carried); the snitch is contained in {} of {} videos",
        m.percent(m.visible),
        m.percent(m.occluded),
        m.percent(m.contained),
        m.percent(m.carried),
        m.videos_with_containment,
        manifest.videos
    )
}

fn evaluate(args: EvalArgs) -> Result<(), Failure> {
    let model = match args.model {
        ModelArg::Aapa => Model::Aapa,
        ModelArg::Heuristic => Model::Heuristic,
        ModelArg::AapaNoActions => Model::AapaNoActions,
        ModelArg::AapaPaper => Model::AapaPaper,
    };
    let perception = match &args.pickles {
        Some(dir) => PerceptionSource::Pickles {
            dir: dir.clone(),
            boxes: match args.perception {
                None => Boxes::Measured,
                Some(p) if p.perception().exact() => Boxes::Exact,
                Some(_) => Boxes::Noisy,
            },
        },
        None => PerceptionSource::find(
            &args.data,
            args.perception.map_or(Perception::Perfect, PerceptionArg::perception),
        )?,
    };
    let param_overrides = match &args.params {
        None => None,
        Some(path) => {
            let text = formats::read_capped_text(path, MAX_PARAMS_BYTES)?;
            let value: serde_json::Value =
                serde_json::from_str(&text).map_err(|e| Failure::Data(format!("{}: {e}", path.display())))?;
            if !value.is_object() {
                return Err(Failure::Data(format!(
                    "{}: expected a JSON object of AAPA parameters",
                    path.display()
                )));
            }
            Some(value)
        }
    };
    let videos = match &args.videos {
        None => None,
        Some(path) => Some(layout::read_video_list(path)?),
    };
    let visible = match args.visible {
        VisibleArg::Opnet => VisibleFrom::Opnet,
        VisibleArg::Perception => {
            VisibleFrom::Perception(PerceptionSource::find(&args.data, Perception::Perfect)?)
        }
    };
    #[allow(clippy::disallowed_methods)] // how long the command took, reported beside its results
    let started = Instant::now();
    let report = eval::evaluate(&EvalOptions {
        data: args.data.clone(),
        model,
        perception,
        params: None,
        param_overrides,
        threads: threads(args.threads),
        predictions_dir: args.predictions.clone(),
        videos,
        annotations: args.annotations.clone(),
        frames: match args.frames {
            FramesArg::All => FramesScored::All,
            FramesArg::FromFirstDetection => FramesScored::FromFirstDetection,
        },
        visible,
        trace: args.trace.clone(),
    })?;
    let elapsed = started.elapsed().as_secs_f64();
    let mut stdout = std::io::stdout().lock();
    let write_error = |e: std::io::Error| Failure::Usage(format!("writing the table: {e}"));
    stdout.write_all(table(&report).as_bytes()).map_err(write_error)?;
    for s in report.skipped.iter().take(20) {
        eprintln!("skipped {}: {}", s.video, s.reason);
    }
    if report.skipped.len() > 20 {
        eprintln!("... and {} more skipped videos (all are in --json)", report.skipped.len() - 20);
    }
    if report.dropped.total() > 0 {
        eprintln!(
            "dropped {} detections in {} videos: {} with a label that names no class (such as -1), {} with a bad box",
            report.dropped.total(),
            report.dropped_videos,
            report.dropped.unknown_class,
            report.dropped.bad_box
        );
    }
    eprintln!(
        "evaluated {} videos ({} skipped) in {elapsed:.2} s; categories from {}",
        report.videos,
        report.skipped.len(),
        report.categories_from
    );
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&json_report(&report))
            .map_err(|e| Failure::Usage(format!("encoding the JSON report: {e}")))?;
        write_file(path, &(text + "\n"))?;
    }
    if let Some(path) = &args.per_video {
        write_file(path, &per_video_csv(&report))?;
    }
    if report.videos == 0 {
        return Err(Failure::Data("no video could be scored".into()));
    }
    if args.strict && !report.skipped.is_empty() {
        return Err(Failure::Data(format!("{} videos skipped (--strict)", report.skipped.len())));
    }
    Ok(())
}

fn write_file(path: &Path, text: &str) -> Result<(), Failure> {
    std::fs::write(path, text).map_err(|e| Failure::Usage(format!("{}: {e}", path.display())))
}

/// `{"model", "perception", "videos", "skipped", "frames", "categories_from", "frame_counts",
/// "iou": {category: {mean, sem, videos}}, "l2": {...}}`.
fn json_report(report: &Report) -> serde_json::Value {
    let metric = |t: &CategoryTable| {
        let mut map = serde_json::Map::new();
        for c in Category::ALL {
            let s = t.get(c);
            map.insert(
                c.name().to_owned(),
                serde_json::json!({"mean": s.mean, "sem": s.sem, "videos": s.videos}),
            );
        }
        serde_json::Value::Object(map)
    };
    let counts: serde_json::Map<String, serde_json::Value> =
        Category::ALL.iter().zip(report.frame_counts).map(|(c, n)| (c.name().to_owned(), n.into())).collect();
    serde_json::json!({
        "model": report.model,
        "perception": report.perception,
        "perception_source": report.perception_source,
        "options": report.options(),
        "params": {"exact_boxes": report.params[0], "noisy_boxes": report.params[1]},
        "noisy_videos": report.noisy_videos,
        "dropped_detections": {
            "unknown_class": report.dropped.unknown_class,
            "bad_box": report.dropped.bad_box,
            "videos": report.dropped_videos,
        },
        "videos": report.videos,
        "skipped": report.skipped,
        "frames": report.frames,
        "categories_from": report.categories_from,
        "frame_counts": counts,
        "iou": metric(&report.iou),
        "l2": metric(&report.l2),
    })
}

fn table(report: &Report) -> String {
    let mut out = format!("{} videos, {} perception\n", report.videos, report.perception);
    out.push_str(&format!("perception: {}\n", report.perception_source));
    out.push_str(&format!("options: {}\n", report.options()));
    for (title, t) in [("Mean IoU ±SEM", &report.iou), ("Mean L2 ±SEM", &report.l2)] {
        out.push_str(&format!("{title:<18}"));
        for c in Category::ALL {
            let mut name = c.name().to_owned();
            name[..1].make_ascii_uppercase();
            out.push_str(&format!("{name:>16}"));
        }
        out.push('\n');
        out.push_str(&format!("{:<18}", report.model));
        for c in Category::ALL {
            let s = t.get(c);
            out.push_str(&format!("{:>16}", format!("{:.2} ±{:.2}", s.mean, s.sem)));
        }
        out.push('\n');
    }
    out
}
