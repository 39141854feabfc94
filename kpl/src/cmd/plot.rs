//! `kpl plot`: an SVG picture of a recorded run over its road network: percepts as dots, objects
//! of link processes as squares (hollow where only predicted), their symbols, the ground truth,
//! recognised situations, inside a time window. The work is `kpl_plot`'s.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args as ClapArgs;
use kpl_core::Time;
use kpl_plot::{DrawOptions, Plot, PlotOptions, Window, events::EventReader};
use kpl_roads::RoadNetwork;
use kpl_roads::scenarios::{self, GridTownSize};
use kpl_score::Recording;

const AFTER_HELP: &str = "\
Examples:
  kpl run specs/traffic/fig5.kpl
  kpl plot out/fig5 --network specs/traffic/fig5/crossing.json
  kpl plot out/fig5 --scenario crossing --stream tracker --stream world_onroad -o fig5.svg
  kpl run specs/traffic/sumo_grid.kpl --for 70s
  kpl plot out/sumo_grid --network specs/traffic/sumo/grid/net.xml.gz --from 60s --to 70s

Every object stream of the recording is drawn (or those given with --stream): streams whose
records say nothing about being measured (the tracker's percepts) as dots, the others (link
outputs, world models per type) as squares, hollow where the state was predicted; each symbol is
labelled where it appears. The ground truth (`*.truth`) is drawn as dashed lines. Records with
`from`/`to` valid times and object symbols (recognised situations) are highlighted along those
objects' paths and drawn on a timeline. See docs/plot.md.
Exit status: 0 written, 1 the recording cannot be plotted as asked, 2 usage or I/O errors.";

#[derive(Debug, ClapArgs)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// A run's output folder (every `*.jsonl` below it) or recorded `.jsonl` files.
    #[arg(required = true, value_name = "RUN_DIR_OR_FILES")]
    paths: Vec<PathBuf>,
    /// The road network to draw under the plot: SUMO `.net.xml` or JSON, either gzipped.
    #[arg(long, value_name = "FILE", conflicts_with = "scenario")]
    network: Option<PathBuf>,
    /// A built-in road network instead: crossing, bridge or grid_town.
    #[arg(long, value_name = "NAME")]
    scenario: Option<String>,
    /// Occluders to draw that are not the network's (the tracker's `occluders_file`).
    #[arg(long, value_name = "FILE", requires = "network")]
    occluders: Option<PathBuf>,
    /// Draw only this stream (repeatable); default every object stream.
    #[arg(long = "stream", value_name = "STREAM")]
    streams: Vec<String>,
    /// The ground-truth stream (default: the one named `truth` or `*.truth`, if any).
    #[arg(long, value_name = "STREAM", conflicts_with = "no_truth")]
    truth: Option<String>,
    /// Leave the ground truth out.
    #[arg(long)]
    no_truth: bool,
    /// Draw only valid times from this one on (`12.5`, `12s`, `500ms`, `2min`).
    #[arg(long, value_name = "TIME", value_parser = parse_time)]
    from: Option<Time>,
    /// Draw only valid times up to this one.
    #[arg(long, value_name = "TIME", value_parser = parse_time)]
    to: Option<Time>,
    /// The part of the world to draw, metres: `X0,Y0,X1,Y1` (default: what is drawn, 15 m around).
    #[arg(long, value_name = "X0,Y0,X1,Y1", value_parser = parse_view, allow_hyphen_values = true)]
    view: Option<([f64; 2], [f64; 2])>,
    /// Width of the picture in pixels, 100 to 20000.
    #[arg(long, value_name = "PX", default_value = "1000", value_parser = parse_width)]
    width: f64,
    /// No symbol labels.
    #[arg(long)]
    no_labels: bool,
    /// No legend.
    #[arg(long)]
    no_legend: bool,
    /// The SVG file to write (default: plot.svg in the run's folder, or beside the first file).
    #[arg(short, long, value_name = "FILE")]
    output: Option<PathBuf>,
}

