//! End-to-end tests of streams between hosts over zenoh, with the built `kpl` binary:
//! - two `kpl run --host` processes of one spec on this machine (loopback defaults): every sample
//!   arrives, in order, with its valid and available times and its value intact, both ways;
//! - endpoints given in the deploy section, the producing host started first;
//! - a consumer whose producing host is killed and never comes back gives up after
//!   `KPL_ZENOH_GIVE_UP`, keeps what arrived, and says its input was cut short (exit 3);
//! - two deployments of one spec side by side, their sessions linked: no sample crosses;
//! - a deployment with keys (`kpl keys`, mutual TLS): outside peers (Python's eclipse-zenoh, using
//!   only the code of docs/streams.md) without a certificate cannot link, one with another host's
//!   certificate is stopped by access control, and what strangers publish through a plain `tcp/`
//!   endpoint is refused and counted; the consumer runs on and records only the producer's samples;
//! - the documented Python envelope code and kpl's agree;
//! - `kpl launch` runs every host of a spec with one summary;
//! - a Python program using `eclipse-zenoh` and only the code of docs/streams.md decodes what
//!   `zenoh.publish` sends and encodes what `zenoh.subscribe` receives (the Python tests are
//!   skipped without `KPL_PYTHON`, unless `KPL_REQUIRE_ORACLES=1`).
//!
//! Hang guards (a process that does not finish within minutes is killed and the test fails) are
//! the only times here; nothing asserts a speed.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr, clippy::disallowed_methods)] // tests; waits are bounded by the wall clock

mod common;

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use common::{free_ports, lines, python, root};
use serde_json::Value;

const HANG: Duration = Duration::from_secs(180);

fn out_dir(name: &str) -> common::TestDir {
    common::fresh_dir("zenoh", name)
}

fn host(spec: &str, host: &str, out: &Path, port_base: u16) -> Child {
    wall_run(&[spec, "--host", host], out, port_base)
}

