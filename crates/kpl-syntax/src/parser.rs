//! From source text to [`ast`]: the pest grammar (`kpl.pest`), syntax-error messages in the
//! user's words, error recovery at item boundaries, and the conversion of pest pairs to the tree.
//!
//! Parsing never panics and never recurses deeper than the bracket nesting that [`lex::scan`]
//! allows: expressions are built with an explicit operator stack, and a tree deeper than
//! [`MAX_EXPR_DEPTH`] is refused with a diagnostic instead of being built.

use pest::Parser as _;
use pest::error::{ErrorVariant, InputLocation};
use pest::iterators::{Pair, Pairs};
use pest_derive::Parser;

use crate::ast::{self, Span};
use crate::diagnostic::Diagnostic;
use crate::diagnostics as diag;
use crate::lex::{self, Comment};

#[derive(Parser)]
#[grammar = "kpl.pest"]
struct KplParser;

/// Largest file accepted, in bytes.
pub const MAX_SOURCE_BYTES: usize = 64 << 20;
/// Deepest expression tree accepted (operators nested in operators).
pub const MAX_EXPR_DEPTH: u32 = 256;

/// The result of parsing a file: the tree of what parsed, its comments, and the problems found.
/// When `diagnostics` holds errors, `spec` has only the items that parsed.
#[derive(Debug, Clone, Default)]
pub struct Parse {
    pub spec: ast::Spec,
    pub comments: Vec<Comment>,
    pub diagnostics: Vec<Diagnostic>,
}

impl Parse {
    pub fn has_errors(&self) -> bool {
        self.diagnostics.iter().any(Diagnostic::is_error)
    }
}

/// Parses a KPL file. Never fails: problems are diagnostics, and after a syntax error the parser
/// resumes at the next item that starts a line, so one run reports an error per broken item.
pub fn parse(source: &str) -> Parse {
    if source.len() > MAX_SOURCE_BYTES {
        return Parse {
            diagnostics: vec![diag::file_too_large(source.len(), MAX_SOURCE_BYTES)],
            ..Parse::default()
        };
    }
    let scan = lex::scan(source);
    if let Some(span) = scan.too_deep {
        return Parse {
            diagnostics: vec![diag::nesting_too_deep(span, lex::MAX_NESTING)],
            comments: scan.comments,
            ..Parse::default()
        };
    }
    let mut parse = Parse { comments: scan.comments, ..Parse::default() };
    match KplParser::parse(Rule::file, source) {
        Ok(pairs) => {
            let mut conv = Converter::new(0, &mut parse.diagnostics, source, &parse.comments);
            parse.spec = conv.file(pairs);
        }
        Err(whole_error) => {
            // Parse each item on its own so that every broken item gets its message, with
            // pest's error detail on (it lists expected punctuation, not only rules). It stays
            // on: it costs a little on every later parse, and turning it off could race with
            // another thread's error path.
            pest::set_error_detail(true);
            let mut bounds: Vec<usize> = scan.item_starts.iter().map(|&s| s as usize).collect();
            if bounds.first() != Some(&0) {
                bounds.insert(0, 0);
            }
            bounds.push(source.len());
            for window in bounds.windows(2) {
                let (start, end) = (window[0], window[1]);
                let chunk = &source[start..end];
                match KplParser::parse(Rule::file, chunk) {
                    Ok(pairs) => {
                        let mut conv =
                            Converter::new(start as u32, &mut parse.diagnostics, source, &parse.comments);
                        let spec = conv.file(pairs);
                        parse.spec.items.extend(spec.items);
                    }
                    Err(err) => parse.diagnostics.push(syntax_error(source, start, &err)),
                }
            }
            if !parse.has_errors() {
                parse.diagnostics.push(syntax_error(source, 0, &whole_error));
            }
        }
    }
    parse
}

/// Parses one formula, as given on the command line (`kpl mtl eval --formula ...`).
pub fn parse_formula(source: &str) -> Result<ast::Expr, Vec<Diagnostic>> {
    if source.len() > MAX_SOURCE_BYTES {
        return Err(vec![diag::file_too_large(source.len(), MAX_SOURCE_BYTES)]);
    }
    let scan = lex::scan(source);
    if let Some(span) = scan.too_deep {
        return Err(vec![diag::nesting_too_deep(span, lex::MAX_NESTING)]);
    }
    let mut pairs = KplParser::parse(Rule::formula_input, source).map_err(|e| {
        pest::set_error_detail(true);
        let detailed = KplParser::parse(Rule::formula_input, source).err().unwrap_or(e);
        vec![syntax_error(source, 0, &detailed)]
    })?;
    let mut diagnostics = Vec::new();
    let expr = {
        let mut conv = Converter::new(0, &mut diagnostics, source, &scan.comments);
        let input = pairs.next().map(|p| p.into_inner());
        input.and_then(|mut inner| inner.next()).map(|e| conv.expr(e))
    };
    match expr {
        Some(expr) if diagnostics.is_empty() => Ok(expr),
        Some(_) => Err(diagnostics),
        None => Err(vec![diag::expected_formula()]),
    }
}

// ---------------------------------------------------------------------------------------------
// syntax errors in the user's words

/// Turns a pest error in `chunk` (which starts at byte `offset` of `source`) into a diagnostic.
/// With pest's error detail on, the error lists the tokens that were expected (including
/// punctuation such as `)`), which say more than the rules.
fn syntax_error(source: &str, offset: usize, err: &pest::error::Error<Rule>) -> Diagnostic {
    let classic_pos = offset
        + match err.location {
            InputLocation::Pos(p) => p,
            InputLocation::Span((s, _)) => s,
        };
    let positives: &[Rule] = match &err.variant {
        ErrorVariant::ParsingError { positives, .. } => positives,
        ErrorVariant::CustomError { .. } => &[],
    };
    // A reserved word where a name was expected: pest's detailed attempts wander into the
    // `!keyword` look-ahead; the rule-level error says it better.
    // A reserved word where a name or an expression could start: pest's detailed attempts
    // wander into the `!keyword` look-ahead (past the word); the rule-level error says it better.
    let at_keyword = keyword(found_text(source, classic_pos));
    let attempts = err.parse_attempts().filter(|a| !(at_keyword && offset + a.max_position > classic_pos));
    let pos = offset
        + match (&attempts, &err.location) {
            (Some(a), _) => a.max_position,
            (None, InputLocation::Pos(p)) => *p,
            (None, InputLocation::Span((s, _))) => *s,
        };
    // pest does not export its token type; its text (`)`, `and`, `0..9`) is what we need.
    let tokens: Vec<String> = attempts
        .as_ref()
        .map(|a| a.expected_tokens().iter().map(ToString::to_string).collect())
        .unwrap_or_default();
    let mut expected = describe_tokens(&tokens);
    if expected.iter().any(|e| e.starts_with("a time unit")) {
        // `50` could also go on as `50.5` or `5e1`; the unit is what is missing.
        expected.retain(|e| e.starts_with("a time unit"));
    }
    if expected.is_empty() {
        expected = positives.iter().map(|r| rule_name(*r).to_string()).collect();
        expected.sort();
        expected.dedup();
    }
    let found = describe_found(source, pos);
    let message = match expected.as_slice() {
        [] => format!("unexpected {found}"),
        [one] => format!("expected {one}, found {found}"),
        many if many.len() <= 10 => {
            let (last, rest) = many.split_last().map_or(("", &[][..]), |(l, r)| (l.as_str(), r));
            format!("expected {} or {last}, found {found}", rest.join(", "))
        }
        _ => format!("unexpected {found}"),
    };
    // When the unexpected token is on a later line, point just after the last token instead:
    // that is where something is missing (an unclosed `{`, a missing `)`).
    let before = source[..pos.min(source.len())].trim_end_matches(char::is_whitespace);
    let (span, label) = if source[before.len()..pos.min(source.len())].contains('\n') && !before.is_empty() {
        (Span::new(before.len() as u32, before.len() as u32), "expected here")
    } else {
        (found_span(source, pos), "unexpected here")
    };
    let hint = hint_for(positives, &expected, source, pos);
    diag::syntax(span, message, label, hint)
}

