//! `kpl check`: parse and check spec files against the registry's signatures (nothing of the
//! runtime is built).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Args as ClapArgs;

use crate::report::{self, DiagnosticFormat, Reporter, SourceFile};

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  kpl check specs/traffic/bridge.kpl\n  kpl check specs/ok specs/traffic\n  kpl check --format json specs/warn/unset_attribute.kpl > diagnostics.json\n\nEach diagnostic has a code; `kpl explain CODE` tells more about it. As text, the first 100\ndiagnostics are shown and the others counted; --format json has every one.\nExit status: 0 when every spec is valid (warnings allowed), 1 when a spec has errors, 2 for usage or I/O errors."
)]
pub struct Args {
    /// Spec files, or directories to search for `.kpl` files (`-` reads standard input).
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// How to print diagnostics (text: the first 100, and how many more).
    #[arg(long, value_enum, default_value = "text")]
    pub format: DiagnosticFormat,
}

/// Parses and checks one file, returning its diagnostics and, when it is valid, the checked spec.
pub fn check_file(file: &SourceFile) -> (Vec<kpl_syntax::Diagnostic>, Option<kpl_semantic::hir::Spec>) {
    if let Some(d) = &file.decode_error {
        return (vec![d.clone()], None);
    }
    let parse = kpl_syntax::parse(&file.text);
    if parse.has_errors() {
        return (parse.diagnostics, None);
    }
    // A spec's parameters that name files (a ROS 2 topic's `msgs`) are read beside it.
    let dir = (file.path != Path::new("-")).then(|| file.path.parent().unwrap_or(Path::new("")));
    let checked = kpl_semantic::check_in(&parse.spec, &crate::registry::signatures(), dir);
    let mut diagnostics = parse.diagnostics;
    diagnostics.extend(checked.diagnostics);
    (diagnostics, checked.spec)
}

/// Reads and checks one spec, printing its diagnostics; the checked spec, or the exit code to
/// stop with (1: the spec has errors, 2: it cannot be read).
pub fn load_checked(path: &Path) -> Result<kpl_semantic::hir::Spec, ExitCode> {
    let file = SourceFile::read(path).map_err(|err| {
        report::read_error(&err);
        ExitCode::from(2)
    })?;
    let (diagnostics, spec) = check_file(&file);
    let mut reporter = Reporter::new(DiagnosticFormat::Text);
    reporter.report(&file, &diagnostics);
    reporter.finish();
    spec.ok_or(ExitCode::from(1))
}

/// Reads each spec file that `paths` name (directories are searched for `.kpl` files) and hands
/// it to `each`; a file that cannot be read is reported and skipped. Returns whether some file
/// could not be read, or exit code 2 when `paths` cannot be listed.
pub(crate) fn for_each_file(
    paths: &[PathBuf],
    mut each: impl FnMut(&Path, SourceFile),
) -> Result<bool, ExitCode> {
    let files = report::expand(paths).map_err(|err| {
        report::io_error(&paths[0], &err);
        ExitCode::from(2)
    })?;
    let mut io_failed = false;
    for path in &files {
        match SourceFile::read(path) {
            Ok(file) => each(path, file),
            Err(err) => {
                report::read_error(&err);
                io_failed = true;
            }
        }
    }
    Ok(io_failed)
}

pub fn run(args: Args) -> ExitCode {
    let mut reporter = Reporter::new(args.format);
    let io_failed = match for_each_file(&args.files, |_, file| {
        let (diagnostics, _) = check_file(&file);
        reporter.report(&file, &diagnostics);
    }) {
        Ok(io_failed) => io_failed,
        Err(code) => return code,
    };
    let errors = reporter.errors;
    reporter.finish();
    if io_failed {
        ExitCode::from(2)
    } else if errors > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    }
}
