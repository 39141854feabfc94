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
            ast::Item::Chronicle(_) => "chronicle",
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

#[test]
fn chronicle_parses_into_its_clauses() {
    let src = "chronicle reckless_overtake(a: Car, b: Car) {
  event start = behind(a, b) becomes true
  event cut_in = in_front(a, b) and same_lane(a, b) becomes true
  event fast = monitor speeding(a) becomes false
  event o = recognised overtake(a, b)
  cut_in - start in [1s, 10s]
  o - start in [-500ms, inf]
  hold close(a, b) from start to cut_in
  never on_road(a) becomes false from start to cut_in
}
";
    let parse = parse(src);
    assert!(parse.diagnostics.is_empty(), "{:#?}", parse.diagnostics);
    let [ast::Item::Chronicle(c)] = parse.spec.items.as_slice() else { panic!("{:#?}", parse.spec) };
    assert_eq!(c.name.name, "reckless_overtake");
    let params: Vec<(&str, &str)> =
        c.params.iter().map(|p| (p.name.name.as_str(), p.ty.name.as_str())).collect();
    assert_eq!(params, [("a", "Car"), ("b", "Car")]);
    let events: Vec<&str> = c.events().map(|e| e.name.name.as_str()).collect();
    assert_eq!(events, ["start", "cut_in", "fast", "o"]);
    let ast::EventPatternKind::Change { predicate, becomes: true } = &c.events().nth(1).unwrap().pattern.kind
    else {
        panic!()
    };
    assert!(matches!(predicate.kind, ExprKind::And(_)));
    let ast::EventPatternKind::Monitor { monitor, args, becomes: false } =
        &c.events().nth(2).unwrap().pattern.kind
    else {
        panic!()
    };
    assert_eq!((monitor.name.as_str(), args.len()), ("speeding", 1));
    let constraints: Vec<_> = c.constraints().collect();
    assert_eq!(
        (constraints[0].later.name.as_str(), constraints[0].earlier.name.as_str()),
        ("cut_in", "start")
    );
    assert!(matches!(constraints[1].lo, ast::StnBound::Duration { negative: true, .. }));
    assert!(matches!(constraints[1].hi, ast::StnBound::Inf { negative: false }));
    assert!(matches!(c.clauses[6], ast::ChronicleClause::Hold(_)));
    assert!(matches!(c.clauses[7], ast::ChronicleClause::Never(_)));
    // `fmt` prints it back as written (it is already canonical).
    assert_eq!(kpl_syntax::format::format(src).unwrap(), src);
}

#[test]
fn chronicle_syntax_errors_name_the_clause() {
    let parse = parse("chronicle c(a: Car) {\n  event e = close(a, b)\n}\n");
    let text = format!("{:?}", parse.diagnostics);
    assert!(text.contains("`becomes`"), "{text}");
}
