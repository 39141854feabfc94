//! Every diagnostic semantic analysis emits, one constructor each (codes `E01xx`, warnings
//! `W02xx`). `docs/diagnostics.md` documents each code with an example.

use kpl_syntax::Diagnostic;
use kpl_syntax::ast::Span;

use kpl_core::did_you_mean;

pub const UNKNOWN_NAME: &str = "E0101";
pub const DUPLICATE: &str = "E0102";
pub const UNKNOWN_ATTRIBUTE: &str = "E0103";
pub const TYPE_MISMATCH: &str = "E0104";
pub const UNKNOWN_TYPE: &str = "E0105";
pub const TYPE_CYCLE: &str = "E0106";
pub const UNKNOWN_FUNCTION: &str = "E0107";
pub const ARITY: &str = "E0108";
pub const DUPLICATE_SYMBOL: &str = "E0109";
pub const UNKNOWN_ENTRY: &str = "E0110";
pub const UNKNOWN_PARAM: &str = "E0111";
pub const MISSING_PARAM: &str = "E0112";
pub const PARAM_TYPE: &str = "E0113";
pub const INPUT_COUNT: &str = "E0114";
pub const NOT_A_STREAM: &str = "E0115";
pub const UNKNOWN_PORT: &str = "E0116";
pub const BUILTIN_TYPE: &str = "E0117";
pub const PARAM_PROBLEM: &str = "E0118";
pub const POLICY_CONFLICT: &str = "E0120";
pub const POLICY_DUPLICATE: &str = "E0121";
pub const POLICY_VALUE: &str = "E0122";
pub const CYCLE: &str = "E0130";
pub const NOT_PLACED: &str = "E0140";
pub const PLACED_TWICE: &str = "E0141";
pub const UNKNOWN_PLACED: &str = "E0142";
pub const STREAM_PLACED: &str = "E0143";
pub const DUPLICATE_HOST: &str = "E0144";
pub const DEPLOY_TWICE: &str = "E0145";
pub const BAD_ENDPOINT: &str = "E0146";
pub const PROTOCOL_NOT_BUILT_IN: &str = "E0147";
pub const EMPTY_DEPLOYMENT_NAME: &str = "E0148";
pub const CONDITION_MISSING: &str = "E0150";
pub const CONDITION_TWICE: &str = "E0151";
pub const NO_PRODUCER: &str = "E0152";
pub const TO_IN_ESTABLISH: &str = "E0153";
pub const LINK_INPUT_TYPE: &str = "E0154";
pub const RESERVED_ATTRIBUTE: &str = "E0155";
pub const LINK_INPUT_FEEDBACK: &str = "E0156";
pub const TEMPORAL_IN_FORGET: &str = "E0158";
pub const FORGET_NOT_SOONER: &str = "E0159";
pub const BAD_INTERVAL: &str = "E0160";
pub const BAD_BOUND: &str = "E0161";
pub const CHRONICLE_ARGS: &str = "E0170";
pub const CHRONICLE_INCONSISTENT: &str = "E0171";
pub const CHRONICLE_UNBOUNDED: &str = "E0172";
pub const CHRONICLE_UNBOUND_PARAM: &str = "E0173";
pub const CHRONICLE_CONDITION_ORDER: &str = "E0174";
pub const CHRONICLE_CYCLE: &str = "E0175";
pub const CHRONICLE_EMPTY: &str = "E0176";
pub const CHRONICLE_HYSTERESIS_NESTED: &str = "E0177";
pub const UNUSED_STREAM: &str = "W0201";
pub const UNUSED_OUTPUT: &str = "W0202";
pub const BARE_BOUND: &str = "W0203";
pub const UNSET_ATTRIBUTE: &str = "W0204";
pub const FORGET_WHEN_INEFFECTIVE: &str = "W0206";
pub const PARAM_INEFFECTIVE: &str = "W0207";

pub fn unknown_name(span: Span, what: &str, name: &str, candidates: &[&str]) -> Diagnostic {
    Diagnostic::error(UNKNOWN_NAME, span, format!("unknown {what} `{name}`"))
        .with_label(format!("no {what} is called `{name}`"))
        .with_hint_opt(did_you_mean(name, candidates))
}

