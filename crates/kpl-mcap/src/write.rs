//! Writing samples to an MCAP file: one channel per stream (its topic the stream's name), each
//! with the JSON schema of the stream's type; every message is the JSON of one sample,
//! `{"valid": ..., "available": ..., "value": ...}`, in the order it was written.
//!
//! The message's MCAP log time is the sample's available time and its publish time the valid
//! time, in nanoseconds (tools order and seek by them); times before 0 are written as 0 there,
//! the message itself keeps them exactly.
//!
//! A run can be killed at any moment, so the file on disk is always readable up to its last
//! whole chunk: a chunk is built in memory and written whole (never a placeholder header patched
//! afterwards, which a killed writer would leave as a chunk of length `u64::MAX`), and a chunk is
//! closed and flushed to the file once its messages span [`CHUNK_WINDOW`] of available time (or
//! reach 1 MiB), so a killed run loses at most that much. `read::Reader` reads such a file, and
//! recovers what an unfinished chunk holds.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use kpl_core::{Time, ValueType};
use kpl_runtime::Sample;
use mcap::records::MessageHeader;
use serde::Serialize;

use crate::{SAMPLE_KEY, SAMPLE_VERSION, TYPE_KEY, schema};

/// How the chunks of the file are compressed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compression {
    /// zstd, the MCAP default.
    Zstd,
    Lz4,
    None,
}

impl Compression {
    /// The names `file.mcap(compression: ...)` takes.
    pub const NAMES: [&'static str; 3] = ["zstd", "lz4", "none"];

    pub fn from_name(name: &str) -> Option<Compression> {
        match name {
            "zstd" => Some(Compression::Zstd),
            "lz4" => Some(Compression::Lz4),
            "none" => Some(Compression::None),
            _ => None,
        }
    }

    fn mcap(self) -> Option<mcap::Compression> {
        match self {
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::Lz4 => Some(mcap::Compression::Lz4),
            Compression::None => None,
        }
    }
}

/// Why a recording could not be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    #[error("cannot write {path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("cannot write {path}: {error}")]
    Mcap { path: String, error: mcap::McapError },
    #[error("cannot write {path}: {error}")]
    Json { path: String, error: serde_json::Error },
}

/// The available time a chunk spans at most before it is closed and written to the file: what a
/// run killed with -9 can lose.
pub const CHUNK_WINDOW: Time = 1_000_000;

/// A stream's channel in a [`Recorder`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StreamId(usize);

#[derive(Debug)]
struct Channel {
    id: u16,
    sequence: u32,
}

/// An MCAP file being written.
pub struct Recorder {
    path: PathBuf,
    writer: mcap::Writer<BufWriter<File>>,
    channels: Vec<Channel>,
    buffer: Vec<u8>,
    /// The available time of the open chunk's first message.
    chunk_start: Option<Time>,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder").field("path", &self.path).field("channels", &self.channels).finish()
    }
}

#[derive(Serialize)]
struct Envelope {
    valid: Time,
    available: Time,
    value: serde_json::Value,
}

/// Nanoseconds for MCAP's log and publish times (0 for times before 0).
pub fn mcap_time(t: Time) -> u64 {
    u64::try_from(t).map_or(0, |us| us.saturating_mul(1000))
}

