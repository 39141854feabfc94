//! Interval events to mark on a plot: recognised situations ("`co3` too fast from 12 s to 15 s"),
//! read from recorded streams.
//!
//! An event is a record of a recorded sample (`{"stream", "valid", "value"}`, the value one record
//! or a list of them) with
//! - `from`: the valid time it began (integer microseconds), required;
//! - `to`: the valid time it ended (integer), absent or `null` while it goes on;
//! - `objects`: the symbols of the objects it is about (a list of strings); without it, every
//!   other string field but `name` and `situation` is taken as a symbol (a monitor's binding,
//!   `{"c": "co3"}`);
//! - `situation` or `name`: what it is called; else the stream's name.
//!
//! A stream reports an open event again at later states; the same (stream, name, objects, from)
//! is one event, with the last `to` reported. Lines that are not samples, and records without an
//! integer `from`, are not events and are skipped silently (a recording holds many other streams);
//! a `to` before `from` or a `from` that is not an integer in an otherwise event-like record is
//! counted as a problem.

use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::Path;

use kpl_core::Time;
use kpl_core::read::{LineError, LineReader, MAX_RECORDING_LINE};
use serde_json::Value as Json;

use crate::error::PlotError;

/// An interval event about some objects.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Event {
    pub name: String,
    /// The stream it was recorded on.
    pub stream: String,
    pub from: Time,
    /// `None`: still going on at the end of the recording.
    pub to: Option<Time>,
    /// The symbols of the objects involved.
    pub objects: Vec<String>,
}

/// The events read, and the event-like records that were left out.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Events {
    pub events: Vec<Event>,
    pub problems: usize,
    /// The first few problems, as `FILE:LINE: what`.
    pub examples: Vec<String>,
}

/// Events are collected by key so that repeated reports of one event merge.
type Key = (String, String, Vec<String>, Time);

#[derive(Debug, Default)]
pub struct EventReader {
    found: BTreeMap<Key, Option<Time>>,
    order: Vec<Key>,
    problems: usize,
    examples: Vec<String>,
}

impl EventReader {
    /// Reads the events of one recorded file (every line; a line longer than
    /// `kpl_core::read::MAX_RECORDING_LINE` ends it with an error naming the line).
    pub fn read(&mut self, path: &Path, reader: impl BufRead) -> Result<(), PlotError> {
        let io = |source| PlotError::Io { path: path.display().to_string(), source };
        let mut lines = LineReader::new(reader, MAX_RECORDING_LINE);
        let mut i = 0;
        loop {
            let line = match lines.next_line() {
                Ok(Some(line)) => String::from_utf8_lossy(line),
                Ok(None) => break,
                Err(LineError::Io { source, .. }) => return Err(io(source)),
                Err(error) => {
                    return Err(io(std::io::Error::new(std::io::ErrorKind::InvalidData, error.to_string())));
                }
            };
            i += 1;
            // Cheap test first: most lines of a recording are no events.
            if !line.contains("\"from\"") && !line.contains("\"start\"") {
                continue;
            }
            let Ok(Json::Object(sample)) = serde_json::from_str::<Json>(&line) else { continue };
            let (Some(Json::String(stream)), Some(value)) = (sample.get("stream"), sample.get("value"))
            else {
                continue;
            };
            let records: Vec<&Json> = match value {
                Json::Array(items) => items.iter().collect(),
                other => vec![other],
            };
            for record in records {
                let Json::Object(record) = record else { continue };
                // A monitor's episode (`start`, `end`, `verdict`) is an event when its verdict held.
                let Some(from) = record.get("from").or_else(|| record.get("start")) else { continue };
                if record.get("verdict") == Some(&Json::Bool(false)) {
                    continue;
                }
                match event_of(stream, record, from) {
                    Ok(event) => self.add(event),
                    Err(what) => {
                        self.problems += 1;
                        if self.examples.len() < 8 {
                            self.examples.push(format!("{}:{i}: {what}", path.display()));
                        }
                    }
                }
            }
        }
        Ok(())
    }

    fn add(&mut self, event: Event) {
        let key = (event.stream, event.name, event.objects, event.from);
        match self.found.get_mut(&key) {
            Some(to) => {
                // The latest report wins, an end over an open report.
                if event.to.is_some() || to.is_none() {
                    *to = event.to;
                }
            }
            None => {
                self.found.insert(key.clone(), event.to);
                self.order.push(key);
            }
        }
    }

