//! Every diagnostic the syntax layer emits, one constructor each, so that codes and wording are
//! easy to find and keep consistent. Codes `E00xx` are syntax errors.

use crate::ast::Span;
use crate::diagnostic::Diagnostic;

pub const SYNTAX: &str = "E0001";
pub const NESTING: &str = "E0002";
pub const NUMBER_RANGE: &str = "E0003";
pub const ESCAPE: &str = "E0004";
pub const FILE_TOO_LARGE: &str = "E0005";
pub const CHAINED_COMPARISON: &str = "E0006";
pub const DURATION: &str = "E0007";

pub fn file_too_large(len: usize, max: usize) -> Diagnostic {
    Diagnostic::error(FILE_TOO_LARGE, Span::default(), format!("file is too large ({len} bytes)"))
        .with_hint(format!("spec files may be at most {} MiB; split the spec", max >> 20))
}

pub fn nesting_too_deep(span: Span, max: usize) -> Diagnostic {
    Diagnostic::error(NESTING, span, format!("brackets nest more than {max} deep"))
        .with_label("too deep")
        .with_hint("split the expression or the type into named parts")
}

pub fn expression_too_deep(span: Span, max: u32) -> Diagnostic {
    Diagnostic::error(NESTING, span, format!("expression nests more than {max} operators deep"))
        .with_label("too deep")
        .with_hint("split the formula into smaller monitors or conditions")
}

pub fn number_out_of_range(span: Span, text: &str) -> Diagnostic {
    Diagnostic::error(NUMBER_RANGE, span, format!("number `{text}` is out of range"))
        .with_label("out of range")
        .with_hint("integers are 64-bit signed; floats must be finite")
}

pub fn bad_escape(span: Span, escape: &str) -> Diagnostic {
    Diagnostic::error(ESCAPE, span, format!("unknown escape `\\{escape}` in string"))
        .with_label("in this string")
        .with_hint("strings accept \\\" \\\\ \\n \\t \\r and \\0")
}

pub fn chained_comparison(span: Span) -> Diagnostic {
    Diagnostic::error(CHAINED_COMPARISON, span, "comparisons cannot be chained")
        .with_label("two comparisons in a row")
        .with_hint("write `a < b and b < c`")
}

pub fn bad_duration(span: Span, exact: bool) -> Diagnostic {
    let message =
        if exact { "duration is out of range" } else { "duration is not a whole number of microseconds" };
    Diagnostic::error(DURATION, span, message)
        .with_label("this duration")
        .with_hint("durations are non-negative, count whole microseconds, and stay below about 146,000 years")
}

pub const NOT_UTF8: &str = "E0008";

pub fn not_utf8(offset: usize) -> Diagnostic {
    Diagnostic::error(NOT_UTF8, Span::new(offset as u32, offset as u32 + 1), "file is not valid UTF-8")
        .with_label("invalid byte sequence")
        .with_hint("save the spec as UTF-8 text")
}

/// A syntax error in the user's words (the parser words `message`, `label` and `hint` from what
/// pest expected).
pub fn syntax(span: Span, message: String, label: &str, hint: Option<String>) -> Diagnostic {
    Diagnostic::error(SYNTAX, span, message).with_label(label).with_hint_opt(hint)
}

/// A formula given on its own (`kpl mtl eval`, an identification) is empty.
pub fn expected_formula() -> Diagnostic {
    Diagnostic::error(SYNTAX, Span::default(), "expected a formula")
}