/// The tokens pest expected, in the user's words: punctuation and words quoted, character
/// classes named, operators grouped, white space and comment starters left out.
fn describe_tokens(tokens: &[String]) -> Vec<String> {
    const OPERATORS: [&str; 15] =
        ["!=", "%", "*", "+", "-", "->", "/", "<", "<=", "==", ">", ">=", "and", "or", "until"];
    const UNITS: [&str; 5] = ["us", "ms", "s", "min", "h"];
    let mut out: Vec<String> = Vec::new();
    let mut push = |s: String| {
        if !out.contains(&s) {
            out.push(s);
        }
    };
    let mut operators = 0;
    for token in tokens {
        match token.as_str() {
            " " | "\t" | "\n" | "\r" | "//" | "/*" | "BUILTIN_RULE" => {}
            "_" | "a..z" | "A..Z" => push("a name".into()),
            "0..9" => push("a number".into()),
            "\"" => push("a string".into()),
            t if UNITS.contains(&t) => push("a time unit (us, ms, s, min, h)".into()),
            t if OPERATORS.contains(&t) => operators += 1,
            t => push(format!("`{t}`")),
        }
    }
    // Quoted tokens first, then the classes, in a stable order.
    out.sort_by_key(|s| (!s.starts_with('`'), s.clone()));
    if operators > 2 {
        out.push("an operator".into());
    } else if operators > 0 {
        // A few operators are worth naming (`->` in a link header).
        for token in tokens.iter().filter(|t| OPERATORS.contains(&t.as_str())) {
            out.push(format!("`{token}`"));
        }
    }
    out
}

fn found_span(source: &str, pos: usize) -> Span {
    let rest = source.get(pos..).unwrap_or("");
    let len = match rest.chars().next() {
        None => 0,
        Some(c) if c.is_ascii_alphanumeric() || c == '_' => {
            rest.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(rest.len())
        }
        Some(c) => c.len_utf8(),
    };
    Span::new(pos as u32, (pos + len) as u32)
}

fn found_text(source: &str, pos: usize) -> &str {
    source.get(found_span(source, pos).range()).unwrap_or("")
}

fn describe_found(source: &str, pos: usize) -> String {
    let span = found_span(source, pos);
    match source.get(span.range()) {
        None | Some("") => "end of file".to_string(),
        Some(text) if text.chars().all(char::is_whitespace) => "a line break".to_string(),
        Some(text) if keyword(text) => format!("the keyword `{text}`"),
        Some(text) if text.chars().count() > 40 => {
            format!("`{}...`", text.chars().take(40).collect::<String>())
        }
        Some(text) => format!("`{}`", text.escape_debug()),
    }
}

fn keyword(word: &str) -> bool {
    matches!(
        word,
        "true"
            | "false"
            | "not"
            | "and"
            | "or"
            | "eventually"
            | "always"
            | "until"
            | "forall"
            | "exists"
            | "inf"
    )
}

fn hint_for(positives: &[Rule], expected: &[String], source: &str, pos: usize) -> Option<String> {
    let rest = source.get(pos..).unwrap_or("");
    let word: String = rest.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
    let expects = |s: &str| expected.iter().any(|e| e == s);
    if positives == [Rule::ident] && keyword(&word) {
        return Some(format!("`{word}` is a reserved word of formulas; choose another name"));
    }
    if word == "inf" {
        return Some(
            "`inf` is only allowed as the upper bound of an interval, as in `eventually[1s, inf]`".into(),
        );
    }
    let after_digit = source[..pos.min(source.len())].ends_with(|c: char| c.is_ascii_digit());
    if after_digit && (positives.contains(&Rule::unit) || expects("a time unit (us, ms, s, min, h)")) {
        return Some(
            "a duration needs a unit right after the number: `us`, `ms`, `s`, `min` or `h` (e.g. `100ms`)"
                .into(),
        );
    }
    if positives.contains(&Rule::policy) {
        return Some("policies are: no approximation, use most recent, any update, any change, sample every T, max delay T, from T to T, any order, monotone order, strict order, queue N block, queue N drop oldest, feedback".into());
    }
    if rest.starts_with('=') && !rest.starts_with("==") && expects("an operator") {
        return Some("equality in a formula is written `==`".into());
    }
    if rest.starts_with("&&") || rest.starts_with("||") || rest.starts_with('!') && !rest.starts_with("!=") {
        return Some("formulas use the words `and`, `or` and `not`".into());
    }
    if expects("`}`") && (rest.is_empty() || lex::ITEM_KEYWORDS.contains(&word.as_str())) {
        return Some("a `{` block is not closed before the next item".into());
    }
    if expects("`)`") && (rest.is_empty() || lex::ITEM_KEYWORDS.contains(&word.as_str())) {
        return Some("a `(` is not closed before the next item".into());
    }
    if positives.contains(&Rule::EOI) && positives.len() <= 2 {
        return Some("a file is a sequence of items: type, source, compute, sink, stream, link, predict, forget, identify, monitor, chronicle, deploy".into());
    }
    None
}