/// Starts `kpl run ARGS --clock wall --out OUT` with zenoh's ports from `port_base`.
fn wall_run(args: &[&str], out: &Path, port_base: u16) -> Child {
    common::kpl_command(&["run"])
        .args(args)
        .args(["--clock", "wall", "--out"])
        .arg(out)
        .env("KPL_ZENOH_PORT_BASE", port_base.to_string())
        .env("KPL_ZENOH_WAIT", "120")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Waits for a process (killing it if it hangs); returns its exit code and standard error.
fn finish(mut child: Child, name: &str) -> (Option<i32>, String) {
    let reader = read_to_end(child.stderr.take().unwrap());
    let Some(status) = wait_or_kill(&mut child) else {
        panic!("{name} did not finish:\n{}", reader.join().unwrap());
    };
    (status.code(), reader.join().unwrap())
}

/// Waits for a process to end; kills it and gives `None` if it has not ended within [`HANG`].
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

/// Reads what is left of a process's output on its own thread (so the process never blocks on it).
fn read_to_end(mut from: impl Read + Send + 'static) -> std::thread::JoinHandle<String> {
    std::thread::spawn(move || {
        let mut text = String::new();
        from.read_to_string(&mut text).unwrap();
        text
    })
}

fn of_stream(lines: &[Value], stream: &str) -> Vec<Value> {
    lines.iter().filter(|l| l["stream"] == stream).cloned().collect()
}

#[test]
fn two_hosts_keep_every_sample_and_its_times() {
    let base = free_ports(2);
    let (a_out, b_out) = (out_dir("two-a"), out_dir("two-b"));
    // The consumer first: it dials `a` until `a` listens.
    let b = host("specs/zenoh/two_hosts.kpl", "b", &b_out, base);
    let a = host("specs/zenoh/two_hosts.kpl", "a", &a_out, base);
    let (a_code, a_err) = finish(a, "host a");
    let (b_code, b_err) = finish(b, "host b");
    assert_eq!(a_code, Some(0), "host a:\n{a_err}");
    assert_eq!(b_code, Some(0), "host b:\n{b_err}");
    // Both streams ended with their end message (host `a` may be seen leaving afterwards).
    for stream in summary(&b_out)["transport"]["inbound"].as_array().unwrap() {
        assert_eq!(stream["ending"], "end", "{stream}\n{b_err}");
        assert_eq!(stream["lost"], 0, "{stream}\n{b_err}");
    }

    let sent = lines(&a_out.join("sent.jsonl"));
    let received = lines(&b_out.join("received.jsonl"));
    for (stream, count) in [("percepts", 120), ("ticks", 300)] {
        let (s, r) = (of_stream(&sent, stream), of_stream(&received, stream));
        assert_eq!(s.len(), count, "{stream}: host a produced every sample");
        // Valid time, available time and value of every sample, in order.
        assert_eq!(r, s, "{stream}: host b received what host a sent");
    }

    // The values are those of the replayed file (wall-clock replay shifts both times equally).
    let file = lines(&root().join("specs/zenoh/data/percepts.jsonl"));
    let percepts = of_stream(&sent, "percepts");
    let shift = percepts[0]["valid"].as_i64().unwrap() - file[0]["valid"].as_i64().unwrap();
    for (line, original) in percepts.iter().zip(&file) {
        assert_eq!(line["value"], original["value"]);
        assert_eq!(line["valid"].as_i64().unwrap() - shift, original["valid"].as_i64().unwrap());
        assert_eq!(line["available"].as_i64().unwrap() - shift, original["available"].as_i64().unwrap());
    }

    // And back: `b` forwards the ticks, `a` records them with their valid times and values.
    let returned = lines(&a_out.join("returned.jsonl"));
    let ticks = of_stream(&sent, "ticks");
    assert_eq!(returned.len(), ticks.len());
    for (back, tick) in returned.iter().zip(&ticks) {
        assert_eq!((&back["valid"], &back["value"]), (&tick["valid"], &tick["value"]));
    }
}

#[test]
fn explicit_endpoints_with_the_producer_started_first() {
    // specs/zenoh/explicit.kpl names its port; this is the only test that uses it.
    let (uav_out, ground_out) = (out_dir("explicit-uav"), out_dir("explicit-ground"));
    let base = free_ports(1); // unused by this spec's hosts, which give their endpoints
    let uav = host("specs/zenoh/explicit.kpl", "uav", &uav_out, base);
    let ground = host("specs/zenoh/explicit.kpl", "ground", &ground_out, base);
    let (uav_code, uav_err) = finish(uav, "uav");
    let (ground_code, ground_err) = finish(ground, "ground");
    assert_eq!(uav_code, Some(0), "uav:\n{uav_err}");
    assert_eq!(ground_code, Some(0), "ground:\n{ground_err}");
    let sent = lines(&uav_out.join("sent.jsonl"));
    assert_eq!(sent.len(), 500);
    assert_eq!(lines(&ground_out.join("received.jsonl")), sent);
}

#[test]
fn a_consumer_gives_up_on_a_killed_producer_that_does_not_come_back() {
    let base = free_ports(2);
    let (producer_out, consumer_out) = (out_dir("killed-producer"), out_dir("killed-consumer"));
    let mut producer = host("specs/zenoh/endless.kpl", "producer", &producer_out, base);
    let mut consumer = common::kpl_command(&["run", "specs/zenoh/endless.kpl", "--host", "consumer"])
        .args(["--clock", "wall", "--out"])
        .arg(&consumer_out)
        .env("KPL_ZENOH_PORT_BASE", base.to_string())
        .env("KPL_ZENOH_GIVE_UP", "3")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The consumer's progress line counts what arrived: kill the producer once samples flow.
    let stderr = consumer.stderr.take().unwrap();
    let mut reader = BufReader::new(stderr);
    let mut seen = String::new();
    let start = Instant::now();
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line).unwrap() == 0 || start.elapsed() > HANG {
            producer.kill().unwrap();
            panic!("the consumer saw no samples:\n{seen}");
        }
        seen.push_str(&line);
        if line.contains("samples/s") && !line.contains("(0 samples,") {
            break;
        }
    }
    producer.kill().unwrap();
    let _ = producer.wait();
    let drain = read_to_end(reader);
    let Some(status) = wait_or_kill(&mut consumer) else {
        panic!("the consumer did not end after its producer was killed");
    };
    let rest = drain.join().unwrap();
    assert_eq!(status.code(), Some(3), "an input cut short:\n{seen}{rest}");
    assert!(rest.contains("host `producer` went away"), "{rest}");
    assert!(rest.contains("cut short"), "{rest}");
    // What arrived is recorded, in order, with nothing invented.
    let received = lines(&consumer_out.join("received.jsonl"));
    assert!(!received.is_empty());
    for (k, line) in received.iter().enumerate() {
        assert_eq!(line["value"], k as i64, "ticks arrive in order, none missing");
    }
    let summary = summary(&consumer_out);
    let inbound = &summary["transport"]["inbound"][0];
    assert_eq!(inbound["received"].as_u64().unwrap(), received.len() as u64);
    let why = inbound["ending"]["cut_short"].as_str().unwrap();
    assert!(why.contains("went away and did not come back within 3 s"), "{why}");
}

