//! Checking chronicles: parameters and their object types, events (predicates over the
//! parameters, monitors' verdicts with the monitor's bindings, other chronicles' recognitions),
//! metric constraints, `hold` / `never` conditions, and the simple temporal network's consistency
//! and boundedness by shortest paths over its distance graph (`kpl_chronicle::stn`).

use std::collections::BTreeMap;

use kpl_chronicle::stn::{Constraint, Stn};
use kpl_core::{Time, ValueType};
use kpl_syntax::ast::{self, Span};

use super::{Checker, Decl, Draft, Named};
use crate::diagnostics as diag;
use crate::formula::{Context, FormulaChecker};
use crate::hir;

use hir::HYSTERESIS;

/// The span of a call of `hysteresis` inside `e`, if any.
fn nested_hysteresis(e: &ast::Expr) -> Option<Span> {
    use ast::ExprKind as K;
    match &e.kind {
        K::Call { func, .. } if func.name == HYSTERESIS => Some(func.span),
        K::Call { args, .. } | K::And(args) | K::Or(args) => args.iter().find_map(nested_hysteresis),
        K::Unary { expr, .. } | K::Temporal { body: expr, .. } | K::Quantified { body: expr, .. } => {
            nested_hysteresis(expr)
        }
        K::Binary { lhs, rhs, .. } | K::Until { lhs, rhs, .. } => {
            nested_hysteresis(lhs).or_else(|| nested_hysteresis(rhs))
        }
        K::Bool(_) | K::Number(_) | K::Str(_) | K::Duration(_) | K::Path(_) => None,
    }
}

/// A chronicle's name and parameter types, for `recognised NAME(...)` in other chronicles.
struct Signature {
    params: Vec<String>,
}

/// The parameters of the chronicle being checked.
struct Params {
    names: Vec<String>,
    types: Vec<ValueType>,
}

impl Params {
    fn index(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }
    fn vars(&self) -> Vec<(String, ValueType)> {
        self.names.iter().cloned().zip(self.types.iter().cloned()).collect()
    }
    fn type_name(&self, index: usize) -> Option<&str> {
        match &self.types[index] {
            ValueType::Record(r) => Some(&r.name),
            _ => None,
        }
    }
}

