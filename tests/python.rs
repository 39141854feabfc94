//! The `kpl` Python package (python/, docs/python.md) against running deployments, on loopback:
//! - its own tests (`python -m unittest` in python/: the codec against the decoder of
//!   docs/streams.md, keys, envelopes);
//! - `specs/zenoh/python.kpl` on two hosts with the package's examples: `sensor.py` publishes
//!   readings (records with a vec2 and a list of floats) into host `station`, `dashboard.py`
//!   subscribes to what host `control` publishes back; every value and time arrives unchanged,
//!   both ways, and the monitor's verdicts reach the dashboard.
//!
//! Needs the Python of `scripts/test` (`KPL_PYTHON`), which installs the package from python/;
//! the tests check that the installed package is the repository's.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr, clippy::disallowed_methods)] // tests: they unwrap, and say what they skip; waits are bounded by the wall clock

mod common;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::time::{Duration, Instant};

use common::{free_ports, lines, python, root};
use serde_json::Value;

/// How long a process may take before the test gives up on it (a hang, not a speed limit).
const HANG: Duration = Duration::from_secs(180);

/// The Python, once it is known to import the repository's package (not an older install).
fn python_with_package() -> Option<String> {
    let python = python("the kpl package")?;
    let out = Command::new(&python)
        .args(["-c", "import kpl, os; print(os.path.dirname(kpl.__file__))"])
        .current_dir(std::env::temp_dir())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{python} cannot import kpl: run scripts/test, which installs python/ into .venv\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let installed = PathBuf::from(String::from_utf8(out.stdout).unwrap().trim());
    for entry in std::fs::read_dir(root().join("python/kpl")).unwrap() {
        let source = entry.unwrap().path();
        if source.extension().is_some_and(|e| e == "py") {
            let copy = installed.join(source.file_name().unwrap());
            assert_eq!(
                std::fs::read(&copy).ok(),
                Some(std::fs::read(&source).unwrap()),
                "{} differs from {}: run scripts/test, which reinstalls the package",
                copy.display(),
                source.display()
            );
        }
    }
    Some(python)
}

/// `kpl run SPEC --host HOST --clock wall --out OUT`, zenoh's ports from `port_base`.
fn host(spec: &Path, host: &str, out: &Path, port_base: u16) -> Child {
    host_with(spec, host, out, port_base, &[])
}