#[test]
fn a_host_whose_producer_never_comes_ends_incomplete() {
    let base = free_ports(2);
    let out = out_dir("never");
    let consumer = host_with(
        "specs/zenoh/endless.kpl",
        "consumer",
        &out,
        &[],
        &[("KPL_ZENOH_PORT_BASE", base.to_string()), ("KPL_ZENOH_GIVE_UP", "2".into())],
    );
    let (code, stderr) = finish(consumer, "consumer");
    assert_eq!(code, Some(3), "{stderr}");
    assert!(stderr.contains("host `producer` did not appear within 2 s"), "{stderr}");
    assert!(stderr.contains("nothing arrived on `ticks` from another host"), "{stderr}");
    let report = summary(&out);
    assert_eq!(report["transport"]["inbound"][0]["received"], 0);
    assert_eq!(report["transport"]["hosts"][0]["first_seen_s"], Value::Null);
}

fn summary(out: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

/// Starts host `host` of `spec` with extra arguments and environment.
fn host_with(spec: &str, host: &str, out: &Path, extra: &[&str], env: &[(&str, String)]) -> Child {
    let mut command = common::kpl_command(&["run", spec, "--host", host, "--clock", "wall", "--out"]);
    command.arg(out).args(extra).env("KPL_ZENOH_WAIT", "120").stdin(Stdio::null()).stdout(Stdio::null());
    for (name, value) in env {
        command.env(name, value);
    }
    command.stderr(Stdio::piped()).spawn().unwrap()
}

#[test]
fn two_deployments_of_one_spec_never_mix() {
    // Deployment `one` on ports p..p+1, `two` on q..q+1. Two's ground station only dials out,
    // to its own uav and to one's: the four sessions meet, the samples do not.
    let (p, q) = (free_ports(2), free_ports(2));
    let dir = out_dir("side-by-side");
    let config = dir.join("two-ground.json5");
    std::fs::write(
        &config,
        format!("{{ connect: {{ endpoints: [\"tcp/127.0.0.1:{q}\", \"tcp/127.0.0.1:{p}\"] }} }}\n"),
    )
    .unwrap();
    let spec = "specs/zenoh/side_by_side.kpl";
    let port = |base: u16| vec![("KPL_ZENOH_PORT_BASE", base.to_string())];
    let mut with_config = port(q);
    with_config.push(("KPL_ZENOH_CONFIG", config.display().to_string()));
    let children = vec![
        ("one/uav", host_with(spec, "uav", &dir.join("one-uav"), &["--deployment", "one"], &port(p))),
        (
            "one/ground",
            host_with(spec, "ground", &dir.join("one-ground"), &["--deployment", "one"], &port(p)),
        ),
        ("two/uav", host_with(spec, "uav", &dir.join("two-uav"), &["--deployment", "two"], &port(q))),
        (
            "two/ground",
            host_with(spec, "ground", &dir.join("two-ground"), &["--deployment", "two"], &with_config),
        ),
    ];
    for (name, child) in children {
        let (code, stderr) = finish(child, name);
        assert_eq!(code, Some(0), "{name}:\n{stderr}");
    }
    for deployment in ["one", "two"] {
        let sent = lines(&dir.join(format!("{deployment}-uav/sent.jsonl")));
        let received = lines(&dir.join(format!("{deployment}-ground/received.jsonl")));
        assert_eq!(sent.len(), 500);
        assert_eq!(received, sent, "deployment {deployment}: its own 500 samples and nothing else");
        let report = summary(&dir.join(format!("{deployment}-ground")));
        assert_eq!(report["transport"]["deployment"], deployment);
        assert_eq!(report["transport"]["inbound"][0]["refused"], 0);
    }
}

/// The code of docs/streams.md, run by Python: seals envelopes, opens kpl's.
#[test]
fn the_documented_envelope_is_kpls() {
    let Some(python) = python("eclipse-zenoh") else { return };
    use kpl_zenoh::credentials::Secret;
    use kpl_zenoh::envelope::Envelope;
    let secret_bytes: Vec<u8> = (0..32).collect();
    let secret = Secret::from_bytes(&secret_bytes);
    let ours = [
        Envelope { host: "uav".into(), incarnation: 0xFEED, sequence: 41, unfinished: false }.seal(
            "kpl/d/s/p",
            b"payload",
            None,
        ),
        Envelope { host: "uav".into(), incarnation: 0xFEED, sequence: 41, unfinished: false }.seal(
            "kpl/d/s/p",
            b"payload",
            Some(&secret),
        ),
        Envelope { host: "gröund".into(), incarnation: u64::MAX, sequence: 7, unfinished: true }.seal(
            "kpl/trial/my%20spec/link/changes",
            b"",
            Some(&secret),
        ),
    ];
    let hex = |b: &[u8]| b.iter().map(|x| format!("{x:02x}")).collect::<String>();
    let to_open = [
        (hex(&ours[1]), "kpl/d/s/p", hex(b"payload"), hex(&secret_bytes)),
        (hex(&ours[2]), "kpl/trial/my%20spec/link/changes", String::new(), hex(&secret_bytes)),
        (hex(&ours[1]), "kpl/d/s/p", hex(b"payloaD"), hex(&secret_bytes)),
    ];
    let input: String = to_open
        .iter()
        .map(|(a, k, p, s)| {
            serde_json::json!({"attachment": a, "key": k, "payload": p, "secret": s}).to_string() + "\n"
        })
        .collect();
    let mut child = Command::new(&python)
        .arg(root().join("tests/zenoh_forger.py"))
        .arg(root().join("docs/streams.md"))
        .arg("check")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::io::Write::write_all(&mut child.stdin.take().unwrap(), input.as_bytes()).unwrap();
    let output = child.wait_with_output().unwrap();
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let answers: Vec<Value> =
        String::from_utf8(output.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    for (i, sealed) in ours.iter().enumerate() {
        assert_eq!(answers[i]["sealed"], hex(sealed), "case {i}: Python seals as kpl does");
    }
    assert_eq!(answers[3]["opened"], serde_json::json!(["uav", 0xFEED, 41, false]));
    assert_eq!(answers[4]["opened"], serde_json::json!(["gröund", u64::MAX, 7, true]));
    assert!(answers[5]["refused"].as_str().unwrap().contains("does not verify"));
}

#[test]
fn outside_peers_cannot_slip_samples_or_ends_into_a_deployment_with_keys() {
    let Some(python) = python("eclipse-zenoh") else { return };
    let dir = out_dir("keys");
    let port = free_ports(4);
    let (uav, ground, ground_tcp, relay) = (port, port + 1, port + 2, port + 3);
    // A spec with TLS endpoints, and a plain TCP one on the ground station (for tools).
    let spec = dir.join("guarded.kpl");
    std::fs::write(
        &spec,
        format!(
            "source ticks : int = timer(period: 20ms, count: 300)\n\
             sink sent = file.jsonl(ticks, path: \"sent.jsonl\")\n\
             sink received = file.jsonl(ticks, path: \"received.jsonl\")\n\
             sink relayed = file.jsonl(ticks, path: \"relayed.jsonl\")\n\
             deploy guarded {{\n\
             \x20 host uav listen \"tls/127.0.0.1:{uav}\" {{ ticks, sent }}\n\
             \x20 host ground listen [\"tls/127.0.0.1:{ground}\", \"tcp/127.0.0.1:{ground_tcp}\"] connect \"tls/127.0.0.1:{uav}\" {{ received }}\n\
             \x20 host relay listen \"tls/127.0.0.1:{relay}\" connect [\"tls/127.0.0.1:{uav}\", \"tls/127.0.0.1:{ground}\"] {{ relayed }}\n\
             }}\n"
        ),
    )
    .unwrap();
    let spec = spec.to_str().unwrap();
    let keys = dir.join("keys");
    let made = common::kpl(&["keys", spec, "--out", keys.to_str().unwrap()]);
    assert!(made.status.success(), "{}", String::from_utf8_lossy(&made.stderr));
    // Without keys (--insecure: otherwise keys are made on first use), TLS endpoints are refused
    // with the way out.
    let refused =
        common::kpl(&["run", spec, "--host", "uav", "--clock", "wall", "--for", "1s", "--insecure"]);
    assert_eq!(refused.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&refused.stderr).contains("kpl keys"),
        "{}",
        String::from_utf8_lossy(&refused.stderr)
    );

    let keys_arg = ["--keys", keys.to_str().unwrap()];
    let hosts: Vec<(&str, Child)> = ["ground", "relay", "uav"]
        .into_iter()
        .map(|h| (h, host_with(spec, h, &dir.join(h), &keys_arg, &[])))
        .collect();
    // Once samples reach the ground station, the strangers try.
    let received = dir.join("ground/received.jsonl");
    let start = Instant::now();
    while std::fs::metadata(&received).map_or(true, |m| m.len() == 0) {
        assert!(start.elapsed() < HANG, "nothing reached the ground station");
        std::thread::sleep(Duration::from_millis(50));
    }
    let key = "kpl/guarded/guarded/ticks";
    let forge = |mode: &str, endpoint: String, extra: &[&str]| -> Value {
        let out = Command::new(&python)
            .arg(root().join("tests/zenoh_forger.py"))
            .arg(root().join("docs/streams.md"))
            .args(["forge", mode, &endpoint, key, "20"])
            .args(extra)
            .output()
            .unwrap();
        assert!(out.status.success(), "{mode}: {}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_str(String::from_utf8_lossy(&out.stdout).lines().last().unwrap()).unwrap()
    };
    let keys_dir = keys.to_str().unwrap();
    let nocert = forge("nocert", format!("tls/127.0.0.1:{ground}"), &[keys_dir]);
    assert_eq!(nocert["connected"], false, "no certificate, no link: {nocert}");
    let member = forge("member", format!("tls/127.0.0.1:{ground}"), &[keys_dir, "relay"]);
    assert_eq!(member["connected"], true, "{member}");
    let plain = forge("plain", format!("tcp/127.0.0.1:{ground_tcp}"), &[]);
    assert_eq!(plain["connected"], true, "{plain}");
    assert_eq!(plain["sent"], 21);

    for (name, child) in hosts {
        let (code, stderr) = finish(child, name);
        assert_eq!(code, Some(0), "{name}:\n{stderr}");
    }
    let sent = lines(&dir.join("uav/sent.jsonl"));
    assert_eq!(sent.len(), 300);
    assert_eq!(lines(&received), sent, "the ground station has the producer's samples and nothing else");
    assert_eq!(lines(&dir.join("relay/relayed.jsonl")), sent);
    let report = summary(&dir.join("ground"));
    let inbound = &report["transport"]["inbound"][0];
    // The stranger's 20 samples and its end reached kpl through the TCP endpoint and were refused;
    // the member's were stopped by access control before (none counted here).
    assert_eq!(inbound["refused"], 21, "{inbound}");
    assert_eq!(inbound["ending"], "end");
    let reasons: Vec<&str> = inbound["refused_examples"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["error"].as_str().unwrap())
        .collect();
    assert!(reasons.iter().any(|r| r.contains("no KPL envelope")), "{reasons:?}");
    assert!(reasons.iter().any(|r| r.contains("no authentication tag")), "{reasons:?}");
    // Whether the stranger's messages also reach the relay depends on zenoh's routing at that
    // moment (seen under load on a fresh machine): if they do, the relay refuses all of them too,
    // and it accepted nothing but the producer's (relayed.jsonl above).
    let relay = &summary(&dir.join("relay"))["transport"]["inbound"][0];
    assert!(relay["refused"] == 0 || relay["refused"] == 21, "{relay}");
}

#[test]
fn kpl_launch_runs_every_host_with_one_summary() {
    let out = out_dir("launch");
    let result =
        common::kpl_command(&["launch", "specs/zenoh/two_hosts.kpl", "--out", out.to_str().unwrap()])
            .env_remove("KPL_ZENOH_PORT_BASE")
            .output()
            .unwrap();
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert_eq!(result.status.code(), Some(0), "{stderr}");
    // The commands to start each host elsewhere, and one summary.
    assert!(
        stderr.contains("kpl run specs/zenoh/two_hosts.kpl --host a --clock wall --deployment default"),
        "{stderr}"
    );
    assert!(stderr.contains("host `a`: exit 0") && stderr.contains("host `b`: exit 0"), "{stderr}");
    let sent = lines(&out.join("a/sent.jsonl"));
    assert_eq!(of_stream(&sent, "ticks").len(), 300);
    assert_eq!(of_stream(&lines(&out.join("b/received.jsonl")), "ticks"), of_stream(&sent, "ticks"));
    let launch: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("launch.json")).unwrap()).unwrap();
    assert!(launch["hosts"][1]["report"]["transport"]["inbound"][0]["received"].as_u64().unwrap() > 0);
    assert!(out.join("b/kpl.log").exists());

    // With --tls: keys made for the launch, every link mutual TLS.
    let out = out_dir("launch-tls");
    let result = common::kpl_command(&[
        "launch",
        "specs/zenoh/two_hosts.kpl",
        "--tls",
        "--out",
        out.to_str().unwrap(),
    ])
    .output()
    .unwrap();
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert_eq!(result.status.code(), Some(0), "{stderr}");
    assert!(out.join("keys/a.pem").exists() && out.join("keys/secret").exists());
    assert!(stderr.contains(&format!("--keys {}", out.join("keys").display())), "{stderr}");
    // Every tick arrived, or its loss is counted: a TLS link between the two processes has been
    // seen to drop and come back within milliseconds on this loaded machine (zenoh 1.10.2's TLS
    // link reads and writes one rustls stream from two tasks at once, zenoh issue #2557), and what
    // was on the broken link is lost, as docs/streams.md ("A known limit of `tls/` links") says.
    let received = of_stream(&lines(&out.join("b/received.jsonl")), "ticks").len() as u64;
    let ticks = &summary(&out.join("b"))["transport"]["inbound"][1];
    assert_eq!(ticks["stream"], "ticks");
    assert_eq!(ticks["received"].as_u64(), Some(received));
    assert_eq!(received + ticks["lost"].as_u64().unwrap(), 300, "{stderr}");
    if received < 300 {
        assert!(stderr.contains("went away"), "a loss comes with its reason:\n{stderr}");
    }
}

