//! `kpl bench mtl`: the MTL engine on the ten timed properties of the Timescales benchmark
//! ([`crate::timescales`]), against R2U2 in the same process when `kpl` is built with the `r2u2`
//! feature (`cargo build --release -p kpl --features r2u2`; docs/performance.md), and DyKnow's link
//! conditions progressed per pair against one shared group.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use kpl_core::{Time, TimeUnit, Value};
use kpl_mtl::{Context, EngineConfig, Formula, InstanceId, Progressor, ProgressorGroup, State};

use crate::BenchError;
use crate::clock::CpuClock;
use crate::timescales::{Property, TimescalesState};

#[derive(Debug, clap::Args)]
#[command(
    after_help = "Examples:\n  kpl bench mtl\n  kpl bench mtl --states 100000 --bounds 10,1000\n  kpl bench mtl --r2u2-cli /tmp/r2u2/bin/r2u2_cli --properties RecurGLB,AbsentBR"
)]
pub struct Args {
    /// States per trace.
    #[arg(long, default_value_t = 1_000_000)]
    states: usize,
    /// Upper bounds of the properties' intervals, in time units (one state per time unit).
    #[arg(long, value_delimiter = ',', default_values_t = [10, 100, 1000, 10000])]
    bounds: Vec<Time>,
    /// Properties to run (default: all ten).
    #[arg(long, value_delimiter = ',')]
    properties: Vec<String>,
    /// Timed pairs per case: the engine and R2U2 run one after the other this many times.
    #[arg(long, default_value_t = 5)]
    repeat: usize,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The `r2u2_cli` program, used to compile R2U2 specifications with C2PO. Without it the R2U2
    /// columns are left empty.
    #[arg(long)]
    r2u2_cli: Option<PathBuf>,
    /// Object pairs for the link-condition table (each condition progressed for every pair, once
    /// by independent progressors and once by one group); 0 skips it.
    #[arg(long, default_value_t = 10_000)]
    links: usize,
}

/// A state of a Timescales trace, as the engine reads it.
struct Row<'a>(&'a TimescalesState);

static BOOLS: [Value; 2] = [Value::Bool(false), Value::Bool(true)];

impl State for Row<'_> {
    fn value(&self, slot: kpl_mtl::SlotId) -> Option<&Value> {
        self.0.get(slot as usize).map(|b| &BOOLS[usize::from(*b)])
    }
}

/// One timed run of a `Progressor` over the trace: seconds and verdict.
fn time_engine(
    formula: &Arc<Formula>,
    trace: &[TimescalesState],
    config: EngineConfig,
) -> (f64, Option<bool>) {
    let mut progressor = Progressor::with_config(formula.clone(), config);
    let clock = CpuClock::start();
    for (t, row) in trace.iter().enumerate() {
        if progressor.step(t as Time, &Row(row)).is_err() {
            break;
        }
    }
    let verdict = progressor.finish();
    (clock.seconds(), verdict)
}

/// The residual's mean and largest size and the share of steps the transition cache answered,
/// from an untimed run.
fn residual_profile(formula: &Arc<Formula>, trace: &[TimescalesState]) -> (f64, usize, f64) {
    let mut progressor = Progressor::new(formula.clone());
    let (mut sum, mut largest) = (0usize, 0usize);
    for (t, row) in trace.iter().enumerate() {
        if progressor.step(t as Time, &Row(row)).is_err() {
            break;
        }
        let size = progressor.residual_size();
        sum += size;
        largest = largest.max(size);
    }
    let stats = progressor.stats();
    let lookups = (stats.cache_hits + stats.cache_misses).max(1);
    (sum as f64 / trace.len().max(1) as f64, largest, stats.cache_hits as f64 / lookups as f64)
}

