//! The canonical layout of KPL files (`kpl fmt`).
//!
//! Properties (tested): formatting is idempotent, keeps every comment, and does not change the
//! tree: `parse(format(x)) == parse(x)` up to spans. Layout rules:
//! - one item per line, except `link` and `deploy` blocks (and type declarations that do not fit
//!   in [`MAX_WIDTH`] columns or hold comments), which put one member per line, indented by two
//!   spaces; condition keywords in a link block are aligned;
//! - blank lines between items are kept, but several collapse into one;
//! - single spaces around binary operators and after commas; parentheses only where precedence
//!   needs them, plus around arithmetic and comparisons under `not` / `eventually` / `always`;
//! - comments stay before the element they preceded, or at the end of its line.

use std::fmt::Write;

use crate::ast::{self, Span};
use crate::diagnostic::Diagnostic;
use crate::lex::Comment;
use crate::parser::precedence_of;

/// Lines longer than this are broken where the layout allows it.
pub const MAX_WIDTH: usize = 100;
const INDENT: &str = "  ";

/// Formats a file. Refuses (returns the diagnostics) when it does not parse cleanly.
pub fn format(source: &str) -> Result<String, Vec<Diagnostic>> {
    let parse = crate::parse(source);
    if parse.has_errors() {
        return Err(parse.diagnostics);
    }
    Ok(format_parsed(source, &parse.spec, &parse.comments))
}

/// Formats a parsed file; `comments` and the spans in `spec` must come from `source`.
pub fn format_parsed(source: &str, spec: &ast::Spec, comments: &[Comment]) -> String {
    let mut f = Formatter { source, comments, next_comment: 0, out: String::new(), last_end: 0 };
    for item in &spec.items {
        f.item(item);
    }
    f.leading_comments(u32::MAX, "");
    if !f.out.is_empty() && !f.out.ends_with('\n') {
        f.out.push('\n');
    }
    f.out
}

struct Formatter<'a> {
    source: &'a str,
    comments: &'a [Comment],
    next_comment: usize,
    out: String,
    /// End of the last element written (for blank-line preservation).
    last_end: u32,
}