#[test]
fn python_follows_the_docs_to_decode_and_encode_samples() {
    let Some(python) = python("eclipse-zenoh") else { return };
    let out = out_dir("python");
    // Readings with awkward values: non-ASCII and quoted text, tiny and huge floats, epoch times.
    let samples: Vec<Value> = (0..200i64)
        .map(|i| {
            let valid = 1_700_000_000_000_000 + i * 1_000;
            serde_json::json!({
                "valid": valid,
                "available": valid + (i % 7) * 13,
                "value": {
                    "id": format!("rd{i}"),
                    "pos": [i as f64 * 0.1, -1e-300 * i as f64],
                    "temp": 21.5 + i as f64 * 1e15,
                    "label": format!("wärme \"{i}\" 🌡"),
                },
            })
        })
        .collect();
    let input = out.join("in.jsonl");
    let text: Vec<String> = samples.iter().map(Value::to_string).collect();
    std::fs::write(&input, text.join("\n") + "\n").unwrap();

    let port = free_ports(1);
    let run = wall_run(&["specs/zenoh/outside.kpl"], &out.join("run"), port);
    let client = Command::new(&python)
        .arg(root().join("tests/zenoh_client.py"))
        .arg(root().join("docs/streams.md"))
        .arg(format!("tcp/127.0.0.1:{port}"))
        .args(["kpl-demo/readings", "kpl-demo/forwarded"])
        .arg(&input)
        .output()
        .unwrap();
    let (code, run_err) = finish(run, "kpl run");
    assert!(client.status.success(), "python:\n{}", String::from_utf8_lossy(&client.stderr));
    assert_eq!(code, Some(0), "kpl run:\n{run_err}");

    // Python decoded, with the documented code, what kpl published: the samples it sent.
    let decoded: Vec<Value> =
        String::from_utf8(client.stdout).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(decoded.last(), Some(&serde_json::json!({"end": 200})));
    assert_eq!(&decoded[..decoded.len() - 1], &samples[..]);

    // kpl decoded what Python encoded with the documented code, and counted the one bad message.
    let recorded = lines(&out.join("run/readings.jsonl"));
    assert_eq!(recorded.len(), samples.len());
    for (line, sample) in recorded.iter().zip(&samples) {
        assert_eq!(
            (&line["valid"], &line["available"], &line["value"]),
            (&sample["valid"], &sample["available"], &sample["value"])
        );
    }
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("run/summary.json")).unwrap()).unwrap();
    let readings = summary["summary"]["processes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["process"] == "readings")
        .unwrap_or_else(|| panic!("{summary}"));
    assert_eq!(readings["malformed"], 1);
    let example = &readings["malformed_examples"][0];
    assert_eq!(example["location"], "zenoh `kpl-demo/readings`, message 1");
    assert!(example["error"].as_str().unwrap().contains("not a KPL message"), "{example}");
}

