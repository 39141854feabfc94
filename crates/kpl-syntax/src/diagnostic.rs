//! Diagnostics: a stable code, a message, the span it is about, labels and a hint; and their
//! rendering as text (rustc-like, by codespan-reporting, with the source lines and every span
//! marked, optionally in colour) or as JSON objects.
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
    /// Every marked place (the primary span first, then the others in source order).
    pub labels: Vec<JsonLabel>,
}

/// One marked place of a diagnostic in `--format json`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct JsonLabel {
    pub line: usize,
    pub column: usize,
    pub end_line: usize,
    pub end_column: usize,
    /// The span the diagnostic is about (one per diagnostic), or a place that explains it.
    pub primary: bool,
    /// The text printed under the span (empty when there is none).
    pub message: String,
}

/// A span with its label, primary or secondary, in the order they are shown.
struct Mark<'d> {
    span: Span,
    label: &'d str,
    primary: bool,
}

impl Diagnostic {
    /// The primary span, then the secondary ones in source order.
    fn marks(&self) -> Vec<Mark<'_>> {
        let mut secondary: Vec<Mark<'_>> = self
            .secondary
            .iter()
            .map(|(span, label)| Mark { span: *span, label: label.as_str(), primary: false })
            .collect();
        secondary.sort_by_key(|m| (m.span.start, m.span.end));
        let primary = Mark { span: self.span, label: self.label.as_deref().unwrap_or(""), primary: true };
        std::iter::once(primary).chain(secondary).collect()
    }

    pub fn to_json(&self, file: &str, source: &str, index: &LineIndex) -> JsonDiagnostic {
        let (line, column) = index.line_col(source, self.span.start);
        let (end_line, end_column) = index.line_col(source, self.span.end);
        let labels = self
            .marks()
            .into_iter()
            .map(|m| {
                let (line, column) = index.line_col(source, m.span.start);
                let (end_line, end_column) = index.line_col(source, m.span.end);
                JsonLabel {
                    line,
                    column,
                    end_line,
                    end_column,
                    primary: m.primary,
                    message: m.label.to_string(),
                }
            })
            .collect();
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
            labels,
        }
    }

    /// Renders the diagnostic as plain text (no colours, so the output is stable for snapshots):
    /// the header with severity and code, `--> file:line:column`, the source lines with every
    /// label under its span in source order, and the hint. See [`Diagnostic::render_styled`].
    pub fn render(&self, file: &str, source: &str, index: &LineIndex) -> String {
        self.render_styled(file, source, index, false)
    }

    /// Renders the diagnostic as text, with ANSI colours when `colour` is set (for a terminal).
    /// The layout is codespan-reporting's, in rustc's style and ASCII characters. A line longer
    /// than [`LONG_LINE`] characters (a minified or generated file) is shown as a window of it
    /// around the primary span; labels on other lines then become notes with their positions.
    pub fn render_styled(&self, file: &str, source: &str, index: &LineIndex, colour: bool) -> String {
        use codespan_reporting::diagnostic::{Diagnostic as Report, Label, Severity as Level};
        let level = match self.severity {
            Severity::Error => Level::Error,
            Severity::Warning => Level::Warning,
        };
        let (line, column) = index.line_col(source, self.span.start);
        let excerpt = Excerpt::new(file, source, index, line, column);
        let mut notes = Vec::new();
        let mut labels = Vec::new();
        for mark in self.marks() {
            match excerpt.range(source, mark.span) {
                Some(range) => {
                    let label =
                        if mark.primary { Label::primary((), range) } else { Label::secondary((), range) };
                    labels.push(label.with_message(mark.label));
                }
                None => {
                    let (l, c) = index.line_col(source, mark.span.start);
                    notes.push(format!("at {file}:{l}:{c}: {}", mark.label));
                }
            }
        }
        if let Some(hint) = &self.hint {
            notes.push(format!("hint: {hint}"));
        }
        let report = Report::new(level)
            .with_code(self.code)
            .with_message(&self.message)
            .with_labels(labels)
            .with_notes(notes);
        let config = codespan_reporting::term::Config {
            chars: codespan_reporting::term::Chars::ascii(),
            ..Default::default()
        };
        let rendered = if colour {
            use codespan_reporting::term::termcolor::Ansi;
            let styles = codespan_reporting::term::Styles::default();
            let mut ansi = Ansi::new(Vec::new());
            let mut writer = codespan_reporting::term::StylesWriter::new(&mut ansi, &styles);
            codespan_reporting::term::emit_to_write_style(&mut writer, &config, &excerpt, &report)
                .map(|()| String::from_utf8_lossy(&ansi.into_inner()).into_owned())
        } else {
            codespan_reporting::term::emit_into_string(&config, &excerpt, &report)
        };
        // Rendering only fails on spans outside the file, which `Excerpt::range` rules out; the
        // header alone is still better than nothing.
        rendered.unwrap_or_else(|_| {
            format!(
                "{}[{}]: {}\n --> {file}:{line}:{column}\n",
                self.severity.as_str(),
                self.code,
                self.message
            )
        })
    }
}