impl Formatter<'_> {
    /// Whether the source has a blank line between the last element and `pos`.
    fn blank_line_before(&self, pos: u32) -> bool {
        if self.out.is_empty() || pos <= self.last_end {
            return false;
        }
        let gap = self.source.get(self.last_end as usize..pos as usize).unwrap_or("");
        gap.matches('\n').count() >= 2
    }

    fn separate(&mut self, pos: u32) {
        if self.blank_line_before(pos) && !self.out.ends_with("{\n") {
            self.out.push('\n');
        }
    }

    /// Writes the comments that start before `pos`, each on its own line.
    fn leading_comments(&mut self, pos: u32, indent: &str) {
        while let Some(comment) = self.comments.get(self.next_comment) {
            if comment.span.start >= pos {
                break;
            }
            self.separate(comment.span.start);
            self.out.push_str(indent);
            self.out.push_str(&comment.text);
            self.out.push('\n');
            self.last_end = comment.span.end;
            self.next_comment += 1;
        }
    }

    /// Whether a comment starts inside `span` (it would be lost on a one-line layout).
    fn has_comment_inside(&self, span: Span) -> bool {
        self.comments[self.next_comment..]
            .iter()
            .any(|c| c.span.start >= span.start && c.span.start < span.end)
    }

    /// Appends the comments that follow `end` on the same source line, then ends the line.
    fn end_line(&mut self, end: u32) {
        self.last_end = self.last_end.max(end);
        while let Some(comment) = self.comments.get(self.next_comment) {
            let gap = self.source.get(end as usize..comment.span.start as usize).unwrap_or("\n");
            let only_punctuation = gap.chars().all(|c| matches!(c, ' ' | '\t' | '{' | '}' | ','));
            if comment.span.start < end || !only_punctuation {
                break;
            }
            self.out.push(' ');
            self.out.push_str(&comment.text);
            self.last_end = comment.span.end;
            self.next_comment += 1;
        }
        self.out.push('\n');
    }

    /// Starts a line for an element at `span`: its leading comments (and, unless `keep_inside`,
    /// those inside it, which a one-line layout cannot keep in place), a preserved blank line,
    /// and the indentation.
    fn begin_line(&mut self, span: Span, indent: &str, keep_inside: bool) {
        self.leading_comments(if keep_inside { span.start } else { span.end }, indent);
        self.separate(span.start);
        self.out.push_str(indent);
    }

    fn item(&mut self, item: &ast::Item) {
        match item {
            ast::Item::Type(decl) => self.type_decl(decl),
            ast::Item::Process(decl) => {
                let mut head = format!("{} {}", decl.kind.keyword(), decl.name.name);
                if let Some(output) = &decl.output {
                    head.push_str(" : ");
                    type_expr(&mut head, output);
                }
                head.push_str(" = ");
                let mut one_line = head.clone();
                call(&mut one_line, &decl.call);
                self.begin_line(decl.span, "", false);
                if one_line.len() <= MAX_WIDTH || decl.call.args.is_empty() {
                    self.out.push_str(&one_line);
                } else {
                    // One argument per line, each followed by a comma.
                    self.out.push_str(&head);
                    self.out.push_str(&decl.call.callee.dotted());
                    self.out.push_str("(\n");
                    for arg in &decl.call.args {
                        self.out.push_str(INDENT);
                        argument(&mut self.out, arg);
                        self.out.push_str(",\n");
                    }
                    self.out.push(')');
                }
                self.end_line(decl.span.end);
            }
            ast::Item::Stream(decl) => {
                self.begin_line(decl.span, "", false);
                let _ = write!(self.out, "stream {} = {}", decl.name.name, decl.source.dotted());
                for (i, policy) in decl.policies.iter().enumerate() {
                    self.out.push_str(if i == 0 { " with " } else { ", " });
                    self.policy(&policy.kind);
                }
                self.end_line(decl.span.end);
            }
            ast::Item::Link(decl) => self.link_decl(decl),
            ast::Item::Predict(decl) => {
                self.begin_line(decl.span, "", false);
                let _ = write!(self.out, "predict {} = ", decl.ty.name);
                call(&mut self.out, &decl.model);
                self.end_line(decl.span.end);
            }
            ast::Item::Forget(decl) => {
                self.begin_line(decl.span, "", false);
                self.out.push_str("forget ");
                if let Some(ty) = &decl.ty {
                    let _ = write!(self.out, "{} ", ty.name);
                }
                self.out.push_str("after ");
                duration(&mut self.out, &decl.after);
                if let Some(sooner) = &decl.sooner {
                    self.out.push_str(", after ");
                    duration(&mut self.out, &sooner.after);
                    self.out.push_str(" when ");
                    expr(&mut self.out, &sooner.condition, 0);
                }
                self.end_line(decl.span.end);
            }
            ast::Item::Identify(decl) => {
                self.begin_line(decl.span, "", false);
                let _ = write!(self.out, "identify {} : {} where ", decl.name.name, decl.ty.name);
                expr(&mut self.out, &decl.description, 0);
                self.end_line(decl.span.end);
            }
            ast::Item::Monitor(decl) => {
                self.begin_line(decl.span, "", false);
                let _ = write!(self.out, "monitor {} = ", decl.name.name);
                expr(&mut self.out, &decl.formula, 0);
                self.end_line(decl.span.end);
            }
            ast::Item::Chronicle(decl) => self.chronicle_decl(decl),
            ast::Item::Deploy(decl) => self.deploy_decl(decl),
        }
    }

    fn chronicle_decl(&mut self, decl: &ast::ChronicleDecl) {
        self.begin_line(decl.span, "", true);
        let params: Vec<String> =
            decl.params.iter().map(|p| format!("{}: {}", p.name.name, p.ty.name)).collect();
        let _ = write!(self.out, "chronicle {}({}) {{", decl.name.name, params.join(", "));
        // The head ends at the body's `{` (a comment after it stays on the head's line).
        let after_name = decl.name.span.end as usize;
        let head_end = self
            .source
            .get(after_name..decl.span.end as usize)
            .and_then(|rest| rest.find('{'))
            .map_or(decl.name.span.end, |i| (after_name + i + 1) as u32);
        self.end_line(head_end);
        for clause in &decl.clauses {
            self.begin_line(clause.span(), INDENT, false);
            match clause {
                ast::ChronicleClause::Event(event) => {
                    let _ = write!(self.out, "event {} = ", event.name.name);
                    event_pattern(&mut self.out, &event.pattern);
                }
                ast::ChronicleClause::Constraint(c) => {
                    let _ = write!(self.out, "{} - {} in [", c.later.name, c.earlier.name);
                    stn_bound(&mut self.out, &c.lo);
                    self.out.push_str(", ");
                    stn_bound(&mut self.out, &c.hi);
                    self.out.push(']');
                }
                ast::ChronicleClause::Hold(c) => {
                    self.out.push_str("hold ");
                    expr(&mut self.out, &c.formula, 0);
                    let _ = write!(self.out, " from {} to {}", c.from.name, c.to.name);
                }
                ast::ChronicleClause::Never(c) => {
                    self.out.push_str("never ");
                    event_pattern(&mut self.out, &c.pattern);
                    let _ = write!(self.out, " from {} to {}", c.from.name, c.to.name);
                }
            }
            self.end_line(clause.span().end);
        }
        self.leading_comments(decl.span.end, INDENT);
        self.out.push('}');
        self.end_line(decl.span.end);
    }

    fn type_decl(&mut self, decl: &ast::TypeDecl) {
        let mut head = format!("type {}", decl.name.name);
        if let Some(parent) = &decl.parent {
            let _ = write!(head, " : {}", parent.name);
        }
        if let Some(symbol) = &decl.symbol {
            let _ = write!(head, " symbol {}", symbol.name);
        }
        let fields: Vec<String> = decl
            .fields
            .iter()
            .map(|f| {
                let mut s = format!("{}: ", f.name.name);
                type_expr(&mut s, &f.ty);
                s
            })
            .collect();
        let one_line = if fields.is_empty() {
            format!("{head} {{ }}")
        } else {
            format!("{head} {{ {} }}", fields.join(", "))
        };
        if one_line.len() <= MAX_WIDTH && !self.has_comment_inside(decl.span) {
            self.begin_line(decl.span, "", false);
            self.out.push_str(&one_line);
            self.end_line(decl.span.end);
            return;
        }
        self.begin_line(decl.span, "", true);
        let _ = write!(self.out, "{head} {{");
        self.end_line(
            decl.fields
                .first()
                .map_or(decl.span.start, |f| f.span.start.saturating_sub(1))
                .max(decl.name.span.end),
        );
        for (field, text) in decl.fields.iter().zip(&fields) {
            self.begin_line(field.span, INDENT, false);
            self.out.push_str(text);
            self.out.push(',');
            self.end_line(field_end(self.source, field.span.end));
        }
        self.leading_comments(decl.span.end, INDENT);
        self.out.push('}');
        self.end_line(decl.span.end);
    }

    fn link_decl(&mut self, decl: &ast::LinkDecl) {
        self.begin_line(decl.span, "", true);
        let _ = write!(
            self.out,
            "link {} : {} -> {} via ",
            decl.name.name, decl.from_type.name, decl.to_type.name
        );
        call(&mut self.out, &decl.via);
        self.out.push_str(" {");
        self.end_line(decl.via.span.end);
        let width = decl
            .clauses
            .iter()
            .map(|c| match c {
                ast::LinkClause::Input(..) => "input".len(),
                ast::LinkClause::Condition(c) => c.kind.keyword().len(),
            })
            .max()
            .unwrap_or(0);
        for clause in &decl.clauses {
            match clause {
                ast::LinkClause::Input(path, span) => {
                    self.begin_line(*span, INDENT, false);
                    let _ = write!(self.out, "{:width$} {}", "input", path.dotted());
                    self.end_line(span.end);
                }
                ast::LinkClause::Condition(condition) => {
                    self.begin_line(condition.span, INDENT, false);
                    let _ = write!(self.out, "{:width$} ", condition.kind.keyword());
                    expr(&mut self.out, &condition.formula, 0);
                    self.end_line(condition.span.end);
                }
            }
        }
        self.leading_comments(decl.span.end, INDENT);
        self.out.push('}');
        self.end_line(decl.span.end);
    }

    fn deploy_decl(&mut self, decl: &ast::DeployDecl) {
        self.begin_line(decl.span, "", true);
        self.out.push_str("deploy ");
        if let Some(name) = &decl.name {
            match &name.kind {
                ast::LitKind::Str(text) if is_plain_name(text) => self.out.push_str(text),
                _ => literal(&mut self.out, name),
            }
            self.out.push(' ');
        }
        self.out.push('{');
        self.end_line(decl.name.as_ref().map_or(decl.span.start + "deploy".len() as u32, |n| n.span.end));
        for host in &decl.hosts {
            self.begin_line(host.span, INDENT, false);
            let _ = write!(self.out, "host {}", host.name.name);
            for (word, endpoints) in [("listen", &host.listen), ("connect", &host.connect)] {
                match endpoints.as_slice() {
                    [] => {}
                    [one] => {
                        let _ = write!(self.out, " {word} ");
                        literal(&mut self.out, one);
                    }
                    many => {
                        let _ = write!(self.out, " {word} [");
                        for (i, e) in many.iter().enumerate() {
                            if i > 0 {
                                self.out.push_str(", ");
                            }
                            literal(&mut self.out, e);
                        }
                        self.out.push(']');
                    }
                }
            }
            let names: Vec<&str> = host.processes.iter().map(|p| p.name.as_str()).collect();
            if names.is_empty() {
                self.out.push_str(" { }");
            } else {
                let _ = write!(self.out, " {{ {} }}", names.join(", "));
            }
            self.end_line(host.span.end);
        }
        self.leading_comments(decl.span.end, INDENT);
        self.out.push('}');
        self.end_line(decl.span.end);
    }

    fn policy(&mut self, kind: &ast::PolicyKind) {
        let out = &mut self.out;
        match kind {
            ast::PolicyKind::NoApproximation => out.push_str("no approximation"),
            ast::PolicyKind::UseMostRecent => out.push_str("use most recent"),
            ast::PolicyKind::AnyUpdate => out.push_str("any update"),
            ast::PolicyKind::AnyChange => out.push_str("any change"),
            ast::PolicyKind::SampleEvery(d) => {
                out.push_str("sample every ");
                duration(out, d);
            }
            ast::PolicyKind::MaxDelay(d) => {
                out.push_str("max delay ");
                duration(out, d);
            }
            ast::PolicyKind::Duration { from, to } => {
                out.push_str("from ");
                duration(out, from);
                out.push_str(" to ");
                match to {
                    Some(to) => duration(out, to),
                    None => out.push_str("inf"),
                }
            }
            ast::PolicyKind::AnyOrder => out.push_str("any order"),
            ast::PolicyKind::MonotoneOrder => out.push_str("monotone order"),
            ast::PolicyKind::StrictOrder => out.push_str("strict order"),
            ast::PolicyKind::Queue { capacity, overflow } => {
                let _ = write!(out, "queue {capacity} ");
                out.push_str(match overflow {
                    ast::Overflow::Block => "block",
                    ast::Overflow::DropOldest => "drop oldest",
                });
            }
            ast::PolicyKind::Feedback => out.push_str("feedback"),
        }
    }
}

