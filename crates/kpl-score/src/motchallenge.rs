//! MOTChallenge-style files of an aligned sequence, so that other tools (py-motmetrics,
//! TrackEval, a spreadsheet) can score exactly what `kpl score` scored.
//!
//! The layout is MOT15-3D's ground-plane variant of the MOTChallenge text format, ten
//! comma-separated columns per object and frame, the box columns unused:
//!
//! ```text
//! frame,id,-1,-1,-1,-1,1,x,y,0
//! ```
//!
//! A sequence of boxes is written in MOT15-2D's layout, the box in pixels and the world columns
//! unused: `frame,id,left,top,width,height,1,-1,-1,-1`.
//!
//! `frame` counts the scored frames from 1 in time order (`frames.csv` gives each frame's valid
//! time), `id` is an integer (the number of the symbol when every id of the file is one prefix
//! and a distinct number, `car12` → 12; else numbered in order of first appearance; `ids.csv`
//! gives the names), `x`, `y` are metres, written so that they parse back to the same numbers.
//! The function returns the files' contents; writing them is the caller's business.

use std::collections::HashMap;
use std::fmt::Write as _;

use crate::mapping::Mapping;
use crate::sequence::{Ids, Object, Sequence};

/// One exported file: its name and contents.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ExportFile {
    pub name: &'static str,
    pub contents: String,
}

/// The files of one scored stream: `gt.txt` (the ground truth), `tracks.txt` (the stream's
/// objects), `frames.csv`, `ids.csv`, and `mapping.csv` when a mapping is given.
pub fn export(sequence: &Sequence, mapping: Option<&Mapping>) -> Vec<ExportFile> {
    let truth_numbers = numbers(sequence.truth_ids());
    let hypothesis_numbers = numbers(sequence.hypothesis_ids());
    let (mut gt, mut tracks, mut frames) = (String::new(), String::new(), String::from("frame,valid_us\n"));
    for (k, frame) in sequence.frames().iter().enumerate() {
        let number = k + 1;
        let _ = writeln!(frames, "{number},{}", frame.time);
        lines(&mut gt, number, &frame.truth, &truth_numbers);
        lines(&mut tracks, number, &frame.hypotheses, &hypothesis_numbers);
    }
    let mut ids = String::from("file,id,name\n");
    for (file, side, numbers) in [
        ("gt.txt", sequence.truth_ids(), &truth_numbers),
        ("tracks.txt", sequence.hypothesis_ids(), &hypothesis_numbers),
    ] {
        for (k, name) in side.names().iter().enumerate() {
            let _ = writeln!(ids, "{file},{},{}", numbers[k], csv_field(name));
        }
    }
    let mut files = vec![
        ExportFile { name: "gt.txt", contents: gt },
        ExportFile { name: "tracks.txt", contents: tracks },
        ExportFile { name: "frames.csv", contents: frames },
        ExportFile { name: "ids.csv", contents: ids },
    ];
    if let Some(mapping) = mapping {
        let mut text = String::from("hypothesis,truth,from_us,to_us,frames\n");
        for c in mapping.correspondences() {
            let _ = writeln!(
                text,
                "{},{},{},{},{}",
                csv_field(&c.hypothesis),
                csv_field(&c.truth),
                c.from,
                c.to,
                c.frames
            );
        }
        files.push(ExportFile { name: "mapping.csv", contents: text });
    }
    files
}

fn lines(out: &mut String, frame: usize, objects: &[Object], numbers: &[u64]) {
    for o in objects {
        // `{}` prints the shortest text that parses back to the same f64.
        let id = numbers[o.id as usize];
        match o.bbox {
            Some([l, t, w, h]) => {
                let _ = writeln!(out, "{frame},{id},{l},{t},{w},{h},1,-1,-1,-1");
            }
            None => {
                let _ = writeln!(out, "{frame},{id},-1,-1,-1,-1,1,{},{},0", o.pos[0], o.pos[1]);
            }
        }
    }
}

/// Integer ids for names: their numbers when all share one prefix and have distinct numbers
/// (below 2^31, as MOTChallenge tools read ids as 32-bit integers), else 1, 2, ... in order.
fn numbers(ids: &Ids) -> Vec<u64> {
    let split = |name: &str| -> Option<(String, u64)> {
        let digits = name.len() - name.trim_end_matches(|c: char| c.is_ascii_digit()).len();
        if digits == 0 || digits > 9 {
            return None;
        }
        let (prefix, number) = name.split_at(name.len() - digits);
        Some((prefix.to_string(), number.parse().ok()?))
    };
    let parsed: Option<Vec<(String, u64)>> = ids.names().iter().map(|n| split(n)).collect();
    if let Some(parsed) = parsed {
        let one_prefix = parsed.windows(2).all(|w| w[0].0 == w[1].0);
        let mut seen: HashMap<u64, ()> = HashMap::new();
        let distinct = parsed.iter().all(|(_, n)| *n < (1 << 31) && seen.insert(*n, ()).is_none());
        if one_prefix && distinct {
            return parsed.into_iter().map(|(_, n)| n).collect();
        }
    }
    (1..=ids.len() as u64).collect()
}

/// A CSV field, quoted when it has to be.
fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn files_in_mot15_3d_layout() {
        let mut s = Sequence::new();
        s.push_frame(0, [("car1", [1.5, -2.0])], [("co7", [1.25, -2.0]), ("co9", [10.0, 3.0])]).unwrap();
        s.push_frame(100_000, [("car1", [2.5, -2.0]), ("car12", [0.1, 0.2])], []).unwrap();
        let files = export(&s, None);
        let file = |n: &str| &files.iter().find(|f| f.name == n).unwrap().contents;
        assert_eq!(
            file("gt.txt"),
            "1,1,-1,-1,-1,-1,1,1.5,-2,0\n2,1,-1,-1,-1,-1,1,2.5,-2,0\n2,12,-1,-1,-1,-1,1,0.1,0.2,0\n"
        );
        assert_eq!(file("tracks.txt"), "1,7,-1,-1,-1,-1,1,1.25,-2,0\n1,9,-1,-1,-1,-1,1,10,3,0\n");
        assert_eq!(file("frames.csv"), "frame,valid_us\n1,0\n2,100000\n");
        assert!(file("ids.csv").contains("gt.txt,12,car12\n"));
    }

    #[test]
    fn names_without_one_numbering_are_counted() {
        let mut s = Sequence::new();
        s.push_frame(0, [("a", [0.0, 0.0]), ("car2", [0.0, 0.0]), ("x,y", [1.0, 1.0])], []).unwrap();
        let ids = &export(&s, None)[3].contents;
        assert_eq!(ids, "file,id,name\ngt.txt,1,a\ngt.txt,2,car2\ngt.txt,3,\"x,y\"\n");
    }
}
