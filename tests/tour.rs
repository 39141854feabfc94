//! A newcomer's first hour, as a test: every command of the README's tour and every example of
//! every `--help` runs as written, in a copy of the shipped specs, with nothing but `kpl` on the
//! PATH, and exits 0 (1 for the tour's checks of `specs/err/`, which show errors on purpose).
//!
//! - A `--help` example written as a session (`$ cat trace.jsonl` and its lines, then `$ kpl ...`
//!   and what it prints) is replayed: the file is written as shown, and each command must print
//!   what the help shows.
//! - Benchmarks (`kpl bench ...`) run for minutes: each must start (load its inputs and begin)
//!   and not fail while it is watched; then it is stopped.
//! - The README's two-host pair is a separate block: `tests/zenoh.rs` runs it; so is its ROS 2
//!   command, which `tests/ros2.rs` runs against a ROS 2 node.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::disallowed_methods)] // tests; waits are bounded by the wall clock

mod common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{free_ports, kpl, root};

/// How long a benchmark is watched before it is stopped.
const WATCH: Duration = Duration::from_secs(5);
/// How long an ordinary command may take before it counts as hung.
const HANG: Duration = Duration::from_secs(600);

/// The commands of the first ```sh block after `## A tour` in README.md, with `\`-continued
/// lines joined; the line defining the `kpl` shell function is left out (the test provides `kpl`).
fn readme_tour() -> Vec<String> {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let tour = &readme[readme.find("## A tour").expect("README has a tour")..];
    let block = tour.split("```sh\n").nth(1).unwrap().split("```").next().unwrap();
    let mut commands = Vec::new();
    let mut pending = String::new();
    for line in block.lines() {
        if let Some(start) = line.strip_suffix('\\') {
            pending.push_str(start);
            continue;
        }
        pending.push_str(line);
        let command = std::mem::take(&mut pending);
        if !command.trim().is_empty() && !command.trim_start().starts_with("kpl()") {
            commands.push(command.trim().to_string());
        }
    }
    assert!(commands.len() >= 15, "{commands:?}");
    commands
}

/// Every subcommand path (`run`, `cater eval`, ...), from the `Commands:` sections of `--help`.
fn subcommands(prefix: &[String]) -> Vec<Vec<String>> {
    let mut args = prefix.to_vec();
    args.push("--help".to_string());
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let help = String::from_utf8(kpl(&args).stdout).unwrap();
    let mut out = Vec::new();
    let Some(section) = help.split("Commands:\n").nth(1) else { return out };
    for line in section.lines().take_while(|l| !l.trim().is_empty()) {
        // Subcommands are listed two spaces in; wrapped descriptions are indented further.
        let Some(name) = line.strip_prefix("  ").filter(|l| !l.starts_with(' ')) else { continue };
        let name = name.split_whitespace().next().unwrap().to_string();
        if name == "help" {
            continue;
        }
        let mut path = prefix.to_vec();
        path.push(name);
        out.push(path.clone());
        out.extend(subcommands(&path));
    }
    out
}

/// One example of a `--help`: a command, the files it needs written first, and the output the
/// help shows for it (for examples written as a session).
#[derive(Debug, Default)]
struct Example {
    command: String,
    files: Vec<(String, String)>,
    shows: Option<String>,
}

