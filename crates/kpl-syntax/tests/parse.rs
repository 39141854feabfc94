#![allow(clippy::unwrap_used, clippy::print_stdout)] // tests

use kpl_syntax::ast::{self, ExprKind};
use kpl_syntax::{parse, parse_formula};

#[test]
fn overview_spec_parses() {
    let src =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../specs/ok/overview.kpl")).unwrap();
    let parse = parse(&src);
    assert!(parse.diagnostics.is_empty(), "{:#?}", parse.diagnostics);
    let kinds: Vec<&str> = parse
        .spec
        .items
        .iter()
        .map(|i| match i {
            ast::Item::Type(_) => "type",
            ast::Item::Process(_) => "process",
            ast::Item::Stream(_) => "stream",
            ast::Item::Link(_) => "link",
            ast::Item::Predict(_) => "predict",
            ast::Item::Forget(_) => "forget",
            ast::Item::Identify(_) => "identify",
            ast::Item::Monitor(_) => "monitor",
            ast::Item::Deploy(_) => "deploy",
        })
        .collect();
    assert_eq!(
        kinds,
        [
            "type", "type", "type", "type", "process", "stream", "link", "link", "link", "predict",
            "predict", "forget", "identify", "monitor", "process", "deploy"
        ]
    );
}

#[test]
fn precedence() {
    let f = parse_formula("not a and b or c -> d").unwrap();
    let ExprKind::Binary { op: ast::BinaryOp::Implies, lhs, .. } = f.kind else { panic!() };
    let ExprKind::Or(items) = lhs.kind else { panic!() };
    assert!(matches!(items[0].kind, ExprKind::And(_)));
}

#[test]
fn overview_formats_idempotently() {
    let src =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../specs/ok/overview.kpl")).unwrap();
    let once = kpl_syntax::format::format(&src).unwrap();
    println!("{once}");
    let twice = kpl_syntax::format::format(&once).unwrap();
    assert_eq!(once, twice);
    let a = serde_json::to_value(&parse(&src).spec).unwrap();
    let b = serde_json::to_value(&parse(&once).spec).unwrap();
    assert_eq!(a, b);
}
