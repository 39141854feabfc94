//! `kpl view`: a recording in the browser (docs/view.md), and what `kpl run --view ADDR
//! --foxglove ADDR` adds to a spec to show a run while it goes: a `view.live` sink over the
//! spec's objects (link outputs), percepts and monitors.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use clap::Args as ClapArgs;
use kpl_core::{Time, ValueType};
use kpl_mcap::scene::Scene;
use kpl_semantic::hir;
use kpl_view::hub::Hub;

use crate::report::{self, DiagnosticFormat, Reporter, SourceFile};

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  kpl run specs/traffic/sumo_situations.kpl --for 60s --out out/situations\n  kpl view out/situations --spec specs/traffic/sumo_situations.kpl --http 127.0.0.1:0 --for 2s\n  kpl run specs/ok/tracker.kpl --for 5s && kpl view out/tracker --http 127.0.0.1:0 --for 2s\n\nServes a page at --http (open it in a browser): the map (roads, lanes, occluders and camera\nfootprint of --spec), each level's objects with their symbols (predicted ones hollow), the\npercepts, a time slider, the situations recognised (click one to jump to it) and counters per\nlevel. To watch a run while it goes: kpl run SPEC --view 127.0.0.1:8080 (and --foxglove\n127.0.0.1:8765 for Foxglove). Serves until Ctrl-C, or for --for.\nExit status: 0 done, 1 some lines or messages were not samples, 2 usage or I/O errors."
)]
pub struct Args {
    /// Recordings: .jsonl and .mcap files, or directories of them (a run's --out).
    #[arg(required = true)]
    pub recordings: Vec<PathBuf>,
    /// The spec that made them: its road network, occluders and camera are drawn under them.
    #[arg(long)]
    pub spec: Option<PathBuf>,
    /// Where the page is served (HOST:PORT; port 0: any free one).
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub http: String,
    /// Serve this long, then end (e.g. 30s, 5min); without it, until Ctrl-C.
    #[arg(long = "for", value_parser = super::run::parse_duration)]
    pub duration: Option<Time>,
}

pub fn run(args: Args) -> ExitCode {
    let scene = match &args.spec {
        Some(path) => match super::check::load_checked(path) {
            Ok(spec) => scene_of(&spec, path),
            Err(code) => return code,
        },
        None => Scene::default(),
    };
    let files = match kpl_view::recording::files(&args.recordings) {
        Ok(files) if !files.is_empty() => files,
        Ok(_) => {
            eprintln!("error: no .jsonl or .mcap file in {}", display(&args.recordings));
            return ExitCode::from(2);
        }
        Err(e) => {
            eprintln!("error: cannot read {}: {e}", display(&args.recordings));
            return ExitCode::from(2);
        }
    };
    let title = display(&args.recordings);
    let hub = Hub::new(scene, &title, false);
    let loaded = match kpl_view::recording::load(&hub, &files) {
        Ok(loaded) => loaded,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    let mut text = format!("{} sample(s) from {} file(s)", loaded.samples, loaded.files.len());
    if let Some((start, end)) = hub.span() {
        let _ = write!(text, ", {:.1} s to {:.1} s", start as f64 / 1e6, end as f64 / 1e6);
    }
    eprintln!("{text}");
    for example in &loaded.examples {
        eprintln!("skipped {example}");
    }
    if loaded.malformed > loaded.examples.len() as u64 {
        eprintln!("... {} more skipped", loaded.malformed - loaded.examples.len() as u64);
    }
    for stream in &loaded.duplicates {
        eprintln!("note: stream `{stream}` is in several files; shown from the first");
    }
    let page = match kpl_view::page::serve(&hub, &args.http) {
        Ok(page) => page,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(2);
        }
    };
    eprintln!("view: the page at {}", page.url);
    match args.duration {
        Some(us) => std::thread::sleep(Duration::from_micros(u64::try_from(us).unwrap_or(0))),
        None => loop {
            std::thread::sleep(Duration::from_secs(3600));
        },
    }
    page.stop();
    if loaded.malformed > 0 { ExitCode::from(1) } else { ExitCode::SUCCESS }
}

fn display(paths: &[PathBuf]) -> String {
    paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(" ")
}

fn scene_of(spec: &hir::Spec, path: &Path) -> Scene {
    let scene = Scene::from_spec(spec, path.parent().unwrap_or(Path::new("")));
    for problem in &scene.problems {
        eprintln!("warning: the view's scene: {problem}");
    }
    scene
}

/// Where `kpl run` shows a run: the page, the Foxglove server, and how long the first sample
/// waits for a Foxglove client.
#[derive(Debug, Clone, Default)]
pub struct LiveOptions {
    pub http: Option<String>,
    pub foxglove: Option<String>,
    pub wait: Option<Time>,
}

/// The streams a view of a spec shows: each link's objects, each monitor's verdicts, and each
/// list of records with a position from a source or unit (percepts); only the processes of
/// `host` when one is given.
fn shown_streams(spec: &hir::Spec, host: Option<&str>) -> Vec<String> {
    spec.processes
        .iter()
        .filter(|p| host.is_none() || spec.host_of(p.id) == host)
        .filter(|p| match &p.kind {
            hir::ProcessKind::Link(_) | hir::ProcessKind::Monitor(_) => true,
            hir::ProcessKind::Source(_) | hir::ProcessKind::Compute(_) => matches!(
                &p.output,
                Some(ValueType::List(item)) if matches!(&**item, ValueType::Record(r) if r.field("pos").is_some())
            ),
            // A chronicle's recognitions are not drawn by the view yet.
            hir::ProcessKind::Sink(_) | hir::ProcessKind::Chronicle(_) => false,
        })
        .map(|p| p.name.clone())
        .collect()
}

/// The spec with a `view.live` sink over what [`shown_streams`] finds, checked again (its text
/// and the sink's line, so any problem is reported as for the spec itself).
pub fn attach(
    path: &Path,
    spec: &hir::Spec,
    host: Option<&str>,
    options: &LiveOptions,
) -> Result<hir::Spec, ExitCode> {
    let streams = shown_streams(spec, host);
    if streams.is_empty() {
        eprintln!("error: --view / --foxglove: the spec has no objects, percepts or monitors to show");
        return Err(ExitCode::from(2));
    }
    let name = (1..)
        .map(|i| if i == 1 { "kpl_view".to_string() } else { format!("kpl_view_{i}") })
        .find(|n| spec.process(n).is_none())
        .unwrap_or_default();
    let quote = |s: &str| serde_json::to_string(s).unwrap_or_default();
    let mut line = format!("\nsink {name} = view.live({}", streams.join(", "));
    if let Some(http) = &options.http {
        let _ = write!(line, ", http: {}", quote(http));
    }
    if let Some(foxglove) = &options.foxglove {
        let _ = write!(line, ", foxglove: {}", quote(foxglove));
    }
    if let Some(wait) = options.wait {
        let _ = write!(line, ", wait_for_client: {}ms", wait / 1000);
    }
    line.push_str(")\n");
    let mut file = SourceFile::read(path).map_err(|err| {
        report::read_error(&err);
        ExitCode::from(2)
    })?;
    file.text.push_str(&line);
    let (diagnostics, checked) = super::check::check_file(&file);
    let errors: Vec<_> =
        diagnostics.into_iter().filter(|d| d.severity == kpl_syntax::Severity::Error).collect();
    if !errors.is_empty() {
        let mut reporter = Reporter::new(DiagnosticFormat::Text);
        reporter.report(&file, &errors);
        reporter.finish();
    }
    checked.ok_or(ExitCode::from(1))
}