pub fn run(args: Args) -> ExitCode {
    match plot(&args) {
        Ok(()) => ExitCode::SUCCESS,
        Err((code, message)) => {
            eprintln!("error: {message}");
            ExitCode::from(code)
        }
    }
}

fn plot(args: &Args) -> Result<(), (u8, String)> {
    if let (Some(from), Some(to)) = (args.from, args.to)
        && from > to
    {
        return Err((2, format!("--from {} s is after --to {} s", from as f64 / 1e6, to as f64 / 1e6)));
    }
    let network = load_network(args)?;
    let occluders = match (&args.occluders, &network) {
        (Some(path), Some(net)) => {
            kpl_roads::load::read_occluders(path, net).map_err(|e| (2, format!("{}: {e}", path.display())))?
        }
        _ => Vec::new(),
    };
    let recording =
        Recording::read(&args.paths).map_err(|e| (if e.is_data_error() { 1 } else { 2 }, e.to_string()))?;
    let options = PlotOptions {
        streams: args.streams.clone(),
        truth: args.truth.clone(),
        no_truth: args.no_truth,
        window: Window { from: args.from, to: args.to },
    };
    let mut plot = Plot::from_recording(&recording, &options).map_err(|e| (1, e.to_string()))?;
    let mut events = EventReader::default();
    for file in recording.files() {
        let reader = kpl_core::read::open(file).map_err(|e| (2, e.to_string()))?;
        events.read(file, std::io::BufReader::new(reader)).map_err(|e| (2, e.to_string()))?;
    }
    let events = events.finish();
    if events.problems > 0 {
        eprintln!(
            "warning: {} event records were left out (first: {})",
            events.problems,
            events.examples.first().map_or("", String::as_str)
        );
    }
    plot.events = events.events.into_iter().filter(|e| plot.window.overlaps(e.from, e.to)).collect();
    let problems = recording.problems();
    if problems.count > 0 {
        eprintln!(
            "warning: {} lines or records of the recording were left out (first: {})",
            problems.count,
            problems.examples.first().map_or("", String::as_str)
        );
    }
    let marks: usize = plot.series.iter().map(|s| s.points().count()).sum();
    if marks == 0 {
        eprintln!("warning: nothing to draw in the time window (check --from, --to and --stream)");
    } else if marks > 200_000 {
        eprintln!("note: {marks} marks make a large picture; --from/--to or --stream draw fewer");
    }
    let draw = DrawOptions {
        width_px: args.width,
        view: args.view,
        labels: !args.no_labels,
        legend: !args.no_legend,
        ..DrawOptions::default()
    };
    let svg = kpl_plot::render(&plot, network.as_ref(), &occluders, &draw);
    let output = args.output.clone().unwrap_or_else(|| default_output(&args.paths[0]));
    std::fs::write(&output, svg).map_err(|e| (2, format!("{}: {e}", output.display())))?;
    let streams: Vec<&str> = plot.series.iter().map(|s| s.stream.as_str()).collect();
    eprintln!(
        "wrote {} ({} marks of {}; {} situations)",
        output.display(),
        marks,
        streams.join(", "),
        plot.events.len()
    );
    if network.is_none() {
        eprintln!("note: no road network drawn (--network FILE or --scenario NAME)");
    }
    Ok(())
}

fn load_network(args: &Args) -> Result<Option<RoadNetwork>, (u8, String)> {
    if let Some(path) = &args.network {
        return RoadNetwork::load(path).map(Some).map_err(|e| (2, format!("{}: {e}", path.display())));
    }
    let Some(name) = &args.scenario else { return Ok(None) };
    let file = scenarios::by_name(name, GridTownSize::default())
        .ok_or_else(|| (2, format!("no built-in road network `{name}` (crossing, bridge, grid_town)")))?;
    RoadNetwork::build(&file).map(Some).map_err(|e| (2, format!("scenario `{name}`: {e}")))
}

