//! Writing rosbag2 bags, as `ros2 bag record` with its MCAP storage writes them, so ROS 2 tools
//! (`ros2 bag play`/`info`, `rosbags`, Foxglove) open a KPL run: a folder with `metadata.yaml`
//! and `<folder>_0.mcap` (profile `ros2`, one channel per topic with message encoding `cdr`, a
//! `ros2msg` schema named `pkg/msg/Name`, the channel metadata `offered_qos_profiles` and
//! `topic_type_hash`, the bag's metadata again in a `rosbag2` metadata record). A message's log
//! and publish times are when it was published (the sample's available time); its valid time is
//! in its `header.stamp`, as on the wire.
//!
//! [`Publications`] are the topics a spec's `ros2.publish` sinks declare: the samples of their
//! input streams, mapped and encoded exactly as a run publishes them (`kpl convert` writes a
//! recording through them).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use kpl_core::{Time, Value, ValueType};
use kpl_ros2::mapping::OutMap;
use kpl_ros2::rosbag2::{Bag, BagFile, BagTopic};
use kpl_ros2::wire::{self, Qos};
use kpl_ros2::{Schema, cdr, topic};
use kpl_semantic::hir;
use mcap::records::{MessageHeader, Metadata};

use crate::write::{WriteError, mcap_time};

/// A topic of a bag being written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicId(usize);

struct Topic {
    /// Its channel in the open file.
    channel: u16,
    sequence: u32,
    ros2msg: String,
    metadata: BTreeMap<String, String>,
    info: BagTopic,
}

/// When a bag's MCAP file is closed and the next one opened, as `ros2 bag record
/// --max-bag-size --max-bag-duration` splits a recording: once the messages of the open file
/// reach `max_bytes` bytes of CDR, or a message would come `max_duration` (microseconds) or more
/// after the file's first. `None`: never.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Split {
    pub max_bytes: Option<u64>,
    pub max_duration: Option<Time>,
}

/// The MCAP file being written and what the bag's metadata says of it.
struct Open {
    writer: mcap::Writer<BufWriter<File>>,
    file: BagFile,
    bytes: u64,
    /// The log time of the open chunk's first message: the chunk is closed and flushed once it
    /// spans [`crate::write::CHUNK_WINDOW`], so a killed run leaves the chunks before it.
    chunk_start: Option<u64>,
}

/// A rosbag2 bag being written: [`BagWriter::finish`] writes its metadata.
pub struct BagWriter {
    dir: PathBuf,
    name: String,
    split: Split,
    open: Open,
    /// The files closed so far.
    files: Vec<BagFile>,
    topics: Vec<Topic>,
    start: Option<u64>,
    end: u64,
}

impl std::fmt::Debug for BagWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BagWriter").field("dir", &self.dir).field("file", &self.open.file.path).finish()
    }
}

/// Creates the bag's `index`th MCAP file, `<name>_<index>.mcap`, in `dir`.
fn create_file(dir: &Path, name: &str, index: usize) -> Result<Open, WriteError> {
    let file = format!("{name}_{index}.mcap");
    let path = dir.join(&file);
    let display = || path.display().to_string();
    let out = File::create(&path).map_err(|error| WriteError::Io { path: display(), error })?;
    let options = mcap::WriteOptions::new()
        .profile("ros2")
        .library(concat!("kpl ", env!("CARGO_PKG_VERSION")))
        // rosbag2's MCAP storage writes uncompressed chunks by default.
        .compression(None)
        .compression_threads(0)
        .disable_seeking(true);
    let writer =
        options.create(BufWriter::new(out)).map_err(|error| WriteError::Mcap { path: display(), error })?;
    Ok(Open {
        writer,
        file: BagFile { path: file, start: 0, end: 0, message_count: 0 },
        bytes: 0,
        chunk_start: None,
    })
}

impl BagWriter {
    /// Creates the bag's folder (and those it is in) and its first MCAP file, replacing a bag of
    /// the same name there; one file for the whole recording.
    pub fn create(dir: &Path) -> Result<BagWriter, WriteError> {
        BagWriter::create_split(dir, Split::default())
    }

