//! Hosts that fail and come back, end to end: three `kpl run --host` processes of one spec, each in
//! its own network namespace where the machine allows it (`ip netns`, as root), else on loopback
//! ports. Every host produces a stream for the two others, and the middle host relays one (a chain
//! a -> b -> c). The scenario:
//!
//! 1. host `c` starts late, after the others stopped waiting for it (`KPL_ZENOH_WAIT`);
//! 2. each host in turn is killed with SIGKILL and started again;
//! 3. the middle host is frozen (SIGSTOP) for longer than zenoh's lease, then thawed;
//!
//! after each step every stream flows again, in every direction; at the end every host is stopped
//! with SIGTERM, and the summaries say which hosts went away and what was lost, with nothing
//! refused, no sample duplicated or out of order within a run of its producer, and no host hung.
//!
//! The scenario starts a host a minute late and freezes one for 20 s, with zenoh's default
//! lease (10 s) and start-up wait (30 s). The default here is a shorter equivalent with the same
//! mechanism: the late start is longer than the start-up wait, the freeze longer than the lease
//! (set to 2 s through a `KPL_ZENOH_CONFIG` file, which also shows that such a file merges with
//! the defaults), and the give-up wait longer than both. `KPL_TEST_LATE_S=60 KPL_TEST_FREEZE_S=20
//! KPL_TEST_LEASE_S=10 KPL_TEST_WAIT_S=30` runs the numbers. Every wait here is bounded.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr, clippy::disallowed_methods)] // tests; waits are bounded by the wall clock

mod common;

use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::free_ports;
use serde_json::Value;

const HOSTS: [&str; 3] = ["a", "b", "c"];

/// What each host receives: (stream, producing host).
fn inputs(host: &str) -> Vec<&'static str> {
    match host {
        "a" => vec!["tb", "tc"],
        "b" => vec!["ta", "tc"],
        _ => vec!["ta", "tb", "relay"],
    }
}

fn seconds(name: &str, default: f64) -> Duration {
    let value = std::env::var(name).ok().and_then(|v| v.parse::<f64>().ok()).unwrap_or(default);
    Duration::from_secs_f64(value)
}

struct Params {
    late: Duration,
    freeze: Duration,
    lease: Duration,
    wait: Duration,
    give_up: Duration,
}

impl Params {
    fn from_env() -> Params {
        let lease = seconds("KPL_TEST_LEASE_S", 2.0);
        let wait = seconds("KPL_TEST_WAIT_S", 3.0);
        let late = seconds("KPL_TEST_LATE_S", 6.0);
        let freeze = seconds("KPL_TEST_FREEZE_S", 5.0);
        // Longer than anything a host is away in this scenario: nothing is cut short.
        let give_up = (late + freeze + lease) * 2 + Duration::from_secs(30);
        assert!(late > wait && freeze > lease, "the scenario needs late > wait and freeze > lease");
        Params { late, freeze, lease, wait, give_up }
    }
}

/// Where the hosts run: network namespaces joined by a bridge, or loopback ports.
struct Network {
    namespaces: Vec<String>,
    /// The address each host listens on.
    addresses: BTreeMap<&'static str, String>,
    base_port: u16,
}

impl Network {
    fn new() -> Network {
        match Network::namespaces() {
            Some(network) => network,
            None => {
                eprintln!(
                    "network namespaces unavailable (not root, or no `ip netns`): hosts on loopback ports"
                );
                let base_port = free_ports(HOSTS.len() as u16);
                let addresses = HOSTS.iter().map(|h| (*h, "127.0.0.1".to_string())).collect();
                Network { namespaces: Vec::new(), addresses, base_port }
            }
        }
    }

