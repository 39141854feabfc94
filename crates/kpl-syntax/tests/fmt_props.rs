//! Property tests of the formatter on generated specs (random items, formulas, spacing and
//! comments): `parse(fmt(x)) == parse(x)`, `fmt` is idempotent, and no comment is lost.
#![allow(clippy::unwrap_used)] // tests

use proptest::prelude::*;
use proptest::strategy::BoxedStrategy;

fn name() -> impl Strategy<Value = String> {
    (
        proptest::sample::select(vec![
            "a", "b", "speed", "pos", "tracker", "w_1", "from", "to", "max", "type", "x",
        ]),
        0..3u8,
    )
        .prop_map(|(n, i)| if i == 0 { n.to_string() } else { format!("{n}{i}") })
}

fn type_name() -> impl Strategy<Value = String> {
    proptest::sample::select(vec!["VisionPercept", "WorldObject", "Car", "T", "Detection"])
        .prop_map(str::to_string)
}

/// Separators that must not change the tree: spaces, line breaks and block comments.
fn sep() -> impl Strategy<Value = String> {
    proptest::sample::select(vec![" ", " ", " ", "  ", "\n  ", " /* note */ ", "\t"]).prop_map(str::to_string)
}

fn duration() -> impl Strategy<Value = String> {
    (0..5000u32, proptest::sample::select(vec!["us", "ms", "s", "min", "h"]), any::<bool>()).prop_map(
        |(n, unit, frac)| {
            if frac && unit != "us" { format!("{}.5{unit}", n / 10) } else { format!("{n}{unit}") }
        },
    )
}

fn literal() -> BoxedStrategy<String> {
    let leaf = prop_oneof![
        (-1000i64..1000).prop_map(|i| i.to_string()),
        (-1000.0f64..1000.0).prop_map(|x| format!("{x:?}")),
        Just("1e-3".to_string()),
        duration(),
        "[a-z ]{0,6}".prop_map(|s| format!("\"{s}\"")),
        Just("\"tab\\tquote\\\"\"".to_string()),
        any::<bool>().prop_map(|b| b.to_string()),
    ];
    leaf.prop_recursive(2, 8, 3, |inner| {
        proptest::collection::vec(inner, 0..3).prop_map(|v| format!("[{}]", v.join(", ")))
    })
    .boxed()
}

fn path() -> impl Strategy<Value = String> {
    proptest::collection::vec(name(), 1..3).prop_map(|v| v.join("."))
}

fn interval() -> impl Strategy<Value = String> {
    prop_oneof![
        Just(String::new()),
        (0..100u32, duration()).prop_map(|(a, b)| format!("[{a}, {b}]")),
        duration().prop_map(|a| format!("[{a}, inf]")),
        (0..10u32, 10..20u32).prop_map(|(a, b)| format!("[{a},{b}]")),
    ]
}

/// Numeric terms: never comparisons, so comparisons built from them never chain.
fn term() -> BoxedStrategy<String> {
    let leaf = prop_oneof![
        (0u32..100).prop_map(|i| i.to_string()),
        (0.0f64..100.0).prop_map(|x| format!("{x:?}")),
        path(),
        duration(),
    ];
    leaf.prop_recursive(3, 16, 3, |inner| {
        prop_oneof![
            (inner.clone(), proptest::sample::select(vec!["+", "-", "*", "/", "%"]), inner.clone())
                .prop_map(|(a, op, b)| format!("{a} {op} {b}")),
            inner.clone().prop_map(|a| format!("-{a}")),
            inner.clone().prop_map(|a| format!("({a})")),
            (name(), proptest::collection::vec(inner, 0..3))
                .prop_map(|(f, args)| format!("{f}({})", args.join(", "))),
        ]
    })
    .boxed()
}

