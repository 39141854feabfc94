//! Data-driven tests of the runtime: a spec in, what it does out, reviewed as text beside it.
//!
//! - Every `specs/plan/NAME.kpl` has `NAME.plan`: the plan of every host of its deploy section
//!   (and of the whole spec), as [`Plan::render`] prints it.
//! - Every `specs/run/NAME.kpl` has `NAME.expected`: how a simulated run of it ended, every file
//!   its sinks wrote, and its summary (what each stream delivered, dropped and approximated; what
//!   each process counted). A line `// run: --for 2s --seed 3 --strict` in the spec sets the run.
//!
//! So a new policy or built-in is a new file pair, not a new Rust test. `KPL_BLESS=1 cargo test
//! -p kpl-runtime --test specs` rewrites the expected files; review the diff.
//!
//! The registry is the runtime's built-ins plus the traffic relations of `kpl-anchor` (pure
//! functions), so that pair monitors run as `kpl run` runs them.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly

use std::path::{Path, PathBuf};

use kpl_runtime::plan::{Plan, Target};
use kpl_runtime::{ClockKind, Registry, RunConfig};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").canonicalize().unwrap()
}

fn registry() -> Registry {
    let mut registry = Registry::with_builtins();
    let functions = kpl_anchor::relations::functions();
    for signature in kpl_anchor::relations::signatures() {
        let function = functions.iter().find(|f| *f.name == *signature.name).unwrap();
        registry.add_function(signature, function.clone());
    }
    registry
}

fn specs_in(dir: &str) -> Vec<PathBuf> {
    let mut specs: Vec<PathBuf> = std::fs::read_dir(root().join(dir))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "kpl"))
        .collect();
    specs.sort();
    specs
}

/// Compares `actual` with the file beside `spec` with this extension, or rewrites it with
/// `KPL_BLESS=1`. Returns a description of the mismatch.
fn expect(spec: &Path, extension: &str, actual: &str) -> Option<String> {
    let path = spec.with_extension(extension);
    if std::env::var_os("KPL_BLESS").is_some() {
        std::fs::write(&path, actual).unwrap();
        return None;
    }
    let expected = std::fs::read_to_string(&path).unwrap_or_default();
    (expected != actual).then(|| {
        let first = expected.lines().zip(actual.lines()).position(|(a, b)| a != b);
        format!(
            "{} differs (KPL_BLESS=1 rewrites it); first differing line {:?}:\n--- expected\n{}\n--- actual\n{}",
            path.display(),
            first.map(|i| i + 1),
            first.and_then(|i| expected.lines().nth(i)).unwrap_or("(end)"),
            first.and_then(|i| actual.lines().nth(i)).unwrap_or("(end)"),
        )
    })
}

fn check(spec: &Path, registry: &Registry) -> kpl_semantic::hir::Spec {
    let text = std::fs::read_to_string(spec).unwrap();
    kpl_semantic::check_text(&text, registry.signatures())
        .unwrap_or_else(|e| panic!("{}: {e}", spec.display()))
}

#[test]
fn plans_are_as_recorded() {
    let registry = registry();
    let specs = specs_in("specs/plan");
    assert!(specs.len() >= 3, "{specs:?}");
    let mut failures = Vec::new();
    for path in &specs {
        let spec = check(path, &registry);
        let name = path.file_stem().unwrap().to_string_lossy().into_owned();
        let mut hosts: Vec<Option<String>> = vec![None];
        if let Some(deploy) = &spec.deploy {
            hosts.extend(deploy.hosts.iter().map(|h| Some(h.name.clone())));
        }
        let mut text = String::new();
        for host in hosts {
            let deployment = spec.deploy.as_ref().and_then(|d| d.name.clone());
            let target = Target {
                host,
                deployment: deployment.unwrap_or_else(|| kpl_runtime::run::DEFAULT_DEPLOYMENT.to_string()),
                spec_name: name.clone(),
            };
            let plan = Plan::new(&spec, &target).unwrap();
            text.push_str(&plan.render(&spec));
            text.push('\n');
        }
        failures.extend(expect(path, "plan", &text));
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// The options of a `// run: ...` line.
fn run_config(text: &str, spec_dir: &Path, out_dir: &Path, name: &str) -> RunConfig {
    let mut config = RunConfig {
        clock: ClockKind::Sim,
        seed: 1,
        out_dir: out_dir.to_path_buf(),
        spec_dir: spec_dir.to_path_buf(),
        spec_name: name.to_string(),
        ..RunConfig::default()
    };
    for line in text.lines().filter_map(|l| l.strip_prefix("// run:")) {
        let mut words = line.split_whitespace();
        while let Some(word) = words.next() {
            match word {
                "--for" => config.duration = Some(kpl_core::parse_duration(words.next().unwrap()).unwrap()),
                "--seed" => config.seed = words.next().unwrap().parse().unwrap(),
                "--strict" => config.strict = true,
                other => panic!("{name}: unknown run option `{other}`"),
            }
        }
    }
    config
}

/// Every file under `dir`, relative, sorted.
fn files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else { continue };
        for entry in entries {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                out.push(path.strip_prefix(dir).unwrap().to_path_buf());
            }
        }
    }
    out.sort();
    out
}

#[test]
fn runs_are_as_recorded() {
    let registry = registry();
    let specs = specs_in("specs/run");
    assert!(specs.len() >= 5, "{specs:?}");
    let mut failures = Vec::new();
    for path in &specs {
        let name = path.file_stem().unwrap().to_string_lossy().into_owned();
        let text = std::fs::read_to_string(path).unwrap();
        let spec = check(path, &registry);
        let spec_dir = path.parent().unwrap();
        let out_dir = std::env::temp_dir().join(format!("kpl-runtime-specs-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&out_dir);
        std::fs::create_dir_all(&out_dir).unwrap();
        let config = run_config(&text, spec_dir, &out_dir, &name);
        let mut actual = String::new();
        match kpl_runtime::run(&spec, &registry, &config, None) {
            Ok(report) => {
                actual.push_str(&format!("ending: {:?}\n", report.ending));
                for failure in &report.failures {
                    actual.push_str(&format!("failure: {failure}\n"));
                }
                for file in files(&out_dir) {
                    actual.push_str(&format!("\n== {}\n", file.display()));
                    actual.push_str(&std::fs::read_to_string(out_dir.join(&file)).unwrap());
                }
                actual.push_str("\n== summary\n");
                actual.push_str(&serde_json::to_string_pretty(&report.summary).unwrap());
                actual.push('\n');
            }
            Err(e) => actual.push_str(&format!("error: {e}\n")),
        }
        // Paths in messages as the spec's folder names them, not this machine's.
        let actual = actual
            .replace(&spec_dir.display().to_string(), "specs/run")
            .replace(&out_dir.display().to_string(), "OUT");
        failures.extend(expect(path, "expected", &actual));
        let _ = std::fs::remove_dir_all(&out_dir);
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}