/// The end of a field including its comma, so a comment after the comma stays on its line.
fn field_end(source: &str, end: u32) -> u32 {
    let rest = source.get(end as usize..).unwrap_or("");
    let trimmed = rest.trim_start_matches([' ', '\t']);
    if trimmed.starts_with(',') { end + (rest.len() - trimmed.len()) as u32 + 1 } else { end }
}

fn type_expr(out: &mut String, ty: &ast::TypeExpr) {
    match ty {
        ast::TypeExpr::Named(id) => out.push_str(&id.name),
        ast::TypeExpr::List(item, _) => {
            out.push_str("list<");
            type_expr(out, item);
            out.push('>');
        }
    }
}

fn call(out: &mut String, call: &ast::Call) {
    out.push_str(&call.callee.dotted());
    if call.args.is_empty() {
        return;
    }
    out.push('(');
    for (i, arg) in call.args.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        argument(out, arg);
    }
    out.push(')');
}

fn argument(out: &mut String, arg: &ast::Arg) {
    match arg {
        ast::Arg::Input(path) => out.push_str(&path.dotted()),
        ast::Arg::Param { name, value } => {
            let _ = write!(out, "{}: ", name.name);
            literal(out, value);
        }
    }
}

/// Whether `text` reads as a name (`trial`), so that it can be printed without quotes.
fn is_plain_name(text: &str) -> bool {
    const RESERVED: [&str; 11] =
        ["true", "false", "not", "and", "or", "eventually", "always", "until", "forall", "exists", "inf"];
    let mut chars = text.chars();
    chars.next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
        && !RESERVED.contains(&text)
}

