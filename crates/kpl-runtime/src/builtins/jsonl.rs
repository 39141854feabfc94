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
//! the first one happens when the run starts.

use std::borrow::Cow;
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::PathBuf;

use kpl_core::{Time, Value, ValueType};
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};
use serde::{Deserialize, Serialize};

use super::replay::{ReplayTimes, StreamFilter};
use crate::clock::ClockKind;
use crate::context::SourceContext;
use crate::process::{BoxFuture, Emitter, Input, ProcessError, Source, SyncUnit, Trigger, Unit};
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

/// Encodes a sample as one line (without the line break).
pub fn encode_line(stream: &str, sample: &Sample) -> String {
    let line = SampleLine {
        stream: stream.to_string(),
        valid: sample.valid,
        available: sample.available,
        value: sample.value.to_json(),
    };
    serde_json::to_string(&line).unwrap_or_default()
}

/// Decodes one line: the stream name and the sample, or what is wrong with it.
pub fn decode_line(line: &str, ty: &ValueType) -> Result<(String, Sample), String> {
    let stream = line_stream(line)?;
    Ok((stream.into_owned(), decode_sample(line, ty)?))
}

/// The stream a line belongs to (`""` when it names none), read without decoding its value: a
/// replay keeps only the lines of one stream, and the other streams' values need not fit its type.
pub fn line_stream(line: &str) -> Result<Cow<'_, str>, String> {
    #[derive(Deserialize)]
    struct Head<'a> {
        #[serde(default, borrow)]
        stream: Cow<'a, str>,
    }
    let head: Head<'_> = serde_json::from_str(line).map_err(|e| format!("not a sample line: {e}"))?;
    Ok(head.stream)
}

/// The sample of a line, its value decoded with `ty`.
fn decode_sample(line: &str, ty: &ValueType) -> Result<Sample, String> {
    #[derive(Deserialize)]
    struct Raw {
        valid: Time,
        available: Option<Time>,
        value: serde_json::Value,
    }
    let raw: Raw = serde_json::from_str(line).map_err(|e| format!("not a sample line: {e}"))?;
    let value = Value::from_json(&raw.value, ty).map_err(|e| format!("value {e}"))?;
    Ok(Sample::new(raw.valid, raw.available.unwrap_or(raw.valid), value))
}

struct Replay {
    path: PathBuf,
    reader: Option<BufReader<File>>,
    filter: StreamFilter,
    ty: ValueType,
    clock: ClockKind,
}

impl Source for Replay {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let Some(reader) = self.reader.take() else { return Ok(()) };
            let display = self.path.display().to_string();
            let mut times = ReplayTimes::new(self.clock);
            for (index, line) in reader.lines().enumerate() {
                let location = format!("{display}:{}", index + 1);
                let line = match line {
                    Ok(line) => line,
                    Err(e) => {
                        ctx.malformed(&location, format!("cannot read the line: {e}"))?;
                        continue;
                    }
                };
                if line.trim().is_empty() {
                    continue;
                }
                // The stream first: other streams' values need not fit this source's type.
                match line_stream(&line) {
                    Ok(stream) if self.filter.keep(&stream) => {}
                    Ok(_) => continue,
                    Err(error) => {
                        ctx.malformed(&location, error)?;
                        continue;
                    }
                }
                let sample = match decode_sample(&line, &self.ty) {
                    Ok(sample) => sample,
                    Err(error) => {
                        ctx.malformed(&location, error)?;
                        continue;
                    }
                };
                let Some(sample) = times.admit(ctx, &location, sample)? else { continue };
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
        let Trigger::Sample(port) = input.trigger else { return Ok(()) };
        let Some(Some(sample)) = input.values.get(port) else { return Ok(()) };
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
        Entry::new(
            EntryKind::Source,
            "file.jsonl",
            "Replays samples recorded as JSON lines (docs/streams.md).",
        )
        .param(Param::required("path", ParamType::Str, "file to read, relative to the spec"))
        .param(Param::optional(
            "stream",
            ParamType::Str,
            Value::str(""),
            "only lines whose `stream` is this (empty: all)",
        )),
        |ctx| {
            let path = ctx.input_path(ctx.param("path").and_then(Value::as_str).unwrap_or(""));
            let file =
                File::open(&path).map_err(|e| ctx.error(format!("cannot open {}: {e}", path.display())))?;
            Ok(Box::new(Replay {
                path,
                reader: Some(BufReader::new(file)),
                filter: StreamFilter::new(ctx.param("stream").and_then(Value::as_str).unwrap_or("")),
                ty: ctx.process.output.clone().unwrap_or(ValueType::Any),
                clock: ctx.clock,
            }))
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

    #[test]
    fn bad_lines_say_what_is_wrong() {
        assert!(decode_line("{", &ValueType::Any).unwrap_err().starts_with("not a sample line"));
        let err = decode_line(r#"{"valid": 1, "value": "NaN"}"#, &ValueType::Float).unwrap_err();
        assert!(err.contains("finite number"), "{err}");
        let (_, s) = decode_line(r#"{"valid": 7, "value": 1}"#, &ValueType::Float).unwrap();
        assert_eq!((s.valid, s.available, s.value), (7, 7, Value::Float(1.0)));
    }
}
