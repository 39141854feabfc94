//! Loading spec files and reporting their diagnostics, as text on stderr (in colour on a
//! terminal, see [`colour`]) or as one JSON array on stdout (`--format json`).

use std::io::Write;
use std::path::{Path, PathBuf};

use kpl_syntax::{Diagnostic, JsonDiagnostic, LineIndex};

/// A spec file read from disk. Bytes that are not UTF-8 become a diagnostic, and the text is
/// kept (lossily) so it can still be shown.
pub struct SourceFile {
    pub path: PathBuf,
    pub text: String,
    /// Set when the file is not UTF-8.
    pub decode_error: Option<Diagnostic>,
}

impl SourceFile {
    /// Reads a spec file (`-`: standard input) of at most [`kpl_syntax::MAX_SOURCE_BYTES`]; a
    /// larger one (or an endless one such as `/dev/zero`) is read no further than that and becomes
    /// the diagnostic E0005, with no text.
    pub fn read(path: &Path) -> Result<SourceFile, kpl_core::read::ReadError> {
        use kpl_core::read::{ReadError, read_capped, read_file};
        let limit = kpl_syntax::MAX_SOURCE_BYTES;
        let bytes = if path.as_os_str() == "-" {
            read_capped(std::io::stdin().lock(), limit)
                .map_err(|source| ReadError::Io { path: path.to_path_buf(), source })?
                .ok_or(ReadError::TooLarge { path: path.to_path_buf(), limit: limit as u64 })
        } else {
            read_file(path, limit)
        };
        let bytes = match bytes {
            Ok(bytes) => bytes,
            Err(ReadError::TooLarge { .. }) => {
                return Ok(SourceFile {
                    path: path.to_path_buf(),
                    text: String::new(),
                    decode_error: Some(kpl_syntax::diagnostics::file_over_limit(limit)),
                });
            }
            Err(error) => return Err(error),
        };
        Ok(match kpl_syntax::decode_source(&bytes) {
            Ok(text) => SourceFile { path: path.to_path_buf(), text: text.to_string(), decode_error: None },
            Err(diagnostic) => SourceFile {
                path: path.to_path_buf(),
                text: String::from_utf8_lossy(&bytes).into_owned(),
                decode_error: Some(diagnostic),
            },
        })
    }

    pub fn display_name(&self) -> String {
        if self.path.as_os_str() == "-" { "<stdin>".to_string() } else { self.path.display().to_string() }
    }
}

/// Expands directories into the `.kpl` files below them (sorted), keeps files as given.
pub fn expand(paths: &[PathBuf]) -> std::io::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for path in paths {
        if path.is_dir() {
            let mut found = Vec::new();
            collect_kpl(path, &mut found)?;
            found.sort();
            out.extend(found);
        } else {
            out.push(path.clone());
        }
    }
    Ok(out)
}

fn collect_kpl(dir: &Path, out: &mut Vec<PathBuf>) -> std::io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        if path.is_dir() {
            collect_kpl(&path, out)?;
        } else if path.extension().is_some_and(|e| e == "kpl") {
            out.push(path);
        }
    }
    Ok(())
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DiagnosticFormat {
    /// Human-readable, with the source line and the span marked.
    Text,
    /// A JSON array of {file, line, column, end_line, end_column, severity, code, message, hint,
    /// labels} (docs/diagnostics.md).
    Json,
}

/// The output of commands that print a result (`kpl list`, `kpl run`, `kpl bench zenoh`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum OutputFormat {
    /// For people.
    Text,
    /// JSON on stdout, for programs.
    Json,
}

/// How many diagnostics the text format shows in one run; the rest are counted under them (as
/// compilers cap their errors). `--format json` has every one.
pub const MAX_SHOWN: usize = 100;

/// Collects diagnostics across files and prints them in the chosen format.
pub struct Reporter {
    format: DiagnosticFormat,
    json: Vec<JsonDiagnostic>,
    /// The first code reported (for the `kpl explain` pointer under the summary).
    first_code: Option<&'static str>,
    pub errors: usize,
    pub warnings: usize,
    /// Diagnostics counted but not shown (text format, past [`MAX_SHOWN`]).
    hidden: usize,
}

