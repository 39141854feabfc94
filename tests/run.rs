//! End-to-end tests of `kpl run`: specs, recorded inputs and expected outputs.
//! - a simulated run with a fixed seed is reproducible byte for byte;
//! - each policy, applied to one recorded stream, gives the expected samples and counts;
//! - a monitor's verdicts come at the violations and at the end;
//! - malformed input is counted and reported with its line, the run goes on, `--strict` stops it;
//! - `--for` and Ctrl-C end a wall-clock run cleanly, with the sinks flushed;
//! - `RUST_LOG` turns on the runtime's logs.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::{kpl_command as kpl, lines};

use serde_json::Value;

fn out_dir(name: &str) -> PathBuf {
    common::fresh_dir("run", name)
}

fn run(spec: &str, out: &Path, extra: &[&str]) -> Output {
    kpl(&["run", "--quiet", spec, "--out", out.to_str().unwrap()]).args(extra).output().unwrap()
}

fn summary(out: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

#[test]
fn simulated_runs_are_reproducible_for_a_seed() {
    let (a, b, c) = (out_dir("repro-a"), out_dir("repro-b"), out_dir("repro-c"));
    for (dir, seed) in [(&a, "3"), (&b, "3"), (&c, "4")] {
        let out = run("specs/ok/tracker.kpl", dir, &["--for", "10s", "--seed", seed]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    }
    let read = |d: &Path| std::fs::read(d.join("percepts.jsonl")).unwrap();
    assert!(read(&a).len() > 10_000, "the tracker recorded frames");
    assert_eq!(read(&a), read(&b), "same seed, same bytes");
    assert_ne!(read(&a), read(&c), "another seed, other traffic");
}

/// The samples of each stream in a recording: (valid time in ms, value).
fn by_stream(records: &[Value]) -> BTreeMap<String, Vec<(i64, Value)>> {
    let mut map: BTreeMap<String, Vec<(i64, Value)>> = BTreeMap::new();
    for r in records {
        let valid = r["valid"].as_i64().unwrap() / 1000;
        map.entry(r["stream"].as_str().unwrap().to_string()).or_default().push((valid, r["value"].clone()));
    }
    map
}

#[test]
fn policies_shape_one_recorded_stream() {
    let out = out_dir("policies");
    let result = run("specs/run/policies.kpl", &out, &[]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let streams = by_stream(&lines(&out.join("policies.jsonl")));
    let times = |name: &str| streams[name].iter().map(|(t, _)| *t).collect::<Vec<_>>();
    let all = [0, 1000, 2000, 3000, 4000, 3500, 5000, 6000, 7000, 8000, 9000, 10000];
    assert_eq!(times("speed"), all);
    // strict order drops the sample at 3.5 s that came after 4 s.
    assert_eq!(times("ordered"), [0, 1000, 2000, 3000, 4000, 5000, 6000, 7000, 8000, 9000, 10000]);
    // max delay 500ms drops 3.5 s (0.6 s late) and 5 s (0.9 s late).
    assert_eq!(times("fresh"), [0, 1000, 2000, 3000, 4000, 6000, 7000, 8000, 9000, 10000]);
    // any change drops the repeated 12.0 at 2 s, 22.0 at 6 s and 11.0 at 9 s.
    assert_eq!(times("changes"), [0, 1000, 3000, 4000, 3500, 5000, 7000, 8000, 10000]);
    assert_eq!(times("window"), [2000, 3000, 4000, 3500, 5000, 6000]);
    // sample every 2.5 s: the most recent value at each tick.
    let resampled: Vec<(i64, f64)> =
        streams["resampled"].iter().map(|(t, v)| (*t, v.as_f64().unwrap())).collect();
    assert_eq!(resampled, [(0, 10.0), (2500, 12.0), (5000, 22.0), (7500, 26.0), (10000, 12.0)]);
    // The monitor reports each violation, then closes with true at the end.
    let verdicts: Vec<(i64, bool)> =
        streams["below_25"].iter().map(|(t, v)| (*t, v.as_bool().unwrap())).collect();
    assert_eq!(verdicts, [(3000, false), (7000, false), (10000, true)]);

    let report = summary(&out);
    let edge = |stream: &str| {
        report["summary"]["streams"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["stream"] == stream && s["consumer"] == "record")
            .cloned()
            .unwrap()
    };
    assert_eq!(edge("ordered")["dropped"]["out_of_order"], 1);
    assert_eq!(edge("ordered")["policy_violations"], 1);
    assert_eq!(edge("fresh")["dropped"]["late"], 2);
    assert_eq!(edge("changes")["dropped"]["unchanged"], 3);
    assert_eq!(edge("window")["dropped"]["outside_window"], 6);
    assert_eq!(edge("resampled")["approximated"], 2);
    assert_eq!(edge("speed")["produced"], 12);
    assert_eq!(edge("speed")["delivered"], 12);
}

#[test]
fn malformed_input_is_counted_reported_and_survived() {
    let out = out_dir("malformed");
    let result = run("specs/run/malformed.kpl", &out, &[]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let replayed = lines(&out.join("replayed.jsonl"));
    let times: Vec<i64> = replayed.iter().map(|r| r["valid"].as_i64().unwrap()).collect();
    assert_eq!(times, [0, 100_000, 400_000, 500_000], "the good lines go through");
    let report = summary(&out);
    let replay = &report["summary"]["processes"].as_array().unwrap()[0];
    assert_eq!(replay["process"], "replay");
    assert_eq!(replay["malformed"], 4);
    let examples: Vec<String> = replay["malformed_examples"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| format!("{}: {}", m["location"].as_str().unwrap(), m["error"].as_str().unwrap()))
        .collect();
    assert!(examples[0].starts_with("specs/run/data/malformed.jsonl:3: not a sample line"), "{examples:?}");
    assert_eq!(
        examples[1],
        "specs/run/data/malformed.jsonl:4: value at `.pos[0]`: expected a finite number, found the string \"NaN\""
    );
    assert_eq!(
        examples[2],
        "specs/run/data/malformed.jsonl:5: value at `.size`: expected a finite number, found the string \"big\""
    );
    assert_eq!(
        examples[3],
        "specs/run/data/malformed.jsonl:7: time stamp goes backwards: available 150000 after 400000"
    );

    // The summary table names them too.
    let loud = kpl(&["run", "specs/run/malformed.kpl", "--out", out.to_str().unwrap()]).output().unwrap();
    let stderr = String::from_utf8_lossy(&loud.stderr);
    assert!(stderr.contains("replay: 4 malformed input(s)"), "{stderr}");

    // --strict stops at the first one.
    let strict_out = out_dir("malformed-strict");
    let strict = run("specs/run/malformed.kpl", &strict_out, &["--strict"]);
    assert_eq!(strict.status.code(), Some(1));
    assert_eq!(summary(&strict_out)["ending"], "strict");
    assert_eq!(lines(&strict_out.join("replayed.jsonl")).len(), 2, "what came before is flushed");
}

/// The process summaries of a run, by process name.
fn processes(out: &Path) -> BTreeMap<String, Value> {
    let report = summary(out);
    let list = report["summary"]["processes"].as_array().unwrap();
    list.iter().map(|p| (p["process"].as_str().unwrap().to_string(), p.clone())).collect()
}

#[test]
fn a_replay_filters_its_stream_before_decoding() {
    let out = out_dir("filter");
    let result = run("specs/run/filter.kpl", &out, &[]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let streams = by_stream(&lines(&out.join("filtered.jsonl")));
    let times = |name: &str| streams[name].iter().map(|(t, _)| *t).collect::<Vec<_>>();
    assert_eq!(times("percepts"), [0, 100, 200]);
    assert_eq!(times("speed"), [0, 100]);
    let processes = processes(&out);
    // Each source counts the line that is not JSON; the other stream's lines are not malformed.
    assert_eq!(processes["percepts"]["malformed"], 1, "{:?}", processes["percepts"]);
    assert_eq!(processes["speed"]["malformed"], 2, "{:?}", processes["speed"]);
    assert_eq!(
        processes["speed"]["malformed_examples"][1]["error"],
        "value at `.`: expected a finite number, found the string \"fast\""
    );
    assert_eq!(processes["percepts"]["warnings"], serde_json::json!([]));
}

#[test]
fn a_replay_whose_filter_matches_nothing_warns() {
    let out = out_dir("filter-typo");
    let result = run("specs/run/filter_typo.kpl", &out, &[]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let expected = "no sample of specs/run/data/mixed.jsonl is of stream \"percept\", so this source is \
                    empty: its streams are \"percepts\" (3), \"speed\" (3); did you mean \"percepts\"?";
    assert_eq!(processes(&out)["percepts"]["warnings"], serde_json::json!([expected]));
    // Printed even with --quiet.
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(stderr.contains(&format!("warning: percepts: {expected}")), "{stderr}");
}

#[test]
fn for_ends_a_wall_clock_run() {
    let out = out_dir("for");
    let result = run("specs/run/endless.kpl", &out, &["--clock", "wall", "--for", "500ms"]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    assert_eq!(summary(&out)["ending"], "duration_reached");
    let ticks = lines(&out.join("ticks.jsonl"));
    assert!(ticks.len() >= 10, "a 10 ms timer for 500 ms: {} samples", ticks.len());
    // Wall-clock times are microseconds since the epoch, 10 ms apart.
    let t: Vec<i64> = ticks.iter().map(|r| r["valid"].as_i64().unwrap()).collect();
    assert!(t[0] > 1_600_000_000_000_000);
    assert!(t.windows(2).all(|w| w[1] - w[0] == 10_000));
}

#[test]
fn ctrl_c_stops_cleanly_and_flushes_the_sinks() {
    let out = out_dir("interrupt");
    let mut child =
        kpl(&["run", "--quiet", "specs/run/endless.kpl", "--clock", "wall", "--out", out.to_str().unwrap()])
            .spawn()
            .unwrap();
    // Wait until the run has written something, then interrupt it.
    let file = out.join("ticks.jsonl");
    for _ in 0..200 {
        std::thread::sleep(std::time::Duration::from_millis(50));
        if std::fs::metadata(out.join("summary.json")).is_err()
            && child.try_wait().unwrap().is_none()
            && file.exists()
        {
            break;
        }
    }
    std::thread::sleep(std::time::Duration::from_millis(500));
    let status = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(status.success());
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130));
    assert_eq!(summary(&out)["ending"], "interrupted");
    let ticks = lines(&file); // every line is whole JSON: the sink was flushed, not cut
    assert!(!ticks.is_empty());
    let delivered = summary(&out)["summary"]["streams"][0]["delivered"].as_u64().unwrap();
    assert_eq!(ticks.len() as u64, delivered, "every sample that reached the sink is in its file");
}

#[test]
fn rust_log_shows_the_runtime() {
    let out = out_dir("log");
    let result = kpl(&["run", "--quiet", "specs/ok/ticks.kpl", "--out", out.to_str().unwrap()])
        .env("RUST_LOG", "kpl_runtime=debug")
        .output()
        .unwrap();
    assert!(result.status.success());
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(stderr.contains("process ended") && stderr.contains("process=ticks"), "{stderr}");
}

#[test]
fn a_spec_with_errors_does_not_run() {
    let out = out_dir("errors");
    let result = run("specs/err/unknown_stream.kpl", &out, &[]);
    assert_eq!(result.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&result.stderr).contains("E0101"));
}