/// Lines longer than this many characters are shown as a window around the primary span.
pub const LONG_LINE: usize = 240;
/// The width of that window, in characters.
const WINDOW: usize = 120;

/// The text codespan-reporting renders from: the whole file, or, when the primary span's line
/// is very long, a window of that one line (with its line number and columns kept).
struct Excerpt<'s> {
    name: &'s str,
    text: std::borrow::Cow<'s, str>,
    /// For a window: the 1-based line it comes from, the byte offset in the file where it
    /// starts and its first column.
    window: Option<(usize, usize, usize)>,
    /// Where the excerpt's lines start: the file's [`LineIndex`] (built once per file, not once
    /// per diagnostic, so that rendering many diagnostics of a large file stays linear).
    line_starts: std::borrow::Cow<'s, [usize]>,
}

impl<'s> Excerpt<'s> {
    fn new(name: &'s str, source: &'s str, index: &'s LineIndex, line: usize, column: usize) -> Excerpt<'s> {
        let line_text = index.line_text(source, line);
        if line_text.chars().nth(LONG_LINE).is_none() {
            return Excerpt {
                name,
                text: source.into(),
                window: None,
                line_starts: index.line_starts.as_slice().into(),
            };
        }
        let first_col = column.saturating_sub(WINDOW / 2).max(1);
        let line_start = line_text.as_ptr() as usize - source.as_ptr() as usize;
        let skip: usize = line_text.chars().take(first_col - 1).map(char::len_utf8).sum();
        let shown: String = line_text[skip..].chars().take(WINDOW).collect();
        Excerpt {
            name,
            text: shown.into(),
            window: Some((line, line_start + skip, first_col)),
            line_starts: vec![0].into(),
        }
    }

    /// Where a span of the file is in the excerpt (`None`: not shown in it).
    fn range(&self, source: &str, span: Span) -> Option<std::ops::Range<usize>> {
        let (start, end) = (span.start as usize, span.end as usize);
        match self.window {
            None => {
                let end = clamp_to_char_boundary(source, end.max(start));
                Some(clamp_to_char_boundary(source, start)..end)
            }
            Some((_, offset, _)) => {
                let len = self.text.len();
                if start < offset || start > offset + len {
                    return None;
                }
                let local_start = clamp_to_char_boundary(&self.text, start - offset);
                let local_end = clamp_to_char_boundary(&self.text, end.saturating_sub(offset).min(len));
                Some(local_start..local_end.max(local_start))
            }
        }
    }
}

impl<'a> codespan_reporting::files::Files<'a> for Excerpt<'_> {
    type FileId = ();
    type Name = &'a str;
    type Source = &'a str;

