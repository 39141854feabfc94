//! What a cut-short MCAP file still holds: the records of a file walked one by one, into its
//! chunks, including an unfinished last chunk (a run killed while writing it, or an older writer
//! that left its header as placeholders of `u64::MAX`), decompressed as far as its bytes go.
//!
//! [`crate::read::Reader`] switches to a [`Walker`] when the regular reader stops on a file that
//! is not whole, and takes the messages it had not read yet from it. Memory stays bounded: one
//! record at a time, a chunk's compressed bytes at most [`crate::read::RECORD_LIMIT`].

use std::fs::File;
use std::io::{BufReader, Cursor, Read};
use std::path::Path;

use mcap::records::op;

use crate::read::RECORD_LIMIT;

/// The MCAP magic at the start of a file.
const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// A record found by a [`Walker`]: its opcode and its body.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawRecord {
    pub opcode: u8,
    pub body: Vec<u8>,
}

/// Where a walk stopped.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct WalkEnd {
    /// Why the walk stopped before the end of the file's records ("" at a clean end).
    pub reason: String,
    /// Messages found in chunks that were not finished.
    pub from_unfinished_chunks: u64,
}

/// Walks the records of a file in file order, chunks opened, stopping at the first record that
/// is cut short (after what an unfinished chunk holds).
pub struct Walker {
    file: BufReader<File>,
    /// Bytes of the file not read yet.
    left: u64,
    /// The decompressed records of the chunk being walked, and whether it is unfinished.
    chunk: Option<(Box<dyn Read + Send>, bool)>,
    end: Option<WalkEnd>,
    from_unfinished: u64,
}

impl std::fmt::Debug for Walker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Walker").field("left", &self.left).field("end", &self.end).finish()
    }
}

/// Reads exactly `buf.len()` bytes; `Ok(false)` when the reader ends first (at any point).
fn read_full<R: Read + ?Sized>(reader: &mut R, buf: &mut [u8]) -> std::io::Result<bool> {
    let mut filled = 0;
    while filled < buf.len() {
        match reader.read(&mut buf[filled..]) {
            Ok(0) => return Ok(false),
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(true)
}

fn u64_at(bytes: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(bytes.get(at..at + 8)?.try_into().ok()?))
}

fn u32_at(bytes: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(bytes.get(at..at + 4)?.try_into().ok()?))
}

impl Walker {
    /// Opens a file and checks its magic.
    pub fn open(path: &Path) -> Result<Walker, String> {
        let file = kpl_core::read::open(path).map_err(|e| e.to_string())?;
        let len = file.metadata().map_err(|e| format!("cannot read {}: {e}", path.display()))?.len();
        let mut file = BufReader::new(file);
        let mut magic = [0u8; 8];
        if !read_full(&mut file, &mut magic).unwrap_or(false) || &magic != MAGIC {
            return Err("the file does not start with the MCAP magic".into());
        }
        Ok(Walker { file, left: len.saturating_sub(8), chunk: None, end: None, from_unfinished: 0 })
    }

    /// Why the walk ended, once [`Walker::next_record`] returned `None`.
    pub fn end(&self) -> Option<&WalkEnd> {
        self.end.as_ref()
    }

    fn stop(&mut self, reason: impl Into<String>) -> Option<RawRecord> {
        self.chunk = None;
        self.end = Some(WalkEnd { reason: reason.into(), from_unfinished_chunks: self.from_unfinished });
        None
    }

    /// The next record (those inside chunks instead of the chunks), or `None` at the end.
    pub fn next_record(&mut self) -> Option<RawRecord> {
        if self.end.is_some() {
            return None;
        }
        loop {
            if let Some((chunk, unfinished)) = &mut self.chunk {
                match read_record(chunk.as_mut()) {
                    Ok(Some(record)) => {
                        if *unfinished && record.opcode == op::MESSAGE {
                            self.from_unfinished += 1;
                        }
                        return Some(record);
                    }
                    // The end of a chunk's records: go on after it, unless it was the unfinished
                    // last one.
                    Ok(None) if !*unfinished => self.chunk = None,
                    Ok(None) | Err(_) => {
                        return self.stop("the file ends inside a chunk that was not finished");
                    }
                }
                continue;
            }
            let mut head = [0u8; 9];
            match read_full(&mut self.file, &mut head) {
                Ok(true) => {}
                Ok(false) if self.left == 0 => return self.stop("the file ends without its footer"),
                Ok(false) => return self.stop("the file ends inside a record"),
                Err(e) => return self.stop(format!("cannot read the file: {e}")),
            }
            self.left = self.left.saturating_sub(9);
            let opcode = head[0];
            let len =
                u64::from_le_bytes([head[1], head[2], head[3], head[4], head[5], head[6], head[7], head[8]]);
            if opcode == op::CHUNK {
                if let Err(reason) = self.open_chunk(len) {
                    return self.stop(reason);
                }
                continue;
            }
            if opcode == op::FOOTER || opcode == op::DATA_END {
                return self.stop("");
            }
            let Some(len) =
                usize::try_from(len).ok().filter(|l| *l <= RECORD_LIMIT && *l as u64 <= self.left)
            else {
                return self.stop("the file ends inside a record");
            };
            let mut body = vec![0u8; len];
            match read_full(&mut self.file, &mut body) {
                Ok(true) => {}
                _ => return self.stop("the file ends inside a record"),
            }
            self.left -= len as u64;
            return Some(RawRecord { opcode, body });
        }
    }

