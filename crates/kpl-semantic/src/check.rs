//! The checker: from a syntax tree and a registry to a checked [`hir::Spec`], reporting every
//! problem it finds in one pass over the file (it never stops at the first).
//!
//! Order of work: object types; the names of processes and streams (one namespace); each
//! process's output type; declared streams and their policies; each process's inputs,
//! parameters and formulas; prediction and forgetting; deployment; the graph and its cycles.

mod chronicle;

use std::collections::BTreeMap;

use kpl_core::{Value, ValueType};
use kpl_syntax::Diagnostic;
use kpl_syntax::ast::{self, Span};

use crate::diagnostics as diag;
use crate::formula::{Context, FormulaChecker, StreamScope, assignable};
use crate::hir::{self, ProcessId, TypeTable};
use crate::registry::{
    CallTypes, Entry, EntryKind, Function, Inputs, ParamProblem, ParamType, Registry, TypeReq,
};
use crate::types;

/// The result of checking: the checked spec when there were no errors, and all diagnostics
/// (errors and warnings) in source order.
#[derive(Debug)]
pub struct Checked {
    pub spec: Option<hir::Spec>,
    pub diagnostics: Vec<Diagnostic>,
}

impl Checked {
    pub fn has_errors(&self) -> bool {
        self.diagnostics.iter().any(Diagnostic::is_error)
    }
}

/// Checks the description of an identification asked for while a spec runs, as an
/// `identify NAME : TYPE where FORMULA` item of the spec is checked: `this` is an object of type
/// `ty` (which must be declared), and the formula may use `registry`'s functions. Returns the
/// errors; an empty list means the description is well typed.
pub fn check_identification(
    registry: &Registry,
    types: &TypeTable,
    ty: &str,
    description: &ast::Expr,
) -> Vec<Diagnostic> {
    let mut diagnostics = Vec::new();
    let Some(record) = types.get(ty) else {
        let names: Vec<&str> = types.names().collect();
        diagnostics.push(diag::unknown_type(description.span, ty, &names));
        return diagnostics;
    };
    let this = vec![("this".to_string(), ValueType::Record(record.clone()))];
    FormulaChecker::new(registry, types, Context::Identify, this, &mut diagnostics)
        .check_formula(description);
    diagnostics
}

/// A spec's errors as text, one per line (`line:column: code message`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SpecErrors(pub String);

impl std::fmt::Display for SpecErrors {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "the spec has errors:\n{}", self.0)
    }
}

impl std::error::Error for SpecErrors {}

/// Parses and checks a spec's text against a registry: the checked spec, or its errors as text.
/// For tests, benchmarks and programs that hold a spec in a string; `kpl check` renders
/// diagnostics with their source instead.
pub fn check_text(text: &str, registry: &Registry) -> Result<hir::Spec, SpecErrors> {
    use std::fmt::Write as _;
    let parse = kpl_syntax::parse(text);
    let index = kpl_syntax::LineIndex::new(text);
    let render = |diagnostics: &[Diagnostic]| {
        let mut out = String::new();
        for d in diagnostics.iter().filter(|d| d.is_error()) {
            let (line, column) = index.line_col(text, d.span.start);
            let _ = writeln!(out, "{line}:{column}: {} {}", d.code, d.message);
        }
        out
    };
    if parse.has_errors() {
        return Err(SpecErrors(render(&parse.diagnostics)));
    }
    let checked = check(&parse.spec, registry);
    match checked.spec {
        Some(spec) if !checked.has_errors() => Ok(spec),
        _ => Err(SpecErrors(render(&checked.diagnostics))),
    }
}

/// Checks a parsed spec against a registry.
pub fn check(spec: &ast::Spec, registry: &Registry) -> Checked {
    check_in(spec, registry, None)
}

/// Checks a parsed spec against a registry, as a spec of the folder `dir`: the checks of calls
/// whose parameters name files (a ROS 2 topic's `msgs`) read them from there.
pub fn check_in(spec: &ast::Spec, registry: &Registry, dir: Option<&std::path::Path>) -> Checked {
    let mut checker = Checker {
        registry,
        diagnostics: Vec::new(),
        types: TypeTable::default(),
        names: BTreeMap::new(),
        dir,
    };
    // Hints look at a bounded number of names in all, so many unknown names stay linear.
    let result = kpl_core::suggest::with_budget(|| checker.run(spec));
    let mut diagnostics = checker.diagnostics;
    let has_errors = diagnostics.iter().any(Diagnostic::is_error);
    if !has_errors {
        diagnostics.extend(crate::attributes::unset(spec, &result, registry));
        diagnostics.extend(crate::attributes::ineffective_params(spec, &result, registry));
    }
    diagnostics.sort_by_key(|d| (d.span.start, d.span.end));
    if has_errors {
        // With errors, "never used" is mostly a consequence of an input that did not resolve.
        diagnostics.retain(|d| !matches!(d.code, diag::UNUSED_STREAM | diag::UNUSED_OUTPUT));
    }
    Checked { spec: if has_errors { None } else { Some(result) }, diagnostics }
}

/// What a name in the process/stream namespace refers to.
#[derive(Debug, Clone, Copy)]
enum Named {
    Process(ProcessId),
    Stream(usize),
}

struct Checker<'a> {
    registry: &'a Registry,
    diagnostics: Vec<Diagnostic>,
    types: TypeTable,
    names: BTreeMap<String, (Named, Span)>,
    /// The spec's folder, for the checks of calls that read files.
    dir: Option<&'a std::path::Path>,
}

/// A process during checking: its declaration and what is known so far.
struct Draft<'s> {
    decl: Decl<'s>,
    name: &'s ast::Ident,
    output: Option<ValueType>,
    ports: Vec<(String, ValueType)>,
}