fn literal(out: &mut String, lit: &ast::Literal) {
    match &lit.kind {
        ast::LitKind::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
        ast::LitKind::Number(n) => number(out, *n),
        ast::LitKind::Str(s) => string(out, s),
        ast::LitKind::Duration(d) => duration(out, d),
        ast::LitKind::List(items) => {
            out.push('[');
            for (i, item) in items.iter().enumerate() {
                if i > 0 {
                    out.push_str(", ");
                }
                literal(out, item);
            }
            out.push(']');
        }
    }
}

fn number(out: &mut String, n: ast::Number) {
    match n {
        ast::Number::Int(i) => {
            let _ = write!(out, "{i}");
        }
        // `{:?}` prints the shortest text that reads back to the same float, always with a `.`
        // or an exponent, so it stays a float.
        ast::Number::Float(x) => {
            let _ = write!(out, "{x:?}");
        }
    }
}

fn duration(out: &mut String, d: &ast::DurationLit) {
    number(out, d.value);
    out.push_str(d.unit.suffix());
}

fn string(out: &mut String, s: &str) {
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\t' => out.push_str("\\t"),
            '\r' => out.push_str("\\r"),
            '\0' => out.push_str("\\0"),
            c => out.push(c),
        }
    }
    out.push('"');
}

fn event_pattern(out: &mut String, pattern: &ast::EventPattern) {
    let names = |args: &[ast::Ident]| args.iter().map(|a| a.name.as_str()).collect::<Vec<_>>().join(", ");
    match &pattern.kind {
        ast::EventPatternKind::Change { predicate, becomes } => {
            expr(out, predicate, 0);
            let _ = write!(out, " becomes {becomes}");
        }
        ast::EventPatternKind::Monitor { monitor, args, becomes } => {
            let _ = write!(out, "monitor {}({}) becomes {becomes}", monitor.name, names(args));
        }
        ast::EventPatternKind::Recognised { chronicle, args } => {
            let _ = write!(out, "recognised {}({})", chronicle.name, names(args));
        }
    }
}