/// Median and range of some ratios.
fn spread(values: &mut [f64]) -> (f64, f64, f64) {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n == 0 {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let median = if n % 2 == 1 { values[n / 2] } else { (values[n / 2 - 1] + values[n / 2]) / 2.0 };
    (median, values[0], values[n - 1])
}

fn min(values: &[f64]) -> f64 {
    values.iter().copied().fold(f64::INFINITY, f64::min)
}

/// One row of the Timescales table.
struct Case {
    property: Property,
    bound: Time,
    states: usize,
    /// Best of the runs, ns per state, with and without the transition cache.
    kpl_ns: f64,
    no_cache_ns: f64,
    mean_residual: f64,
    largest_residual: usize,
    hit_rate: f64,
    verdict: Option<bool>,
    /// R2U2's best ns per state, the per-pair ratios (KPL throughput over R2U2's), or why not.
    r2u2: Result<(f64, Vec<f64>, String), String>,
}

fn run_case(args: &Args, property: Property, b: Time, scratch: &Path) -> Result<Case, String> {
    let trace = property.trace(b, args.states, args.seed, false);
    let mut context = Context::new(TimeUnit::Ms, TimeUnit::Ms);
    let mtl = property.formula(b, &mut context);
    let formula = Arc::new(Formula::new(&mtl, &context).map_err(|e| e.to_string())?);
    let spec = match (&args.r2u2_cli, r2u2::spec(property, b)) {
        _ if !r2u2::BUILT => Err("not built in (--features r2u2)".to_string()),
        (Some(cli), Some(spec)) => {
            r2u2::compile(cli, &spec, &scratch.join(format!("{}-{b}", property.name()))).map(Some)
        }
        (None, Some(_)) => Err("not run".to_string()),
        (_, None) => Err("not expressible".to_string()),
    };
    let n = trace.len() as f64;
    let (mut kpl, mut r2u2, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
    let mut verdict = None;
    let mut r2u2_note = String::new();
    let mut r2u2_error = None;
    // Paired runs: the engine, then R2U2 on the same trace, `repeat` times.
    for _ in 0..args.repeat.max(1) {
        let (seconds, v) = time_engine(&formula, &trace, EngineConfig::default());
        verdict = v;
        kpl.push(seconds);
        if let Ok(Some(spec)) = &spec {
            match r2u2::time(spec, &trace) {
                Ok(run) => {
                    ratios.push(run.seconds / seconds);
                    r2u2.push(run.seconds);
                    r2u2_note = if run.overflow {
                        " (queue overflow)".to_string()
                    } else if run.violations > 0 {
                        format!(" ({} false verdicts)", run.violations)
                    } else {
                        String::new()
                    };
                }
                Err(e) => r2u2_error = Some(e),
            }
        }
    }
    let (no_cache, _) =
        time_engine(&formula, &trace, EngineConfig { transition_cache: false, ..Default::default() });
    let (mean_residual, largest_residual, hit_rate) = residual_profile(&formula, &trace);
    let r2u2 = match (spec, r2u2_error) {
        (Err(why), _) => Err(why),
        (_, Some(e)) => Err(format!("R2U2 failed: {e}")),
        (Ok(_), None) => Ok((min(&r2u2) * 1e9 / n, ratios, r2u2_note)),
    };
    Ok(Case {
        property,
        bound: b,
        states: trace.len(),
        kpl_ns: min(&kpl) * 1e9 / n,
        no_cache_ns: no_cache * 1e9 / n,
        mean_residual,
        largest_residual,
        hit_rate,
        verdict,
        r2u2,
    })
}

/// Runs the benchmark and writes its tables to `out`.
pub fn run(args: &Args, out: &mut dyn Write) -> Result<(), BenchError> {
    let properties: Vec<Property> = if args.properties.is_empty() {
        Property::ALL.to_vec()
    } else {
        let mut out = Vec::new();
        for name in &args.properties {
            match Property::ALL.iter().find(|p| p.name().eq_ignore_ascii_case(name)) {
                Some(p) => out.push(*p),
                None => {
                    let names: Vec<&str> = Property::ALL.iter().map(|p| p.name()).collect();
                    return Err(BenchError::Failed(format!(
                        "unknown property `{name}` (known: {})",
                        names.join(", ")
                    )));
                }
            }
        }
        out
    };
    // R2U2's compiled specs; removed when dropped, however the run ends.
    let scratch = tempfile::Builder::new()
        .prefix("kpl-bench-r2u2-")
        .tempdir()
        .map_err(|e| BenchError::Failed(e.to_string()))?;
    writeln!(
        out,
        "Timescales properties, {} states per trace, {} pairs of runs; times are {}.\n",
        args.states,
        args.repeat.max(1),
        CpuClock::name()
    )?;
    writeln!(
        out,
        "| property | bound | states | kpl ns/state | without cache | residual nodes (mean / largest) | ns per state per node | cached steps | verdict | R2U2 ns/state | kpl / R2U2 (median [range]) |"
    )?;
    writeln!(out, "|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|")?;
    let mut flatness: Vec<(Property, f64, f64)> = Vec::new();
    let mut worst_ratio: Option<(f64, String)> = None;
    let mut worst_per_node: Option<(f64, String)> = None;
    for property in &properties {
        let mut first_ns = None;
        let mut last_ns = None;
        for &b in &args.bounds {
            let case = run_case(args, *property, b, scratch.path())
                .map_err(|e| BenchError::Failed(format!("{} bound {b}: {e}", property.name())))?;
            first_ns.get_or_insert(case.kpl_ns);
            last_ns = Some(case.kpl_ns);
            let verdict = match case.verdict {
                Some(true) => "holds",
                Some(false) => "VIOLATED",
                None => "error",
            };
            let name = format!("{} {}", case.property.name(), case.bound);
            let per_node = case.kpl_ns / case.mean_residual.max(1.0);
            if worst_per_node.as_ref().is_none_or(|(w, _)| per_node > *w) {
                worst_per_node = Some((per_node, name.clone()));
            }
            let (r2u2_ns, ratio) = match case.r2u2 {
                Ok((ns, mut ratios, note)) => {
                    let (median, lo, hi) = spread(&mut ratios);
                    if worst_ratio.as_ref().is_none_or(|(w, _)| median < *w) {
                        worst_ratio = Some((median, name));
                    }
                    (format!("{ns:.1}{note}"), format!("{median:.2} [{lo:.2} - {hi:.2}]"))
                }
                Err(why) => (why, "-".to_string()),
            };
            writeln!(
                out,
                "| {} | {} | {} | {:.1} | {:.1} | {:.1} / {} | {per_node:.1} | {:.1} % | {verdict} | {r2u2_ns} | {ratio} |",
                case.property.name(),
                case.bound,
                case.states,
                case.kpl_ns,
                case.no_cache_ns,
                case.mean_residual,
                case.largest_residual,
                case.hit_rate * 100.0,
            )?;
            out.flush()?;
        }
        if let (Some(first), Some(last)) = (first_ns, last_ns) {
            flatness.push((*property, first, last));
        }
    }
    if let Some((ratio, case)) = worst_ratio {
        writeln!(
            out,
            "\nLowest KPL / R2U2 (median of the pairs): {ratio:.2} ({case}; target: at least 1.5)."
        )?;
    }
    if let Some((ns, case)) = worst_per_node {
        writeln!(out, "Highest ns per state per residual node: {ns:.1} ({case}; target: at most 15).")?;
    }
    if let (Some(lo), Some(hi)) = (args.bounds.first(), args.bounds.last()) {
        writeln!(out, "\nCost per state, bound {hi} relative to bound {lo} (target: at most 2):\n")?;
        writeln!(out, "| property | ns/state at {lo} | ns/state at {hi} | ratio |")?;
        writeln!(out, "|---|---:|---:|---:|")?;
        for (property, first, last) in flatness {
            writeln!(out, "| {} | {first:.1} | {last:.1} | {:.2} |", property.name(), last / first)?;
        }
    }
    if args.links > 0 {
        bench_links(args.links, args.repeat, out)?;
    }
    Ok(())
}

/// The state of one link instance: the two objects bound to `from` and `to`.
struct PairState<'a> {
    from: &'a Value,
    to: &'a Value,
}

impl State for PairState<'_> {
    fn value(&self, slot: kpl_mtl::SlotId) -> Option<&Value> {
        match slot {
            0 => Some(self.from),
            1 => Some(self.to),
            _ => None,
        }
    }
}

