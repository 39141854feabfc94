//! Anchoring on the stream runtime, as `kpl run specs/traffic/bridge.kpl` runs it: the spec checks
//! against the runtime's registry (built-ins, `kpl-std`, anchoring), runs with simulated time, and
//! every sample its link processes emitted (the objects of each link's type and its changes) is
//! what the pure engine computes from the same tracker snapshots, recorded in the same run.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use kpl_anchor::{AnchorConfig, Anchoring, Snapshot};
use kpl_core::{Time, Value};
use kpl_runtime::{Ending, RunConfig};

fn registry() -> kpl_runtime::Registry {
    // Built-ins, kpl-std and kpl_anchor::runtime::register, as the `kpl` command builds it.
    kpl_anchor::registry::runtime_registry()
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
    let out_dir = std::env::temp_dir().join(format!("kpl-anchor-runtime-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out_dir);
    let config = RunConfig {
        duration: Some(40_000_000),
        seed: 3,
        out_dir: out_dir.clone(),
        spec_dir: specs_dir(),
        spec_name: "bridge".into(),
        ..RunConfig::default()
    };
    let report = kpl_runtime::run(&spec, &registry, &config, None).unwrap();
    assert!(report.failures.is_empty(), "{:?}", report.failures);
    assert!(matches!(report.ending, Ending::DurationReached | Ending::SourcesEnded), "{:?}", report.ending);

    let samples = read_samples(&out_dir.join("all.jsonl"));
    let mut by_stream: BTreeMap<&str, BTreeMap<Time, &serde_json::Value>> = BTreeMap::new();
    for (stream, valid, value) in &samples {
        let previous = by_stream.entry(stream).or_default().insert(*valid, value);
        assert!(previous.is_none(), "two samples of {stream} at {valid}");
    }
    let frames = by_stream["tracker"].len();
    assert!(frames >= 390, "{frames} tracker frames");

    // The same snapshots through the pure engine give the same outputs at every time.
    let mut engine = Anchoring::from_spec(&spec, AnchorConfig::default()).unwrap();
    let link_types =
        [("vision_world", "WorldObject"), ("world_onroad", "OnRoadObject"), ("onroad_car", "Car")];
    let percepts_type = kpl_core::ValueType::List(Box::new(kpl_core::ValueType::Record(
        spec.types.get("VisionPercept").unwrap().clone(),
    )));
    let mut compared = 0;
    let mut cars = 0;
    for (&time, value) in &by_stream["tracker"] {
        let objects = Value::from_json(value, &percepts_type).unwrap();
        let output = engine
            .step(time, &[Snapshot { source: "percepts", ty: "VisionPercept", objects: &objects }])
            .unwrap();
        assert!(output.warnings.is_empty(), "{:?}", output.warnings);
        for (link, ty) in link_types {
            let Some(emitted) = by_stream.get(link).and_then(|s| s.get(&time)) else {
                // The run may end between the tracker's last frame and the links' outputs.
                continue;
            };
            assert_eq!(**emitted, engine.snapshot(ty).unwrap().to_json(), "{link} at {time}");
            let changes: Vec<serde_json::Value> = output
                .changes
                .iter()
                .filter(|c| engine.link_of_change(c) == Some(link))
                .map(|c| c.to_value().to_json())
                .collect();
            let recorded = by_stream.get(format!("{link}.changes").as_str()).and_then(|s| s.get(&time));
            match recorded {
                Some(recorded) => {
                    assert_eq!(**recorded, serde_json::Value::Array(changes), "{link}.changes at {time}")
                }
                None => {
                    assert!(changes.is_empty(), "{link} changed at {time} but emitted nothing: {changes:?}")
                }
            }
            compared += 1;
        }
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