pub fn duplicate(span: Span, what: &str, name: &str, first: Span) -> Diagnostic {
    Diagnostic::error(DUPLICATE, span, format!("{what} `{name}` is defined more than once"))
        .with_label("defined again here")
        .with_secondary(first, "first defined here")
        .with_hint("rename one of them")
}

pub fn unknown_attribute(span: Span, ty: &str, field: &str, candidates: &[&str]) -> Diagnostic {
    let hint = did_you_mean(field, candidates)
        .or_else(|| (!candidates.is_empty()).then(|| format!("`{ty}` has: {}", candidates.join(", "))));
    Diagnostic::error(UNKNOWN_ATTRIBUTE, span, format!("`{ty}` has no attribute `{field}`"))
        .with_label("unknown attribute")
        .with_hint_opt(hint)
}

pub fn type_mismatch(span: Span, expected: &str, found: &str) -> Diagnostic {
    Diagnostic::error(TYPE_MISMATCH, span, format!("expected {expected}, found {found}"))
        .with_label(format!("this is {found}"))
}

pub fn type_mismatch_hint(span: Span, expected: &str, found: &str, hint: &str) -> Diagnostic {
    type_mismatch(span, expected, found).with_hint(hint)
}

pub fn unknown_type(span: Span, name: &str, candidates: &[&str]) -> Diagnostic {
    let hint = did_you_mean(name, candidates).unwrap_or_else(|| {
        "built-in types are bool, int, float, string, vec2, box, duration and list<T>; declare object types with `type`".to_string()
    });
    Diagnostic::error(UNKNOWN_TYPE, span, format!("unknown type `{name}`"))
        .with_label("not a type")
        .with_hint(hint)
}

pub fn type_cycle(span: Span, cycle: &[String]) -> Diagnostic {
    Diagnostic::error(TYPE_CYCLE, span, format!("type hierarchy has a cycle: {}", cycle.join(" : ")))
        .with_label("inherits from itself")
        .with_hint("each type has at most one parent, and following parents must end at a type without one")
}

pub fn unknown_function(span: Span, name: &str, candidates: &[&str]) -> Diagnostic {
    Diagnostic::error(UNKNOWN_FUNCTION, span, format!("unknown function `{name}`"))
        .with_label("not a function")
        .with_hint_opt(
            did_you_mean(name, candidates)
                .or_else(|| Some("`kpl list` shows the functions formulas may call".into())),
        )
}

pub fn arity(span: Span, name: &str, expected: &str, given: usize, signature: &str) -> Diagnostic {
    Diagnostic::error(ARITY, span, format!("`{name}` takes {expected}, {given} given"))
        .with_label("wrong number of arguments")
        .with_hint(format!("the signature is `{signature}`"))
}

pub fn duplicate_symbol(span: Span, symbol: &str, ty: &str, other: &str, first: Span) -> Diagnostic {
    Diagnostic::error(
        DUPLICATE_SYMBOL,
        span,
        format!("types `{ty}` and `{other}` both use the symbol prefix `{symbol}`"),
    )
    .with_label("same prefix")
    .with_secondary(first, "also used here")
    .with_hint("give each type its own prefix with `symbol`, so that symbols like `wo3` name one type")
}

pub fn builtin_type(span: Span, name: &str) -> Diagnostic {
    Diagnostic::error(BUILTIN_TYPE, span, format!("`{name}` is a built-in type and cannot be redefined"))
        .with_label("built-in")
        .with_hint("choose another name")
}

pub fn unknown_entry(
    span: Span,
    kind: &str,
    name: &str,
    other_kinds: &[&str],
    candidates: &[&str],
) -> Diagnostic {
    let hint = if let Some(other) = other_kinds.first() {
        Some(format!("`{name}` is a {other}, not a {kind}"))
    } else {
        did_you_mean(name, candidates).or_else(|| Some("`kpl list` shows what the runtime provides".into()))
    };
    Diagnostic::error(UNKNOWN_ENTRY, span, format!("no {kind} named `{name}` is registered"))
        .with_label(format!("unknown {kind}"))
        .with_hint_opt(hint)
}

