//! Differential test against py-motmetrics (CLEAR MOT, identity measures) and TrackEval (HOTA),
//! the reference implementations, on generated tracking results with identity switches,
//! fragmentations, false positives and misses.
//!
//! Each case is scored here and exported as MOTChallenge-style files
//! ([`kpl_score::motchallenge::export`]); `oracles.py` scores the files with the Python code of
//! docs/scoring.md ("Scoring an export with other tools"), which feeds them to py-motmetrics'
//! `MOTAccumulator` with Euclidean distances gated at the same distance and to TrackEval's
//! `HOTA.eval_sequence` with TrackEval's own Euclidean similarity. Every count must be equal and
//! every ratio equal to 1e-9. Needs the Python of `scripts/test` (`KPL_PYTHON`).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr)] // a test reports and fails loudly

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use kpl_score::{Config, Evaluation, evaluate, motchallenge};
use serde_json::{Value, json};

fn python() -> Option<String> {
    match std::env::var("KPL_PYTHON") {
        Ok(p) if !p.is_empty() => Some(p),
        _ => {
            let required = std::env::var("KPL_REQUIRE_ORACLES").is_ok_and(|v| v == "1");
            assert!(!required, "KPL_REQUIRE_ORACLES=1 but KPL_PYTHON is not set: run scripts/test");
            eprintln!(
                "skipped: KPL_PYTHON is not set (scripts/test sets it up with py-motmetrics and TrackEval)"
            );
            None
        }
    }
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Runs the oracles on `folders` (with their configurations); one result per folder.
fn oracle(python: &str, dir: &Path, cases: &[(PathBuf, Config)]) -> Vec<Value> {
    let batch = json!({
        "cases": cases.iter().map(|(folder, config)| json!({
            "folder": folder,
            "max_distance": config.max_distance(),
            "zero_distance": config.hota_zero_distance(),
            "iou": config.iou_threshold(),
        })).collect::<Vec<_>>()
    });
    let batch_path = dir.join("batch.json");
    let results_path = dir.join("results.json");
    std::fs::write(&batch_path, batch.to_string()).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/oracles.py");
    let output = Command::new(python)
        .arg(&script)
        .arg(workspace().join("docs/scoring.md"))
        .arg(&batch_path)
        .arg(&results_path)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{python} {} failed:\n{}",
        script.display(),
        String::from_utf8_lossy(&output.stderr)
    );
    let results: Value = serde_json::from_str(&std::fs::read_to_string(&results_path).unwrap()).unwrap();
    results["results"].as_array().unwrap().clone()
}

fn write_export(dir: &Path, sequence: &kpl_score::Sequence) {
    std::fs::create_dir_all(dir).unwrap();
    for file in motchallenge::export(sequence, None) {
        std::fs::write(dir.join(file.name), file.contents).unwrap();
    }
}

