//! Computational units in Python (`python.unit`, docs/python.md) run by `kpl run` in worker
//! processes it supervises:
//! - the shipped `specs/python/vehicle_kind.kpl` (NumPy classifier beside the spec) twice in
//!   simulated time with one seed: byte-identical outputs; and on the wall clock;
//! - lockstep: a worker that takes 50 ms a call gives the same bytes in simulated time as one
//!   that answers at once; on the wall clock its latency is in the outputs' available times;
//! - a unit that raises (traceback and the spec's position, the run goes on or stops as
//!   `on_error` says), one that hangs (the spec's `timeout`), one that returns a wrong type (the
//!   field named), a worker killed mid-run (restarted, the lost input counted);
//! - what `kpl check` finds without running Python (module, function, parameters).
//!
//! Needs the Python of `scripts/test` (`KPL_PYTHON`, with NumPy and the repository's package);
//! skipped without it unless `KPL_REQUIRE_ORACLES=1`.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests unwrap

mod common;

use std::path::Path;
use std::process::Output;

use common::{fresh_dir, kpl, kpl_command, lines, root};
use serde_json::Value;

/// `kpl run SPEC --out OUT --python PYTHON ARGS... --format json`.
fn run(python: &str, spec: &Path, out: &Path, args: &[&str]) -> Output {
    kpl_command(&["run"])
        .arg(spec)
        .arg("--out")
        .arg(out)
        .args(["--python", python, "--format", "json", "--quiet"])
        .args(args)
        .output()
        .unwrap()
}

/// The summary of a `--format json` run, and the process's entry in it.
fn process<'a>(summary: &'a Value, name: &str) -> &'a Value {
    summary["summary"]["processes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["process"] == name)
        .unwrap_or_else(|| panic!("no process `{name}` in {summary}"))
}

fn result(process: &Value, what: &str) -> u64 {
    process["results"]
        .as_array()
        .unwrap()
        .iter()
        .find(|o| o["what"] == what)
        .and_then(|o| o["count"].as_u64())
        .unwrap_or_else(|| panic!("no result `{what}` in {process}"))
}

fn summary(output: &Output) -> Value {
    serde_json::from_slice(&output.stdout).unwrap_or_else(|e| {
        panic!(
            "not a JSON summary ({e}): {}\n{}",
            String::from_utf8_lossy(&output.stdout),
            String::from_utf8_lossy(&output.stderr)
        )
    })
}

/// A folder with `units.py` and a spec `NAME.kpl` of `body`.
fn fixture(name: &str, body: &str) -> common::InTestDir {
    let dir = fresh_dir("pyunits", name);
    std::fs::write(dir.join("units.py"), UNITS).unwrap();
    let spec = dir.join(format!("{name}.kpl"));
    std::fs::write(&spec, body).unwrap();
    dir.holding(spec)
}

/// The units of the fixtures: each misbehaves at one input, on purpose.
const UNITS: &str = r#"
import os, signal, time

def double(x, *, delay=0.0):
    if delay:
        time.sleep(delay)
    return 2.0 * x

def raises_at(x, *, at=3):
    if x == at:
        raise ValueError(f"no good: {x}")
    return float(x)

def hangs_at(x, *, at=3):
    if x == at:
        time.sleep(600)
    return float(x)

def dies_at(x, *, at=3):
    if x == at:
        os.kill(os.getpid(), signal.SIGKILL)
    return float(x)

def wrong_kind(x):
    return {"id": "k1", "kind": 3 if x == 2 else "car", "size": 1.0}

def total(xs):
    return {"id": "t1", "sum": float(sum(xs)), "n": len(xs), "kind": type(xs).__name__}
"#;

fn ticks_spec(count: u32, unit: &str) -> String {
    format!(
        "source ticks : int = timer(period: 100ms, count: {count})\n\
         compute y : float = {unit}\n\
         sink out = file.jsonl(ticks, y, path: \"y.jsonl\")\n"
    )
}