    /// One namespace per host and a switch namespace with a bridge; `None` when `ip` refuses.
    fn namespaces() -> Option<Network> {
        let ip = |args: &[&str]| {
            Command::new("ip").args(args).stderr(Stdio::null()).status().is_ok_and(|s| s.success())
        };
        let id = std::process::id() % 200 + 20;
        let prefix = format!("kplf{}", std::process::id());
        let switch = format!("{prefix}-sw");
        let mut network = Network { namespaces: Vec::new(), addresses: BTreeMap::new(), base_port: 7447 };
        if !ip(&["netns", "add", &switch]) {
            return None;
        }
        network.namespaces.push(switch.clone());
        let ok = ip(&["-n", &switch, "link", "add", "br0", "type", "bridge"])
            && ip(&["-n", &switch, "link", "set", "br0", "up"]);
        if !ok {
            return None;
        }
        for (i, host) in HOSTS.iter().enumerate() {
            let ns = format!("{prefix}-{host}");
            if !ip(&["netns", "add", &ns]) {
                return None;
            }
            network.namespaces.push(ns.clone());
            let (inner, outer) = (format!("v{host}0"), format!("v{host}1"));
            let address = format!("10.{id}.0.{}", i + 1);
            let ok = ip(&[
                "link", "add", &inner, "netns", &ns, "type", "veth", "peer", "name", &outer, "netns", &switch,
            ]) && ip(&["-n", &ns, "addr", "add", &format!("{address}/24"), "dev", &inner])
                && ip(&["-n", &ns, "link", "set", &inner, "up"])
                && ip(&["-n", &ns, "link", "set", "lo", "up"])
                && ip(&["-n", &switch, "link", "set", &outer, "master", "br0"])
                && ip(&["-n", &switch, "link", "set", &outer, "up"]);
            if !ok {
                return None;
            }
            network.addresses.insert(host, address);
        }
        Some(network)
    }

    /// The command that runs `kpl` on `host`'s side of the network.
    fn command(&self, host: &str) -> Command {
        let kpl = env!("CARGO_BIN_EXE_kpl");
        let mut command = match self.namespaces.iter().find(|n| n.ends_with(&format!("-{host}"))) {
            Some(ns) => {
                // `ip netns exec` replaces itself with kpl: the child's id is kpl's.
                let mut c = Command::new("ip");
                c.args(["netns", "exec", ns, kpl]);
                c
            }
            None => Command::new(kpl),
        };
        command.current_dir(common::root()).env("NO_COLOR", "1");
        command
    }

    fn endpoint(&self, host: &str) -> String {
        let i = HOSTS.iter().position(|h| *h == host).unwrap() as u16;
        let port = if self.namespaces.is_empty() { self.base_port + i } else { self.base_port };
        format!("tcp/{}:{port}", self.addresses[host])
    }

    /// The spec, with each host listening on its address and dialling the hosts before it.
    fn spec(&self) -> String {
        let host = |name: &str, processes: &str| {
            let before: Vec<String> = HOSTS
                .iter()
                .take_while(|h| **h != name)
                .map(|h| format!("\"{}\"", self.endpoint(h)))
                .collect();
            let connect =
                if before.is_empty() { String::new() } else { format!(" connect [{}]", before.join(", ")) };
            format!("  host {name} listen \"{}\"{connect} {{ {processes} }}\n", self.endpoint(name))
        };
        format!(
            "// Three hosts, every one sending to the two others; b relays a's ticks to c (tests/faults.rs).\n\
             source ta : int = timer(period: 50ms)\n\
             source tb : int = timer(period: 50ms)\n\
             source tc : int = timer(period: 50ms)\n\
             compute relay = kpl.merge(ta)\n\
             sink at_a = file.jsonl(tb, tc, path: \"in.jsonl\")\n\
             sink at_b = file.jsonl(ta, tc, path: \"in.jsonl\")\n\
             sink at_c = file.jsonl(ta, tb, relay, path: \"in.jsonl\")\n\
             deploy faults {{\n{}{}{}}}\n",
            host("a", "ta, at_a"),
            host("b", "tb, relay, at_b"),
            host("c", "tc, at_c"),
        )
    }
}

impl Drop for Network {
    fn drop(&mut self) {
        for ns in self.namespaces.iter().rev() {
            let _ = Command::new("ip").args(["netns", "del", ns]).status();
        }
    }
}

