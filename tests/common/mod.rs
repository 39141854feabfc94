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

/// An empty folder `kpl-{prefix}-{name}-{pid}` in the system's temporary folder.
pub fn fresh_dir(prefix: &str, name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("kpl-{prefix}-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The JSON values of a JSON lines file.
pub fn lines(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}
