//! Reading samples from an MCAP file, message by message in file order, without loading it whole.
//!
//! A message's channel says what it is: a channel written by KPL (metadata [`crate::SAMPLE_KEY`])
//! carries sample envelopes `{"valid", "available", "value"}`; another channel with JSON messages
//! (`message_encoding` `json`, written by any tool) carries values, whose valid time is the
//! message's publish time and available time its log time (nanoseconds, truncated to
//! microseconds); a rosbag2 channel (`message_encoding` `cdr`, schema encoding `ros2msg`, as
//! `ros2 bag record` and `rosbags` write them) carries CDR messages, decoded with the channel's
//! message definition (kpl-ros2's codec) into JSON objects with the fields' names, with the same
//! times. Messages are filtered by their channel's topic before they are decoded, then
//! decoded with the replaying source's type as a JSON-lines replay decodes a line. A message that
//! does not decode is malformed (counted, the replay goes on). A file cut short (a killed run) is
//! read on with [`crate::recover::Walker`]: the messages of its whole chunks and what an
//! unfinished last chunk holds, then one malformed entry says where and why it ended. A file that
//! is not MCAP at all, or has a record over [`RECORD_LIMIT`], ends the replay after what came
//! before, with one malformed entry saying so.
//!
//! Channels that KPL writes for viewers (metadata [`crate::VIEW_KEY`]: Foxglove's schemas, see
//! [`crate::foxglove`]) are skipped: the samples are in the stream's own channel.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use kpl_core::{Time, Value, ValueType};
use kpl_runtime::Sample;
use kpl_runtime::builtins::StreamFilter;
use mcap::records::{MessageHeader, Record, op};
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
use serde::Deserialize;

use crate::recover::Walker;
use crate::{SAMPLE_KEY, VIEW_KEY};

/// The largest record (or chunk) a reader accepts, so a hostile file cannot make it allocate
/// without bound.
pub const RECORD_LIMIT: usize = 256 << 20;

/// What a channel's messages are.
#[derive(Debug, Clone, PartialEq)]
enum Encoding {
    /// KPL sample envelopes.
    Sample,
    /// JSON values of another writer.
    Json,
    /// ROS 2 messages in CDR, with their definition (rosbag2).
    Cdr(Arc<kpl_ros2::Schema>),
    /// A channel whose schema this reader cannot use: why.
    Unusable(String),
    /// An encoding this reader does not decode (`cdr`, `protobuf`, ...).
    Other(String),
    /// A channel KPL wrote for viewers, beside the stream's own: skipped.
    View,
}

#[derive(Debug)]
struct Channel {
    topic: Arc<str>,
    encoding: Encoding,
    /// The RIHS01 type hash a rosbag2 channel records (`topic_type_hash`), if it has one.
    type_hash: Option<String>,
}

/// A message as JSON, before its value is typed.
#[derive(Debug, Clone, PartialEq)]
pub enum RawEvent {
    /// A message of stream `stream` with its times and value; `location` is where it is.
    Message { stream: Arc<str>, valid: Time, available: Time, value: serde_json::Value, location: String },
    /// Something that is not a message: what is wrong, and where.
    Malformed { location: String, error: String },
}

/// The next thing a replay gets from a file.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A sample of stream `stream`; `location` is where it is (`f.mcap: message 17`).
    Sample { stream: Arc<str>, sample: Sample, location: String },
    /// Something that is not a sample: what is wrong, and where.
    Malformed { location: String, error: String },
}

/// An MCAP file being read.
pub struct Reader {
    path: PathBuf,
    file: File,
    reader: LinearReader,
    records: Records,
    done: bool,
    /// After the regular reader stopped on a file that is not whole: the walk that reads on, the
    /// messages it still has to pass over (those read already), and why the regular reader stopped.
    salvage: Option<(Walker, u64, String)>,
}

