//! JSON-lines replay (`source ... = file.jsonl(path)`) and recording (`sink ... =
//! file.jsonl(inputs, path)`). One sample per line (`docs/streams.md`):
//!
//! ```json
//! {"stream": "percepts", "valid": 100000, "available": 120000, "value": {"id": "vp1", "pos": [1.5, 2.0]}}
//! ```
//!
//! `valid` and `available` are integer microseconds; `available` may be left out (then it equals
//! `valid`). Replay decodes `value` with the source's declared type; a line that is not JSON, a
//! value of the wrong type, NaN where a number is needed, or an available time going backwards is
//! counted as malformed with its file and line, and the replay goes on (`--strict` stops the run).
//! With simulated time samples keep their recorded times; with wall-clock time they are shifted so
//! the first one happens when the run starts (a time that the shift would take past the range of
//! 64-bit microseconds is malformed, not wrapped).
//!
//! Hostile paths are refused or bounded: a directory is refused when the run starts; a line is at
//! most [`MAX_RECORDING_LINE`] bytes (a longer one, such as `/dev/zero` gives, ends the replay as a
//! failure of the process naming the line, so memory stays bounded; `kpl_core::read`); so does a
//! read error; and
//! the replay yields to the run between lines, so a file of nothing but bad lines neither blocks
//! Ctrl-C nor starves the other processes.

use std::fs::File;
use std::io::{BufReader, BufWriter, Write};
use std::path::PathBuf;

use kpl_core::read::{LineReader, MAX_RECORDING_LINE};
use kpl_core::{Time, Value, ValueType};
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};
use serde::{Deserialize, Serialize};

use super::replay::{ReplaySetup, ReplayTimes, StreamFilter, replay_entry};
use crate::clock::ClockKind;
use crate::context::SourceContext;
use crate::process::{BoxFuture, Emitter, Input, ProcessError, Source, SyncUnit, Unit};
use crate::registry::Registry;
use crate::sample::Sample;

/// One line of a JSON-lines stream file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SampleLine {
    pub stream: String,
    pub valid: Time,
    pub available: Time,
    pub value: serde_json::Value,
}

/// Encodes a sample as one line (without the line break): a [`SampleLine`], written straight from
/// the value (no JSON tree is built).
pub fn encode_line(stream: &str, sample: &Sample) -> String {
    #[derive(Serialize)]
    struct Line<'a> {
        stream: &'a str,
        valid: Time,
        available: Time,
        value: &'a Value,
    }
    let line = Line { stream, valid: sample.valid, available: sample.available, value: &sample.value };
    serde_json::to_string(&line).unwrap_or_default()
}

/// Decodes one line: the stream name and the sample, or what is wrong with it (in words that
/// point at the line's shape, not at the JSON parser's internals).
pub fn decode_line(line: &str, ty: &ValueType) -> Result<(String, Sample), String> {
    let line = read_line(line)?;
    let value = Value::from_json(&line.value, ty).map_err(|e| format!("value {e}"))?;
    Ok((line.stream, Sample::new(line.valid, line.available, value)))
}

/// Reads one line's envelope (stream, times) and its value as plain JSON, not yet decoded with a
/// type: a replay keeps only the lines of one stream, and the other streams' values need not fit
/// its type. The stream is `""` when the line names none; `available` defaults to `valid`.
pub fn read_line(line: &str) -> Result<SampleLine, String> {
    use serde_json::Value as J;
    let json: J = serde_json::from_str(line).map_err(|e| not_json(&e))?;
    let J::Object(mut fields) = json else {
        return Err(format!("the line is not a JSON object; {SAMPLE_LINE}"));
    };
    let time = |name: &str| match fields.get(name) {
        None | Some(J::Null) => Ok(None),
        Some(v) => v.as_i64().map(Some).ok_or_else(|| format!("`{name}` is {v}, not whole microseconds")),
    };
    let valid = time("valid")?.ok_or_else(|| format!("the line has no `valid` time; {SAMPLE_LINE}"))?;
    let available = time("available")?.unwrap_or(valid);
    let stream = match fields.remove("stream") {
        None | Some(J::Null) => String::new(),
        Some(J::String(name)) => name,
        Some(other) => return Err(format!("`stream` is {other}, not a stream name")),
    };
    let value = fields.remove("value").ok_or_else(|| format!("the line has no `value`; {SAMPLE_LINE}"))?;
    Ok(SampleLine { stream, valid, available, value })
}

/// The shape of a sample line, for messages about lines that do not have it.
const SAMPLE_LINE: &str = "a sample line is {\"stream\": NAME, \"valid\": MICROSECONDS, \"available\": \
                           MICROSECONDS, \"value\": VALUE} with `stream` and `available` optional";

/// What is wrong with a line that is not JSON.
fn not_json(error: &serde_json::Error) -> String {
    use serde_json::error::Category;
    let column = error.column();
    match error.classify() {
        Category::Eof => format!("the line ends inside a JSON value (column {column})"),
        Category::Syntax | Category::Data | Category::Io => {
            format!("the line is not JSON (unexpected text at column {column}); {SAMPLE_LINE}")
        }
    }
}

