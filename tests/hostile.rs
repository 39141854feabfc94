//! Hostile files given to the `kpl` command, each run under an address-space limit (`ulimit -v`),
//! so that a reader without a cap ends in an allocation failure (an abort) instead of a clear error:
//! - spec files that are `/dev/zero` (`kpl check`, `fmt`, `run`, standard input): E0005 after
//!   64 MiB;
//! - a JSON-lines recording that is `/dev/zero`, or has a line longer than 64 MiB (`kpl convert`,
//!   `kpl score`, `kpl plot`): an error naming the file and the line;
//! - road networks, occluders, recorded traffic and vehicle types that are `/dev/zero`
//!   (`kpl plot`, `kpl situations`): refused with what is wrong;
//! - a spec with tens of thousands of errors: the text shows the first 100 and counts the rest,
//!   JSON has every one;
//! - numeric options out of range (`kpl plot --width 0`, `1e9`, ...): usage errors.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use common::{fresh_dir, root};

/// The address space each command may use: the binary, its threads' reservations and a 64 MiB
/// line or file with room to spare, far below what an unbounded read of `/dev/zero` takes.
const ADDRESS_SPACE_KIB: u64 = 2 << 20;

/// Runs the built `kpl` under [`ADDRESS_SPACE_KIB`], reading `stdin` (default: nothing).
fn kpl_limited(args: &[&str], stdin: Option<&Path>) -> Output {
    let mut command = Command::new("sh");
    command
        .arg("-c")
        .arg(format!("ulimit -v {ADDRESS_SPACE_KIB} && exec \"$0\" \"$@\""))
        .arg(env!("CARGO_BIN_EXE_kpl"))
        .args(args)
        .current_dir(root())
        .env("NO_COLOR", "1")
        .stdin(match stdin {
            Some(path) => Stdio::from(std::fs::File::open(path).unwrap()),
            None => Stdio::null(),
        });
    command.output().unwrap()
}

/// The exit code (a signal, such as an abort, is a failure of the test) and stderr.
fn ended(output: &Output, what: &str) -> (i32, String) {
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    let code = output.status.code().unwrap_or_else(|| panic!("{what} ended by a signal: {stderr}"));
    (code, stderr)
}

fn dev_zero() -> Option<&'static Path> {
    let path = Path::new("/dev/zero");
    path.exists().then_some(path)
}

/// A file of `head` and then zeros up to `len` bytes without a line break (sparse: it takes no
/// disk space).
fn with_endless_line(dir: &Path, name: &str, head: &str, len: u64) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, head).unwrap();
    std::fs::OpenOptions::new().write(true).open(&path).unwrap().set_len(len).unwrap();
    path
}

#[test]
fn a_spec_that_is_dev_zero_is_refused_after_64_mib() {
    let Some(zero) = dev_zero() else { return };
    let zero = zero.to_str().unwrap();
    for args in [vec!["check", zero], vec!["fmt", "--check", zero], vec!["run", zero], vec!["graph", zero]] {
        let (code, stderr) = ended(&kpl_limited(&args, None), &args.join(" "));
        assert_eq!(code, 1, "{args:?}: {stderr}");
        assert!(stderr.contains("error[E0005]: file is larger than 64 MiB"), "{args:?}: {stderr}");
        assert!(stderr.contains("--> /dev/zero:1:1"), "{args:?}: {stderr}");
        assert!(stderr.len() < 2_000, "{args:?}: {} bytes of stderr", stderr.len());
    }
    // Standard input.
    for args in [vec!["check", "-"], vec!["fmt", "-"]] {
        let (code, stderr) = ended(&kpl_limited(&args, Some(Path::new(zero))), &args.join(" "));
        assert_eq!(code, 1, "{args:?}: {stderr}");
        assert!(stderr.contains("error[E0005]: file is larger than 64 MiB"), "{args:?}: {stderr}");
    }
    // As JSON: one diagnostic, at the file's start.
    let output = kpl_limited(&["check", "--format", "json", zero], None);
    let (code, stderr) = ended(&output, "check --format json");
    assert_eq!(code, 1, "{stderr}");
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(json.as_array().unwrap().len(), 1, "{json}");
    assert_eq!(json[0]["code"], "E0005");
    assert_eq!((json[0]["file"].as_str(), json[0]["line"].as_u64()), (Some(zero), Some(1)));
}

