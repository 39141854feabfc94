//! The invariants of docs/architecture.md that are about the code's shape, enforced ("tidy"
//! tests, as rust-analyzer has them):
//! - the crate graph: the engines (formulas, anchoring, AAPA, roads, simulators, scoring, ...)
//!   know nothing of the runtime, tokio or zenoh; zenoh is used by `kpl-zenoh` alone; the checker
//!   layers know nothing of the runtime;
//! - diagnostics are built only in each layer's `diagnostics.rs`;
//! - every module opens with a `//!` doc that says what it is for.
//!
//! (That nothing outside the runtime's `Clock` reads the system's clocks is clippy's
//! `disallowed-methods`, in clippy.toml.)
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use common::root;

/// Each workspace crate's normal (not dev or build) dependencies.
fn dependencies() -> BTreeMap<String, Vec<String>> {
    let out = std::process::Command::new(env!("CARGO"))
        .args(["metadata", "--offline", "--no-deps", "--format-version", "1"])
        .current_dir(root())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let metadata: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let mut graph = BTreeMap::new();
    for package in metadata["packages"].as_array().unwrap() {
        let deps = package["dependencies"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|d| d["kind"].is_null())
            .map(|d| d["name"].as_str().unwrap().to_string())
            .collect();
        graph.insert(package["name"].as_str().unwrap().to_string(), deps);
    }
    graph
}

#[test]
fn engines_know_nothing_of_the_runtime_tokio_or_zenoh() {
    let graph = dependencies();
    // Pure layers: time is an argument, nothing is spawned, nothing goes on a wire.
    let engines = [
        "kpl-core",
        "kpl-syntax",
        "kpl-semantic",
        "kpl-mtl",
        "kpl-roads",
        "kpl-camera",
        "kpl-sim",
        "kpl-aapa",
        "kpl-chronicle",
        "kpl-anchor",
        "kpl-cater",
        "kpl-score",
        "kpl-plot",
    ];
    for engine in engines {
        let deps = graph.get(engine).unwrap_or_else(|| panic!("no crate {engine}"));
        for forbidden in ["kpl-runtime", "kpl-std", "kpl-zenoh", "kpl-mcap", "kpl-bench", "tokio", "zenoh"] {
            assert!(!deps.iter().any(|d| d == forbidden), "{engine} depends on {forbidden}: {deps:?}");
        }
    }
    // The engines below each other as the code map says.
    let only = |krate: &str, allowed: &[&str]| {
        for dep in graph[krate].iter().filter(|d| d.starts_with("kpl")) {
            assert!(
                allowed.contains(&dep.as_str()),
                "{krate} depends on {dep}; docs/architecture.md allows {allowed:?}"
            );
        }
    };
    only("kpl-core", &[]);
    only("kpl-syntax", &["kpl-core"]);
    only("kpl-chronicle", &["kpl-core"]);
    only("kpl-semantic", &["kpl-core", "kpl-syntax", "kpl-chronicle"]);
    only("kpl-mtl", &["kpl-core", "kpl-syntax"]);
    only("kpl-roads", &["kpl-core"]);
    only("kpl-anchor", &["kpl-core", "kpl-syntax", "kpl-semantic", "kpl-mtl", "kpl-roads"]);
    // zenoh in one crate.
    for (krate, deps) in &graph {
        if krate != "kpl-zenoh" {
            assert!(!deps.iter().any(|d| d == "zenoh"), "{krate} uses zenoh; only kpl-zenoh may");
        }
    }
}

/// The `.rs` files under `dir`.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else { continue };
        for entry in entries {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// The library sources of every crate (`crates/*/src`, `kpl/src`).
fn library_sources() -> Vec<PathBuf> {
    let mut files = rust_files(&root().join("kpl/src"));
    for entry in std::fs::read_dir(root().join("crates")).unwrap() {
        files.extend(rust_files(&entry.unwrap().path().join("src")));
    }
    files
}

#[test]
fn diagnostics_are_built_only_in_diagnostics_rs() {
    let mut offenders = Vec::new();
    for file in library_sources() {
        let name = file.file_name().unwrap().to_string_lossy();
        if name == "diagnostics.rs" || name == "diagnostic.rs" {
            continue;
        }
        let text = std::fs::read_to_string(&file).unwrap();
        // Tests build diagnostics to test their rendering.
        let code = text.split("#[cfg(test)]").next().unwrap_or("");
        for (i, line) in code.lines().enumerate() {
            if line.contains("Diagnostic::error(") || line.contains("Diagnostic::warning(") {
                offenders.push(format!("{}:{}", file.strip_prefix(root()).unwrap().display(), i + 1));
            }
        }
    }
    assert!(offenders.is_empty(), "make these constructors in the layer's diagnostics.rs: {offenders:?}");
}

#[test]
fn every_module_says_what_it_is_for() {
    let mut missing = Vec::new();
    for file in library_sources() {
        let text = std::fs::read_to_string(&file).unwrap();
        let first = text.lines().find(|l| !l.trim().is_empty()).unwrap_or("");
        if !first.starts_with("//!") {
            missing.push(file.strip_prefix(root()).unwrap().display().to_string());
        }
    }
    assert!(missing.is_empty(), "these files do not open with a `//!` doc: {missing:?}");
}