/// The word a user reads for each grammar rule. Exhaustive on purpose: a new rule must be named
/// here before it can appear in an error.
fn rule_name(rule: Rule) -> &'static str {
    match rule {
        Rule::EOI => "end of file",
        Rule::item => {
            "an item (type, source, compute, sink, stream, link, predict, forget, identify, monitor, chronicle or deploy)"
        }
        Rule::digits | Rule::exponent => "a number",
        Rule::arg => "an input stream or a parameter `name: value`",
        Rule::link_clause => "`input`, `establish`, `reestablish` or `maintain`",
        Rule::prefix | Rule::primary => "an expression",
        Rule::infix => "an operator",
        Rule::WHITESPACE | Rule::COMMENT => "a comment",
        Rule::file => {
            "an item (type, source, compute, sink, stream, link, predict, forget, identify, monitor, chronicle or deploy)"
        }
        Rule::formula_input => "a formula",
        Rule::ident_char | Rule::ident | Rule::keyword => "a name",
        Rule::path => "a name",
        Rule::kw_type => "`type`",
        Rule::kw_symbol => "`symbol`",
        Rule::kw_list => "`list`",
        Rule::kw_source => "`source`",
        Rule::kw_compute => "`compute`",
        Rule::kw_sink => "`sink`",
        Rule::kw_stream => "`stream`",
        Rule::kw_with => "`with`",
        Rule::kw_link => "`link`",
        Rule::kw_via => "`via`",
        Rule::kw_input => "`input`",
        Rule::kw_predict => "`predict`",
        Rule::kw_forget => "`forget`",
        Rule::kw_after => "`after`",
        Rule::kw_identify => "`identify`",
        Rule::kw_where => "`where`",
        Rule::identify_decl => "an identification `identify NAME : TYPE where FORMULA`",
        Rule::kw_monitor => "`monitor`",
        Rule::kw_deploy => "`deploy`",
        Rule::kw_host => "`host`",
        Rule::kw_listen => "`listen`",
        Rule::kw_connect => "`connect`",
        Rule::kw_establish => "`establish`",
        Rule::kw_reestablish => "`reestablish`",
        Rule::kw_maintain => "`maintain`",
        Rule::kw_true | Rule::kw_false | Rule::boolean => "`true` or `false`",
        Rule::kw_not | Rule::op_not => "`not`",
        Rule::kw_and | Rule::op_and => "`and`",
        Rule::kw_or | Rule::op_or => "`or`",
        Rule::kw_eventually => "`eventually`",
        Rule::kw_always => "`always`",
        Rule::kw_until | Rule::op_until => "`until`",
        Rule::kw_forall => "`forall`",
        Rule::kw_exists => "`exists`",
        Rule::kw_inf => "`inf`",
        Rule::number | Rule::signed => "a number",
        Rule::unit => "a time unit (us, ms, s, min, h)",
        Rule::duration => "a duration (e.g. `100ms`)",
        Rule::uint => "a whole number",
        Rule::string | Rule::string_body => "a string",
        Rule::literal => "a value (number, duration, string, boolean or list)",
        Rule::list_literal => "a list `[...]`",
        Rule::type_decl => "a type declaration",
        Rule::type_parent => "`:` and a parent type",
        Rule::type_symbol => "`symbol` and a prefix",
        Rule::field => "an attribute `name: type`",
        Rule::type_expr | Rule::list_type => "a type",
        Rule::process_decl => "a process declaration",
        Rule::process_kind => "`source`, `compute` or `sink`",
        Rule::process_output => "`:` and the output type",
        Rule::call => "a process name (e.g. `file.jsonl(...)`)",
        Rule::call_args => "arguments `(...)`",
        Rule::param => "a parameter `name: value`",
        Rule::stream_decl => "a stream declaration",
        Rule::policy => "a policy",
        Rule::no_approximation => "`no approximation`",
        Rule::use_most_recent => "`use most recent`",
        Rule::any_update => "`any update`",
        Rule::any_change => "`any change`",
        Rule::sample_every => "`sample every`",
        Rule::max_delay => "`max delay`",
        Rule::duration_window => "`from T to T`",
        Rule::any_order => "`any order`",
        Rule::monotone_order => "`monotone order`",
        Rule::strict_order => "`strict order`",
        Rule::queue_policy => "`queue N`",
        Rule::overflow | Rule::overflow_block | Rule::overflow_drop_oldest => "`block` or `drop oldest`",
        Rule::feedback => "`feedback`",
        Rule::w_no => "`no`",
        Rule::w_approximation => "`approximation`",
        Rule::w_use => "`use`",
        Rule::w_most => "`most`",
        Rule::w_recent => "`recent`",
        Rule::w_any => "`any`",
        Rule::w_update => "`update`",
        Rule::w_change => "`change`",
        Rule::w_sample => "`sample`",
        Rule::w_every => "`every`",
        Rule::w_max => "`max`",
        Rule::w_delay => "`delay`",
        Rule::w_from => "`from`",
        Rule::w_to => "`to`",
        Rule::w_order => "`order`",
        Rule::w_monotone => "`monotone`",
        Rule::w_strict => "`strict`",
        Rule::w_queue => "`queue`",
        Rule::w_block => "`block`",
        Rule::w_drop => "`drop`",
        Rule::w_oldest => "`oldest`",
        Rule::w_when => "`when`",
        Rule::w_feedback => "`feedback`",
        Rule::link_decl => "a link specification",
        Rule::link_input => "`input` and a stream",
        Rule::condition => "a condition (establish, reestablish or maintain)",
        Rule::condition_kind => "`establish`, `reestablish` or `maintain`",
        Rule::predict_decl => "a prediction model",
        Rule::forget_decl => "a forget declaration",
        Rule::forget_sooner => "`, after DURATION when CONDITION`",
        Rule::monitor_decl => "a monitor",
        Rule::kw_chronicle => "`chronicle`",
        Rule::chronicle_decl => "a chronicle `chronicle NAME(x: Type, ...) { ... }`",
        Rule::chronicle_params => "the chronicle's parameters `(x: Type, ...)`",
        Rule::chronicle_param => "a parameter `name: Type`",
        Rule::chronicle_clause => "`event`, `hold`, `never` or a constraint `e2 - e1 in [lo, hi]`",
        Rule::chronicle_event => "an event `event NAME = ...`",
        Rule::event_pattern => {
            "an event (`PREDICATE becomes true`, `monitor NAME(x, ...) becomes false`, `recognised NAME(x, ...)`)"
        }
        Rule::event_monitor => "a monitor's verdict `monitor NAME(x, ...) becomes true|false`",
        Rule::event_recognised => "a recognition `recognised NAME(x, ...)`",
        Rule::event_change => "a change `PREDICATE becomes true|false`",
        Rule::event_args => "the objects `(x, ...)`",
        Rule::chronicle_hold => "a condition `hold FORMULA from e1 to e2`",
        Rule::chronicle_never => "a condition `never EVENT from e1 to e2`",
        Rule::chronicle_constraint => "a constraint `e2 - e1 in [lo, hi]`",
        Rule::stn_bound => "a bound (a duration, `-` and a duration, `inf` or `-inf`)",
        Rule::stn_negative => "`-`",
        Rule::w_event => "`event`",
        Rule::w_becomes => "`becomes`",
        Rule::w_recognised => "`recognised`",
        Rule::w_hold => "`hold`",
        Rule::w_never => "`never`",
        Rule::w_in => "`in`",
        Rule::deploy_decl => "a deploy section",
        Rule::deploy_name => "the deployment's name",
        Rule::host_decl => "a host `host NAME { ... }`",
        Rule::host_listen => "`listen`",
        Rule::host_connect => "`connect`",
        Rule::endpoints => "an endpoint string or a list of them",
        Rule::expr | Rule::paren | Rule::call_expr => "an expression",
        Rule::op_neg | Rule::op_sub => "`-`",
        Rule::temporal => "`eventually` or `always`",
        Rule::quantifier => "`forall` or `exists`",
        Rule::op_implies => "`->`",
        Rule::op_le => "`<=`",
        Rule::op_ge => "`>=`",
        Rule::op_eq => "`==`",
        Rule::op_ne => "`!=`",
        Rule::op_lt => "`<`",
        Rule::op_gt => "`>`",
        Rule::op_add => "`+`",
        Rule::op_mul => "`*`",
        Rule::op_div => "`/`",
        Rule::op_rem => "`%`",
        Rule::interval => "an interval `[a, b]`",
        Rule::bound => "an interval bound (a whole number, a duration or `inf`)",
    }
}

// ---------------------------------------------------------------------------------------------
// pairs to tree

struct Converter<'d> {
    base: u32,
    diagnostics: &'d mut Vec<Diagnostic>,
    /// The whole source and its comments, to trim the trivia pest leaves at the end of spans.
    source: &'d str,
    comments: &'d [Comment],
}

/// An operand on the expression stack: the tree, its depth, and whether it is a comparison
/// written without parentheses (comparisons do not chain).
struct Operand {
    expr: ast::Expr,
    depth: u32,
    bare_comparison: bool,
}

