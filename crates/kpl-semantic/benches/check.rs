//! `kpl check` speed on a generated 10,000-line spec: parse, check, and the two together, with
//! the lexical pre-scan as the baseline measured in the same run (docs/performance.md).
//! And on specs with many errors (`many_errors`): N and 4N duplicate definitions or unknown
//! names, parsed, checked and every diagnostic rendered as text and JSON; linear work makes the
//! 4N case take 4 times as long, quadratic work 16 times.
//! Run: `cargo bench -p kpl-semantic --bench check`.

use criterion::{Criterion, criterion_group, criterion_main};
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, Registry, TypeReq};

#[path = "generate.rs"]
mod generate;

fn registry() -> Registry {
    let mut r = Registry::default();
    r.add(
        Entry::new(EntryKind::Source, "timer", "")
            .param(Param::required("period", ParamType::Duration, ""))
            .param(Param::optional("count", ParamType::Int, kpl_core::Value::Int(0), ""))
            .output(TypeReq::Exact(kpl_core::ValueType::Int)),
    );
    r.add(Entry::new(EntryKind::Source, "file.jsonl", "").param(Param::required("path", ParamType::Str, "")));
    r.add(Entry::new(EntryKind::Compute, "kpl.merge", "").variadic(1, "in", TypeReq::Any, ""));
    r.add(Entry::new(EntryKind::Sink, "console", "").variadic(1, "in", TypeReq::Any, ""));
    r.add(Entry::new(EntryKind::Link, "anchor.copy", ""));
    r.add(Entry::new(EntryKind::Predict, "constant_velocity", ""));
    for (name, arity) in [("xydist", 2), ("norm", 1), ("abs", 1)] {
        r.add_function(kpl_semantic::registry::Function::new(
            name,
            vec![kpl_core::ValueType::Any; arity],
            kpl_core::ValueType::Float,
            "",
        ));
    }
    r
}

fn bench(c: &mut Criterion) {
    let text = generate::spec(10_000);
    let registry = registry();
    let parse = kpl_syntax::parse(&text);
    assert!(!parse.has_errors());
    let checked = kpl_semantic::check(&parse.spec, &registry);
    assert!(!checked.has_errors(), "{:?}", checked.diagnostics.first());
    let mut group = c.benchmark_group("check_10k_lines");
    group.sample_size(20);
    group.bench_function("lex_scan_baseline", |b| b.iter(|| kpl_syntax::lex::scan(&text)));
    group.bench_function("parse", |b| b.iter(|| kpl_syntax::parse(&text)));
    group.bench_function("check", |b| b.iter(|| kpl_semantic::check(&parse.spec, &registry)));
    group.bench_function("parse_and_check", |b| {
        b.iter(|| {
            let parse = kpl_syntax::parse(&text);
            kpl_semantic::check(&parse.spec, &registry)
        })
    });
    group.finish();
}

/// `n` definitions of one name: `n - 1` duplicates (E0102), each pointing back at the first.
fn duplicates(n: usize) -> String {
    "source t : int = timer(period: 100ms)\n".repeat(n)
}

/// `n` streams over `n` unknown names (E0101), among `2n` names: each unknown name gets a hint
/// search over every name.
fn unknown_names(n: usize) -> String {
    (0..n).map(|i| format!("source t{i} : int = timer(period: 100ms)\nstream s{i} = u{i}\n")).collect()
}

/// What `kpl check` does with a file: parse, check, and render every diagnostic as text and as
/// JSON (the command shows the first 100 as text, every one as JSON).
fn check_and_render(text: &str, registry: &Registry) -> usize {
    let parse = kpl_syntax::parse(text);
    let checked = kpl_semantic::check(&parse.spec, registry);
    let index = kpl_syntax::LineIndex::new(text);
    checked
        .diagnostics
        .iter()
        .map(|d| d.render("many.kpl", text, &index).len() + d.to_json("many.kpl", text, &index).line)
        .sum()
}

fn many_errors(c: &mut Criterion) {
    let registry = registry();
    let mut group = c.benchmark_group("many_errors");
    group.sample_size(10);
    for (kind, make) in [("duplicates", duplicates as fn(usize) -> String), ("unknown_names", unknown_names)]
    {
        for n in [2_000, 8_000] {
            let text = make(n);
            let checked = kpl_semantic::check(&kpl_syntax::parse(&text).spec, &registry);
            assert!(checked.diagnostics.len() >= n - 1, "{kind}: {}", checked.diagnostics.len());
            group.bench_function(format!("{kind}/{n}"), |b| b.iter(|| check_and_render(&text, &registry)));
        }
    }
    group.finish();
}

criterion_group!(benches, bench, many_errors);
criterion_main!(benches);