/// The channels of a file and the messages read so far: what turns records into events.
#[derive(Debug)]
struct Records {
    display: String,
    channels: HashMap<u16, Channel>,
    /// The schemas seen so far: name, encoding and text.
    schemas: HashMap<u16, (String, String, Vec<u8>)>,
    /// The shipped ROS 2 message definitions, read at the first rosbag2 channel.
    ros2: Option<kpl_ros2::Definitions>,
    /// The type hashes the bag's `metadata.yaml` records, by topic ([`Reader::recorded_hashes`]).
    recorded: BTreeMap<String, String>,
    /// Messages read so far (kept or not), for locations.
    messages: u64,
}

/// The channel metadata in which rosbag2 (Jazzy on: `ros2 bag record` with its MCAP storage)
/// records a topic's RIHS01 type hash, as `type_description_hash` in `metadata.yaml`.
pub const TYPE_HASH_KEY: &str = "topic_type_hash";

impl Reader {
    /// Has the file's rosbag2 channels checked against the type hashes that its bag's
    /// `metadata.yaml` records (by topic), as against their own `topic_type_hash`.
    pub fn recorded_hashes(mut self, hashes: BTreeMap<String, String>) -> Reader {
        self.records.recorded = hashes;
        self
    }

    /// The type hash that the channels of `topic` read so far record (rosbag2's
    /// `topic_type_hash`; `None` when none does, as in bags of older recorders).
    pub fn type_hash(&self, topic: &str) -> Option<&str> {
        self.records.channels.values().filter(|c| &*c.topic == topic).find_map(|c| c.type_hash.as_deref())
    }
}

impl std::fmt::Debug for Reader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Reader").field("records", &self.records).finish()
    }
}

#[derive(Deserialize)]
struct Envelope {
    valid: Time,
    available: Time,
    value: serde_json::Value,
}

/// Microseconds from MCAP's nanoseconds.
pub fn kpl_time(ns: u64) -> Time {
    Time::try_from(ns / 1000).unwrap_or(Time::MAX)
}

impl Reader {
    /// Opens a file; nothing is read yet.
    pub fn open(path: &Path) -> std::io::Result<Reader> {
        let file = File::open(path)?;
        let options = LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_record_length_limit(RECORD_LIMIT);
        Ok(Reader {
            path: path.to_path_buf(),
            salvage: None,
            file,
            reader: LinearReader::new_with_options(options),
            records: Records {
                display: path.display().to_string(),
                channels: HashMap::new(),
                schemas: HashMap::new(),
                ros2: None,
                recorded: BTreeMap::new(),
                messages: 0,
            },
            done: false,
        })
    }

    /// The next sample of a stream `filter` keeps, decoded with `ty`, or what was wrong; `None` at
    /// the end of the file (or after it stopped being MCAP, which was the last event).
    pub fn next_event(&mut self, filter: &mut StreamFilter, ty: &ValueType) -> Option<Event> {
        Some(match self.next_raw(filter)? {
            RawEvent::Message { stream, valid, available, value, location } => {
                match Value::from_json(&value, ty) {
                    Ok(value) => {
                        Event::Sample { stream, sample: Sample::new(valid, available, value), location }
                    }
                    Err(e) => Event::Malformed { location, error: format!("value {e}") },
                }
            }
            RawEvent::Malformed { location, error } => Event::Malformed { location, error },
        })
    }

    /// The next message of a stream `filter` keeps, its value as JSON (what `kpl convert`
    /// copies), or what was wrong; `None` at the end of the file.
    pub fn next_raw(&mut self, filter: &mut StreamFilter) -> Option<RawEvent> {
        while !self.done {
            if self.salvage.is_some() {
                return self.next_salvaged(filter);
            }
            let event = match self.reader.next_event() {
                None => {
                    self.done = true;
                    return None;
                }
                Some(Err(e)) => {
                    // Read on from the start with the walk, past the messages read already: a
                    // file cut short keeps what its chunks hold.
                    match Walker::open(&self.path) {
                        Ok(walker) => {
                            self.salvage = Some((walker, self.records.messages, e.to_string()));
                            continue;
                        }
                        Err(_) => {
                            self.done = true;
                            return Some(self.records.not_mcap(e.to_string()));
                        }
                    }
                }
                Some(Ok(event)) => event,
            };
            match event {
                LinearReadEvent::ReadRequest(need) => match self.file.read(self.reader.insert(need)) {
                    Ok(read) => self.reader.notify_read(read),
                    Err(e) => {
                        self.done = true;
                        return Some(RawEvent::Malformed {
                            location: self.records.after(),
                            error: format!("cannot read the file: {e}"),
                        });
                    }
                },
                LinearReadEvent::Record { opcode, data } => {
                    if let Some(event) = self.records.record(opcode, data, filter) {
                        return Some(event);
                    }
                }
            }
        }
        None
    }