    /// The events in order of their first report.
    pub fn finish(self) -> Events {
        let EventReader { found, order, problems, examples } = self;
        let events = order
            .into_iter()
            .map(|key| {
                let to = found.get(&key).copied().flatten();
                let (stream, name, objects, from) = key;
                Event { name, stream, from, to, objects }
            })
            .collect();
        Events { events, problems, examples }
    }
}

fn event_of(stream: &str, record: &serde_json::Map<String, Json>, from: &Json) -> Result<Event, String> {
    let from = from.as_i64().ok_or_else(|| format!("event `from` is not an integer time: {from}"))?;
    let to = match record.get("to").or_else(|| record.get("end")) {
        None | Some(Json::Null) => None,
        Some(to) => Some(to.as_i64().ok_or_else(|| format!("event `to` is not an integer time: {to}"))?),
    };
    if let Some(to) = to
        && to < from
    {
        return Err(format!("event ends ({to}) before it begins ({from})"));
    }
    let name = ["situation", "name"]
        .iter()
        .find_map(|k| record.get(*k).and_then(Json::as_str))
        .unwrap_or(stream)
        .to_string();
    let objects = match record.get("objects") {
        Some(Json::Array(items)) => items.iter().filter_map(|v| v.as_str().map(str::to_string)).collect(),
        Some(other) => return Err(format!("event `objects` is not a list of symbols: {other}")),
        None => record
            .iter()
            .filter(|(k, _)| !matches!(k.as_str(), "name" | "situation"))
            .filter_map(|(_, v)| v.as_str().map(str::to_string))
            .collect(),
    };
    Ok(Event { name, stream: stream.to_string(), from, to, objects })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, reason = "tests")]
    use super::*;

    fn read(text: &str) -> Events {
        let mut r = EventReader::default();
        r.read(Path::new("run.jsonl"), text.as_bytes()).unwrap();
        r.finish()
    }

    #[test]
    fn monitor_episodes_are_events_when_their_verdict_held() {
        let events = read(concat!(
            r#"{"stream":"overtake","valid":31,"value":{"a":"co7","b":"co6","end":31,"start":26,"verdict":true}}"#,
            "\n",
            r#"{"stream":"overtake","valid":40,"value":{"a":"co7","b":"co6","end":40,"start":32,"verdict":false}}"#,
            "\n",
        ));
        assert_eq!(events.problems, 0);
        assert_eq!(events.events.len(), 1, "{:?}", events.events);
        let e = &events.events[0];
        assert_eq!((e.name.as_str(), e.from, e.to), ("overtake", 26, Some(31)));
        assert_eq!(e.objects, ["co7", "co6"]);
    }

    #[test]
    fn merges_repeated_reports_and_takes_symbols_from_fields() {
        let events = read(concat!(
            r#"{"stream":"tracker","valid":0,"value":[{"id":"vp1","pos":[0,0]}]}"#,
            "\n",
            r#"{"stream":"too_fast","valid":5,"value":[{"c":"co3","from":2,"to":null}]}"#,
            "\n",
            r#"{"stream":"too_fast","valid":9,"value":{"c":"co3","from":2,"to":8}}"#,
            "\n",
            r#"{"stream":"sit","valid":9,"value":[{"situation":"overtakes","objects":["co1","co2"],"from":1}]}"#,
            "\n",
        ));
        assert_eq!(events.problems, 0);
        assert_eq!(
            events.events,
            vec![
                Event {
                    name: "too_fast".into(),
                    stream: "too_fast".into(),
                    from: 2,
                    to: Some(8),
                    objects: vec!["co3".into()]
                },
                Event {
                    name: "overtakes".into(),
                    stream: "sit".into(),
                    from: 1,
                    to: None,
                    objects: vec!["co1".into(), "co2".into()]
                },
            ]
        );
    }

    #[test]
    fn bad_event_records_are_counted_with_their_line() {
        let events = read(concat!(
            r#"{"stream":"s","valid":0,"value":[{"from":"soon"}]}"#,
            "\n",
            r#"{"stream":"s","valid":0,"value":[{"from":5,"to":1}]}"#,
            "\n",
            "not json \"from\"\n",
        ));
        assert!(events.events.is_empty());
        assert_eq!(events.problems, 2);
        assert_eq!(events.examples[1], "run.jsonl:2: event ends (1) before it begins (5)");
    }
}
