//! The readers against py-motmetrics' own readers (`motmetrics.io.loadtxt`) on the files
//! py-motmetrics ships (data we did not make): the TUD-Campus and TUD-Stadtmitte sequences'
//! ground truth and a tracker's output in MOTChallenge's format, its MOTChallenge and UA-DETRAC
//! XML samples. Every box of every frame is the same (py-motmetrics moves boxes by one pixel to
//! count from 0; the comparison moves them back). Needs the Python of `scripts/test`
//! (`KPL_PYTHON`).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::print_stderr,
    reason = "a test reports and fails loudly"
)]

use std::path::PathBuf;
use std::process::Command;

use kpl_camera::formats::{Format, read_file};
use serde_json::Value;

fn python() -> Option<String> {
    match std::env::var("KPL_PYTHON") {
        Ok(p) if !p.is_empty() => Some(p),
        _ => {
            let required = std::env::var("KPL_REQUIRE_ORACLES").is_ok_and(|v| v == "1");
            assert!(!required, "KPL_REQUIRE_ORACLES=1 but KPL_PYTHON is not set: run scripts/test");
            eprintln!("skipped: KPL_PYTHON is not set (scripts/test sets it up with py-motmetrics)");
            None
        }
    }
}

const ORACLE: &str = r#"
import json, os, sys
import motmetrics as mm
data = os.path.join(os.path.dirname(mm.__file__), "data")
out = {"data": data, "files": {}}
for name, fmt in [("TUD-Campus/gt.txt", "mot15-2D"), ("TUD-Campus/test.txt", "mot15-2D"),
                  ("TUD-Stadtmitte/gt.txt", "mot15-2D"), ("TUD-Stadtmitte/test.txt", "mot15-2D"),
                  ("iotest/motchallenge.txt", "mot15-2D"), ("iotest/detrac.xml", "detrac-xml")]:
    df = mm.io.loadtxt(os.path.join(data, name), fmt=fmt)
    rows = []
    for (frame, oid), r in df.iterrows():
        rows.append([int(frame), int(oid), float(r["X"]) + 1, float(r["Y"]) + 1, float(r["Width"]), float(r["Height"]), float(r["Confidence"])])
    out["files"][name] = rows
json.dump(out, sys.stdout)
"#;

#[test]
fn the_readers_read_py_motmetrics_files_as_py_motmetrics_does() {
    let Some(python) = python() else { return };
    let output = Command::new(&python).args(["-c", ORACLE]).output().expect("run the Python oracle");
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let oracle: Value = serde_json::from_slice(&output.stdout).unwrap();
    let data = PathBuf::from(oracle["data"].as_str().unwrap());
    let mut boxes = 0;
    for (name, rows) in oracle["files"].as_object().unwrap() {
        let format = if name.ends_with(".xml") { Format::Detrac } else { Format::MotChallenge };
        let parsed = read_file(&data.join(name), format).unwrap();
        assert!(parsed.problems.is_empty(), "{name}: {:?}", parsed.problems);
        let mut ours: Vec<[f64; 7]> = parsed
            .detections
            .iter()
            .map(|d| {
                let id = d.id.unwrap_or(-1) as f64;
                [d.frame as f64, id, d.bbox.left, d.bbox.top, d.bbox.width, d.bbox.height, d.score]
            })
            .collect();
        let mut theirs: Vec<[f64; 7]> = rows
            .as_array()
            .unwrap()
            .iter()
            .map(|r| {
                let r: Vec<f64> = r.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
                [r[0], r[1], r[2], r[3], r[4], r[5], r[6]]
            })
            .collect();
        let key = |r: &[f64; 7]| (r[0] as i64, r[1] as i64);
        ours.sort_by_key(key);
        theirs.sort_by_key(key);
        assert_eq!(ours.len(), theirs.len(), "{name}");
        for (a, b) in ours.iter().zip(&theirs) {
            for (x, y) in a.iter().zip(b) {
                assert!((x - y).abs() <= 1e-9 * (1.0 + y.abs()), "{name}: {a:?} vs {b:?}");
            }
        }
        boxes += ours.len();
    }
    eprintln!("{boxes} boxes in 6 files read alike");
    assert!(boxes > 2400, "the shipped sequences have about 2,500 boxes: {boxes}");
}
