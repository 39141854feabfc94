//! Reading what users give, with caps: every reader of a user's file (specs, recordings, traffic,
//! road networks, occluders, ground truth) goes through here, so that a file that is not what it
//! claims to be (`/dev/zero`, a gzip bomb, a binary file without line breaks) ends in a clear error
//! naming the file (and the line) instead of filling the memory.
//!
//! - [`open`]: a file to read, refusing a directory (which opens on Unix, and then every read
//!   fails). Every reader of a user's file opens it here (a test of the workspace checks that
//!   nothing else opens files for reading), and then reads it with one of:
//! - [`read_capped`] / [`read_file`]: a whole file of at most a given size. A regular file larger
//!   than the cap is refused before anything is read; a stream (a pipe, `/dev/zero`, a
//!   decompressor) is read up to one byte past the cap. Memory never grows past the cap (the
//!   buffer is not doubled beyond it).
//! - [`LineReader`]: lines of at most a given length, one reused buffer, numbered from 1. A longer
//!   line ends the reading ([`LineError::TooLong`], with its number): what follows it is not read,
//!   since a file without line breaks has no next line to resume at.
//! - [`BreakGuard`]: a reader that fails once too many bytes pass without one of a set of
//!   separators (for XML read as a stream: `<` and `>`), so that a parser's own buffer stays
//!   bounded.
//!
//! ```
//! use kpl_core::read::{LineError, LineReader};
//! let mut lines = LineReader::new(&b"{\"a\": 1}\r\nsecond\n"[..], 16);
//! assert_eq!(lines.next_line().unwrap(), Some(&b"{\"a\": 1}"[..]));
//! assert_eq!(lines.next_line().unwrap(), Some(&b"second"[..]));
//! assert_eq!(lines.number(), 2);
//! assert_eq!(lines.next_line().unwrap(), None);
//!
//! // An endless line (what `/dev/zero` gives) is refused at the limit.
//! let mut zeros = LineReader::new(std::io::BufReader::new(std::io::repeat(0)), 1 << 10);
//! assert!(matches!(zeros.next_line(), Err(LineError::TooLong { line: 1, limit: 1024 })));
//! ```

use std::io::{BufRead, Read};
use std::path::{Path, PathBuf};

/// The longest line of a JSON-lines recording (`file.jsonl` replay, `kpl convert`, `kpl score`,
/// `kpl plot`, `kpl situations`): a snapshot of a very large world is one line.
pub const MAX_RECORDING_LINE: usize = 64 << 20;

/// The largest small input read whole (a list of action rules, a parameter file).
pub const MAX_TEXT_FILE: usize = 64 << 20;

/// A size in words: `64 MiB`, `1 GiB`, `1000 bytes`.
pub fn size_in_words(bytes: u64) -> String {
    match bytes {
        b if b >= 1 << 30 && b % (1 << 30) == 0 => format!("{} GiB", b >> 30),
        b if b >= 1 << 20 && b % (1 << 20) == 0 => format!("{} MiB", b >> 20),
        b if b >= 1 << 10 && b % (1 << 10) == 0 => format!("{} KiB", b >> 10),
        b => format!("{b} bytes"),
    }
}

/// A file could not be read within its cap.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("cannot read {}: {source}", path.display())]
    Io { path: PathBuf, source: std::io::Error },
    #[error("cannot read {}: it is a directory", path.display())]
    Directory { path: PathBuf },
    #[error("cannot read {}: larger than {} (is it the right file?); nothing of it is used", path.display(), size_in_words(*limit))]
    TooLarge { path: PathBuf, limit: u64 },
}

impl ReadError {
    /// The file it is about.
    pub fn path(&self) -> &Path {
        match self {
            ReadError::Io { path, .. } | ReadError::Directory { path } | ReadError::TooLarge { path, .. } => {
                path
            }
        }
    }
}

impl From<ReadError> for std::io::Error {
    /// The error without the path (for callers that name the file themselves).
    fn from(error: ReadError) -> std::io::Error {
        match error {
            ReadError::Io { source, .. } => source,
            ReadError::Directory { .. } => {
                std::io::Error::new(std::io::ErrorKind::InvalidInput, "it is a directory")
            }
            ReadError::TooLarge { limit, .. } => std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("larger than {} (is it the right file?)", size_in_words(limit)),
            ),
        }
    }
}

/// Opens the file at `path` for reading; a directory is refused.
pub fn open(path: &Path) -> Result<std::fs::File, ReadError> {
    let io = |source| ReadError::Io { path: path.to_path_buf(), source };
    let file = std::fs::File::open(path).map_err(io)?;
    if file.metadata().map_err(io)?.is_dir() {
        return Err(ReadError::Directory { path: path.to_path_buf() });
    }
    Ok(file)
}

/// Everything `reader` gives, if that is at most `limit` bytes (`Ok(None)`: there is more). The
/// buffer grows by doubling but never past `limit + 1` bytes.
pub fn read_capped(mut reader: impl Read, limit: usize) -> std::io::Result<Option<Vec<u8>>> {
    read_capped_into(&mut reader, limit, Vec::new())
}

