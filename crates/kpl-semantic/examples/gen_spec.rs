//! Prints a generated spec of about N lines (default 10,000), for timing `kpl check`:
//! `cargo run -p kpl-semantic --example gen_spec -- 10000 > /tmp/big.kpl && time kpl check /tmp/big.kpl`
#![allow(clippy::print_stdout)] // the example's output is the spec

#[path = "../benches/generate.rs"]
mod generate;

fn main() {
    let lines = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(10_000);
    print!("{}", generate::spec(lines));
}