impl Checker<'_> {
    /// Checks every chronicle of the spec; returns those without errors.
    pub(super) fn chronicles(&mut self, spec: &ast::Spec, drafts: &[Draft<'_>]) -> Vec<hir::Chronicle> {
        let mut signatures: BTreeMap<String, (Signature, Span)> = BTreeMap::new();
        let mut decls = Vec::new();
        for item in &spec.items {
            let ast::Item::Chronicle(c) = item else { continue };
            // Declared as a process (its recogniser); a second use of the name is reported there.
            if let Some((_, first)) = self.names.get(&c.name.name)
                && *first != c.name.span
            {
                continue;
            }
            if let Some((_, first)) = signatures.get(&c.name.name) {
                self.diagnostics.push(diag::duplicate(c.name.span, "chronicle", &c.name.name, *first));
                continue;
            }
            let params = c.params.iter().map(|p| p.ty.name.clone()).collect();
            signatures.insert(c.name.name.clone(), (Signature { params }, c.name.span));
            decls.push(c);
        }
        let mut out = Vec::new();
        for decl in decls {
            let before = self.diagnostics.len();
            let checked = self.chronicle(decl, drafts, &signatures);
            if self.diagnostics.len() == before {
                out.push(checked);
            }
        }
        self.chronicle_cycles(&out);
        out
    }

    fn chronicle(
        &mut self,
        decl: &ast::ChronicleDecl,
        drafts: &[Draft<'_>],
        signatures: &BTreeMap<String, (Signature, Span)>,
    ) -> hir::Chronicle {
        let mut params = Params { names: Vec::new(), types: Vec::new() };
        for p in &decl.params {
            if let Some(first) =
                decl.params.iter().find(|q| q.name.name == p.name.name).filter(|q| q.span != p.span)
                && first.span.start < p.span.start
            {
                self.diagnostics.push(diag::duplicate(
                    p.name.span,
                    "parameter",
                    &p.name.name,
                    first.name.span,
                ));
            }
            let ty = self.record_type(&p.ty).unwrap_or(ValueType::Any);
            params.names.push(p.name.name.clone());
            params.types.push(ty);
        }
        let mut event_spans: Vec<(String, Span)> = Vec::new();
        let mut events = Vec::new();
        for e in decl.events() {
            if let Some((_, first)) = event_spans.iter().find(|(n, _)| *n == e.name.name) {
                self.diagnostics.push(diag::duplicate(e.name.span, "event", &e.name.name, *first));
            }
            event_spans.push((e.name.name.clone(), e.name.span));
            let (source, args, value) = self.event_pattern(&e.pattern, &params, drafts, signatures);
            events.push(hir::ChronicleEvent { name: e.name.name.clone(), source, args, value });
        }
        if events.is_empty() {
            self.diagnostics.push(diag::chronicle_empty(decl.name.span, &decl.name.name));
        }
        for (index, p) in decl.params.iter().enumerate() {
            if !events.iter().any(|e| e.args.contains(&index)) && !events.is_empty() {
                self.diagnostics.push(diag::chronicle_unbound_param(p.name.span, &p.name.name));
            }
        }
        let names: Vec<&str> = event_spans.iter().map(|(n, _)| n.as_str()).collect();
        let mut constraints = Vec::new();
        let mut constraint_decls = Vec::new();
        let resolved_before = self.diagnostics.len();
        for c in decl.constraints() {
            let later = self.event_index(&c.later, &names);
            let earlier = self.event_index(&c.earlier, &names);
            let lo = self.stn_bound(&c.lo, false);
            let hi = self.stn_bound(&c.hi, true);
            if let (Some(later), Some(earlier), Some(lo), Some(hi)) = (later, earlier, lo, hi) {
                constraints.push(Constraint { later, earlier, lo, hi });
                constraint_decls.push(c);
            }
        }
        let mut window = 0;
        // The network is judged only when every constraint resolved (no cascade from a typo).
        let resolved = self.diagnostics.len() == resolved_before;
        let network = Stn::new(events.len(), constraints.clone());
        let minimal =
            match network.minimal().map_err(Some).and_then(|m| if resolved { Ok(m) } else { Err(None) }) {
                Err(None) => None,
                Ok(minimal) => Some(minimal),
                Err(Some(cycle)) => {
                    let labelled: Vec<(Span, String)> = cycle
                        .constraints
                        .iter()
                        .map(|&k| (constraint_decls[k].span, constraint_text(constraint_decls[k])))
                        .collect();
                    self.diagnostics.push(diag::chronicle_inconsistent(
                        decl.name.span,
                        &decl.name.name,
                        &labelled,
                    ));
                    None
                }
            };
        if let Some(minimal) = &minimal {
            if let Some((i, j)) = minimal.unbounded_pair() {
                self.diagnostics.push(diag::chronicle_unbounded(
                    decl.name.span,
                    &decl.name.name,
                    names[i],
                    names[j],
                ));
            }
            window = minimal.window().unwrap_or(0);
        }
        let mut holds = Vec::new();
        let mut nevers = Vec::new();
        for clause in &decl.clauses {
            match clause {
                ast::ChronicleClause::Hold(h) => {
                    self.chronicle_formula(&h.formula, &params);
                    let args = mentioned_params(&h.formula, &params.names);
                    if let Some((from, to)) =
                        self.condition_ends(&h.from, &h.to, h.span, &names, minimal.as_ref())
                    {
                        holds.push(hir::ChronicleHold { formula: h.formula.clone(), args, from, to });
                    }
                }
                ast::ChronicleClause::Never(n) => {
                    let (source, args, value) = self.event_pattern(&n.pattern, &params, drafts, signatures);
                    if let Some((from, to)) =
                        self.condition_ends(&n.from, &n.to, n.span, &names, minimal.as_ref())
                    {
                        nevers.push(hir::ChronicleNever { source, args, value, from, to });
                    }
                }
                ast::ChronicleClause::Event(_) | ast::ChronicleClause::Constraint(_) => {}
            }
        }
        hir::Chronicle {
            name: decl.name.name.clone(),
            span: decl.name.span,
            params: decl.params.iter().map(|p| (p.name.name.clone(), p.ty.name.clone())).collect(),
            events,
            constraints,
            holds,
            nevers,
            window,
        }
    }

    /// The source, parameter indices and value of an event pattern.
    fn event_pattern(
        &mut self,
        pattern: &ast::EventPattern,
        params: &Params,
        drafts: &[Draft<'_>],
        signatures: &BTreeMap<String, (Signature, Span)>,
    ) -> (hir::EventSource, Vec<usize>, bool) {
        match &pattern.kind {
            ast::EventPatternKind::Change { predicate, becomes } => {
                self.chronicle_formula(predicate, params);
                let args = mentioned_params(predicate, &params.names);
                (hir::EventSource::Predicate(predicate.clone()), args, *becomes)
            }
            ast::EventPatternKind::Monitor { monitor, args, becomes } => {
                let bindings = match self.names.get(&monitor.name).map(|(n, _)| *n) {
                    Some(Named::Process(id)) => match drafts[id].decl {
                        Decl::Monitor(m) => Some(
                            hir::monitor_bindings(&m.formula)
                                .0
                                .into_iter()
                                .map(|(_, ty)| ty.to_string())
                                .collect::<Vec<_>>(),
                        ),
                        _ => None,
                    },
                    _ => None,
                };
                let Some(bindings) = bindings else {
                    let monitors: Vec<&str> = drafts
                        .iter()
                        .filter(|d| matches!(d.decl, Decl::Monitor(_)))
                        .map(|d| d.name.name.as_str())
                        .collect();
                    self.diagnostics.push(diag::chronicle_not_a_monitor(
                        monitor.span,
                        &monitor.name,
                        &monitors,
                    ));
                    return (hir::EventSource::Monitor(monitor.name.clone()), Vec::new(), *becomes);
                };
                let args = self.event_args(pattern.span, "monitor", monitor, args, &bindings, params);
                (hir::EventSource::Monitor(monitor.name.clone()), args, *becomes)
            }
            ast::EventPatternKind::Recognised { chronicle, args } => {
                let Some((signature, _)) = signatures.get(&chronicle.name) else {
                    let known: Vec<&str> = signatures.keys().map(String::as_str).collect();
                    self.diagnostics.push(diag::unknown_name(
                        chronicle.span,
                        "chronicle",
                        &chronicle.name,
                        &known,
                    ));
                    return (hir::EventSource::Chronicle(chronicle.name.clone()), Vec::new(), true);
                };
                let args =
                    self.event_args(pattern.span, "chronicle", chronicle, args, &signature.params, params);
                (hir::EventSource::Chronicle(chronicle.name.clone()), args, true)
            }
        }
    }

    /// The parameter indices of `args`, checked against the object types `expected`.
    fn event_args(
        &mut self,
        span: Span,
        what: &str,
        name: &ast::Ident,
        args: &[ast::Ident],
        expected: &[String],
        params: &Params,
    ) -> Vec<usize> {
        if args.len() != expected.len() {
            self.diagnostics.push(diag::chronicle_arg_count(
                span,
                what,
                &name.name,
                expected.len(),
                args.len(),
            ));
        }
        let mut indices = Vec::new();
        for (arg, ty) in args.iter().zip(expected) {
            let Some(index) = params.index(&arg.name) else {
                let names: Vec<&str> = params.names.iter().map(String::as_str).collect();
                self.diagnostics.push(diag::chronicle_arg_not_param(arg.span, &arg.name, &names));
                continue;
            };
            if let Some(found) = params.type_name(index)
                && !self.types.is_subtype(found, ty)
            {
                self.diagnostics.push(diag::chronicle_arg_type(arg.span, &arg.name, found, ty));
            }
            indices.push(index);
        }
        indices
    }

    /// Checks a predicate of a chronicle: a state formula over the parameters, which may be
    /// `hysteresis(ENTER, LEAVE)` at its top (and only there: the recogniser keeps its state).
    fn chronicle_formula(&mut self, formula: &ast::Expr, params: &Params) {
        let hysteresis = [crate::registry::Function::new(
            HYSTERESIS,
            vec![ValueType::Bool, ValueType::Bool],
            ValueType::Bool,
            "a fluent: becomes true when the first holds, false when the second holds",
        )];
        let Checker { registry, types, diagnostics, .. } = self;
        FormulaChecker {
            local_functions: &hysteresis,
            ..FormulaChecker::new(registry, types, Context::Chronicle, params.vars(), diagnostics)
        }
        .check_formula(formula);
        let inner: &[ast::Expr] = match &formula.kind {
            ast::ExprKind::Call { func, args } if func.name == HYSTERESIS => args,
            _ => std::slice::from_ref(formula),
        };
        for e in inner {
            if let Some(span) = nested_hysteresis(e) {
                self.diagnostics.push(diag::chronicle_hysteresis_nested(span));
            }
        }
    }

    fn event_index(&mut self, name: &ast::Ident, names: &[&str]) -> Option<usize> {
        let index = names.iter().position(|n| *n == name.name);
        if index.is_none() {
            self.diagnostics.push(diag::unknown_name(name.span, "event", &name.name, names));
        }
        index
    }

    /// A bound in microseconds (`None` inside: infinite); `None` outside after a diagnostic.
    fn stn_bound(&mut self, bound: &ast::StnBound, upper: bool) -> Option<Option<Time>> {
        match bound {
            ast::StnBound::Inf { negative } if *negative != upper => Some(None),
            ast::StnBound::Inf { .. } => {
                let message =
                    if upper { "`-inf` cannot be an upper bound" } else { "`inf` cannot be a lower bound" };
                self.diagnostics.push(diag::bad_bound(stn_bound_span(bound), message));
                None
            }
            ast::StnBound::Duration { negative, value } => match value.micros() {
                Some(us) => Some(Some(if *negative { -us } else { us })),
                None => {
                    self.diagnostics.push(diag::bad_bound(value.span, "this duration is out of range"));
                    None
                }
            },
        }
    }

    /// The node indices of a condition's `from` and `to`, which must come in that order.
    fn condition_ends(
        &mut self,
        from: &ast::Ident,
        to: &ast::Ident,
        span: Span,
        names: &[&str],
        minimal: Option<&kpl_chronicle::stn::Minimal>,
    ) -> Option<(usize, usize)> {
        let (from_index, to_index) = (self.event_index(from, names)?, self.event_index(to, names)?);
        if let Some(minimal) = minimal
            && minimal.lower(from_index, to_index).is_none_or(|lo| lo < 0)
        {
            self.diagnostics.push(diag::chronicle_condition_order(span, &from.name, &to.name));
        }
        Some((from_index, to_index))
    }

    /// Reports chronicles that recognise each other in a cycle (the first one found).
    fn chronicle_cycles(&mut self, chronicles: &[hir::Chronicle]) {
        let index: BTreeMap<&str, usize> =
            chronicles.iter().enumerate().map(|(i, c)| (c.name.as_str(), i)).collect();
        let uses: Vec<Vec<usize>> = chronicles
            .iter()
            .map(|c| {
                let sources = c.events.iter().map(|e| &e.source).chain(c.nevers.iter().map(|n| &n.source));
                sources
                    .filter_map(|s| match s {
                        hir::EventSource::Chronicle(name) => index.get(name.as_str()).copied(),
                        _ => None,
                    })
                    .collect()
            })
            .collect();
        // Depth-first search; a back edge closes a cycle.
        let mut state = vec![0u8; chronicles.len()];
        let mut path = Vec::new();
        for start in 0..chronicles.len() {
            if let Some(cycle) = find_cycle(start, &uses, &mut state, &mut path) {
                let names: Vec<String> = cycle.iter().map(|&i| chronicles[i].name.clone()).collect();
                self.diagnostics.push(diag::chronicle_cycle(chronicles[cycle[0]].span, &names));
                return;
            }
        }
    }
}

/// The monitors whose verdicts are events of `chronicle`, itself or through the chronicles it uses
/// (without cycles among them), each once, in the order met.
fn monitors_used(
    chronicle: &hir::Chronicle,
    chronicles: &[hir::Chronicle],
    out: &mut Vec<String>,
    depth: usize,
) {
    if depth > chronicles.len() {
        return; // a cycle, reported by `chronicle_cycles`
    }
    let sources =
        chronicle.events.iter().map(|e| &e.source).chain(chronicle.nevers.iter().map(|n| &n.source));
    for source in sources {
        match source {
            hir::EventSource::Monitor(m) if !out.contains(m) => out.push(m.clone()),
            hir::EventSource::Chronicle(name) => {
                if let Some(used) = chronicles.iter().find(|c| c.name == *name) {
                    monitors_used(used, chronicles, out, depth + 1);
                }
            }
            _ => {}
        }
    }
}

/// Makes the inputs of every monitor whose verdicts a chronicle has as events (itself or through
/// the chronicles it uses) inputs of the chronicle's recogniser too: it progresses those monitors
/// itself, at its own states (`kpl_runtime::monitor::MonitorVerdicts`), so it reads what they read.
pub(super) fn feed_monitors(chronicles: &[hir::Chronicle], processes: &mut [hir::Process]) {
    for k in 0..processes.len() {
        let hir::ProcessKind::Chronicle(name) = &processes[k].kind else { continue };
        let Some(chronicle) = chronicles.iter().find(|c| c.name == *name) else { continue };
        let mut monitors = Vec::new();
        monitors_used(chronicle, chronicles, &mut monitors, 0);
        let mut inputs = processes[k].inputs.clone();
        for monitor in &monitors {
            let Some(m) = processes
                .iter()
                .find(|p| p.name == *monitor && matches!(p.kind, hir::ProcessKind::Monitor(_)))
            else {
                continue;
            };
            for input in &m.inputs {
                if !inputs.iter().any(|i| i.port == input.port && i.stream.name == input.stream.name) {
                    inputs.push(input.clone());
                }
            }
        }
        processes[k].inputs = inputs;
    }
}

fn find_cycle(
    node: usize,
    uses: &[Vec<usize>],
    state: &mut [u8],
    path: &mut Vec<usize>,
) -> Option<Vec<usize>> {
    match state[node] {
        2 => return None,
        1 => {
            let start = path.iter().position(|&n| n == node).unwrap_or(0);
            let mut cycle = path[start..].to_vec();
            cycle.push(node);
            return Some(cycle);
        }
        _ => {}
    }
    state[node] = 1;
    path.push(node);
    for &next in &uses[node] {
        if let Some(cycle) = find_cycle(next, uses, state, path) {
            return Some(cycle);
        }
    }
    path.pop();
    state[node] = 2;
    None
}

/// The parameters a formula mentions (free, not shadowed by a quantifier), in parameter order.
fn mentioned_params(formula: &ast::Expr, params: &[String]) -> Vec<usize> {
    let mut seen = vec![false; params.len()];
    let mut bound: Vec<&str> = Vec::new();
    walk(formula, params, &mut bound, &mut seen);
    (0..params.len()).filter(|&i| seen[i]).collect()
}

fn walk<'e>(e: &'e ast::Expr, params: &[String], bound: &mut Vec<&'e str>, seen: &mut [bool]) {
    use ast::ExprKind as K;
    match &e.kind {
        K::Bool(_) | K::Number(_) | K::Str(_) | K::Duration(_) => {}
        K::Path(path) => {
            if let Some(first) = path.segments.first()
                && !bound.contains(&first.name.as_str())
                && let Some(i) = params.iter().position(|p| *p == first.name)
            {
                seen[i] = true;
            }
        }
        K::Call { args, .. } | K::And(args) | K::Or(args) => {
            args.iter().for_each(|a| walk(a, params, bound, seen))
        }
        K::Unary { expr, .. } | K::Temporal { body: expr, .. } => walk(expr, params, bound, seen),
        K::Binary { lhs, rhs, .. } | K::Until { lhs, rhs, .. } => {
            walk(lhs, params, bound, seen);
            walk(rhs, params, bound, seen);
        }
        K::Quantified { var, body, .. } => {
            bound.push(&var.name);
            walk(body, params, bound, seen);
            bound.pop();
        }
    }
}

fn stn_bound_span(bound: &ast::StnBound) -> Span {
    match bound {
        ast::StnBound::Duration { value, .. } => value.span,
        ast::StnBound::Inf { .. } => Span::default(),
    }
}

/// `later - earlier in [lo, hi]` as written (for the hint of an inconsistent network).
fn constraint_text(c: &ast::TimeConstraint) -> String {
    let bound = |b: &ast::StnBound| match b {
        ast::StnBound::Inf { negative } => if *negative { "-inf" } else { "inf" }.to_string(),
        ast::StnBound::Duration { negative, value } => {
            let number = match value.value {
                ast::Number::Int(i) => i.to_string(),
                ast::Number::Float(x) => x.to_string(),
            };
            format!("{}{number}{}", if *negative { "-" } else { "" }, value.unit.suffix())
        }
    };
    format!("{} - {} in [{}, {}]", c.later.name, c.earlier.name, bound(&c.lo), bound(&c.hi))
}