pub fn unknown_param(span: Span, entry: &str, name: &str, candidates: &[&str]) -> Diagnostic {
    let hint = did_you_mean(name, candidates).or_else(|| {
        Some(if candidates.is_empty() {
            format!("`{entry}` takes no parameters")
        } else {
            format!("`{entry}` takes: {}", candidates.join(", "))
        })
    });
    Diagnostic::error(UNKNOWN_PARAM, span, format!("`{entry}` has no parameter `{name}`"))
        .with_label("unknown parameter")
        .with_hint_opt(hint)
}

pub fn missing_param(span: Span, entry: &str, name: &str, ty: &str, doc: &str) -> Diagnostic {
    Diagnostic::error(MISSING_PARAM, span, format!("`{entry}` needs the parameter `{name}`"))
        .with_label(format!("`{name}` missing"))
        .with_hint(format!("add `{name}: <{ty}>` ({doc})"))
}

pub fn param_type(span: Span, entry: &str, name: &str, expected: &str, found: &str) -> Diagnostic {
    Diagnostic::error(
        PARAM_TYPE,
        span,
        format!("parameter `{name}` of `{entry}` must be {expected}, found {found}"),
    )
    .with_label(format!("expected {expected}"))
}

/// What an entry's own check of its parameters found (a ROS 2 mapping against its message).
pub fn param_problem(span: Span, entry: &str, problem: &crate::registry::ParamProblem) -> Diagnostic {
    Diagnostic::error(PARAM_PROBLEM, span, format!("`{entry}`: {}", problem.message))
        .with_label(format!("in `{}`", problem.param))
        .with_hint_opt(problem.hint.clone())
}

pub fn input_count(span: Span, entry: &str, expected: &str, given: usize) -> Diagnostic {
    Diagnostic::error(INPUT_COUNT, span, format!("`{entry}` takes {expected}, {given} given"))
        .with_label("wrong number of input streams")
        .with_hint("inputs are the positional arguments; parameters are written `name: value`")
}

pub fn not_a_stream(span: Span, name: &str, what: &str) -> Diagnostic {
    Diagnostic::error(NOT_A_STREAM, span, format!("`{name}` is {what}, not a stream"))
        .with_label("not a stream")
        .with_hint("inputs name a `stream`, or a source, compute, link or monitor (its output stream)")
}

pub fn unknown_port(span: Span, process: &str, port: &str, candidates: &[&str]) -> Diagnostic {
    let hint = did_you_mean(port, candidates).or_else(|| {
        Some(if candidates.is_empty() {
            format!("`{process}` has only its default output: write `{process}`")
        } else {
            format!("`{process}` has the outputs: {}", candidates.join(", "))
        })
    });
    Diagnostic::error(UNKNOWN_PORT, span, format!("`{process}` has no output `{port}`"))
        .with_label("unknown output")
        .with_hint_opt(hint)
}

pub fn policy_conflict(span: Span, message: &str, other: Span, hint: &str) -> Diagnostic {
    Diagnostic::error(POLICY_CONFLICT, span, format!("conflicting policies: {message}"))
        .with_label("conflicts")
        .with_secondary(other, "with this")
        .with_hint(hint)
}

pub fn policy_conflict_default(span: Span, message: &str, hint: &str) -> Diagnostic {
    Diagnostic::error(POLICY_CONFLICT, span, format!("conflicting policies: {message}"))
        .with_label("conflicts")
        .with_hint(hint)
}

pub fn policy_duplicate(span: Span, class: &str, first: Span) -> Diagnostic {
    Diagnostic::error(POLICY_DUPLICATE, span, format!("two {class} policies on one stream"))
        .with_label("second one")
        .with_secondary(first, "first one")
        .with_hint(format!("a stream has at most one {class} policy; keep one"))
}

pub fn policy_value(span: Span, message: &str, hint: &str) -> Diagnostic {
    Diagnostic::error(POLICY_VALUE, span, message.to_string()).with_label("here").with_hint(hint)
}

