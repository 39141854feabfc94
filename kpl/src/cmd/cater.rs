//! `kpl cater`: generate CATER-style videos in LA-CATER's layout and evaluate snitch localisation
//! (the AAPA paper's Table I). Exit codes: 0 done, 1 the data is bad, 2 usage or I/O errors.
#![allow(clippy::print_stderr, reason = "the kpl binary is the one crate that prints")]

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::{Args, Subcommand, ValueEnum};
use kpl_aapa::Params;
use kpl_cater::CaterError;
use kpl_cater::dataset::{self, Perception};
use kpl_cater::eval::{self, EvalOptions, Report};
use kpl_cater::models::Model;
use kpl_cater::score::{Category, CategoryTable};

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Generate videos: scene JSON, `<video>_bb.json` ground truth, perfect and detector perception.
    #[command(
        after_help = "Example:\n  kpl cater generate --videos 20 --seed 1 --out /tmp/cater\n\nLA-CATER's test set has 1371 videos (docs/cater.md)."
    )]
    Generate(GenerateArgs),
    /// Run a model over a data directory and print mean IoU and L2 per category (Table I's layout).
    #[command(
        after_help = "Examples (after `kpl cater generate --videos 20 --seed 1 --out /tmp/cater`):\n  kpl cater eval --data /tmp/cater --model aapa --perception perfect\n  \
                            kpl cater eval --data /tmp/cater --model heuristic --perception detector --json /tmp/h.json"
    )]
    Eval(EvalArgs),
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
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

#[derive(Debug, Clone, Copy, ValueEnum)]
enum ModelArg {
    /// AAPA with CATER's actions (this implementation's extensions on).
    Aapa,
    /// OPNet's programmed baseline: nearest object to the last known location, with its stack.
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
    /// The simulated noisy detector.
    Detector,
}

#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Data directory written by `kpl cater generate` (or LA-CATER data in the same layout).
    #[arg(long)]
    data: PathBuf,
    #[arg(long, value_enum)]
    model: ModelArg,
    #[arg(long, value_enum)]
    perception: PerceptionArg,
    /// Also write the results as JSON to this file.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// AAPA parameters as JSON (missing fields keep the model's defaults).
    #[arg(long, value_name = "FILE")]
    params: Option<PathBuf>,
    /// Write each video's predictions as `<video>_bb.json` into this directory.
    #[arg(long, value_name = "DIR")]
    predictions: Option<PathBuf>,
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

fn threads(requested: Option<usize>) -> usize {
    requested.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get())).max(1)
}

fn generate(args: GenerateArgs) -> Result<(), Failure> {
    let started = Instant::now();
    let manifest = dataset::generate(&args.out, args.videos, args.seed, threads(args.threads))?;
    eprintln!(
        "generated {} videos (seed {}) in {} in {:.1} s",
        manifest.videos,
        manifest.seed,
        args.out.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

fn evaluate(args: EvalArgs) -> Result<(), Failure> {
    let model = match args.model {
        ModelArg::Aapa => Model::Aapa,
        ModelArg::Heuristic => Model::Heuristic,
        ModelArg::AapaNoActions => Model::AapaNoActions,
        ModelArg::AapaPaper => Model::AapaPaper,
    };
    let perception = match args.perception {
        PerceptionArg::Perfect => Perception::Perfect,
        PerceptionArg::Detector => Perception::Detector,
    };
    let params = match &args.params {
        None => None,
        Some(path) => Some(read_params(path, model, perception)?),
    };
    let started = Instant::now();
    let report = eval::evaluate(&EvalOptions {
        data: args.data.clone(),
        model,
        perception,
        params,
        threads: threads(args.threads),
        predictions_dir: args.predictions.clone(),
    })?;
    let elapsed = started.elapsed().as_secs_f64();
    let mut stdout = std::io::stdout().lock();
    let write_error = |e: std::io::Error| Failure::Usage(format!("writing the table: {e}"));
    stdout.write_all(table(&report).as_bytes()).map_err(write_error)?;
    eprintln!("evaluated {} videos in {elapsed:.2} s", report.videos);
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&json_report(&report))
            .map_err(|e| Failure::Usage(format!("encoding the JSON report: {e}")))?;
        std::fs::write(path, text + "\n").map_err(|e| Failure::Usage(format!("{}: {e}", path.display())))?;
    }
    Ok(())
}

fn read_params(path: &std::path::Path, model: Model, perception: Perception) -> Result<Params, Failure> {
    let text =
        std::fs::read_to_string(path).map_err(|e| Failure::Usage(format!("{}: {e}", path.display())))?;
    // Fields missing from the file keep the model's defaults.
    let mut base = serde_json::to_value(model.default_params(perception))
        .map_err(|e| Failure::Usage(format!("encoding default parameters: {e}")))?;
    let overrides: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| Failure::Data(format!("{}: {e}", path.display())))?;
    let (Some(base_map), serde_json::Value::Object(over)) = (base.as_object_mut(), overrides) else {
        return Err(Failure::Data(format!("{}: expected a JSON object of AAPA parameters", path.display())));
    };
    base_map.extend(over);
    serde_json::from_value(base).map_err(|e| Failure::Data(format!("{}: {e}", path.display())))
}

/// `{"model", "perception", "videos", "iou": {category: {mean, sem}}, "l2": {...}}`.
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
    serde_json::json!({
        "model": report.model,
        "perception": report.perception,
        "videos": report.videos,
        "iou": metric(&report.iou),
        "l2": metric(&report.l2),
    })
}

fn table(report: &Report) -> String {
    let mut out = format!("{} videos, {} perception\n", report.videos, report.perception);
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
