//! `kpl fmt`: rewrite spec files in the canonical layout (or check that they are).

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args as ClapArgs;

use crate::report::{self, DiagnosticFormat, Reporter, SourceFile};

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  kpl fmt specs/traffic/bridge.kpl\n  kpl fmt --check specs/\n  cat spec.kpl | kpl fmt - > formatted.kpl\n\nFormatting keeps every comment, is idempotent and never changes what a spec means.\nExit status: 0 done (or, with --check, nothing to change), 1 a file would change or does not parse, 2 I/O errors."
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
    let files = match report::expand(&args.files) {
        Ok(files) => files,
        Err(err) => {
            report::io_error(&args.files[0], &err);
            return ExitCode::from(2);
        }
    };
    let mut reporter = Reporter::new(DiagnosticFormat::Text);
    let mut io_failed = false;
    let mut would_change = Vec::new();
    for path in &files {
        let file = match SourceFile::read(path) {
            Ok(file) => file,
            Err(err) => {
                report::io_error(path, &err);
                io_failed = true;
                continue;
            }
        };
        if let Some(d) = &file.decode_error {
            reporter.report(&file, std::slice::from_ref(d));
            continue;
        }
        let formatted = match kpl_syntax::format::format(&file.text) {
            Ok(formatted) => formatted,
            Err(diagnostics) => {
                reporter.report(&file, &diagnostics);
                continue;
            }
        };
        if path.as_os_str() == "-" {
            let _ = std::io::stdout().lock().write_all(formatted.as_bytes());
            continue;
        }
        if formatted == file.text {
            continue;
        }
        if args.check {
            would_change.push(file.display_name());
        } else if let Err(err) = std::fs::write(path, formatted) {
            report::io_error(path, &err);
            io_failed = true;
        }
    }
    let errors = reporter.errors;
    reporter.finish();
    if !would_change.is_empty() {
        let mut stderr = std::io::stderr().lock();
        for name in &would_change {
            let _ = writeln!(stderr, "would reformat {name}");
        }
    }
    if io_failed {
        ExitCode::from(2)
    } else if errors > 0 || !would_change.is_empty() {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    }
}
