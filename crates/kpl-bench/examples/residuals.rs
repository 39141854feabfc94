//! Prints the residual of a Timescales property after each state of its trace, to see what the
//! progressor keeps: `cargo run -p kpl-bench --example residuals -- AbsentBR 10 40`.

#![allow(clippy::print_stdout, clippy::unwrap_used, clippy::expect_used)] // a developer tool

use std::sync::Arc;

use kpl_bench::timescales::Property;
use kpl_core::{TimeUnit, Value};
use kpl_mtl::{Context, Formula, Progressor, SlotState};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).map_or("AbsentBR", String::as_str);
    let bound: i64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(10);
    let states: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(40);
    let property = Property::ALL.into_iter().find(|p| p.name() == name).expect("a Timescales property name");
    let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
    let formula = Arc::new(Formula::new(&property.formula(bound, &mut ctx), &ctx).unwrap());
    println!("{formula}");
    let mut progressor = Progressor::new(formula);
    for (t, row) in property.trace(bound, states, 1, false).iter().take(states).enumerate() {
        let state = SlotState::new(row.iter().map(|b| Some(Value::Bool(*b))).collect());
        progressor.step(t as i64, &state).unwrap();
        println!("{t:>4} {row:?} [{}] {}", progressor.residual_size(), progressor.residual());
    }
}