    /// [`BagWriter::create`], closing a file and going on in the next as `split` says.
    pub fn create_split(dir: &Path, split: Split) -> Result<BagWriter, WriteError> {
        let name =
            dir.file_name().and_then(|n| n.to_str()).filter(|n| !n.is_empty()).unwrap_or("bag").to_string();
        std::fs::create_dir_all(dir)
            .map_err(|error| WriteError::Io { path: dir.display().to_string(), error })?;
        // The files of an earlier bag of this name would be read as part of this one.
        if let Ok(entries) = std::fs::read_dir(dir) {
            for entry in entries.flatten() {
                let path = entry.path();
                let stale = path.file_name().and_then(|n| n.to_str()).is_some_and(|n| {
                    n.strip_prefix(name.as_str())
                        .and_then(|rest| rest.strip_prefix('_'))
                        .and_then(|rest| rest.strip_suffix(".mcap"))
                        .is_some_and(|index| !index.is_empty() && index.bytes().all(|b| b.is_ascii_digit()))
                });
                if stale {
                    std::fs::remove_file(&path)
                        .map_err(|error| WriteError::Io { path: path.display().to_string(), error })?;
                }
            }
        }
        let open = create_file(dir, &name, 0)?;
        Ok(BagWriter {
            dir: dir.to_path_buf(),
            name,
            split,
            open,
            files: Vec::new(),
            topics: Vec::new(),
            start: None,
            end: 0,
        })
    }

    fn mcap_error(&self, error: mcap::McapError) -> WriteError {
        WriteError::Mcap { path: self.dir.join(&self.open.file.path).display().to_string(), error }
    }

    /// Declares `topic`'s schema and channel in the open file.
    fn declare(open: &mut Open, topic: &Topic) -> Result<u16, mcap::McapError> {
        let schema_id = open.writer.add_schema(&topic.info.type_name, "ros2msg", topic.ros2msg.as_bytes())?;
        open.writer.add_channel(schema_id, &topic.info.name, "cdr", &topic.metadata)
    }

    /// Adds a topic of messages of `schema`'s type, offered with `qos`.
    pub fn add_topic(&mut self, name: &str, schema: &Schema, qos: Qos) -> Result<TopicId, WriteError> {
        let type_hash = schema.type_hash();
        let metadata = BTreeMap::from([
            ("offered_qos_profiles".to_string(), kpl_ros2::rosbag2::qos_profiles(&qos, 0)),
            ("topic_type_hash".to_string(), type_hash.clone()),
        ]);
        let info = BagTopic {
            name: name.to_string(),
            type_name: schema.name().to_string(),
            type_hash,
            qos,
            message_count: 0,
        };
        let mut topic = Topic { channel: 0, sequence: 0, ros2msg: schema.ros2msg(), metadata, info };
        topic.channel = BagWriter::declare(&mut self.open, &topic).map_err(|e| self.mcap_error(e))?;
        self.topics.push(topic);
        Ok(TopicId(self.topics.len() - 1))
    }

    /// The bag's metadata with the files closed so far and the open one.
    fn bag(&self) -> Bag {
        let start = self.start.unwrap_or(0);
        let mut files = self.files.clone();
        files.push(self.open.file.clone());
        Bag {
            files,
            start,
            end: self.end.max(start),
            topics: self.topics.iter().map(|t| t.info.clone()).collect(),
        }
    }

    /// Closes the open file and opens the next, with every topic declared again (as rosbag2
    /// does on a split).
    fn split_now(&mut self) -> Result<(), WriteError> {
        let information = self.bag().information(0);
        let mut next = create_file(&self.dir, &self.name, self.files.len() + 1)?;
        for topic in &mut self.topics {
            topic.channel = BagWriter::declare(&mut next, topic).map_err(|error| WriteError::Mcap {
                path: self.dir.join(&next.file.path).display().to_string(),
                error,
            })?;
        }
        let closed = std::mem::replace(&mut self.open, next);
        self.files.push(close(&self.dir, closed, information)?);
        Ok(())
    }

