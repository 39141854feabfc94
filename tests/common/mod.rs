//! What the end-to-end tests of the `kpl` command share: the workspace, the built binary, fresh
//! output folders, recorded JSON lines. Each test file uses the part it needs.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

/// The workspace (the tests run from `kpl/`).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// The built `kpl` with `args`, run from the workspace, without colours.
pub fn kpl_command(args: &[&str]) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_kpl"));
    command.args(args).current_dir(root()).env("NO_COLOR", "1");
    command
}

/// Runs the built `kpl` with `args` from the workspace and waits for it.
pub fn kpl(args: &[&str]) -> Output {
    kpl_command(args).output().unwrap()
}

/// A test's folder in the system's temporary folder, removed with everything in it when the
/// value is dropped, unless the test is failing then (the folder is kept to look at). It derefs
/// to its `Path`; keep it alive as long as the folder is used (a `fresh_dir(..).join(..)` would
/// drop it at once).
#[derive(Debug)]
pub struct TestDir(PathBuf);

impl std::ops::Deref for TestDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TestDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for TestDir {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

impl Drop for TestDir {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

impl TestDir {
    /// `path` (a file or folder in this one), keeping this folder as long as it lives.
    pub fn holding(self, path: PathBuf) -> InTestDir {
        InTestDir { path, _dir: self }
    }
}

/// A path in a [`TestDir`] that keeps the folder alive; derefs to the path.
#[derive(Debug)]
pub struct InTestDir {
    path: PathBuf,
    _dir: TestDir,
}

impl std::ops::Deref for InTestDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.path
    }
}

impl AsRef<Path> for InTestDir {
    fn as_ref(&self) -> &Path {
        &self.path
    }
}

/// An empty folder `kpl-{prefix}-{name}-{pid}` in the system's temporary folder, removed when
/// the returned [`TestDir`] is dropped.
pub fn fresh_dir(prefix: &str, name: &str) -> TestDir {
    let dir = std::env::temp_dir().join(format!("kpl-{prefix}-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    TestDir(dir)
}

/// The JSON values of a JSON lines file.
pub fn lines(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

/// A base port whose next `n` ports on 127.0.0.1 are free now (the processes bind them a moment
/// later).
pub fn free_ports(n: u16) -> u16 {
    for _ in 0..100 {
        let probe = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let base = probe.local_addr().unwrap().port();
        drop(probe);
        if base.checked_add(n).is_some()
            && (0..n).all(|i| std::net::TcpListener::bind(("127.0.0.1", base + i)).is_ok())
        {
            return base;
        }
    }
    panic!("no {n} free consecutive ports on 127.0.0.1");
}

/// The Python of the test oracles (`KPL_PYTHON`, set by scripts/test), or `None` with a note that
/// the test was skipped for want of a Python with `needs`; under `KPL_REQUIRE_ORACLES=1` a missing
/// Python is a failure.
#[allow(clippy::print_stderr, reason = "a skipped test says so")]
pub fn python(needs: &str) -> Option<String> {
    match std::env::var("KPL_PYTHON") {
        Ok(python) if !python.is_empty() => Some(python),
        _ => {
            if std::env::var("KPL_REQUIRE_ORACLES").is_ok_and(|v| v == "1") {
                panic!("KPL_REQUIRE_ORACLES=1 but KPL_PYTHON is not set (scripts/test sets both)");
            }
            eprintln!("skipped: set KPL_PYTHON to a Python with {needs} (scripts/test does)");
            None
        }
    }
}
