//! Lowering the syntax tree of a formula (`kpl_syntax::ast::Expr`) to an [`Mtl`]: names are
//! resolved against a [`Context`], interval bounds are converted to the context's time unit, and
//! every problem becomes a [`CompileError`] with its span (all of them, not just the first).

use kpl_core::{Time, TimeUnit, Value};
use kpl_syntax::ast::{self, BinaryOp, Bound, ExprKind, Quantifier, Span, TemporalOp, UnaryOp};

use crate::context::Context;
use crate::error::CompileError;
use crate::formula::{Formula, Mtl, Window};
use crate::term::{BinOp, Term};

/// Lowers a formula. In an open context ([`Context::open`]) unknown names become new slots;
/// otherwise they are errors.
pub fn lower(expr: &ast::Expr, context: &mut Context) -> Result<Mtl, Vec<CompileError>> {
    let mut lowering = Lowering { context, scope: Vec::new(), errors: Vec::new() };
    let mtl = lowering.formula(expr);
    if lowering.errors.is_empty() { Ok(mtl) } else { Err(lowering.errors) }
}

impl Formula {
    /// Lowers and compiles a formula's syntax tree.
    pub fn from_ast(expr: &ast::Expr, context: &mut Context) -> Result<Formula, Vec<CompileError>> {
        let mtl = lower(expr, context)?;
        Formula::new(&mtl, context).map_err(|e| vec![CompileError::new(expr.span, e.to_string())])
    }
}

/// Converts an interval bound to `unit`. A bare integer counts in `tick_unit`; a duration is
/// converted exactly (an error if it is not a whole number of `unit`).
pub fn bound_in_unit(bound: &Bound, unit: TimeUnit, tick_unit: TimeUnit) -> Result<Option<Time>, String> {
    let micros = match bound {
        Bound::Inf => return Ok(None),
        Bound::Ticks(n) => {
            let n = i64::try_from(*n).map_err(|_| format!("bound {n} is too large"))?;
            tick_unit.to_micros(n).ok_or_else(|| format!("bound {n}{} is too large", tick_unit.suffix()))?
        }
        Bound::Duration(d) => {
            d.micros().ok_or_else(|| "the duration is negative or too large".to_string())?
        }
    };
    if micros % unit.micros() != 0 {
        return Err(format!(
            "{} is not a whole number of {} (the time unit of the time stamps)",
            kpl_core::format_micros(micros),
            unit.suffix()
        ));
    }
    Ok(Some(micros / unit.micros()))
}

struct Lowering<'a> {
    context: &'a mut Context,
    /// Variables bound by enclosing quantifiers, outermost first.
    scope: Vec<String>,
    errors: Vec<CompileError>,
}