/// The README's two hosts, as written (no keys given: they are made on first use), and a
/// stranger on the same machine without them: it declares the liveliness tokens of a subscriber
/// that is not there, of a host and of a done stream, and publishes samples and ends into both
/// hosts' inputs (without an envelope, with an untagged one, with one tagged by a secret of its
/// own and a far sequence number). Nothing of it is accepted, the hosts are not fooled into
/// thinking host `b` is there, the run goes on, and the summaries count what was refused.
#[test]
fn strangers_cannot_forge_into_the_default_two_host_deployment() {
    let Some(python) = python("eclipse-zenoh") else { return };
    let base = free_ports(2);
    let dir = out_dir("strangers");
    let state = dir.join("state");
    let env = |c: &mut Command| {
        c.env("KPL_ZENOH_PORT_BASE", base.to_string())
            .env("KPL_STATE_DIR", &state)
            .env("KPL_ZENOH_WAIT", "120");
    };
    let run = |host: &str| -> Child {
        let mut c =
            common::kpl_command(&["run", "specs/zenoh/two_hosts.kpl", "--clock", "wall", "--host", host]);
        c.arg("--out").arg(dir.join(host)).stdin(Stdio::null()).stdout(Stdio::null()).stderr(Stdio::piped());
        env(&mut c);
        c.spawn().unwrap()
    };
    let forger = |args: &[&str], as_host: &str| -> Value {
        let out = Command::new(&python)
            .arg(root().join("tests/zenoh_forger.py"))
            .arg(root().join("docs/streams.md"))
            .args(args)
            .env("KPL_FORGE_AS", as_host)
            .output()
            .unwrap();
        assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_str(String::from_utf8_lossy(&out.stdout).lines().last().unwrap()).unwrap()
    };
    let a_port = format!("tcp/127.0.0.1:{base}");
    let b_port = format!("tcp/127.0.0.1:{}", base + 1);
    let a = run("a");
    // Before b comes: fake tokens of b subscribing, of b running and of b having the ends.
    let streams = "kpl/default/two_hosts";
    let tokens: Vec<String> = ["ticks", "percepts"]
        .iter()
        .flat_map(|s| [format!("{streams}/{s}/@subscriber/b"), format!("{streams}/{s}/@done/b")])
        .chain([format!("{streams}/@host/b")])
        .collect();
    let holder = {
        let (python, a_port, tokens) = (python.clone(), a_port.clone(), tokens.clone());
        std::thread::spawn(move || {
            Command::new(python)
                .arg(root().join("tests/zenoh_forger.py"))
                .arg(root().join("docs/streams.md"))
                .args(["tokens", &a_port, "6"])
                .args(&tokens)
                .output()
                .unwrap()
        })
    };
    // Forged samples and ends into a's input from b.
    for mode in ["plain", "wrongkey"] {
        let forged = forger(&["forge", mode, &a_port, &format!("{streams}/echoed"), "20"], "b");
        assert_eq!(forged["connected"], true, "{forged}");
    }
    let held = holder.join().unwrap();
    assert!(held.status.success(), "{}", String::from_utf8_lossy(&held.stderr));
    // Now b, and forged samples into b's input from a while the run goes on.
    let b = run("b");
    for mode in ["plain", "wrongkey"] {
        let forged = forger(&["forge", mode, &b_port, &format!("{streams}/ticks"), "20"], "a");
        assert_eq!(forged["connected"], true, "{forged}");
    }
    let (a_code, a_err) = finish(a, "host a");
    let (b_code, b_err) = finish(b, "host b");
    assert_eq!(a_code, Some(0), "host a:\n{a_err}");
    assert_eq!(b_code, Some(0), "host b:\n{b_err}");
    // a was not fooled: it waited for the real b (the fake tokens carry no authenticated word).
    assert!(a_err.contains("waiting for host(s) `b`"), "{a_err}");
    assert!(!a_err.contains("went on after"), "a did not go on without b: {a_err}");
    let sent = lines(&dir.join("a/sent.jsonl"));
    let received = lines(&dir.join("b/received.jsonl"));
    for stream in ["percepts", "ticks"] {
        assert_eq!(
            of_stream(&received, stream),
            of_stream(&sent, stream),
            "{stream}: b has a's samples, none forged"
        );
    }
    assert_eq!(lines(&dir.join("a/returned.jsonl")).len(), 300, "a has b's echoes, none forged");
    let refused = |host: &str, stream: &str| -> u64 {
        let report = summary(&dir.join(host));
        let inbound = report["transport"]["inbound"].as_array().unwrap();
        let s = inbound.iter().find(|s| s["stream"] == stream).unwrap();
        assert_eq!(s["ending"], "end", "{s}");
        assert_eq!(s["lost"], 0, "{s}");
        s["refused"].as_u64().unwrap()
    };
    // Whatever of the forged messages zenoh delivered (a client's puts before a subscriber
    // matched are dropped) was refused and counted; the stranger's last puts came after a match.
    let (on_a, on_b) = (refused("a", "echoed"), refused("b", "ticks"));
    eprintln!("strangers: refused {on_a} message(s) at a, {on_b} at b");
    assert!(on_a > 0 && on_b > 0, "a refused {on_a}, b refused {on_b}");
}