fn default_output(first: &Path) -> PathBuf {
    if first.is_dir() { first.join("plot.svg") } else { first.with_file_name("plot.svg") }
}

/// A valid time: seconds (`12.5`) or with a unit (`500ms`, `12s`, `2min`, `100us`).
fn parse_time(text: &str) -> Result<Time, String> {
    let text = text.trim();
    let split = text.find(|c: char| c.is_ascii_alphabetic()).unwrap_or(text.len());
    let (number, unit) = text.split_at(split);
    let value: f64 =
        number.trim().parse().map_err(|_| format!("`{text}` is not a time (12.5, 12s, 500ms, 2min)"))?;
    let scale = match unit {
        "" | "s" => 1e6,
        "ms" => 1e3,
        "us" => 1.0,
        "min" => 60e6,
        "h" => 3600e6,
        other => return Err(format!("unknown time unit `{other}` (us, ms, s, min, h)")),
    };
    let micros = value * scale;
    if !micros.is_finite() || micros.abs() > 1e17 {
        return Err(format!("`{text}` is out of range"));
    }
    Ok(micros.round() as Time)
}

/// The narrowest and the widest picture drawn, pixels: narrower leaves no room for the legend and
/// the timeline, wider is more than a browser shows (and `1e9` was once accepted silently).
const WIDTH_PX: std::ops::RangeInclusive<f64> = 100.0..=20_000.0;

/// A width in pixels within [`WIDTH_PX`].
fn parse_width(text: &str) -> Result<f64, String> {
    let width: f64 = text.trim().parse().map_err(|_| format!("`{text}` is not a number of pixels"))?;
    if !WIDTH_PX.contains(&width) {
        return Err(format!(
            "{text} px is out of range: the picture is {} to {} pixels wide",
            WIDTH_PX.start(),
            WIDTH_PX.end()
        ));
    }
    Ok(width)
}

/// The farthest coordinate of a view, metres (SUMO's projected coordinates stay far below).
const MAX_COORDINATE_M: f64 = 1e8;

/// `X0,Y0,X1,Y1` in metres, with X0 < X1 and Y0 < Y1.
fn parse_view(text: &str) -> Result<([f64; 2], [f64; 2]), String> {
    let numbers: Result<Vec<f64>, _> = text.split(',').map(|n| n.trim().parse::<f64>()).collect();
    match numbers.as_deref() {
        Ok(&[x0, y0, x1, y1])
            if [x0, y0, x1, y1].iter().all(|v| v.abs() <= MAX_COORDINATE_M) && x0 < x1 && y0 < y1 =>
        {
            Ok(([x0, y0], [x1, y1]))
        }
        _ => Err(format!(
            "`{text}` is not X0,Y0,X1,Y1 with X0 < X1 and Y0 < Y1 (metres, at most {MAX_COORDINATE_M:e} from 0)"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_and_views() {
        assert_eq!(parse_time("12.5"), Ok(12_500_000));
        assert_eq!(parse_time("500ms"), Ok(500_000));
        assert_eq!(parse_time("2min"), Ok(120_000_000));
        assert!(
            parse_time("3 parsecs").is_err() && parse_time("inf").is_err() && parse_time("1e300").is_err()
        );
        assert_eq!(parse_view("-10,-5,10,5"), Ok(([-10.0, -5.0], [10.0, 5.0])));
        assert!(parse_view("10,0,0,5").is_err() && parse_view("1,2,3").is_err());
        assert!(parse_view("0,0,1e300,1").is_err() && parse_view("NaN,0,1,1").is_err());
        assert_eq!(parse_width("1000"), Ok(1000.0));
        assert_eq!(parse_width("100"), Ok(100.0));
        for bad in ["0", "-5", "1e9", "99.9", "20001", "NaN", "inf", "wide"] {
            assert!(parse_width(bad).is_err(), "{bad}");
        }
        assert_eq!(
            parse_width("0").unwrap_err(),
            "0 px is out of range: the picture is 100 to 20000 pixels wide"
        );
    }
}