impl Lowering<'_> {
    fn error(&mut self, span: Span, message: impl Into<String>) {
        self.errors.push(CompileError::new(span, message));
    }

    fn formula(&mut self, expr: &ast::Expr) -> Mtl {
        match &expr.kind {
            ExprKind::Bool(b) => Mtl::Const(*b),
            ExprKind::Number(_) | ExprKind::Str(_) | ExprKind::Duration(_) => {
                self.error(expr.span, "expected a condition (a boolean), found a constant value");
                Mtl::Const(false)
            }
            ExprKind::Path(_) | ExprKind::Call { .. } => Mtl::Atom(self.term(expr)),
            ExprKind::Unary { op: UnaryOp::Not, expr: inner } => Mtl::not(self.formula(inner)),
            ExprKind::Unary { op: UnaryOp::Neg, .. } => {
                self.error(expr.span, "expected a condition (a boolean), found a negated number");
                Mtl::Const(false)
            }
            ExprKind::Binary { op: BinaryOp::Implies, lhs, rhs } => {
                Mtl::implies(self.formula(lhs), self.formula(rhs))
            }
            ExprKind::Binary { op, .. } if op.is_comparison() => Mtl::Atom(self.term(expr)),
            ExprKind::Binary { op, .. } => {
                self.error(
                    expr.span,
                    format!("expected a condition (a boolean), found arithmetic (`{}`)", op.symbol()),
                );
                Mtl::Const(false)
            }
            ExprKind::And(items) => Mtl::And(items.iter().map(|e| self.formula(e)).collect()),
            ExprKind::Or(items) => Mtl::Or(items.iter().map(|e| self.formula(e)).collect()),
            ExprKind::Temporal { op, interval, body } => {
                let window = self.window(interval.as_ref(), expr.span);
                let body = self.formula(body);
                match op {
                    TemporalOp::Eventually => Mtl::eventually(window, body),
                    TemporalOp::Always => Mtl::always(window, body),
                }
            }
            ExprKind::Until { interval, lhs, rhs } => {
                let window = self.window(interval.as_ref(), expr.span);
                Mtl::until(window, self.formula(lhs), self.formula(rhs))
            }
            ExprKind::Quantified { quantifier, var, ty, body } => {
                let domain = match self.context.domain(&ty.name) {
                    Some(d) => d,
                    None if self.context.is_open() => self.context.declare_object_type(&ty.name),
                    None => {
                        let known: Vec<String> =
                            self.context.domain_names().iter().map(|n| n.to_string()).collect();
                        let mut err =
                            CompileError::new(ty.span, format!("unknown object type `{}`", ty.name));
                        if let Some(best) = closest(&ty.name, known.iter().map(String::as_str)) {
                            err = err.with_help(format!("did you mean `{best}`?"));
                        }
                        self.errors.push(err);
                        0
                    }
                };
                self.scope.push(var.name.clone());
                let body = self.formula(body);
                self.scope.pop();
                match quantifier {
                    Quantifier::Forall => Mtl::Forall(domain, Box::new(body)),
                    Quantifier::Exists => Mtl::Exists(domain, Box::new(body)),
                }
            }
        }
    }

    fn window(&mut self, interval: Option<&ast::Interval>, span: Span) -> Window {
        let Some(interval) = interval else { return Window::UNBOUNDED };
        let unit = self.context.time_unit();
        let tick = self.context.tick_unit();
        let lo = match bound_in_unit(&interval.lo, unit, tick) {
            Ok(Some(lo)) => lo,
            Ok(None) => {
                self.error(interval.span, "the lower bound of an interval cannot be `inf`");
                0
            }
            Err(message) => {
                self.error(interval.span, message);
                0
            }
        };
        let hi = match bound_in_unit(&interval.hi, unit, tick) {
            Ok(hi) => hi,
            Err(message) => {
                self.error(interval.span, message);
                None
            }
        };
        if let Some(hi) = hi
            && hi < lo
        {
            self.error(interval.span, format!("the interval is empty: {lo} is above {hi}"));
            let _ = span;
            return Window::new(lo, None);
        }
        Window::new(lo, hi)
    }

    fn term(&mut self, expr: &ast::Expr) -> Term {
        match &expr.kind {
            ExprKind::Bool(b) => Term::Const(Value::Bool(*b)),
            ExprKind::Number(ast::Number::Int(i)) => Term::Const(Value::Int(*i)),
            ExprKind::Number(ast::Number::Float(x)) => Term::Const(Value::Float(*x)),
            ExprKind::Str(s) => Term::Const(Value::str(s)),
            ExprKind::Duration(d) => match d.micros() {
                Some(us) => Term::Const(Value::Duration(us)),
                None => {
                    self.error(expr.span, "the duration is negative or too large");
                    Term::Const(Value::Duration(0))
                }
            },
            ExprKind::Path(path) => self.path(path),
            ExprKind::Call { func, args } => {
                let args: Vec<Term> = args.iter().map(|a| self.term(a)).collect();
                match self.context.function(&func.name) {
                    Some(id) => {
                        let function = &self.context.functions()[id as usize];
                        if !function.accepts(args.len()) {
                            let message = format!(
                                "`{}` takes {} argument(s), found {}",
                                func.name,
                                function.arity_text(),
                                args.len()
                            );
                            self.error(expr.span, message);
                        }
                        Term::Call(id, args)
                    }
                    None => {
                        let mut err =
                            CompileError::new(func.span, format!("unknown function `{}`", func.name));
                        if let Some(best) = closest(&func.name, self.context.function_names()) {
                            err = err.with_help(format!("did you mean `{best}`?"));
                        }
                        self.errors.push(err);
                        Term::Const(Value::Bool(false))
                    }
                }
            }
            ExprKind::Unary { op, expr: inner } => {
                let inner = Box::new(self.term(inner));
                match op {
                    UnaryOp::Not => Term::Not(inner),
                    UnaryOp::Neg => Term::Neg(inner),
                }
            }
            ExprKind::Binary { op, lhs, rhs } => {
                let op = match op {
                    BinaryOp::Add => BinOp::Add,
                    BinaryOp::Sub => BinOp::Sub,
                    BinaryOp::Mul => BinOp::Mul,
                    BinaryOp::Div => BinOp::Div,
                    BinaryOp::Rem => BinOp::Rem,
                    BinaryOp::Lt => BinOp::Lt,
                    BinaryOp::Le => BinOp::Le,
                    BinaryOp::Gt => BinOp::Gt,
                    BinaryOp::Ge => BinOp::Ge,
                    BinaryOp::Eq => BinOp::Eq,
                    BinaryOp::Ne => BinOp::Ne,
                    BinaryOp::Implies => {
                        // `a -> b` inside a value: `not a or b`.
                        let l = self.term(lhs);
                        let r = self.term(rhs);
                        return Term::binary(BinOp::Or, Term::Not(Box::new(l)), r);
                    }
                };
                let l = self.term(lhs);
                let r = self.term(rhs);
                Term::binary(op, l, r)
            }
            ExprKind::And(items) | ExprKind::Or(items) => {
                let op = if matches!(expr.kind, ExprKind::And(_)) { BinOp::And } else { BinOp::Or };
                let mut terms = items.iter().map(|e| self.term(e));
                let first = terms.next().unwrap_or(Term::Const(Value::Bool(op == BinOp::And)));
                terms.fold(first, |acc, t| Term::binary(op, acc, t))
            }
            ExprKind::Temporal { .. } | ExprKind::Until { .. } | ExprKind::Quantified { .. } => {
                self.error(
                    expr.span,
                    "a temporal operator or quantifier cannot be part of a value (compare values, then combine conditions)",
                );
                Term::Const(Value::Bool(false))
            }
        }
    }

    fn path(&mut self, path: &ast::Path) -> Term {
        let Some((first, rest)) = path.segments.split_first() else {
            self.error(path.span, "empty name");
            return Term::Const(Value::Bool(false));
        };
        let base = if let Some(depth) = self.scope.iter().rposition(|v| *v == first.name) {
            Term::Var(depth as u32)
        } else if let Some(slot) = self.context.slot(&first.name) {
            Term::Slot(slot)
        } else if self.context.is_open() {
            Term::Slot(self.context.declare_value(&first.name))
        } else {
            let mut candidates: Vec<String> =
                self.context.slot_names().iter().map(|n| n.to_string()).collect();
            candidates.extend(self.scope.iter().cloned());
            let mut err = CompileError::new(first.span, format!("unknown name `{}`", first.name));
            if let Some(best) = closest(&first.name, candidates.iter().map(String::as_str)) {
                err = err.with_help(format!("did you mean `{best}`?"));
            }
            self.errors.push(err);
            return Term::Const(Value::Bool(false));
        };
        rest.iter().fold(base, |acc, seg| acc.field(&seg.name))
    }
}

