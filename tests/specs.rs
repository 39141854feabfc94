//! Data-driven tests of `kpl check` over the spec folders:
//! - every spec outside `specs/err/` checks with exit 0 and is in `kpl fmt`'s layout;
//! - every `specs/warn/NAME.kpl` checks with exit 0 and warnings equal to `NAME.diagnostics`;
//! - every `specs/err/NAME.kpl` fails with exit 1, and its rendered diagnostics equal
//!   `specs/err/NAME.diagnostics` (rewrite them with `KPL_BLESS=1 cargo test -p kpl --test specs`);
//! - `--format json` gives the documented fields, and every code it uses is in docs/diagnostics.md.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr)] // tests

mod common;

use common::{kpl, root};

fn specs_under(dir: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![root().join(dir)];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "kpl") {
                out.push(path.strip_prefix(root()).unwrap().to_string_lossy().into_owned());
            }
        }
    }
    out.sort();
    out
}

/// Every spec outside `specs/err/`.
fn valid_specs() -> Vec<String> {
    let mut specs = Vec::new();
    for entry in std::fs::read_dir(root().join("specs")).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if path.is_dir() && name != "err" {
            specs.extend(specs_under(&format!("specs/{name}")));
        }
    }
    assert!(specs.len() >= 3, "expected valid specs, found {specs:?}");
    specs
}

#[test]
fn valid_specs_check() {
    for spec in valid_specs() {
        let out = kpl(&["check", &spec]);
        assert_eq!(out.status.code(), Some(0), "{spec}:\n{}", String::from_utf8_lossy(&out.stderr));
    }
}

#[test]
fn valid_specs_are_in_canonical_layout() {
    let mut args = vec!["fmt", "--check"];
    let specs = valid_specs();
    args.extend(specs.iter().map(String::as_str));
    let out = kpl(&args);
    assert_eq!(
        out.status.code(),
        Some(0),
        "run `kpl fmt` on these:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn error_specs_match_their_diagnostics() {
    let specs = specs_under("specs/err");
    assert!(specs.len() >= 40);
    expect_diagnostics(&specs, 1);
}

#[test]
fn warning_specs_match_their_diagnostics() {
    let specs = specs_under("specs/warn");
    assert!(!specs.is_empty());
    expect_diagnostics(&specs, 0);
}

fn expect_diagnostics(specs: &[String], exit: i32) {
    let bless = std::env::var_os("KPL_BLESS").is_some();
    let mut mismatches = Vec::new();
    for spec in specs {
        let out = kpl(&["check", spec]);
        assert_eq!(out.status.code(), Some(exit), "{spec} should exit with {exit}");
        let rendered = String::from_utf8(out.stderr).unwrap();
        let expected_path = root().join(spec).with_extension("diagnostics");
        if bless {
            std::fs::write(&expected_path, &rendered).unwrap();
            continue;
        }
        let expected = std::fs::read_to_string(&expected_path).unwrap_or_default();
        if expected != rendered {
            mismatches.push(format!("--- {}\n{expected}\n+++ actual\n{rendered}", expected_path.display()));
        }
    }
    assert!(
        mismatches.is_empty(),
        "{} spec(s) differ (KPL_BLESS=1 rewrites):\n{}",
        mismatches.len(),
        mismatches.join("\n")
    );
}

#[test]
fn json_diagnostics_have_the_documented_fields_and_codes() {
    let docs = std::fs::read_to_string(root().join("docs/diagnostics.md")).unwrap();
    let specs = specs_under("specs/err");
    let mut args = vec!["check", "--format", "json"];
    args.extend(specs.iter().map(String::as_str));
    let out = kpl(&args);
    assert_eq!(out.status.code(), Some(1));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let items = json.as_array().unwrap();
    assert!(items.len() >= specs.len());
    let mut files_seen = std::collections::BTreeSet::new();
    for item in items {
        for key in ["file", "line", "column", "end_line", "end_column", "severity", "code", "message"] {
            assert!(item.get(key).is_some(), "missing {key} in {item}");
        }
        let code = item["code"].as_str().unwrap();
        assert!(docs.contains(&format!("## {code}")), "code {code} is not documented in docs/diagnostics.md");
        assert!(item["line"].as_u64().unwrap() >= 1 && item["column"].as_u64().unwrap() >= 1);
        files_seen.insert(item["file"].as_str().unwrap().to_string());
    }
    assert_eq!(files_seen.len(), specs.len(), "every error spec reports something");
}

#[test]
fn exit_codes() {
    assert_eq!(kpl(&["check", "specs/ok/overview.kpl"]).status.code(), Some(0));
    assert_eq!(kpl(&["check", "specs/err/unknown_stream.kpl"]).status.code(), Some(1));
    assert_eq!(kpl(&["check", "no/such/file.kpl"]).status.code(), Some(2));
    assert_eq!(kpl(&["check"]).status.code(), Some(2));
    assert_eq!(kpl(&["check", "--format", "yaml", "x.kpl"]).status.code(), Some(2));
    let help = kpl(&["check", "--help"]);
    assert_eq!(help.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&help.stdout).contains("Examples:"));
}

#[test]
fn every_command_has_help_with_an_example() {
    for command in [
        "check",
        "graph",
        "fmt",
        "list",
        "run",
        "convert",
        "score",
        "mtl",
        "mtl eval",
        "cater",
        "cater generate",
        "cater eval",
        "bench",
        "bench mtl",
        "bench runtime",
        "bench anchor",
    ] {
        let mut args: Vec<&str> = command.split(' ').collect();
        args.push("--help");
        let out = kpl(&args);
        assert_eq!(out.status.code(), Some(0), "{command}");
        assert!(String::from_utf8_lossy(&out.stdout).contains("Example"), "{command} --help has no example");
    }
}

#[test]
fn every_code_in_the_code_base_is_documented() {
    let docs = std::fs::read_to_string(root().join("docs/diagnostics.md")).unwrap();
    let mut codes = Vec::new();
    for file in ["crates/kpl-syntax/src/diagnostics.rs", "crates/kpl-semantic/src/diagnostics.rs"] {
        let text = std::fs::read_to_string(root().join(file)).unwrap();
        for line in text.lines().filter(|l| l.starts_with("pub const ")) {
            let code = line.split('"').nth(1).unwrap();
            codes.push(code.to_string());
        }
    }
    assert!(codes.len() > 40, "{codes:?}");
    for code in &codes {
        assert!(
            docs.contains(&format!("## {code}:")),
            "{code} is used but not documented in docs/diagnostics.md"
        );
    }
}