impl Reporter {
    pub fn new(format: DiagnosticFormat) -> Reporter {
        Reporter { format, json: Vec::new(), first_code: None, errors: 0, warnings: 0, hidden: 0 }
    }

    pub fn report(&mut self, file: &SourceFile, diagnostics: &[Diagnostic]) {
        let index = LineIndex::new(&file.text);
        let name = file.display_name();
        for d in diagnostics {
            self.first_code.get_or_insert(d.code);
            if d.is_error() {
                self.errors += 1;
            } else {
                self.warnings += 1;
            }
            match self.format {
                DiagnosticFormat::Text if self.errors + self.warnings > MAX_SHOWN => self.hidden += 1,
                DiagnosticFormat::Text => {
                    let mut stderr = std::io::stderr().lock();
                    let _ = write!(stderr, "{}", d.render_styled(&name, &file.text, &index, colour()));
                }
                DiagnosticFormat::Json => self.json.push(d.to_json(&name, &file.text, &index)),
            }
        }
    }

    /// Prints the JSON array (json format) or a one-line summary (text format, when anything was found).
    pub fn finish(self) {
        match self.format {
            DiagnosticFormat::Json => {
                let mut stdout = std::io::stdout().lock();
                let _ = writeln!(
                    stdout,
                    "{}",
                    serde_json::to_string_pretty(&self.json).unwrap_or_else(|_| "[]".into())
                );
            }
            DiagnosticFormat::Text if self.errors + self.warnings > 0 => {
                let plural =
                    |n: usize, word: &str| if n == 1 { format!("1 {word}") } else { format!("{n} {word}s") };
                let mut stderr = std::io::stderr().lock();
                if self.hidden > 0 {
                    let (hidden, word) =
                        (self.hidden, if self.hidden == 1 { "diagnostic" } else { "diagnostics" });
                    let _ = writeln!(
                        stderr,
                        "... and {hidden} more {word} not shown (the first {MAX_SHOWN} are; `kpl check --format json` lists \
                         every one)"
                    );
                }
                let _ = writeln!(
                    stderr,
                    "{}, {}",
                    plural(self.errors, "error"),
                    plural(self.warnings, "warning")
                );
                if let Some(code) = self.first_code {
                    let _ = writeln!(stderr, "For more about a code, try `kpl explain {code}`.");
                }
            }
            DiagnosticFormat::Text => {}
        }
    }
}

/// Prints an I/O or usage problem (exit code 2).
pub fn io_error(path: &Path, err: &std::io::Error) {
    let mut stderr = std::io::stderr().lock();
    let _ = writeln!(stderr, "error: cannot read {}: {err}", path.display());
}

/// Prints a spec file that could not be read (exit code 2).
pub fn read_error(err: &kpl_core::read::ReadError) {
    let mut stderr = std::io::stderr().lock();
    let _ = writeln!(stderr, "error: {err}");
}

/// When to colour what goes to the terminal (`--color`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ColorChoice {
    /// On a terminal, unless `NO_COLOR` is set; never in a pipe or a file.
    #[default]
    Auto,
    Always,
    Never,
}

static COLOR: std::sync::OnceLock<ColorChoice> = std::sync::OnceLock::new();

/// Sets the `--color` choice (once, at start).
pub fn set_color(choice: ColorChoice) {
    let _ = COLOR.set(choice);
}

/// Whether text for stderr is coloured: `--color always`, or `auto` on a terminal without
/// `NO_COLOR` (<https://no-color.org>).
pub fn colour() -> bool {
    match COLOR.get().copied().unwrap_or_default() {
        ColorChoice::Always => true,
        ColorChoice::Never => false,
        ColorChoice::Auto => {
            std::io::IsTerminal::is_terminal(&std::io::stderr())
                && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty())
        }
    }
}