struct Replay {
    path: PathBuf,
    reader: Option<BufReader<File>>,
    filter: StreamFilter,
    ty: ValueType,
    clock: ClockKind,
}

/// How many lines replay reads without emitting before it lets the other tasks run.
const LINES_PER_YIELD: usize = 256;

impl Source for Replay {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let Some(reader) = self.reader.take() else { return Ok(()) };
            let mut lines = LineReader::new(reader, MAX_RECORDING_LINE);
            let display = self.path.display().to_string();
            let mut times = ReplayTimes::new(self.clock);
            let mut number = 0usize;
            let mut since_yield = 0usize;
            loop {
                number += 1;
                since_yield += 1;
                if since_yield >= LINES_PER_YIELD {
                    since_yield = 0;
                    tokio::task::yield_now().await;
                    if ctx.should_stop() {
                        break;
                    }
                }
                let location = format!("{display}:{number}");
                let line = match lines.next_line() {
                    Ok(Some(line)) => line,
                    Ok(None) => break,
                    Err(error) => {
                        return Err(ProcessError::failed(format!("cannot replay {display}: {error}")));
                    }
                };
                let Ok(line) = std::str::from_utf8(line) else {
                    ctx.malformed(&location, "the line is not UTF-8 text")?;
                    continue;
                };
                if line.trim().is_empty() {
                    continue;
                }
                // The stream first: other streams' values need not fit this source's type.
                let line = match read_line(line) {
                    Ok(line) if self.filter.keep(&line.stream) => line,
                    Ok(_) => continue,
                    Err(error) => {
                        ctx.malformed(&location, error)?;
                        continue;
                    }
                };
                let sample = match Value::from_json(&line.value, &self.ty) {
                    Ok(value) => Sample::new(line.valid, line.available, value),
                    Err(error) => {
                        ctx.malformed(&location, format!("value {error}"))?;
                        continue;
                    }
                };
                let Some(sample) = times.admit(ctx, &location, sample)? else { continue };
                since_yield = 0;
                if !ctx.wait_until(sample.available).await {
                    break;
                }
                ctx.emit_sample(sample).await;
                if ctx.unconsumed() {
                    break;
                }
            }
            if let Some(warning) = self.filter.warning(&display) {
                ctx.warn(warning);
            }
            Ok(())
        })
    }
}

struct Record {
    path: PathBuf,
    writer: Option<BufWriter<File>>,
}

impl Record {
    fn writer(&mut self) -> Result<&mut BufWriter<File>, ProcessError> {
        if self.writer.is_none() {
            if let Some(dir) = self.path.parent() {
                std::fs::create_dir_all(dir)
                    .map_err(|e| ProcessError::failed(format!("cannot create {}: {e}", dir.display())))?;
            }
            let file = File::create(&self.path)
                .map_err(|e| ProcessError::failed(format!("cannot write {}: {e}", self.path.display())))?;
            self.writer = Some(BufWriter::new(file));
        }
        self.writer.as_mut().ok_or_else(|| ProcessError::failed("no writer"))
    }
}

impl Unit for Record {
    fn on_input(&mut self, input: &Input<'_>, _out: &mut Emitter) -> Result<(), ProcessError> {
        let Some((port, sample)) = input.trigger_sample() else { return Ok(()) };
        let line = encode_line(input.names.get(port).map_or("", |n| n), sample);
        let path = self.path.display().to_string();
        writeln!(self.writer()?, "{line}")
            .map_err(|e| ProcessError::failed(format!("cannot write {path}: {e}")))
    }

    fn on_end(&mut self, _out: &mut Emitter) -> Result<(), ProcessError> {
        // Create the file even when nothing arrived, so a run's outputs always exist.
        let path = self.path.display().to_string();
        self.writer()?.flush().map_err(|e| ProcessError::failed(format!("cannot write {path}: {e}")))
    }
}

impl Drop for Record {
    fn drop(&mut self) {
        if let Some(writer) = &mut self.writer {
            let _ = writer.flush();
        }
    }
}