impl Recorder {
    /// Creates (or replaces) the file, and the directories it is in.
    pub fn create(path: &Path, compression: Compression) -> Result<Recorder, WriteError> {
        let display = || path.display().to_string();
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|error| WriteError::Io { path: display(), error })?;
        }
        let file = File::create(path).map_err(|error| WriteError::Io { path: display(), error })?;
        let options = mcap::WriteOptions::new()
            .compression(compression.mcap())
            .library(concat!("kpl ", env!("CARGO_PKG_VERSION")))
            // Compress on the writing thread: a sink must not start threads of its own.
            .compression_threads(0)
            // Chunks are built in memory and written whole: a killed run leaves whole chunks.
            .disable_seeking(true);
        let writer = options
            .create(BufWriter::new(file))
            .map_err(|error| WriteError::Mcap { path: display(), error })?;
        Ok(Recorder {
            path: path.to_path_buf(),
            writer,
            channels: Vec::new(),
            buffer: Vec::new(),
            chunk_start: None,
        })
    }

    fn mcap_error(&self, error: mcap::McapError) -> WriteError {
        WriteError::Mcap { path: self.path.display().to_string(), error }
    }

    /// Adds a stream's channel: topic `name`, messages described by the schema of `ty`.
    pub fn add_stream(&mut self, name: &str, ty: &ValueType) -> Result<StreamId, WriteError> {
        let schema = serde_json::to_vec(&schema::sample_schema(ty))
            .map_err(|error| WriteError::Json { path: self.path.display().to_string(), error })?;
        let schema_id =
            self.writer.add_schema(&ty.to_string(), "jsonschema", &schema).map_err(|e| self.mcap_error(e))?;
        let metadata = BTreeMap::from([
            (SAMPLE_KEY.to_string(), SAMPLE_VERSION.to_string()),
            (TYPE_KEY.to_string(), ty.to_string()),
        ]);
        // Two inputs of one sink can be the same stream: they get channels of their own.
        let id = (0..=u16::MAX)
            .find(|id| !self.channels.iter().any(|c| c.id == *id))
            .ok_or_else(|| self.mcap_error(mcap::McapError::TooManyChannels))?;
        self.writer
            .add_channel_with_id(id, schema_id, name, "json", &metadata)
            .map_err(|e| self.mcap_error(e))?;
        self.channels.push(Channel { id, sequence: 0 });
        Ok(StreamId(self.channels.len() - 1))
    }

    /// Adds a channel of messages given already encoded (the views of [`crate::foxglove`]):
    /// `topic`, its schema (`name`, `encoding`, `data`), the messages' encoding and the channel's
    /// metadata.
    pub fn add_channel(
        &mut self,
        topic: &str,
        schema: (&str, &str, &[u8]),
        message_encoding: &str,
        metadata: BTreeMap<String, String>,
    ) -> Result<StreamId, WriteError> {
        let (name, encoding, data) = schema;
        let schema_id = self.writer.add_schema(name, encoding, data).map_err(|e| self.mcap_error(e))?;
        let id = (0..=u16::MAX)
            .find(|id| !self.channels.iter().any(|c| c.id == *id))
            .ok_or_else(|| self.mcap_error(mcap::McapError::TooManyChannels))?;
        self.writer
            .add_channel_with_id(id, schema_id, topic, message_encoding, &metadata)
            .map_err(|e| self.mcap_error(e))?;
        self.channels.push(Channel { id, sequence: 0 });
        Ok(StreamId(self.channels.len() - 1))
    }

    /// Writes one message already encoded on a channel of [`Recorder::add_channel`]; its MCAP log
    /// and publish times are `log_time` and `publish_time` (microseconds).
    pub fn write_raw(
        &mut self,
        stream: StreamId,
        log_time: Time,
        publish_time: Time,
        data: &[u8],
    ) -> Result<(), WriteError> {
        let Some(channel) = self.channels.get_mut(stream.0) else { return Ok(()) };
        channel.sequence = channel.sequence.wrapping_add(1);
        let header = MessageHeader {
            channel_id: channel.id,
            sequence: channel.sequence,
            log_time: mcap_time(log_time),
            publish_time: mcap_time(publish_time),
        };
        self.writer.write_to_known_channel(&header, data).map_err(|e| self.mcap_error(e))?;
        self.after_message(log_time)
    }

    /// Writes one sample of a stream.
    pub fn write(&mut self, stream: StreamId, sample: &Sample) -> Result<(), WriteError> {
        self.write_json(stream, sample.valid, sample.available, sample.value.to_json())
    }

    /// Writes one sample of a stream given as JSON (its value as `Value::to_json` writes it).
    pub fn write_json(
        &mut self,
        stream: StreamId,
        valid: Time,
        available: Time,
        value: serde_json::Value,
    ) -> Result<(), WriteError> {
        let envelope = Envelope { valid, available, value };
        self.buffer.clear();
        serde_json::to_writer(&mut self.buffer, &envelope)
            .map_err(|error| WriteError::Json { path: self.path.display().to_string(), error })?;
        let Some(channel) = self.channels.get_mut(stream.0) else { return Ok(()) };
        channel.sequence = channel.sequence.wrapping_add(1);
        let header = MessageHeader {
            channel_id: channel.id,
            sequence: channel.sequence,
            log_time: mcap_time(available),
            publish_time: mcap_time(valid),
        };
        self.writer.write_to_known_channel(&header, &self.buffer).map_err(|e| self.mcap_error(e))?;
        self.after_message(available)
    }

    /// Closes the open chunk (and flushes the file) once it spans [`CHUNK_WINDOW`].
    fn after_message(&mut self, available: Time) -> Result<(), WriteError> {
        let start = *self.chunk_start.get_or_insert(available);
        if available.saturating_sub(start) >= CHUNK_WINDOW {
            self.chunk_start = None;
            self.writer.flush().map_err(|e| self.mcap_error(e))?;
        }
        Ok(())
    }

    /// Writes the rest of the file (the last chunk, the summary and the footer) and flushes it.
    /// (Dropping a recorder finishes the file too, without saying whether that failed.)
    pub fn finish(mut self) -> Result<(), WriteError> {
        self.writer.finish().map_err(|e| self.mcap_error(e))?;
        let path = self.path.display().to_string();
        self.writer.into_inner().flush().map_err(|error| WriteError::Io { path, error })
    }
}