#[test]
fn a_recording_with_an_endless_line_is_an_error_naming_the_line() {
    let dir = fresh_dir("hostile", "recording");
    let good = "{\"stream\": \"truth\", \"valid\": 0, \"value\": [{\"id\": \"c1\", \"pos\": [0.0, 0.0]}]}\n";
    // One good line, then 70 MiB without a line break.
    let recording = with_endless_line(&dir, "run.jsonl", good, 70 << 20);
    let input = recording.to_str().unwrap();
    let mcap = dir.join("run.mcap");
    let output = kpl_limited(&["convert", input, mcap.to_str().unwrap()], None);
    let (code, stderr) = ended(&output, "convert");
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr
            .contains(&format!("cannot read {input}: line 2 is longer than 64 MiB (is it the right file?)")),
        "{stderr}"
    );
    assert!(stderr.contains("the 1 sample(s) before it are in"), "{stderr}");
    for command in ["score", "plot"] {
        let (code, stderr) = ended(&kpl_limited(&[command, dir.to_str().unwrap()], None), command);
        assert_eq!(code, 1, "{command}: {stderr}");
        assert!(stderr.contains(&format!("{input}:2: a line longer than 64 MiB")), "{command}: {stderr}");
    }
    // A recording that is /dev/zero, under a name `kpl convert` takes for JSON lines.
    if let Some(zero) = dev_zero() {
        let link = dir.join("zero.jsonl");
        std::os::unix::fs::symlink(zero, &link).unwrap();
        let output = kpl_limited(&["convert", link.to_str().unwrap(), mcap.to_str().unwrap()], None);
        let (code, stderr) = ended(&output, "convert /dev/zero");
        assert_eq!(code, 2, "{stderr}");
        assert!(stderr.contains("zero.jsonl: line 1 is longer than 64 MiB"), "{stderr}");
        assert!(stderr.contains("the 0 sample(s) before it are in"), "{stderr}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn networks_occluders_traffic_and_vehicle_types_that_are_dev_zero_are_refused() {
    let Some(zero) = dev_zero() else { return };
    let zero = zero.to_str().unwrap();
    let dir = fresh_dir("hostile", "inputs");
    let recording = dir.join("run.jsonl");
    std::fs::write(&recording, "{\"stream\": \"truth\", \"valid\": 0, \"value\": []}\n").unwrap();
    let recording = recording.to_str().unwrap();
    let crossing = "specs/traffic/fig5/crossing.json";
    let overtake = "specs/traffic/sumo/overtake";
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["plot".into(), recording.into(), "--network".into(), zero.into()],
            "/dev/zero is neither a KPL road network (JSON) nor a SUMO network",
        ),
        (
            vec![
                "plot".into(),
                recording.into(),
                "--network".into(),
                crossing.into(),
                "--occluders".into(),
                zero.into(),
            ],
            "/dev/zero is neither a KPL road network (JSON) nor a SUMO network",
        ),
        (
            vec![
                "situations".into(),
                recording.into(),
                "--traffic".into(),
                zero.into(),
                "--network".into(),
                format!("{overtake}/net.xml.gz"),
            ],
            "its header (line 1) is longer than 1 MiB",
        ),
        (
            vec![
                "situations".into(),
                recording.into(),
                "--traffic".into(),
                format!("{overtake}/fcd.xml.gz"),
                "--vtypes".into(),
                zero.into(),
            ],
            "more than 1 MiB without `<` or `>`",
        ),
        (
            vec![
                "situations".into(),
                recording.into(),
                "--traffic".into(),
                format!("{overtake}/fcd.xml.gz"),
                "--network".into(),
                zero.into(),
            ],
            "/dev/zero is neither a KPL road network (JSON) nor a SUMO network",
        ),
    ];
    for (args, says) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, stderr) = ended(&kpl_limited(&args, None), &args.join(" "));
        assert_eq!(code, 2, "{args:?}: {stderr}");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn many_errors_show_the_first_hundred_as_text_and_every_one_as_json() {
    let dir = fresh_dir("hostile", "many-errors");
    let spec = dir.join("many.kpl");
    // 20,000 definitions of one name: 19,999 duplicates.
    std::fs::write(&spec, "source t : int = timer(period: 100ms)\n".repeat(20_000)).unwrap();
    let spec = spec.to_str().unwrap();
    let (code, stderr) = ended(&kpl_limited(&["check", spec], None), "check");
    assert_eq!(code, 1);
    assert_eq!(stderr.matches("error[E0102]").count(), 100, "the first 100 are shown");
    assert!(
        stderr.contains(
            "... and 19899 more diagnostics not shown (the first 100 are; `kpl check --format json` lists every one)"
        ),
        "{}",
        &stderr[stderr.len().saturating_sub(500)..]
    );
    assert!(stderr.contains("19999 errors, 0 warnings"), "{}", &stderr[stderr.len().saturating_sub(500)..]);
    assert!(stderr.lines().count() < 1_500, "{} lines", stderr.lines().count());
    let output = kpl_limited(&["check", "--format", "json", spec], None);
    assert_eq!(ended(&output, "check --format json").0, 1);
    let json: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let all = json.as_array().unwrap();
    assert_eq!(all.len(), 19_999);
    assert_eq!((all[19_998]["code"].as_str(), all[19_998]["line"].as_u64()), (Some("E0102"), Some(20_000)));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn numeric_options_out_of_range_are_usage_errors() {
    let cases: [(&[&str], &str); 6] = [
        (&["plot", "out", "--width", "0"], "0 px is out of range: the picture is 100 to 20000 pixels wide"),
        (&["plot", "out", "--width", "1e9"], "1e9 px is out of range"),
        (&["plot", "out", "--view", "0,0,1e300,1"], "is not X0,Y0,X1,Y1"),
        (&["score", "out", "--max-distance", "0"], "0 m is out of range"),
        (&["score", "out", "--hota-zero-distance", "1e9"], "1e9 m is out of range"),
        (&["situations", "out", "--traffic", "x", "--slack=-1"], "-1 s is out of range"),
    ];
    for (args, says) in cases {
        let (code, stderr) = ended(&kpl_limited(args, None), &args.join(" "));
        assert_eq!(code, 2, "{args:?}: {stderr}");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
    }
}

/// Files that open or read files by themselves rather than through `kpl_core::read`, and why.
const OWN_READERS: &[(&str, &str)] = &[
    ("crates/kpl-core/src/read.rs", "the capped readers themselves"),
    ("crates/kpl-mcap/src/read.rs", "MCAP records, each capped by kpl_mcap::read::RECORD_LIMIT"),
    ("crates/kpl-zenoh/src/credentials.rs", "a deployment's keys, as `kpl keys` writes them"),
    ("crates/kpl-zenoh/src/bench.rs", "the output of its own child process"),
    ("kpl/src/cmd/mtl.rs", "formula and trace files, capped at 64 MiB by its own reader"),
    ("kpl/src/cmd/launch.rs", "the summary.json its own hosts wrote"),
    ("crates/kpl-bench/src/runtime.rs", "/proc/self/statm"),
    ("crates/kpl-bench/src/mtl.rs", "the file R2U2's C2PO compiler wrote for the benchmark"),
];

/// Every other reader of a file goes through `kpl_core::read` (docs/architecture.md): nothing
/// else in the libraries or the command opens a file to read it.
#[test]
fn files_are_read_only_through_kpl_core_read() {
    fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                sources(&path, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    let root = root();
    let mut files = Vec::new();
    sources(&root.join("kpl/src"), &mut files);
    for entry in std::fs::read_dir(root.join("crates")).unwrap() {
        let src = entry.unwrap().path().join("src");
        if src.is_dir() {
            sources(&src, &mut files);
        }
    }
    assert!(files.len() > 100, "{} source files", files.len());
    let reads = ["File::open(", "fs::read(", "fs::read_to_string(", ".read_to_end(", ".read_to_string("];
    let mut found = Vec::new();
    for file in files {
        let name = file.strip_prefix(&root).unwrap().to_string_lossy().replace('\\', "/");
        if OWN_READERS.iter().any(|(own, _)| *own == name) {
            continue;
        }
        let text = std::fs::read_to_string(&file).unwrap();
        // Unit tests (at the end of a file) read what they wrote.
        let code = text.split("#[cfg(test)]").next().unwrap_or("");
        for (number, line) in code.lines().enumerate() {
            if reads.iter().any(|r| line.contains(r)) && !line.trim_start().starts_with("//") {
                found.push(format!("{name}:{}: {}", number + 1, line.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "read files through kpl_core::read (open, read_file, LineReader, BreakGuard), which caps them, or add \
         the file to OWN_READERS with its reason:\n{}",
        found.join("\n")
    );
}