/// The objects of the link benchmark at one step: object i moves along x at 10 m/s; its
/// partner is 4 m (even i) or 30 m away; it leaves the road (|y| >= 5) for 0.3 s every 1.7 s,
/// shifted by i.
fn link_objects(links: usize, step: usize, partner: bool) -> Vec<Value> {
    (0..links)
        .map(|i| {
            let offset = if !partner {
                0.0
            } else if i % 2 == 0 {
                4.0
            } else {
                30.0
            };
            let x = i as f64 * 50.0 + step as f64 + offset;
            let off_road = (step + i) % 17 < 3;
            let y = if off_road { 8.0 } else { 1.0 };
            let fields = vec![(Arc::from("pos"), Value::vec2(x, y))];
            Value::Record(Arc::new(kpl_core::Record { id: None, fields }))
        })
        .collect()
}

fn link_formula(text: &str) -> Result<Arc<Formula>, String> {
    let mut context = Context::new(TimeUnit::Us, TimeUnit::Ms);
    context.declare_value("from");
    context.declare_value("to");
    context.register_function(kpl_mtl::Function::new("on_road", (1, Some(1)), |args| match &args[0] {
        Value::Vec2([_, y]) => Ok(Value::Bool(y.abs() < 5.0)),
        other => Err(format!("expected a position, found {}", other.kind())),
    }));
    let expr = kpl_syntax::parse_formula(text).map_err(|_| format!("`{text}` does not parse"))?;
    Formula::from_ast(&expr, &mut context).map(Arc::new).map_err(|e| format!("{e:?}"))
}