/// Two `kpl launch` of one spec at once, each with its own --out: both pick their own ports and
/// nothing crosses; a third with the first one's --out refuses, naming it.
#[test]
fn two_launches_of_one_spec_at_once_never_mix() {
    let dir = out_dir("launches");
    let state = dir.join("state");
    let launch = |out: &Path| -> Child {
        common::kpl_command(&["launch", "specs/zenoh/two_hosts.kpl", "--quiet", "--out"])
            .arg(out)
            .env_remove("KPL_ZENOH_PORT_BASE")
            .env("KPL_STATE_DIR", &state)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (one, two) = (dir.join("one"), dir.join("two"));
    let first = launch(&one);
    let second = launch(&two);
    let start = Instant::now();
    while !one.join("launch.lock").exists() {
        assert!(start.elapsed() < HANG, "the first launch never started");
        std::thread::sleep(Duration::from_millis(10));
    }
    let third = common::kpl_command(&["launch", "specs/zenoh/two_hosts.kpl", "--quiet", "--out"])
        .arg(&one)
        .env("KPL_STATE_DIR", &state)
        .output()
        .unwrap();
    let third_err = String::from_utf8_lossy(&third.stderr);
    assert_eq!(third.status.code(), Some(2), "{third_err}");
    assert!(third_err.contains("held by another kpl launch (process"), "{third_err}");
    for (name, child, out) in [("first", first, &one), ("second", second, &two)] {
        let (code, stderr) = finish(child, name);
        assert_eq!(code, Some(0), "{name}:\n{stderr}");
        let sent = of_stream(&lines(&out.join("a/sent.jsonl")), "ticks");
        assert_eq!(sent.len(), 300);
        assert_eq!(
            of_stream(&lines(&out.join("b/received.jsonl")), "ticks"),
            sent,
            "{name}: its own ticks only"
        );
        let report = summary(&out.join("b"));
        assert!(
            report["transport"]["inbound"].as_array().unwrap().iter().all(|s| s["refused"] == 0),
            "{report}"
        );
    }
}