    /// Whether a message received at `ns` goes into a new file.
    fn splits_at(&self, ns: u64) -> bool {
        let open = &self.open;
        open.file.message_count > 0
            && (self.split.max_bytes.is_some_and(|max| open.bytes >= max)
                || self
                    .split
                    .max_duration
                    .is_some_and(|max| ns.saturating_sub(open.file.start) >= max.unsigned_abs() * 1000))
    }

    /// Writes one CDR message (with its encapsulation header) received at `time` (microseconds
    /// since the epoch).
    pub fn write(&mut self, topic: TopicId, time: Time, cdr: &[u8]) -> Result<(), WriteError> {
        if topic.0 >= self.topics.len() {
            return Ok(());
        }
        let ns = mcap_time(time);
        if self.splits_at(ns) {
            self.split_now()?;
        }
        let t = &mut self.topics[topic.0];
        t.sequence = t.sequence.wrapping_add(1);
        t.info.message_count += 1;
        let header =
            MessageHeader { channel_id: t.channel, sequence: t.sequence, log_time: ns, publish_time: ns };
        self.start = Some(self.start.map_or(ns, |s| s.min(ns)));
        self.end = self.end.max(ns);
        let open = &mut self.open;
        open.file.start = if open.file.message_count == 0 { ns } else { open.file.start.min(ns) };
        open.file.end = open.file.end.max(ns);
        open.file.message_count += 1;
        open.bytes += cdr.len() as u64;
        let written = open.writer.write_to_known_channel(&header, cdr);
        written.map_err(|e| self.mcap_error(e))?;
        let open = &mut self.open;
        let chunk_start = *open.chunk_start.get_or_insert(ns);
        if ns.saturating_sub(chunk_start) >= crate::write::CHUNK_WINDOW.unsigned_abs() * 1000 {
            open.chunk_start = None;
            let flushed = open.writer.flush();
            flushed.map_err(|e| self.mcap_error(e))?;
        }
        Ok(())
    }

    /// Writes the rest of the open MCAP file (with the `rosbag2` metadata record) and
    /// `metadata.yaml`; returns the bag's metadata.
    pub fn finish(self) -> Result<Bag, WriteError> {
        let bag = self.bag();
        let BagWriter { dir, open, .. } = self;
        close(&dir, open, bag.information(0))?;
        let yaml = dir.join("metadata.yaml");
        std::fs::write(&yaml, bag.metadata_yaml())
            .map_err(|error| WriteError::Io { path: yaml.display().to_string(), error })?;
        Ok(bag)
    }
}

/// Writes the rest of a bag's file, with the `rosbag2` metadata record (`information`: the bag
/// as it stands).
fn close(dir: &Path, open: Open, information: String) -> Result<BagFile, WriteError> {
    let Open { mut writer, file, .. } = open;
    let metadata = Metadata {
        name: "rosbag2".into(),
        metadata: BTreeMap::from([("serialized_metadata".to_string(), information)]),
    };
    let path = dir.join(&file.path).display().to_string();
    let mcap = |error| WriteError::Mcap { path: path.clone(), error };
    writer.write_metadata(&metadata).map_err(mcap)?;
    writer.finish().map_err(mcap)?;
    writer.into_inner().flush().map_err(|error| WriteError::Io { path: path.clone(), error })?;
    Ok(file)
}

/// A topic a spec's `ros2.publish` declares: the stream it publishes, its name (with the
/// namespace), type, QoS and mapping.
pub struct Publication {
    /// The sink's name in the spec.
    pub process: String,
    /// The name of the stream it publishes, as a recording names it.
    pub stream: String,
    pub stream_type: ValueType,
    pub topic: String,
    pub schema: Arc<Schema>,
    pub qos: Qos,
    map: OutMap,
    buffer: Vec<u8>,
}