/// What one way of progressing the link conditions did: seconds, decisions, and residual nodes
/// held at the end (distinct nodes: shared ones count once).
struct LinkRun {
    seconds: f64,
    decisions: usize,
    nodes: usize,
}

const LINK_STEPS: usize = 100;
const LINK_DT: Time = 100_000;

/// One progressor per pair.
fn links_independent(
    formula: &Arc<Formula>,
    from: &[Vec<Value>],
    to: &[Vec<Value>],
) -> Result<LinkRun, String> {
    let links = from[0].len();
    let mut progressors: Vec<Progressor> = (0..links).map(|_| Progressor::new(formula.clone())).collect();
    let mut decisions = 0;
    let clock = CpuClock::start();
    for step in 0..LINK_STEPS {
        let time = step as Time * LINK_DT;
        for (i, progressor) in progressors.iter_mut().enumerate() {
            let state = PairState { from: &from[step][i], to: &to[step][i] };
            // A decided condition is started again, as a link process does when it goes back to
            // unlinked, so every instance works at every state.
            if progressor.step(time, &state).map_err(|e| e.to_string())?.is_some() {
                decisions += 1;
                progressor.reset();
            }
        }
    }
    let seconds = clock.seconds();
    let nodes = progressors.iter().map(Progressor::residual_size).sum();
    Ok(LinkRun { seconds, decisions, nodes })
}

/// One group for all pairs.
fn links_shared(formula: &Arc<Formula>, from: &[Vec<Value>], to: &[Vec<Value>]) -> Result<LinkRun, String> {
    let links = from[0].len();
    let mut group = ProgressorGroup::new(formula.clone());
    let ids: Vec<InstanceId> = (0..links).map(|_| group.start()).collect();
    let mut decisions = 0;
    let clock = CpuClock::start();
    for step in 0..LINK_STEPS {
        let time = step as Time * LINK_DT;
        for (i, id) in ids.iter().enumerate() {
            let state = PairState { from: &from[step][i], to: &to[step][i] };
            if group.step(*id, time, &state).map_err(|e| e.to_string())?.is_some() {
                decisions += 1;
                group.restart(*id);
            }
        }
    }
    Ok(LinkRun { seconds: clock.seconds(), decisions, nodes: group.total_residual_size() })
}

