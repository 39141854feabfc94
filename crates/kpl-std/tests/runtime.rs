//! Anchoring on the stream runtime, as `kpl run specs/traffic/bridge.kpl` runs it: the spec checks
//! against the runtime's registry (built-ins, `kpl-std`, anchoring), runs with simulated time, and
//! every sample its link processes emitted (the objects of each link's type and its changes) is
//! what the pure engine computes when each link steps on its own input (the tracker's recorded
//! snapshots, then each link's recorded output), and what `Anchoring::step` computes from the
//! tracker snapshots alone (all links at once).
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use kpl_anchor::{AnchorConfig, Anchoring, FromSnapshot, Snapshot};
use kpl_core::{Time, Value};
use kpl_runtime::{Ending, RunConfig, RunReport};

fn registry() -> kpl_runtime::Registry {
    // The registry the `kpl` command runs with.
    kpl_std::registry()
}

fn specs_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../specs/traffic")
}

fn check(text: &str, registry: &kpl_runtime::Registry) -> kpl_semantic::hir::Spec {
    let parse = kpl_syntax::parse(text);
    assert!(!parse.has_errors(), "{:?}", parse.diagnostics);
    let checked = kpl_semantic::check(&parse.spec, registry.signatures());
    assert!(!checked.has_errors(), "{:?}", checked.diagnostics);
    checked.spec.unwrap()
}

/// A fresh directory for one test's run (`name` keeps the tests apart).
fn fresh_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kpl-anchor-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs a spec made from `bridge.kpl` as `kpl run` does, with simulated time (seed 3) for
/// `duration`, its outputs in `out_dir`; no process may fail.
fn run_bridge(
    spec: &kpl_semantic::hir::Spec,
    registry: &kpl_runtime::Registry,
    out_dir: &Path,
    duration: Time,
) -> RunReport {
    let config = RunConfig {
        duration: Some(duration),
        seed: 3,
        out_dir: out_dir.to_path_buf(),
        spec_dir: specs_dir(),
        spec_name: "bridge".into(),
        ..RunConfig::default()
    };
    let report = kpl_runtime::run(spec, registry, &config, None).unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    report
}

/// One recorded sample: (stream, valid time, value as JSON).
fn read_samples(path: &Path) -> Vec<(String, Time, serde_json::Value)> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .map(|line| {
            let j: serde_json::Value = serde_json::from_str(line).unwrap();
            (j["stream"].as_str().unwrap().to_string(), j["valid"].as_i64().unwrap(), j["value"].clone())
        })
        .collect()
}

#[test]
fn the_bridge_spec_runs_on_the_runtime_as_the_engine_computes_it() {
    let registry = registry();
    let bridge = std::fs::read_to_string(specs_dir().join("bridge.kpl")).unwrap();
    // The spec as it is checks against the runtime's registry.
    let _ = check(&bridge, &registry);
    // Record everything the link processes emit, with the tracker's snapshots.
    let text = format!(
        "{bridge}\nsink everything = file.jsonl(tracker, vision_world, world_onroad, onroad_car, vision_world.changes, world_onroad.changes, onroad_car.changes, world, path: \"all.jsonl\")\ncompute world = anchor.world_model(onroad_car)\n"
    );
    let spec = check(&text, &registry);
    let out_dir = fresh_dir("runtime");
    let report = run_bridge(&spec, &registry, &out_dir, 40_000_000);
    assert!(matches!(report.ending, Ending::DurationReached | Ending::SourcesEnded), "{:?}", report.ending);

    let samples = read_samples(&out_dir.join("all.jsonl"));
    let mut by_stream: BTreeMap<&str, BTreeMap<Time, &serde_json::Value>> = BTreeMap::new();
    for (stream, valid, value) in &samples {
        let previous = by_stream.entry(stream).or_default().insert(*valid, value);
        assert!(previous.is_none(), "two samples of {stream} at {valid}");
    }
    let frames = by_stream["tracker"].len();
    assert!(frames >= 390, "{frames} tracker frames");

    // Each link process stepped the engine on its own input: the same steps on the pure engine
    // give the same outputs at every time, and so does `step` with the tracker's snapshots.
    let mut engine = Anchoring::from_spec(&spec, AnchorConfig::default()).unwrap();
    let mut all_at_once = Anchoring::from_spec(&spec, AnchorConfig::default()).unwrap();
    let links = [
        ("vision_world", "percepts", "WorldObject"),
        ("world_onroad", "vision_world", "OnRoadObject"),
        ("onroad_car", "world_onroad", "Car"),
    ];
    let percepts_type = kpl_core::ValueType::List(Box::new(kpl_core::ValueType::Record(
        spec.types.get("VisionPercept").unwrap().clone(),
    )));
    let mut compared = 0;
    let mut cars = 0;
    for (&time, value) in &by_stream["tracker"] {
        let percepts = Value::from_json(value, &percepts_type).unwrap();
        let mut input = percepts.clone();
        for (link, stream, ty) in links {
            let output = engine
                .step_link(link, time, &[FromSnapshot { stream, valid: time, objects: &input }], &[])
                .unwrap();
            assert!(output.warnings.is_empty(), "{:?}", output.warnings);
            let objects = engine.snapshot(ty).unwrap();
            let Some(emitted) = by_stream.get(link).and_then(|s| s.get(&time)) else {
                // The run may end between the tracker's last frame and the links' outputs.
                break;
            };
            assert_eq!(**emitted, objects.to_json(), "{link} at {time}");
            let changes = output.changes_value().to_json();
            match by_stream.get(format!("{link}.changes").as_str()).and_then(|s| s.get(&time)) {
                Some(recorded) => assert_eq!(**recorded, changes, "{link}.changes at {time}"),
                None => {
                    assert_eq!(changes, serde_json::json!([]), "{link} changed at {time}, emitted nothing")
                }
            }
            compared += 1;
            input = objects;
        }
        all_at_once
            .step(time, &[Snapshot { source: "percepts", ty: "VisionPercept", objects: &percepts }])
            .unwrap();
        assert_eq!(all_at_once.describe(), engine.describe(), "at {time}");
        assert_eq!(all_at_once.world_model(), engine.world_model(), "at {time}");
        if let Some(world) = by_stream.get("world").and_then(|s| s.get(&time)) {
            assert_eq!(**world, engine.world_model().to_json(), "world model at {time}");
        }
        cars = engine.snapshot("Car").map_or(0, |c| match c {
            Value::List(items) => items.len(),
            _ => 0,
        });
    }
    assert!(compared >= 3 * (frames - 2), "compared {compared} of {} samples", 3 * frames);
    assert!(cars >= 2, "only {cars} cars at the end");
    assert!(by_stream.contains_key("world"));
    let _ = std::fs::remove_dir_all(&out_dir);
}