/// [`host`] with more arguments.
fn host_with(spec: &Path, host: &str, out: &Path, port_base: u16, more: &[&str]) -> Child {
    common::kpl_command(&["run"])
        .arg(spec)
        .args(["--host", host, "--clock", "wall", "--out"])
        .arg(out)
        .args(more)
        .env("KPL_ZENOH_PORT_BASE", port_base.to_string())
        .env("KPL_ZENOH_WAIT", "120")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// A Python program of python/examples with its arguments.
fn example(python: &str, name: &str, args: &[String]) -> Child {
    Command::new(python)
        .arg(root().join("python/examples").join(name))
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// The first line a program prints (its own "subscribed" or "watching" line: it is ready), read
/// byte by byte so that the rest stays for [`finish`].
fn first_line(child: &mut Child) -> String {
    let mut stdout = child.stdout.take().unwrap();
    let mut line = Vec::new();
    let mut byte = [0u8; 1];
    while stdout.read(&mut byte).unwrap() == 1 && byte[0] != b'\n' {
        line.push(byte[0]);
    }
    child.stdout = Some(stdout);
    String::from_utf8(line).unwrap()
}

/// Waits for a process (killing it if it hangs): its status and both outputs.
fn finish(mut child: Child, name: &str) -> Output {
    let stdout = child.stdout.take().map(read_to_end);
    let stderr = child.stderr.take().map(read_to_end);
    let status = wait_or_kill(&mut child);
    let collect =
        |h: Option<std::thread::JoinHandle<Vec<u8>>>| h.map(|h| h.join().unwrap()).unwrap_or_default();
    let (stdout, stderr) = (collect(stdout), collect(stderr));
    let Some(status) = status else {
        panic!("{name} did not finish:\n{}", String::from_utf8_lossy(&stderr));
    };
    Output { status, stdout, stderr }
}

fn wait_or_kill(child: &mut Child) -> Option<ExitStatus> {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return Some(status);
        }
        if start.elapsed() > HANG {
            child.kill().unwrap();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn read_to_end(mut from: impl Read + Send + 'static) -> std::thread::JoinHandle<Vec<u8>> {
    std::thread::spawn(move || {
        let mut out = Vec::new();
        let _ = from.read_to_end(&mut out);
        out
    })
}

fn json_lines(bytes: &[u8]) -> Vec<Value> {
    String::from_utf8_lossy(bytes).lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

fn succeeded(out: &Output, name: &str) {
    assert!(
        out.status.success(),
        "{name} failed ({}):\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn the_package_s_own_tests_pass() {
    let Some(python) = python("the kpl package") else { return };
    let out = Command::new(&python)
        .args(["-m", "unittest", "discover", "-s", "tests", "-v"])
        .current_dir(root().join("python"))
        .output()
        .unwrap();
    succeeded(&out, "python -m unittest");
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("\nOK") && !said.contains("skipped"), "{said}");
}

#[test]
fn a_python_source_and_a_python_sink_in_a_deployment() {
    let Some(python) = python_with_package() else { return };
    let dir = common::fresh_dir("python", "deployment");
    let spec = root().join("specs/zenoh/python.kpl");
    let base = free_ports(2);
    let station = host(&spec, "station", &dir.join("station"), base);
    let control = host(&spec, "control", &dir.join("control"), base);
    let connect = |port: u16| vec!["--connect".to_string(), format!("tcp/127.0.0.1:{port}")];
    let dashboard = example(&python, "dashboard.py", &connect(base + 1));
    let count = 40;
    let mut args = connect(base);
    args.extend(["--count".into(), count.to_string(), "--period".into(), "0.01".into()]);
    let sensor = finish(example(&python, "sensor.py", &args), "sensor.py");
    succeeded(&sensor, "sensor.py");
    let dashboard = finish(dashboard, "dashboard.py");
    for (child, name) in [(station, "station"), (control, "control")] {
        let out = finish(child, name);
        succeeded(&out, name);
    }
    succeeded(&dashboard, "dashboard.py");

    check_exchange(&dir, &json_lines(&sensor.stdout), &json_lines(&dashboard.stdout));
}

/// What `sensor.py` sent (`sent`, as it printed it) reached host `control` (its `log.jsonl` in
/// `dir/control`) and the dashboard (`got`, as it printed it) unchanged, with the monitor's
/// verdicts.
fn check_exchange(dir: &Path, sent: &[Value], got: &[Value]) {
    let count = sent.len();
    assert!(count > 0);
    // What the sensor sent, as it printed it.
    let hot = sent.iter().filter(|s| s["value"]["temp"].as_f64().unwrap() >= 30.0).count();
    assert!(hot > 0 && hot < count, "the readings warm past 30 degrees: {hot} of {count}");

    // kpl decoded every reading with its times and typed value (the spectrum came packed).
    let log = lines(&dir.join("control/log.jsonl"));
    let readings: Vec<&Value> = log.iter().filter(|l| l["stream"] == "readings").collect();
    assert_eq!(readings.len(), count);
    for (line, sample) in readings.iter().zip(sent) {
        assert_eq!(
            (&line["valid"], &line["available"], &line["value"]),
            (&sample["valid"], &sample["available"], &sample["value"])
        );
    }
    let verdicts: Vec<&Value> = log.iter().filter(|l| l["stream"] == "too_hot").collect();
    let first_hot = sent.iter().find(|s| s["value"]["temp"].as_f64().unwrap() >= 30.0).unwrap();
    assert!(
        verdicts.iter().any(|v| v["value"] == false && v["valid"] == first_hot["valid"]),
        "a violation at the first hot reading: {verdicts:?}"
    );

    // The dashboard got the readings back and the verdicts, unchanged, then both ends.
    assert_eq!(got[0], serde_json::json!({"subscribed": "kpl-demo/out/*"}));
    let on = |key: &str| -> Vec<&Value> {
        got.iter().filter(|l| l["key"] == key && l.get("end").is_none()).collect()
    };
    let echo = on("kpl-demo/out/echo");
    assert_eq!(echo.len(), count);
    for (line, sample) in echo.iter().zip(sent) {
        assert_eq!(
            (&line["valid"], &line["available"], &line["value"]),
            (&sample["valid"], &sample["available"], &sample["value"])
        );
    }
    let alerts = on("kpl-demo/out/alerts");
    assert_eq!(alerts.len(), verdicts.len());
    for (line, verdict) in alerts.iter().zip(&verdicts) {
        assert_eq!(
            (&line["valid"], &line["available"], &line["value"]),
            (&verdict["valid"], &verdict["available"], &verdict["value"])
        );
    }
    let ends: Vec<&Value> = got.iter().filter(|l| l.get("end").is_some()).collect();
    assert_eq!(ends.len(), 2, "{got:?}");
    assert!(ends.contains(&&serde_json::json!({"key": "kpl-demo/out/echo", "end": count})));
}

#[test]
fn python_in_an_authenticated_deployment() {
    let Some(python) = python_with_package() else { return };
    let dir = common::fresh_dir("python", "keys");
    let spec = root().join("specs/zenoh/python.kpl");
    let keys = dir.join("keys");
    let made = common::kpl(&["keys", spec.to_str().unwrap(), "--out", keys.to_str().unwrap()]);
    assert!(made.status.success(), "kpl keys:\n{}", String::from_utf8_lossy(&made.stderr));
    // The same keys but another secret: what a stranger with a certificate would have.
    let stranger = dir.join("stranger");
    std::fs::create_dir_all(&stranger).unwrap();
    for entry in std::fs::read_dir(&keys).unwrap() {
        let path = entry.unwrap().path();
        std::fs::copy(&path, stranger.join(path.file_name().unwrap())).unwrap();
    }
    std::fs::write(stranger.join("secret"), "ab".repeat(32) + "\n").unwrap();

    let base = free_ports(2);
    let tls = |port: u16, keys: &Path, host: &str| {
        let mut args = vec!["--connect".to_string(), format!("tls/127.0.0.1:{port}")];
        args.extend(["--keys".into(), keys.display().to_string(), "--as".into(), host.into()]);
        args
    };
    let keys_arg = keys.display().to_string();
    let station = host_with(&spec, "station", &dir.join("station"), base, &["--keys", &keys_arg]);
    let control = host_with(&spec, "control", &dir.join("control"), base, &["--keys", &keys_arg]);
    let dashboard = example(&python, "dashboard.py", &tls(base + 1, &keys, "control"));
    let watch = |keys: &Path, extra: &[&str]| {
        let mut args = tls(base, keys, "station");
        args.extend(["--spec", "python", "--from-host", "station"].map(String::from));
        args.extend(extra.iter().map(|s| s.to_string()));
        args.extend(["readings", "too_hot"].map(String::from));
        example(&python, "watch.py", &args)
    };
    let mut watcher = watch(&keys, &[]);
    let mut stranger_watcher = watch(&stranger, &["--idle", "10"]);
    // The sensor starts once both watchers have subscribed, so that they see every message.
    for w in [&mut watcher, &mut stranger_watcher] {
        let line = first_line(w);
        assert!(line.starts_with("{\"watching\""), "{line}");
    }
    let count = 30;
    let mut args = tls(base, &keys, "station");
    args.extend(["--count".into(), count.to_string(), "--period".into(), "0.01".into()]);
    let sensor = finish(example(&python, "sensor.py", &args), "sensor.py");
    succeeded(&sensor, "sensor.py");
    let dashboard = finish(dashboard, "dashboard.py");
    let watcher = finish(watcher, "watch.py");
    let stranger_watcher = finish(stranger_watcher, "watch.py (another secret)");
    for (child, name) in [(station, "station"), (control, "control")] {
        succeeded(&finish(child, name), name);
    }
    succeeded(&dashboard, "dashboard.py");
    succeeded(&watcher, "watch.py");
    let sent = json_lines(&sensor.stdout);
    check_exchange(&dir, &sent, &json_lines(&dashboard.stdout));

    // The watcher read the streams station sends control, each message from host `station`,
    // tagged with the deployment's secret, in sequence, nothing refused or lost.
    let watched = json_lines(&watcher.stdout);
    assert!(!watched.is_empty(), "{}", String::from_utf8_lossy(&watcher.stderr));
    let readings: Vec<&Value> =
        watched.iter().filter(|l| l["stream"] == "readings" && l.get("value").is_some()).collect();
    assert_eq!(readings.len(), count);
    for (i, (line, sample)) in readings.iter().zip(&sent).enumerate() {
        assert_eq!(
            (&line["host"], &line["sequence"], &line["authenticated"]),
            (&"station".into(), &i.into(), &true.into())
        );
        assert_eq!((&line["valid"], &line["value"]), (&sample["valid"], &sample["value"]));
    }
    for stream in ["readings", "too_hot"] {
        let report = watched.iter().find(|l| l["stream"] == stream && l.get("refused").is_some()).unwrap();
        assert_eq!((&report["refused"], &report["lost"]), (&0.into(), &0.into()), "{report}");
    }
    assert!(watched.contains(&serde_json::json!({"stream": "readings", "end": count})));

    // With another secret every message is refused, none is shown, and no end comes.
    assert_eq!(stranger_watcher.status.code(), Some(1));
    let refused = json_lines(&stranger_watcher.stdout);
    assert!(refused.iter().all(|l| l.get("value").is_none()), "{refused:?}");
    let report = refused.iter().find(|l| l["stream"] == "readings" && l.get("refused").is_some()).unwrap();
    assert_eq!(report["refused"], count + 1, "the samples and the end: {report}");
    assert!(report["reasons"][0].as_str().unwrap().contains("tag does not verify"), "{report}");
}
