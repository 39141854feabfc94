//! The transport between zenoh sessions in one process (each with its own loopback port):
//! - samples cross with their times and typed values, then the end, which the consumer confirms;
//! - bytes that are not KPL messages are malformed; messages without the deployment's envelope,
//!   from another host, or with a bad tag are refused and counted;
//! - a producer that goes away does not end the stream: it resumes when the producer comes back
//!   (counting the restart), and is cut short when it does not;
//! - a host that subscribes after the stream ended still gets the end;
//! - a publisher waits for every consuming host, and says how many came;
//! - deployments of one spec do not see each other's samples;
//! - two hosts of a spec run by the runtime (`run_async`) exchange streams both ways.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::disallowed_methods)] // tests; waits are bounded by the wall clock

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use kpl_core::{Value, ValueType};
use kpl_runtime::transport::{InboundEnding, InboundReport, Remote, RemoteReceiver, RemoteSender, StreamKey};
use kpl_runtime::{ClockKind, RunConfig, Sample};
use kpl_semantic::hir;
use kpl_zenoh::envelope::Envelope;
use kpl_zenoh::{HostSession, Sessions, ZenohOptions, ZenohReceiver, ZenohSender};

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// A deploy section of hosts named `h0`, `h1`, ..., `h0` listening on `port`, the others dialling it.
fn deploy(port: u16, hosts: usize) -> hir::Deploy {
    let endpoint = format!("tcp/127.0.0.1:{port}");
    hir::Deploy {
        name: None,
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

async fn open(deploy: &hir::Deploy, host: usize, options: ZenohOptions) -> Arc<HostSession> {
    Sessions::new(options).open(Some(deploy), Some(&format!("h{host}"))).await.unwrap()
}

/// Sessions of `hosts` hosts that wait `wait` for each other and for absent producers.
async fn sessions(hosts: usize, wait: Duration) -> Vec<Arc<HostSession>> {
    let deploy = deploy(free_port(), hosts);
    let mut out = Vec::new();
    for i in 0..hosts {
        let options = ZenohOptions { subscriber_wait: wait, give_up: wait, ..ZenohOptions::default() };
        out.push(open(&deploy, i, options).await);
    }
    out
}

fn key(producer: &str) -> StreamKey {
    StreamKey {
        deployment: "test".into(),
        spec: "test spec".into(),
        producer: producer.into(),
        port: Some("out".into()),
    }
}

fn consumers(names: &[&str]) -> BTreeSet<String> {
    names.iter().map(|s| s.to_string()).collect()
}

/// A receiver of a deployment's stream produced on `producer_host`, and its report.
async fn receiver_from(
    session: &HostSession,
    key: &StreamKey,
    ty: ValueType,
    host: &str,
    producer_host: &str,
) -> (ZenohReceiver, Arc<Mutex<InboundReport>>) {
    let report = Arc::new(Mutex::new(InboundReport::default()));
    let receiver = ZenohReceiver::declare_with(
        session,
        key,
        ty,
        host,
        Some(producer_host.into()),
        report.clone(),
        Arc::default(),
    )
    .await
    .unwrap();
    (receiver, report)
}

async fn recv(receiver: &mut ZenohReceiver) -> Option<Remote> {
    tokio::time::timeout(Duration::from_secs(60), receiver.recv()).await.expect("nothing arrived")
}

fn int(i: i64) -> Sample {
    Sample::new(i, i, Value::Int(i))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn samples_cross_with_their_times_then_the_end() {
    let s = sessions(2, Duration::from_secs(60)).await;
    let ty = ValueType::List(Box::new(ValueType::Vec2));
    let (mut receiver, report) = receiver_from(&s[1], &key("p"), ty, "h1", "h0").await;
    let mut sender = ZenohSender::declare(&s[0], &key("p"), "h0", consumers(&["h1"])).await.unwrap();
    assert_eq!(sender.wait_for_subscribers(1).await, 1);
    let samples: Vec<Sample> = (0..500i64)
        .map(|i| {
            let points: Vec<Value> = (0..i % 5).map(|k| Value::vec2(k as f64 * 0.1, -(i as f64))).collect();
            Sample::new(i * 1_000 - 7, i * 1_000 + i % 3, Value::List(points.into()))
        })
        .collect();
    for sample in &samples {
        RemoteSender::send(&mut sender, sample).await;
    }
    // The end returns once the consuming host confirms it has it.
    let consume = async move {
        for sample in &samples {
            assert_eq!(recv(&mut receiver).await, Some(Remote::Sample(sample.clone())));
        }
        assert_eq!(recv(&mut receiver).await, Some(Remote::End));
    };
    let started = std::time::Instant::now();
    tokio::join!(RemoteSender::end(&mut sender, true), consume);
    // Not a speed check: the end must not have run into its 60-second wait.
    assert!(started.elapsed() < Duration::from_secs(50), "the end waited for a consumer that had it");
    let report = report.lock().unwrap().clone();
    assert_eq!((report.received, report.lost, report.refused), (500, 0, 0));
    assert_eq!(report.ending, InboundEnding::End);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn strangers_are_refused_and_counted_and_garbage_is_malformed() {
    let s = sessions(2, Duration::from_secs(60)).await;
    let (mut receiver, report) = receiver_from(&s[1], &key("p"), ValueType::Float, "h1", "h0").await;
    let raw = s[0].session.declare_publisher(kpl_zenoh::keys::stream(&key("p"))).await.unwrap();
    while !raw.matching_status().await.unwrap().matching() {
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let key_expr = kpl_zenoh::keys::stream(&key("p"));
    let mut good = Vec::new();
    kpl_zenoh::codec::encode_sample(&Sample::new(5, 6, Value::Float(2.5)), &mut good).unwrap();
    let envelope = |host: &str, sequence: u64| Envelope {
        host: host.into(),
        incarnation: 42,
        sequence,
        unfinished: false,
    };
    // A well-formed sample and a forged end without an envelope, one from the wrong host.
    raw.put(good.clone()).await.unwrap();
    raw.put(kpl_zenoh::codec::encode_end(0)).await.unwrap();
    raw.put(good.clone()).attachment(envelope("h2", 0).seal(&key_expr, &good, None)).await.unwrap();
    // An enveloped message that does not decode is malformed; a good one is delivered; the same
    // sequence number again is a replay.
    let bad = b"{\"valid\": 1}".to_vec();
    raw.put(bad.clone()).attachment(envelope("h0", 0).seal(&key_expr, &bad, None)).await.unwrap();
    raw.put(good.clone()).attachment(envelope("h0", 1).seal(&key_expr, &good, None)).await.unwrap();
    raw.put(good.clone()).attachment(envelope("h0", 1).seal(&key_expr, &good, None)).await.unwrap();
    let end = kpl_zenoh::codec::encode_end(3);
    raw.put(end.clone()).attachment(envelope("h0", 3).seal(&key_expr, &end, None)).await.unwrap();

    let Some(Remote::Malformed { location, error }) = recv(&mut receiver).await else { panic!() };
    assert_eq!(location, "zenoh `kpl/test/test%20spec/p/out`, message 4");
    assert!(error.contains("not a KPL message"), "{error}");
    assert_eq!(recv(&mut receiver).await, Some(Remote::Sample(Sample::new(5, 6, Value::Float(2.5)))));
    assert_eq!(recv(&mut receiver).await, Some(Remote::End));
    let report = report.lock().unwrap().clone();
    assert_eq!(report.refused, 4, "{report:?}");
    let why: Vec<&str> = report.refused_examples.iter().map(|m| m.error.as_str()).collect();
    assert!(why[0].contains("no KPL envelope") && why[1].contains("no KPL envelope"), "{why:?}");
    assert!(why[2].contains("from host `h2`"), "{why:?}");
    assert!(why[3].contains("replayed"), "{why:?}");
    // Sequence numbers 0 (malformed) and 2 never arrived as samples: one lost before the end.
    assert_eq!((report.received, report.lost), (1, 1));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn with_keys_only_tagged_messages_are_accepted() {
    let dir = std::env::temp_dir().join(format!("kpl-transport-keys-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    kpl_zenoh::credentials::make(&dir, "test", &["h0".into(), "h1".into()]).unwrap();
    let deploy = deploy(free_port(), 2);
    let options = ZenohOptions { keys: Some(dir.clone()), ..ZenohOptions::default() };
    let s0 = open(&deploy, 0, options.clone()).await;
    let s1 = open(&deploy, 1, options).await;
    let (mut receiver, report) = receiver_from(&s1, &key("p"), ValueType::Int, "h1", "h0").await;
    let mut sender = ZenohSender::declare(&s0, &key("p"), "h0", consumers(&["h1"])).await.unwrap();
    assert_eq!(sender.wait_for_subscribers(1).await, 1);
    // A forger without the secret, then one with another deployment's secret.
    let key_expr = kpl_zenoh::keys::stream(&key("p"));
    let raw = s0.session.declare_publisher(key_expr.clone()).await.unwrap();
    let mut forged = Vec::new();
    kpl_zenoh::codec::encode_sample(&int(-1), &mut forged).unwrap();
    let envelope = Envelope { host: "h0".into(), incarnation: 7, sequence: 0, unfinished: false };
    raw.put(forged.clone()).attachment(envelope.seal(&key_expr, &forged, None)).await.unwrap();
    let other = kpl_zenoh::credentials::Secret::from_bytes(&[9; 32]);
    raw.put(forged.clone()).attachment(envelope.seal(&key_expr, &forged, Some(&other))).await.unwrap();
    let end = kpl_zenoh::codec::encode_end(0);
    raw.put(end.clone()).attachment(envelope.seal(&key_expr, &end, Some(&other))).await.unwrap();
    for i in 0..10 {
        RemoteSender::send(&mut sender, &int(i)).await;
    }
    let consume = async {
        for i in 0..10 {
            assert_eq!(recv(&mut receiver).await, Some(Remote::Sample(int(i))));
        }
        assert_eq!(recv(&mut receiver).await, Some(Remote::End));
    };
    tokio::join!(RemoteSender::end(&mut sender, true), consume);
    let report = report.lock().unwrap().clone();
    assert_eq!((report.received, report.refused, report.lost), (10, 3, 0), "{report:?}");
    assert!(report.refused_examples[0].error.contains("no authentication tag"), "{report:?}");
    assert!(report.refused_examples[1].error.contains("does not verify"), "{report:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_resumes_when_its_producer_comes_back_and_is_cut_short_when_it_does_not() {
    let port = free_port();
    let deploy = deploy(port, 2);
    let wait = Duration::from_secs(5);
    let options = ZenohOptions { subscriber_wait: wait, give_up: wait, ..ZenohOptions::default() };
    let consumer = open(&deploy, 1, options.clone()).await;
    let (mut receiver, report) = receiver_from(&consumer, &key("p"), ValueType::Int, "h1", "h0").await;
    for run in 0..2i64 {
        // A run of the producing host: a session, a few samples, then it dies without an end.
        let producer = open(&deploy, 0, options.clone()).await;
        let mut sender = ZenohSender::declare(&producer, &key("p"), "h0", consumers(&["h1"])).await.unwrap();
        assert_eq!(sender.wait_for_subscribers(1).await, 1);
        for i in 0..5 {
            RemoteSender::send(&mut sender, &int(run * 100 + i)).await;
        }
        for i in 0..5 {
            assert_eq!(recv(&mut receiver).await, Some(Remote::Sample(int(run * 100 + i))));
        }
        drop(sender);
        producer.session.close().await.unwrap();
    }
    // Nobody comes back: the stream is cut short after the wait (short here; the same mechanism
    // as the default 30 s).
    let Some(Remote::CutShort(why)) = recv(&mut receiver).await else { panic!("expected a cut") };
    assert!(why.contains("went away and did not come back within 5 s"), "{why}");
    let report = report.lock().unwrap().clone();
    assert_eq!((report.received, report.lost, report.producer_restarts), (10, 0, 1), "{report:?}");
    assert!(matches!(report.ending, InboundEnding::CutShort(_)));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_host_that_comes_after_the_end_still_gets_it() {
    let s = sessions(2, Duration::from_secs(60)).await;
    let mut sender = ZenohSender::declare(&s[0], &key("p"), "h0", consumers(&["h1"])).await.unwrap();
    for i in 0..3 {
        RemoteSender::send(&mut sender, &int(i)).await;
    }
    let late = async {
        // Subscribes only once the stream has ended (the producer now waits for it).
        tokio::time::sleep(Duration::from_millis(500)).await;
        let (mut receiver, report) = receiver_from(&s[1], &key("p"), ValueType::Int, "h1", "h0").await;
        assert_eq!(recv(&mut receiver).await, Some(Remote::End));
        let report = report.lock().unwrap().clone();
        assert_eq!((report.received, report.lost), (0, 3), "the three samples before it came are lost");
    };
    let started = std::time::Instant::now();
    tokio::join!(RemoteSender::end(&mut sender, true), late);
    assert!(started.elapsed() < Duration::from_secs(50), "the producer saw the late host confirm the end");
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

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn deployments_of_one_spec_do_not_mix() {
    let s = sessions(2, Duration::from_secs(2)).await;
    let other = StreamKey { deployment: "other".into(), ..key("p") };
    let (mut receiver, report) = receiver_from(&s[1], &other, ValueType::Int, "h1", "h0").await;
    let mut sender = ZenohSender::declare(&s[0], &key("p"), "h0", consumers(&["h1"])).await.unwrap();
    for i in 0..20 {
        RemoteSender::send(&mut sender, &int(i)).await;
    }
    let Some(Remote::CutShort(why)) = recv(&mut receiver).await else { panic!("expected a cut") };
    assert!(why.contains("did not appear"), "{why}");
    assert_eq!(report.lock().unwrap().received, 0);
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

// Both hosts run in this test's one task (`tokio::join!`), so a wake-up of one must not be lost
// while the other opens its session: `zenoh::open` blocks its thread in a nested `block_on` that
// shared the outer one's parker and took such wake-ups (about 1 run in 8 to 1 in 3 hung until the
// timeout, whenever the second session took a connect retry to open); sessions now open on a
// blocking-pool thread (kpl_zenoh::session).
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
    // The hosts' logs, with RUST_LOG (e.g. `RUST_LOG=kpl_zenoh=debug`), shown when the test fails.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_test_writer()
        .try_init();
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
    // Bounded: 400 samples take well under a second; a hang is a failure, not a stuck suite.
    let (a, b) = tokio::time::timeout(Duration::from_secs(180), async {
        tokio::join!(
            kpl_runtime::run::run_async(&spec, &registry, &config_a, Some(&factory_a)),
            kpl_runtime::run::run_async(&spec, &registry, &config_b, Some(&factory_b)),
        )
    })
    .await
    .expect("the two hosts did not finish within 180 s");
    let (a, b) = (a.unwrap(), b.unwrap());
    assert!(a.failures.is_empty() && b.failures.is_empty(), "{:?} {:?}", a.failures, b.failures);
    assert!(
        a.incomplete().is_empty() && b.incomplete().is_empty(),
        "{:?} {:?}",
        a.incomplete(),
        b.incomplete()
    );
    let sent = lines(&dir.join("a/sent.jsonl"));
    assert_eq!(sent.len(), 400);
    assert_eq!(lines(&dir.join("b/received.jsonl")), sent);
    let returned = lines(&dir.join("a/returned.jsonl"));
    let pairs = |l: &[serde_json::Value]| -> Vec<(i64, i64)> {
        l.iter().map(|x| (x["valid"].as_i64().unwrap(), x["value"].as_i64().unwrap())).collect()
    };
    assert_eq!(pairs(&returned), pairs(&sent));
    let report_b = b.transport.unwrap();
    assert_eq!(report_b.deployment, "default");
    assert_eq!(report_b.inbound[0].received, 400);
    assert_eq!(report_b.hosts[0].host, "a");
    assert!(report_b.hosts[0].first_seen_s.is_some());
    std::fs::remove_dir_all(&dir).unwrap();
}
