//! The example's specs run with the example's own `kpl` (its units registered through
//! `kpl::main_with`).
#![allow(clippy::unwrap_used)] // tests

use std::path::Path;
use std::process::Command;

/// Runs one of the example's specs with the example's `kpl` and returns the recorded sums.
fn sums_of(spec: &str) -> Vec<f64> {
    let spec = Path::new(env!("CARGO_MANIFEST_DIR")).join(spec);
    let out = std::env::temp_dir()
        .join(format!("kpl-custom-unit-{}-{}", std::process::id(), spec.display()).replace('/', "_"));
    let status = Command::new(env!("CARGO_BIN_EXE_custom-unit"))
        .args(["run", "--quiet", "--out"])
        .arg(&out)
        .arg(&spec)
        .status()
        .unwrap();
    assert!(status.success());
    let text = std::fs::read_to_string(out.join("sum.jsonl")).unwrap();
    std::fs::remove_dir_all(&out).ok();
    text.lines().map(|l| serde_json_value(l, "value")).collect()
}

#[test]
fn the_running_sum_reads_its_own_previous_output() {
    // ticks 0..9 doubled: 0, 2, 4, ...; running sums 0, 2, 6, 12, ..., 90.
    let expected: Vec<f64> = (0..10)
        .scan(0.0, |acc, k| {
            *acc += 2.0 * f64::from(k);
            Some(*acc)
        })
        .collect();
    assert_eq!(sums_of("accumulate.kpl"), expected);
}

#[test]
fn feedback_is_read_back_even_when_states_come_in_a_burst() {
    assert_eq!(sums_of("burst.kpl"), [0.0, 1.0, 3.0, 6.0, 10.0, 15.0, 21.0, 28.0, 36.0, 45.0]);
}

#[test]
fn the_stock_kpl_does_not_know_the_units() {
    // Without the example's registry the spec does not check: the units really come from here.
    let kpl = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/debug/kpl");
    if !kpl.exists() {
        return; // the workspace's own `kpl` is not built in this configuration
    }
    let spec = Path::new(env!("CARGO_MANIFEST_DIR")).join("accumulate.kpl");
    let out = Command::new(kpl).arg("check").arg(&spec).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("demo.scale"));
}

#[test]
fn the_units_are_listed_with_their_parameters() {
    let out = Command::new(env!("CARGO_BIN_EXE_custom-unit")).arg("list").output().unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("demo.accumulate") && text.contains("demo.scale"), "{text}");
    assert!(text.contains("factor"));
}

/// The number in `"key":NUMBER` of a JSON line (the example keeps its dependencies minimal).
fn serde_json_value(line: &str, key: &str) -> f64 {
    let at = line.find(&format!("\"{key}\":")).unwrap() + key.len() + 3;
    line[at..].trim_end_matches('}').parse().unwrap()
}
