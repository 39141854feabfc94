//! The transport between two zenoh sessions in one process (each with its own loopback port):
//! - samples cross with their times and typed values, then the end with the count published;
//! - bytes that are not KPL messages are reported as malformed, with where they came from;
//! - a producer that goes away without an end ends the stream after what arrived;
//! - a publisher waits for every consuming host, and says how many came;
//! - two hosts of one spec run by the runtime (`run_async`) exchange streams both ways.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use kpl_core::{Value, ValueType};
use kpl_runtime::transport::{Remote, RemoteReceiver, RemoteSender, StreamKey};
use kpl_runtime::{ClockKind, RunConfig, Sample};
use kpl_semantic::hir;
use kpl_zenoh::{HostSession, Sessions, ZenohOptions, ZenohReceiver, ZenohSender};

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// A deploy section of hosts named `h0`, `h1`, ..., `h0` listening on `port`, the others dialling it.
fn deploy(port: u16, hosts: usize) -> hir::Deploy {
    let endpoint = format!("tcp/127.0.0.1:{port}");
    hir::Deploy {
        hosts: (0..hosts)
            .map(|i| hir::Host {
                name: format!("h{i}"),
                listen: if i == 0 { vec![endpoint.clone()] } else { Vec::new() },
                connect: if i == 0 { Vec::new() } else { vec![endpoint.clone()] },
                processes: Vec::new(),
            })
            .collect(),
    }
}

async fn sessions(hosts: usize, wait: Duration) -> Vec<Arc<HostSession>> {
    let deploy = deploy(free_port(), hosts);
    let mut out = Vec::new();
    for i in 0..hosts {
        let options = ZenohOptions { subscriber_wait: wait, ..ZenohOptions::default() };
        out.push(Sessions::new(options).open(Some(&deploy), Some(&format!("h{i}"))).await.unwrap());
    }
    out
}

fn key(producer: &str) -> StreamKey {
    StreamKey { spec: "test spec".into(), producer: producer.into(), port: Some("out".into()) }
}

fn consumers(names: &[&str]) -> BTreeSet<String> {
    names.iter().map(|s| s.to_string()).collect()
}

