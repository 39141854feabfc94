//! The example's spec runs with the example's own `kpl`, and the stock `kpl` does not know its
//! units (so the example really extends the registry).
#![allow(clippy::unwrap_used)] // tests

use std::path::Path;
use std::process::Command;

#[test]
fn the_running_sum_reads_its_own_previous_output() {
    let spec = Path::new(env!("CARGO_MANIFEST_DIR")).join("accumulate.kpl");
    let out = std::env::temp_dir().join(format!("kpl-custom-unit-{}", std::process::id()));
    let status = Command::new(env!("CARGO_BIN_EXE_custom-unit"))
        .args(["run", "--quiet", "--out"])
        .arg(&out)
        .arg(&spec)
        .status()
        .unwrap();
    assert!(status.success());
    let text = std::fs::read_to_string(out.join("sum.jsonl")).unwrap();
    let sums: Vec<f64> = text.lines().map(|l| serde_json_value(l, "value")).collect();
    // ticks 0..9 doubled: 0, 2, 4, ...; running sums 0, 2, 6, 12, ..., 90.
    let expected: Vec<f64> = (0..10)
        .scan(0.0, |acc, k| {
            *acc += 2.0 * f64::from(k);
            Some(*acc)
        })
        .collect();
    assert_eq!(sums, expected);
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn feedback_is_read_back_even_when_states_come_in_a_burst() {
    let spec = Path::new(env!("CARGO_MANIFEST_DIR")).join("burst.kpl");
    let out = std::env::temp_dir().join(format!("kpl-custom-unit-burst-{}", std::process::id()));
    let status = Command::new(env!("CARGO_BIN_EXE_custom-unit"))
        .args(["run", "--quiet", "--out"])
        .arg(&out)
        .arg(&spec)
        .status()
        .unwrap();
    assert!(status.success());
    let text = std::fs::read_to_string(out.join("sum.jsonl")).unwrap();
    let sums: Vec<f64> = text.lines().map(|l| serde_json_value(l, "value")).collect();
    assert_eq!(sums, [0.0, 1.0, 3.0, 6.0, 10.0, 15.0, 21.0, 28.0, 36.0, 45.0]);
    std::fs::remove_dir_all(&out).ok();
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
