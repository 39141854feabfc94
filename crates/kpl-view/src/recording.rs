//! Recordings into a view (`kpl view`): JSON lines (`file.jsonl`) and MCAP files (`file.mcap`;
//! their Foxglove views are skipped, the samples are in the streams' own channels), each stream
//! drawn as its first telling sample says (objects with `measured`, points with `pos`, episodes
//! with `verdict`). A stream that two files both hold is taken from the first.

use std::collections::BTreeSet;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use kpl_core::Value;
use kpl_mcap::foxglove::Role;
use kpl_mcap::read::{RawEvent, Reader};
use kpl_runtime::Sample;
use kpl_runtime::builtins::{StreamFilter, read_line};

use crate::hub::Hub;

/// A line longer than this is not a sample (a file that is not JSON lines).
const LINE_LIMIT: u64 = 64 << 20;

/// What loading found.
#[derive(Debug, Default)]
pub struct Loaded {
    pub files: Vec<PathBuf>,
    pub samples: u64,
    /// Lines or messages that were not samples, with where they are (the first few).
    pub malformed: u64,
    pub examples: Vec<String>,
    /// Streams skipped because an earlier file had them.
    pub duplicates: BTreeSet<String>,
}

impl Loaded {
    fn bad(&mut self, location: String, error: String) {
        self.malformed += 1;
        if self.examples.len() < 5 {
            self.examples.push(format!("{location}: {error}"));
        }
    }
}

/// The recordings `paths` name: files, or directories searched (three levels deep) for `.jsonl`
/// and `.mcap` files, in name order.
pub fn files(paths: &[PathBuf]) -> std::io::Result<Vec<PathBuf>> {
    fn walk(dir: &Path, depth: usize, out: &mut Vec<PathBuf>) -> std::io::Result<()> {
        let mut entries: Vec<PathBuf> =
            std::fs::read_dir(dir)?.filter_map(|e| e.ok().map(|e| e.path())).collect();
        entries.sort();
        for path in entries {
            if path.is_dir() && depth > 0 {
                walk(&path, depth - 1, out)?;
            } else if matches!(path.extension().and_then(|e| e.to_str()), Some("jsonl" | "mcap")) {
                out.push(path);
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    for path in paths {
        if path.is_dir() {
            walk(path, 3, &mut out)?;
        } else {
            out.push(path.clone());
        }
    }
    Ok(out)
}

/// Reads recordings into a hub.
pub fn load(hub: &Hub, files: &[PathBuf]) -> Result<Loaded, String> {
    let mut loaded = Loaded::default();
    let mut taken: BTreeSet<String> = BTreeSet::new();
    for file in files {
        // The streams of earlier files are not taken again.
        let before = taken.clone();
        let mut take = |stream: &str, sample: Sample, loaded: &mut Loaded| {
            if before.contains(stream) {
                loaded.duplicates.insert(stream.to_string());
                return;
            }
            taken.insert(stream.to_string());
            let mut timeline = hub.timeline();
            let id = timeline.stream(stream, Role::Unknown);
            timeline.push(id, &sample);
            loaded.samples += 1;
        };
        match file.extension().and_then(|e| e.to_str()) {
            Some("mcap") => {
                let mut reader =
                    Reader::open(file).map_err(|e| format!("cannot read {}: {e}", file.display()))?;
                let mut filter = StreamFilter::new("");
                while let Some(event) = reader.next_raw(&mut filter) {
                    match event {
                        RawEvent::Message { stream, valid, available, value, location } => {
                            match Value::from_json_untyped(&value) {
                                Ok(value) => take(&stream, Sample::new(valid, available, value), &mut loaded),
                                Err(e) => loaded.bad(location, e.to_string()),
                            }
                        }
                        RawEvent::Malformed { location, error } => loaded.bad(location, error),
                    }
                }
            }
            _ => {
                let f = kpl_core::read::open(file).map_err(|e| e.to_string())?;
                let mut reader = BufReader::new(f);
                let mut line = Vec::new();
                for number in 1.. {
                    line.clear();
                    let n = (&mut reader)
                        .take(LINE_LIMIT)
                        .read_until(b'\n', &mut line)
                        .map_err(|e| format!("cannot read {}: {e}", file.display()))?;
                    if n == 0 {
                        break;
                    }
                    let location = format!("{}:{number}", file.display());
                    if n as u64 >= LINE_LIMIT && line.last() != Some(&b'\n') {
                        loaded.bad(location, format!("a line of over {LINE_LIMIT} bytes: not JSON lines"));
                        break;
                    }
                    let text = String::from_utf8_lossy(&line);
                    if text.trim().is_empty() {
                        continue;
                    }
                    match read_line(text.trim_end()) {
                        Ok(s) => match Value::from_json_untyped(&s.value) {
                            Ok(value) => {
                                take(&s.stream, Sample::new(s.valid, s.available, value), &mut loaded)
                            }
                            Err(e) => loaded.bad(location, e.to_string()),
                        },
                        Err(e) => loaded.bad(location, e),
                    }
                }
            }
        }
        loaded.files.push(file.clone());
    }
    hub.finish();
    Ok(loaded)
}