    fn name(&'a self, (): ()) -> Result<&'a str, codespan_reporting::files::Error> {
        Ok(self.name)
    }

    fn source(&'a self, (): ()) -> Result<&'a str, codespan_reporting::files::Error> {
        Ok(&self.text)
    }

    fn line_index(&'a self, (): (), byte_index: usize) -> Result<usize, codespan_reporting::files::Error> {
        Ok(self.line_starts.partition_point(|&start| start <= byte_index).saturating_sub(1))
    }

    fn line_number(&'a self, (): (), line_index: usize) -> Result<usize, codespan_reporting::files::Error> {
        Ok(self.window.map_or(line_index + 1, |(line, ..)| line))
    }

    fn column_number(
        &'a self,
        (): (),
        line_index: usize,
        byte_index: usize,
    ) -> Result<usize, codespan_reporting::files::Error> {
        let range = self.line_range((), line_index)?;
        let column = codespan_reporting::files::column_index(&self.text, range, byte_index) + 1;
        Ok(self.window.map_or(column, |(_, _, first_col)| column + first_col - 1))
    }

    fn line_range(
        &'a self,
        (): (),
        line_index: usize,
    ) -> Result<std::ops::Range<usize>, codespan_reporting::files::Error> {
        let start =
            *self.line_starts.get(line_index).ok_or(codespan_reporting::files::Error::LineTooLarge {
                given: line_index,
                max: self.line_starts.len() - 1,
            })?;
        let end = self.line_starts.get(line_index + 1).copied().unwrap_or(self.text.len());
        Ok(start..end)
    }
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
    fn renders_every_label_in_source_order_with_location_and_hint() {
        let src = "stream a = b\nstream a = c\n";
        let index = LineIndex::new(src);
        let diag = Diagnostic::error("E0102", Span::new(20, 21), "`a` is defined twice")
            .with_label("second definition")
            .with_secondary(Span::new(7, 8), "first defined here")
            .with_hint("rename one of them");
        let text = diag.render("x.kpl", src, &index);
        assert_eq!(
            text,
            "error[E0102]: `a` is defined twice\n  --> x.kpl:2:8\n  |\n1 | stream a = b\n  |        - first defined here\n2 | stream a = c\n  |        ^ second definition\n  |\n  = hint: rename one of them\n\n"
        );
        assert!(!text.contains('\x1b'), "plain text has no colour codes");
        let coloured = diag.render_styled("x.kpl", src, &index, true);
        assert!(coloured.contains("\x1b["), "{coloured:?}");
        let json = diag.to_json("x.kpl", src, &index);
        assert_eq!((json.line, json.column, json.end_line, json.end_column), (2, 8, 2, 9));
        let labels: Vec<_> =
            json.labels.iter().map(|l| (l.line, l.column, l.primary, l.message.as_str())).collect();
        assert_eq!(labels, [(2, 8, true, "second definition"), (1, 8, false, "first defined here")]);
    }

    #[test]
    fn secondary_labels_are_in_source_order() {
        let src = "a b c d\n";
        let index = LineIndex::new(src);
        let diag = Diagnostic::error("E0001", Span::new(0, 1), "m")
            .with_secondary(Span::new(6, 7), "third")
            .with_secondary(Span::new(2, 3), "first");
        let json = diag.to_json("x.kpl", src, &index);
        let columns: Vec<_> = json.labels.iter().map(|l| l.column).collect();
        assert_eq!(columns, [1, 3, 7]);
    }

    #[test]
    fn a_very_long_line_is_shown_as_a_window_with_true_columns() {
        let src = format!("{}bad{}\nnext line\n", "x".repeat(10_000), "y".repeat(10_000));
        let index = LineIndex::new(&src);
        let diag = Diagnostic::error("E0001", Span::new(10_000, 10_003), "unexpected")
            .with_label("here")
            .with_secondary(Span::new(20_004, 20_008), "elsewhere")
            .with_hint("fix it");
        let text = diag.render("big.kpl", &src, &index);
        assert!(text.contains("--> big.kpl:1:10001"), "{text}");
        assert!(text.contains("^^^ here"), "{text}");
        assert!(text.contains("at big.kpl:2:1: elsewhere"), "{text}");
        assert!(text.contains("hint: fix it"), "{text}");
        assert!(text.len() < 1_000, "{} bytes", text.len());
    }
}