/// A running system asks for objects by description through `anchor.identify`: here the
/// requests are replayed from a file (they could as well come from `zenoh.subscribe`). A good
/// request is answered with the partial object's symbol and completed by the link processes
/// (`identified` with its name on a change stream); a refused one is answered with the reason,
/// counted as an error of the unit, and the run goes on.
#[test]
fn a_running_system_asks_for_a_car_by_description() {
    let registry = registry();
    let bridge = std::fs::read_to_string(specs_dir().join("bridge.kpl")).unwrap();
    let out_dir = fresh_dir("identify");
    let requests = [
        (5_000_000, "eastbound", "Car", "this.vel.x > 5.0"),
        (6_000_000, "truck", "Truck", "true"),
        (7_000_000, "eastbound", "Car", "this.vel.x > 0.0"),
        (8_000_000, "typo", "Car", "this.speeed > 1.0"),
    ];
    let lines: Vec<String> = requests
        .iter()
        .map(|(t, name, ty, description)| {
            serde_json::json!({"stream": "requests", "valid": t, "value": {"name": name, "type": ty, "description": description}})
                .to_string()
        })
        .collect();
    let requests_path = out_dir.join("requests.jsonl");
    std::fs::write(&requests_path, lines.join("\n") + "\n").unwrap();
    let text = format!(
        "{bridge}\ntype IdentifyRequest {{ name: string, type: string, description: string }}\n\
         source requests : IdentifyRequest = file.jsonl(path: {path:?})\n\
         compute answers = anchor.identify(requests)\n\
         sink everything = file.jsonl(answers, vision_world.changes, world_onroad.changes, onroad_car.changes, path: \"all.jsonl\")\n",
        path = requests_path.to_string_lossy()
    );
    let spec = check(&text, &registry);
    let report = run_bridge(&spec, &registry, &out_dir, 30_000_000);

    let samples = read_samples(&out_dir.join("all.jsonl"));
    let answers: Vec<&serde_json::Value> =
        samples.iter().filter(|(s, _, _)| s == "answers").map(|(_, _, v)| v).collect();
    assert_eq!(answers.len(), 4, "{answers:?}");
    assert_eq!(answers[0]["accepted"], true, "{}", answers[0]);
    let symbol = answers[0]["symbol"].as_str().unwrap();
    assert!(symbol.starts_with("co"), "{symbol}");
    for (answer, reason) in answers[1..].iter().zip(["not declared", "already in use", "does not compile"]) {
        assert_eq!(answer["accepted"], false, "{answer}");
        assert!(answer["error"].as_str().unwrap().contains(reason), "{answer}");
    }
    // Checked as the spec's `identify` items are: a misspelt attribute is named, with the type's.
    let typo = answers[3]["error"].as_str().unwrap();
    assert!(typo.contains("`Car` has no attribute `speeed`") && typo.contains("lane_offset"), "{typo}");
    // The request was completed: `identified` with its name, at or after the request.
    let changes: Vec<(Time, &serde_json::Value)> = samples
        .iter()
        .filter(|(s, _, _)| s.ends_with(".changes"))
        .flat_map(|(_, t, v)| v.as_array().unwrap().iter().map(move |c| (*t, c)))
        .collect();
    let created = changes
        .iter()
        .find(|(_, c)| c["kind"] == "created" && c["name"] == "eastbound")
        .expect("the partial object's creation is reported");
    assert_eq!(created.1["symbol"], symbol);
    assert!(created.0 >= 5_000_000);
    let identified = changes
        .iter()
        .find(|(_, c)| c["kind"] == "identified" && c["name"] == "eastbound")
        .unwrap_or_else(|| panic!("`eastbound` never identified: {changes:?}"));
    assert!(identified.0 >= created.0);
    assert!(!changes.iter().any(|(_, c)| c["name"] == "truck" || c["name"] == "typo"));
    // The refusals are counted and reported as errors of the unit; the run went on to the end.
    let unit = report.summary.processes.iter().find(|p| p.process == "answers").unwrap();
    assert_eq!(unit.errors, 3, "{unit:?}");
    assert!(unit.error_examples.iter().any(|e| e.contains("`truck` refused")), "{unit:?}");
    assert!(matches!(report.ending, Ending::DurationReached | Ending::SourcesEnded), "{:?}", report.ending);
    let _ = std::fs::remove_dir_all(&out_dir);
}
