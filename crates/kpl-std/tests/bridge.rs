//! `specs/traffic/bridge.kpl` with the simulated tracker (noise, missed detections, false
//! positives): every car that passes under the bridge loses its percept there for about 2 s and
//! comes out with a new percept id, and keeps its world object, on-road object and car symbols
//! across the gap. The ground truth of the simulator says which car each percept shows.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use kpl_core::Time;
use kpl_sim::{CarId, PerceptSource};
use kpl_std::driver::{IdentityScore, SimDriver};

const TYPES: [&str; 3] = ["WorldObject", "OnRoadObject", "Car"];

/// A percept and the symbols anchored to it: (type, symbol) from the world object up.
type Anchored = (String, Vec<(Arc<str>, Arc<str>)>);

/// One car's passage under the bridge.
#[derive(Debug, Default, Clone)]
struct Passage {
    /// The car's percept and its anchored symbols at its last detection before the bridge.
    before: Option<Anchored>,
    hidden_from: Option<Time>,
    hidden_until: Option<Time>,
    /// The same after the bridge, at the first detection whose structure is complete again.
    after: Option<Anchored>,
}

fn spec_with_seed(seed: u64) -> kpl_semantic::hir::Spec {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../specs/traffic/bridge.kpl");
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.contains("seed: 7,"));
    let text = text.replace("seed: 7,", &format!("seed: {seed},"));
    kpl_std::check_text(&text).unwrap()
}

#[test]
fn cars_keep_their_symbols_under_the_bridge() {
    check_seed(7);
}

/// The same spec with other seeds: every passage keeps its symbols.
#[test]
fn other_seeds_keep_symbols_too() {
    for seed in (1..=12).filter(|s| *s != 7) {
        check_seed(seed);
    }
}

fn check_seed(seed: u64) {
    let mut driver = SimDriver::from_spec(&spec_with_seed(seed), Default::default()).unwrap();
    let network = driver.sources[0].sim.network().clone();
    let mut passages: BTreeMap<CarId, Vec<Passage>> = BTreeMap::new();
    let mut score = IdentityScore::default();
    let mut warnings = 0;
    driver
        .run_until(120_000_000, |step| {
            warnings += step.output.warnings.len();
            score.record(&step);
            let (_, frame) = step.frames[0];
            let seen: BTreeMap<CarId, String> = frame
                .percepts
                .iter()
                .filter_map(|p| match p.source {
                    PerceptSource::Car(car) => Some((car, p.id.to_string())),
                    PerceptSource::FalsePositive => None,
                })
                .collect();
            for car in &frame.cars {
                let hidden = network.occluders().hiding(car.pos, car.road()).is_some();
                let list = passages.entry(car.id).or_default();
                if hidden {
                    match list.last_mut() {
                        Some(p) if p.hidden_from.is_none() => p.hidden_from = Some(step.time),
                        Some(p) if p.hidden_until.is_none() => {}
                        _ => list.push(Passage { hidden_from: Some(step.time), ..Passage::default() }),
                    }
                    continue;
                }
                if let Some(open) =
                    list.last_mut().filter(|p| p.hidden_until.is_none() && p.hidden_from.is_some())
                {
                    open.hidden_until = Some(step.time);
                }
                let Some(percept) = seen.get(&car.id) else { continue };
                let chain = step.engine.chain(percept);
                match list.last_mut() {
                    // Before any bridge, or after the last one completed: remember as "before".
                    None => {
                        list.push(Passage { before: Some((percept.clone(), chain)), ..Passage::default() })
                    }
                    Some(p) if p.hidden_from.is_none() => p.before = Some((percept.clone(), chain)),
                    Some(p) => {
                        let complete = chain.len() == TYPES.len();
                        let recent = p.hidden_until.is_some_and(|t| step.time - t <= 1_500_000);
                        if p.after.is_none() && complete && recent {
                            p.after = Some((percept.clone(), chain.clone()));
                        }
                        if p.after.is_some() && !recent {
                            // The next passage starts from here.
                            list.push(Passage {
                                before: Some((percept.clone(), chain)),
                                ..Passage::default()
                            });
                        }
                    }
                }
            }
        })
        .unwrap();
    assert_eq!(warnings, 0);

    let mut checked = 0;
    for (car, list) in &passages {
        for p in list {
            let (Some((vp_before, before)), Some(from), Some(until)) =
                (&p.before, p.hidden_from, p.hidden_until)
            else {
                continue;
            };
            // Only cars that were fully anchored (up to a car) when they went under the bridge.
            if before.len() != TYPES.len() {
                continue;
            }
            let gap = until - from;
            assert!((1_500_000..=2_600_000).contains(&gap), "{car:?} hidden for {gap} us");
            let (vp_after, after) = p.after.as_ref().unwrap_or_else(|| {
                panic!(
                    "{car:?} ({vp_before}: {before:?}) was not anchored again within 1.5 s after the bridge"
                )
            });
            assert_ne!(vp_before, vp_after, "the tracker gives a new percept id after the bridge");
            assert_eq!(
                before, after,
                "seed {seed}, {car:?}: {vp_before} before the bridge, {vp_after} after"
            );
            checked += 1;
        }
    }
    assert!(checked >= 4, "seed {seed}: only {checked} passages under the bridge were checked");

    // Over the whole run, the world object, on-road object and car of each car never change.
    for ty in TYPES {
        assert_eq!(score.switches(ty), 0, "seed {seed}: {ty} symbols switched: {:?}", score.symbols);
    }
}

/// Over 12 seeds, a link whose maintain condition failed is not made again between the same
/// two objects (by reestablish) right after: the conditions say "detected on a road"
/// (`from.measured`), so a predicted world object neither keeps nor regains an on-road object.
#[test]
fn no_maintain_failure_is_undone_by_a_reestablish_of_the_same_pair() {
    let mut failures = 0;
    for seed in 1..=12 {
        let mut driver = SimDriver::from_spec(&spec_with_seed(seed), Default::default()).unwrap();
        let mut unlinked: BTreeMap<(String, String, String), Time> = BTreeMap::new();
        let mut undone = Vec::new();
        driver
            .run_until(120_000_000, |step| {
                for c in &step.output.changes {
                    let (Some(link), Some(from)) = (&c.link, &c.from) else { continue };
                    let pair = (link.to_string(), from.to_string(), c.symbol.to_string());
                    match (c.kind, c.cause) {
                        (kpl_anchor::ChangeKind::Unlinked, kpl_anchor::Cause::Maintain) => {
                            failures += 1;
                            unlinked.insert(pair, c.time);
                        }
                        (kpl_anchor::ChangeKind::Linked, kpl_anchor::Cause::Reestablish) => {
                            if let Some(at) = unlinked.get(&pair) {
                                undone.push((pair, *at, c.time));
                            }
                        }
                        _ => {}
                    }
                }
            })
            .unwrap();
        assert!(undone.is_empty(), "seed {seed}: maintain failures undone by reestablish: {undone:?}");
    }
    eprintln!("{failures} maintain failures over 12 seeds, none undone");
}