pub(super) fn register(registry: &mut Registry) {
    registry.add_source(
        replay_entry(
            "file.jsonl",
            "Replays samples recorded as JSON lines (docs/streams.md).",
            "only lines whose `stream` is this (empty: all)",
        ),
        |ctx| {
            let ReplaySetup { path, filter, ty, clock } = ReplaySetup::from_context(ctx);
            // A directory opens on Unix, and then every read fails: refused here.
            let file = kpl_core::read::open(&path).map_err(|e| match e {
                kpl_core::read::ReadError::Directory { .. } => ctx.error(format!(
                    "cannot replay {}: it is a directory (give a JSON lines file)",
                    path.display()
                )),
                e => ctx.error(format!("cannot open {}: {}", path.display(), std::io::Error::from(e))),
            })?;
            Ok(Box::new(Replay { path, reader: Some(BufReader::new(file)), filter, ty, clock }))
        },
    );
    registry.add_unit(
        Entry::new(
            EntryKind::Sink,
            "file.jsonl",
            "Records samples as JSON lines, one per sample (docs/streams.md).",
        )
        .variadic(1, "in", TypeReq::Any, "streams to record")
        .param(Param::required(
            "path",
            ParamType::Str,
            "file to write, relative to the run's --out directory",
        )),
        |ctx| {
            let path = ctx.output_path(ctx.param("path").and_then(Value::as_str).unwrap_or("out.jsonl"));
            Ok(Box::new(SyncUnit(Record { path, writer: None })))
        },
    );
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn lines_round_trip() {
        let sample = Sample::new(100, 120, Value::vec2(1.5, -2.0));
        let line = encode_line("s", &sample);
        assert_eq!(line, r#"{"stream":"s","valid":100,"available":120,"value":[1.5,-2.0]}"#);
        assert_eq!(decode_line(&line, &ValueType::Vec2).unwrap(), ("s".to_string(), sample));
    }

    /// Any value, with records whose keys repeat, clash with `id` and come in any order, and
    /// floats that are not finite.
    fn any_value() -> impl proptest::strategy::Strategy<Value = Value> {
        use proptest::prelude::*;
        let float = prop_oneof![
            any::<f64>(),
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(-0.0),
            Just(1e300),
            Just(0.1)
        ];
        let leaf = prop_oneof![
            any::<bool>().prop_map(Value::Bool),
            any::<i64>().prop_map(Value::Int),
            float.clone().prop_map(Value::Float),
            r#"[a-z"\\é\n]{0,6}"#.prop_map(|s| Value::Str(s.into())),
            (float.clone(), float.clone()).prop_map(|(x, y)| Value::Vec2([x, y])),
            (float.clone(), float.clone(), float.clone(), float).prop_map(|(a, b, c, d)| Value::BBox(
                std::sync::Arc::new(kpl_core::BBox { x1: a, y1: b, x2: c, y2: d })
            )),
            any::<i64>().prop_map(Value::Duration),
        ];
        leaf.prop_recursive(3, 24, 4, |inner| {
            prop_oneof![
                proptest::collection::vec(inner.clone(), 0..4).prop_map(|items| Value::List(items.into())),
                (
                    proptest::option::of("[a-z]{0,3}"),
                    proptest::collection::vec(("id|pos|a|b|[a-z]{1,3}", inner), 0..5)
                )
                    .prop_map(|(id, fields)| Value::Record(std::sync::Arc::new(
                        kpl_core::Record {
                            id: id.map(Into::into),
                            fields: fields.into_iter().map(|(name, value)| (name.into(), value)).collect(),
                        }
                    ))),
            ]
        })
    }

    proptest::proptest! {
        /// The line written straight from the value is the text of the value's JSON tree, as
        /// before (`Value::to_json`), byte for byte.
        #[test]
        fn lines_are_written_as_the_json_tree_reads(value in any_value(), valid in 0i64..1_000_000) {
            let sample = Sample::new(valid, valid + 1, value.clone());
            let tree = SampleLine {
                stream: "s".to_string(),
                valid,
                available: valid + 1,
                value: value.to_json(),
            };
            proptest::prop_assert_eq!(encode_line("s", &sample), serde_json::to_string(&tree).unwrap());
        }
    }

    #[test]
    fn bad_lines_say_what_is_wrong() {
        let err = decode_line("{", &ValueType::Any).unwrap_err();
        assert_eq!(err, "the line ends inside a JSON value (column 1)");
        let err = decode_line("this is not json", &ValueType::Any).unwrap_err();
        assert!(
            err.starts_with("the line is not JSON (unexpected text at column 2); a sample line is"),
            "{err}"
        );
        for (line, says) in [
            ("[1, 2]", "the line is not a JSON object"),
            (r#"{"value": 1}"#, "the line has no `valid` time"),
            (r#"{"valid": 1.5, "value": 1}"#, "`valid` is 1.5, not whole microseconds"),
            (r#"{"valid": 1}"#, "the line has no `value`"),
            (r#"{"valid": 1, "stream": 3, "value": 1}"#, "`stream` is 3, not a stream name"),
        ] {
            let err = decode_line(line, &ValueType::Float).unwrap_err();
            assert!(err.starts_with(says), "{line}: {err}");
            assert!(!err.contains("expected ident") && !err.contains("invalid type"), "{err}");
        }
        let err = decode_line(r#"{"valid": 1, "value": "NaN"}"#, &ValueType::Float).unwrap_err();
        assert!(err.contains("finite number"), "{err}");
        let (_, s) = decode_line(r#"{"valid": 7, "value": 1}"#, &ValueType::Float).unwrap();
        assert_eq!((s.valid, s.available, s.value), (7, 7, Value::Float(1.0)));
    }
}