enum Prefix {
    Not,
    Neg,
    Temporal(ast::TemporalOp, Option<ast::Interval>),
    Quantified(ast::Quantifier, ast::Ident, ast::Ident),
}

enum Infix {
    Binary(ast::BinaryOp),
    And,
    Or,
    Until(Option<ast::Interval>),
}

enum Op {
    Prefix(Prefix, Span),
    Infix(Infix),
}

impl Op {
    /// Binding power: higher binds tighter.
    fn precedence(&self) -> u8 {
        use ast::BinaryOp as B;
        match self {
            Op::Prefix(Prefix::Quantified(..), _) => 1,
            Op::Infix(Infix::Binary(B::Implies)) => 2,
            Op::Infix(Infix::Or) => 3,
            Op::Infix(Infix::And) => 4,
            Op::Infix(Infix::Until(_)) => 5,
            Op::Prefix(Prefix::Not | Prefix::Temporal(..), _) => 6,
            Op::Infix(Infix::Binary(B::Lt | B::Le | B::Gt | B::Ge | B::Eq | B::Ne)) => 7,
            Op::Infix(Infix::Binary(B::Add | B::Sub)) => 8,
            Op::Infix(Infix::Binary(B::Mul | B::Div | B::Rem)) => 9,
            Op::Prefix(Prefix::Neg, _) => 10,
        }
    }

    fn right_associative(&self) -> bool {
        matches!(self, Op::Infix(Infix::Binary(ast::BinaryOp::Implies) | Infix::Until(_)))
    }
}

/// The precedence of an expression's top operator, as the formatter needs it to place
/// parentheses (atoms bind tightest).
pub(crate) fn precedence_of(kind: &ast::ExprKind) -> u8 {
    use ast::ExprKind as K;
    match kind {
        K::Quantified { .. } => 1,
        K::Binary { op: ast::BinaryOp::Implies, .. } => 2,
        K::Or(_) => 3,
        K::And(_) => 4,
        K::Until { .. } => 5,
        K::Unary { op: ast::UnaryOp::Not, .. } | K::Temporal { .. } => 6,
        K::Binary { op, .. } if op.is_comparison() => 7,
        K::Binary { op: ast::BinaryOp::Add | ast::BinaryOp::Sub, .. } => 8,
        K::Binary { .. } => 9,
        K::Unary { op: ast::UnaryOp::Neg, .. } => 10,
        K::Bool(_) | K::Number(_) | K::Str(_) | K::Duration(_) | K::Path(_) | K::Call { .. } => 11,
    }
}

