//! Parsing and checking never panic and never overflow the stack, whatever the input: binary
//! garbage, invalid UTF-8, 100k nested brackets or operators, a 50 MB file. (The cargo-fuzz
//! target in `fuzz/` explores the same entry point further.)
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests

use kpl_semantic::registry::{Entry, EntryKind, Registry, TypeReq};
use proptest::prelude::*;

fn registry() -> Registry {
    let mut r = Registry::default();
    r.add(Entry::new(EntryKind::Source, "timer", "ticks").output(TypeReq::Exact(kpl_core::ValueType::Int)));
    r.add(Entry::new(EntryKind::Sink, "console", "prints").variadic(1, "in", TypeReq::Any, "streams"));
    r.add(Entry::new(EntryKind::Link, "anchor.copy", "copies"));
    r
}

/// Parse, check, and (when it parses) format and parse again: the whole front end.
fn front_end(text: &str) -> usize {
    let parse = kpl_syntax::parse(text);
    let mut n = parse.diagnostics.len();
    if !parse.has_errors() {
        n += kpl_semantic::check(&parse.spec, &registry()).diagnostics.len();
        let formatted = kpl_syntax::format::format(text).expect("a clean parse formats");
        assert!(!kpl_syntax::parse(&formatted).has_errors(), "formatting broke:\n{formatted}");
    }
    n
}

fn codes(text: &str) -> Vec<&'static str> {
    kpl_syntax::parse(text).diagnostics.iter().map(|d| d.code).collect()
}

#[test]
fn hundred_thousand_nested_brackets() {
    for (open, close) in [("(", ")"), ("[", "]"), ("{", "}"), ("list<", ">")] {
        let text = format!("monitor m = {}p{}\n", open.repeat(100_000), close.repeat(100_000));
        assert_eq!(codes(&text), ["E0002"], "{open}");
        assert!(
            kpl_syntax::parse_formula(&format!("{}p{}", open.repeat(100_000), close.repeat(100_000)))
                .is_err()
        );
    }
}

#[test]
fn hundred_thousand_chained_operators() {
    // Prefix chains, right-associative chains and left-associative chains.
    for text in [
        format!("monitor m = {}p\n", "not ".repeat(100_000)),
        format!("monitor m = {}p\n", "always ".repeat(100_000)),
        format!("monitor m = {}x > 0\n", "- ".repeat(100_000)),
        format!("monitor m = {}p\n", "p -> ".repeat(100_000)),
        format!("monitor m = {}p\n", "p until ".repeat(100_000)),
        format!("monitor m = {}x > 0\n", "x + ".repeat(100_000)),
        format!("monitor m = {}p\n", "forall c: Car . ".repeat(100_000)),
    ] {
        assert_eq!(codes(&text), ["E0002"], "{}", &text[..40]);
    }
    // n-ary `and` / `or` stay flat: a long conjunction is fine.
    let text = format!("monitor m = {}p\n", "p and ".repeat(100_000));
    assert!(codes(&text).is_empty());
    front_end(&text);
}

#[test]
fn deepest_accepted_nesting_fits_a_test_threads_stack() {
    // Test threads have a 2 MiB stack; the limits must hold there, in an unoptimised build too.
    let max = kpl_syntax::lex::MAX_NESTING;
    let text = format!("monitor m = {}p and q{}\n", "(not ".repeat(max), ")".repeat(max));
    let handle = std::thread::Builder::new().stack_size(2 << 20).spawn(move || front_end(&text)).unwrap();
    handle.join().expect("no stack overflow");
    let text = format!("monitor m = {}p\n", "not ".repeat(kpl_syntax::MAX_EXPR_DEPTH as usize - 1));
    let handle = std::thread::Builder::new().stack_size(2 << 20).spawn(move || front_end(&text)).unwrap();
    handle.join().expect("no stack overflow");
}

#[test]
fn invalid_utf8_is_a_diagnostic() {
    let bytes = b"type A { x: int }\n\xff\xfe garbage\n";
    let err = kpl_syntax::decode_source(bytes).unwrap_err();
    assert_eq!(err.code, "E0008");
    assert_eq!(err.span.start, 18);
    front_end(&String::from_utf8_lossy(bytes));
}

#[test]
fn fifty_megabyte_files() {
    // A valid spec of 50 MB: many small items.
    let item = "stream s = ticks with any change, queue 8 drop oldest // a comment to pad the line\n";
    let mut text = String::from("source ticks : int = timer\nsink out = console(ticks)\n");
    let mut i = 0;
    while text.len() < 50 << 20 {
        text.push_str(&item.replace("stream s", &format!("stream s{i}")));
        i += 1;
    }
    let parse = kpl_syntax::parse(&text);
    assert!(!parse.has_errors());
    assert_eq!(parse.spec.items.len(), i + 2);
    let checked = kpl_semantic::check(&parse.spec, &registry());
    assert!(!checked.has_errors());
    assert_eq!(checked.diagnostics.len(), i, "one unused-stream warning each");
    drop(parse);

    // 50 MB on one line of garbage, and a file over the size limit.
    let garbage: String = "x@1".repeat((50 << 20) / 3);
    assert_eq!(codes(&garbage), ["E0001"]);
    let too_big = " ".repeat(kpl_syntax::MAX_SOURCE_BYTES + 1);
    assert_eq!(codes(&too_big), ["E0005"]);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        front_end(&String::from_utf8_lossy(&bytes));
    }

    #[test]
    fn arbitrary_token_soup_never_panics(tokens in proptest::collection::vec(proptest::sample::select(vec![
        "type", "A", "B", ":", "{", "}", "x", ",", "int", "list", "<", ">", "source", "s", "=", "timer", "(", ")",
        "stream", "with", "sample", "every", "100ms", "any", "order", "link", "l", "->", "via", "anchor.copy",
        "establish", "reestablish", "maintain", "eventually", "[", "0", "1s", "inf", "]", "always", "until",
        "not", "and", "or", "true", "false", "from.x", "to.x", "+", "-", "*", "<=", "==", "forall", "c", ".",
        "monitor", "m", "sink", "console", "deploy", "host", "h", "listen", "\"tcp/1.2.3.4:5\"", "feedback",
        "predict", "forget", "after", "30s", "1e400", "\"\\q\"", "//c\n", "/*", "*/", "\n", "-5", "2.5",
    ]), 0..60)) {
        front_end(&tokens.join(" "));
    }
}
