//! End-to-end tests of `kpl run`: specs, recorded inputs and expected outputs.
//! - a simulated run with a fixed seed is reproducible byte for byte;
//! - each policy, applied to one recorded stream, gives the expected samples and counts;
//! - a monitor's verdicts come at the violations and at the end;
//! - malformed input is counted and reported with its line, the run goes on, `--strict` stops it;
//! - `--for` and Ctrl-C end a wall-clock run cleanly, with the sinks flushed; SIGTERM alike, with
//!   the same summary and its own exit status;
//! - hostile replay paths (a directory, `/dev/zero`, valid times near the end of 64 bits) give a
//!   clear error, without spinning or growing;
//! - `RUST_LOG` turns on the runtime's logs.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::disallowed_methods)] // tests; waits are bounded by the wall clock

mod common;

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output};

use common::{kpl_command as kpl, lines};

use serde_json::Value;

fn out_dir(name: &str) -> common::TestDir {
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
    assert!(
        examples[0].starts_with(
            "specs/run/data/malformed.jsonl:3: the line is not JSON (unexpected text at column 2)"
        ),
        "{examples:?}"
    );
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

/// Runs the endless spec on the wall clock until it has written samples, then sends it `signal`
/// (`INT`, `TERM`); returns its exit status, standard error and output folder.
fn interrupt_with(signal: &str) -> (Option<i32>, String, common::TestDir) {
    let out = out_dir(&format!("interrupt-{signal}"));
    let mut child = kpl(&["run", "specs/run/endless.kpl", "--clock", "wall", "--out", out.to_str().unwrap()])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || std::io::read_to_string(stderr).unwrap());
    // Wait until the run has written something (the sink's buffer went to the file), then stop it.
    let file = out.join("ticks.jsonl");
    for _ in 0..600 {
        std::thread::sleep(std::time::Duration::from_millis(50));
        if std::fs::metadata(&file).is_ok_and(|m| m.len() > 0) || child.try_wait().unwrap().is_some() {
            break;
        }
    }
    let status =
        Command::new("kill").args([&format!("-{signal}"), &child.id().to_string()]).status().unwrap();
    assert!(status.success());
    let status = child.wait().unwrap();
    (status.code(), reader.join().unwrap(), out)
}

/// The summary table without what depends on timing (times, counts, and the warning that a
/// wall-clock timer fell behind, which a loaded machine gives to one run and not the other).
fn summary_shape(stderr: &str) -> Vec<String> {
    let start = stderr.find("run ended").unwrap_or_else(|| panic!("no summary:\n{stderr}"));
    stderr[start..]
        .lines()
        .filter(|l| !l.contains("could not keep its period"))
        .map(|l| {
            let words: Vec<&str> = l
                .split_whitespace()
                .filter(|w| !w.chars().next().is_some_and(|c| c.is_ascii_digit()))
                .collect();
            let line = words.join(" ").replace("SIGTERM", "SIGNAL").replace("Ctrl-C", "SIGNAL");
            // The output folder and the files' sizes differ between two runs; their names do not.
            match line.split_once(' ') {
                Some((_, "B" | "kB" | "MB")) => line.split(' ').next().unwrap_or("").to_string(),
                _ if line.starts_with("outputs in ") => "outputs in OUT".to_string(),
                _ => line,
            }
        })
        .collect()
}

#[test]
fn ctrl_c_and_sigterm_stop_alike_and_flush_the_sinks() {
    let (int_code, int_err, int_out) = interrupt_with("INT");
    let (term_code, term_err, term_out) = interrupt_with("TERM");
    assert_eq!(int_code, Some(130), "{int_err}");
    assert_eq!(term_code, Some(143), "{term_err}");
    assert!(int_err.contains("run ended (interrupted by Ctrl-C)"), "{int_err}");
    assert!(term_err.contains("run ended (interrupted by SIGTERM)"), "{term_err}");
    assert_eq!(summary_shape(&int_err), summary_shape(&term_err), "the same summary");
    for (out, signal) in [(&int_out, "SIGINT"), (&term_out, "SIGTERM")] {
        let report = summary(out);
        assert_eq!(report["ending"], "interrupted");
        assert_eq!(report["signal"], signal);
        let ticks = lines(&out.join("ticks.jsonl")); // every line is whole JSON: flushed, not cut
        assert!(!ticks.is_empty());
        let delivered = report["summary"]["streams"][0]["delivered"].as_u64().unwrap();
        assert_eq!(ticks.len() as u64, delivered, "every sample that reached the sink is in its file");
    }
}

