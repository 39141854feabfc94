//! A light lexical pass run before the grammar: it finds comments (which `fmt` keeps), the
//! starts of top-level items (where the parser resumes after a syntax error), and rejects nesting
//! deeper than the parser's recursion can take, so that no input overflows the stack.

use crate::ast::Span;

/// Deepest bracket nesting (`(`, `[`, `{`, `list<`) accepted.
pub const MAX_NESTING: usize = 64;

/// Words that start a top-level item.
pub const ITEM_KEYWORDS: [&str; 12] = [
    "type",
    "source",
    "compute",
    "sink",
    "stream",
    "link",
    "predict",
    "forget",
    "identify",
    "monitor",
    "chronicle",
    "deploy",
];

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Comment {
    pub span: Span,
    /// The comment as written, including `//` or `/* */`.
    pub text: String,
}

#[derive(Debug, Default)]
pub struct Scan {
    pub comments: Vec<Comment>,
    /// Byte offsets of item keywords at the start of a line, outside comments and strings.
    pub item_starts: Vec<u32>,
    /// The first bracket that nests deeper than [`MAX_NESTING`].
    pub too_deep: Option<Span>,
}

pub fn scan(source: &str) -> Scan {
    let bytes = source.as_bytes();
    let mut out = Scan::default();
    let mut depth = 0usize;
    let mut list_run = 0usize;
    let mut at_line_start = true;
    let mut i = 0;
    while i < bytes.len() {
        let b = bytes[i];
        match b {
            b'\n' => {
                at_line_start = true;
                i += 1;
                continue;
            }
            b' ' | b'\t' | b'\r' => {
                i += 1;
                continue;
            }
            b'/' if bytes.get(i + 1) == Some(&b'/') => {
                let end = source[i..].find('\n').map_or(bytes.len(), |n| i + n);
                out.comments
                    .push(Comment { span: span(i, end), text: source[i..end].trim_end().to_string() });
                i = end;
                continue;
            }
            b'/' if bytes.get(i + 1) == Some(&b'*') => {
                let end = source[i + 2..].find("*/").map_or(bytes.len(), |n| i + 2 + n + 2);
                out.comments.push(Comment { span: span(i, end), text: source[i..end].to_string() });
                i = end;
                at_line_start = false;
                continue;
            }
            _ => {}
        }
        let line_start = std::mem::replace(&mut at_line_start, false);
        match b {
            b'"' => {
                // Skip the string; an unterminated one ends at the line break (as in the grammar).
                i += 1;
                while i < bytes.len() && bytes[i] != b'"' && bytes[i] != b'\n' {
                    i += if bytes[i] == b'\\' { 2 } else { 1 };
                }
                i += 1;
                list_run = 0;
            }
            b'(' | b'[' | b'{' => {
                depth += 1;
                if depth + list_run > MAX_NESTING && out.too_deep.is_none() {
                    out.too_deep = Some(span(i, i + 1));
                }
                i += 1;
            }
            b')' | b']' | b'}' => {
                depth = depth.saturating_sub(1);
                list_run = 0;
                i += 1;
            }
            _ if b.is_ascii_alphanumeric() || b == b'_' => {
                let start = i;
                while i < bytes.len() && (bytes[i].is_ascii_alphanumeric() || bytes[i] == b'_') {
                    i += 1;
                }
                let word = &source[start..i];
                if word == "list" && next_non_space(bytes, i) == Some(b'<') {
                    list_run += 1;
                    if depth + list_run > MAX_NESTING && out.too_deep.is_none() {
                        out.too_deep = Some(span(start, i));
                    }
                } else {
                    list_run = 0;
                }
                let next = next_non_space(bytes, i);
                let starts_item = match word {
                    "deploy" => next == Some(b'{'),
                    _ => next.is_some_and(|c| c.is_ascii_alphabetic() || c == b'_'),
                };
                if line_start && starts_item && ITEM_KEYWORDS.contains(&word) {
                    out.item_starts.push(start as u32);
                }
            }
            _ => {
                // Any other byte, including the rest of a multi-byte character.
                i += 1;
            }
        }
    }
    out
}

fn next_non_space(bytes: &[u8], mut i: usize) -> Option<u8> {
    while i < bytes.len() && bytes[i].is_ascii_whitespace() {
        i += 1;
    }
    bytes.get(i).copied()
}

fn span(start: usize, end: usize) -> Span {
    Span::new(start as u32, end as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_comments_and_item_starts_but_not_inside_strings() {
        let src =
            "// head\ntype A {\n  type: int }\n/* stream x\ntype B */ sink s = \"a // b\"\n  stream t = s\n";
        let scan = scan(src);
        let texts: Vec<&str> = scan.comments.iter().map(|c| c.text.as_str()).collect();
        assert_eq!(texts, ["// head", "/* stream x\ntype B */"]);
        let starts: Vec<&str> = scan.item_starts.iter().map(|&s| &src[s as usize..s as usize + 4]).collect();
        assert_eq!(starts, ["type", "stre"]);
        assert!(scan.too_deep.is_none());
    }

    #[test]
    fn rejects_deep_nesting_of_every_bracket_kind() {
        for (open, close) in [("(", ")"), ("[", "]"), ("list<", ">")] {
            let ok = format!("{}x{}", open.repeat(MAX_NESTING), close.repeat(MAX_NESTING));
            assert!(scan(&ok).too_deep.is_none(), "{open}");
            let deep = format!("{}x{}", open.repeat(MAX_NESTING + 1), close.repeat(MAX_NESTING + 1));
            assert!(scan(&deep).too_deep.is_some(), "{open}");
        }
    }
}
