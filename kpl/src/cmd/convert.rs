//! `kpl convert`: a recording from JSON lines to MCAP and back, losing nothing (docs/streams.md,
//! "MCAP files"). The stream of a line is the topic of a channel and the line's `valid`,
//! `available` and `value` are the message, copied as JSON; order is kept. Going to MCAP, the
//! streams are also written in Foxglove's schemas for its 3D panel (`kpl_mcap::foxglove`; the
//! roads, occluders and camera of `--spec`), unless `--no-foxglove`. Going from MCAP, a file cut
//! short by a killed run gives what its chunks hold (`kpl_mcap::recover`). To a rosbag2 bag (an
//! output without extension), the samples of the streams the spec's `ros2.publish` sinks publish
//! become CDR messages of their topics, mapped as a run publishes them (`kpl_mcap::rosbag2`).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args as ClapArgs;
use kpl_core::read::{LineError, LineReader, MAX_RECORDING_LINE};
use kpl_core::{Value, ValueType};
use kpl_mcap::foxglove::{Role, ViewChannels, ViewId, Views};
use kpl_mcap::read::{RawEvent, Reader};
use kpl_mcap::scene::Scene;
use kpl_mcap::write::{Compression, Recorder, StreamId};
use kpl_runtime::Sample;
use kpl_runtime::builtins::{SampleLine, StreamFilter, read_line};

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  kpl run specs/ok/tracker.kpl --for 5s --out out/rec\n  kpl convert out/rec/percepts.jsonl out/rec/percepts.mcap --spec specs/ok/tracker.kpl\n  kpl convert out/rec/percepts.mcap out/rec/back.jsonl\n  kpl run specs/ros2/replay.kpl --out out/replay\n  kpl convert out/replay/tracks.jsonl out/replay/cars --spec specs/ros2/markers.kpl\n  kpl convert out/replay/cars out/replay/cars.jsonl\n\nThe direction follows the extensions (.jsonl, .mcap; none: a rosbag2 bag, written through the\nros2.publish sinks of --spec, each sample of the stream a sink publishes a message of its topic,\nor read whole into .jsonl with its type hashes checked). Going to MCAP, each stream is also written\nin Foxglove's schemas (objects, percepts, situations, and the roads, occluders and camera of\n--spec) for its 3D panel; --no-foxglove leaves them out. Going from MCAP, a file cut short by a\nkilled run gives what its chunks hold, and says where it ends. Lines or messages that do not convert are\nreported with where they are and skipped. Exit status: 0 done, 1 some did not convert, 2 usage or\nI/O errors."
)]
pub struct Args {
    /// The recording to read (.jsonl or .mcap).
    pub input: PathBuf,
    /// The file to write (.mcap or .jsonl), or a rosbag2 bag: a folder (no extension) with
    /// `metadata.yaml` and the bag's MCAP file, of the topics the --spec's ros2.publish sinks
    /// publish.
    pub output: PathBuf,
    /// The spec that made the recording: gives each stream's type for the MCAP schemas (without
    /// it, a stream's schema accepts any value).
    #[arg(long)]
    pub spec: Option<PathBuf>,
    /// How the MCAP chunks are compressed.
    #[arg(long, default_value = "zstd", value_parser = clap::builder::PossibleValuesParser::new(Compression::NAMES))]
    pub compression: String,
    /// Only the streams' own channels, not their views in Foxglove's schemas.
    #[arg(long)]
    pub no_foxglove: bool,
    /// Writing a rosbag2 bag: a new MCAP file once a file's messages reach this many bytes (as
    /// `ros2 bag record --max-bag-size`).
    #[arg(long, value_name = "BYTES")]
    pub max_bag_size: Option<u64>,
    /// Writing a rosbag2 bag: a new MCAP file once a message comes this long after the file's
    /// first (`60s`; as `ros2 bag record --max-bag-duration`).
    #[arg(long, value_name = "DURATION", value_parser = kpl_core::parse_duration)]
    pub max_bag_duration: Option<kpl_core::Time>,
}

fn extension(path: &Path) -> &str {
    path.extension().and_then(|e| e.to_str()).unwrap_or("")
}