/// Runs a spec with a hang guard, sampling the process's resident memory; returns its exit
/// status, standard error and the largest resident set seen (bytes).
fn run_watched(spec: &str, out: &Path, extra: &[&str]) -> (Option<i32>, String, u64) {
    let mut child = kpl(&["run", "--quiet", spec, "--out", out.to_str().unwrap()])
        .args(extra)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || std::io::read_to_string(stderr).unwrap());
    let status_file = format!("/proc/{}/status", child.id());
    let start = std::time::Instant::now();
    let mut peak = 0u64;
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if let Ok(text) = std::fs::read_to_string(&status_file)
            && let Some(kb) = text.lines().find_map(|l| l.strip_prefix("VmRSS:"))
        {
            let kb: u64 = kb.trim().trim_end_matches("kB").trim().parse().unwrap_or(0);
            peak = peak.max(kb * 1024);
        }
        if start.elapsed() > std::time::Duration::from_secs(120) {
            child.kill().unwrap();
            panic!("`kpl run {spec}` did not end within two minutes (spinning?)");
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    };
    (status.code(), reader.join().unwrap(), peak)
}

#[test]
fn hostile_replay_paths_get_a_clear_error() {
    // A directory: refused when the run starts.
    let out = out_dir("replay-dir");
    let (code, stderr, _) = run_watched("specs/run/replay_directory.kpl", &out, &[]);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("cannot replay specs/run/data: it is a directory"), "{stderr}");

    // /dev/zero never ends a line: the replay stops at the limit, the run reports it and ends.
    let out = out_dir("replay-zero");
    for clock in ["sim", "wall"] {
        let (code, stderr, peak) = run_watched("specs/run/replay_dev_zero.kpl", &out, &["--clock", clock]);
        assert_eq!(code, Some(1), "{stderr}");
        let report = summary(&out);
        let failure = report["failures"][0].as_str().unwrap();
        assert!(
            failure.contains("cannot replay /dev/zero: line 1 is longer than 64 MiB (is it the right file?)"),
            "{failure}"
        );
        // The limit, a read buffer and the runtime; not the gigabytes an unbounded line would take.
        assert!(peak < 256 << 20, "resident memory peaked at {peak} bytes");
    }

    // Valid times near the end of 64 bits: kept in simulated time; not movable to the wall clock.
    let out = out_dir("replay-far");
    let (code, stderr, _) = run_watched("specs/run/replay_far_future.kpl", &out, &[]);
    assert_eq!(code, Some(0), "{stderr}");
    let valid: Vec<i64> =
        lines(&out.join("replayed.jsonl")).iter().map(|r| r["valid"].as_i64().unwrap()).collect();
    assert_eq!(valid, [0, 1000, 9_223_372_036_854_775_000]);
    let (code, stderr, _) =
        run_watched("specs/run/replay_far_future.kpl", &out, &["--clock", "wall", "--for", "2s"]);
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(lines(&out.join("replayed.jsonl")).len(), 2);
    let replay = summary(&out)["summary"]["processes"][0].clone();
    assert_eq!(replay["malformed"], 1, "{replay}");
    let error = replay["malformed_examples"][0]["error"].as_str().unwrap();
    assert!(error.contains("cannot be moved to the wall clock"), "{error}");
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

