//! The process-unit protocol's frames and messages (docs/process-units.md): what kpl and a
//! unit's worker process say to each other over the worker's standard input and output. One
//! place encodes and decodes them; `python/kpl/unit.py` is the reference worker.
//!
//! A frame is a little-endian `u32` length (of what follows it), a kind byte and a body.
//! Kinds: `H` hello (kpl, JSON), `R` ready (worker, JSON), `C` call (kpl, binary: valid time,
//! time now, the inputs as KPL wire messages), `O` output (worker: nothing, or one KPL wire
//! sample message), `E` error (worker, JSON: `error`, `traceback`), `Q` quit (kpl).

use std::io::{Read, Write};

use kpl_core::Time;
use kpl_runtime::sample::Sample;
use serde::{Deserialize, Serialize};

/// The protocol version kpl speaks; the worker's `ready` must say the same.
pub const PROTOCOL: u32 = 1;
/// The largest frame either side accepts.
pub const MAX_FRAME: usize = 256 << 20;
/// An input that has no sample yet, in a call.
const ABSENT: u32 = u32::MAX;

pub const HELLO: u8 = b'H';
pub const READY: u8 = b'R';
pub const CALL: u8 = b'C';
pub const OUTPUT: u8 = b'O';
pub const ERROR: u8 = b'E';
pub const QUIT: u8 = b'Q';

/// What kpl tells a worker when it starts it: the unit to load and how it is called.
#[derive(Debug, Clone, Serialize)]
pub struct Hello {
    pub protocol: u32,
    /// The KPL wire format version of the values in calls and outputs.
    pub wire: u8,
    /// The process's name in the spec.
    pub unit: String,
    pub module: String,
    pub function: String,
    /// Folders to look for the module in first (the spec's directory).
    pub path: Vec<String>,
    /// The names of the unit's inputs, in the order the function takes them.
    pub inputs: Vec<String>,
    /// The declared output type, as the spec writes it.
    pub output: String,
    /// The unit's own parameters (keyword arguments), as JSON.
    pub params: serde_json::Map<String, serde_json::Value>,
    /// `numpy` or `list`: how a `list<float>` input arrives.
    pub arrays: String,
}

/// The worker's answer to [`Hello`].
#[derive(Debug, Clone, Deserialize)]
pub struct Ready {
    pub protocol: u32,
    pub wire: u8,
    /// `function` or `class`.
    pub kind: String,
    /// The language and its version (`python 3.11.7`).
    pub implementation: String,
}

/// A worker's error: the message and, for an exception, its traceback.
#[derive(Debug, Clone, Deserialize, PartialEq, Eq)]
pub struct WorkerError {
    pub error: String,
    #[serde(default)]
    pub traceback: String,
}

/// One frame as read.
#[derive(Debug, Clone)]
pub struct Frame {
    pub kind: u8,
    pub body: Vec<u8>,
}

/// Writes one frame (not flushed).
pub fn write_frame(out: &mut impl Write, kind: u8, body: &[u8]) -> std::io::Result<()> {
    let length = u32::try_from(body.len() + 1)
        .ok()
        .filter(|n| *n as usize <= MAX_FRAME)
        .ok_or_else(|| std::io::Error::other(format!("a frame of {} bytes is too large", body.len() + 1)))?;
    out.write_all(&length.to_le_bytes())?;
    out.write_all(&[kind])?;
    out.write_all(body)
}

/// Reads one frame; `Ok(None)` when the stream ends between frames.
pub fn read_frame(input: &mut impl Read) -> std::io::Result<Option<Frame>> {
    let mut head = [0u8; 5];
    let mut filled = 0;
    while filled < head.len() {
        match input.read(&mut head[filled..])? {
            0 if filled == 0 => return Ok(None),
            0 => {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::UnexpectedEof,
                    "the worker's output ended inside a frame",
                ));
            }
            n => filled += n,
        }
    }
    let length = u32::from_le_bytes([head[0], head[1], head[2], head[3]]) as usize;
    if length == 0 || length > MAX_FRAME {
        return Err(std::io::Error::other(format!("a frame of {length} bytes (at most {MAX_FRAME})")));
    }
    let mut body = vec![0u8; length - 1];
    input.read_exact(&mut body)?;
    Ok(Some(Frame { kind: head[4], body }))
}

/// The body of a call: the valid time, the time now, and each input's latest sample as a KPL
/// wire message (or absent).
pub fn encode_call(
    valid: Time,
    now: Time,
    inputs: &[Option<&Sample>],
    out: &mut Vec<u8>,
) -> Result<(), String> {
    out.clear();
    out.extend_from_slice(&valid.to_le_bytes());
    out.extend_from_slice(&now.to_le_bytes());
    out.extend_from_slice(&(inputs.len() as u32).to_le_bytes());
    let mut message = Vec::new();
    for input in inputs {
        match input {
            None => out.extend_from_slice(&ABSENT.to_le_bytes()),
            Some(sample) => {
                kpl_zenoh::codec::encode_sample(sample, &mut message).map_err(|e| e.to_string())?;
                let length = u32::try_from(message.len()).ok().filter(|n| *n != ABSENT);
                let length = length.ok_or("an input value too large for a call")?;
                out.extend_from_slice(&length.to_le_bytes());
                out.extend_from_slice(&message);
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_round_trip_and_refuse_what_is_cut_or_too_large() {
        let mut bytes = Vec::new();
        write_frame(&mut bytes, CALL, b"abc").unwrap();
        write_frame(&mut bytes, QUIT, b"").unwrap();
        let mut input = &bytes[..];
        let first = read_frame(&mut input).unwrap().unwrap();
        assert_eq!((first.kind, first.body.as_slice()), (CALL, &b"abc"[..]));
        let second = read_frame(&mut input).unwrap().unwrap();
        assert_eq!((second.kind, second.body.len()), (QUIT, 0));
        assert!(read_frame(&mut input).unwrap().is_none());
        let cut = &bytes[..6];
        assert!(read_frame(&mut &cut[..]).is_err());
        let huge = [0xff, 0xff, 0xff, 0x7f, b'O'];
        assert!(read_frame(&mut &huge[..]).is_err());
        let empty = [0, 0, 0, 0, b'O'];
        assert!(read_frame(&mut &empty[..]).is_err());
    }
}