impl<'d> Converter<'d> {
    fn new(
        base: u32,
        diagnostics: &'d mut Vec<Diagnostic>,
        source: &'d str,
        comments: &'d [Comment],
    ) -> Converter<'d> {
        Converter { base, diagnostics, source, comments }
    }

    /// The span of a pair without the white space and comments pest includes at the end of a
    /// rule that ends in an optional or repeated part.
    fn span(&self, pair: &Pair<'_, Rule>) -> Span {
        let s = pair.as_span();
        let start = self.base + s.start() as u32;
        let mut end = self.base + s.end() as u32;
        let bytes = self.source.as_bytes();
        loop {
            while end > start && bytes.get(end as usize - 1).is_some_and(u8::is_ascii_whitespace) {
                end -= 1;
            }
            let comment = self.comments.binary_search_by_key(&end, |c| c.span.end);
            match comment {
                Ok(i) if self.comments[i].span.start >= start && end > start => {
                    end = self.comments[i].span.start
                }
                _ => break,
            }
        }
        Span::new(start, end)
    }

    fn ident(&self, pair: Pair<'_, Rule>) -> ast::Ident {
        ast::Ident { name: pair.as_str().to_string(), span: self.span(&pair) }
    }

    fn path(&self, pair: Pair<'_, Rule>) -> ast::Path {
        let span = self.span(&pair);
        ast::Path { segments: pair.into_inner().map(|p| self.ident(p)).collect(), span }
    }

    fn file(&mut self, mut pairs: Pairs<'_, Rule>) -> ast::Spec {
        let mut spec = ast::Spec::default();
        let Some(file) = pairs.next() else { return spec };
        for pair in file.into_inner() {
            let item = match pair.as_rule() {
                Rule::type_decl => ast::Item::Type(self.type_decl(pair)),
                Rule::process_decl => ast::Item::Process(self.process_decl(pair)),
                Rule::stream_decl => ast::Item::Stream(self.stream_decl(pair)),
                Rule::link_decl => ast::Item::Link(self.link_decl(pair)),
                Rule::predict_decl => ast::Item::Predict(self.predict_decl(pair)),
                Rule::forget_decl => ast::Item::Forget(self.forget_decl(pair)),
                Rule::identify_decl => ast::Item::Identify(self.identify_decl(pair)),
                Rule::monitor_decl => ast::Item::Monitor(self.monitor_decl(pair)),
                Rule::chronicle_decl => ast::Item::Chronicle(self.chronicle_decl(pair)),
                Rule::deploy_decl => ast::Item::Deploy(self.deploy_decl(pair)),
                _ => continue, // EOI
            };
            spec.items.push(item);
        }
        spec
    }

    fn type_decl(&mut self, pair: Pair<'_, Rule>) -> ast::TypeDecl {
        let span = self.span(&pair);
        let mut decl = ast::TypeDecl {
            name: placeholder_ident(span),
            parent: None,
            symbol: None,
            fields: Vec::new(),
            span,
        };
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::ident => decl.name = self.ident(p),
                Rule::type_parent => decl.parent = p.into_inner().next().map(|i| self.ident(i)),
                Rule::type_symbol => {
                    decl.symbol = p.into_inner().find(|i| i.as_rule() == Rule::ident).map(|i| self.ident(i))
                }
                Rule::field => {
                    let span = self.span(&p);
                    let mut inner = p.into_inner();
                    let name = inner.next().map_or(placeholder_ident(span), |i| self.ident(i));
                    let ty = inner
                        .next()
                        .map_or(ast::TypeExpr::Named(placeholder_ident(span)), |t| self.type_expr(t));
                    decl.fields.push(ast::Field { name, ty, span });
                }
                _ => {}
            }
        }
        decl
    }

    fn type_expr(&self, pair: Pair<'_, Rule>) -> ast::TypeExpr {
        let span = self.span(&pair);
        let Some(inner) = pair.into_inner().next() else {
            return ast::TypeExpr::Named(placeholder_ident(span));
        };
        match inner.as_rule() {
            Rule::list_type => {
                let item = inner
                    .into_inner()
                    .find(|p| p.as_rule() == Rule::type_expr)
                    .map_or(ast::TypeExpr::Named(placeholder_ident(span)), |t| self.type_expr(t));
                ast::TypeExpr::List(Box::new(item), span)
            }
            _ => ast::TypeExpr::Named(self.ident(inner)),
        }
    }

    fn process_decl(&mut self, pair: Pair<'_, Rule>) -> ast::ProcessDecl {
        let span = self.span(&pair);
        let mut kind = ast::ProcessKind::Source;
        let mut name = placeholder_ident(span);
        let mut output = None;
        let mut call = placeholder_call(span);
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::process_kind => {
                    kind = match p.as_str() {
                        "compute" => ast::ProcessKind::Compute,
                        "sink" => ast::ProcessKind::Sink,
                        _ => ast::ProcessKind::Source,
                    }
                }
                Rule::ident => name = self.ident(p),
                Rule::process_output => output = p.into_inner().next().map(|t| self.type_expr(t)),
                Rule::call => call = self.call(p),
                _ => {}
            }
        }
        ast::ProcessDecl { kind, name, output, call, span }
    }

    fn call(&mut self, pair: Pair<'_, Rule>) -> ast::Call {
        let span = self.span(&pair);
        let mut call = placeholder_call(span);
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::path => call.callee = self.path(p),
                Rule::call_args => {
                    for arg in p.into_inner() {
                        match arg.as_rule() {
                            Rule::path => call.args.push(ast::Arg::Input(self.path(arg))),
                            Rule::param => {
                                let span = self.span(&arg);
                                let mut inner = arg.into_inner();
                                let name = inner.next().map_or(placeholder_ident(span), |i| self.ident(i));
                                let value = match inner.next() {
                                    Some(v) => self.literal(v),
                                    None => ast::Literal { kind: ast::LitKind::Bool(false), span },
                                };
                                call.args.push(ast::Arg::Param { name, value });
                            }
                            _ => {}
                        }
                    }
                }
                _ => {}
            }
        }
        call
    }

    fn literal(&mut self, pair: Pair<'_, Rule>) -> ast::Literal {
        let span = self.span(&pair);
        let Some(inner) = pair.into_inner().next() else {
            return ast::Literal { kind: ast::LitKind::Bool(false), span };
        };
        let kind = match inner.as_rule() {
            Rule::duration => ast::LitKind::Duration(self.duration(inner)),
            Rule::signed => ast::LitKind::Number(self.number(&inner)),
            Rule::string => ast::LitKind::Str(self.string(inner)),
            Rule::boolean => ast::LitKind::Bool(inner.as_str() == "true"),
            Rule::list_literal => ast::LitKind::List(inner.into_inner().map(|l| self.literal(l)).collect()),
            _ => ast::LitKind::Bool(false),
        };
        ast::Literal { kind, span }
    }

    fn number(&mut self, pair: &Pair<'_, Rule>) -> ast::Number {
        let text = pair.as_str();
        let span = self.span(pair);
        if text.contains(['.', 'e', 'E']) {
            match text.parse::<f64>() {
                Ok(x) if x.is_finite() => ast::Number::Float(x),
                _ => {
                    self.diagnostics.push(diag::number_out_of_range(span, text));
                    ast::Number::Float(0.0)
                }
            }
        } else {
            match text.parse::<i64>() {
                Ok(i) => ast::Number::Int(i),
                Err(_) => {
                    self.diagnostics.push(diag::number_out_of_range(span, text));
                    ast::Number::Int(0)
                }
            }
        }
    }

    fn duration(&mut self, pair: Pair<'_, Rule>) -> ast::DurationLit {
        let span = self.span(&pair);
        let mut value = ast::Number::Int(0);
        let mut unit = kpl_core::TimeUnit::S;
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::number => value = self.number(&p),
                Rule::unit => {
                    unit = kpl_core::TimeUnit::from_suffix(p.as_str()).unwrap_or(kpl_core::TimeUnit::S)
                }
                _ => {}
            }
        }
        let lit = ast::DurationLit { value, unit, span };
        let exact = match value {
            ast::Number::Int(_) => true,
            ast::Number::Float(x) => {
                let us = x * unit.micros() as f64;
                (us - us.round()).abs() < 1e-6
            }
        };
        if lit.micros().is_none() || !exact {
            self.diagnostics.push(diag::bad_duration(span, exact));
        }
        lit
    }

    fn string(&mut self, pair: Pair<'_, Rule>) -> String {
        let span = self.span(&pair);
        let body = pair.into_inner().next().map_or("", |b| b.as_str());
        let mut out = String::with_capacity(body.len());
        let mut chars = body.chars();
        while let Some(c) = chars.next() {
            if c != '\\' {
                out.push(c);
                continue;
            }
            match chars.next() {
                Some('n') => out.push('\n'),
                Some('t') => out.push('\t'),
                Some('r') => out.push('\r'),
                Some('0') => out.push('\0'),
                Some('\\') => out.push('\\'),
                Some('"') => out.push('"'),
                other => {
                    let shown = other.map_or(String::new(), String::from);
                    self.diagnostics.push(diag::bad_escape(span, &shown));
                }
            }
        }
        out
    }

    fn stream_decl(&mut self, pair: Pair<'_, Rule>) -> ast::StreamDecl {
        let span = self.span(&pair);
        let mut decl = ast::StreamDecl {
            name: placeholder_ident(span),
            source: placeholder_path(span),
            policies: vec![],
            span,
        };
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::ident => decl.name = self.ident(p),
                Rule::path => decl.source = self.path(p),
                Rule::policy => {
                    if let Some(policy) = self.policy(p) {
                        decl.policies.push(policy);
                    }
                }
                _ => {}
            }
        }
        decl
    }

    fn policy(&mut self, pair: Pair<'_, Rule>) -> Option<ast::Policy> {
        let span = self.span(&pair);
        let inner = pair.into_inner().next()?;
        let rule = inner.as_rule();
        let mut durations = Vec::new();
        let mut capacity = 0;
        let mut overflow = ast::Overflow::Block;
        for p in inner.into_inner() {
            match p.as_rule() {
                Rule::duration => durations.push(self.duration(p)),
                Rule::uint => match p.as_str().parse::<u64>() {
                    Ok(n) => capacity = n,
                    Err(_) => self.diagnostics.push(diag::number_out_of_range(self.span(&p), p.as_str())),
                },
                Rule::overflow if p.as_str().starts_with("drop") => overflow = ast::Overflow::DropOldest,
                _ => {}
            }
        }
        let first = durations.first().copied();
        let kind = match rule {
            Rule::no_approximation => ast::PolicyKind::NoApproximation,
            Rule::use_most_recent => ast::PolicyKind::UseMostRecent,
            Rule::any_update => ast::PolicyKind::AnyUpdate,
            Rule::any_change => ast::PolicyKind::AnyChange,
            Rule::sample_every => ast::PolicyKind::SampleEvery(first?),
            Rule::max_delay => ast::PolicyKind::MaxDelay(first?),
            Rule::duration_window => {
                ast::PolicyKind::Duration { from: first?, to: durations.get(1).copied() }
            }
            Rule::any_order => ast::PolicyKind::AnyOrder,
            Rule::monotone_order => ast::PolicyKind::MonotoneOrder,
            Rule::strict_order => ast::PolicyKind::StrictOrder,
            Rule::queue_policy => ast::PolicyKind::Queue { capacity, overflow },
            Rule::feedback => ast::PolicyKind::Feedback,
            _ => return None,
        };
        Some(ast::Policy { kind, span })
    }

    fn link_decl(&mut self, pair: Pair<'_, Rule>) -> ast::LinkDecl {
        let span = self.span(&pair);
        let mut idents = Vec::new();
        let mut via = placeholder_call(span);
        let mut clauses = Vec::new();
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::ident => idents.push(self.ident(p)),
                Rule::call => via = self.call(p),
                Rule::link_input => {
                    let clause_span = self.span(&p);
                    if let Some(path) = p.into_inner().find(|i| i.as_rule() == Rule::path) {
                        clauses.push(ast::LinkClause::Input(self.path(path), clause_span));
                    }
                }
                Rule::condition => {
                    let clause_span = self.span(&p);
                    let mut kind = ast::ConditionKind::Maintain;
                    let mut formula = None;
                    for c in p.into_inner() {
                        match c.as_rule() {
                            Rule::condition_kind => {
                                kind = match c.as_str() {
                                    "establish" => ast::ConditionKind::Establish,
                                    "reestablish" => ast::ConditionKind::Reestablish,
                                    _ => ast::ConditionKind::Maintain,
                                }
                            }
                            Rule::expr => formula = Some(self.expr(c)),
                            _ => {}
                        }
                    }
                    if let Some(formula) = formula {
                        clauses.push(ast::LinkClause::Condition(ast::Condition {
                            kind,
                            formula,
                            span: clause_span,
                        }));
                    }
                }
                _ => {}
            }
        }
        let mut idents = idents.into_iter();
        let mut next = || idents.next().unwrap_or_else(|| placeholder_ident(span));
        ast::LinkDecl { name: next(), from_type: next(), to_type: next(), via, clauses, span }
    }

    fn predict_decl(&mut self, pair: Pair<'_, Rule>) -> ast::PredictDecl {
        let span = self.span(&pair);
        let mut decl = ast::PredictDecl { ty: placeholder_ident(span), model: placeholder_call(span), span };
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::ident => decl.ty = self.ident(p),
                Rule::call => decl.model = self.call(p),
                _ => {}
            }
        }
        decl
    }

    fn forget_decl(&mut self, pair: Pair<'_, Rule>) -> ast::ForgetDecl {
        let span = self.span(&pair);
        let mut decl = ast::ForgetDecl {
            ty: None,
            after: ast::DurationLit { value: ast::Number::Int(0), unit: kpl_core::TimeUnit::S, span },
            sooner: None,
            span,
        };
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::ident => decl.ty = Some(self.ident(p)),
                Rule::duration => decl.after = self.duration(p),
                Rule::forget_sooner => decl.sooner = Some(self.forget_sooner(p)),
                _ => {}
            }
        }
        decl
    }

    fn forget_sooner(&mut self, pair: Pair<'_, Rule>) -> ast::ForgetSooner {
        let span = self.span(&pair);
        let mut sooner = ast::ForgetSooner {
            after: ast::DurationLit { value: ast::Number::Int(0), unit: kpl_core::TimeUnit::S, span },
            condition: ast::Expr { kind: ast::ExprKind::Bool(true), span },
            span,
        };
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::duration => sooner.after = self.duration(p),
                Rule::expr => sooner.condition = self.expr(p),
                _ => {}
            }
        }
        sooner
    }

    fn identify_decl(&mut self, pair: Pair<'_, Rule>) -> ast::IdentifyDecl {
        let span = self.span(&pair);
        let mut idents = Vec::new();
        let mut description = ast::Expr { kind: ast::ExprKind::Bool(true), span };
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::ident => idents.push(self.ident(p)),
                Rule::expr => description = self.expr(p),
                _ => {}
            }
        }
        let mut idents = idents.into_iter();
        let name = idents.next().unwrap_or_else(|| placeholder_ident(span));
        let ty = idents.next().unwrap_or_else(|| placeholder_ident(span));
        ast::IdentifyDecl { name, ty, description, span }
    }

    fn monitor_decl(&mut self, pair: Pair<'_, Rule>) -> ast::MonitorDecl {
        let span = self.span(&pair);
        let mut name = placeholder_ident(span);
        let mut formula = ast::Expr { kind: ast::ExprKind::Bool(true), span };
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::ident => name = self.ident(p),
                Rule::expr => formula = self.expr(p),
                _ => {}
            }
        }
        ast::MonitorDecl { name, formula, span }
    }

    fn chronicle_decl(&mut self, pair: Pair<'_, Rule>) -> ast::ChronicleDecl {
        let span = self.span(&pair);
        let mut decl =
            ast::ChronicleDecl { name: placeholder_ident(span), params: vec![], clauses: vec![], span };
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::ident => decl.name = self.ident(p),
                Rule::chronicle_params => {
                    for param in p.into_inner() {
                        let span = self.span(&param);
                        let mut idents = param.into_inner().map(|i| self.ident(i));
                        let name = idents.next().unwrap_or_else(|| placeholder_ident(span));
                        let ty = idents.next().unwrap_or_else(|| placeholder_ident(span));
                        decl.params.push(ast::ChronicleParam { name, ty, span });
                    }
                }
                Rule::chronicle_event => {
                    let span = self.span(&p);
                    let mut name = placeholder_ident(span);
                    let mut pattern = None;
                    for e in p.into_inner() {
                        match e.as_rule() {
                            Rule::ident => name = self.ident(e),
                            Rule::event_pattern => pattern = Some(self.event_pattern(e)),
                            _ => {}
                        }
                    }
                    let pattern = pattern.unwrap_or_else(|| placeholder_pattern(span));
                    decl.clauses.push(ast::ChronicleClause::Event(ast::ChronicleEvent {
                        name,
                        pattern,
                        span,
                    }));
                }
                Rule::chronicle_constraint => {
                    let span = self.span(&p);
                    let mut idents = Vec::new();
                    let mut bounds = Vec::new();
                    for c in p.into_inner() {
                        match c.as_rule() {
                            Rule::ident => idents.push(self.ident(c)),
                            Rule::stn_bound => bounds.push(self.stn_bound(c)),
                            _ => {}
                        }
                    }
                    let mut idents = idents.into_iter();
                    let later = idents.next().unwrap_or_else(|| placeholder_ident(span));
                    let earlier = idents.next().unwrap_or_else(|| placeholder_ident(span));
                    let mut bounds = bounds.into_iter();
                    let lo = bounds.next().unwrap_or(ast::StnBound::Inf { negative: true });
                    let hi = bounds.next().unwrap_or(ast::StnBound::Inf { negative: false });
                    decl.clauses.push(ast::ChronicleClause::Constraint(ast::TimeConstraint {
                        later,
                        earlier,
                        lo,
                        hi,
                        span,
                    }));
                }
                Rule::chronicle_hold | Rule::chronicle_never => {
                    let span = self.span(&p);
                    let hold = p.as_rule() == Rule::chronicle_hold;
                    let mut idents = Vec::new();
                    let mut formula = None;
                    let mut pattern = None;
                    for c in p.into_inner() {
                        match c.as_rule() {
                            Rule::ident => idents.push(self.ident(c)),
                            Rule::expr => formula = Some(self.expr(c)),
                            Rule::event_pattern => pattern = Some(self.event_pattern(c)),
                            _ => {}
                        }
                    }
                    let mut idents = idents.into_iter();
                    let from = idents.next().unwrap_or_else(|| placeholder_ident(span));
                    let to = idents.next().unwrap_or_else(|| placeholder_ident(span));
                    decl.clauses.push(if hold {
                        let formula = formula.unwrap_or(ast::Expr { kind: ast::ExprKind::Bool(true), span });
                        ast::ChronicleClause::Hold(ast::HoldCondition { formula, from, to, span })
                    } else {
                        let pattern = pattern.unwrap_or_else(|| placeholder_pattern(span));
                        ast::ChronicleClause::Never(ast::NeverCondition { pattern, from, to, span })
                    });
                }
                _ => {}
            }
        }
        decl
    }

    fn event_pattern(&mut self, pair: Pair<'_, Rule>) -> ast::EventPattern {
        let span = self.span(&pair);
        let Some(inner) = pair.into_inner().next() else { return placeholder_pattern(span) };
        let rule = inner.as_rule();
        let mut predicate = None;
        let mut name = None;
        let mut args = Vec::new();
        let mut becomes = true;
        for p in inner.into_inner() {
            match p.as_rule() {
                Rule::expr => predicate = Some(self.expr(p)),
                Rule::ident => name = Some(self.ident(p)),
                Rule::event_args => args = p.into_inner().map(|a| self.ident(a)).collect(),
                Rule::boolean => becomes = p.as_str() == "true",
                _ => {}
            }
        }
        let name = name.unwrap_or_else(|| placeholder_ident(span));
        let kind = match rule {
            Rule::event_monitor => ast::EventPatternKind::Monitor { monitor: name, args, becomes },
            Rule::event_recognised => ast::EventPatternKind::Recognised { chronicle: name, args },
            _ => ast::EventPatternKind::Change {
                predicate: predicate.unwrap_or(ast::Expr { kind: ast::ExprKind::Bool(true), span }),
                becomes,
            },
        };
        ast::EventPattern { kind, span }
    }

    fn stn_bound(&mut self, pair: Pair<'_, Rule>) -> ast::StnBound {
        let mut negative = false;
        let mut bound = ast::StnBound::Inf { negative: false };
        for p in pair.into_inner() {
            match p.as_rule() {
                Rule::stn_negative => negative = true,
                Rule::duration => bound = ast::StnBound::Duration { negative, value: self.duration(p) },
                _ => bound = ast::StnBound::Inf { negative },
            }
        }
        bound
    }

    fn deploy_decl(&mut self, pair: Pair<'_, Rule>) -> ast::DeployDecl {
        let span = self.span(&pair);
        let mut hosts = Vec::new();
        let mut name = None;
        for p in pair.clone().into_inner().filter(|p| p.as_rule() == Rule::deploy_name) {
            if let Some(inner) = p.into_inner().next() {
                let span = self.span(&inner);
                name = Some(match inner.as_rule() {
                    Rule::string => ast::Literal { kind: ast::LitKind::Str(self.string(inner)), span },
                    _ => ast::Literal { kind: ast::LitKind::Str(inner.as_str().to_string()), span },
                });
            }
        }
        for host in pair.into_inner().filter(|p| p.as_rule() == Rule::host_decl) {
            let host_span = self.span(&host);
            let mut decl = ast::HostDecl {
                name: placeholder_ident(host_span),
                listen: vec![],
                connect: vec![],
                processes: vec![],
                span: host_span,
            };
            let mut seen_name = false;
            for p in host.into_inner() {
                match p.as_rule() {
                    Rule::ident if !seen_name => {
                        decl.name = self.ident(p);
                        seen_name = true;
                    }
                    Rule::ident => decl.processes.push(self.ident(p)),
                    Rule::host_listen | Rule::host_connect => {
                        let listen = p.as_rule() == Rule::host_listen;
                        let mut endpoints = Vec::new();
                        for e in p.into_inner().filter(|e| e.as_rule() == Rule::endpoints) {
                            for s in e.into_inner() {
                                let span = self.span(&s);
                                endpoints
                                    .push(ast::Literal { kind: ast::LitKind::Str(self.string(s)), span });
                            }
                        }
                        if listen { decl.listen.extend(endpoints) } else { decl.connect.extend(endpoints) }
                    }
                    _ => {}
                }
            }
            hosts.push(decl);
        }
        ast::DeployDecl { name, hosts, span }
    }

    fn interval(&mut self, pair: Pair<'_, Rule>) -> ast::Interval {
        let span = self.span(&pair);
        let mut bounds = pair.into_inner().filter_map(|b| b.into_inner().next()).map(|b| match b.as_rule() {
            Rule::kw_inf => ast::Bound::Inf,
            Rule::duration => ast::Bound::Duration(self.duration(b)),
            _ => match b.as_str().parse::<u64>() {
                Ok(n) => ast::Bound::Ticks(n),
                Err(_) => {
                    self.diagnostics.push(diag::number_out_of_range(self.span(&b), b.as_str()));
                    ast::Bound::Ticks(0)
                }
            },
        });
        let lo = bounds.next().unwrap_or(ast::Bound::Ticks(0));
        let hi = bounds.next().unwrap_or(ast::Bound::Inf);
        ast::Interval { lo, hi, span }
    }

    /// Builds an expression from the flat sequence `prefix* primary (infix prefix* primary)*`
    /// with an operator stack (shunting-yard), so that no chain length can exhaust the stack.
    fn expr(&mut self, pair: Pair<'_, Rule>) -> ast::Expr {
        self.expr_operand(pair).expr
    }

    fn expr_operand(&mut self, pair: Pair<'_, Rule>) -> Operand {
        let mut operands: Vec<Operand> = Vec::new();
        let mut operators: Vec<Op> = Vec::new();
        let mut too_deep = false;
        for p in pair.into_inner() {
            let span = self.span(&p);
            match p.as_rule() {
                Rule::op_not => operators.push(Op::Prefix(Prefix::Not, span)),
                Rule::op_neg => operators.push(Op::Prefix(Prefix::Neg, span)),
                Rule::temporal => {
                    let mut op = ast::TemporalOp::Eventually;
                    let mut interval = None;
                    for t in p.into_inner() {
                        match t.as_rule() {
                            Rule::kw_always => op = ast::TemporalOp::Always,
                            Rule::interval => interval = Some(self.interval(t)),
                            _ => {}
                        }
                    }
                    operators.push(Op::Prefix(Prefix::Temporal(op, interval), span));
                }
                Rule::quantifier => {
                    let mut quantifier = ast::Quantifier::Forall;
                    let mut names = Vec::new();
                    for q in p.into_inner() {
                        match q.as_rule() {
                            Rule::kw_exists => quantifier = ast::Quantifier::Exists,
                            Rule::ident => names.push(self.ident(q)),
                            _ => {}
                        }
                    }
                    let mut names = names.into_iter();
                    let var = names.next().unwrap_or_else(|| placeholder_ident(span));
                    let ty = names.next().unwrap_or_else(|| placeholder_ident(span));
                    operators.push(Op::Prefix(Prefix::Quantified(quantifier, var, ty), span));
                }
                rule if infix_rule(rule) => {
                    let op = self.infix(p);
                    while let Some(top) = operators.last() {
                        let reduce = match top {
                            Op::Prefix(..) => top.precedence() >= op.precedence(),
                            Op::Infix(_) => {
                                top.precedence() > op.precedence()
                                    || (top.precedence() == op.precedence() && !op.right_associative())
                            }
                        };
                        if !reduce {
                            break;
                        }
                        self.reduce(&mut operands, &mut operators, &mut too_deep);
                    }
                    operators.push(op);
                }
                _ => {
                    let operand = self.primary(p);
                    operands.push(operand);
                }
            }
        }
        while !operators.is_empty() {
            self.reduce(&mut operands, &mut operators, &mut too_deep);
        }
        operands.pop().unwrap_or(Operand {
            expr: ast::Expr { kind: ast::ExprKind::Bool(false), span: Span::new(self.base, self.base) },
            depth: 1,
            bare_comparison: false,
        })
    }

    fn infix(&mut self, pair: Pair<'_, Rule>) -> Op {
        use ast::BinaryOp as B;
        let op = match pair.as_rule() {
            Rule::op_implies => Infix::Binary(B::Implies),
            Rule::op_or => Infix::Or,
            Rule::op_and => Infix::And,
            Rule::op_until => {
                let interval =
                    pair.into_inner().find(|p| p.as_rule() == Rule::interval).map(|i| self.interval(i));
                Infix::Until(interval)
            }
            Rule::op_le => Infix::Binary(B::Le),
            Rule::op_ge => Infix::Binary(B::Ge),
            Rule::op_eq => Infix::Binary(B::Eq),
            Rule::op_ne => Infix::Binary(B::Ne),
            Rule::op_lt => Infix::Binary(B::Lt),
            Rule::op_gt => Infix::Binary(B::Gt),
            Rule::op_add => Infix::Binary(B::Add),
            Rule::op_sub => Infix::Binary(B::Sub),
            Rule::op_mul => Infix::Binary(B::Mul),
            Rule::op_div => Infix::Binary(B::Div),
            _ => Infix::Binary(B::Rem),
        };
        Op::Infix(op)
    }

    fn primary(&mut self, pair: Pair<'_, Rule>) -> Operand {
        let span = self.span(&pair);
        let leaf = |kind| Operand { expr: ast::Expr { kind, span }, depth: 1, bare_comparison: false };
        match pair.as_rule() {
            Rule::duration => leaf(ast::ExprKind::Duration(self.duration(pair))),
            Rule::number => leaf(ast::ExprKind::Number(self.number(&pair))),
            Rule::string => leaf(ast::ExprKind::Str(self.string(pair))),
            Rule::boolean => leaf(ast::ExprKind::Bool(pair.as_str() == "true")),
            Rule::path => leaf(ast::ExprKind::Path(self.path(pair))),
            Rule::paren => match pair.into_inner().next() {
                Some(inner) => Operand { bare_comparison: false, ..self.expr_operand(inner) },
                None => leaf(ast::ExprKind::Bool(false)),
            },
            Rule::call_expr => {
                let mut inner = pair.into_inner();
                let func = inner.next().map_or_else(|| placeholder_ident(span), |f| self.ident(f));
                let mut depth = 1;
                let mut args = Vec::new();
                for arg in inner {
                    let operand = self.expr_operand(arg);
                    depth = depth.max(operand.depth + 1);
                    args.push(operand.expr);
                }
                Operand {
                    expr: ast::Expr { kind: ast::ExprKind::Call { func, args }, span },
                    depth,
                    bare_comparison: false,
                }
            }
            _ => leaf(ast::ExprKind::Bool(false)),
        }
    }

    /// Applies the operator on top of the stack to its operands.
    fn reduce(&mut self, operands: &mut Vec<Operand>, operators: &mut Vec<Op>, too_deep: &mut bool) {
        let Some(op) = operators.pop() else { return };
        let result = match op {
            Op::Prefix(prefix, op_span) => {
                let Some(operand) = operands.pop() else { return };
                let span = op_span.to(operand.expr.span);
                let body = Box::new(operand.expr);
                let kind = match prefix {
                    Prefix::Not => ast::ExprKind::Unary { op: ast::UnaryOp::Not, expr: body },
                    Prefix::Neg => ast::ExprKind::Unary { op: ast::UnaryOp::Neg, expr: body },
                    Prefix::Temporal(op, interval) => ast::ExprKind::Temporal { op, interval, body },
                    Prefix::Quantified(quantifier, var, ty) => {
                        ast::ExprKind::Quantified { quantifier, var, ty, body }
                    }
                };
                Operand { expr: ast::Expr { kind, span }, depth: operand.depth + 1, bare_comparison: false }
            }
            Op::Infix(infix) => {
                let (Some(rhs), Some(lhs)) = (operands.pop(), operands.pop()) else { return };
                let span = lhs.expr.span.to(rhs.expr.span);
                match infix {
                    Infix::And | Infix::Or => {
                        let and = matches!(infix, Infix::And);
                        let depth = flat_depth(&lhs, and).max(flat_depth(&rhs, and));
                        // Extend the left operand's list in place: a chain of n `and`s costs O(n).
                        let mut items = match lhs.expr.kind {
                            ast::ExprKind::And(children) if and => children,
                            ast::ExprKind::Or(children) if !and => children,
                            kind => vec![ast::Expr { kind, span: lhs.expr.span }],
                        };
                        match rhs.expr.kind {
                            ast::ExprKind::And(children) if and => items.extend(children),
                            ast::ExprKind::Or(children) if !and => items.extend(children),
                            kind => items.push(ast::Expr { kind, span: rhs.expr.span }),
                        }
                        let kind = if and { ast::ExprKind::And(items) } else { ast::ExprKind::Or(items) };
                        Operand { expr: ast::Expr { kind, span }, depth, bare_comparison: false }
                    }
                    Infix::Until(interval) => Operand {
                        expr: ast::Expr {
                            kind: ast::ExprKind::Until {
                                interval,
                                lhs: Box::new(lhs.expr),
                                rhs: Box::new(rhs.expr),
                            },
                            span,
                        },
                        depth: lhs.depth.max(rhs.depth) + 1,
                        bare_comparison: false,
                    },
                    Infix::Binary(op) => {
                        if op.is_comparison() && (lhs.bare_comparison || rhs.bare_comparison) {
                            self.diagnostics.push(diag::chained_comparison(span));
                        }
                        Operand {
                            expr: ast::Expr {
                                kind: ast::ExprKind::Binary {
                                    op,
                                    lhs: Box::new(lhs.expr),
                                    rhs: Box::new(rhs.expr),
                                },
                                span,
                            },
                            depth: lhs.depth.max(rhs.depth) + 1,
                            bare_comparison: op.is_comparison(),
                        }
                    }
                }
            }
        };
        if result.depth > MAX_EXPR_DEPTH {
            if !*too_deep {
                self.diagnostics.push(diag::expression_too_deep(result.expr.span, MAX_EXPR_DEPTH));
                *too_deep = true;
            }
            // Keep the stack shallow: replace the over-deep tree by a leaf. Dropping it is safe,
            // as each of its children is within the limit.
            let span = result.expr.span;
            operands.push(Operand {
                expr: ast::Expr { kind: ast::ExprKind::Bool(false), span },
                depth: 1,
                bare_comparison: false,
            });
        } else {
            operands.push(result);
        }
    }
}