#[derive(Clone, Copy)]
enum Decl<'s> {
    Process(&'s ast::ProcessDecl),
    Link(&'s ast::LinkDecl),
    Monitor(&'s ast::MonitorDecl),
    Chronicle(&'s ast::ChronicleDecl),
}

impl<'a> Checker<'a> {
    fn run(&mut self, spec: &ast::Spec) -> hir::Spec {
        let type_decls: Vec<&ast::TypeDecl> = spec
            .items
            .iter()
            .filter_map(|i| match i {
                ast::Item::Type(t) => Some(t),
                _ => None,
            })
            .collect();
        self.types = types::collect(&type_decls, &mut self.diagnostics);

        // Names and output types of processes; names of streams.
        let mut drafts: Vec<Draft<'_>> = Vec::new();
        let mut stream_decls: Vec<&ast::StreamDecl> = Vec::new();
        for item in &spec.items {
            let (decl, name) = match item {
                ast::Item::Process(p) => (Decl::Process(p), &p.name),
                ast::Item::Link(l) => (Decl::Link(l), &l.name),
                ast::Item::Monitor(m) => (Decl::Monitor(m), &m.name),
                ast::Item::Chronicle(c) => (Decl::Chronicle(c), &c.name),
                ast::Item::Stream(s) => {
                    if self.declare(&s.name, Named::Stream(stream_decls.len())) {
                        stream_decls.push(s);
                    }
                    continue;
                }
                _ => continue,
            };
            if self.declare(name, Named::Process(drafts.len())) {
                let (output, ports) = self.output_of(decl);
                drafts.push(Draft { decl, name, output, ports });
            }
        }

        // Declared streams.
        let mut streams: Vec<Option<hir::StreamRef>> = Vec::new();
        for decl in &stream_decls {
            let resolved = self.stream_decl(decl, &drafts);
            streams.push(resolved);
        }

        // Who produces objects of each type, and which streams are declared over each process.
        let mut producers: BTreeMap<String, Vec<ProcessId>> = BTreeMap::new();
        for (id, draft) in drafts.iter().enumerate() {
            let is_sink = matches!(draft.decl, Decl::Process(p) if p.kind == ast::ProcessKind::Sink);
            // Object streams: each sample is the list of the objects present (a snapshot).
            if let (Some(ValueType::List(item)), false) = (&draft.output, is_sink)
                && let ValueType::Record(r) = item.as_ref()
            {
                producers.entry(r.name.to_string()).or_default().push(id);
            }
        }
        let mut declared_over: BTreeMap<ProcessId, Vec<usize>> = BTreeMap::new();
        for (index, stream) in streams.iter().enumerate() {
            if let Some(stream) = stream.as_ref().filter(|s| s.port.is_none()) {
                declared_over.entry(stream.producer).or_default().push(index);
            }
        }

        // Inputs, parameters and formulas.
        let mut used_streams = vec![false; stream_decls.len()];
        let mut processes = Vec::with_capacity(drafts.len());
        for (id, draft) in drafts.iter().enumerate() {
            let mut resolver = Resolver {
                checker: self,
                drafts: &drafts,
                streams: &streams,
                used: &mut used_streams,
                producers: &producers,
                declared_over: &declared_over,
            };
            let (kind, inputs) = resolver.process(draft);
            processes.push(hir::Process {
                id,
                name: draft.name.name.clone(),
                span: draft.name.span,
                kind,
                output: draft.output.clone(),
                ports: draft.ports.clone(),
                inputs,
            });
        }
        let (predictions, mut forget) = self.anchoring(spec);
        Resolver {
            checker: self,
            drafts: &drafts,
            streams: &streams,
            used: &mut used_streams,
            producers: &producers,
            declared_over: &declared_over,
        }
        .forget_conditions(spec, &mut forget, &mut processes);
        for (decl, used) in stream_decls.iter().zip(&used_streams) {
            if !used {
                self.diagnostics.push(diag::unused_stream(decl.name.span, &decl.name.name));
            }
        }

        let identifications = self.identifications(spec, &drafts);
        let chronicles = self.chronicles(spec, &drafts);
        chronicle::feed_monitors(&chronicles, &mut processes);
        let deploy = self.deploy(spec, &drafts, &stream_decls);
        let graph = self.graph(&processes);

        let mut stream_map = BTreeMap::new();
        for (decl, stream) in stream_decls.iter().zip(streams) {
            if let Some(stream) = stream {
                stream_map.insert(decl.name.name.clone(), stream);
            }
        }
        hir::Spec {
            types: std::mem::take(&mut self.types),
            processes,
            streams: stream_map,
            predictions,
            forget,
            identifications,
            chronicles,
            deploy,
            graph,
        }
    }

    /// Enters a name into the process/stream namespace; reports duplicates.
    fn declare(&mut self, name: &ast::Ident, named: Named) -> bool {
        if let Some((_, first)) = self.names.get(&name.name) {
            self.diagnostics.push(diag::duplicate(name.span, "name", &name.name, *first));
            return false;
        }
        self.names.insert(name.name.clone(), (named, name.span));
        true
    }

    fn resolve_type(&mut self, ty: &ast::TypeExpr) -> ValueType {
        let types = &self.types;
        match types::resolve_type_expr(ty, &mut |n| types.get(n).cloned()) {
            Ok(t) => t,
            Err(types::TypeError::Unknown(id)) => {
                let names = kpl_core::suggest::candidates(self.types.names());
                self.diagnostics.push(diag::unknown_type(id.span, &id.name, &names));
                ValueType::Any
            }
        }
    }

    fn record_type(&mut self, id: &ast::Ident) -> Option<ValueType> {
        match self.types.get(&id.name) {
            Some(t) => Some(ValueType::Record(t.clone())),
            None => {
                let names = kpl_core::suggest::candidates(self.types.names());
                self.diagnostics.push(diag::unknown_type(id.span, &id.name, &names));
                None
            }
        }
    }

    /// The registry entry a call names, or a diagnostic.
    fn entry(&mut self, kind: EntryKind, call: &ast::Call) -> Option<&'a Entry> {
        let name = call.callee.dotted();
        if let Some(entry) = self.registry.entry(kind, &name) {
            return Some(entry);
        }
        let other_kinds: Vec<&str> = self.registry.entries_named(&name).map(|e| e.kind.noun()).collect();
        let candidates: Vec<&str> = self.registry.entries_of(kind).map(|e| e.name.as_str()).collect();
        self.diagnostics.push(diag::unknown_entry(
            call.callee.span,
            kind.noun(),
            &name,
            &other_kinds,
            &candidates,
        ));
        None
    }

    /// Output type and extra ports of a process, from its declaration and its registry entry.
    fn output_of(&mut self, decl: Decl<'_>) -> (Option<ValueType>, Vec<(String, ValueType)>) {
        match decl {
            Decl::Process(p) => {
                let kind = entry_kind(p.kind);
                let entry = self.entry(kind, &p.call);
                let ports = entry.map_or_else(Vec::new, |e| {
                    e.ports.iter().map(|port| (port.name.clone(), req_type(&port.ty))).collect()
                });
                if p.kind == ast::ProcessKind::Sink {
                    if let Some(output) = &p.output {
                        self.diagnostics.push(diag::sink_with_output(output.span()));
                    }
                    return (None, ports);
                }
                let declared = p.output.as_ref().map(|t| (self.resolve_type(t), t.span()));
                let output = match (declared, entry) {
                    (Some((ty, span)), Some(entry)) => {
                        if !satisfies(&ty, &entry.output, &self.types) {
                            self.diagnostics.push(
                                diag::type_mismatch(
                                    span,
                                    &format!("a type matching {}", entry.output),
                                    &describe(&ty),
                                )
                                .with_hint(format!("`{}` produces {}", entry.name, entry.output)),
                            );
                        }
                        ty
                    }
                    (Some((ty, _)), None) => ty,
                    (None, Some(entry)) => req_type(&entry.output),
                    (None, None) => ValueType::Any,
                };
                (Some(output), ports)
            }
            Decl::Link(l) => {
                // A link's output is an object stream: the list of its `to` objects at each time.
                let to =
                    self.types.get(&l.to_type.name).map_or(ValueType::Any, |t| ValueType::Record(t.clone()));
                (Some(ValueType::List(Box::new(to))), vec![("changes".to_string(), ValueType::Any)])
            }
            Decl::Monitor(m) => {
                let (vars, _) = hir::monitor_bindings(&m.formula);
                if vars.is_empty() {
                    (Some(ValueType::Bool), Vec::new())
                } else {
                    let names: Vec<&str> = vars.iter().map(|(var, _)| *var).collect();
                    (Some(hir::binding_verdict_type(&m.name.name, &names)), Vec::new())
                }
            }
            Decl::Chronicle(c) => {
                let names: Vec<&str> = c.params.iter().map(|p| p.name.name.as_str()).collect();
                (Some(hir::recognition_type(&c.name.name, &names)), Vec::new())
            }
        }
    }

    fn stream_decl(&mut self, decl: &ast::StreamDecl, drafts: &[Draft<'_>]) -> Option<hir::StreamRef> {
        let policy = self.policy(&decl.policies);
        let source = &decl.source;
        let first = source.segments.first()?;
        let (producer, port, ty) = match self.names.get(&first.name).map(|(n, _)| *n) {
            Some(Named::Process(id)) => self.process_output(&drafts[id], id, source)?,
            Some(Named::Stream(_)) => {
                self.diagnostics.push(
                    diag::not_a_stream(source.span, &first.name, "a stream")
                        .with_hint("a stream's source is a process; declare this stream over that process with all the policies it needs"),
                );
                return None;
            }
            None => {
                self.unknown_stream(first);
                return None;
            }
        };
        Some(hir::StreamRef { name: decl.name.name.clone(), producer, port, policy, ty })
    }

    /// The producer, port and type of `process[.port]`.
    fn process_output(
        &mut self,
        draft: &Draft<'_>,
        id: ProcessId,
        path: &ast::Path,
    ) -> Option<(ProcessId, Option<String>, ValueType)> {
        let name = &draft.name.name;
        if matches!(draft.decl, Decl::Process(p) if p.kind == ast::ProcessKind::Sink) {
            self.diagnostics.push(diag::not_a_stream(path.span, name, "a sink"));
            return None;
        }
        match path.segments.as_slice() {
            [_] => Some((id, None, draft.output.clone().unwrap_or(ValueType::Any))),
            [_, port] => match draft.ports.iter().find(|(n, _)| *n == port.name) {
                Some((port_name, ty)) => Some((id, Some(port_name.clone()), ty.clone())),
                None => {
                    let names: Vec<&str> = draft.ports.iter().map(|(n, _)| n.as_str()).collect();
                    self.diagnostics.push(diag::unknown_port(port.span, name, &port.name, &names));
                    None
                }
            },
            [_, _, extra, ..] => {
                self.diagnostics.push(diag::unknown_port(extra.span, name, &extra.name, &[]));
                None
            }
            [] => None,
        }
    }

    fn unknown_stream(&mut self, name: &ast::Ident) {
        if self.types.get(&name.name).is_some() {
            self.diagnostics.push(diag::not_a_stream(name.span, &name.name, "a type"));
            return;
        }
        let candidates = kpl_core::suggest::candidates(self.names.keys().map(String::as_str));
        self.diagnostics.push(diag::unknown_name(name.span, "stream or process", &name.name, &candidates));
    }

    /// Resolves a stream's policies, with defaults, reporting duplicates and conflicts.
    fn policy(&mut self, policies: &[ast::Policy]) -> hir::Policy {
        let mut policy = hir::Policy::default();
        let mut seen: BTreeMap<ast::PolicyClass, &ast::Policy> = BTreeMap::new();
        for p in policies {
            let class = p.kind.class();
            if let Some(first) = seen.get(&class) {
                self.diagnostics.push(diag::policy_duplicate(p.span, class_name(class), first.span));
                continue;
            }
            seen.insert(class, p);
            let micros = |d: &ast::DurationLit| d.micros().unwrap_or(0);
            match &p.kind {
                ast::PolicyKind::NoApproximation => policy.approximation = hir::Approximation::None,
                ast::PolicyKind::UseMostRecent => policy.approximation = hir::Approximation::UseMostRecent,
                ast::PolicyKind::AnyUpdate => policy.change = hir::Change::AnyUpdate,
                ast::PolicyKind::AnyChange => policy.change = hir::Change::AnyChange,
                ast::PolicyKind::SampleEvery(d) => {
                    if micros(d) == 0 {
                        self.diagnostics.push(diag::policy_value(
                            p.span,
                            "`sample every` needs a period above zero",
                            "write e.g. `sample every 100ms`",
                        ));
                    }
                    policy.change = hir::Change::SampleEvery(micros(d));
                }
                ast::PolicyKind::MaxDelay(d) => policy.max_delay = Some(micros(d)),
                ast::PolicyKind::Duration { from, to } => {
                    let (from_us, to_us) = (micros(from), to.as_ref().map(micros));
                    if to_us.is_some_and(|t| t < from_us) {
                        self.diagnostics.push(diag::policy_value(
                            p.span,
                            "the duration window ends before it starts",
                            "write `from A to B` with A <= B",
                        ));
                    }
                    policy.window = Some((from_us, to_us));
                }
                ast::PolicyKind::AnyOrder => policy.order = hir::Order::Any,
                ast::PolicyKind::MonotoneOrder => policy.order = hir::Order::Monotone,
                ast::PolicyKind::StrictOrder => policy.order = hir::Order::Strict,
                ast::PolicyKind::Queue { capacity, overflow } => {
                    if *capacity == 0 {
                        self.diagnostics.push(diag::policy_value(
                            p.span,
                            "a queue needs room for at least one sample",
                            "write e.g. `queue 64 drop oldest`",
                        ));
                    }
                    policy.queue = hir::Queue { capacity: *capacity, overflow: *overflow };
                }
                ast::PolicyKind::Feedback => policy.feedback = true,
            }
        }
        if let Some(sample) =
            seen.get(&ast::PolicyClass::Change).filter(|p| matches!(p.kind, ast::PolicyKind::SampleEvery(_)))
        {
            match seen.get(&ast::PolicyClass::Order) {
                Some(order) if order.kind == ast::PolicyKind::AnyOrder => self.diagnostics.push(diag::policy_conflict(
                    sample.span,
                    "`sample every` needs samples in time order, but the stream accepts `any order`",
                    order.span,
                    "use `monotone order` or `strict order` (the default with `sample every` is monotone)",
                )),
                Some(_) => {}
                None => policy.order = hir::Order::Monotone,
            }
            match seen.get(&ast::PolicyClass::Approximation) {
                Some(approx) if approx.kind == ast::PolicyKind::NoApproximation => self.diagnostics.push(diag::policy_conflict(
                    sample.span,
                    "`sample every` must fill instants that have no sample, but the stream has `no approximation`",
                    approx.span,
                    "use `use most recent` (the default with `sample every`)",
                )),
                Some(_) => {}
                None => policy.approximation = hir::Approximation::UseMostRecent,
            }
        }
        policy
    }

    /// Converts the named parameters of a call, filling defaults; returns the resolved call.
    fn params(&mut self, entry: &Entry, call: &ast::Call) -> hir::Call {
        let mut params = BTreeMap::new();
        let mut seen: BTreeMap<&str, Span> = BTreeMap::new();
        for (name, literal) in call.params() {
            if let Some(first) = seen.get(name.name.as_str()) {
                self.diagnostics.push(diag::duplicate(name.span, "parameter", &name.name, *first));
                continue;
            }
            seen.insert(&name.name, name.span);
            let Some(param) = entry.param_named(&name.name) else {
                if entry.extra_params.is_some() {
                    match literal_value(literal, &ParamType::Any) {
                        Ok(value) => {
                            params.insert(name.name.clone(), value);
                        }
                        Err(found) => self.diagnostics.push(diag::param_type(
                            literal.span,
                            &entry.name,
                            &name.name,
                            "any",
                            &found,
                        )),
                    }
                    continue;
                }
                let names: Vec<&str> = entry.params.iter().map(|p| p.name.as_str()).collect();
                self.diagnostics.push(diag::unknown_param(name.span, &entry.name, &name.name, &names));
                continue;
            };
            match literal_value(literal, &param.ty) {
                Ok(value) => {
                    params.insert(param.name.clone(), value);
                }
                Err(found) => {
                    let mut d = diag::param_type(
                        literal.span,
                        &entry.name,
                        &name.name,
                        &param.ty.to_string(),
                        &found,
                    );
                    if let ParamType::Choice(options) = &param.ty {
                        d = d.with_hint(format!("one of: {}", options.join(", ")));
                    }
                    self.diagnostics.push(d);
                }
            }
        }
        for param in &entry.params {
            if params.contains_key(&param.name) || seen.contains_key(param.name.as_str()) {
                continue;
            }
            match &param.default {
                Some(default) => {
                    params.insert(param.name.clone(), default.clone());
                }
                None => self.diagnostics.push(diag::missing_param(
                    call.span,
                    &entry.name,
                    &param.name,
                    &param.ty.to_string(),
                    &param.doc,
                )),
            }
        }
        hir::Call { entry: entry.name.clone(), params }
    }

    fn anchoring(&mut self, spec: &ast::Spec) -> (Vec<hir::Prediction>, hir::Forget) {
        let mut predictions = Vec::new();
        let mut predicted: BTreeMap<String, Span> = BTreeMap::new();
        let mut forget = hir::Forget::default();
        let mut forget_spans: BTreeMap<Option<String>, Span> = BTreeMap::new();
        for item in &spec.items {
            match item {
                ast::Item::Predict(p) => {
                    let ty = self.record_type(&p.ty);
                    if let Some(first) = predicted.get(&p.ty.name) {
                        self.diagnostics.push(diag::duplicate(
                            p.ty.span,
                            "prediction model for",
                            &p.ty.name,
                            *first,
                        ));
                        continue;
                    }
                    predicted.insert(p.ty.name.clone(), p.ty.span);
                    let Some(entry) = self.entry(EntryKind::Predict, &p.model) else { continue };
                    if let Some(ty) = &ty
                        && !satisfies(ty, &entry.output, &self.types)
                    {
                        self.diagnostics.push(
                            diag::type_mismatch(
                                p.ty.span,
                                &format!("a type with {}", entry.output),
                                &describe(ty),
                            )
                            .with_hint(format!("`{}` needs objects with {}", entry.name, entry.output)),
                        );
                    }
                    self.no_inputs(entry, &p.model);
                    let model = self.params(entry, &p.model);
                    predictions.push(hir::Prediction { ty: p.ty.name.clone(), model });
                }
                ast::Item::Forget(f) => {
                    let key = f.ty.as_ref().map(|t| t.name.clone());
                    let span = f.ty.as_ref().map_or(f.span, |t| t.span);
                    if let Some(ty) = &f.ty {
                        self.record_type(ty);
                    }
                    if let Some(first) = forget_spans.get(&key) {
                        let what = key.clone().unwrap_or_else(|| "all types".into());
                        self.diagnostics.push(diag::duplicate(span, "forget time for", &what, *first));
                        continue;
                    }
                    forget_spans.insert(key.clone(), span);
                    let after = f.after.micros().unwrap_or(0);
                    match key {
                        Some(ty) => {
                            forget.per_type.insert(ty, after);
                        }
                        None => forget.default = Some(after),
                    }
                }
                _ => {}
            }
        }
        (predictions, forget)
    }

    fn identifications(&mut self, spec: &ast::Spec, drafts: &[Draft<'_>]) -> Vec<hir::Identification> {
        let mut out: Vec<hir::Identification> = Vec::new();
        let mut seen: BTreeMap<String, Span> = BTreeMap::new();
        for item in &spec.items {
            let ast::Item::Identify(decl) = item else { continue };
            if let Some(first) =
                seen.get(&decl.name.name).or_else(|| self.names.get(&decl.name.name).map(|(_, s)| s))
            {
                self.diagnostics.push(diag::duplicate(decl.name.span, "name", &decl.name.name, *first));
                continue;
            }
            seen.insert(decl.name.name.clone(), decl.name.span);
            if self.record_type(&decl.ty).is_none() {
                continue;
            }
            let linked_into =
                drafts.iter().any(|d| matches!(d.decl, Decl::Link(l) if l.to_type.name == decl.ty.name));
            if !linked_into {
                self.diagnostics.push(
                    diag::no_producer(
                        decl.ty.span,
                        &decl.ty.name,
                        &format!("identification `{}`", decl.name.name),
                    )
                    .with_hint(format!(
                        "an identification is completed by a link into its type: declare `link ... -> {}`",
                        decl.ty.name
                    )),
                );
            }
            // The same check as an identification asked for while the spec runs.
            let errors = check_identification(self.registry, &self.types, &decl.ty.name, &decl.description);
            self.diagnostics.extend(errors);
            out.push(hir::Identification {
                name: decl.name.name.clone(),
                ty: decl.ty.name.clone(),
                description: decl.description.clone(),
            });
        }
        out
    }

    fn no_inputs(&mut self, entry: &Entry, call: &ast::Call) {
        let given = call.inputs().count();
        let expected = match &entry.inputs {
            Inputs::Fixed(ports) => ports.len(),
            Inputs::Variadic { .. } => return,
        };
        if given != expected {
            self.diagnostics.push(diag::input_count(call.span, &entry.name, &count_words(expected), given));
        }
    }

    fn deploy(
        &mut self,
        spec: &ast::Spec,
        drafts: &[Draft<'_>],
        streams: &[&ast::StreamDecl],
    ) -> Option<hir::Deploy> {
        let mut sections = spec.items.iter().filter_map(|i| match i {
            ast::Item::Deploy(d) => Some(d),
            _ => None,
        });
        let section = sections.next()?;
        for extra in sections {
            self.diagnostics.push(diag::deploy_twice(extra.span, section.span));
        }
        let mut hosts: Vec<hir::Host> = Vec::new();
        let mut host_spans: BTreeMap<&str, Span> = BTreeMap::new();
        let mut placed: BTreeMap<ProcessId, (Span, &str)> = BTreeMap::new();
        for host in &section.hosts {
            if let Some(first) = host_spans.get(host.name.name.as_str()) {
                self.diagnostics.push(diag::duplicate_host(host.name.span, &host.name.name, *first));
                continue;
            }
            host_spans.insert(&host.name.name, host.name.span);
            let registry: &Registry = self.registry;
            let protocols = registry.link_protocols();
            let endpoints = |lits: &[ast::Literal], diagnostics: &mut Vec<Diagnostic>| -> Vec<String> {
                let mut out = Vec::new();
                for lit in lits {
                    if let ast::LitKind::Str(s) = &lit.kind {
                        if !valid_endpoint(s) {
                            diagnostics.push(diag::bad_endpoint(lit.span, s));
                        } else if let Some(protocol) = s.split('/').next()
                            && !protocols.is_empty()
                            && !protocols.iter().any(|p| p == protocol)
                        {
                            diagnostics.push(diag::protocol_not_built_in(lit.span, protocol, protocols));
                        }
                        out.push(s.clone());
                    }
                }
                out
            };
            let listen = endpoints(&host.listen, &mut self.diagnostics);
            let connect = endpoints(&host.connect, &mut self.diagnostics);
            let mut processes = Vec::new();
            for name in &host.processes {
                match self.names.get(&name.name).map(|(n, _)| *n) {
                    Some(Named::Process(id)) => {
                        if let Some((first, first_host)) = placed.get(&id) {
                            self.diagnostics.push(diag::placed_twice(
                                name.span,
                                &name.name,
                                &host.name.name,
                                *first,
                                first_host,
                            ));
                        } else {
                            placed.insert(id, (name.span, &host.name.name));
                            processes.push(id);
                        }
                    }
                    Some(Named::Stream(_)) => {
                        self.diagnostics.push(diag::stream_placed(name.span, &name.name))
                    }
                    None => {
                        let candidates =
                            kpl_core::suggest::candidates(drafts.iter().map(|d| d.name.name.as_str()));
                        self.diagnostics.push(diag::unknown_placed(name.span, &name.name, &candidates));
                    }
                }
            }
            hosts.push(hir::Host { name: host.name.name.clone(), listen, connect, processes });
        }
        let _ = streams;
        for (id, draft) in drafts.iter().enumerate() {
            if !placed.contains_key(&id) {
                self.diagnostics.push(diag::not_placed(
                    draft.name.span,
                    &draft.name.name,
                    decl_kind(draft.decl),
                ));
            }
        }
        let name = section.name.as_ref().and_then(|lit| match &lit.kind {
            ast::LitKind::Str(name) if name.is_empty() => {
                self.diagnostics.push(diag::empty_deployment_name(lit.span));
                None
            }
            ast::LitKind::Str(name) => Some(name.clone()),
            _ => None,
        });
        Some(hir::Deploy { name, hosts })
    }

    fn graph(&mut self, processes: &[hir::Process]) -> hir::ProcessGraph {
        let mut graph = hir::ProcessGraph::default();
        for p in processes {
            graph.nodes.push(graph.graph.add_node(p.id));
        }
        let mut acyclic = petgraph::graph::DiGraph::<ProcessId, ()>::new();
        let acyclic_nodes: Vec<_> = processes.iter().map(|p| acyclic.add_node(p.id)).collect();
        let mut consumed = vec![false; processes.len()];
        for p in processes {
            for input in &p.inputs {
                let from = input.stream.producer;
                consumed[from] = true;
                graph.graph.add_edge(
                    graph.nodes[from],
                    graph.nodes[p.id],
                    hir::Edge {
                        stream: input.stream.name.clone(),
                        port: input.stream.port.clone(),
                        input: input.port.clone(),
                        policy: input.stream.policy.clone(),
                    },
                );
                if !input.stream.policy.feedback {
                    acyclic.add_edge(acyclic_nodes[from], acyclic_nodes[p.id], ());
                }
            }
        }
        for component in petgraph::algo::tarjan_scc(&acyclic) {
            let self_loop = component.len() == 1 && acyclic.contains_edge(component[0], component[0]);
            if component.len() < 2 && !self_loop {
                continue;
            }
            let mut members: Vec<ProcessId> = component.iter().map(|n| acyclic[*n]).collect();
            members.sort_unstable();
            let cycle = cycle_path(&acyclic, &acyclic_nodes, &members);
            let names: Vec<String> = cycle.iter().map(|id| processes[*id].name.clone()).collect();
            self.diagnostics.push(diag::cycle(processes[members[0]].span, &names));
        }
        for p in processes {
            let kind = match p.kind {
                hir::ProcessKind::Source(_) => "source",
                hir::ProcessKind::Compute(_) => "computational unit",
                _ => continue,
            };
            if !consumed[p.id] {
                self.diagnostics.push(diag::unused_output(p.span, &p.name, kind));
            }
        }
        graph
    }
}

/// A cycle through the first member of a strongly connected component, in edge order.
fn cycle_path(
    graph: &petgraph::graph::DiGraph<ProcessId, ()>,
    nodes: &[petgraph::graph::NodeIndex],
    members: &[ProcessId],
) -> Vec<ProcessId> {
    let start = nodes[members[0]];
    // Breadth-first search inside the component back to the start.
    let mut previous: BTreeMap<petgraph::graph::NodeIndex, petgraph::graph::NodeIndex> = BTreeMap::new();
    let mut queue = std::collections::VecDeque::from([start]);
    while let Some(node) = queue.pop_front() {
        for next in graph.neighbors(node) {
            if !members.contains(&graph[next]) {
                continue;
            }
            if next == start {
                let mut path = vec![graph[node]];
                let mut current = node;
                while current != start {
                    current = previous[&current];
                    path.push(graph[current]);
                }
                path.reverse();
                return path;
            }
            if let std::collections::btree_map::Entry::Vacant(e) = previous.entry(next) {
                e.insert(node);
                queue.push_back(next);
            }
        }
    }
    members.to_vec()
}

/// Resolves the inputs of one process (needs the drafts of all processes).
struct Resolver<'c, 'a, 's> {
    checker: &'c mut Checker<'a>,
    drafts: &'c [Draft<'s>],
    streams: &'c [Option<hir::StreamRef>],
    used: &'c mut [bool],
    /// Processes producing objects of each record type (by exact type), in declaration order.
    producers: &'c BTreeMap<String, Vec<ProcessId>>,
    /// The declared streams over each process's default output.
    declared_over: &'c BTreeMap<ProcessId, Vec<usize>>,
}

impl Resolver<'_, '_, '_> {
    fn process(&mut self, draft: &Draft<'_>) -> (hir::ProcessKind, Vec<hir::Input>) {
        match draft.decl {
            Decl::Process(p) => {
                let kind = entry_kind(p.kind);
                let Some(entry) = self.checker.registry.entry(kind, &p.call.callee.dotted()) else {
                    // Reported when the output type was computed; still resolve the inputs.
                    for path in p.call.inputs() {
                        self.stream_ref(path);
                    }
                    let call = hir::Call { entry: p.call.callee.dotted(), params: BTreeMap::new() };
                    return (wrap(p.kind, call), Vec::new());
                };
                let before = self.checker.diagnostics.len();
                let inputs = self.call_inputs(entry, &p.call);
                let call = self.checker.params(entry, &p.call);
                if let Some(check) = &entry.check
                    && self.checker.diagnostics.len() == before
                {
                    let types: Vec<ValueType> = inputs.iter().map(|i| i.stream.ty.clone()).collect();
                    let seen = CallTypes {
                        params: &call.params,
                        output: draft.output.as_ref(),
                        inputs: &types,
                        dir: self.checker.dir,
                    };
                    for problem in (check.0)(&seen) {
                        let span = param_span(&p.call, &problem);
                        self.checker.diagnostics.push(diag::param_problem(span, &entry.name, &problem));
                    }
                }
                (wrap(p.kind, call), inputs)
            }
            Decl::Link(l) => self.link(l),
            Decl::Monitor(m) => self.monitor(m),
            Decl::Chronicle(c) => self.chronicle_process(c),
        }
    }

    /// A chronicle's recogniser: its inputs are the object streams of the parameter types of the
    /// chronicle and of every chronicle it uses (they are recognised inside it, at the same
    /// instants). The chronicle itself is checked later ([`Checker::chronicles`]).
    fn chronicle_process(&mut self, c: &ast::ChronicleDecl) -> (hir::ProcessKind, Vec<hir::Input>) {
        let mut types: Vec<String> = Vec::new();
        let mut seen: Vec<&str> = Vec::new();
        let mut todo: Vec<&ast::ChronicleDecl> = vec![c];
        while let Some(decl) = todo.pop() {
            if seen.contains(&decl.name.name.as_str()) {
                continue;
            }
            seen.push(&decl.name.name);
            for p in &decl.params {
                if !types.contains(&p.ty.name) {
                    types.push(p.ty.name.clone());
                }
            }
            let patterns = decl.clauses.iter().filter_map(|clause| match clause {
                ast::ChronicleClause::Event(e) => Some(&e.pattern),
                ast::ChronicleClause::Never(n) => Some(&n.pattern),
                _ => None,
            });
            for pattern in patterns {
                let ast::EventPatternKind::Recognised { chronicle, .. } = &pattern.kind else { continue };
                let used = self.drafts.iter().find_map(|d| match d.decl {
                    Decl::Chronicle(u) if u.name.name == chronicle.name => Some(u),
                    _ => None,
                });
                todo.extend(used);
            }
        }
        let mut inputs = Vec::new();
        for ty in &types {
            if self.checker.types.get(ty).is_none() {
                continue; // reported when the chronicle is checked
            }
            let producers = self.producers_of(ty, &c.name.name);
            if producers.is_empty() {
                self.checker.diagnostics.push(diag::no_producer(
                    c.name.span,
                    ty,
                    &format!("chronicle `{}`", c.name.name),
                ));
            }
            for stream in producers {
                if !inputs.iter().any(|i: &hir::Input| i.stream.name == stream.name) {
                    inputs.push(hir::Input { port: "objects".into(), stream });
                }
            }
        }
        (hir::ProcessKind::Chronicle(c.name.name.clone()), inputs)
    }

    /// A stream reference in an input position.
    fn stream_ref(&mut self, path: &ast::Path) -> Option<hir::StreamRef> {
        let first = path.segments.first()?;
        match self.checker.names.get(&first.name).map(|(n, _)| *n) {
            Some(Named::Stream(index)) => {
                self.used[index] = true;
                if let Some(extra) = path.segments.get(1) {
                    self.checker.diagnostics.push(
                        diag::unknown_port(extra.span, &first.name, &extra.name, &[])
                            .with_hint("a declared stream has no named outputs; name the process output in the stream declaration"),
                    );
                    return None;
                }
                self.streams[index].clone()
            }
            Some(Named::Process(id)) => {
                let (producer, port, ty) = self.checker.process_output(&self.drafts[id], id, path)?;
                let name = path.dotted();
                Some(hir::StreamRef { name, producer, port, policy: hir::Policy::default(), ty })
            }
            None => {
                self.checker.unknown_stream(first);
                None
            }
        }
    }

    fn call_inputs(&mut self, entry: &Entry, call: &ast::Call) -> Vec<hir::Input> {
        let paths: Vec<&ast::Path> = call.inputs().collect();
        let ports: Vec<(String, TypeReq)> = match &entry.inputs {
            Inputs::Fixed(ports) => {
                if ports.len() != paths.len() {
                    self.checker.diagnostics.push(diag::input_count(
                        call.span,
                        &entry.name,
                        &count_words(ports.len()),
                        paths.len(),
                    ));
                }
                ports.iter().map(|p| (p.name.clone(), p.ty.clone())).collect()
            }
            Inputs::Variadic { min, port } => {
                if paths.len() < *min {
                    self.checker.diagnostics.push(diag::input_count(
                        call.span,
                        &entry.name,
                        &format!("at least {}", count_words(*min)),
                        paths.len(),
                    ));
                }
                (0..paths.len()).map(|i| (format!("{}{i}", port.name), port.ty.clone())).collect()
            }
        };
        let mut inputs = Vec::new();
        for (path, (port, req)) in paths.iter().zip(ports) {
            let Some(stream) = self.stream_ref(path) else { continue };
            if !satisfies(&stream.ty, &req, &self.checker.types) {
                self.checker.diagnostics.push(
                    diag::type_mismatch(
                        path.span,
                        &format!("a stream of {req}"),
                        &format!("a stream of {}", describe(&stream.ty)),
                    )
                    .with_hint(format!("input `{port}` of `{}` takes {req}", entry.name)),
                );
            }
            inputs.push(hir::Input { port, stream });
        }
        inputs
    }

    /// The streams that carry objects of exactly type `ty`: for each producer, its one declared
    /// stream if it has exactly one, else the producer's output directly. Subtypes do not count:
    /// in an object linkage structure an on-road object `oo3` is a different object from the
    /// world object `wo5` it was linked from, though its type inherits `WorldObject`'s attributes.
    fn producers_of(&mut self, ty: &str, consumer: &str) -> Vec<hir::StreamRef> {
        let mut refs = Vec::new();
        for &id in self.producers.get(ty).map_or(&[][..], Vec::as_slice) {
            let draft = &self.drafts[id];
            if draft.name.name == consumer {
                continue;
            }
            match self.declared_over.get(&id).map(Vec::as_slice) {
                Some([one]) => {
                    self.used[*one] = true;
                    if let Some(s) = self.streams[*one].clone() {
                        refs.push(s);
                    }
                }
                _ => refs.push(hir::StreamRef {
                    name: draft.name.name.clone(),
                    producer: id,
                    port: None,
                    policy: hir::Policy::default(),
                    ty: draft.output.clone().unwrap_or(ValueType::Any),
                }),
            }
        }
        refs
    }

    fn link(&mut self, l: &ast::LinkDecl) -> (hir::ProcessKind, Vec<hir::Input>) {
        let from = self.checker.record_type(&l.from_type);
        let to = self.checker.record_type(&l.to_type);
        let mut inputs = Vec::new();

        // The stream(s) of `from` objects.
        let explicit: Vec<&ast::Path> = l
            .clauses
            .iter()
            .filter_map(|c| match c {
                ast::LinkClause::Input(p, _) => Some(p),
                ast::LinkClause::Condition(_) => None,
            })
            .collect();
        if explicit.is_empty() {
            if from.is_some() {
                let producers = self.producers_of(&l.from_type.name, &l.name.name);
                if producers.is_empty() {
                    self.checker.diagnostics.push(diag::no_producer(
                        l.from_type.span,
                        &l.from_type.name,
                        &format!("link `{}`", l.name.name),
                    ));
                }
                inputs.extend(producers.into_iter().map(|stream| hir::Input { port: "from".into(), stream }));
            }
        } else {
            for path in explicit {
                let Some(stream) = self.stream_ref(path) else { continue };
                if let Some(from_ty) = &from
                    && !assignable(
                        &stream.ty,
                        &ValueType::List(Box::new(from_ty.clone())),
                        &self.checker.types,
                    )
                {
                    self.checker.diagnostics.push(diag::link_input_type(
                        path.span,
                        &path.dotted(),
                        &describe(&stream.ty),
                        &l.from_type.name,
                    ));
                }
                inputs.push(hir::Input { port: "from".into(), stream });
            }
        }

        // A link steps at the states of its inputs; `feedback` inputs are never waited for.
        if !inputs.is_empty() && inputs.iter().all(|i: &hir::Input| i.stream.policy.feedback) {
            self.checker.diagnostics.push(diag::link_input_feedback(l.name.span, &l.name.name));
        }

        // The link unit: its own inputs and parameters; it must be able to fill `to` objects.
        let via_entry = self.checker.entry(EntryKind::Link, &l.via);
        let provided: &[Function] = via_entry.map_or(&[], |e| e.provides.as_slice());
        let via = match via_entry {
            Some(entry) => {
                if let Some(to_ty) = &to
                    && !satisfies(to_ty, &entry.output, &self.checker.types)
                {
                    self.checker.diagnostics.push(
                        diag::type_mismatch(
                            l.to_type.span,
                            &format!("a type with {}", entry.output),
                            &describe(to_ty),
                        )
                        .with_hint(format!("`{}` fills objects with {}", entry.name, entry.output)),
                    );
                }
                inputs.extend(self.call_inputs(entry, &l.via));
                self.checker.params(entry, &l.via)
            }
            None => hir::Call { entry: l.via.callee.dotted(), params: BTreeMap::new() },
        };

        // The three conditions, each exactly once.
        let mut conditions: BTreeMap<&str, &ast::Condition> = BTreeMap::new();
        for clause in &l.clauses {
            let ast::LinkClause::Condition(c) = clause else { continue };
            let keyword = c.kind.keyword();
            if let Some(first) = conditions.get(keyword) {
                self.checker.diagnostics.push(diag::condition_twice(c.span, keyword, first.span));
                continue;
            }
            conditions.insert(keyword, c);
            let mut vars = vec![("from".to_string(), from.clone().unwrap_or(ValueType::Any))];
            let to_bound = c.kind != ast::ConditionKind::Establish;
            if to_bound {
                vars.push(("to".to_string(), to.clone().unwrap_or(ValueType::Any)));
            }
            // Names other than `from` and `to` are streams, as in monitors (a camera's
            // `in_view(cam, to.pos)`): they become inputs of the link process (port `env`).
            for stream in self.scoped_formula(&c.formula, Context::Link { to_bound }, vars, provided).0 {
                if !inputs.iter().any(|i| i.port == "env" && i.stream.name == stream.name) {
                    inputs.push(hir::Input { port: "env".into(), stream });
                }
            }
        }
        let mut formula = |kind: ast::ConditionKind| -> ast::Expr {
            match conditions.get(kind.keyword()) {
                Some(c) => c.formula.clone(),
                None => {
                    self.checker.diagnostics.push(diag::condition_missing(
                        l.name.span,
                        &l.name.name,
                        kind.keyword(),
                    ));
                    ast::Expr { kind: ast::ExprKind::Bool(false), span: l.span }
                }
            }
        };
        let establish = formula(ast::ConditionKind::Establish);
        let reestablish = formula(ast::ConditionKind::Reestablish);
        let maintain = formula(ast::ConditionKind::Maintain);
        let link = hir::Link {
            from_type: l.from_type.name.clone(),
            to_type: l.to_type.name.clone(),
            via,
            establish,
            reestablish,
            maintain,
        };
        (hir::ProcessKind::Link(Box::new(link)), inputs)
    }

    fn monitor(&mut self, m: &ast::MonitorDecl) -> (hir::ProcessKind, Vec<hir::Input>) {
        let (refs, quantified) = self.scoped_formula(&m.formula, Context::Monitor, Vec::new(), &[]);
        let used_streams: Vec<String> = refs.iter().map(|r| r.name.clone()).collect();
        let mut inputs: Vec<hir::Input> =
            refs.into_iter().map(|stream| hir::Input { port: "state".into(), stream }).collect();
        for ty in &quantified {
            let producers = self.producers_of(ty, &m.name.name);
            if producers.is_empty() {
                self.checker.diagnostics.push(diag::no_producer(
                    m.name.span,
                    ty,
                    &format!("monitor `{}`", m.name.name),
                ));
            }
            inputs.extend(producers.into_iter().map(|stream| hir::Input { port: "objects".into(), stream }));
        }
        let monitor =
            hir::Monitor { formula: m.formula.clone(), streams: used_streams, object_types: quantified };
        (hir::ProcessKind::Monitor(monitor), inputs)
    }

    /// Checks a formula whose names besides `vars` are streams (as a monitor's are), and gives
    /// the streams it reads, in the order it names them, and the object types it quantifies over.
    fn scoped_formula(
        &mut self,
        expr: &ast::Expr,
        context: Context,
        vars: Vec<(String, ValueType)>,
        local_functions: &[Function],
    ) -> (Vec<hir::StreamRef>, Vec<String>) {
        // Borrow the checker's parts separately: the formula checker reads the types and the
        // registry while the scope resolves stream names and marks streams used.
        let Checker { registry, types, diagnostics, names, .. } = &mut *self.checker;
        let mut scope = MonitorScope {
            refs: BTreeMap::new(),
            names,
            drafts: self.drafts,
            streams: self.streams,
            used: self.used,
        };
        let mut checker = FormulaChecker {
            streams: Some(&mut scope),
            local_functions,
            ..FormulaChecker::new(registry, types, context, vars, diagnostics)
        };
        checker.check_formula(expr);
        let used_streams = std::mem::take(&mut checker.used_streams);
        let quantified = std::mem::take(&mut checker.quantified_types);
        drop(checker);
        (used_streams.iter().filter_map(|name| scope.refs.get(name).cloned()).collect(), quantified)
    }

    /// The conditions of `forget ... after T when C` (`this` is an object of the declaration's
    /// type, or of any type): checked, their streams recorded, and those streams made inputs
    /// (port `env`) of the links into the types each condition applies to.
    fn forget_conditions(
        &mut self,
        spec: &ast::Spec,
        forget: &mut hir::Forget,
        processes: &mut [hir::Process],
    ) {
        for item in &spec.items {
            let ast::Item::Forget(f) = item else { continue };
            let Some(sooner) = &f.sooner else { continue };
            let key = f.ty.as_ref().map(|t| t.name.clone());
            let this = key
                .as_deref()
                .and_then(|ty| self.checker.types.get(ty))
                .map_or(ValueType::Any, |r| ValueType::Record(r.clone()));
            let (refs, _) = self.scoped_formula(
                &sooner.condition,
                Context::Forget,
                vec![("this".to_string(), this)],
                &[],
            );
            if let Some(ty) = &f.ty
                && !processes
                    .iter()
                    .any(|p| matches!(&p.kind, hir::ProcessKind::Link(l) if l.to_type == ty.name))
            {
                self.checker.diagnostics.push(diag::forget_when_ineffective(sooner.span, &ty.name));
            }
            let (Some(after), Some(shorter)) = (f.after.micros(), sooner.after.micros()) else { continue };
            if shorter >= after {
                self.checker.diagnostics.push(diag::forget_not_sooner(
                    sooner.after.span,
                    &duration_text(&sooner.after),
                    &duration_text(&f.after),
                ));
            }
            // Only the declaration checked first counts (a second one is reported as a duplicate).
            if forget.sooner.contains_key(&key) {
                continue;
            }
            forget.sooner.insert(
                key.clone(),
                hir::Sooner {
                    after: shorter,
                    condition: sooner.condition.clone(),
                    streams: refs.iter().map(|r| r.name.clone()).collect(),
                },
            );
            for process in processes.iter_mut() {
                let hir::ProcessKind::Link(link) = &process.kind else { continue };
                let applies = match &key {
                    Some(ty) => link.to_type == *ty,
                    None => !forget.per_type.contains_key(&link.to_type),
                };
                if !applies {
                    continue;
                }
                for stream in &refs {
                    if !process.inputs.iter().any(|i| i.port == "env" && i.stream.name == stream.name) {
                        process.inputs.push(hir::Input { port: "env".into(), stream: stream.clone() });
                    }
                }
            }
        }
    }
}

/// Resolves the stream names a monitor's formula uses.
struct MonitorScope<'r, 's> {
    refs: BTreeMap<String, hir::StreamRef>,
    names: &'r BTreeMap<String, (Named, Span)>,
    drafts: &'r [Draft<'s>],
    streams: &'r [Option<hir::StreamRef>],
    used: &'r mut [bool],
}

impl StreamScope for MonitorScope<'_, '_> {
    fn stream_type(&mut self, name: &ast::Ident) -> Option<Result<ValueType, Diagnostic>> {
        if let Some(stream) = self.refs.get(&name.name) {
            return Some(Ok(stream.ty.clone()));
        }
        let path = ast::Path { segments: vec![name.clone()], span: name.span };
        match self.names.get(&name.name).map(|(n, _)| *n) {
            Some(Named::Stream(index)) => {
                self.used[index] = true;
                // A declared stream whose own declaration failed was reported there.
                let Some(stream) = self.streams[index].clone() else {
                    return Some(Ok(ValueType::Any));
                };
                let ty = stream.ty.clone();
                self.refs.insert(name.name.clone(), stream);
                Some(Ok(ty))
            }
            Some(Named::Process(id)) => {
                let draft = &self.drafts[id];
                if matches!(draft.decl, Decl::Process(p) if p.kind == ast::ProcessKind::Sink) {
                    return Some(Err(diag::not_a_stream(name.span, &name.name, "a sink")));
                }
                let ty = draft.output.clone().unwrap_or(ValueType::Any);
                let stream = hir::StreamRef {
                    name: path.dotted(),
                    producer: id,
                    port: None,
                    policy: hir::Policy::default(),
                    ty: ty.clone(),
                };
                self.refs.insert(name.name.clone(), stream);
                Some(Ok(ty))
            }
            None => None,
        }
    }

    fn stream_names(&self) -> Vec<String> {
        kpl_core::suggest::candidates(self.names.keys().map(String::as_str))
            .into_iter()
            .map(str::to_string)
            .collect()
    }
}

/// `500ms`, `1.5s`: a duration as written.
fn duration_text(d: &ast::DurationLit) -> String {
    match d.value {
        ast::Number::Int(i) => format!("{i}{}", d.unit.suffix()),
        ast::Number::Float(x) => format!("{x}{}", d.unit.suffix()),
    }
}

fn wrap(kind: ast::ProcessKind, call: hir::Call) -> hir::ProcessKind {
    match kind {
        ast::ProcessKind::Source => hir::ProcessKind::Source(call),
        ast::ProcessKind::Compute => hir::ProcessKind::Compute(call),
        ast::ProcessKind::Sink => hir::ProcessKind::Sink(call),
    }
}

fn entry_kind(kind: ast::ProcessKind) -> EntryKind {
    match kind {
        ast::ProcessKind::Source => EntryKind::Source,
        ast::ProcessKind::Compute => EntryKind::Compute,
        ast::ProcessKind::Sink => EntryKind::Sink,
    }
}

fn decl_kind(decl: Decl<'_>) -> &'static str {
    match decl {
        Decl::Process(p) => p.kind.keyword(),
        Decl::Link(_) => "link",
        Decl::Monitor(_) => "monitor",
        Decl::Chronicle(_) => "chronicle",
    }
}

fn class_name(class: ast::PolicyClass) -> &'static str {
    match class {
        ast::PolicyClass::Approximation => "approximation",
        ast::PolicyClass::Change => "change",
        ast::PolicyClass::Delay => "delay",
        ast::PolicyClass::Duration => "duration",
        ast::PolicyClass::Order => "order",
        ast::PolicyClass::Queue => "queue",
        ast::PolicyClass::Feedback => "feedback",
    }
}

fn count_words(n: usize) -> String {
    match n {
        0 => "no input streams".into(),
        1 => "one input stream".into(),
        n => format!("{n} input streams"),
    }
}

fn describe(t: &ValueType) -> String {
    match t {
        ValueType::Record(r) => format!("`{}`", r.name),
        other => format!("`{other}`"),
    }
}

/// The type a requirement stands for when nothing more is declared.
fn req_type(req: &TypeReq) -> ValueType {
    match req {
        TypeReq::Exact(t) => t.clone(),
        TypeReq::Objects(_) => ValueType::List(Box::new(ValueType::Any)),
        TypeReq::Any | TypeReq::Fields(_) => ValueType::Any,
    }
}

/// Whether values of `ty` meet `req`.
pub(crate) fn satisfies(ty: &ValueType, req: &TypeReq, types: &TypeTable) -> bool {
    match req {
        TypeReq::Any => true,
        TypeReq::Exact(t) => assignable(ty, t, types),
        TypeReq::Fields(fields) => match ty {
            ValueType::Any => true,
            ValueType::Record(r) => {
                fields.iter().all(|(name, t)| r.field(name).is_some_and(|f| assignable(&f.ty, t, types)))
            }
            _ => false,
        },
        TypeReq::Objects(fields) => match ty {
            ValueType::Any => true,
            ValueType::List(item) => satisfies(item, &TypeReq::Fields(fields.clone()), types),
            _ => false,
        },
    }
}

/// A zenoh endpoint: `protocol/address` (`tcp/127.0.0.1:7447`).
fn valid_endpoint(s: &str) -> bool {
    let Some((protocol, address)) = s.split_once('/') else { return false };
    let protocol_ok = !protocol.is_empty() && protocol.chars().all(|c| c.is_ascii_lowercase() || c == '-');
    let address = address.split('#').next().unwrap_or("");
    let needs_port = matches!(protocol, "tcp" | "udp" | "tls" | "quic" | "ws");
    let port_ok = !needs_port
        || address
            .rsplit_once(':')
            .is_some_and(|(host, port)| !host.is_empty() && port.parse::<u16>().is_ok());
    protocol_ok && !address.is_empty() && port_ok
}

/// Where a parameter check's problem is in the spec: the part of the string it names, when the
/// string literal is written without escapes before it; else the literal (the element of a list,
/// the parameter's value), or the call when the parameter was left to its default.
fn param_span(call: &ast::Call, problem: &ParamProblem) -> Span {
    let Some((_, literal)) = call.params().find(|(name, _)| name.name == problem.param) else {
        return call.callee.span;
    };
    let literal = match (&literal.kind, problem.element) {
        (ast::LitKind::List(items), Some(i)) => items.get(i).unwrap_or(literal),
        _ => literal,
    };
    match &literal.kind {
        ast::LitKind::Str(text)
            if literal.span.end - literal.span.start == text.len() as u32 + 2
                && problem.range.0 < problem.range.1
                && problem.range.1 <= text.len() =>
        {
            let start = literal.span.start + 1;
            Span::new(start + problem.range.0 as u32, start + problem.range.1 as u32)
        }
        _ => literal.span,
    }
}

/// Converts a parameter literal to the value the parameter type asks for, or says what it found.
fn literal_value(literal: &ast::Literal, ty: &ParamType) -> Result<Value, String> {
    use ast::LitKind as L;
    let found = || -> String {
        match &literal.kind {
            L::Bool(_) => "a boolean".into(),
            L::Number(ast::Number::Int(_)) => "an integer".into(),
            L::Number(ast::Number::Float(_)) => "a float".into(),
            L::Str(_) => "a string".into(),
            L::Duration(_) => "a duration".into(),
            L::List(_) => "a list".into(),
        }
    };
    match (ty, &literal.kind) {
        (ParamType::Bool | ParamType::Any, L::Bool(b)) => Ok(Value::Bool(*b)),
        (ParamType::Int | ParamType::Any, L::Number(ast::Number::Int(i))) => Ok(Value::Int(*i)),
        (ParamType::Float, L::Number(n)) => Ok(Value::Float(n.as_f64())),
        (ParamType::Any, L::Number(ast::Number::Float(x))) => Ok(Value::Float(*x)),
        (ParamType::Str | ParamType::Any, L::Str(s)) => Ok(Value::str(s)),
        (ParamType::Choice(options), L::Str(s)) if options.iter().any(|o| o == s) => Ok(Value::str(s)),
        (ParamType::Duration | ParamType::Any, L::Duration(d)) => {
            Ok(Value::Duration(d.micros().unwrap_or(0)))
        }
        (ParamType::List(item), L::List(items)) => {
            let values: Result<Vec<Value>, String> = items.iter().map(|i| literal_value(i, item)).collect();
            Ok(Value::List(values?.into()))
        }
        (ParamType::Any, L::List(items)) => {
            let values: Result<Vec<Value>, String> =
                items.iter().map(|i| literal_value(i, &ParamType::Any)).collect();
            Ok(Value::List(values?.into()))
        }
        (ParamType::Choice(_), L::Str(s)) => Err(format!("\"{s}\"")),
        _ => Err(found()),
    }
}