/// The candidate closest to `name`, if close enough to be a likely typo (`kpl_core::closest`).
fn closest<'a>(name: &str, candidates: impl Iterator<Item = &'a str>) -> Option<String> {
    let candidates: Vec<&str> = candidates.collect();
    kpl_core::closest(name, &candidates).map(str::to_string)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failing test should fail loudly
mod tests {
    use super::*;
    use kpl_syntax::ast::DurationLit;

    fn dur(value: ast::Number, unit: TimeUnit) -> Bound {
        Bound::Duration(DurationLit { value, unit, span: Span::default() })
    }

    #[test]
    fn bounds_convert_exactly_or_fail() {
        let ms = TimeUnit::Ms;
        assert_eq!(bound_in_unit(&Bound::Ticks(500), ms, ms), Ok(Some(500)));
        assert_eq!(bound_in_unit(&Bound::Ticks(500), TimeUnit::Us, ms), Ok(Some(500_000)));
        assert_eq!(bound_in_unit(&dur(ast::Number::Int(1), TimeUnit::S), ms, ms), Ok(Some(1000)));
        assert_eq!(bound_in_unit(&dur(ast::Number::Float(1.5), TimeUnit::S), ms, ms), Ok(Some(1500)));
        assert!(bound_in_unit(&dur(ast::Number::Int(1500), TimeUnit::Us), ms, ms).is_err());
        assert_eq!(bound_in_unit(&Bound::Inf, ms, ms), Ok(None));
    }

    #[test]
    fn typos_get_a_suggestion() {
        assert_eq!(closest("xydst", ["xydist", "dist", "abs"].into_iter()), Some("xydist".into()));
        assert_eq!(closest("speed", ["pos", "id"].into_iter()), None);
    }
}