    /// Reads a chunk's header and compressed bytes (as many as the file has when it was not
    /// finished) and starts decompressing them.
    fn open_chunk(&mut self, len: u64) -> Result<(), String> {
        let unfinished = len > self.left;
        // message_start_time, message_end_time, uncompressed_size, uncompressed_crc,
        // compression (a string), compressed_size.
        let mut fixed = [0u8; 8 + 8 + 8 + 4 + 4];
        if !read_full(&mut self.file, &mut fixed).map_err(|e| e.to_string())? {
            return Err("the file ends inside a chunk's header".into());
        }
        let name_len = u32_at(&fixed, 28).unwrap_or(0) as usize;
        if name_len > 64 {
            return Err("a chunk's header does not parse".into());
        }
        let mut name = vec![0u8; name_len];
        let mut size = [0u8; 8];
        if !read_full(&mut self.file, &mut name).map_err(|e| e.to_string())?
            || !read_full(&mut self.file, &mut size).map_err(|e| e.to_string())?
        {
            return Err("the file ends inside a chunk's header".into());
        }
        let header_len = (fixed.len() + name_len + 8) as u64;
        self.left = self.left.saturating_sub(header_len);
        let compressed_size = u64_at(&size, 0).unwrap_or(u64::MAX);
        let available = if unfinished { self.left } else { compressed_size.min(self.left) };
        let take = usize::try_from(available)
            .ok()
            .filter(|n| *n <= RECORD_LIMIT)
            .ok_or_else(|| format!("a chunk of {available} bytes is over the {RECORD_LIMIT}-byte limit"))?;
        let mut data = vec![0u8; take];
        let whole = read_full(&mut self.file, &mut data).map_err(|e| e.to_string())?;
        if !whole {
            return Err("the file ends inside a chunk".into());
        }
        self.left -= take as u64;
        if !unfinished {
            // Whatever a finished chunk has after its compressed data (nothing, in files we know).
            let rest = len.saturating_sub(header_len + compressed_size);
            let skipped = std::io::copy(&mut (&mut self.file).take(rest), &mut std::io::sink())
                .map_err(|e| e.to_string())?;
            self.left = self.left.saturating_sub(skipped);
        }
        let compression = String::from_utf8_lossy(&name).into_owned();
        let data = Cursor::new(data);
        let reader: Box<dyn Read + Send> = match compression.as_str() {
            "" => Box::new(data),
            "zstd" => Box::new(zstd::stream::read::Decoder::new(data).map_err(|e| e.to_string())?),
            "lz4" => Box::new(lz4::Decoder::new(data).map_err(|e| e.to_string())?),
            other => {
                return Err(format!("a chunk is compressed with `{other}`, which this reader does not know"));
            }
        };
        self.chunk = Some((reader, unfinished));
        Ok(())
    }
}

/// The next record of a chunk's decompressed records; `Ok(None)` at their end.
fn read_record(reader: &mut (dyn Read + Send)) -> Result<Option<RawRecord>, ()> {
    let mut head = [0u8; 9];
    let mut first = [0u8; 1];
    match reader.read(&mut first) {
        Ok(0) => return Ok(None),
        Ok(_) => head[0] = first[0],
        Err(_) => return Err(()),
    }
    if !read_full(reader, &mut head[1..]).map_err(|_| ())? {
        return Err(());
    }
    let len = u64::from_le_bytes([head[1], head[2], head[3], head[4], head[5], head[6], head[7], head[8]]);
    let len = usize::try_from(len).ok().filter(|l| *l <= RECORD_LIMIT).ok_or(())?;
    let mut body = vec![0u8; len];
    if !read_full(reader, &mut body).map_err(|_| ())? {
        return Err(());
    }
    Ok(Some(RawRecord { opcode: head[0], body }))
}