pub fn cycle(span: Span, names: &[String]) -> Diagnostic {
    let mut path = names.to_vec();
    if let Some(first) = names.first() {
        path.push(first.clone());
    }
    Diagnostic::error(CYCLE, span, format!("the processes {} form a cycle", path.join(" -> ")))
        .with_label("part of the cycle")
        .with_hint(
            "a cycle is allowed only through a delayed edge: declare one stream of the cycle `with feedback`",
        )
}

pub fn not_placed(span: Span, name: &str, kind: &str) -> Diagnostic {
    Diagnostic::error(NOT_PLACED, span, format!("{kind} `{name}` is not placed on any host"))
        .with_label("not in the deploy section")
        .with_hint("with a deploy section, every process must be listed under exactly one host")
}

pub fn placed_twice(span: Span, name: &str, host: &str, first: Span, first_host: &str) -> Diagnostic {
    Diagnostic::error(PLACED_TWICE, span, format!("`{name}` is placed on both `{first_host}` and `{host}`"))
        .with_label(format!("on `{host}`"))
        .with_secondary(first, format!("on `{first_host}`"))
        .with_hint("a process runs on exactly one host; a stream reaches other hosts by itself")
}

pub fn unknown_placed(span: Span, name: &str, candidates: &[&str]) -> Diagnostic {
    Diagnostic::error(UNKNOWN_PLACED, span, format!("no process named `{name}` to place"))
        .with_label("unknown process")
        .with_hint_opt(did_you_mean(name, candidates))
}

pub fn stream_placed(span: Span, name: &str) -> Diagnostic {
    Diagnostic::error(STREAM_PLACED, span, format!("`{name}` is a stream; only processes are placed"))
        .with_label("a stream")
        .with_hint("a stream's policy runs where each consumer runs; remove it from the host")
}

pub fn duplicate_host(span: Span, name: &str, first: Span) -> Diagnostic {
    Diagnostic::error(DUPLICATE_HOST, span, format!("host `{name}` is declared twice"))
        .with_label("again")
        .with_secondary(first, "first here")
        .with_hint("list all of a host's processes in one `host` block")
}

pub fn deploy_twice(span: Span, first: Span) -> Diagnostic {
    Diagnostic::error(DEPLOY_TWICE, span, "a spec has at most one deploy section")
        .with_label("second deploy section")
        .with_secondary(first, "first one")
        .with_hint("merge the hosts into one `deploy { ... }`")
}

pub fn bad_endpoint(span: Span, endpoint: &str) -> Diagnostic {
    Diagnostic::error(BAD_ENDPOINT, span, format!("`{endpoint}` is not a zenoh endpoint"))
        .with_label("expected PROTOCOL/ADDRESS")
        .with_hint("endpoints look like \"tcp/127.0.0.1:7447\" or \"tls/192.168.1.2:7447\"")
}

pub fn protocol_not_built_in(span: Span, protocol: &str, protocols: &[String]) -> Diagnostic {
    let list: Vec<String> = protocols.iter().map(|p| format!("`{p}/`")).collect();
    Diagnostic::error(PROTOCOL_NOT_BUILT_IN, span, format!("`{protocol}` links are not built into kpl"))
        .with_label("kpl run could not open this endpoint")
        .with_hint(format!("this kpl links hosts over {}", list.join(" and ")))
}

pub fn empty_deployment_name(span: Span) -> Diagnostic {
    Diagnostic::error(EMPTY_DEPLOYMENT_NAME, span, "the deployment's name is empty")
        .with_label("empty name")
        .with_hint("name the deployment (`deploy trial { ... }`), or leave the name out for `default`")
}

pub fn condition_missing(span: Span, link: &str, kind: &str) -> Diagnostic {
    Diagnostic::error(CONDITION_MISSING, span, format!("link `{link}` has no {kind} condition"))
        .with_label("incomplete link specification")
        .with_hint(format!("add `{kind} <formula>` (use `{kind} false` to never {kind}, `true` to always)"))
}

