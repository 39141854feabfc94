//! Fuzzes the whole front end: bytes -> UTF-8 check -> parse -> check -> format -> parse.
//! Run with `cargo fuzz run parse_check` (see docs/architecture.md); the property tests in
//! `crates/kpl-semantic/tests/robust.rs` run the same pipeline in CI.
#![no_main]

use kpl_semantic::registry::{Entry, EntryKind, Registry, TypeReq};
use libfuzzer_sys::fuzz_target;

fn registry() -> Registry {
    let mut r = Registry::default();
    r.add(Entry::new(EntryKind::Source, "timer", "ticks").output(TypeReq::Exact(kpl_core::ValueType::Int)));
    r.add(Entry::new(EntryKind::Sink, "console", "prints").variadic(1, "in", TypeReq::Any, "streams"));
    r.add(Entry::new(EntryKind::Link, "anchor.copy", "copies"));
    r.add(Entry::new(EntryKind::Predict, "constant_velocity", "moves on"));
    r
}

fuzz_target!(|bytes: &[u8]| {
    let text = match kpl_syntax::decode_source(bytes) {
        Ok(text) => text.to_string(),
        Err(_) => String::from_utf8_lossy(bytes).into_owned(),
    };
    let parse = kpl_syntax::parse(&text);
    if parse.has_errors() {
        return;
    }
    let _ = kpl_semantic::check(&parse.spec, &registry());
    let formatted = kpl_syntax::format::format(&text).expect("a spec that parses formats");
    let again = kpl_syntax::parse(&formatted);
    assert!(!again.has_errors(), "formatting produced an invalid spec:\n{formatted}");
    // Spans are not serialized, so equal JSON means the same tree whatever the layout.
    let a = serde_json::to_value(&parse.spec).expect("trees serialize");
    let b = serde_json::to_value(&again.spec).expect("trees serialize");
    assert_eq!(a, b, "formatting changed the tree:\n{formatted}");
});