    /// The next message of the walk that reads on after the regular reader stopped.
    fn next_salvaged(&mut self, filter: &mut StreamFilter) -> Option<RawEvent> {
        loop {
            let (walker, skip, _) = self.salvage.as_mut()?;
            let Some(record) = walker.next_record() else {
                self.done = true;
                let (walker, _, error) = self.salvage.take()?;
                let end = walker.end().cloned().unwrap_or_default();
                if end.reason.is_empty() {
                    return Some(self.records.not_mcap(error));
                }
                let location = self.records.after();
                let unfinished = match end.from_unfinished_chunks {
                    0 => String::new(),
                    n => format!(" ({n} of them from a chunk that was not finished)"),
                };
                return Some(RawEvent::Malformed {
                    location,
                    error: format!(
                        "the file is cut short (a run killed while writing it?): {}; {} message(s) read{unfinished}",
                        end.reason, self.records.messages
                    ),
                });
            };
            if record.opcode == op::MESSAGE && *skip > 0 {
                *skip -= 1;
                continue;
            }
            if let Some(event) = self.records.record(record.opcode, &record.body, filter) {
                return Some(event);
            }
        }
    }
}

impl Records {
    fn location(&self) -> String {
        format!("{}: message {}", self.display, self.messages)
    }

    fn after(&self) -> String {
        format!("{}: after message {}", self.display, self.messages)
    }

    fn not_mcap(&self, error: String) -> RawEvent {
        RawEvent::Malformed { location: self.after(), error: format!("not readable as MCAP: {error}") }
    }

    /// What a record means to a replay: a channel is noted, a message of a stream the filter
    /// keeps is returned.
    fn record(&mut self, opcode: u8, data: &[u8], filter: &mut StreamFilter) -> Option<RawEvent> {
        match opcode {
            op::CHANNEL => match mcap::parse_record(op::CHANNEL, data) {
                Ok(Record::Channel(channel)) => {
                    let type_hash = channel.metadata.get(TYPE_HASH_KEY).filter(|h| !h.is_empty()).cloned();
                    let encoding = if channel.metadata.contains_key(VIEW_KEY) {
                        Encoding::View
                    } else if channel.metadata.contains_key(SAMPLE_KEY) {
                        Encoding::Sample
                    } else if channel.message_encoding == "json" {
                        Encoding::Json
                    } else if channel.message_encoding == "cdr" {
                        self.cdr_encoding(channel.schema_id, &channel.topic, type_hash.as_deref())
                    } else {
                        Encoding::Other(channel.message_encoding.clone())
                    };
                    self.channels
                        .insert(channel.id, Channel { topic: channel.topic.into(), encoding, type_hash });
                    None
                }
                Ok(_) | Err(_) => Some(RawEvent::Malformed {
                    location: self.after(),
                    error: "a channel record does not parse".into(),
                }),
            },
            op::MESSAGE => {
                self.messages += 1;
                let (header, data) = match mcap::parse_record(op::MESSAGE, data) {
                    Ok(Record::Message { header, data }) => (header, data),
                    Ok(_) | Err(_) => {
                        let error = "the message record does not parse".to_string();
                        return Some(RawEvent::Malformed { location: self.location(), error });
                    }
                };
                let Some(channel) = self.channels.get(&header.channel_id) else {
                    let error = format!(
                        "the message is on channel {}, which the file does not declare before it",
                        header.channel_id
                    );
                    return Some(RawEvent::Malformed { location: self.location(), error });
                };
                if matches!(channel.encoding, Encoding::View) || !filter.keep(&channel.topic) {
                    return None;
                }
                let stream = channel.topic.clone();
                Some(match decode(&channel.encoding, &stream, &header, &data) {
                    Ok((valid, available, value)) => {
                        RawEvent::Message { stream, valid, available, value, location: self.location() }
                    }
                    Err(error) => RawEvent::Malformed { location: self.location(), error },
                })
            }
            op::SCHEMA => {
                if let Ok(Record::Schema { header, data }) = mcap::parse_record(op::SCHEMA, data) {
                    self.schemas.insert(header.id, (header.name, header.encoding, data.into_owned()));
                }
                None
            }
            _ => None,
        }
    }