/// The runs of the three hosts: each host's current process and every output folder it had.
struct Deployment {
    network: Network,
    dir: PathBuf,
    spec: PathBuf,
    config: PathBuf,
    params: Params,
    running: BTreeMap<&'static str, (Child, PathBuf)>,
    /// Every run of each host: its output folder and (once ended) its exit status and stderr.
    runs: Vec<(&'static str, PathBuf, Option<i32>, String)>,
}

impl Deployment {
    fn start(&mut self, host: &'static str) {
        let n =
            self.runs.iter().filter(|r| r.0 == host).count() + usize::from(self.running.contains_key(host));
        let out = self.dir.join(format!("{host}-{}", n + 1));
        let child = self
            .network
            .command(host)
            .args(["run", self.spec.to_str().unwrap(), "--host", host, "--clock", "wall", "--quiet", "--out"])
            .arg(&out)
            .env("KPL_ZENOH_CONFIG", &self.config)
            .env("KPL_ZENOH_WAIT", self.params.wait.as_secs_f64().to_string())
            .env("KPL_ZENOH_GIVE_UP", self.params.give_up.as_secs_f64().to_string())
            .env("RUST_LOG", "warn,kpl_zenoh::transport=info")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        eprintln!("started {host} ({}) -> {}", child.id(), out.display());
        self.running.insert(host, (child, out));
    }

    fn signal(&self, host: &str, signal: &str) {
        let (child, _) = &self.running[host];
        let status = Command::new("kill").args(["-s", signal, &child.id().to_string()]).status().unwrap();
        assert!(status.success(), "kill -s {signal} {host}");
    }