fn values(path: &Path) -> Vec<f64> {
    lines(path).iter().filter(|l| l["stream"] == "y").map(|l| l["value"].as_f64().unwrap()).collect()
}

#[test]
fn the_shipped_spec_is_byte_identical_run_to_run_in_simulated_time() {
    let Some(python) = common::python("NumPy and the kpl package") else { return };
    let spec = root().join("specs/python/vehicle_kind.kpl");
    let (a, b) = (fresh_dir("pyunits", "ship-a"), fresh_dir("pyunits", "ship-b"));
    for out in [&a, &b] {
        let output = run(&python, &spec, out, &["--for", "30s", "--seed", "3"]);
        assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
        let summary = summary(&output);
        let kinds = process(&summary, "kinds");
        assert_eq!(kinds["errors"], 0, "{kinds}");
        assert_eq!(result(kinds, "failed calls"), 0);
        assert!(result(kinds, "calls") > 100, "{kinds}");
    }
    for file in ["kinds.jsonl", "tracks.jsonl", "changes.jsonl"] {
        let (x, y) = (std::fs::read(a.join(file)).unwrap(), std::fs::read(b.join(file)).unwrap());
        assert!(x == y, "{file} differs between two runs with the same seed");
    }
    // One answer per frame of percepts, each percept classified; the four cars are cars.
    let kinds = lines(&a.join("kinds.jsonl"));
    let frames: Vec<Value> =
        lines(&a.join("tracks.jsonl")).into_iter().filter(|l| l["stream"] == "tracker").collect();
    assert_eq!(kinds.len(), frames.len());
    for (kind, frame) in kinds.iter().zip(&frames) {
        assert_eq!(kind["valid"], frame["valid"]);
        let ids: Vec<&Value> = frame["value"].as_array().unwrap().iter().map(|p| &p["id"]).collect();
        let classified: Vec<&Value> = kind["value"].as_array().unwrap().iter().map(|k| &k["id"]).collect();
        assert_eq!(ids, classified);
    }
    let last = kinds.last().unwrap()["value"].as_array().unwrap();
    assert!(last.iter().any(|k| k["kind"] == "car"), "{last:?}");
}

