//! Data-driven tests of `kpl check` over the spec folders:
//! - every spec outside `specs/err/` checks with exit 0 and is in `kpl fmt`'s layout;
//! - every `specs/warn/NAME.kpl` checks with exit 0 and warnings equal to `NAME.diagnostics`;
//! - every `specs/err/NAME.kpl` fails with exit 1, and its rendered diagnostics equal
//!   `specs/err/NAME.diagnostics` (rewrite them with `KPL_BLESS=1 cargo test -p kpl --test specs`);
//! - `--format json` gives the documented fields (every label, in source order), and every code
//!   it uses is in docs/diagnostics.md, which `kpl explain CODE` prints;
//! - `kpl fmt --check specs/` passes: files that do not parse on purpose carry `// kpl fmt: skip`.
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
        for key in
            ["file", "line", "column", "end_line", "end_column", "severity", "code", "message", "labels"]
        {
            assert!(item.get(key).is_some(), "missing {key} in {item}");
        }
        let labels = item["labels"].as_array().unwrap();
        assert_eq!(labels[0]["primary"], true, "the primary label comes first: {item}");
        assert_eq!((&labels[0]["line"], &labels[0]["column"]), (&item["line"], &item["column"]));
        let places: Vec<(u64, u64)> = labels[1..]
            .iter()
            .map(|l| {
                assert_eq!(l["primary"], false);
                (l["line"].as_u64().unwrap(), l["column"].as_u64().unwrap())
            })
            .collect();
        assert!(places.windows(2).all(|w| w[0] <= w[1]), "secondary labels in source order: {item}");
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

#[test]
fn every_documented_code_is_explained() {
    let docs = std::fs::read_to_string(root().join("docs/diagnostics.md")).unwrap();
    let codes: Vec<&str> =
        docs.lines().filter_map(|l| l.strip_prefix("## ")).filter_map(|l| l.split(':').next()).collect();
    assert!(codes.len() > 40);
    for code in &codes {
        let out = kpl(&["explain", &code.to_lowercase()]);
        assert_eq!(out.status.code(), Some(0), "{code}");
        let text = String::from_utf8(out.stdout).unwrap();
        assert!(text.starts_with(&format!("{code}: ")), "{code}: {text}");
    }
    let listed = String::from_utf8(kpl(&["explain"]).stdout).unwrap();
    assert_eq!(listed.lines().count(), codes.len());
    let unknown = kpl(&["explain", "E9999"]);
    assert_eq!(unknown.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&unknown.stderr).contains("no diagnostic has the code"));
}

#[test]
fn the_whole_specs_folder_is_in_canonical_layout() {
    let out = kpl(&["fmt", "--check", "specs"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(stderr.contains("marked `// kpl fmt: skip`"), "{stderr}");
    // The skipped files are exactly the ones that do not parse.
    for spec in specs_under("specs") {
        let text = String::from_utf8_lossy(&std::fs::read(root().join(&spec)).unwrap()).into_owned();
        let marked = text.lines().any(|l| l == "// kpl fmt: skip");
        let parses = kpl_syntax_parses(&spec);
        assert_eq!(marked, !parses, "{spec}: marked {marked}, parses {parses}");
    }
}

/// Whether `kpl fmt -` can format the spec (it parses).
fn kpl_syntax_parses(spec: &str) -> bool {
    use std::io::Write;
    let mut child = common::kpl_command(&["fmt", "-"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let bytes = std::fs::read(root().join(spec)).unwrap();
    child.stdin.take().unwrap().write_all(&bytes).unwrap();
    child.wait().unwrap().success()
}

/// The numbers after `name="` in an SVG element.
fn attr(element: &str, name: &str) -> f64 {
    let at = element.find(&format!(" {name}=\"")).unwrap() + name.len() + 3;
    element[at..].split('"').next().unwrap().parse().unwrap()
}

#[test]
fn graphs_are_drawn_as_svg_with_every_process_and_stream_and_no_box_over_another() {
    for spec in valid_specs() {
        let out = kpl(&["graph", &spec]);
        assert_eq!(out.status.code(), Some(0), "{spec}");
        let svg = String::from_utf8(out.stdout).unwrap();
        assert!(svg.starts_with("<svg xmlns=\"http://www.w3.org/2000/svg\"") && svg.ends_with("</svg>\n"));
        let json: serde_json::Value =
            serde_json::from_slice(&kpl(&["graph", "--format", "json", &spec]).stdout).unwrap();
        let processes = json["processes"].as_array().unwrap();
        let boxes: Vec<(String, [f64; 4])> = svg
            .lines()
            .filter(|l| l.starts_with("<g class=\"process\""))
            .map(|l| {
                let name = l.split("data-name=\"").nth(1).unwrap().split('"').next().unwrap().to_string();
                let rect = &l[l.find("<rect").unwrap()..];
                (name, [attr(rect, "x"), attr(rect, "y"), attr(rect, "width"), attr(rect, "height")])
            })
            .collect();
        assert_eq!(boxes.len(), processes.len(), "{spec}: a box per process");
        for p in processes {
            assert!(boxes.iter().any(|(n, _)| n == p["name"].as_str().unwrap()), "{spec}: {}", p["name"]);
        }
        for (i, (a, [ax, ay, aw, ah])) in boxes.iter().enumerate() {
            for (b, [bx, by, bw, bh]) in &boxes[i + 1..] {
                let apart = ax + aw <= *bx || bx + bw <= *ax || ay + ah <= *by || by + bh <= *ay;
                assert!(apart, "{spec}: boxes of {a} and {b} overlap");
            }
        }
        let streams = svg.lines().filter(|l| l.starts_with("<path class=\"stream\"")).count();
        assert_eq!(streams, json["streams"].as_array().unwrap().len(), "{spec}: a curve per stream");
    }
}

#[test]
fn graphs_show_only_policies_that_differ_from_the_default() {
    let dot = String::from_utf8(kpl(&["graph", "--format", "dot", "specs/ok/overview.kpl"]).stdout).unwrap();
    assert!(!dot.contains("queue 1024 block") && !dot.contains("any update"), "{dot}");
    assert!(dot.contains("sample every 100ms, max delay 50ms, strict order"), "{dot}");
    let json: serde_json::Value =
        serde_json::from_slice(&kpl(&["graph", "--format", "json", "specs/ok/overview.kpl"]).stdout).unwrap();
    let percepts = &json["streams"][0];
    assert_eq!(percepts["policy_changes"], "sample every 100ms, max delay 50ms, strict order");
    assert!(percepts["policy_text"].as_str().unwrap().contains("queue 1024 block"), "JSON keeps every part");
}
