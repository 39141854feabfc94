//! `kpl check` speed on a generated 10,000-line spec: parse, check, and the two together, with
//! the lexical pre-scan as the baseline measured in the same run (docs/performance.md).
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

criterion_group!(benches, bench);
criterion_main!(benches);
