//! docs/custom-units.md takes a user from an empty crate to a running unit; this crate is the
//! one it builds. The page's files must be this crate's files, its `Cargo.toml` for a crate
//! outside this repository must resolve against a clone, and its commands must run as written.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests

use std::path::{Path, PathBuf};
use std::process::Command;

fn here() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn workspace() -> PathBuf {
    here().join("../..").canonicalize().unwrap()
}

/// The code blocks of the page that follow a `<!-- file: PATH -->` line: (path, content).
fn documented_files() -> Vec<(String, String)> {
    let page = std::fs::read_to_string(workspace().join("docs/custom-units.md")).unwrap();
    let mut files = Vec::new();
    let mut rest = page.as_str();
    while let Some(at) = rest.find("<!-- file: ") {
        let after = &rest[at + "<!-- file: ".len()..];
        let path = after.split(" -->").next().unwrap().to_string();
        let block = after.split_once("```").unwrap().1;
        let block = block.split_once('\n').unwrap().1;
        let (content, next) = block.split_once("\n```").unwrap();
        files.push((path, format!("{content}\n")));
        rest = next;
    }
    files
}

fn fresh(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kpl-custom-unit-docs-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn the_page_shows_this_crates_files() {
    let files = documented_files();
    let paths: Vec<&str> = files.iter().map(|(p, _)| p.as_str()).collect();
    assert_eq!(paths, ["Cargo.toml", "src/lib.rs", "src/main.rs", "accumulate.kpl", "braking.kpl"]);
    for (path, content) in &files[1..] {
        let actual = std::fs::read_to_string(here().join(path)).unwrap();
        assert_eq!(&actual, content, "docs/custom-units.md shows another {path} than examples/custom-unit");
    }
}

/// The platform this test runs on, as rustc names it (`host:` of `rustc -vV`).
fn host_triple() -> String {
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".to_string());
    let out = Command::new(rustc).arg("-vV").output().unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    text.lines().find_map(|l| l.strip_prefix("host: ")).expect("rustc -vV names its host").trim().to_string()
}

#[test]
fn the_pages_cargo_toml_resolves_outside_the_repository() {
    // A crate beside "the clone": the page's `../kpl/` paths point at this workspace.
    let dir = fresh("outside");
    let (_, manifest) = &documented_files()[0];
    let manifest = manifest.replace("../kpl/", &format!("{}/", workspace().display()));
    let krate = dir.join("my-units");
    std::fs::create_dir_all(krate.join("src")).unwrap();
    std::fs::write(krate.join("Cargo.toml"), manifest).unwrap();
    std::fs::copy(here().join("src/lib.rs"), krate.join("src/lib.rs")).unwrap();
    std::fs::copy(here().join("src/main.rs"), krate.join("src/main.rs")).unwrap();
    // The same versions as the workspace, and no network: resolution only. Only this platform's
    // packages: a build downloads no others, so a fresh `CARGO_HOME` holds no others either.
    std::fs::copy(workspace().join("Cargo.lock"), krate.join("Cargo.lock")).unwrap();
    let out = Command::new(env!("CARGO"))
        .args(["metadata", "--offline", "--format-version", "1", "--filter-platform", &host_triple()])
        .arg("--manifest-path")
        .arg(krate.join("Cargo.toml"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let metadata: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let root = metadata["resolve"]["root"].as_str().unwrap();
    assert!(root.contains("my-units"), "{root}");
    let names: Vec<&str> =
        metadata["packages"].as_array().unwrap().iter().map(|p| p["name"].as_str().unwrap()).collect();
    for needed in ["kpl", "kpl-core", "kpl-runtime", "kpl-semantic", "kpl-anchor", "kpl-std"] {
        assert!(names.contains(&needed), "{needed} not resolved: {names:?}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_pages_commands_run_as_written() {
    // `cargo run -- ARGS` in the new crate is this crate's binary with ARGS.
    let dir = fresh("run");
    std::fs::copy(here().join("accumulate.kpl"), dir.join("accumulate.kpl")).unwrap();
    let kpl = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_custom-unit")).args(args).current_dir(&dir).output().unwrap()
    };
    let list = kpl(&["list"]);
    assert!(String::from_utf8_lossy(&list.stdout).contains("demo.accumulate"));
    assert_eq!(kpl(&["check", "accumulate.kpl"]).status.code(), Some(0));
    let run = kpl(&["run", "accumulate.kpl"]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let sums: Vec<f64> = std::fs::read_to_string(dir.join("out/accumulate/sum.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["value"].as_f64().unwrap())
        .collect();
    assert_eq!(sums.first(), Some(&0.0));
    assert_eq!(sums.last(), Some(&90.0), "0, 2, 6, 12, ..., 90 as the page says");
    assert!(Path::new(&dir.join("out/accumulate/summary.json")).exists());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_users_prediction_model_runs_in_kpl_run() {
    // `braking.kpl`: a car seen at 10 m/s along x until x = 10 m at 1 s, then no more; its world
    // object is predicted by `demo.braking(deceleration: 2.0)` and must stop 25 m further on
    // (v² / 2a), slowing by 0.2 m/s every 100 ms on the way.
    let dir = fresh("braking");
    for file in ["braking.kpl", "braking.jsonl"] {
        std::fs::copy(here().join(file), dir.join(file)).unwrap();
    }
    let kpl = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_custom-unit")).args(args).current_dir(&dir).output().unwrap()
    };
    assert!(String::from_utf8_lossy(&kpl(&["list"]).stdout).contains("demo.braking"));
    let run = kpl(&["run", "braking.kpl"]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let states: Vec<(f64, f64, bool)> = std::fs::read_to_string(dir.join("out/braking/world.jsonl"))
        .unwrap()
        .lines()
        .filter_map(|l| {
            let line: serde_json::Value = serde_json::from_str(l).unwrap();
            let object = line["value"].as_array()?.first()?.clone();
            Some((object["pos"][0].as_f64()?, object["vel"][0].as_f64()?, object["measured"].as_bool()?))
        })
        .collect();
    let predicted: Vec<&(f64, f64, bool)> = states.iter().filter(|s| !s.2).collect();
    assert!(predicted.len() > 30, "{states:?}");
    let (x, v, _) = predicted.last().unwrap();
    assert!((x - 35.0).abs() < 0.6 && v.abs() < 1e-9, "stood at {x} with {v} m/s: {predicted:?}");
    for pair in predicted.windows(2).filter(|w| w[0].1 > 0.2) {
        assert!((pair[0].1 - pair[1].1 - 0.2).abs() < 1e-6, "{pair:?}");
    }
    std::fs::remove_dir_all(&dir).ok();
}