pub fn condition_twice(span: Span, kind: &str, first: Span) -> Diagnostic {
    Diagnostic::error(CONDITION_TWICE, span, format!("the {kind} condition is given twice"))
        .with_label("second one")
        .with_secondary(first, "first one")
        .with_hint("combine them with `and` or `or`")
}

pub fn no_producer(span: Span, ty: &str, user: &str) -> Diagnostic {
    Diagnostic::error(NO_PRODUCER, span, format!("no process produces objects of type `{ty}` for {user}"))
        .with_label(format!("nothing produces `{ty}`"))
        .with_hint(format!(
            "declare a source of `{ty}`, or a link `... -> {ty}`, or name the stream with `input`"
        ))
}

pub fn to_in_establish(span: Span) -> Diagnostic {
    Diagnostic::error(TO_IN_ESTABLISH, span, "`to` is not bound in an establish condition")
        .with_label("no `to` object yet")
        .with_hint("establish decides whether to create a new object, so only `from` exists; compare with existing objects in `reestablish`")
}

pub fn link_input_type(span: Span, stream: &str, found: &str, expected: &str) -> Diagnostic {
    Diagnostic::error(
        LINK_INPUT_TYPE,
        span,
        format!("stream `{stream}` carries {found}, but the link is from `{expected}`"),
    )
    .with_label(format!("not `{expected}` objects"))
    .with_hint(format!("give the link a stream of `{expected}` (or of a subtype)"))
}

pub fn reserved_attribute(span: Span, name: &str, meaning: &str) -> Diagnostic {
    Diagnostic::error(RESERVED_ATTRIBUTE, span, format!("`{name}` is an attribute every object has"))
        .with_label(format!("anchoring sets `{name}`: {meaning}"))
        .with_hint("choose another name for this attribute")
}

pub fn link_input_feedback(span: Span, link: &str) -> Diagnostic {
    Diagnostic::error(
        LINK_INPUT_FEEDBACK,
        span,
        format!("link `{link}` takes its objects only through `feedback` streams"),
    )
    .with_label("a link steps at the states of its inputs, and a `feedback` input starts none")
    .with_hint("give the link an input without `feedback` (drop `feedback` from this stream's policy)")
}

pub fn temporal_in_forget(span: Span) -> Diagnostic {
    Diagnostic::error(TEMPORAL_IN_FORGET, span, "a forget condition cannot use a temporal operator")
        .with_label("the condition is evaluated on the object's state at each step")
        .with_hint(
            "describe the state (`in_view(cam, this.pos)`); the time since the object was last anchored is the `after` duration",
        )
}

pub fn forget_not_sooner(span: Span, sooner: &str, after: &str) -> Diagnostic {
    Diagnostic::error(
        FORGET_NOT_SOONER,
        span,
        format!("`after {sooner} when ...` is not shorter than the forget time {after}"),
    )
    .with_label("this condition would never make a difference")
    .with_hint("give the condition a shorter time than the declaration's first `after`")
}

pub fn bad_interval(span: Span, lo: &str, hi: &str) -> Diagnostic {
    Diagnostic::error(
        BAD_INTERVAL,
        span,
        format!("interval [{lo}, {hi}] is empty: its lower bound is above its upper bound"),
    )
    .with_label("empty interval")
    .with_hint("write the bounds in increasing order")
}

pub fn bad_bound(span: Span, message: &str) -> Diagnostic {
    Diagnostic::error(BAD_BOUND, span, message.to_string()).with_label("this bound").with_hint(
        "in a spec a bare integer bound counts milliseconds; durations take a unit (`500ms`, `2s`)",
    )
}

pub fn unused_stream(span: Span, name: &str) -> Diagnostic {
    Diagnostic::warning(UNUSED_STREAM, span, format!("stream `{name}` is never used"))
        .with_label("declared here")
        .with_hint("use it as an input, or remove it")
}

pub fn unused_output(span: Span, name: &str, kind: &str) -> Diagnostic {
    Diagnostic::warning(UNUSED_OUTPUT, span, format!("the output of {kind} `{name}` is never used"))
        .with_label("nothing consumes this")
        .with_hint("connect it to a sink or another process, or remove it")
}