fn stn_bound(out: &mut String, bound: &ast::StnBound) {
    match bound {
        ast::StnBound::Duration { negative, value } => {
            if *negative {
                out.push('-');
            }
            duration(out, value);
        }
        ast::StnBound::Inf { negative } => out.push_str(if *negative { "-inf" } else { "inf" }),
    }
}

fn interval(out: &mut String, interval: &Option<ast::Interval>) {
    let Some(interval) = interval else { return };
    out.push('[');
    for (i, bound) in [interval.lo, interval.hi].iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        match bound {
            ast::Bound::Ticks(n) => {
                let _ = write!(out, "{n}");
            }
            ast::Bound::Duration(d) => duration(out, d),
            ast::Bound::Inf => out.push_str("inf"),
        }
    }
    out.push(']');
}

/// Writes `e`, in parentheses when its precedence is below `min_precedence`.
pub fn expr(out: &mut String, e: &ast::Expr, min_precedence: u8) {
    use ast::ExprKind as K;
    let precedence = precedence_of(&e.kind);
    let parens = precedence < min_precedence;
    if parens {
        out.push('(');
    }
    match &e.kind {
        K::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
        K::Number(n) => number(out, *n),
        K::Str(s) => string(out, s),
        K::Duration(d) => duration(out, d),
        K::Path(p) => out.push_str(&p.dotted()),
        K::Call { func, args } => {
            out.push_str(&func.name);
            out.push('(');
            for (i, arg) in args.iter().enumerate() {
                if i > 0 {
                    out.push_str(", ");
                }
                expr(out, arg, 0);
            }
            out.push(')');
        }
        K::Unary { op: ast::UnaryOp::Neg, expr: operand } => {
            out.push('-');
            expr(out, operand, precedence);
        }
        K::Unary { op: ast::UnaryOp::Not, expr: operand } => {
            out.push_str("not ");
            prefix_operand(out, operand, precedence);
        }
        K::Temporal { op, interval: iv, body } => {
            out.push_str(op.keyword());
            interval(out, iv);
            out.push(' ');
            prefix_operand(out, body, precedence);
        }
        K::Quantified { quantifier, var, ty, body } => {
            let word = match quantifier {
                ast::Quantifier::Forall => "forall",
                ast::Quantifier::Exists => "exists",
            };
            let _ = write!(out, "{word} {}: {} . ", var.name, ty.name);
            expr(out, body, precedence);
        }
        K::And(items) | K::Or(items) => {
            let word = if matches!(e.kind, K::And(_)) { " and " } else { " or " };
            for (i, item) in items.iter().enumerate() {
                if i > 0 {
                    out.push_str(word);
                }
                expr(out, item, precedence + 1);
            }
        }
        K::Until { interval: iv, lhs, rhs } => {
            expr(out, lhs, precedence + 1);
            out.push_str(" until");
            interval(out, iv);
            out.push(' ');
            expr(out, rhs, precedence);
        }
        K::Binary { op, lhs, rhs } => {
            let (left, right) = if *op == ast::BinaryOp::Implies {
                (precedence + 1, precedence)
            } else if op.is_comparison() {
                (precedence + 1, precedence + 1)
            } else {
                (precedence, precedence + 1)
            };
            expr(out, lhs, left);
            let _ = write!(out, " {} ", op.symbol());
            expr(out, rhs, right);
        }
    }
    if parens {
        out.push(')');
    }
}