fn formula() -> BoxedStrategy<String> {
    let leaf = prop_oneof![
        Just("true".to_string()),
        Just("false".to_string()),
        path(),
        (term(), proptest::sample::select(vec!["<", "<=", ">", ">=", "==", "!="]), term())
            .prop_map(|(a, op, b)| format!("{a} {op} {b}")),
        (name(), proptest::collection::vec(term(), 1..3))
            .prop_map(|(f, args)| format!("on_{f}({})", args.join(", "))),
    ];
    leaf.prop_recursive(4, 24, 3, |inner| {
        prop_oneof![
            inner.clone().prop_map(|a| format!("not {a}")),
            (proptest::sample::select(vec!["eventually", "always"]), interval(), inner.clone())
                .prop_map(|(op, i, a)| format!("{op}{i} {a}")),
            (inner.clone(), proptest::sample::select(vec!["and", "or", "->"]), sep(), inner.clone())
                .prop_map(|(a, op, s, b)| format!("{a}{s}{op} {b}")),
            (inner.clone(), interval(), inner.clone()).prop_map(|(a, i, b)| format!("{a} until{i} {b}")),
            (proptest::sample::select(vec!["forall", "exists"]), name(), type_name(), inner.clone())
                .prop_map(|(q, v, t, a)| format!("{q} {v}: {t} . {a}")),
            inner.prop_map(|a| format!("({a})")),
        ]
    })
    .boxed()
}

fn policy() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("no approximation".to_string()),
        Just("use most recent".to_string()),
        Just("any update".to_string()),
        Just("any change".to_string()),
        duration().prop_map(|d| format!("sample every {d}")),
        duration().prop_map(|d| format!("max delay {d}")),
        (duration(), prop_oneof![Just("inf".to_string()), duration()])
            .prop_map(|(a, b)| format!("from {a} to {b}")),
        Just("any order".to_string()),
        Just("monotone order".to_string()),
        Just("strict order".to_string()),
        (1..5000u32, any::<bool>())
            .prop_map(|(n, b)| format!("queue {n} {}", if b { "block" } else { "drop oldest" })),
        Just("feedback".to_string()),
    ]
}

fn call() -> impl Strategy<Value = String> {
    (
        path(),
        any::<bool>(),
        proptest::collection::vec(
            prop_oneof![path(), (name(), literal()).prop_map(|(n, l)| format!("{n}: {l}"))],
            0..4,
        ),
    )
        .prop_map(
            |(f, parens, args)| {
                if parens || !args.is_empty() { format!("{f}({})", args.join(", ")) } else { f }
            },
        )
}

fn type_expr() -> BoxedStrategy<String> {
    prop_oneof![
        proptest::sample::select(vec!["int", "float", "bool", "string", "vec2", "box", "duration"])
            .prop_map(str::to_string),
        type_name(),
    ]
    .prop_recursive(2, 4, 1, |inner| inner.prop_map(|t| format!("list<{t}>")))
    .boxed()
}

fn item() -> BoxedStrategy<String> {
    prop_oneof![
        (
            type_name(),
            proptest::option::of(type_name()),
            proptest::option::of(name()),
            proptest::collection::vec((name(), type_expr()), 0..4)
        )
            .prop_map(|(n, p, s, fields)| {
                let parent = p.map(|p| format!(" : {p}")).unwrap_or_default();
                let symbol = s.map(|s| format!(" symbol {s}")).unwrap_or_default();
                let fields: Vec<String> = fields.iter().map(|(f, t)| format!("{f}: {t}")).collect();
                format!("type {n}{parent}{symbol} {{ {} }}", fields.join(", "))
            }),
        (proptest::sample::select(vec!["source", "compute"]), name(), type_expr(), sep(), call())
            .prop_map(|(k, n, t, s, c)| format!("{k} {n} : {t}{s}={s}{c}")),
        (name(), call()).prop_map(|(n, c)| format!("sink {n} = {c}")),
        (name(), path(), proptest::collection::vec(policy(), 0..4)).prop_map(|(n, p, ps)| if ps.is_empty() {
            format!("stream {n} = {p}")
        } else {
            format!("stream {n} = {p} with {}", ps.join(", "))
        }),
        (
            name(),
            type_name(),
            type_name(),
            call(),
            proptest::collection::vec((0..4u8, formula(), sep()), 0..5)
        )
            .prop_map(|(n, a, b, c, clauses)| {
                let body: Vec<String> = clauses
                    .iter()
                    .map(|(k, f, s)| match k {
                        0 => format!("establish{s}{f}"),
                        1 => format!("reestablish {f}"),
                        2 => format!("maintain {f} // why"),
                        _ => "input percepts".to_string(),
                    })
                    .collect();
                format!("link {n} : {a} -> {b} via {c} {{\n{}\n}}", body.join("\n"))
            }),
        (type_name(), call()).prop_map(|(t, c)| format!("predict {t} = {c}")),
        (proptest::option::of(type_name()), duration()).prop_map(|(t, d)| match t {
            Some(t) => format!("forget {t} after {d}"),
            None => format!("forget after {d}"),
        }),
        (name(), formula()).prop_map(|(n, f)| format!("monitor {n} = {f}")),
        chronicle(),
        (name(), type_name(), formula()).prop_map(|(n, t, f)| format!("identify {n} : {t} where {f}")),
        (
            proptest::collection::vec((name(), proptest::collection::vec(name(), 0..3), any::<bool>()), 0..3),
            proptest::sample::select(vec!["", "trial ", "\"site-3\" ", "\"and\" ", "\"\" "]),
        )
            .prop_map(|(hosts, deployment)| {
                let hosts: Vec<String> = hosts
                    .iter()
                    .map(|(h, ps, listen)| {
                        let endpoints = if *listen {
                            " listen \"tcp/127.0.0.1:7447\" connect [\"tcp/10.0.0.1:7447\", \"udp/x:1\"]"
                        } else {
                            ""
                        };
                        format!("  host {h}{endpoints} {{ {} }}", ps.join(", "))
                    })
                    .collect();
                format!("deploy {deployment}{{\n{}\n}}", hosts.join("\n"))
            }),
    ]
    .boxed()
}