/// The examples of one `--help` text: the indented lines after a line starting with `Example`.
fn examples(help: &str) -> Vec<Example> {
    let mut out = Vec::new();
    let mut in_examples = false;
    let mut session: Vec<String> = Vec::new();
    for line in help.lines() {
        if line.starts_with("Example") {
            in_examples = true;
            continue;
        }
        if !line.starts_with("  ") {
            in_examples = false;
            continue;
        }
        if in_examples {
            session.push(line.trim().to_string());
        }
    }
    if session.iter().any(|l| l.starts_with("$ ")) {
        // A session: commands after `$ `, each followed by what it prints.
        let mut files = Vec::new();
        let mut i = 0;
        while i < session.len() {
            let command = session[i].strip_prefix("$ ").expect("a session line").to_string();
            let mut shown = Vec::new();
            i += 1;
            while i < session.len() && !session[i].starts_with("$ ") {
                shown.push(session[i].clone());
                i += 1;
            }
            let shown = shown.join("\n") + "\n";
            match command.strip_prefix("cat ") {
                Some(file) => files.push((file.to_string(), shown)),
                None => out.push(Example { command, files: files.clone(), shows: Some(shown) }),
            }
        }
    } else {
        for line in session {
            // `cargo run --release -p kpl -- ARGS` is `kpl ARGS` built from source.
            let command = line.replace("cargo run --release -p kpl --", "kpl");
            out.push(Example { command, ..Example::default() });
        }
    }
    out
}

/// A folder with a copy of the shipped specs (commands may write beside them) and `bin/kpl`.
fn workspace(name: &str) -> common::TestDir {
    let dir = common::fresh_dir("tour", name);
    copy_dir(&root().join("specs"), &dir.join("specs"));
    std::fs::create_dir_all(dir.join("bin")).unwrap();
    std::os::unix::fs::symlink(env!("CARGO_BIN_EXE_kpl"), dir.join("bin/kpl")).unwrap();
    // The `.venv` that `scripts/test` makes at the repository's root (examples name
    // `.venv/bin/python`): the oracles' environment, when there is one.
    if let Ok(python) = std::env::var("KPL_PYTHON")
        && !python.is_empty()
    {
        let python = Path::new(&python);
        match python.parent().and_then(Path::parent).filter(|venv| venv.join("pyvenv.cfg").exists()) {
            Some(venv) => std::os::unix::fs::symlink(venv, dir.join(".venv")).unwrap(),
            None => {
                std::fs::create_dir_all(dir.join(".venv/bin")).unwrap();
                std::os::unix::fs::symlink(python, dir.join(".venv/bin/python")).unwrap();
            }
        }
    }
    dir
}