async fn recv(receiver: &mut ZenohReceiver) -> Option<Remote> {
    tokio::time::timeout(Duration::from_secs(60), receiver.recv()).await.expect("nothing arrived")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn samples_cross_with_their_times_then_the_end() {
    let s = sessions(2, Duration::from_secs(60)).await;
    let ty = ValueType::List(Box::new(ValueType::Vec2));
    let mut receiver = ZenohReceiver::declare(&s[1], &key("p"), ty, "h1").await.unwrap();
    let mut sender = ZenohSender::declare(&s[0], &key("p"), "h0", consumers(&["h1"])).await.unwrap();
    assert_eq!(sender.wait_for_subscribers(1).await, 1);
    let samples: Vec<Sample> = (0..500i64)
        .map(|i| {
            let points: Vec<Value> = (0..i % 5).map(|k| Value::vec2(k as f64 * 0.1, -(i as f64))).collect();
            Sample::new(i * 1_000 - 7, i * 1_000 + i % 3, Value::List(points.into()))
        })
        .collect();
    for sample in &samples {
        sender.send(sample).await;
    }
    // The end returns once the consuming host has it and lets go of its subscription, as the
    // runtime does after an end.
    let consume = async move {
        for sample in &samples {
            assert_eq!(recv(&mut receiver).await, Some(Remote::Sample(sample.clone())));
        }
        assert_eq!(recv(&mut receiver).await, Some(Remote::End));
    };
    let started = std::time::Instant::now();
    tokio::join!(sender.end(), consume);
    // Not a speed check: the end must not have run into its 60-second wait.
    assert!(started.elapsed() < Duration::from_secs(50), "the end waited for a consumer that had left");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bytes_that_are_not_kpl_messages_are_malformed() {
    let s = sessions(2, Duration::from_secs(60)).await;
    let mut receiver = ZenohReceiver::declare(&s[1], &key("p"), ValueType::Float, "h1").await.unwrap();
    let raw = s[0].session.declare_publisher(kpl_zenoh::keys::stream(&key("p"))).await.unwrap();
    while !raw.matching_status().await.unwrap().matching() {
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    raw.put(b"{\"valid\": 1}".to_vec()).await.unwrap();
    let mut wrong_type = b"KPL\x01S".to_vec();
    wrong_type.extend_from_slice(&[0; 16]);
    wrong_type.extend_from_slice(b"s\x03\0\0\0NaN"); // the string "NaN" where a float is declared
    raw.put(wrong_type).await.unwrap();
    let mut good = Vec::new();
    kpl_zenoh::codec::encode_sample(&Sample::new(5, 6, Value::Float(2.5)), &mut good).unwrap();
    raw.put(good).await.unwrap();

    let Some(Remote::Malformed { location, error }) = recv(&mut receiver).await else { panic!() };
    assert_eq!(location, "zenoh `kpl/test%20spec/p/out`, message 1");
    assert!(error.contains("not a KPL message"), "{error}");
    let Some(Remote::Malformed { location, error }) = recv(&mut receiver).await else { panic!() };
    assert!(location.ends_with("message 2"), "{location}");
    assert!(error.contains("finite number"), "{error}");
    assert_eq!(recv(&mut receiver).await, Some(Remote::Sample(Sample::new(5, 6, Value::Float(2.5)))));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_producer_that_goes_away_ends_the_stream_after_what_arrived() {
    let s = sessions(2, Duration::from_secs(60)).await;
    let mut receiver = ZenohReceiver::declare(&s[1], &key("p"), ValueType::Int, "h1").await.unwrap();
    let mut sender = ZenohSender::declare(&s[0], &key("p"), "h0", consumers(&["h1"])).await.unwrap();
    assert_eq!(sender.wait_for_subscribers(1).await, 1);
    for i in 0..20 {
        sender.send(&Sample::new(i, i, Value::Int(i))).await;
    }
    // No end message: the producing host's session closes (as when the process dies).
    s[0].session.close().await.unwrap();
    for i in 0..20 {
        assert_eq!(recv(&mut receiver).await, Some(Remote::Sample(Sample::new(i, i, Value::Int(i)))));
    }
    assert_eq!(recv(&mut receiver).await, Some(Remote::End));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_publisher_waits_for_every_consuming_host() {
    // A short wait: the first call is meant to give up (one of two hosts never subscribes).
    let s = sessions(3, Duration::from_millis(300)).await;
    let mut sender = ZenohSender::declare(&s[0], &key("p"), "h0", consumers(&["h1", "h2"])).await.unwrap();
    assert_eq!(sender.wait_for_subscribers(2).await, 0, "nobody subscribed yet");
    let _first = ZenohReceiver::declare(&s[1], &key("p"), ValueType::Int, "h1").await.unwrap();
    assert_eq!(sender.wait_for_subscribers(2).await, 1, "one host of two");
    let _second = ZenohReceiver::declare(&s[2], &key("p"), ValueType::Int, "h2").await.unwrap();
    assert_eq!(sender.wait_for_subscribers(2).await, 2);
    // Another stream's subscribers do not count.
    let mut other = ZenohSender::declare(&s[0], &key("q"), "h0", consumers(&["h1"])).await.unwrap();
    assert_eq!(other.wait_for_subscribers(1).await, 0);
}

fn checked(text: &str, registry: &kpl_runtime::Registry) -> hir::Spec {
    let parse = kpl_syntax::parse(text);
    assert!(!parse.has_errors(), "{:?}", parse.diagnostics);
    let checked = kpl_semantic::check(&parse.spec, registry.signatures());
    checked.spec.unwrap_or_else(|| panic!("{:?}", checked.diagnostics))
}

fn lines(path: &std::path::Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_hosts_of_a_spec_run_by_the_runtime() {
    let port = free_port();
    let text = format!(
        r#"
source ticks : int = timer(period: 1ms, count: 400)
compute back = kpl.merge(ticks)
sink sent = file.jsonl(ticks, path: "sent.jsonl")
sink received = file.jsonl(ticks, path: "received.jsonl")
sink returned = file.jsonl(back, path: "returned.jsonl")
deploy {{
  host a listen "tcp/127.0.0.1:{port}" {{ ticks, sent, returned }}
  host b connect "tcp/127.0.0.1:{port}" {{ back, received }}
}}
"#
    );
    let mut registry = kpl_runtime::Registry::with_builtins();
    let sessions = Sessions::new(ZenohOptions::default());
    kpl_zenoh::register_with(&mut registry, sessions);
    let spec = checked(&text, &registry);
    let dir = std::env::temp_dir().join(format!("kpl-zenoh-runtime-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let config = |host: &str| RunConfig {
        clock: ClockKind::Wall,
        out_dir: dir.join(host),
        spec_dir: PathBuf::from("."),
        spec_name: "two".into(),
        host: Some(host.into()),
        ..RunConfig::default()
    };
    // Each host has its own sessions, as two processes would.
    let (factory_a, factory_b) = (
        kpl_zenoh::ZenohFactory::new(Sessions::new(ZenohOptions::default())),
        kpl_zenoh::ZenohFactory::new(Sessions::new(ZenohOptions::default())),
    );
    let (config_a, config_b) = (config("a"), config("b"));
    let (a, b) = tokio::join!(
        kpl_runtime::run::run_async(&spec, &registry, &config_a, Some(&factory_a)),
        kpl_runtime::run::run_async(&spec, &registry, &config_b, Some(&factory_b)),
    );
    let (a, b) = (a.unwrap(), b.unwrap());
    assert!(a.failures.is_empty() && b.failures.is_empty(), "{:?} {:?}", a.failures, b.failures);
    let sent = lines(&dir.join("a/sent.jsonl"));
    assert_eq!(sent.len(), 400);
    assert_eq!(lines(&dir.join("b/received.jsonl")), sent);
    let returned = lines(&dir.join("a/returned.jsonl"));
    let pairs = |l: &[serde_json::Value]| -> Vec<(i64, i64)> {
        l.iter().map(|x| (x["valid"].as_i64().unwrap(), x["value"].as_i64().unwrap())).collect()
    };
    assert_eq!(pairs(&returned), pairs(&sent));
    std::fs::remove_dir_all(&dir).unwrap();
}