    /// Waits for a host's process to end (bounded), keeping its exit status and stderr.
    fn reap(&mut self, host: &'static str) {
        let (mut child, out) = self.running.remove(host).unwrap();
        let mut stderr = String::new();
        let pipe = child.stderr.take().unwrap();
        let reader = std::thread::spawn(move || {
            let mut pipe = pipe;
            let mut text = String::new();
            let _ = pipe.read_to_string(&mut text);
            text
        });
        let start = Instant::now();
        let status = loop {
            if let Some(status) = child.try_wait().unwrap() {
                break status;
            }
            if start.elapsed() > self.params.give_up + Duration::from_secs(120) {
                child.kill().unwrap();
                let _ = child.wait();
                panic!("host {host} did not end: it hung");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        stderr.push_str(&reader.join().unwrap());
        self.runs.push((host, out, status.code(), stderr));
    }

    fn kill(&mut self, host: &'static str) {
        self.signal(host, "KILL");
        self.reap(host);
    }

    /// The samples each stream brought to a host's current run so far.
    fn received(&self, host: &str) -> BTreeMap<String, usize> {
        let (_, out) = &self.running[host];
        let text = std::fs::read_to_string(out.join("in.jsonl")).unwrap_or_default();
        let mut counts = BTreeMap::new();
        for line in text.lines() {
            // The sink's buffer may hold a half-written last line.
            if let Ok(v) = serde_json::from_str::<Value>(line) {
                *counts.entry(v["stream"].as_str().unwrap_or("").to_string()).or_insert(0) += 1;
            }
        }
        counts
    }

    /// Waits until every stream into every running host has grown by a few samples.
    fn all_streams_flow(&self, after: &str) {
        let before: BTreeMap<&str, BTreeMap<String, usize>> =
            self.running.keys().map(|h| (*h, self.received(h))).collect();
        let limit = self.params.give_up + Duration::from_secs(60);
        let start = Instant::now();
        loop {
            let mut stalled = Vec::new();
            for host in self.running.keys() {
                let now = self.received(host);
                for stream in inputs(host) {
                    let count = |m: &BTreeMap<String, usize>| m.get(stream).copied().unwrap_or(0);
                    let grew = count(&now).saturating_sub(count(&before[host]));
                    // The file sink writes in blocks: wait for a block's worth.
                    if grew < 20 {
                        stalled.push(format!("{stream} -> {host}"));
                    }
                }
            }
            if stalled.is_empty() {
                eprintln!("after {after}: every stream flows ({:.1} s)", start.elapsed().as_secs_f64());
                return;
            }
            assert!(start.elapsed() < limit, "after {after}, streams do not flow again: {stalled:?}");
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

fn summary(out: &Path) -> Value {
    let path = out.join("summary.json");
    serde_json::from_str(
        &std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
    .unwrap()
}

#[test]
fn hosts_killed_restarted_frozen_and_late_resume_every_stream() {
    let params = Params::from_env();
    let network = Network::new();
    let dir = common::fresh_dir("faults", "deployment");
    let spec = dir.join("faults.kpl");
    std::fs::write(&spec, network.spec()).unwrap();
    let config = dir.join("zenoh.json5");
    let lease_ms = params.lease.as_millis();
    std::fs::write(
        &config,
        format!("{{ transport: {{ link: {{ tx: {{ lease: {lease_ms}, keep_alive: 4 }} }} }} }}\n"),
    )
    .unwrap();
    let mut d = Deployment { network, dir, spec, config, params, running: BTreeMap::new(), runs: Vec::new() };

    // 1. c starts after a and b stopped waiting for it.
    d.start("a");
    d.start("b");
    std::thread::sleep(d.params.late);
    d.start("c");
    d.all_streams_flow("the late start of c");

    // 2. Each host is killed and started again.
    for host in HOSTS {
        d.kill(host);
        std::thread::sleep(Duration::from_secs(1));
        d.start(host);
        d.all_streams_flow(&format!("the restart of {host}"));
    }

    // 3. The middle host is frozen longer than the lease.
    d.signal("b", "STOP");
    std::thread::sleep(d.params.freeze);
    d.signal("b", "CONT");
    d.all_streams_flow("the freeze of b");

    // The end: every host stops on SIGTERM.
    for host in HOSTS {
        d.signal(host, "TERM");
    }
    for host in HOSTS {
        d.reap(host);
    }

    for (host, out, code, stderr) in &d.runs {
        if code.is_none() {
            continue; // SIGKILL: no status, no summary
        }
        assert_eq!(*code, Some(143), "host {host} ({}) ended on SIGTERM:\n{stderr}", out.display());
        let report = summary(out);
        assert_eq!(report["signal"], "SIGTERM");
        let transport = &report["transport"];
        assert_eq!(transport["deployment"], "faults");
        for stream in transport["inbound"].as_array().unwrap() {
            assert_eq!(stream["refused"], 0, "{host}: {stream}");
            assert!(stream["received"].as_u64().unwrap() > 0, "{host}: {stream}");
            assert_eq!(stream["ending"], "open", "{host}: nothing was cut short: {stream}");
        }
        // Within each run of a producer, samples arrive in order and once.
        let mut last: BTreeMap<String, i64> = BTreeMap::new();
        for line in common::lines(&out.join("in.jsonl")) {
            let stream = line["stream"].as_str().unwrap().to_string();
            let value = line["value"].as_i64().unwrap();
            if let Some(previous) = last.get(&stream) {
                assert!(value > *previous || value == 0, "{host}: {stream} went from {previous} to {value}");
            }
            last.insert(stream, value);
        }
    }
    // Every host that was killed or frozen was seen going away and coming back by the others
    // (their logs; a killed run leaves no summary), and the last runs' summaries count it.
    let logs: String = d.runs.iter().map(|r| r.3.as_str()).collect();
    for host in HOSTS {
        assert!(logs.contains(&format!("host `{host}` went away")), "nobody saw {host} go away:\n{logs}");
        assert!(logs.contains(&format!("host `{host}` is back")), "nobody saw {host} come back:\n{logs}");
    }
    let last_a = d.runs.iter().rev().find(|r| r.0 == "a").unwrap();
    let hosts = summary(&last_a.1)["transport"]["hosts"].clone();
    let b = hosts.as_array().unwrap().iter().find(|h| h["host"] == "b").unwrap();
    assert!(b["lost"].as_u64().unwrap() >= 2, "a saw b killed and frozen: {b}");
    assert!(
        b["away_s"].as_f64().unwrap() >= d.params.freeze.as_secs_f64() - d.params.lease.as_secs_f64() - 1.0
    );
    // The late c missed what a and b sent before it came: counted by the consumers' first runs'
    // logs as lost samples, and nothing hung.
    // a and b said they waited for c while it was late, then went on without it.
    for host in ["a", "b"] {
        let first = d.runs.iter().find(|r| r.0 == host).unwrap();
        assert!(first.3.contains("waiting for host(s) `c`"), "{host} reported its wait:\n{}", first.3);
        assert!(first.3.contains("without host(s) `c`"), "{host} went on without c:\n{}", first.3);
    }
    let first_c = d.runs.iter().find(|r| r.0 == "c").unwrap();
    assert!(first_c.3.contains("lost on the way"), "c counted what it missed:\n{}", first_c.3);
}