/// Compares one case; panics with the case's name and the first difference.
fn compare(name: &str, ours: &Evaluation, theirs: &Value) {
    if let Some(e) = theirs.get("error") {
        panic!("{name}: the oracle failed: {e}");
    }
    let (c, i, h) = (&ours.scores.clear, &ours.scores.identity, &ours.scores.hota);
    let counts: [(&str, usize); 17] = [
        ("num_frames", c.frames),
        ("num_objects", c.objects),
        ("num_predictions", c.predictions),
        ("num_unique_objects", c.unique_objects),
        ("num_matches", c.matches),
        ("num_switches", c.switches),
        ("num_detections", c.detections()),
        ("num_false_positives", c.false_positives),
        ("num_misses", c.misses),
        ("num_fragmentations", c.fragmentations),
        ("mostly_tracked", c.mostly_tracked),
        ("partially_tracked", c.partially_tracked),
        ("mostly_lost", c.mostly_lost),
        ("idtp", i.idtp),
        ("idfp", i.idfp),
        ("idfn", i.idfn),
        ("HOTA_TP", h.per_alpha.tp.iter().sum()),
    ];
    for (field, ours) in counts {
        let theirs = match &theirs[field] {
            Value::Array(a) => a.iter().map(|v| v.as_f64().unwrap()).sum::<f64>(),
            v => v.as_f64().unwrap_or_else(|| panic!("{name}: {field} is {v}")),
        };
        assert_eq!(ours as f64, theirs, "{name}: {field}");
    }
    let ratios: [(&str, f64); 16] = [
        ("mota", c.mota),
        ("motp", c.motp),
        ("precision", c.precision),
        ("recall", c.recall),
        ("idf1", i.idf1),
        ("idp", i.idp),
        ("idr", i.idr),
        ("HOTA", h.hota),
        ("DetA", h.det_a),
        ("AssA", h.ass_a),
        ("LocA", h.loc_a),
        ("DetRe", h.det_re),
        ("DetPr", h.det_pr),
        ("AssRe", h.ass_re),
        ("AssPr", h.ass_pr),
        ("HOTA(0)", h.hota_0),
    ];
    for (field, ours) in ratios.into_iter().chain([("LocA(0)", h.loc_a_0)]) {
        match theirs[field].as_f64() {
            None => assert!(!ours.is_finite(), "{name}: {field}: ours {ours}, theirs not a number"),
            Some(t) if t.is_infinite() || !ours.is_finite() => assert_eq!(ours, t, "{name}: {field}"),
            Some(t) => assert!((ours - t).abs() <= 1e-9, "{name}: {field}: ours {ours}, theirs {t}"),
        }
    }
    let per_alpha: Vec<f64> =
        theirs["HOTA_per_alpha"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert_eq!(per_alpha.len(), h.per_alpha.hota.len(), "{name}: thresholds");
    for (a, (o, t)) in h.per_alpha.hota.iter().zip(&per_alpha).enumerate() {
        assert!((o - t).abs() <= 1e-9, "{name}: HOTA at threshold {a}: ours {o}, theirs {t}");
    }
    let tp: Vec<f64> = theirs["HOTA_TP"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    let ours_tp: Vec<f64> = h.per_alpha.tp.iter().map(|&n| n as f64).collect();
    assert_eq!(ours_tp, tp, "{name}: HOTA true positives per threshold");
}

#[test]
fn the_metrics_agree_with_py_motmetrics_and_trackeval() {
    let Some(python) = python() else { return };
    let dir = std::env::temp_dir().join(format!("kpl-score-oracles-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut cases = Vec::new();
    let mut evaluations = Vec::new();
    for seed in 0..300u64 {
        let case = common::case(seed);
        let sequence = case.sequence();
        let config = Config::new(case.max_distance).unwrap();
        // One case in four with another zero distance for HOTA.
        let config = if seed % 4 == 3 {
            config.with_hota_zero_distance(case.max_distance * 1.3).unwrap()
        } else {
            config
        };
        let folder = dir.join(format!("case{seed}"));
        write_export(&folder, &sequence);
        evaluations.push((format!("case {seed}"), evaluate(&sequence, &config)));
        cases.push((folder, config));
    }
    // Edge cases: no hypotheses at all, no true objects at all, nothing at all.
    let base = common::case(7);
    for (label, keep_truth, keep_hyps) in
        [("no hypotheses", true, false), ("no truth", false, true), ("empty", false, false)]
    {
        let mut case = base.clone();
        for (truth, hyps) in &mut case.frames {
            if !keep_truth {
                truth.clear();
            }
            if !keep_hyps {
                hyps.clear();
            }
        }
        let sequence = case.sequence();
        let config = Config::new(case.max_distance).unwrap();
        let folder = dir.join(label.replace(' ', "_"));
        write_export(&folder, &sequence);
        evaluations.push((label.to_string(), evaluate(&sequence, &config)));
        cases.push((folder, config));
    }
    let results = oracle(&python, &dir, &cases);
    assert_eq!(results.len(), evaluations.len());
    for ((name, ours), theirs) in evaluations.iter().zip(&results) {
        compare(name, ours, theirs);
    }
    // The cases exercise what they are meant to.
    let total = |f: &dyn Fn(&Evaluation) -> usize| evaluations.iter().map(|(_, e)| f(e)).sum::<usize>();
    let switches = total(&|e| e.scores.clear.switches);
    let fragmentations = total(&|e| e.scores.clear.fragmentations);
    let false_positives = total(&|e| e.scores.clear.false_positives);
    let misses = total(&|e| e.scores.clear.misses);
    let partly = total(&|e| e.scores.clear.partially_tracked);
    eprintln!(
        "{} cases: {switches} switches, {fragmentations} fragmentations, {false_positives} false positives, {misses} misses, {partly} partially tracked",
        evaluations.len()
    );
    assert!(switches > 100 && fragmentations > 100 && false_positives > 1000 && misses > 1000 && partly > 50);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A case of boxes made from a case of points: each object a box around its position (scaled to
/// pixels) of a size of its own, hypotheses' sizes a little off, so IoU decides the matches.
fn box_case(seed: u64) -> (kpl_score::Sequence, f64) {
    let case = common::case(seed);
    let size = |id: &str, hypothesis: bool| {
        let h = id.bytes().fold(seed, |a, b| a.wrapping_mul(31).wrapping_add(u64::from(b)));
        let (w, ht) = (20.0 + (h % 17) as f64, 40.0 + (h % 23) as f64);
        if hypothesis {
            (w * (0.8 + (h % 5) as f64 * 0.1), ht * (0.9 + (h % 3) as f64 * 0.1))
        } else {
            (w, ht)
        }
    };
    let boxes = |objects: &[(String, [f64; 2])], hypothesis: bool| -> Vec<(String, [f64; 4])> {
        objects
            .iter()
            .map(|(id, p)| {
                let (w, h) = size(id, hypothesis);
                // Positions are within a few tens of metres: 8 pixels per metre.
                (id.clone(), [p[0] * 8.0 - w / 2.0, p[1] * 8.0 - h / 2.0, w, h])
            })
            .collect()
    };
    let mut s = kpl_score::Sequence::new();
    for (k, (truth, hyps)) in case.frames.iter().enumerate() {
        let (t, h) = (boxes(truth, false), boxes(hyps, true));
        s.push_frame_boxes(
            k as i64 * 40_000,
            t.iter().map(|(id, b)| (id.as_str(), *b)),
            h.iter().map(|(id, b)| (id.as_str(), *b)),
        )
        .unwrap();
    }
    (s, [0.5, 0.3, 0.7][(seed % 3) as usize])
}

#[test]
fn box_metrics_agree_with_py_motmetrics_and_trackeval() {
    let Some(python) = python() else { return };
    let dir = std::env::temp_dir().join(format!("kpl-score-box-oracles-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let (mut cases, mut evaluations) = (Vec::new(), Vec::new());
    for seed in 0..150u64 {
        let (sequence, threshold) = box_case(seed);
        let config = Config::iou(threshold).unwrap();
        let folder = dir.join(format!("boxes{seed}"));
        write_export(&folder, &sequence);
        evaluations.push((format!("box case {seed}"), evaluate(&sequence, &config)));
        cases.push((folder, config));
    }
    let results = oracle(&python, &dir, &cases);
    for ((name, ours), theirs) in evaluations.iter().zip(&results) {
        compare(name, ours, theirs);
    }
    let total = |f: &dyn Fn(&Evaluation) -> usize| evaluations.iter().map(|(_, e)| f(e)).sum::<usize>();
    let (switches, matches, false_positives) = (
        total(&|e| e.scores.clear.switches),
        total(&|e| e.scores.clear.matches),
        total(&|e| e.scores.clear.false_positives),
    );
    eprintln!(
        "{} box cases: {matches} matches, {switches} switches, {false_positives} false positives",
        evaluations.len()
    );
    assert!(switches > 50 && matches > 1000 && false_positives > 500);
    let _ = std::fs::remove_dir_all(&dir);
}