/// Examples that need the `.venv` of the oracles run only where there is one (KPL_PYTHON).
#[allow(clippy::print_stderr, reason = "a skipped example says so")]
fn runnable(dir: &Path, examples: &mut Vec<(String, Example)>) {
    if dir.join(".venv").exists() {
        return;
    }
    let needs = |e: &Example| e.command.contains(".venv/");
    if std::env::var("KPL_REQUIRE_ORACLES").is_ok_and(|v| v == "1") && examples.iter().any(|(_, e)| needs(e))
    {
        panic!("KPL_REQUIRE_ORACLES=1 but KPL_PYTHON is not set (scripts/test sets both)");
    }
    examples.retain(|(origin, e)| {
        if needs(e) {
            eprintln!("skipped ({origin}): `{}` needs KPL_PYTHON's environment", e.command);
        }
        !needs(e)
    });
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

/// `bash -c COMMAND` in `dir` with `dir/bin` first on the PATH, in its own process group, with
/// `dir/tmp` as its temporary folder (a benchmark stopped with SIGKILL cannot remove its scratch
/// folder; it goes with `dir`).
fn shell(dir: &Path, command: &str) -> Command {
    use std::os::unix::process::CommandExt;
    let path = format!("{}:{}", dir.join("bin").display(), std::env::var("PATH").unwrap_or_default());
    let tmp = dir.join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    let mut shell = Command::new("bash");
    shell
        .args(["-c", &format!("set -eo pipefail\n{command}")])
        .current_dir(dir)
        .env("PATH", path)
        .env("NO_COLOR", "1")
        .env("TMPDIR", tmp)
        .env("KPL_ZENOH_PORT_BASE", free_ports(2).to_string())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .process_group(0);
    shell
}

/// Runs a command to its end (or [`HANG`]); returns its exit code and output.
fn run(dir: &Path, command: &str, watch_only: bool) -> Result<(Option<i32>, String, String), String> {
    let mut child = shell(dir, command).spawn().unwrap();
    let (stdout, stderr) = (child.stdout.take().unwrap(), child.stderr.take().unwrap());
    let read = |mut from: Box<dyn std::io::Read + Send>| {
        std::thread::spawn(move || {
            let mut text = String::new();
            let _ = from.read_to_string(&mut text);
            text
        })
    };
    let (stdout, stderr) = (read(Box::new(stdout)), read(Box::new(stderr)));
    let start = Instant::now();
    let limit = if watch_only { WATCH } else { HANG };
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break Some(status);
        }
        if start.elapsed() > limit {
            // The whole group: a benchmark starts a copy of itself.
            let _ = Command::new("kill").args(["-KILL", "--", &format!("-{}", child.id())]).status();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let (stdout, stderr) = (stdout.join().unwrap(), stderr.join().unwrap());
    match status {
        Some(status) => Ok((status.code(), stdout, stderr)),
        None if watch_only => Ok((None, stdout, stderr)),
        None => Err(format!("`{command}` did not end within {HANG:?}:\n{stderr}")),
    }
}

/// Runs each command; returns what went wrong.
fn check_all(dir: &Path, examples: &[(String, Example)]) -> Vec<String> {
    let mut failures = Vec::new();
    for (origin, example) in examples {
        for (file, content) in &example.files {
            std::fs::write(dir.join(file), content).unwrap();
        }
        let watch_only = example.command.starts_with("kpl bench");
        let expected_exit = if example.command.contains("specs/err/") { 1 } else { 0 };
        match run(dir, &example.command, watch_only) {
            Err(hung) => failures.push(format!("{origin}: {hung}")),
            Ok((None, ..)) => {} // a benchmark, still running fine when stopped
            Ok((code, stdout, stderr)) => {
                if code != Some(expected_exit) {
                    failures.push(format!(
                        "{origin}: `{}` exited with {code:?}, not {expected_exit}:\n{stderr}",
                        example.command
                    ));
                } else if let Some(shows) = &example.shows
                    && &stdout != shows
                {
                    failures.push(format!(
                        "{origin}: `{}` printed\n{stdout}but the help shows\n{shows}",
                        example.command
                    ));
                }
            }
        }
    }
    failures
}

#[test]
fn every_command_of_the_readme_tour_runs_as_written() {
    let dir = workspace("readme");
    let mut tour: Vec<(String, Example)> = readme_tour()
        .into_iter()
        .map(|command| ("README.md".to_string(), Example { command, ..Example::default() }))
        .collect();
    runnable(&dir, &mut tour);
    let failures = check_all(&dir, &tour);
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
    // What the tour promises is there: the picture, and the run's outputs straight under out/NAME.
    let svg = std::fs::read_to_string(dir.join("overview.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("vision_world"));
    assert!(dir.join("out/bridge/tracks.jsonl").exists() && !dir.join("out/bridge/bridge").exists());
}

#[test]
fn every_example_of_every_help_runs_as_written() {
    let dir = workspace("help");
    let commands = subcommands(&[]);
    assert!(commands.len() >= 15, "{commands:?}");
    let mut all = Vec::new();
    for path in &commands {
        let mut args: Vec<&str> = path.iter().map(String::as_str).collect();
        args.push("--help");
        let help = String::from_utf8(kpl(&args).stdout).unwrap();
        let found = examples(&help);
        // Commands that only group others show their subcommands' examples.
        assert!(!found.is_empty() || help.contains("Commands:"), "`kpl {}` has no example", path.join(" "));
        for example in found {
            all.push((format!("kpl {} --help", path.join(" ")), example));
        }
    }
    // Examples shown in several helps (a group's and its subcommand's) run once.
    let mut seen = std::collections::BTreeSet::new();
    all.retain(|(_, example)| seen.insert(example.command.clone()));
    runnable(&dir, &mut all);
    let failures = check_all(&dir, &all);
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}