impl std::fmt::Debug for Publication {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Publication").field("process", &self.process).field("topic", &self.topic).finish()
    }
}

impl Publication {
    /// The message of one sample, in CDR as the run publishes it.
    pub fn encode(&mut self, valid: Time, value: &Value) -> Result<&[u8], String> {
        let msg = self.map.apply(valid, value)?;
        cdr::encode_into(&self.schema, &msg, &mut self.buffer).map_err(|e| e.to_string())?;
        Ok(&self.buffer)
    }
}

/// The `ros2.publish` sinks of a checked spec whose folder is `dir` (where `msgs` is read), in
/// the spec's order; an error names the sink and what is wrong.
pub fn publications(spec: &hir::Spec, dir: &Path) -> Result<Vec<Publication>, String> {
    let mut out = Vec::new();
    for process in &spec.processes {
        let hir::ProcessKind::Sink(call) = &process.kind else { continue };
        if call.entry != "ros2.publish" {
            continue;
        }
        let Some(input) = process.inputs.first() else { continue };
        let params = &call.params;
        let err = |e: kpl_ros2::mapping::MapError| {
            format!("sink `{}`: {}", process.name, topic::describe(params, &e))
        };
        let schema = topic::schema_in(params, dir).map_err(err)?;
        let map = OutMap::compile(schema.clone(), &topic::out_spec(params), &input.stream.ty).map_err(err)?;
        let namespace = topic::text(params, "namespace");
        let name = topic::text(params, "topic");
        wire::check_topic(name).map_err(|e| format!("sink `{}`: `topic`: {e}", process.name))?;
        let depth = params.get("depth").and_then(Value::as_i64).unwrap_or(10);
        let qos = Qos {
            reliable: topic::text(params, "reliability") != "best_effort",
            transient_local: topic::text(params, "durability") == "transient_local",
            depth: u32::try_from(depth).ok().filter(|d| *d > 0),
        };
        out.push(Publication {
            process: process.name.clone(),
            stream: input.stream.name.clone(),
            stream_type: input.stream.ty.clone(),
            topic: wire::qualify(if namespace.is_empty() { "/" } else { namespace }, name),
            schema,
            qos,
            map,
            buffer: Vec::new(),
        });
    }
    Ok(out)
}

/// The MCAP files of a bag: `path` itself if it is a file, else the folder's `.mcap` files in
/// name order (rosbag2 splits a long recording into `<bag>_0.mcap`, `<bag>_1.mcap`, ...).
pub fn bag_files(path: &Path) -> std::io::Result<Vec<PathBuf>> {
    if !path.is_dir() {
        return Ok(vec![path.to_path_buf()]);
    }
    let mut files: Vec<PathBuf> = std::fs::read_dir(path)?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    // `_10` after `_9`: by the number before the extension, then by name.
    files.sort_by_key(|p| {
        let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or("");
        let number = stem.rsplit('_').next().and_then(|n| n.parse::<u64>().ok()).unwrap_or(0);
        (number, p.clone())
    });
    if files.is_empty() {
        return Err(std::io::Error::new(std::io::ErrorKind::NotFound, "a folder without .mcap files"));
    }
    Ok(files)
}

/// The type hashes that a bag's `metadata.yaml` records, by topic (none when `path` is an MCAP
/// file or its folder has no `metadata.yaml`; [`kpl_ros2::rosbag2::recorded_type_hashes`]).
pub fn recorded_hashes(path: &Path) -> Result<BTreeMap<String, String>, String> {
    let metadata = path.join("metadata.yaml");
    if !path.is_dir() || !metadata.is_file() {
        return Ok(BTreeMap::new());
    }
    // A bag's metadata.yaml is a few kB per topic: 16 MB is far beyond any real one.
    let bytes = kpl_core::read::read_file(&metadata, 16 << 20).map_err(|e| e.to_string())?;
    Ok(kpl_ros2::rosbag2::recorded_type_hashes(&String::from_utf8_lossy(&bytes)))
}
