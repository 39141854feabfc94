//! Types of expressions and formulas: names, attribute access, operators, function calls,
//! quantifiers and interval bounds. A formula must be of type `bool`.
//!
//! `ValueType::Any` stands for "unknown": it is the type of a name that failed to resolve, so one
//! mistake is reported once and does not cascade.

use kpl_core::ValueType;
use kpl_syntax::Diagnostic;
use kpl_syntax::ast::{self, BinaryOp, ExprKind, UnaryOp};

use crate::diagnostics as diag;
use crate::hir::{SPEC_TICK, TypeTable};
use crate::registry::{Function, Registry};

/// Where a formula appears, which decides the names it may use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Context {
    /// A link condition: `from` (and `to`, unless establish) are objects.
    Link { to_bound: bool },
    /// A monitor: names are streams; quantifiers range over objects of a type.
    Monitor,
    /// A top-down identification: `this` is the sought object.
    Identify,
    /// A chronicle's predicate or condition: its parameters are objects.
    Chronicle,
    /// The condition of `forget ... after T when C`: `this` is the object, evaluated on its state
    /// at one step (no temporal operators); names are streams, as in monitors.
    Forget,
}

/// Resolves a stream or process name to the type of its samples (monitors only). A monitor names
/// a stream by its first path segment; the rest are attributes (`car_states.speed`). To use a
/// named output (`link.changes`) declare a stream for it.
pub(crate) trait StreamScope {
    fn stream_type(&mut self, name: &ast::Ident) -> Option<Result<ValueType, Diagnostic>>;
    fn stream_names(&self) -> Vec<String>;
}

pub(crate) struct FormulaChecker<'a> {
    pub registry: &'a Registry,
    /// Functions available here besides the registry's (those a link's unit provides).
    pub local_functions: &'a [Function],
    pub types: &'a TypeTable,
    pub context: Context,
    pub vars: Vec<(String, ValueType)>,
    pub streams: Option<&'a mut dyn StreamScope>,
    pub diagnostics: &'a mut Vec<Diagnostic>,
    /// Stream names the formula reads (monitors).
    pub used_streams: Vec<String>,
    /// Object types the formula quantifies over.
    pub quantified_types: Vec<String>,
}

fn is_numeric(t: &ValueType) -> bool {
    matches!(t, ValueType::Int | ValueType::Float | ValueType::Any)
}

fn describe(t: &ValueType) -> String {
    match t {
        ValueType::Record(r) => format!("an object of type `{}`", r.name),
        ValueType::Any => "an unknown type".to_string(),
        other => format!("`{other}`"),
    }
}

/// Whether a value of type `found` can be used where `expected` is needed (ints widen to floats).
pub(crate) fn assignable(found: &ValueType, expected: &ValueType, types: &TypeTable) -> bool {
    match (found, expected) {
        (ValueType::Any, _) | (_, ValueType::Any) => true,
        (ValueType::Int, ValueType::Float) => true,
        (ValueType::Record(a), ValueType::Record(b)) => types.is_subtype(&a.name, &b.name),
        (ValueType::List(a), ValueType::List(b)) => assignable(a, b, types),
        (a, b) => a == b,
    }
}

impl<'a> FormulaChecker<'a> {
    /// A checker for a formula that names no streams and may call only the registry's functions
    /// (set `streams` or `local_functions` on the result where a formula may).
    pub fn new(
        registry: &'a Registry,
        types: &'a TypeTable,
        context: Context,
        vars: Vec<(String, ValueType)>,
        diagnostics: &'a mut Vec<Diagnostic>,
    ) -> Self {
        FormulaChecker {
            registry,
            local_functions: &[],
            types,
            context,
            vars,
            streams: None,
            diagnostics,
            used_streams: Vec::new(),
            quantified_types: Vec::new(),
        }
    }

    /// Checks a formula (must be boolean).
    pub fn check_formula(&mut self, expr: &ast::Expr) {
        let ty = self.expr(expr);
        self.expect_bool(expr, &ty);
    }

    /// A forget condition is about the object's state at one step: a temporal operator there is
    /// an error.
    fn state_only(&mut self, expr: &ast::Expr) {
        if self.context == Context::Forget {
            self.diagnostics.push(diag::temporal_in_forget(expr.span));
        }
    }

