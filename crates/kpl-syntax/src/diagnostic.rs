//! Diagnostics: a stable code, a message, the span it is about, labels and a hint; and their
//! rendering as text (rustc-like, with the source line and the span marked) or as JSON objects.
//!
//! Every diagnostic code is documented in `docs/diagnostics.md` with an example; a test checks
//! that the list there and the codes used in the code base agree.

use serde::Serialize;

use crate::ast::Span;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Severity {
    Error,
    Warning,
}

impl Severity {
    pub fn as_str(self) -> &'static str {
        match self {
            Severity::Error => "error",
            Severity::Warning => "warning",
        }
    }
}

/// One problem found in a file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Diagnostic {
    pub severity: Severity,
    /// A stable code such as `E0101`; see `docs/diagnostics.md`.
    pub code: &'static str,
    pub message: String,
    /// Where the problem is.
    pub span: Span,
    /// Text printed under the marked span.
    pub label: Option<String>,
    /// Other places that explain the problem (a previous definition, ...).
    pub secondary: Vec<(Span, String)>,
    /// What to do about it.
    pub hint: Option<String>,
}

impl Diagnostic {
    pub fn error(code: &'static str, span: Span, message: impl Into<String>) -> Diagnostic {
        Diagnostic {
            severity: Severity::Error,
            code,
            message: message.into(),
            span,
            label: None,
            secondary: Vec::new(),
            hint: None,
        }
    }

    pub fn warning(code: &'static str, span: Span, message: impl Into<String>) -> Diagnostic {
        Diagnostic { severity: Severity::Warning, ..Diagnostic::error(code, span, message) }
    }

    pub fn with_label(mut self, label: impl Into<String>) -> Diagnostic {
        self.label = Some(label.into());
        self
    }

    pub fn with_hint(mut self, hint: impl Into<String>) -> Diagnostic {
        self.hint = Some(hint.into());
        self
    }

    pub fn with_hint_opt(mut self, hint: Option<String>) -> Diagnostic {
        if hint.is_some() {
            self.hint = hint;
        }
        self
    }

    pub fn with_secondary(mut self, span: Span, label: impl Into<String>) -> Diagnostic {
        self.secondary.push((span, label.into()));
        self
    }

    pub fn is_error(&self) -> bool {
        self.severity == Severity::Error
    }

    /// Moves the spans by `offset` bytes (for diagnostics of a piece parsed on its own).
    pub fn shifted(mut self, offset: u32) -> Diagnostic {
        let shift = |s: Span| Span::new(s.start + offset, s.end + offset);
        self.span = shift(self.span);
        for (span, _) in &mut self.secondary {
            *span = shift(*span);
        }
        self
    }
}

/// Maps byte offsets to 1-based lines and columns (columns count characters, not bytes).
#[derive(Debug, Clone)]
pub struct LineIndex {
    line_starts: Vec<usize>,
}

impl LineIndex {
    pub fn new(source: &str) -> LineIndex {
        let mut line_starts = vec![0];
        line_starts.extend(source.bytes().enumerate().filter(|(_, b)| *b == b'\n').map(|(i, _)| i + 1));
        LineIndex { line_starts }
    }

    /// 1-based line and column of a byte offset (clamped to the source).
    pub fn line_col(&self, source: &str, offset: u32) -> (usize, usize) {
        let offset = clamp_to_char_boundary(source, offset as usize);
        let line = self.line_starts.partition_point(|&start| start <= offset).max(1);
        let start = self.line_starts[line - 1];
        let column = source[start..offset].chars().count() + 1;
        (line, column)
    }

    /// The text of a 1-based line, without its line break.
    pub fn line_text<'a>(&self, source: &'a str, line: usize) -> &'a str {
        let start = self.line_starts.get(line - 1).copied().unwrap_or(source.len()).min(source.len());
        let end = self.line_starts.get(line).map_or(source.len(), |&next| next - 1).max(start);
        source[start..end].trim_end_matches('\r')
    }
}

fn clamp_to_char_boundary(source: &str, mut offset: usize) -> usize {
    offset = offset.min(source.len());
    while !source.is_char_boundary(offset) {
        offset -= 1;
    }
    offset
}

/// A diagnostic located in a file, in the shape `--format json` prints.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct JsonDiagnostic {
    pub file: String,
    pub line: usize,
    pub column: usize,
    /// Line of the end of the span.
    pub end_line: usize,
    /// Column just past the end of the span (exclusive).
    pub end_column: usize,
    pub severity: Severity,
    pub code: String,
    pub message: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hint: Option<String>,
}

impl Diagnostic {
    pub fn to_json(&self, file: &str, source: &str, index: &LineIndex) -> JsonDiagnostic {
        let (line, column) = index.line_col(source, self.span.start);
        let (end_line, end_column) = index.line_col(source, self.span.end);
        JsonDiagnostic {
            file: file.to_string(),
            line,
            column,
            end_line,
            end_column,
            severity: self.severity,
            code: self.code.to_string(),
            message: self.message.clone(),
            hint: self.hint.clone(),
        }
    }