#[test]
fn a_monitor_over_forall_reports_each_binding_once_per_decision() {
    let out = out_dir("bindings");
    let result = run("specs/run/bindings.kpl", &out, &[]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let verdicts: Vec<(i64, String, bool)> = lines(&out.join("verdicts.jsonl"))
        .iter()
        .map(|r| {
            let v = &r["value"];
            (
                r["valid"].as_i64().unwrap() / 1000,
                v["c"].as_str().unwrap().to_string(),
                v["verdict"].as_bool().unwrap(),
            )
        })
        .collect();
    // No car at 0 s: nothing (not a vacuous `true`). car1 too fast at 2 s and 3 s: one `false`;
    // fine at 4 s and gone at 5 s: `true` as of 4 s. car2 too fast at 5 s.
    assert_eq!(
        verdicts,
        [
            (2000, "car1".to_string(), false),
            (4000, "car1".to_string(), true),
            (5000, "car2".to_string(), false)
        ]
    );
}

#[test]
fn for_on_the_wall_clock_lasts_its_time_even_when_the_last_sample_comes_earlier() {
    // A 1 s timer: its sample after 1.5 s would come at 2 s; the run still lasts 1.5 s.
    let out = out_dir("for-last-sample");
    let spec = out.join("slow.kpl");
    std::fs::write(
        &spec,
        "source ticks : int = timer(period: 1s)\nsink record = file.jsonl(ticks, path: \"t.jsonl\")\n",
    )
    .unwrap();
    let result = run(spec.to_str().unwrap(), &out, &["--clock", "wall", "--for", "1500ms"]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let report = summary(&out);
    assert_eq!(report["ending"], "duration_reached");
    assert!(report["clock_elapsed"].as_i64().unwrap() >= 1_500_000, "{report}");
    assert_eq!(lines(&out.join("t.jsonl")).len(), 2, "ticks at 0 s and 1 s");
}

#[test]
fn a_host_that_receives_nothing_stops_at_the_end_of_for() {
    // Host `b` of two_hosts waits for `a`, which never comes; with the transport's wait far
    // longer than --for, the run must still end at --for and say so.
    let out = out_dir("for-alone");
    let result = kpl(&[
        "run",
        "--quiet",
        "specs/zenoh/two_hosts.kpl",
        "--host",
        "b",
        "--clock",
        "wall",
        "--for",
        "2s",
        "--out",
        out.to_str().unwrap(),
    ])
    .env("KPL_ZENOH_WAIT", "600")
    .env("KPL_ZENOH_PORT_BASE", common::free_ports(2).to_string())
    .output()
    .unwrap();
    // Nothing arrived from another host: the run is incomplete (exit status 3) and says why.
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert_eq!(result.status.code(), Some(3), "{stderr}");
    assert!(stderr.contains("incomplete: nothing arrived on `percepts` from another host"), "{stderr}");
    let report = summary(&out);
    assert!(report["transport"]["inbound"].as_array().unwrap().iter().all(|s| s["received"] == 0));
    assert_eq!(report["ending"], "duration_reached");
    let elapsed = report["clock_elapsed"].as_i64().unwrap();
    assert!(
        (2_000_000..600_000_000).contains(&elapsed),
        "stopped at --for, not after the wait: {elapsed} us"
    );
}

#[test]
fn a_host_the_deploy_section_does_not_have_is_a_usage_error() {
    let out = out_dir("no-such-host");
    let result = run("specs/zenoh/two_hosts.kpl", &out, &["--host", "mars", "--clock", "wall"]);
    assert_eq!(result.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(stderr.contains("--host mars") && stderr.contains("`a`, `b`"), "{stderr}");
}

#[test]
fn a_run_lists_its_outputs_and_what_the_links_achieved() {
    let out = out_dir("report");
    let result = kpl(&["run", "specs/traffic/bridge.kpl", "--for", "30s", "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(result.status.success());
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(stderr.contains(&format!("outputs in {}:", out.display())), "{stderr}");
    for file in ["tracks.jsonl", "changes.jsonl", "summary.json"] {
        assert!(stderr.lines().any(|l| l.trim_start().starts_with(file)), "{file} listed:\n{stderr}");
        assert!(out.join(file).exists());
    }
    assert!(stderr.contains("new Car objects (establish)"), "{stderr}");
    // The counts are the changes the links recorded.
    let changes = lines(&out.join("changes.jsonl"));
    let reestablished = changes
        .iter()
        .flat_map(|r| r["value"].as_array().unwrap().clone())
        .filter(|c| c["kind"] == "linked" && c["cause"] == "reestablish" && c["link"] == "vision_world")
        .count() as u64;
    let report = summary(&out);
    let vision_world = report["summary"]["processes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["process"] == "vision_world")
        .unwrap()
        .clone();
    let result = vision_world["results"]
        .as_array()
        .unwrap()
        .iter()
        .find(|o| o["what"].as_str().unwrap().starts_with("links reestablished"))
        .unwrap()
        .clone();
    assert_eq!(result["count"].as_u64().unwrap(), reestablished);
    assert!(reestablished > 0, "the bridge makes the tracker lose cars");
}

#[test]
fn a_spec_that_never_ends_says_so_at_the_start() {
    let out = out_dir("endless-note");
    let mut child = kpl(&["run", "specs/run/endless.kpl", "--clock", "wall", "--out", out.to_str().unwrap()])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = std::io::BufReader::new(child.stderr.take().unwrap());
    let mut first = String::new();
    std::io::BufRead::read_line(&mut stderr, &mut first).unwrap();
    child.kill().unwrap();
    let _ = child.wait();
    assert!(first.starts_with("note: this run does not end by itself (`ticks` never ends)"), "{first}");
}

#[test]
fn recorded_traffic_ends_the_run_with_its_recording() {
    let out = out_dir("recorded-ends");
    let sumo = common::root().join("specs/traffic/sumo/highway");
    let spec = out.join("recorded.kpl");
    std::fs::write(
        &spec,
        format!(
            "type VisionPercept symbol vp {{ pos: vec2, vel: vec2, size: float }}\n\
             source tracker : list<VisionPercept> = sim.uav_tracker(network_file: {:?}, traffic_file: {:?})\n\
             sink seen = file.jsonl(tracker, path: \"seen.jsonl\")\n",
            sumo.join("net.xml.gz").to_str().unwrap(),
            sumo.join("fcd.xml.gz").to_str().unwrap(),
        ),
    )
    .unwrap();
    let output = kpl(&["run", spec.to_str().unwrap(), "--out", out.to_str().unwrap()]).output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(!stderr.contains("does not end by itself"), "{stderr}");
    assert!(stderr.contains("every source ended"), "{stderr}");
    // The highway recording is 240 s long, at the tracker's 10 Hz.
    let seen = lines(&out.join("seen.jsonl"));
    let last = seen.last().unwrap()["valid"].as_i64().unwrap();
    assert!((239_000_000..=240_000_000).contains(&last), "{last}");
}

#[test]
fn a_pair_monitor_reports_an_overtake_as_one_episode_gated_or_not() {
    let out = out_dir("pairs");
    let result = run("specs/run/pairs.kpl", &out, &[]);
    assert!(result.status.success(), "{}", String::from_utf8_lossy(&result.stderr));
    let records = lines(&out.join("pairs.jsonl"));
    let situations = |stream: &str| -> Vec<(String, String, i64, i64)> {
        records
            .iter()
            .filter(|r| r["stream"] == stream && r["value"]["verdict"] == true)
            .map(|r| {
                let v = &r["value"];
                let s = |k: &str| v[k].as_str().unwrap().to_string();
                (s("a"), s("b"), v["start"].as_i64().unwrap(), v["end"].as_i64().unwrap())
            })
            .collect()
    };
    // car1 is behind from 0 s, beside at 4 s, in front at 5 s: one overtake from 0 s to 5 s.
    let expected = vec![("car1".to_string(), "car2".to_string(), 0, 5_000_000)];
    assert_eq!(situations("gated"), expected);
    assert_eq!(situations("ungated"), expected);
    // Ungated, pairs far apart are progressed too: their `false` verdicts are reported (gated,
    // they are not progressed at all).
    let count = |stream: &str| records.iter().filter(|r| r["stream"] == stream).count();
    assert!(count("ungated") >= count("gated"), "{} < {}", count("ungated"), count("gated"));
    for r in &records {
        assert!(r["value"]["start"].as_i64().unwrap() <= r["value"]["end"].as_i64().unwrap(), "{r}");
    }
}

/// A reader that stops early (`kpl graph ... | head`) ends the command quietly, as it ends `cat`:
/// killed by SIGPIPE (or done, if it wrote everything before the pipe closed), never a panic.
#[test]
fn a_reader_that_stops_early_is_not_a_panic() {
    use std::os::unix::process::ExitStatusExt;
    use std::process::Stdio;
    for args in [
        ["graph", "specs/ok/overview.kpl", "--format", "dot"],
        ["check", "specs/ok/overview.kpl", "--format", "json"],
    ] {
        let mut child = kpl(&args).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
        drop(child.stdout.take());
        let output = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!stderr.contains("panicked"), "kpl {}: {stderr}", args.join(" "));
        assert!(
            output.status.success() || output.status.signal() == Some(13),
            "kpl {}: {:?} {stderr}",
            args.join(" "),
            output.status
        );
    }
}