pub fn bare_bound(span: Span, bare: &[u64], fixed: &str) -> Diagnostic {
    let numbers: Vec<String> = bare.iter().map(|n| format!("`{n}`")).collect();
    let message = if bare.len() == 1 {
        format!("the bare number {} in a time bound counts milliseconds", numbers[0])
    } else {
        format!("the bare numbers {} in a time bound count milliseconds", numbers.join(" and "))
    };
    Diagnostic::warning(BARE_BOUND, span, message)
        .with_label("milliseconds")
        .with_hint(format!("write the unit: `{fixed}` (or `s`, `min` where that is meant)"))
}

pub fn unset_attribute(
    span: Span,
    ty: &str,
    attribute: &str,
    link: (Span, &str),
    unit: &str,
    sets: &[String],
) -> Diagnostic {
    let sets = if sets.is_empty() { "nothing".to_string() } else { sets.join(", ") };
    Diagnostic::warning(UNSET_ATTRIBUTE, span, format!("nothing sets `{ty}.{attribute}`: it keeps its default"))
        .with_label("declared here")
        .with_secondary(link.0, format!("`{ty}` objects come from `{}`", link.1))
        .with_hint(format!(
            "`{unit}` sets {sets} of a `{ty}`; compute `{attribute}` in a link unit that sets it (see `kpl list`), or remove the attribute"
        ))
}

/// A subtype declares an attribute its parent already has.
pub fn inherited_attribute(span: Span, name: &str) -> Diagnostic {
    Diagnostic::error(DUPLICATE, span, format!("attribute `{name}` is already inherited"))
        .with_label("inherited from a parent type")
        .with_hint("a subtype adds attributes; it cannot redefine its parent's")
}

/// `sink NAME : TYPE = ...`: sinks produce nothing.
pub fn sink_with_output(span: Span) -> Diagnostic {
    Diagnostic::error(TYPE_MISMATCH, span, "a sink has no output type")
        .with_label("remove this")
        .with_hint("sinks consume streams; write `sink NAME = entry(inputs...)`")
}

pub fn chronicle_arg_not_param(span: Span, name: &str, params: &[&str]) -> Diagnostic {
    Diagnostic::error(CHRONICLE_ARGS, span, format!("`{name}` is not a parameter of this chronicle"))
        .with_label("not a parameter")
        .with_hint(did_you_mean(name, params).unwrap_or_else(|| {
            format!("an event's objects are the chronicle's parameters: {}", params.join(", "))
        }))
}

pub fn chronicle_arg_count(span: Span, what: &str, name: &str, expected: usize, found: usize) -> Diagnostic {
    Diagnostic::error(
        CHRONICLE_ARGS,
        span,
        format!("{what} `{name}` takes {expected} object(s), {found} given"),
    )
    .with_label("wrong number of objects")
    .with_hint(format!("give one parameter for each of the {what}'s {expected} object(s), in order"))
}

pub fn chronicle_arg_type(span: Span, name: &str, found: &str, expected: &str) -> Diagnostic {
    Diagnostic::error(
        CHRONICLE_ARGS,
        span,
        format!("parameter `{name}` is a `{found}`, but `{expected}` is needed here"),
    )
    .with_label("wrong object type")
    .with_hint(format!("declare `{name}` as a `{expected}` (or a subtype)"))
}

pub fn chronicle_not_a_monitor(span: Span, name: &str, monitors: &[&str]) -> Diagnostic {
    Diagnostic::error(UNKNOWN_NAME, span, format!("unknown monitor `{name}`"))
        .with_label("no monitor is called so")
        .with_hint(
            did_you_mean(name, monitors)
                .unwrap_or_else(|| "declare it with `monitor NAME = forall x: T . ...`".into()),
        )
}