    /// Renders the diagnostic as text: header, location, the source line with the span marked,
    /// secondary labels and the hint. No colours, so the output is stable for snapshots.
    pub fn render(&self, file: &str, source: &str, index: &LineIndex) -> String {
        use std::fmt::Write;
        let mut out = String::new();
        let (line, column) = index.line_col(source, self.span.start);
        let _ = writeln!(out, "{}[{}]: {}", self.severity.as_str(), self.code, self.message);
        let gutter = digits(line).max(
            self.secondary.iter().map(|(s, _)| digits(index.line_col(source, s.start).0)).max().unwrap_or(0),
        );
        let pad = " ".repeat(gutter);
        let _ = writeln!(out, "{pad}--> {file}:{line}:{column}");
        let _ = writeln!(out, "{pad} |");
        // The primary span's line first, with any secondary labels on that same line under it;
        // then each other line once, with its labels.
        let mut marks: Vec<(usize, Span, Option<&str>, char)> =
            vec![(line, self.span, self.label.as_deref(), '^')];
        for (span, label) in &self.secondary {
            marks.push((index.line_col(source, span.start).0, *span, Some(label.as_str()), '-'));
        }
        let mut shown_lines: Vec<usize> = Vec::new();
        for &(mark_line, ..) in &marks {
            if shown_lines.contains(&mark_line) {
                continue;
            }
            shown_lines.push(mark_line);
            let on_line: Vec<_> =
                marks.iter().filter(|m| m.0 == mark_line).map(|m| (m.1, m.2, m.3)).collect();
            snippet(&mut out, source, index, &on_line, gutter);
        }
        if let Some(hint) = &self.hint {
            let _ = writeln!(out, "{pad} = hint: {hint}");
        }
        out
    }
}

fn digits(n: usize) -> usize {
    n.to_string().len()
}

fn snippet(
    out: &mut String,
    source: &str,
    index: &LineIndex,
    marks: &[(Span, Option<&str>, char)],
    gutter: usize,
) {
    use std::fmt::Write;
    let Some((first, ..)) = marks.first() else { return };
    let (line, column) = index.line_col(source, first.start);
    let text = index.line_text(source, line);
    // Very long lines (a 50 MB single-line file) are cut around the first span.
    let (shown, first_col) = window(text, column);
    let shown_len = shown.chars().count();
    let _ = writeln!(out, "{line:>gutter$} | {}", shown.replace('\t', " "));
    for (span, label, mark) in marks {
        let (_, column) = index.line_col(source, span.start);
        let (end_line, end_column) = index.line_col(source, span.end);
        if column < first_col || column - first_col > shown_len {
            continue;
        }
        let width = if end_line == line {
            end_column.saturating_sub(column)
        } else {
            text.chars().count() + 1 - column
        };
        let width = width.clamp(1, (shown_len + 1 - (column - first_col)).max(1));
        let marker: String = std::iter::repeat_n(*mark, width).collect();
        let indent = " ".repeat(column - first_col);
        match label {
            Some(label) => {
                let _ = writeln!(out, "{:gutter$} | {indent}{marker} {label}", "");
            }
            None => {
                let _ = writeln!(out, "{:gutter$} | {indent}{marker}", "");
            }
        }
    }
}

/// Up to 120 characters of `text` around `column`; returns the shown text and its first column.
fn window(text: &str, column: usize) -> (String, usize) {
    const MAX: usize = 120;
    let total = text.chars().count();
    if total <= MAX {
        return (text.to_string(), 1);
    }
    let first = column.saturating_sub(MAX / 2).max(1);
    (text.chars().skip(first - 1).take(MAX).collect(), first)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_and_column_count_characters() {
        let src = "ab\nçd x\n";
        let index = LineIndex::new(src);
        assert_eq!(index.line_col(src, 0), (1, 1));
        assert_eq!(index.line_col(src, 3), (2, 1));
        // `x` is at byte 7 (ç is two bytes) but column 4.
        assert_eq!(index.line_col(src, 7), (2, 4));
        assert_eq!(index.line_text(src, 2), "çd x");
        assert_eq!(index.line_col(src, 999), (3, 1));
    }

    #[test]
    fn renders_span_hint_and_secondary() {
        let src = "stream a = b\nstream a = c\n";
        let index = LineIndex::new(src);
        let diag = Diagnostic::error("E0102", Span::new(20, 21), "`a` is defined twice")
            .with_label("second definition")
            .with_secondary(Span::new(7, 8), "first defined here")
            .with_hint("rename one of them");
        let text = diag.render("x.kpl", src, &index);
        assert_eq!(
            text,
            "error[E0102]: `a` is defined twice\n --> x.kpl:2:8\n  |\n2 | stream a = c\n  |        ^ second definition\n1 | stream a = b\n  |        - first defined here\n  = hint: rename one of them\n"
        );
        let json = diag.to_json("x.kpl", src, &index);
        assert_eq!((json.line, json.column, json.end_line, json.end_column), (2, 8, 2, 9));
    }
}