pub fn run(args: Args) -> ExitCode {
    let to_bag = extension(&args.output).is_empty();
    if !to_bag && (args.max_bag_size.is_some() || args.max_bag_duration.is_some()) {
        eprintln!(
            "warning: --max-bag-size and --max-bag-duration split a rosbag2 bag; the output is not one"
        );
    }
    let result = match (extension(&args.input), extension(&args.output)) {
        ("jsonl", "mcap") => {
            let (types, scene) = match &args.spec {
                Some(path) => match super::check::load_checked(path) {
                    Ok(spec) => {
                        let scene = Scene::from_spec(&spec, path.parent().unwrap_or(Path::new("")));
                        for problem in &scene.problems {
                            eprintln!("warning: the view's scene: {problem}");
                        }
                        (stream_types(&spec), scene)
                    }
                    Err(code) => return code,
                },
                None => (BTreeMap::new(), Scene::default()),
            };
            let compression = Compression::from_name(&args.compression).unwrap_or(Compression::Zstd);
            let views = (!args.no_foxglove).then(|| Views::new(std::sync::Arc::new(scene)));
            to_mcap(&args.input, &args.output, &types, compression, views)
        }
        ("mcap", "jsonl") => to_jsonl(std::slice::from_ref(&args.input), BTreeMap::new(), &args.output),
        ("", "jsonl") if args.input.is_dir() => bag_to_jsonl(&args.input, &args.output),
        ("jsonl", "") => {
            let Some(path) = &args.spec else {
                eprintln!(
                    "error: a rosbag2 bag is written through the ros2.publish sinks of the spec that made the recording: name it with --spec"
                );
                return ExitCode::from(2);
            };
            let spec = match super::check::load_checked(path) {
                Ok(spec) => spec,
                Err(code) => return code,
            };
            if args.no_foxglove || args.compression != "zstd" {
                eprintln!(
                    "warning: --no-foxglove and --compression apply to MCAP recordings, not to a rosbag2 bag"
                );
            }
            let split = kpl_mcap::rosbag2::Split {
                max_bytes: args.max_bag_size.filter(|b| *b > 0),
                max_duration: args.max_bag_duration.filter(|d| *d > 0),
            };
            to_rosbag2(&args.input, &args.output, &spec, path.parent().unwrap_or(Path::new("")), split)
        }
        (from, to) => {
            eprintln!(
                "error: kpl convert goes from .jsonl to .mcap, from .mcap or a rosbag2 bag (a folder) to .jsonl, or from .jsonl to a rosbag2 bag (a folder: no extension), not from `.{from}` to `.{to}`"
            );
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(Converted { samples, skipped }) => {
            eprintln!(
                "{}: {samples} sample(s){}",
                args.output.display(),
                if skipped > 0 { format!(", {skipped} skipped") } else { String::new() }
            );
            if skipped > 0 { ExitCode::from(1) } else { ExitCode::SUCCESS }
        }
        Err(error) => {
            eprintln!("error: {error}");
            ExitCode::from(2)
        }
    }
}

/// The type and view role of every stream a process of the spec consumes, by the name a
/// recording gives it.
fn stream_types(spec: &kpl_semantic::hir::Spec) -> BTreeMap<String, (ValueType, Role)> {
    let mut types = BTreeMap::new();
    for process in &spec.processes {
        for input in &process.inputs {
            types
                .entry(input.stream.name.clone())
                .or_insert_with(|| (input.stream.ty.clone(), Role::of_stream(spec, &input.stream)));
        }
    }
    types
}

/// A read error that ended a conversion, with what was written before it.
fn read_error(input: &Path, error: &LineError, samples: u64, output: &Path) -> String {
    format!(
        "cannot read {}: {error}; the {samples} sample(s) before it are in {}",
        input.display(),
        output.display()
    )
}

struct Converted {
    samples: u64,
    skipped: u64,
}

fn skip(location: &str, error: &str) {
    eprintln!("skipped {location}: {error}");
}

/// The samples of a JSON-lines recording, in order. A line that is not a sample is said (`skip`)
/// and counted in `skipped`; a line too long (`/dev/zero` has no line break) ends the reading
/// with an error: the file is not a recording.
struct RecordingSamples {
    lines: LineReader<BufReader<File>>,
    number: u64,
    input: PathBuf,
}

impl RecordingSamples {
    fn open(input: &Path) -> Result<RecordingSamples, String> {
        let file = kpl_core::read::open(input).map_err(|e| e.to_string())?;
        let lines = LineReader::new(BufReader::new(file), MAX_RECORDING_LINE);
        Ok(RecordingSamples { lines, number: 0, input: input.to_path_buf() })
    }

    /// The next sample and where it is (`FILE:LINE`), `None` at the end, or the read error.
    fn next(&mut self, skipped: &mut u64) -> Result<Option<(String, SampleLine)>, LineError> {
        loop {
            self.number += 1;
            let location = format!("{}:{}", self.input.display(), self.number);
            let Some(line) = self.lines.next_line()? else { return Ok(None) };
            let Ok(line) = std::str::from_utf8(line) else {
                skip(&location, "the line is not UTF-8 text");
                *skipped += 1;
                continue;
            };
            if line.trim().is_empty() {
                continue;
            }
            match read_line(line) {
                Ok(line) => return Ok(Some((location, line))),
                Err(error) => {
                    skip(&location, &error);
                    *skipped += 1;
                }
            }
        }
    }
}

fn to_mcap(
    input: &Path,
    output: &Path,
    types: &BTreeMap<String, (ValueType, Role)>,
    compression: Compression,
    mut views: Option<Views>,
) -> Result<Converted, String> {
    let mut samples = RecordingSamples::open(input)?;
    let mut recorder = Recorder::create(output, compression).map_err(|e| e.to_string())?;
    let mut streams: BTreeMap<String, (StreamId, Option<ViewId>)> = BTreeMap::new();
    let mut channels = ViewChannels::default();
    let mut messages = Vec::new();
    let mut converted = Converted { samples: 0, skipped: 0 };
    loop {
        // What was converted before a read error is kept in the MCAP file.
        let line = match samples.next(&mut converted.skipped) {
            Ok(Some((_, line))) => line,
            Ok(None) => break,
            Err(error) => {
                recorder.finish().map_err(|e| e.to_string())?;
                return Err(read_error(input, &error, converted.samples, output));
            }
        };
        let (id, view) = match streams.get(&line.stream) {
            Some(ids) => *ids,
            None => {
                let (ty, role) = types.get(&line.stream).cloned().unwrap_or((ValueType::Any, Role::Unknown));
                let id = recorder.add_stream(&line.stream, &ty).map_err(|e| e.to_string())?;
                let view = views.as_mut().map(|v| v.add_stream(&line.stream, role));
                streams.insert(line.stream.clone(), (id, view));
                (id, view)
            }
        };
        if let (Some(views), Some(view)) = (views.as_mut(), view)
            && let Ok(value) = Value::from_json_untyped(&line.value)
        {
            messages.clear();
            views.messages(view, &Sample::new(line.valid, line.available, value), &mut messages);
        } else {
            messages.clear();
        }
        recorder.write_json(id, line.valid, line.available, line.value).map_err(|e| e.to_string())?;
        for message in &messages {
            channels.write(&mut recorder, message).map_err(|e| e.to_string())?;
        }
        converted.samples += 1;
    }
    recorder.finish().map_err(|e| e.to_string())?;
    Ok(converted)
}

/// A recording into a rosbag2 bag (the folder `output`): each sample of a stream that a
/// `ros2.publish` sink of the spec publishes becomes a message of that sink's topic, mapped as the
/// run publishes it. Samples of other streams are counted and said, not written.
fn to_rosbag2(
    input: &Path,
    output: &Path,
    spec: &kpl_semantic::hir::Spec,
    dir: &Path,
    split: kpl_mcap::rosbag2::Split,
) -> Result<Converted, String> {
    use kpl_mcap::rosbag2::{BagWriter, publications};
    let mut publications = publications(spec, dir)?;
    if publications.is_empty() {
        return Err("the spec has no ros2.publish sink: a bag holds the ROS 2 topics a spec publishes".into());
    }
    let mut samples = RecordingSamples::open(input)?;
    let mut bag = BagWriter::create_split(output, split).map_err(|e| e.to_string())?;
    let mut topics = Vec::new();
    for p in &publications {
        topics.push(bag.add_topic(&p.topic, &p.schema, p.qos).map_err(|e| e.to_string())?);
    }
    let mut converted = Converted { samples: 0, skipped: 0 };
    let mut unpublished: BTreeMap<String, u64> = BTreeMap::new();
    loop {
        let (location, line) = match samples.next(&mut converted.skipped) {
            Ok(Some(sample)) => sample,
            Ok(None) => break,
            Err(error) => {
                bag.finish().map_err(|e| e.to_string())?;
                return Err(read_error(input, &error, converted.samples, output));
            }
        };
        let mut published = false;
        for (p, topic) in publications.iter_mut().zip(&topics) {
            if p.stream != line.stream {
                continue;
            }
            published = true;
            let message = Value::from_json(&line.value, &p.stream_type)
                .map_err(|e| e.to_string())
                .and_then(|value| p.encode(line.valid, &value).map(<[u8]>::to_vec));
            match message {
                Ok(message) => {
                    bag.write(*topic, line.available, &message).map_err(|e| e.to_string())?;
                    converted.samples += 1;
                }
                Err(error) => {
                    skip(&location, &format!("`{}` on {}: {error}", line.stream, p.topic));
                    converted.skipped += 1;
                }
            }
        }
        if !published {
            *unpublished.entry(line.stream).or_default() += 1;
        }
    }
    let written = bag.finish().map_err(|e| e.to_string())?;
    for topic in &written.topics {
        eprintln!("{}: {} message(s) of {}", topic.name, topic.message_count, topic.type_name);
    }
    for (stream, count) in unpublished {
        eprintln!(
            "note: {count} sample(s) of `{stream}` are not in the bag: no ros2.publish of the spec publishes it"
        );
    }
    Ok(converted)
}

/// A rosbag2 bag (its folder: `metadata.yaml` and its MCAP files, in order) into JSON lines, each
/// channel's `ros2msg` definition checked against the type hash that `metadata.yaml` records for
/// its topic.
fn bag_to_jsonl(bag: &Path, output: &Path) -> Result<Converted, String> {
    let files = kpl_mcap::rosbag2::bag_files(bag)
        .map_err(|e| format!("cannot read the bag {}: {e}", bag.display()))?;
    let hashes = kpl_mcap::rosbag2::recorded_hashes(bag)?;
    to_jsonl(&files, hashes, output)
}

/// MCAP files (a bag's, in order, with the type hashes its `metadata.yaml` records) into one
/// JSON lines recording.
fn to_jsonl(
    inputs: &[PathBuf],
    hashes: BTreeMap<String, String>,
    output: &Path,
) -> Result<Converted, String> {
    let mut readers = Vec::new();
    for input in inputs {
        let reader = Reader::open(input).map_err(|e| format!("cannot read {}: {e}", input.display()))?;
        readers.push(reader.recorded_hashes(hashes.clone()));
    }
    if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    }
    let write_error = |e: std::io::Error| format!("cannot write {}: {e}", output.display());
    let mut out = BufWriter::new(File::create(output).map_err(write_error)?);
    let mut filter = StreamFilter::new("");
    let mut converted = Converted { samples: 0, skipped: 0 };
    for mut reader in readers {
        while let Some(event) = reader.next_raw(&mut filter) {
            match event {
                RawEvent::Message { stream, valid, available, value, .. } => {
                    let line = SampleLine { stream: stream.to_string(), valid, available, value };
                    let text = serde_json::to_string(&line).map_err(|e| e.to_string())?;
                    writeln!(out, "{text}").map_err(write_error)?;
                    converted.samples += 1;
                }
                RawEvent::Malformed { location, error } => {
                    skip(&location, &error);
                    converted.skipped += 1;
                }
            }
        }
    }
    out.flush().map_err(write_error)?;
    Ok(converted)
}