    /// What the names of a formula in this context are, for an unknown one.
    fn context_hint(&self) -> &'static str {
        match self.context {
            Context::Link { to_bound: true } => {
                "link conditions talk about `from` and `to` (e.g. `from.pos`)"
            }
            Context::Link { to_bound: false } => {
                "an establish condition talks about `from` (e.g. `from.pos`)"
            }
            Context::Monitor => "monitors name streams and quantified variables",
            Context::Identify => "an identification describes `this`, the object sought (e.g. `this.pos`)",
            Context::Chronicle => {
                "a chronicle's predicates talk about its parameters (e.g. `a.speed > 30.0`, `close(a, b)`)"
            }
            Context::Forget => {
                "a forget condition talks about `this`, the object (e.g. `this.pos`), and streams"
            }
        }
    }

    fn expect_bool(&mut self, expr: &ast::Expr, ty: &ValueType) {
        if !matches!(ty, ValueType::Bool | ValueType::Any) {
            let hint = match ty {
                ValueType::Int | ValueType::Float => "compare it, as in `x > 0.0`",
                _ => "a formula must be true or false: compare values or call a predicate",
            };
            self.diagnostics.push(diag::type_mismatch_hint(expr.span, "a boolean", &describe(ty), hint));
        }
    }

    fn expr(&mut self, expr: &ast::Expr) -> ValueType {
        match &expr.kind {
            ExprKind::Bool(_) => ValueType::Bool,
            ExprKind::Number(ast::Number::Int(_)) => ValueType::Int,
            ExprKind::Number(ast::Number::Float(_)) => ValueType::Float,
            ExprKind::Str(_) => ValueType::Str,
            ExprKind::Duration(_) => ValueType::Duration,
            ExprKind::Path(path) => self.path(path),
            ExprKind::Call { func, args } => self.call(func, args),
            ExprKind::Unary { op: UnaryOp::Not, expr: operand } => {
                let t = self.expr(operand);
                self.expect_bool(operand, &t);
                ValueType::Bool
            }
            ExprKind::Unary { op: UnaryOp::Neg, expr: operand } => {
                let t = self.expr(operand);
                match t {
                    ValueType::Int | ValueType::Float | ValueType::Vec2 | ValueType::Any => t,
                    other => {
                        self.diagnostics.push(diag::type_mismatch(
                            operand.span,
                            "a number or a vector",
                            &describe(&other),
                        ));
                        ValueType::Any
                    }
                }
            }
            ExprKind::And(items) | ExprKind::Or(items) => {
                for item in items {
                    let t = self.expr(item);
                    self.expect_bool(item, &t);
                }
                ValueType::Bool
            }
            ExprKind::Temporal { interval, body, .. } => {
                self.state_only(expr);
                self.interval(interval.as_ref());
                let t = self.expr(body);
                self.expect_bool(body, &t);
                ValueType::Bool
            }
            ExprKind::Until { interval, lhs, rhs } => {
                self.state_only(expr);
                self.interval(interval.as_ref());
                for side in [lhs, rhs] {
                    let t = self.expr(side);
                    self.expect_bool(side, &t);
                }
                ValueType::Bool
            }
            ExprKind::Quantified { var, ty, body, .. } => {
                let record = match self.types.get(&ty.name) {
                    Some(record) => ValueType::Record(record.clone()),
                    None => {
                        let names = kpl_core::suggest::candidates(self.types.names());
                        self.diagnostics.push(diag::unknown_type(ty.span, &ty.name, &names));
                        ValueType::Any
                    }
                };
                if matches!(record, ValueType::Record(_)) && !self.quantified_types.contains(&ty.name) {
                    self.quantified_types.push(ty.name.clone());
                }
                self.vars.push((var.name.clone(), record));
                let t = self.expr(body);
                self.vars.pop();
                self.expect_bool(body, &t);
                ValueType::Bool
            }
            ExprKind::Binary { op, lhs, rhs } => self.binary(expr, *op, lhs, rhs),
        }
    }

    fn binary(&mut self, expr: &ast::Expr, op: BinaryOp, lhs: &ast::Expr, rhs: &ast::Expr) -> ValueType {
        let l = self.expr(lhs);
        let r = self.expr(rhs);
        use ValueType as T;
        match op {
            BinaryOp::Implies => {
                self.expect_bool(lhs, &l);
                self.expect_bool(rhs, &r);
                T::Bool
            }
            BinaryOp::Add | BinaryOp::Sub | BinaryOp::Mul | BinaryOp::Div | BinaryOp::Rem => {
                let additive = matches!(op, BinaryOp::Add | BinaryOp::Sub);
                match (&l, &r) {
                    (T::Any, _) | (_, T::Any) => T::Any,
                    (T::Int, T::Int) => T::Int,
                    (a, b) if is_numeric(a) && is_numeric(b) => T::Float,
                    (T::Vec2, T::Vec2) if additive => T::Vec2,
                    (T::Vec2, b) if is_numeric(b) && matches!(op, BinaryOp::Mul | BinaryOp::Div) => T::Vec2,
                    (a, T::Vec2) if is_numeric(a) && op == BinaryOp::Mul => T::Vec2,
                    (T::Duration, T::Duration) if additive => T::Duration,
                    _ => {
                        self.diagnostics.push(
                            diag::type_mismatch(expr.span, &format!("operands that `{}` applies to", op.symbol()), &format!("{} and {}", describe(&l), describe(&r)))
                                .with_hint("arithmetic works on numbers, on vectors (+, -, and scaling) and on durations (+, -)"),
                        );
                        T::Any
                    }
                }
            }
            BinaryOp::Lt | BinaryOp::Le | BinaryOp::Gt | BinaryOp::Ge => {
                let ok = matches!(
                    (&l, &r),
                    (T::Any, _) | (_, T::Any) | (T::Duration, T::Duration) | (T::Str, T::Str)
                ) || (is_numeric(&l) && is_numeric(&r));
                if !ok {
                    self.diagnostics.push(
                        diag::type_mismatch(
                            expr.span,
                            "two numbers, two durations or two strings to order",
                            &format!("{} and {}", describe(&l), describe(&r)),
                        )
                        .with_hint(
                            "to compare positions use a distance, as in `xydist(a.pos, b.pos) < 10.0`",
                        ),
                    );
                }
                T::Bool
            }
            BinaryOp::Eq | BinaryOp::Ne => {
                let ok = matches!((&l, &r), (T::Any, _) | (_, T::Any))
                    || (is_numeric(&l) && is_numeric(&r))
                    || assignable(&l, &r, self.types)
                    || assignable(&r, &l, self.types);
                if !ok {
                    self.diagnostics.push(diag::type_mismatch(
                        expr.span,
                        "two values of the same type",
                        &format!("{} and {}", describe(&l), describe(&r)),
                    ));
                }
                T::Bool
            }
        }
    }

    fn path(&mut self, path: &ast::Path) -> ValueType {
        let Some(first) = path.segments.first() else { return ValueType::Any };
        let mut ty = if let Some((_, t)) = self.vars.iter().rev().find(|(n, _)| *n == first.name) {
            t.clone()
        } else if first.name == "to" && self.context == (Context::Link { to_bound: false }) {
            self.diagnostics.push(diag::to_in_establish(first.span));
            return ValueType::Any;
        } else if let Some(scope) = self.streams.as_deref_mut() {
            match scope.stream_type(first) {
                Some(Ok(t)) => {
                    if !self.used_streams.contains(&first.name) {
                        self.used_streams.push(first.name.clone());
                    }
                    t
                }
                Some(Err(diagnostic)) => {
                    self.diagnostics.push(diagnostic);
                    return ValueType::Any;
                }
                None => {
                    let mut names = scope.stream_names();
                    names.extend(self.vars.iter().map(|(n, _)| n.clone()));
                    if matches!(self.context, Context::Link { .. }) {
                        names.extend(["from".to_string(), "to".to_string()]);
                    }
                    let names: Vec<&str> = names.iter().map(String::as_str).collect();
                    let what = if self.context == Context::Monitor { "stream" } else { "name" };
                    let mut d = diag::unknown_name(first.span, what, &first.name, &names);
                    if d.hint.is_none() && self.context != Context::Monitor {
                        d = d.with_hint(self.context_hint());
                    }
                    self.diagnostics.push(d);
                    return ValueType::Any;
                }
            }
        } else {
            let mut names: Vec<&str> = self.vars.iter().map(|(n, _)| n.as_str()).collect();
            if matches!(self.context, Context::Link { .. }) {
                names.extend(["from", "to"]);
            }
            let context_hint = self.context_hint();
            let mut d = diag::unknown_name(first.span, "name", &first.name, &names);
            if d.hint.is_none() {
                d = d.with_hint(context_hint);
            }
            self.diagnostics.push(d);
            return ValueType::Any;
        };
        for segment in &path.segments[1..] {
            ty = self.attribute(ty, segment);
        }
        ty
    }

    fn attribute(&mut self, ty: ValueType, field: &ast::Ident) -> ValueType {
        let fields: &[(&str, ValueType)] = match &ty {
            ValueType::Any => return ValueType::Any,
            ValueType::Record(record) => {
                if field.name == "id" {
                    return ValueType::Str;
                }
                // Set by anchoring on percepts and the objects of links (`docs/language.md`).
                if field.name == "measured" {
                    return ValueType::Bool;
                }
                if let Some(f) = record.field(&field.name) {
                    return f.ty.clone();
                }
                let names: Vec<&str> = record.fields.iter().map(|f| &*f.name).collect();
                self.diagnostics.push(diag::unknown_attribute(field.span, &record.name, &field.name, &names));
                return ValueType::Any;
            }
            ValueType::Vec2 => &[("x", ValueType::Float), ("y", ValueType::Float)],
            ValueType::BBox => &[
                ("x1", ValueType::Float),
                ("y1", ValueType::Float),
                ("x2", ValueType::Float),
                ("y2", ValueType::Float),
                ("width", ValueType::Float),
                ("height", ValueType::Float),
                ("center", ValueType::Vec2),
            ],
            _ => &[],
        };
        if let Some((_, t)) = fields.iter().find(|(n, _)| *n == field.name) {
            return t.clone();
        }
        let names: Vec<&str> = fields.iter().map(|(n, _)| *n).collect();
        self.diagnostics.push(diag::unknown_attribute(field.span, &ty.to_string(), &field.name, &names));
        ValueType::Any
    }

    fn call(&mut self, func: &ast::Ident, args: &[ast::Expr]) -> ValueType {
        let arg_types: Vec<ValueType> = args.iter().map(|a| self.expr(a)).collect();
        let local = self.local_functions.iter().find(|f| f.name == func.name);
        let Some(function) = local.or_else(|| self.registry.function(&func.name)) else {
            let mut names: Vec<&str> = self.registry.functions().map(|f| f.name.as_str()).collect();
            names.extend(self.local_functions.iter().map(|f| f.name.as_str()));
            self.diagnostics.push(diag::unknown_function(func.span, &func.name, &names));
            return ValueType::Any;
        };
        if !function.accepts(args.len()) {
            let span = args.first().map_or(func.span, |a| func.span.to(a.span));
            let n = function.params.len();
            let plural = |n: usize| if n == 1 { "1 argument".to_string() } else { format!("{n} arguments") };
            let expected = if function.variadic {
                format!("at least {}", plural(n.saturating_sub(1).max(1)))
            } else {
                plural(n)
            };
            self.diagnostics.push(diag::arity(
                span,
                &function.name,
                &expected,
                args.len(),
                &function.signature(),
            ));
            return function.returns.clone();
        }
        for (i, (arg, found)) in args.iter().zip(&arg_types).enumerate() {
            let expected = function.param(i);
            if !assignable(found, expected, self.types) {
                self.diagnostics.push(
                    diag::type_mismatch(arg.span, &describe(expected), &describe(found))
                        .with_hint(format!("the signature is `{}`", function.signature())),
                );
            }
        }
        function.returns.clone()
    }

    fn interval(&mut self, interval: Option<&ast::Interval>) {
        let Some(interval) = interval else { return };
        let lo = bound_micros(&interval.lo);
        let hi = bound_micros(&interval.hi);
        match (lo, hi) {
            (Err(message), _) | (_, Err(message)) => {
                self.diagnostics.push(diag::bad_bound(interval.span, &message));
            }
            (Ok(Some(lo)), Ok(Some(hi))) if lo > hi => {
                self.diagnostics.push(diag::bad_interval(
                    interval.span,
                    &kpl_core::format_micros(lo),
                    &kpl_core::format_micros(hi),
                ));
            }
            (Ok(None), _) => {
                self.diagnostics
                    .push(diag::bad_bound(interval.span, "`inf` can only be the upper bound of an interval"));
            }
            _ => self.bare_bounds(interval),
        }
    }

    /// Warns about bare numbers other than 0 in an interval (they count milliseconds, which is
    /// easy to miss: `eventually[0, 3]` is 3 ms), with the interval written with units.
    fn bare_bounds(&mut self, interval: &ast::Interval) {
        let bare: Vec<u64> = [interval.lo, interval.hi]
            .iter()
            .filter_map(|b| match b {
                ast::Bound::Ticks(n) if *n != 0 => Some(*n),
                _ => None,
            })
            .collect();
        if bare.is_empty() {
            return;
        }
        let text = |b: &ast::Bound| match b {
            ast::Bound::Ticks(0) => "0".to_string(),
            ast::Bound::Ticks(n) => format!("{n}ms"),
            ast::Bound::Inf => "inf".to_string(),
            ast::Bound::Duration(_) => {
                bound_micros(b).ok().flatten().map_or("?".to_string(), kpl_core::format_micros)
            }
        };
        let fixed = format!("[{}, {}]", text(&interval.lo), text(&interval.hi));
        self.diagnostics.push(diag::bare_bound(interval.span, &bare, &fixed));
    }
}

/// A bound in microseconds (`None` for `inf`). Bare integers count milliseconds in a spec.
pub fn bound_micros(bound: &ast::Bound) -> Result<Option<kpl_core::Time>, String> {
    match bound {
        ast::Bound::Inf => Ok(None),
        ast::Bound::Ticks(n) => i64::try_from(*n)
            .ok()
            .and_then(|n| SPEC_TICK.to_micros(n))
            .filter(|us| *us < (1 << 62))
            .map(Some)
            .ok_or_else(|| format!("bound {n} is too large")),
        ast::Bound::Duration(d) => {
            d.micros().map(Some).ok_or_else(|| "duration bound is out of range".to_string())
        }
    }
}
