//! End-to-end tests of `kpl mtl eval`: the built binary on trace files, checking its output
//! shapes, verdicts, `decided_at`, and its errors (with line numbers, exit code 1).

#![allow(clippy::unwrap_used, clippy::expect_used)] // a test fails loudly

use std::path::PathBuf;
use std::process::Command;

struct Run {
    code: i32,
    stdout: String,
    stderr: String,
}

fn trace_file(name: &str, lines: &[&str]) -> PathBuf {
    let dir =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("kpl-mtl-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, lines.iter().map(|l| format!("{l}\n")).collect::<String>()).unwrap();
    path
}

fn eval(formula: &str, trace: &PathBuf, extra: &[&str]) -> Run {
    let output = Command::new(env!("CARGO_BIN_EXE_kpl"))
        .args(["mtl", "eval", "--formula", formula, "--trace"])
        .arg(trace)
        .args(extra)
        .output()
        .unwrap();
    Run {
        code: output.status.code().unwrap_or(-1),
        stdout: String::from_utf8(output.stdout).unwrap(),
        stderr: String::from_utf8(output.stderr).unwrap(),
    }
}

fn json_lines(s: &str) -> Vec<serde_json::Value> {
    s.lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

const TRACE: &[&str] = &[
    r#"{"t": 0, "p": true,  "q": false, "x": 1.5}"#,
    r#"{"t": 2, "p": false, "q": false, "x": 0.5}"#,
    r#"{"t": 3, "p": true,  "q": true,  "x": 0.25}"#,
    r#"{"t": 9, "p": false, "q": false, "x": 4}"#,
];

/// (formula, verdict, decided_at) over `TRACE`, in milliseconds.
const CASES: &[(&str, bool, Option<i64>)] = &[
    ("p", true, Some(0)),
    ("q", false, Some(0)),
    ("eventually[0, 5] q", true, Some(3)),
    // The window [1, 2] holds only the state at 2.
    ("eventually[1, 2] q", false, Some(2)),
    // Time jumps from 3 to 9, over the whole window [4, 6]: decided at 9.
    ("eventually[4, 6] p", false, Some(9)),
    // The window [0, 3] ends with the state at 3.
    ("always[0, 3] x < 2", true, Some(3)),
    ("always x < 2", false, Some(9)),
    // Only the end of the trace decides an unbounded always that holds.
    ("always x > 0", true, None),
    ("eventually (x > 10)", false, None),
    // DyKnow's until: q at 3, and not p strictly between 0 and 3 (p at 0 itself is not asked).
    ("not p until[0, 5] q", true, Some(3)),
    ("p until[0, 5] q", false, Some(2)),
    ("p -> eventually[0, 5] (q and x < 1.0)", true, Some(3)),
    ("always[0, 5] (p -> eventually[0, 1s] q)", true, Some(9)),
    ("x * 2 >= 3 and abs(x - 2) < 1", true, Some(0)),
];

#[test]
fn single_verdict_and_decision_time() {
    let trace = trace_file("cases.jsonl", TRACE);
    for (formula, verdict, decided_at) in CASES {
        let run = eval(formula, &trace, &[]);
        assert_eq!(run.code, 0, "{formula}: {}", run.stderr);
        let out = json_lines(&run.stdout);
        assert_eq!(out.len(), 1, "{formula}: one line");
        assert_eq!(out[0]["verdict"], serde_json::json!(verdict), "{formula}");
        assert_eq!(out[0]["decided_at"], serde_json::json!(decided_at), "{formula}");
    }
}

#[test]
fn every_state_gets_a_verdict() {
    let trace = trace_file("every.jsonl", TRACE);
    let run = eval("eventually[0, 1] q", &trace, &["--every"]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let out = json_lines(&run.stdout);
    let got: Vec<(i64, bool)> =
        out.iter().map(|v| (v["t"].as_i64().unwrap(), v["verdict"].as_bool().unwrap())).collect();
    // From 2, the state at 3 is 1 ms later and has q; from 9 nothing follows.
    assert_eq!(got, vec![(0, false), (2, true), (3, true), (9, false)]);
}

#[test]
fn time_unit_sets_the_unit_of_time_stamps_and_bare_bounds() {
    let trace = trace_file("seconds.jsonl", &[r#"{"t": 0, "q": false}"#, r#"{"t": 2, "q": true}"#]);
    // In seconds, [0, 2] reaches the state at 2 s; so does [0, 2000ms].
    for formula in ["eventually[0, 2] q", "eventually[0, 2000ms] q", "eventually[0, 2s] q"] {
        let run = eval(formula, &trace, &["--time-unit", "s"]);
        assert_eq!(
            json_lines(&run.stdout)[0]["verdict"],
            serde_json::json!(true),
            "{formula}: {}",
            run.stderr
        );
    }
    // 1500 ms is not a whole number of seconds.
    let run = eval("eventually[0, 1500ms] q", &trace, &["--time-unit", "s"]);
    assert_eq!(run.code, 1);
    assert!(run.stderr.contains("not a whole number of s"), "{}", run.stderr);
}

#[test]
fn quantifiers_range_over_the_objects_of_a_state() {
    let trace = trace_file(
        "cars.jsonl",
        &[
            r#"{"t": 0, "Car": [{"id": "c1", "speed": 20}, {"id": "c2", "speed": 10}]}"#,
            r#"{"t": 100, "Car": [{"id": "c1", "speed": 24}, {"id": "c2", "speed": 26}]}"#,
        ],
    );
    let run = eval("forall c: Car . always (c.speed < 25)", &trace, &[]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert_eq!(json_lines(&run.stdout)[0], serde_json::json!({"verdict": false, "decided_at": 100}));
    let run = eval("exists c: Car . eventually (c.speed > 25)", &trace, &[]);
    assert_eq!(json_lines(&run.stdout)[0], serde_json::json!({"verdict": true, "decided_at": 100}));
}

fn assert_fails(run: &Run, needles: &[&str]) {
    assert_eq!(run.code, 1, "stdout: {} stderr: {}", run.stdout, run.stderr);
    assert!(run.stdout.is_empty(), "no verdict on error: {}", run.stdout);
    for needle in needles {
        assert!(run.stderr.contains(needle), "expected {needle:?} in:\n{}", run.stderr);
    }
}

#[test]
fn bad_traces_are_reported_with_their_line_number() {
    let malformed = trace_file("malformed.jsonl", &[r#"{"t": 0, "p": true}"#, r#"{"t": 1, "p": tru}"#]);
    assert_fails(&eval("always p", &malformed, &[]), &["malformed.jsonl:2:", "not a JSON object"]);

    let not_object = trace_file("array.jsonl", &[r#"{"t": 0, "p": true}"#, "", "[1, 2]"]);
    assert_fails(&eval("always p", &not_object, &[]), &["array.jsonl:3:", "expected a JSON object"]);

    let backwards = trace_file("backwards.jsonl", &[r#"{"t": 5, "p": true}"#, r#"{"t": 5, "p": true}"#]);
    assert_fails(&eval("always p", &backwards, &[]), &["backwards.jsonl:2:", "time stamps must increase"]);

    let no_time = trace_file("no_time.jsonl", &[r#"{"p": true}"#]);
    assert_fails(&eval("p", &no_time, &[]), &["no_time.jsonl:1:", "no time stamp `t`"]);

    let float_time = trace_file("float_time.jsonl", &[r#"{"t": 0.5, "p": true}"#]);
    assert_fails(&eval("p", &float_time, &[]), &["float_time.jsonl:1:", "`t` must be an integer"]);

    // A name the formula uses is missing from the third state: reported even though the verdict
    // of `eventually p` was already certain at the first.
    let missing = trace_file(
        "missing.jsonl",
        &[r#"{"t": 0, "p": true}"#, r#"{"t": 1, "p": false}"#, r#"{"t": 2, "pp": true}"#],
    );
    assert_fails(&eval("eventually p", &missing, &[]), &["missing.jsonl:3:", "unknown name `p`"]);

    let wrong_type = trace_file("type.jsonl", &[r#"{"t": 0, "p": 3}"#]);
    assert_fails(&eval("p", &wrong_type, &[]), &["type.jsonl:1:", "expected bool, found int"]);

    let empty = trace_file("empty.jsonl", &[]);
    assert_fails(&eval("p", &empty, &[]), &["no states"]);
}

#[test]
fn bad_formulas_are_reported_against_the_formula() {
    let trace = trace_file("formula_errors.jsonl", TRACE);
    assert_fails(&eval("eventually[0, 5 q", &trace, &[]), &["<formula>"]);
    assert_fails(
        &eval("xydst(p, q) < 3", &trace, &[]),
        &["unknown function `xydst`", "did you mean `xydist`?"],
    );
    assert_fails(&eval("eventually[5, 2] p", &trace, &[]), &["interval is empty"]);
    assert_fails(&eval("always (x + 1)", &trace, &[]), &["expected a condition"]);
}

#[test]
fn a_missing_trace_file_is_an_io_error() {
    let run = eval("p", &PathBuf::from("/nonexistent/trace.jsonl"), &[]);
    assert_eq!(run.code, 2);
    assert!(run.stderr.contains("cannot read"), "{}", run.stderr);
}

#[test]
fn help_shows_an_example() {
    let output = Command::new(env!("CARGO_BIN_EXE_kpl")).args(["mtl", "eval", "--help"]).output().unwrap();
    let help = String::from_utf8(output.stdout).unwrap();
    assert!(help.contains("Example:") && help.contains("--every") && help.contains("--time-unit"), "{help}");
}

#[test]
fn long_formulas_come_from_a_file() {
    let trace = trace_file("formula_file.jsonl", TRACE);
    let dir = trace.parent().unwrap().to_path_buf();
    // 30,000 conjuncts: far past what a command line takes (128 KiB per argument on Linux).
    let long: String = (0..30_000).map(|_| "x > 0").collect::<Vec<_>>().join(" and ");
    let path = dir.join("long.mtl");
    std::fs::write(&path, format!("always[0, 3] ({long})\n")).unwrap();
    let run = |extra: &[&str]| {
        let output = Command::new(env!("CARGO_BIN_EXE_kpl"))
            .args(["mtl", "eval", "--trace"])
            .arg(&trace)
            .args(extra)
            .output()
            .unwrap();
        (
            output.status.code(),
            String::from_utf8(output.stdout).unwrap(),
            String::from_utf8(output.stderr).unwrap(),
        )
    };
    let (code, stdout, stderr) = run(&["--formula-file", path.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{stderr}");
    assert_eq!(json_lines(&stdout)[0], serde_json::json!({"verdict": true, "decided_at": 3}));
    // Errors point into the file.
    let bad = dir.join("bad.mtl");
    std::fs::write(&bad, "always[0, 3]\n  (x > 0 and xydst(x, x) < 1)\n").unwrap();
    let (code, _, stderr) = run(&["--formula-file", bad.to_str().unwrap()]);
    assert_eq!(code, Some(1));
    assert!(stderr.contains("bad.mtl:2:14") && stderr.contains("did you mean `xydist`?"), "{stderr}");
    // One formula source, exactly.
    let (code, _, _) = run(&[]);
    assert_eq!(code, Some(2));
    let (code, _, _) = run(&["--formula", "p", "--formula-file", path.to_str().unwrap()]);
    assert_eq!(code, Some(2));
    let (code, _, stderr) = run(&["--formula-file", "/nonexistent/f.mtl"]);
    assert_eq!(code, Some(2), "{stderr}");
}

#[test]
fn invalid_utf8_is_an_input_error_with_its_line_and_a_byte_order_mark_is_skipped() {
    let dir =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("kpl-mtl-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("latin1.jsonl");
    let mut bytes = b"{\"t\": 0, \"p\": true}\n{\"t\": 1, \"p\": true, \"name\": \"M".to_vec();
    bytes.extend_from_slice(&[0xfc, b'l', b'l', b'e', b'r']);
    bytes.extend_from_slice(b"\"}\n");
    std::fs::write(&bad, &bytes).unwrap();
    assert_fails(&eval("always p", &bad, &[]), &["latin1.jsonl:2:", "not valid UTF-8"]);

    let bom = dir.join("bom.jsonl");
    std::fs::write(&bom, b"\xEF\xBB\xBF{\"t\": 0, \"p\": true}\n{\"t\": 1, \"p\": false}\n").unwrap();
    let run = eval("always p", &bom, &[]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert_eq!(json_lines(&run.stdout)[0], serde_json::json!({"verdict": false, "decided_at": 1}));
}

#[test]
fn every_prints_each_verdict_as_soon_as_it_and_the_earlier_ones_are_known() {
    use std::io::{BufRead, BufReader, Write};
    // The trace comes through a pipe, one state at a time; each verdict must come out before the
    // trace ends. `eventually[0, 2] q` from state i is known at most 2 states later.
    let mut child = Command::new(env!("CARGO_BIN_EXE_kpl"))
        .args(["mtl", "eval", "--formula", "eventually[0, 2] q", "--every", "--trace", "/dev/stdin"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let (lines, rx) = std::sync::mpsc::channel::<String>();
    let stdout = child.stdout.take().unwrap();
    let reader = std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            if lines.send(line.unwrap()).is_err() {
                break;
            }
        }
    });
    let mut printed = Vec::new();
    for t in 0..200i64 {
        writeln!(stdin, "{{\"t\": {t}, \"q\": {}}}", t % 5 == 4).unwrap();
        stdin.flush().unwrap();
        if t >= 2 {
            // State t - 2's verdict is known now (the window [t - 2, t] is closed).
            let line = rx
                .recv_timeout(std::time::Duration::from_secs(120))
                .expect("a verdict before the trace ends");
            printed.push(serde_json::from_str::<serde_json::Value>(&line).unwrap());
        }
    }
    drop(stdin);
    while let Ok(line) = rx.recv_timeout(std::time::Duration::from_secs(120)) {
        printed.push(serde_json::from_str(&line).unwrap());
    }
    assert!(child.wait().unwrap().success());
    reader.join().unwrap();
    assert_eq!(printed.len(), 200);
    for (i, v) in printed.iter().enumerate() {
        let t = i as i64;
        // q at every t with t % 5 == 4; from t, a q within [t, t + 2] (and inside the trace).
        let want = (t..=(t + 2).min(199)).any(|u| u % 5 == 4);
        assert_eq!(v, &serde_json::json!({"t": t, "verdict": want}), "state {t}");
    }
}