/// The constraints on a negative cycle of the distance graph, each labelled.
pub fn chronicle_inconsistent(span: Span, chronicle: &str, cycle: &[(Span, String)]) -> Diagnostic {
    let written: Vec<&str> = cycle.iter().map(|(_, text)| text.as_str()).collect();
    let mut d = Diagnostic::error(
        CHRONICLE_INCONSISTENT,
        span,
        format!("the time constraints of chronicle `{chronicle}` cannot all hold"),
    )
    .with_label("never recognised");
    for (at, _) in cycle {
        d = d.with_secondary(*at, "on the cycle");
    }
    d.with_hint(format!(
        "these constraints contradict each other (a negative cycle of the distance graph): {}; widen one of them",
        written.join("; ")
    ))
}

pub fn chronicle_unbounded(span: Span, chronicle: &str, first: &str, second: &str) -> Diagnostic {
    Diagnostic::error(
        CHRONICLE_UNBOUNDED,
        span,
        format!("chronicle `{chronicle}` puts no upper bound on the time between `{first}` and `{second}`"),
    )
    .with_label("unbounded")
    .with_hint(format!(
        "add a constraint such as `{second} - {first} in [0s, 30s]`: a partial instance waits at most as long as the constraints allow"
    ))
}

pub fn chronicle_unbound_param(span: Span, param: &str) -> Diagnostic {
    Diagnostic::error(CHRONICLE_UNBOUND_PARAM, span, format!("parameter `{param}` appears in no event"))
        .with_label("never bound")
        .with_hint("every parameter must be an object of some event, so that a recognition names it")
}

pub fn chronicle_condition_order(span: Span, from: &str, to: &str) -> Diagnostic {
    Diagnostic::error(
        CHRONICLE_CONDITION_ORDER,
        span,
        format!("`{to}` may happen before `{from}`, so `from {from} to {to}` is not an interval"),
    )
    .with_label("not ordered")
    .with_hint(format!("add a constraint `{to} - {from} in [0s, ...]`"))
}

pub fn chronicle_cycle(span: Span, cycle: &[String]) -> Diagnostic {
    Diagnostic::error(
        CHRONICLE_CYCLE,
        span,
        format!("chronicles recognise each other in a cycle: {}", cycle.join(" -> ")),
    )
    .with_label("part of the cycle")
    .with_hint("a chronicle can use the recognitions of another only if that one does not depend on it")
}

pub fn chronicle_empty(span: Span, chronicle: &str) -> Diagnostic {
    Diagnostic::error(CHRONICLE_EMPTY, span, format!("chronicle `{chronicle}` has no events"))
        .with_label("no `event`")
        .with_hint("add events such as `event pass = beside(a, b) becomes true`")
}

pub fn chronicle_hysteresis_nested(span: Span) -> Diagnostic {
    Diagnostic::error(
        CHRONICLE_HYSTERESIS_NESTED,
        span,
        "`hysteresis` is a whole predicate of a chronicle, not part of one".to_string(),
    )
    .with_label("inside another expression")
    .with_hint("write `event e = hysteresis(ENTER, LEAVE) becomes true`, with the conditions inside it: `hysteresis(close(a, b, 20.0), not close(a, b, 25.0))`")
}

pub fn param_ineffective(span: Span, param: &str, unit: &str, ty: &str, acts_on: &[String]) -> Diagnostic {
    let names: Vec<String> = acts_on.iter().map(|a| format!("`{a}`")).collect();
    Diagnostic::warning(
        PARAM_INEFFECTIVE,
        span,
        format!("`{param}` of `{unit}` has no effect: `{ty}` declares none of {}", names.join(", ")),
    )
    .with_label("sets nothing")
    .with_hint(format!("declare {} on `{ty}` to get what it sets, or remove `{param}`", names.join(" or ")))
}

pub fn forget_when_ineffective(span: Span, ty: &str) -> Diagnostic {
    Diagnostic::warning(
        FORGET_WHEN_INEFFECTIVE,
        span,
        format!("the `when` condition of `forget {ty}` has no effect: no link makes `{ty}` objects"),
    )
    .with_label("never evaluated")
    .with_hint(
        "objects that come from a source (percepts) are forgotten by time only; put the condition on a type a link makes, or remove it",
    )
}