    /// How a `cdr` channel of `topic` with schema `id` is read: its `ros2msg` definition, or why
    /// not (also when the type hash of that definition is not the one the channel or the bag's
    /// `metadata.yaml` records: the definition is not the one the messages were recorded with).
    fn cdr_encoding(&mut self, id: u16, topic: &str, channel_hash: Option<&str>) -> Encoding {
        if id == 0 {
            return Encoding::Unusable("no schema (rosbag2 channels have a `ros2msg` one)".into());
        }
        let Some((name, encoding, data)) = self.schemas.get(&id) else {
            return Encoding::Unusable(format!("its schema {id} is not in the file before it"));
        };
        if encoding != "ros2msg" {
            return Encoding::Unusable(format!(
                "its schema `{name}` has encoding `{encoding}`, not `ros2msg`"
            ));
        }
        let text = String::from_utf8_lossy(data);
        let defs = self.ros2.get_or_insert_with(kpl_ros2::Definitions::builtin);
        let schema = match defs.schema_of_ros2msg(name, &text) {
            Ok(schema) => schema,
            Err(e) => return Encoding::Unusable(format!("its schema `{name}` does not read: {e}")),
        };
        let computed = schema.type_hash();
        let recorded = [
            (channel_hash, "the channel's `topic_type_hash`"),
            (self.recorded.get(topic).map(String::as_str), "the bag's metadata.yaml"),
        ];
        match recorded.into_iter().find_map(|(hash, by)| Some((hash?, by)).filter(|(h, _)| *h != computed)) {
            Some((hash, by)) => Encoding::Unusable(format!(
                "its `ros2msg` schema `{name}` has type hash {computed} and {by} records {hash}: the bag holds another definition of the type than the one its messages were recorded with"
            )),
            None => Encoding::Cdr(schema),
        }
    }
}

/// A message's valid and available times and its value.
fn decode(
    encoding: &Encoding,
    topic: &str,
    header: &MessageHeader,
    data: &[u8],
) -> Result<(Time, Time, serde_json::Value), String> {
    match encoding {
        Encoding::Sample => {
            let envelope: Envelope =
                serde_json::from_slice(data).map_err(|e| format!("not a KPL sample message: {e}"))?;
            Ok((envelope.valid, envelope.available, envelope.value))
        }
        Encoding::Json => {
            let json: serde_json::Value =
                serde_json::from_slice(data).map_err(|e| format!("not a JSON message: {e}"))?;
            Ok((kpl_time(header.publish_time), kpl_time(header.log_time), json))
        }
        Encoding::View => Err(format!("channel `{topic}` is a view of another stream")),
        Encoding::Cdr(schema) => {
            let message = kpl_ros2::cdr::decode(schema, data)
                .map_err(|e| format!("not a CDR `{}`: {e}", schema.name()))?;
            Ok((
                kpl_time(header.publish_time),
                kpl_time(header.log_time),
                kpl_ros2::json::to_json(schema, &message),
            ))
        }
        Encoding::Unusable(why) => Err(format!("channel `{topic}` has message encoding `cdr`, but {why}")),
        Encoding::Other(name) => Err(format!(
            "channel `{topic}` has message encoding `{name}`; file.mcap reads JSON messages and rosbag2 CDR messages (docs/streams.md)"
        )),
    }
}