/// The operand of `not`, `eventually` or `always`: arithmetic and comparisons get parentheses
/// for readability (`always (speed < 25.0)`), though precedence would not need them.
fn prefix_operand(out: &mut String, operand: &ast::Expr, precedence: u8) {
    let needs = precedence_of(&operand.kind);
    if (7..=9).contains(&needs) {
        out.push('(');
        expr(out, operand, 0);
        out.push(')');
    } else {
        expr(out, operand, precedence);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fmt(src: &str) -> String {
        match format(src) {
            Ok(s) => s,
            Err(d) => panic!("{d:#?}"),
        }
    }

    #[test]
    fn keeps_comments_and_blank_lines() {
        let src = "// head\n\n\n\ntype A {x:int}   // trailing\nstream s=a   with  strict order\n\n/* block */\nmonitor m = not (a<b)\n// tail\n";
        let out = fmt(src);
        assert_eq!(
            out,
            "// head\n\ntype A { x: int } // trailing\nstream s = a with strict order\n\n/* block */\nmonitor m = not (a < b)\n// tail\n"
        );
        assert_eq!(fmt(&out), out);
    }

    #[test]
    fn link_blocks_align_conditions() {
        let src = "link l : A -> B via f(x) { establish eventually[1s,inf] true // new\n maintain always p }";
        let out = fmt(src);
        assert_eq!(
            out,
            "link l : A -> B via f(x) {\n  establish eventually[1s, inf] true // new\n  maintain  always p\n}\n"
        );
    }

    #[test]
    fn parentheses_only_where_needed() {
        let cases = [
            ("monitor m = (a -> b) -> c", "monitor m = (a -> b) -> c"),
            ("monitor m = a -> (b -> c)", "monitor m = a -> b -> c"),
            ("monitor m = (a or b) and c", "monitor m = (a or b) and c"),
            ("monitor m = a - (b - c)", "monitor m = a - (b - c)"),
            ("monitor m = (a - b) - c", "monitor m = a - b - c"),
            ("monitor m = not (p until q)", "monitor m = not (p until q)"),
            ("monitor m = a and (forall c: Car . p)", "monitor m = a and (forall c: Car . p)"),
            ("monitor m = -(-x) < 2.0", "monitor m = --x < 2.0"),
            ("monitor m = (a < b) == c", "monitor m = (a < b) == c"),
        ];
        for (src, want) in cases {
            assert_eq!(fmt(src).trim_end(), want, "{src}");
        }
    }
}