fn read_capped_into(
    reader: &mut dyn Read,
    limit: usize,
    mut out: Vec<u8>,
) -> std::io::Result<Option<Vec<u8>>> {
    let most = limit.saturating_add(1);
    let mut chunk = vec![0u8; (64 << 10).min(most)];
    loop {
        let want = chunk.len().min(most - out.len());
        let n = match reader.read(&mut chunk[..want]) {
            Ok(0) => return Ok(Some(out)),
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        if out.capacity() - out.len() < n {
            let grown = out.capacity().saturating_mul(2).max(out.len() + n).max(8 << 10).min(most);
            out.reserve_exact(grown - out.len());
        }
        out.extend_from_slice(&chunk[..n]);
        if out.len() > limit {
            return Ok(None);
        }
    }
}

/// The bytes of the file at `path`, at most `limit` of them. A directory is refused; a regular
/// file larger than `limit` is refused without reading it.
pub fn read_file(path: &Path, limit: usize) -> Result<Vec<u8>, ReadError> {
    let io = |source| ReadError::Io { path: path.to_path_buf(), source };
    let mut file = open(path)?;
    let meta = file.metadata().map_err(io)?;
    let too_large = || ReadError::TooLarge { path: path.to_path_buf(), limit: limit as u64 };
    // A regular file says how long it is; devices and pipes say 0 and are read to the cap.
    let mut out = Vec::new();
    if meta.is_file() {
        if meta.len() > limit as u64 {
            return Err(too_large());
        }
        out.reserve_exact(usize::try_from(meta.len()).unwrap_or(limit).saturating_add(1).min(limit + 1));
    }
    read_capped_into(&mut file, limit, out).map_err(io)?.ok_or_else(too_large)
}

/// Why [`LineReader::next_line`] stopped.
#[derive(Debug, thiserror::Error)]
pub enum LineError {
    /// Line `line` is longer than `limit` bytes; nothing after it is read.
    #[error("line {line} is longer than {} (is it the right file?); the rest of the file is not read", size_in_words(*limit as u64))]
    TooLong { line: u64, limit: usize },
    /// Reading line `line` failed.
    #[error("line {line}: {source}")]
    Io { line: u64, source: std::io::Error },
}

impl LineError {
    /// The number of the line it is about (from 1).
    pub fn line(&self) -> u64 {
        match self {
            LineError::TooLong { line, .. } | LineError::Io { line, .. } => *line,
        }
    }
}

/// Lines of at most `limit` bytes, in one reused buffer, numbered from 1.
#[derive(Debug)]
pub struct LineReader<R> {
    reader: R,
    buffer: Vec<u8>,
    limit: usize,
    number: u64,
    /// Set after a too-long line or an error: nothing more is read.
    stopped: bool,
}

impl<R: BufRead> LineReader<R> {
    pub fn new(reader: R, limit: usize) -> LineReader<R> {
        LineReader { reader, buffer: Vec::new(), limit, number: 0, stopped: false }
    }

    /// The next line without its line break (`\n` or `\r\n`), `None` at the end. After an error
    /// the reader is at its end.
    pub fn next_line(&mut self) -> Result<Option<&[u8]>, LineError> {
        if self.stopped {
            return Ok(None);
        }
        self.buffer.clear();
        self.number += 1;
        let most = u64::try_from(self.limit).unwrap_or(u64::MAX).saturating_add(1);
        let read = match (&mut self.reader).take(most).read_until(b'\n', &mut self.buffer) {
            Ok(read) => read,
            Err(source) => {
                self.stopped = true;
                self.buffer = Vec::new();
                return Err(LineError::Io { line: self.number, source });
            }
        };
        if read == 0 {
            self.number -= 1;
            self.stopped = true;
            return Ok(None);
        }
        if self.buffer.last() == Some(&b'\n') {
            self.buffer.pop();
            if self.buffer.last() == Some(&b'\r') {
                self.buffer.pop();
            }
        } else if self.buffer.len() > self.limit {
            self.stopped = true;
            // Give the memory of the long line back: the reader may be kept.
            self.buffer = Vec::new();
            return Err(LineError::TooLong { line: self.number, limit: self.limit });
        }
        Ok(Some(&self.buffer))
    }

    /// The number of the last line returned (from 1; 0 before the first).
    pub fn number(&self) -> u64 {
        self.number
    }

    /// The longest line accepted, in bytes.
    pub fn limit(&self) -> usize {
        self.limit
    }
}

/// A reader that fails (`InvalidData`) once more than `limit` bytes pass without one of
/// `separators`: for text read as a stream by a parser that buffers up to its next separator
/// (quick-xml up to the next `<` or `>`), so that one endless token cannot fill the memory.
#[derive(Debug)]
pub struct BreakGuard<R> {
    inner: R,
    separators: &'static [u8],
    limit: usize,
    since_break: usize,
}

impl<R: Read> BreakGuard<R> {
    pub fn new(inner: R, separators: &'static [u8], limit: usize) -> BreakGuard<R> {
        BreakGuard { inner, separators, limit, since_break: 0 }
    }
}

impl<R: Read> Read for BreakGuard<R> {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(out)?;
        for &b in &out[..n] {
            if self.separators.contains(&b) {
                self.since_break = 0;
            } else {
                self.since_break += 1;
            }
        }
        if self.since_break > self.limit {
            let separators: Vec<String> =
                self.separators.iter().map(|&b| format!("`{}`", b as char)).collect();
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("more than {} without {}", size_in_words(self.limit as u64), separators.join(" or ")),
            ));
        }
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn lines_are_numbered_and_bounded() {
        let text = "one\r\ntwo\n\nthree-is-long\nlast";
        let mut lines = LineReader::new(text.as_bytes(), 8);
        assert_eq!(lines.next_line().unwrap(), Some(&b"one"[..]));
        assert_eq!(lines.next_line().unwrap(), Some(&b"two"[..]));
        assert_eq!(lines.next_line().unwrap(), Some(&b""[..]));
        assert_eq!(lines.number(), 3);
        let err = lines.next_line().unwrap_err();
        assert!(matches!(err, LineError::TooLong { line: 4, limit: 8 }), "{err}");
        assert_eq!(
            err.to_string(),
            "line 4 is longer than 8 bytes (is it the right file?); the rest of the file is not read"
        );
        // Nothing after a too-long line is read.
        assert_eq!(lines.next_line().unwrap(), None);
        // The last line needs no line break; a line of exactly the limit is accepted.
        let mut lines = LineReader::new(&b"12345678\nlast"[..], 8);
        assert_eq!(lines.next_line().unwrap(), Some(&b"12345678"[..]));
        assert_eq!(lines.next_line().unwrap(), Some(&b"last"[..]));
        assert_eq!(lines.next_line().unwrap(), None);
        assert_eq!(lines.number(), 2);
    }

    #[test]
    fn an_endless_line_is_cut_at_the_limit() {
        let mut zeros = LineReader::new(std::io::BufReader::new(std::io::repeat(0)), 1 << 20);
        assert!(matches!(zeros.next_line(), Err(LineError::TooLong { line: 1, .. })));
        assert_eq!(zeros.buffer.capacity(), 0, "the long line's memory is given back");
    }

    #[test]
    fn whole_files_are_capped_without_doubling_past_the_cap() {
        let zeros = read_capped(std::io::repeat(0), 1_000_000).unwrap();
        assert!(zeros.is_none());
        let small = read_capped(&b"hello"[..], 5).unwrap().unwrap();
        assert_eq!(small, b"hello");
        assert!(read_capped(&b"hello!"[..], 5).unwrap().is_none());
        // The buffer's capacity stays within the cap (+1) for any length.
        for len in [0usize, 1, 8191, 8192, 100_000, 999_999, 1_000_000] {
            let got = read_capped_into(&mut std::io::repeat(7).take(len as u64), 1_000_000, Vec::new())
                .unwrap()
                .unwrap();
            assert_eq!(got.len(), len);
            assert!(got.capacity() <= 1_000_001, "{len}: {}", got.capacity());
        }
    }

    #[test]
    fn files_too_large_or_directories_are_refused() {
        let dir = std::env::temp_dir().join(format!("kpl-core-read-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("ten.txt");
        std::fs::write(&path, "0123456789").unwrap();
        assert_eq!(read_file(&path, 10).unwrap(), b"0123456789");
        let err = read_file(&path, 9).unwrap_err();
        assert_eq!(
            err.to_string(),
            format!(
                "cannot read {}: larger than 9 bytes (is it the right file?); nothing of it is used",
                path.display()
            )
        );
        assert!(matches!(read_file(&dir, 10), Err(ReadError::Directory { .. })));
        assert!(matches!(read_file(&dir.join("missing"), 10), Err(ReadError::Io { .. })));
        if Path::new("/dev/zero").exists() {
            let err = read_file(Path::new("/dev/zero"), 1 << 20).unwrap_err();
            assert!(err.to_string().contains("larger than 1 MiB"), "{err}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_guard_fails_after_too_many_bytes_without_a_separator() {
        let mut ok = String::new();
        BreakGuard::new(&b"<a>0123<b>4567</b>"[..], b"<>", 4).read_to_string(&mut ok).unwrap();
        let mut out = Vec::new();
        let err = BreakGuard::new(std::io::repeat(b'x'), b"<>", 1000).read_to_end(&mut out).unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::InvalidData);
        assert_eq!(err.to_string(), "more than 1000 bytes without `<` or `>`");
        assert!(out.len() < 1000 + (64 << 10), "{}", out.len());
    }

    #[test]
    fn sizes_in_words() {
        assert_eq!(size_in_words(64 << 20), "64 MiB");
        assert_eq!(size_in_words(1 << 30), "1 GiB");
        assert_eq!(size_in_words(1000), "1000 bytes");
        assert_eq!(size_in_words(16 << 10), "16 KiB");
    }
}