fn stn_bound() -> impl Strategy<Value = String> {
    prop_oneof![
        duration(),
        duration().prop_map(|d| format!("-{d}")),
        Just("inf".to_string()),
        Just("-inf".to_string()),
    ]
}

fn event_pattern() -> impl Strategy<Value = String> {
    prop_oneof![
        (formula(), any::<bool>()).prop_map(|(f, b)| format!("{f} becomes {b}")),
        (name(), proptest::collection::vec(name(), 0..3), any::<bool>())
            .prop_map(|(m, args, b)| format!("monitor {m}({}) becomes {b}", args.join(", "))),
        (name(), proptest::collection::vec(name(), 0..3))
            .prop_map(|(c, args)| format!("recognised {c}({})", args.join(",")))
    ]
}

fn chronicle() -> impl Strategy<Value = String> {
    let clause = prop_oneof![
        (name(), sep(), event_pattern()).prop_map(|(n, s, p)| format!("event {n}{s}={s}{p}")),
        (name(), name(), stn_bound(), stn_bound())
            .prop_map(|(a, b, lo, hi)| format!("{a}-{b} in [{lo},{hi}]")),
        (formula(), name(), name()).prop_map(|(f, a, b)| format!("hold {f} from {a} to {b} // why")),
        (event_pattern(), name(), name()).prop_map(|(p, a, b)| format!("never {p} from {a} to {b}")),
    ];
    (name(), proptest::collection::vec((name(), type_name()), 0..3), proptest::collection::vec(clause, 0..5))
        .prop_map(|(n, params, clauses)| {
            let params: Vec<String> = params.iter().map(|(p, t)| format!("{p}:{t}")).collect();
            format!("chronicle {n}({}) {{ // head\n{}\n}}", params.join(", "), clauses.join("\n"))
        })
}

fn spec() -> impl Strategy<Value = String> {
    proptest::collection::vec(
        (
            item(),
            proptest::sample::select(vec![
                "\n",
                "\n\n",
                "\n\n\n",
                " // trailing\n",
                "\n// own line\n",
                "\n/* block */\n",
            ]),
        ),
        0..8,
    )
    .prop_map(|items| items.into_iter().map(|(i, s)| format!("{i}{s}")).collect())
}

fn tree(text: &str) -> serde_json::Value {
    let parse = kpl_syntax::parse(text);
    assert!(parse.diagnostics.is_empty(), "{text}\n{:#?}", parse.diagnostics);
    serde_json::to_value(&parse.spec).unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1500))]

    #[test]
    fn format_keeps_the_tree_and_is_idempotent(text in spec()) {
        let before = tree(&text);
        let once = kpl_syntax::format::format(&text).unwrap();
        prop_assert_eq!(&tree(&once), &before, "formatted:\n{}", once);
        let twice = kpl_syntax::format::format(&once).unwrap();
        prop_assert_eq!(&twice, &once);
        let comments = |t: &str| kpl_syntax::lex::scan(t).comments.into_iter().map(|c| c.text).collect::<Vec<_>>();
        prop_assert_eq!(comments(&once), comments(&text));
    }

    #[test]
    fn formulas_round_trip(text in formula()) {
        let source = format!("monitor m = {text}\n");
        let before = tree(&source);
        let once = kpl_syntax::format::format(&source).unwrap();
        prop_assert_eq!(tree(&once), before);
    }
}
