//! Runs a built-in scenario and draws it: ground-truth tracks as lines, percepts as dots (false
//! positives in grey).
//!
//! `cargo run -p kpl-sim --example render -- SCENARIO SECONDS OUT.svg` (e.g. `bridge 30 bridge.svg`)
#![allow(clippy::print_stderr, reason = "an example's usage message")]

use std::collections::BTreeMap;
use std::sync::Arc;

use kpl_roads::svg::{self, Layer};
use kpl_sim::{Params, PerceptSource, UavTrackerSim};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [scenario, seconds, out] = args.as_slice() else {
        eprintln!("usage: render SCENARIO SECONDS OUT.svg");
        std::process::exit(2);
    };
    let params = Params {
        scenario: scenario.clone(),
        grid_blocks_x: 3,
        grid_blocks_y: 3,
        n_cars: 6,
        false_positive_rate: 1.0,
        ..Params::default()
    };
    params.validate()?;
    let network = Arc::new(params.load_network()?);
    let mut sim = UavTrackerSim::new(&params, network.clone(), 0)?;
    let frames = sim.frames_until((seconds.parse::<f64>()? * 1e6) as i64);
    let mut truth: BTreeMap<_, Vec<[f64; 2]>> = BTreeMap::new();
    let mut percepts = Vec::new();
    let mut false_positives = Vec::new();
    for frame in &frames {
        for car in &frame.cars {
            truth.entry(car.id).or_default().push(car.pos);
        }
        for p in &frame.percepts {
            match p.source {
                PerceptSource::Car(_) => percepts.push(p.pos),
                PerceptSource::FalsePositive => false_positives.push(p.pos),
            }
        }
    }
    let layers = [
        Layer::line("ground truth", "#1f77b4", truth.into_values().collect()),
        Layer::dots("percepts", "#d62728", vec![percepts]),
        Layer::dots("false positives", "#555555", vec![false_positives]),
    ];
    std::fs::write(out, svg::render(&network, &layers, &svg::SvgOptions::default()))?;
    Ok(())
}
