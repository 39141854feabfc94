//! `kpl situations` end to end on recorded SUMO traffic (the `overtake`, `motorway` and `wrong_way`
//! scenarios of scripts/sumo-scenarios.py): `specs/traffic/sumo_situations.kpl`,
//! `sumo_situations_motorway.kpl` and `sumo_wrong_way.kpl` run under the noisy tracker with
//! occluders, their situations are scored against the true ones computed from SUMO's own
//! trajectories, and the targets hold (precision and recall >= 0.9 for overtakes and speeding, on
//! two seeds of the first); both wrong-way drivers are found; on traffic not made for the specs
//! (the `tls_grid` and `spider` scenarios) no overtake at standstill and speeding a little over
//! the threshold found (issue 24); every situation names cars and a time interval; bad input gets
//! clear errors and exit codes.
#![allow(clippy::unwrap_used, clippy::expect_used, reason = "tests")]

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Mutex;

use serde_json::Value;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

fn kpl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_kpl")).args(args).current_dir(workspace()).output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A spec run once per seed over its whole recording; its output folder.
fn situations_run(spec: &str, seed: u32) -> PathBuf {
    static RUNS: Mutex<BTreeMap<(String, u32), PathBuf>> = Mutex::new(BTreeMap::new());
    let key = (spec.to_string(), seed);
    if let Some(dir) = RUNS.lock().unwrap().get(&key) {
        return dir.clone();
    }
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("kpl-situations-cli-{}-{spec}-{seed}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let spec_file = format!("specs/traffic/{spec}.kpl");
    let seed_text = seed.to_string();
    let out = kpl(&[
        "run",
        "--quiet",
        &spec_file,
        "--clock",
        "sim",
        "--seed",
        &seed_text,
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let run = dir.join(spec);
    RUNS.lock().unwrap().insert(key, run.clone());
    run
}

/// `kpl situations` on a run of `spec` over the scenario folder `scenario`.
fn score(spec: &str, seed: u32, scenario: &str, extra: &[&str]) -> Output {
    let run = situations_run(spec, seed).to_str().unwrap().to_string();
    let traffic = format!("{scenario}/fcd.xml.gz");
    let network = format!("{scenario}/net.xml.gz");
    let vtypes = format!("{scenario}/vtypes.xml");
    let mut args =
        vec!["situations", &run, "--traffic", &traffic, "--network", &network, "--vtypes", &vtypes];
    args.extend_from_slice(extra);
    kpl(&args)
}

fn json_scores(spec: &str, seed: u32, scenario: &str) -> Value {
    let out = score(spec, seed, scenario, &["--format", "json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    serde_json::from_slice(&out.stdout).unwrap()
}

fn kind<'a>(json: &'a Value, kind: &str) -> Option<&'a Value> {
    json["scores"].as_array().unwrap().iter().find(|s| s["kind"] == kind)
}

/// Precision and recall of `kinds` are at least 0.9, over at least `least_truth` true situations.
fn assert_targets(json: &Value, kinds: &[&str], least_truth: u64, what: &str) {
    for k in kinds {
        let s = kind(json, k).unwrap_or_else(|| panic!("{what}: no {k}"));
        let (p, r) = (s["precision"].as_f64().unwrap(), s["recall"].as_f64().unwrap());
        assert!(p >= 0.9 && r >= 0.9, "{what}, {k}: precision {p}, recall {r}: {s}");
        assert!(s["truth"].as_u64().unwrap() >= least_truth, "{what}, {k}: too few true situations: {s}");
    }
    for r in json["recognised"].as_array().unwrap() {
        assert!(r["start"].as_i64().unwrap() <= r["end"].as_i64().unwrap(), "{r}");
        for o in r["objects"].as_array().unwrap() {
            assert!(o.as_str().unwrap().starts_with("co"), "{r}");
        }
    }
}

const OVERTAKE: &str = "specs/traffic/sumo/overtake";
const MOTORWAY: &str = "specs/traffic/sumo/motorway";
const WRONG_WAY: &str = "specs/traffic/sumo/wrong_way";

#[test]
fn overtakes_and_speeding_are_recognised_with_precision_and_recall_over_0_9() {
    // The spec's own seed, and one its formulas were not looked at with.
    for seed in [0, 5] {
        let json = json_scores("sumo_situations", seed, OVERTAKE);
        assert_targets(&json, &["overtake", "speeding"], 10, &format!("overtake scenario, seed {seed}"));
        // The broken-down car is found, and nothing on the road drives the wrong way.
        assert_eq!(kind(&json, "stopped").unwrap()["found"], 1, "seed {seed}");
        assert!(kind(&json, "wrong_way").is_none(), "seed {seed}");
    }
    // The table says the same.
    let table = score("sumo_situations", 0, OVERTAKE, &[]);
    assert!(table.status.success());
    let text = String::from_utf8_lossy(&table.stdout);
    assert!(text.lines().any(|l| l.starts_with("overtake")), "{text}");
    assert!(text.lines().any(|l| l.starts_with("speeding")), "{text}");

    // A recording with overtakes alone (a spec with no speeding monitor, and no summary.json
    // beside it) is not scored as a speeding recall of 0: the kind is named under the table.
    let run = situations_run("sumo_situations", 0);
    let only = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("kpl-situations-cli-{}-only-overtakes", std::process::id()));
    let _ = std::fs::remove_dir_all(&only);
    std::fs::create_dir_all(&only).unwrap();
    let lines: String = std::fs::read_to_string(run.join("situations.jsonl"))
        .unwrap()
        .lines()
        .filter(|l| l.contains("\"stream\":\"overtake\""))
        .map(|l| format!("{l}\n"))
        .collect();
    assert!(!lines.is_empty());
    std::fs::write(only.join("situations.jsonl"), lines).unwrap();
    std::fs::copy(run.join("tracks.jsonl"), only.join("tracks.jsonl")).unwrap();
    let traffic = format!("{OVERTAKE}/fcd.xml.gz");
    let out = kpl(&["situations", only.to_str().unwrap(), "--traffic", &traffic]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.lines().any(|l| l.starts_with("overtake")), "{text}");
    assert!(!text.lines().any(|l| l.starts_with("speeding")), "{text}");
    let note = text.lines().find(|l| l.starts_with("not recognised in this recording")).unwrap_or_default();
    assert!(note.contains("speeding (") && note.contains("no summary.json"), "{text}");
}

#[test]
fn overtakes_and_speeding_on_three_lanes_with_another_traffic_mix() {
    let json = json_scores("sumo_situations_motorway", 0, MOTORWAY);
    assert_targets(&json, &["overtake", "speeding"], 10, "motorway scenario");
    // Three lanes: some overtakes pass two lanes over.
    assert!(kind(&json, "overtake").unwrap()["truth"].as_u64().unwrap() >= 100);
}

const TLS_GRID: &str = "specs/traffic/sumo/tls_grid";
const SPIDER: &str = "specs/traffic/sumo/spider";

/// The sums of `field` of the score of `kind_name` over runs of `spec` with `seeds`.
fn summed(
    spec: &str,
    scenario: &str,
    seeds: &[u32],
    kind_name: &str,
    extra: &[&str],
) -> BTreeMap<&'static str, u64> {
    let mut sums = BTreeMap::new();
    for &seed in seeds {
        let mut args = vec!["--format", "json"];
        args.extend_from_slice(extra);
        let out = score(spec, seed, scenario, &args);
        assert!(out.status.success(), "{}", stderr(&out));
        let json: Value = serde_json::from_slice(&out.stdout).unwrap();
        let s = kind(&json, kind_name).unwrap_or_else(|| panic!("{spec}, seed {seed}: no {kind_name}"));
        for field in ["recognised", "correct", "truth", "found"] {
            *sums.entry(field).or_insert(0) += s[field].as_u64().unwrap();
        }
    }
    sums
}

/// Issue 24: on a grid with traffic lights (traffic not made for the spec), two cars standing side
/// by side at a red light, or creeping in a queue, swap their measured order by the tracker's
/// noise; that is no overtake. The monitor of main before the fix was right 2 to 3 times in 10
/// here (the cars' measured order flickers); it must be right at least 8 times in 10 and still
/// find most true overtakes.
#[test]
fn no_overtake_at_standstill_on_a_grid_with_traffic_lights() {
    let sums = summed("sumo_situations_tls_grid", TLS_GRID, &[1, 2], "overtake", &[]);
    let precision = sums["correct"] as f64 / sums["recognised"] as f64;
    let recall = sums["found"] as f64 / sums["truth"] as f64;
    assert!(sums["truth"] >= 10, "{sums:?}");
    assert!(precision >= 0.8 && recall >= 0.6, "precision {precision}, recall {recall}: {sums:?}");
}

/// Issue 24: speeding on the spider network (traffic not made for the spec). With one frame's
/// noisy speed over the threshold for the whole window, main found 68 to 76 % of the speeding
/// episodes (53 of 75 over three tracker seeds); with the Kalman filter's speed the monitors find
/// at least 85 % of them, every vehicle more than 0.5 m/s over for 5 s at least 90 % of the time,
/// and precision stays at least 0.95.
#[test]
fn speeding_a_little_over_the_threshold_is_found() {
    let seeds = [1, 2, 7];
    let all = summed("sumo_situations_spider", SPIDER, &seeds, "speeding", &[]);
    let precision = all["correct"] as f64 / all["recognised"] as f64;
    let recall = all["found"] as f64 / all["truth"] as f64;
    assert!(all["truth"] >= 30, "{all:?}");
    assert!(precision >= 0.95 && recall >= 0.85, "precision {precision}, recall {recall}: {all:?}");
    let clear = summed(
        "sumo_situations_spider",
        SPIDER,
        &seeds,
        "speeding",
        &["--speeding-margin", "3.5", "--speeding-min", "5"],
    );
    let clear_recall = clear["found"] as f64 / clear["truth"] as f64;
    assert!(clear["truth"] >= 20 && clear_recall >= 0.9, "recall {clear_recall}: {clear:?}");
}

/// Issue 24: cars IDF1 >= 0.98 on the spider network, where half the routes end inside the map
/// (0.946 with sumo_situations.kpl's waits and a second before a vanished car is given up; the
/// spec's shorter waits, docs/anchoring.md "Forgetting"), on two tracker seeds: `--seed 7` is the
/// one where giving up percepts after 300 ms instead of 400 made an identity switch (0.972).
#[test]
fn cars_keep_their_identity_where_half_the_routes_end_inside_the_map() {
    for seed in [7, 1] {
        let run = situations_run("sumo_situations_spider", seed);
        let out = kpl(&["score", run.to_str().unwrap(), "--stream", "onroad_car", "--format", "json"]);
        assert!(out.status.success(), "{}", stderr(&out));
        let json: Value = serde_json::from_slice(&out.stdout).unwrap();
        let identity = &json["streams"][0]["identity"];
        let idf1 = identity["idf1"].as_f64().unwrap();
        eprintln!("spider, tracker seed {seed}: cars {identity}");
        assert!(idf1 >= 0.98, "tracker seed {seed}: cars IDF1 {idf1}: {identity}");
    }
}

#[test]
fn wrong_way_drivers_are_recognised_and_overtake_nobody() {
    let json = json_scores("sumo_wrong_way", 0, WRONG_WAY);
    let wrong = kind(&json, "wrong_way").expect("wrong-way truth");
    // Two drivers against the lane, each found, and nothing else reported driving the wrong way.
    assert_eq!((wrong["truth"].as_u64(), wrong["found"].as_u64()), (Some(2), Some(2)), "{wrong}");
    assert_eq!(wrong["precision"].as_f64(), Some(1.0), "{wrong}");
    let ghosts: BTreeSet<&str> = json["recognised"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["kind"] == "wrong_way")
        .flat_map(|r| r["truth_objects"].as_array().unwrap().iter().filter_map(Value::as_str))
        .collect();
    assert_eq!(ghosts, BTreeSet::from(["ghost.0", "ghost.1"]));
    // A wrong-way driver meeting a car is not an overtake, in the truth or recognised.
    assert!(json["truth"].as_array().unwrap().iter().all(|t| t["kind"] != "overtake"
        || t["objects"].as_array().unwrap().iter().all(|o| !o.as_str().unwrap().starts_with("ghost"))));
    assert_targets(&json, &["overtake"], 10, "wrong-way scenario");
    assert!(json["recognised"].as_array().unwrap().iter().all(|r| {
        r["kind"] != "overtake"
            || r["truth_objects"]
                .as_array()
                .unwrap()
                .iter()
                .all(|o| !o.as_str().unwrap_or("").starts_with("ghost"))
    }));
}

#[test]
fn bad_input_gets_clear_errors() {
    let run = situations_run("sumo_situations", 0).to_str().unwrap().to_string();
    // Floating car data without positions along lanes (the highway scenario's) cannot give truth
    // (its network and vehicle types are found beside it).
    let out = kpl(&["situations", &run, "--traffic", "specs/traffic/sumo/highway/fcd.xml.gz"]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("lane,pos"), "{}", stderr(&out));
    // A missing file is an I/O error.
    let out =
        kpl(&["situations", &run, "--traffic", "nope.xml", "--network", &format!("{OVERTAKE}/net.xml.gz")]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("nope.xml"), "{}", stderr(&out));
    // ... also without --network: the traffic file is named, not the network it would be beside.
    let out = kpl(&["situations", &run, "--traffic", "/nonexistent/fcd.xml.gz"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("/nonexistent/fcd.xml.gz: no such traffic file"), "{}", stderr(&out));
    // A traffic file with no network beside it: where it was looked for, and the option.
    let lone = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("kpl-lone-fcd-{}", std::process::id()));
    std::fs::create_dir_all(&lone).unwrap();
    std::fs::copy(workspace().join(OVERTAKE).join("fcd.xml.gz"), lone.join("fcd.xml.gz")).unwrap();
    let out = kpl(&["situations", &run, "--traffic", lone.join("fcd.xml.gz").to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("net.xml.gz") && stderr(&out).contains("--network"), "{}", stderr(&out));
    std::fs::remove_dir_all(&lone).unwrap();
    // A car stream the recording does not have.
    let out = score("sumo_situations", 0, OVERTAKE, &["--stream", "no_such_stream"]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(stderr(&out).contains("no_such_stream"), "{}", stderr(&out));
}