#[test]
fn the_shipped_spec_runs_on_the_wall_clock() {
    let Some(python) = common::python("NumPy and the kpl package") else { return };
    let spec = root().join("specs/python/vehicle_kind.kpl");
    let out = fresh_dir("pyunits", "ship-wall");
    let output = run(&python, &spec, &out, &["--for", "3s", "--clock", "wall"]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let kinds = lines(&out.join("kinds.jsonl"));
    assert!(kinds.len() > 10, "{} answers in 3 s", kinds.len());
    for k in &kinds {
        assert!(k["available"].as_i64().unwrap() >= k["valid"].as_i64().unwrap());
    }
}

#[test]
fn a_slow_worker_changes_nothing_in_simulated_time_and_its_latency_shows_on_the_wall_clock() {
    let Some(python) = common::python("the kpl package") else { return };
    let fast =
        fixture("fast", &ticks_spec(10, "python.unit(ticks, module: \"units\", function: \"double\")"));
    let slow = fixture(
        "slow",
        &ticks_spec(10, "python.unit(ticks, module: \"units\", function: \"double\", delay: 0.05)"),
    );
    let (a, b) = (fresh_dir("pyunits", "fast-out"), fresh_dir("pyunits", "slow-out"));
    assert!(run(&python, &fast, &a, &[]).status.success());
    assert!(run(&python, &slow, &b, &[]).status.success());
    let (x, y) = (std::fs::read(a.join("y.jsonl")).unwrap(), std::fs::read(b.join("y.jsonl")).unwrap());
    assert!(x == y, "a worker taking 50 ms a call changed the simulated run's output");
    assert_eq!(values(&a.join("y.jsonl")), (0..10).map(|i| 2.0 * f64::from(i)).collect::<Vec<_>>());
    for line in lines(&a.join("y.jsonl")) {
        assert_eq!(line["valid"], line["available"], "in simulated time a call takes no time: {line}");
    }
    let wall = fresh_dir("pyunits", "slow-wall");
    assert!(run(&python, &slow, &wall, &["--clock", "wall"]).status.success());
    let ys: Vec<Value> = lines(&wall.join("y.jsonl")).into_iter().filter(|l| l["stream"] == "y").collect();
    assert_eq!(ys.len(), 10);
    for line in &ys {
        let latency = line["available"].as_i64().unwrap() - line["valid"].as_i64().unwrap();
        assert!(latency >= 50_000, "the call's 50 ms are not in the available time: {line}");
    }
}

#[test]
fn a_unit_that_raises_is_reported_with_its_traceback_and_position_and_the_run_goes_on() {
    let Some(python) = common::python("the kpl package") else { return };
    let spec =
        fixture("raises", &ticks_spec(6, "python.unit(ticks, module: \"units\", function: \"raises_at\")"));
    let out = fresh_dir("pyunits", "raises-out");
    let output = run(&python, &spec, &out, &[]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let first = summary(&output);
    let y = process(&first, "y");
    assert_eq!((y["errors"].as_u64(), result(y, "failed calls"), result(y, "calls")), (Some(1), 1, 6));
    let example = y["error_examples"][0].as_str().unwrap();
    assert!(example.contains("ValueError: no good: 3"), "{example}");
    assert!(example.contains("Traceback (most recent call last)"), "{example}");
    assert!(example.contains("units.py\", line"), "{example}");
    assert!(example.contains("raises.kpl:2:"), "the spec's position of the unit: {example}");
    assert_eq!(values(&out.join("y.jsonl")), [0.0, 1.0, 2.0, 4.0, 5.0]);

    // `on_error: "stop"` stops the run there, and says so.
    let spec = fixture(
        "raises-stop",
        &ticks_spec(6, "python.unit(ticks, module: \"units\", function: \"raises_at\", on_error: \"stop\")"),
    );
    let out = fresh_dir("pyunits", "raises-stop-out");
    let output = run(&python, &spec, &out, &[]);
    assert_eq!(output.status.code(), Some(1));
    let stopped = summary(&output);
    assert_eq!(stopped["ending"], "unit_stopped", "{stopped}");
    let failure = stopped["failures"][0].as_str().unwrap();
    assert!(
        failure.contains("ValueError: no good: 3") && failure.contains("policy stops the run"),
        "{failure}"
    );
    assert_eq!(values(&out.join("y.jsonl")), [0.0, 1.0, 2.0]);
}

#[test]
fn a_unit_that_hangs_is_stopped_by_the_specs_timeout_and_restarted() {
    let Some(python) = common::python("the kpl package") else { return };
    let spec = fixture(
        "hangs",
        &ticks_spec(6, "python.unit(ticks, module: \"units\", function: \"hangs_at\", timeout: 500ms)"),
    );
    let out = fresh_dir("pyunits", "hangs-out");
    // The unit sleeps 600 s at 3: the values and the message below say the timeout stopped it.
    let output = run(&python, &spec, &out, &[]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let summary = summary(&output);
    let y = process(&summary, "y");
    assert_eq!(
        (result(y, "failed calls"), result(y, "worker restarts"), result(y, "inputs lost with a worker")),
        (1, 1, 1)
    );
    let example = y["error_examples"][0].as_str().unwrap();
    assert!(example.contains("did not answer within 500ms"), "{example}");
    assert_eq!(values(&out.join("y.jsonl")), [0.0, 1.0, 2.0, 4.0, 5.0]);
}

#[test]
fn a_killed_worker_is_restarted_and_the_input_it_had_is_counted_as_lost() {
    let Some(python) = common::python("the kpl package") else { return };
    let spec =
        fixture("dies", &ticks_spec(6, "python.unit(ticks, module: \"units\", function: \"dies_at\")"));
    let out = fresh_dir("pyunits", "dies-out");
    let output = run(&python, &spec, &out, &[]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let summary = summary(&output);
    let y = process(&summary, "y");
    assert_eq!(
        (result(y, "failed calls"), result(y, "worker restarts"), result(y, "inputs lost with a worker")),
        (1, 1, 1)
    );
    let example = y["error_examples"][0].as_str().unwrap();
    assert!(example.contains("killed by signal 9") && example.contains("is lost"), "{example}");
    assert_eq!(values(&out.join("y.jsonl")), [0.0, 1.0, 2.0, 4.0, 5.0]);
}

#[test]
fn a_wrong_type_is_an_error_naming_the_field() {
    let Some(python) = common::python("the kpl package") else { return };
    let spec = fixture(
        "wrong",
        "type Kind symbol k { kind: string, size: float }\n\
         source ticks : int = timer(period: 100ms, count: 4)\n\
         compute y : Kind = python.unit(ticks, module: \"units\", function: \"wrong_kind\")\n\
         sink out = file.jsonl(y, path: \"y.jsonl\")\n",
    );
    let out = fresh_dir("pyunits", "wrong-out");
    let output = run(&python, &spec, &out, &[]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let summary = summary(&output);
    let y = process(&summary, "y");
    assert_eq!(result(y, "failed calls"), 1);
    let example = y["error_examples"][0].as_str().unwrap();
    assert!(example.contains("not a `Kind`") && example.contains("kind"), "{example}");
    assert_eq!(lines(&out.join("y.jsonl")).len(), 3);
}

#[test]
fn float_lists_arrive_as_numpy_arrays_or_lists() {
    let Some(python) = common::python("NumPy and the kpl package") else { return };
    for (arrays, kind) in [("numpy", "ndarray"), ("list", "list")] {
        let spec = fixture(
            &format!("arrays-{arrays}"),
            &format!(
                "type Total symbol tt {{ sum: float, n: int, kind: string }}\n\
                 source xs : list<float> = file.jsonl(path: \"xs.jsonl\")\n\
                 compute t : Total = python.unit(xs, module: \"units\", function: \"total\", arrays: \"{arrays}\")\n\
                 sink out = file.jsonl(t, path: \"t.jsonl\")\n"
            ),
        );
        let values: Vec<f64> = (0..1000).map(|i| f64::from(i) * 0.5).collect();
        let line = serde_json::json!({"stream": "xs", "valid": 0, "value": values});
        std::fs::write(spec.parent().unwrap().join("xs.jsonl"), format!("{line}\n")).unwrap();
        let out = fresh_dir("pyunits", &format!("arrays-{arrays}-out"));
        let output = run(&python, &spec, &out, &[]);
        assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
        let t = lines(&out.join("t.jsonl"));
        let total = &t[0]["value"];
        assert_eq!(
            (&total["sum"], &total["n"], &total["kind"]),
            (&serde_json::json!(249750.0), &serde_json::json!(1000), &serde_json::json!(kind)),
            "{t:?}"
        );
    }
}

#[test]
fn kpl_check_finds_the_module_the_function_and_its_parameters_without_running_python() {
    let dir = fresh_dir("pyunits", "check");
    std::fs::write(dir.join("units.py"), UNITS).unwrap();
    let check = |name: &str, unit: &str| -> String {
        let spec = dir.join(format!("{name}.kpl"));
        std::fs::write(&spec, ticks_spec(3, unit)).unwrap();
        let output = kpl(&["check", spec.to_str().unwrap()]);
        String::from_utf8_lossy(&output.stderr).to_string() + &String::from_utf8_lossy(&output.stdout)
    };
    let ok = check("ok", "python.unit(ticks, module: \"units\", function: \"double\", delay: 0.5)");
    assert!(!ok.contains("error"), "{ok}");
    let module = check("module", "python.unit(ticks, module: \"unit\", function: \"double\")");
    assert!(module.contains("E0118") && module.contains("no module `unit` beside the spec"), "{module}");
    let function = check("function", "python.unit(ticks, module: \"units\", function: \"doubel\")");
    assert!(
        function.contains("has no function or class `doubel`") && function.contains("did you mean `double`"),
        "{function}"
    );
    let param = check("param", "python.unit(ticks, module: \"units\", function: \"double\", dealy: 0.5)");
    assert!(
        param.contains("`double` has no parameter `dealy`") && param.contains("did you mean `delay`"),
        "{param}"
    );
    let inputs = check("inputs", "python.unit(ticks, ticks, module: \"units\", function: \"double\")");
    assert!(inputs.contains("`double` takes 1 input(s), but the spec gives it 2"), "{inputs}");
    let missing = check("missing", "python.unit(ticks, module: \"units\")");
    assert!(missing.contains("function"), "{missing}");
}

/// A process unit written from docs/process-units.md alone, without the `kpl` package: it answers
/// each call with its first input's sample message unchanged, and fails its `fail_call`-th call.
const RAW_WORKER: &str = r#"#!/usr/bin/env python3
import json, struct, sys

inp, out = sys.stdin.buffer, sys.stdout.buffer

def read():
    head = inp.read(5)
    if len(head) < 5:
        return None, b""
    length, kind = struct.unpack("<IB", head)
    return bytes([kind]), inp.read(length - 1)

def write(kind, body=b""):
    out.write(struct.pack("<IB", len(body) + 1, kind[0]))
    out.write(body)
    out.flush()

kind, body = read()
hello = json.loads(body)
fail = hello["params"].get("fail_call", 0)
ready = {"protocol": hello["protocol"], "wire": hello["wire"], "kind": "function", "implementation": "raw"}
write(b"R", json.dumps(ready).encode())
calls = 0
while True:
    kind, body = read()
    if kind is None or kind == b"Q":
        break
    calls += 1
    valid, now, n = struct.unpack_from("<qqI", body)
    (length,) = struct.unpack_from("<I", body, 20)
    if calls == fail:
        write(b"E", json.dumps({"error": f"call {calls} fails on purpose", "traceback": ""}).encode())
    else:
        write(b"O", b"" if length == 0xFFFFFFFF else body[24 : 24 + length])
"#;

#[test]
fn a_unit_in_any_language_runs_as_a_process_that_speaks_the_documented_protocol() {
    let Some(_python) = common::python("python3 on the PATH") else { return };
    let dir = fresh_dir("pyunits", "process");
    let worker = dir.join("echo_worker.py");
    std::fs::write(&worker, RAW_WORKER).unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&worker, std::fs::Permissions::from_mode(0o755)).unwrap();
    let body = |unit: &str| {
        format!(
            "source ticks : int = timer(period: 100ms, count: 6)\n\
             compute y : int = {unit}\n\
             sink out = file.jsonl(ticks, y, path: \"y.jsonl\")\n"
        )
    };
    let spec = dir.join("process.kpl");
    std::fs::write(&spec, body("process.unit(ticks, command: [\"./echo_worker.py\"], fail_call: 4)"))
        .unwrap();
    let out = dir.join("out");
    let output = kpl_command(&["run"])
        .arg(&spec)
        .arg("--out")
        .arg(&out)
        .args(["--format", "json", "--quiet"])
        .output()
        .unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let summary = summary(&output);
    let y = process(&summary, "y");
    assert_eq!((result(y, "calls"), result(y, "failed calls"), result(y, "worker restarts")), (6, 1, 0));
    let example = y["error_examples"][0].as_str().unwrap();
    assert!(example.contains("call 4 fails on purpose") && example.contains("./echo_worker.py"), "{example}");
    assert_eq!(values(&out.join("y.jsonl")), [0.0, 1.0, 2.0, 4.0, 5.0]);

    // `kpl check` finds a program path that is not there.
    let missing = dir.join("missing.kpl");
    std::fs::write(&missing, body("process.unit(ticks, command: [\"./no_such_worker\"])")).unwrap();
    let output = kpl(&["check", missing.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&output.stderr).to_string() + &String::from_utf8_lossy(&output.stdout);
    assert!(!output.status.success() && text.contains("E0118") && text.contains("no program"), "{text}");
}