/// Depth of `operand` as an n-ary `and`/`or` node absorbing it: its children keep their depth.
fn flat_depth(operand: &Operand, and: bool) -> u32 {
    match &operand.expr.kind {
        ast::ExprKind::And(_) if and => operand.depth,
        ast::ExprKind::Or(_) if !and => operand.depth,
        _ => operand.depth + 1,
    }
}

fn infix_rule(rule: Rule) -> bool {
    matches!(
        rule,
        Rule::op_implies
            | Rule::op_or
            | Rule::op_and
            | Rule::op_until
            | Rule::op_le
            | Rule::op_ge
            | Rule::op_eq
            | Rule::op_ne
            | Rule::op_lt
            | Rule::op_gt
            | Rule::op_add
            | Rule::op_sub
            | Rule::op_mul
            | Rule::op_div
            | Rule::op_rem
    )
}

fn placeholder_ident(span: Span) -> ast::Ident {
    ast::Ident { name: String::new(), span }
}

fn placeholder_pattern(span: Span) -> ast::EventPattern {
    let predicate = ast::Expr { kind: ast::ExprKind::Bool(true), span };
    ast::EventPattern { kind: ast::EventPatternKind::Change { predicate, becomes: true }, span }
}

fn placeholder_path(span: Span) -> ast::Path {
    ast::Path { segments: vec![], span }
}

fn placeholder_call(span: Span) -> ast::Call {
    ast::Call { callee: placeholder_path(span), args: vec![], span }
}
