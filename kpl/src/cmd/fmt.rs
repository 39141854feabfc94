//! `kpl fmt`: rewrite spec files in the canonical layout (or check that they are).

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args as ClapArgs;

use crate::report::{self, DiagnosticFormat, Reporter};

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  kpl fmt specs/traffic/bridge.kpl\n  kpl fmt --check specs/\n  kpl fmt - < specs/ok/ticks.kpl > formatted.kpl\n\nFormatting keeps every comment, is idempotent and never changes what a spec means. A file whose\nleading comments include the line `// kpl fmt: skip` is left as it is (specs/err/ has files that\ndo not parse on purpose).\nExit status: 0 done (or, with --check, nothing to change), 1 a file would change or does not parse, 2 I/O errors."
)]
pub struct Args {
    /// Spec files or directories (`-` formats standard input to standard output).
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Do not write; list the files whose layout differs and exit 1 if any does.
    #[arg(long)]
    pub check: bool,
}

pub fn run(args: Args) -> ExitCode {
    let mut reporter = Reporter::new(DiagnosticFormat::Text);
    let mut write_failed = false;
    let mut would_change = Vec::new();
    let mut skipped = 0usize;
    let read_failed = match super::check::for_each_file(&args.files, |path, file| {
        if path.as_os_str() != "-" && marked_skip(&file.text) {
            skipped += 1;
            return;
        }
        if let Some(d) = &file.decode_error {
            reporter.report(&file, std::slice::from_ref(d));
            return;
        }
        let formatted = match kpl_syntax::format::format(&file.text) {
            Ok(formatted) => formatted,
            Err(diagnostics) => {
                reporter.report(&file, &diagnostics);
                return;
            }
        };
        if path.as_os_str() == "-" {
            let _ = std::io::stdout().lock().write_all(formatted.as_bytes());
            return;
        }
        if formatted == file.text {
            return;
        }
        if args.check {
            would_change.push(file.display_name());
        } else if let Err(err) = std::fs::write(path, formatted) {
            report::io_error(path, &err);
            write_failed = true;
        }
    }) {
        Ok(read_failed) => read_failed,
        Err(code) => return code,
    };
    let io_failed = read_failed || write_failed;
    let errors = reporter.errors;
    reporter.finish();
    let mut stderr = std::io::stderr().lock();
    for name in &would_change {
        let _ = writeln!(stderr, "would reformat {name}");
    }
    if skipped > 0 {
        let files = if skipped == 1 { "file" } else { "files" };
        let _ = writeln!(stderr, "left {skipped} {files} marked `{SKIP_MARKER}` as they are");
    }
    if io_failed {
        ExitCode::from(2)
    } else if errors > 0 || !would_change.is_empty() {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    }
}

/// The comment that keeps `kpl fmt` away from a file.
pub const SKIP_MARKER: &str = "// kpl fmt: skip";

/// Whether the comment lines at the top of the file include [`SKIP_MARKER`]. Read from the text,
/// not the syntax tree, so that files that do not parse can carry it.
fn marked_skip(text: &str) -> bool {
    text.lines()
        .map(str::trim)
        .take_while(|line| line.is_empty() || line.starts_with("//"))
        .any(|line| line == SKIP_MARKER)
}

#[cfg(test)]
mod tests {
    use super::marked_skip;

    #[test]
    fn only_leading_comments_mark_a_file() {
        assert!(marked_skip("// kpl fmt: skip\nstream a = ("));
        assert!(marked_skip("// a syntax error on purpose\n\n  // kpl fmt: skip  \ntype A {}"));
        assert!(!marked_skip("type A {}\n// kpl fmt: skip\n"));
        assert!(!marked_skip("// kpl fmt: skipped\n"));
    }
}