/// DyKnow's link conditions (paper, section V) for `links` object pairs at 10 Hz for 10 s, in
/// microseconds with millisecond bounds, as the runtime runs them: one progressor per pair
/// (independent), against one group holding every pair's instance (shared), paired runs.
fn bench_links(links: usize, repeat: usize, out: &mut dyn Write) -> Result<(), BenchError> {
    let conditions = [
        ("reestablish", "eventually[0, 1000] xydist(from.pos, to.pos) < 10.0"),
        ("establish", "eventually[1000, inf] always[0, 1000] on_road(from.pos)"),
        ("maintain", "always eventually[0, 10000] always[0, 1000] on_road(from.pos)"),
    ];
    let from: Vec<Vec<Value>> = (0..LINK_STEPS).map(|k| link_objects(links, k, false)).collect();
    let to: Vec<Vec<Value>> = (0..LINK_STEPS).map(|k| link_objects(links, k, true)).collect();
    writeln!(
        out,
        "\nLink conditions: {links} object pairs, {LINK_STEPS} states 100 ms apart, {} pairs of runs ({}):\n",
        repeat.max(1),
        CpuClock::name()
    )?;
    writeln!(
        out,
        "| condition | formula | independent ns per instance-step | shared ns per instance-step | shared / independent rate (median [range]) | residual nodes independent / shared | decisions |"
    )?;
    writeln!(out, "|---|---|---:|---:|---:|---:|---:|")?;
    for (name, text) in conditions {
        let formula = link_formula(text).map_err(|e| BenchError::Failed(format!("{name}: {e}")))?;
        let (mut alone, mut shared, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
        let mut last = None;
        for _ in 0..repeat.max(1) {
            let runs = links_independent(&formula, &from, &to)
                .and_then(|a| Ok((a, links_shared(&formula, &from, &to)?)));
            let (a, s) = runs.map_err(|e| BenchError::Failed(format!("{name}: {e}")))?;
            if a.decisions != s.decisions {
                return Err(BenchError::Failed(format!(
                    "{name}: {} decisions independently, {} shared",
                    a.decisions, s.decisions
                )));
            }
            ratios.push(a.seconds / s.seconds);
            alone.push(a.seconds);
            shared.push(s.seconds);
            last = Some((a, s));
        }
        let Some((a, s)) = last else { return Ok(()) };
        let steps = (links * LINK_STEPS) as f64;
        let (median, lo, hi) = spread(&mut ratios);
        writeln!(
            out,
            "| {name} | `{text}` | {:.0} | {:.0} | {median:.1} [{lo:.1} - {hi:.1}] | {} / {} | {} |",
            min(&alone) * 1e9 / steps,
            min(&shared) * 1e9 / steps,
            a.nodes,
            s.nodes,
            a.decisions,
        )?;
    }
    Ok(())
}

/// R2U2 (`r2u2_core`), run in this process on the same traces, when built with the `r2u2` feature.
#[cfg(feature = "r2u2")]
mod r2u2 {
    use std::path::Path;

    use kpl_core::Time;

    use crate::clock::CpuClock;
    use crate::timescales::{PROPOSITIONS, Property, TimescalesState};

    pub(super) const BUILT: bool = true;

    /// The property in R2U2's bounded MLTL (C2PO syntax), if it can be written there. R2U2 gives a
    /// verdict at every time step, which stands for our outer `always`.
    pub(super) fn spec(property: Property, b: Time) -> Option<String> {
        let a = property.lower_bound(b);
        let formula = match property {
            Property::AbsentAQ => format!("q -> G[0,{b}] !p"),
            Property::AlwaysAQ => format!("q -> G[0,{b}] p"),
            Property::RecurGLB => format!("F[0,{b}] p"),
            Property::RespondGLB => format!("p -> F[{a},{b}] s"),
            // With `F[0,b] r` as premise the first r comes within b, so `U` may be bounded by b.
            Property::AbsentBR => format!("F[0,{b}] r -> (!p U[0,{b}] r)"),
            Property::AlwaysBR => format!("F[0,{b}] r -> (p U[0,{b}] r)"),
            // The "between Q and R" properties need an unbounded `eventually r`.
            _ => return None,
        };
        Some(format!("INPUT\n    p, q, r, s: bool;\n\nFTSPEC\n    {formula};\n"))
    }

    /// Compiles a spec with C2PO through `r2u2_cli compile` and returns the binary specification.
    pub(super) fn compile(cli: &Path, spec: &str, dir: &Path) -> Result<Vec<u8>, String> {
        std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
        let spec_path = dir.join("spec.c2po");
        let map_path = dir.join("signals.map");
        let bin_path = dir.join("spec.bin");
        let _ = std::fs::remove_file(&bin_path);
        std::fs::write(&spec_path, spec).map_err(|e| format!("cannot write {}: {e}", spec_path.display()))?;
        let map: String = PROPOSITIONS.iter().enumerate().map(|(i, n)| format!("{n}:{i}\n")).collect();
        std::fs::write(&map_path, map).map_err(|e| format!("cannot write {}: {e}", map_path.display()))?;
        let output = std::process::Command::new(cli)
            .arg("compile")
            .arg(&spec_path)
            .arg(&map_path)
            .arg("--output")
            .arg(dir)
            .current_dir(dir)
            .output()
            .map_err(|e| format!("cannot run {}: {e}", cli.display()))?;
        if !output.status.success() {
            return Err(format!(
                "C2PO failed: {}{}",
                String::from_utf8_lossy(&output.stdout),
                String::from_utf8_lossy(&output.stderr)
            ));
        }
        std::fs::read(&bin_path).map_err(|e| format!("C2PO wrote no {}: {e}", bin_path.display()))
    }

    pub(super) struct R2u2Run {
        pub seconds: f64,
        pub violations: usize,
        pub overflow: bool,
    }

    /// One timed run of R2U2, which panics (index out of bounds) when a specification needs more
    /// queue slots than it was built with (`R2U2_MAX_QUEUE_SLOTS`, 2048 unless set when r2u2_core is
    /// compiled): the panic is caught and reported.
    pub(super) fn time(spec: &[u8], trace: &[TimescalesState]) -> Result<R2u2Run, String> {
        let hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(|_| {}));
        let result = std::panic::catch_unwind(|| {
            let mut monitor = r2u2_core::get_monitor(spec);
            let (mut violations, mut overflow) = (0, false);
            let clock = CpuClock::start();
            for row in trace {
                for (i, v) in row.iter().enumerate() {
                    r2u2_core::load_bool_signal(&mut monitor, i, *v);
                }
                if !r2u2_core::monitor_step(&mut monitor) {
                    overflow = true;
                }
                violations +=
                    r2u2_core::get_output_buffer(&monitor).iter().filter(|o| !o.verdict.truth).count();
            }
            R2u2Run { seconds: clock.seconds(), violations, overflow }
        });
        std::panic::set_hook(hook);
        result.map_err(|panic| {
            let message = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            format!(
                "R2U2 panicked ({message}); its queues hold {} slots, set R2U2_MAX_QUEUE_SLOTS when building",
                r2u2_core::R2U2_MAX_QUEUE_SLOTS
            )
        })
    }
}

/// Without the `r2u2` feature: the R2U2 columns say how to get them.
#[cfg(not(feature = "r2u2"))]
mod r2u2 {
    use std::path::Path;

    use kpl_core::Time;

    use crate::timescales::{Property, TimescalesState};

    pub(super) const BUILT: bool = false;
    const NOT_BUILT: &str = "R2U2 not built in (--features r2u2)";

    pub(super) struct R2u2Run {
        pub seconds: f64,
        pub violations: usize,
        pub overflow: bool,
    }

    pub(super) fn spec(_property: Property, _b: Time) -> Option<String> {
        None
    }

    pub(super) fn compile(_cli: &Path, _spec: &str, _dir: &Path) -> Result<Vec<u8>, String> {
        Err(NOT_BUILT.to_string())
    }

    pub(super) fn time(_spec: &[u8], _trace: &[TimescalesState]) -> Result<R2u2Run, String> {
        Err(NOT_BUILT.to_string())
    }
}
