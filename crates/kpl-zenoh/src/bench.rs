//! `kpl bench zenoh`: streams between two processes on loopback, through KPL's transport
//! ([`ZenohSender`] / [`ZenohReceiver`]: encoding, zenoh, decoding into a typed sample) against
//! bare zenoh publisher/subscriber code sending the same payloads, in the same run.
//!
//! For each payload size, repeated, bare and KPL one after the other (each ratio is taken between
//! two such neighbouring runs, then summarized as median and range over the repeats):
//! - **throughput**: one process publishes `messages` samples as fast as zenoh takes them (both
//!   with `Block` congestion control, so none is dropped), the other receives and counts; samples/s
//!   are measured at the receiver from the first sample to the last;
//! - **latency**: ping-pong; one process sends a sample, the other sends it back as soon as it
//!   has it (decoded and encoded again, for KPL), `round_trips` times after a warm-up; the
//!   round-trip times give p50 and p99.
//!
//! A KPL sample carries a string value of `size` bytes (the wire message adds a 21-byte header and
//! the JSON quotes), or with [`Payload::Floats`] a list of `size / 8` floats; the bare payload is
//! `size` bytes. Both use the same session configuration
//! (peer mode, no multicast, TCP on 127.0.0.1).
//!
//! The process that measures runs [`run`]; it starts the other one, which runs [`run_peer`], with
//! the `Command` the caller builds (the `kpl` binary starts itself), and reads its report (one JSON
//! line on standard output).

use std::collections::BTreeSet;
use std::io::Read;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use kpl_core::{Value, ValueType};
use kpl_runtime::Sample;
use kpl_runtime::transport::{Remote, RemoteReceiver, RemoteSender, StreamKey};
use kpl_semantic::hir;
use serde::{Deserialize, Serialize};

use crate::config::ZenohOptions;
use crate::session::{HostSession, Sessions};
use crate::transport::{ZenohReceiver, ZenohSender};

mod ros2;

/// What to measure.
#[derive(Debug, Clone)]
pub struct BenchOptions {
    /// Payload sizes in bytes.
    pub sizes: Vec<usize>,
    /// Samples per throughput run of 64-byte payloads; larger payloads send proportionally fewer
    /// (at least an eighth as many), so that each run moves a similar amount of time.
    pub messages: usize,
    /// Round trips per latency run (after `round_trips / 10` warm-up ones).
    pub round_trips: usize,
    /// Runs of each case; figures are medians over them.
    pub repeat: usize,
    /// What a KPL sample carries.
    pub payload: Payload,
}

impl Default for BenchOptions {
    fn default() -> BenchOptions {
        BenchOptions {
            sizes: vec![64, 4096],
            messages: 1_000_000,
            round_trips: 5_000,
            repeat: 3,
            payload: Payload::String,
        }
    }
}

/// The value of a KPL sample of `size` bytes (bare zenoh sends `size` raw bytes either way).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Payload {
    /// A string of `size` bytes: on the wire, the JSON string (`size + 2` bytes).
    #[default]
    String,
    /// A `list<float>` of `size / 8` numbers (what `size` bytes hold in binary); their JSON text
    /// is about twice as long, and each number is printed and parsed.
    Floats,
    /// A `geometry_msgs/msg/PoseStamped` through kpl's ROS 2 path (`kpl bench ros2`; [`ros2`]):
    /// `size` is ignored, bare zenoh sends the message's CDR bytes.
    #[serde(rename = "pose_stamped")]
    PoseStamped,
    /// A `visualization_msgs/msg/MarkerArray` of 100 markers through kpl's ROS 2 path.
    #[serde(rename = "marker_array")]
    MarkerArray,
}

impl Payload {
    /// What bare zenoh sends: `size` bytes, or the CDR message of a ROS 2 payload.
    pub fn bytes(self, size: usize) -> Result<Vec<u8>, BenchError> {
        match ros2::message(self) {
            Some(message) => message.cdr(),
            None => Ok(payload(size)),
        }
    }

    /// The size of what bare zenoh sends (a ROS 2 payload's CDR message), for `kpl bench ros2`'s
    /// sizes.
    pub fn size(self, size: usize) -> Result<usize, BenchError> {
        Ok(self.bytes(size)?.len())
    }

    fn value(self, size: usize) -> Value {
        match self {
            // (a ROS 2 payload goes through `ros2`, never a KPL stream)
            Payload::String | Payload::PoseStamped | Payload::MarkerArray => {
                Value::str(&String::from_utf8_lossy(&payload(size)))
            }
            Payload::Floats => {
                Value::List((0..size / 8).map(|i| Value::Float(i as f64 * 0.37 - 41.3)).collect())
            }
        }
    }

    fn ty(self) -> ValueType {
        match self {
            Payload::String | Payload::PoseStamped | Payload::MarkerArray => ValueType::Str,
            Payload::Floats => ValueType::List(Box::new(ValueType::Float)),
        }
    }
}

/// Which code sends the samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Implementation {
    /// Publisher and subscriber code on zenoh alone, raw bytes.
    Bare,
    /// KPL's transport: typed samples, encoded and decoded.
    Kpl,
}

/// What the other process does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// Receives and counts `count` samples.
    Sub,
    /// Sends every sample back, `count` times.
    Pong,
}

/// The other process's task (passed to it as JSON).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PeerTask {
    pub role: Role,
    pub implementation: Implementation,
    pub payload: Payload,
    pub size: usize,
    pub count: usize,
    /// The port it listens on (127.0.0.1).
    pub port: u16,
}

/// What the other process reports.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct PeerReport {
    pub received: usize,
    /// From the first sample received to the last, microseconds.
    pub elapsed_us: u64,
}

/// One measured case (medians over the repeats).
#[derive(Debug, Clone, Serialize)]
pub struct CaseResult {
    pub size: usize,
    pub implementation: Implementation,
    pub samples_per_s: f64,
    pub round_trip_p50_us: f64,
    pub round_trip_p99_us: f64,
    /// Samples that did not arrive in the throughput runs (should be 0).
    pub lost: usize,
}

/// A ratio over the repeats: its median and range.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Spread {
    pub median: f64,
    pub min: f64,
    pub max: f64,
}

impl Spread {
    fn of(mut values: Vec<f64>) -> Spread {
        values.sort_by(f64::total_cmp);
        Spread {
            median: percentile(&values, 0.5),
            min: values.first().copied().unwrap_or(f64::NAN),
            max: values.last().copied().unwrap_or(f64::NAN),
        }
    }
}

/// KPL against bare zenoh for one size, each ratio taken between the two runs of one repeat
/// (measured one after the other), then summarized over the repeats.
#[derive(Debug, Clone, Serialize)]
pub struct Ratios {
    pub size: usize,
    /// KPL's samples/s as a fraction of bare zenoh's (target: at least 0.7).
    pub throughput: Spread,
    /// KPL's round-trip p50 as a multiple of bare zenoh's (target: at most 1.5).
    pub round_trip_p50: Spread,
    pub round_trip_p99: Spread,
}

/// Everything measured: the figures of each case (medians over the repeats) and the ratios.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    pub payload: Payload,
    pub messages: usize,
    pub round_trips: usize,
    pub repeat: usize,
    pub cases: Vec<CaseResult>,
    pub ratios: Vec<Ratios>,
}

#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error("{0}")]
    Failed(String),
    #[error("the peer process: {0}")]
    Peer(String),
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

fn failed(e: impl std::fmt::Display) -> BenchError {
    BenchError::Failed(e.to_string())
}

const SPEC: &str = "bench";
const IDLE: Duration = Duration::from_secs(10);

fn key(name: &str) -> StreamKey {
    StreamKey { deployment: "bench".into(), spec: SPEC.into(), producer: name.into(), port: None }
}

/// A two-host deploy section: `peer` listens on `port`, `main` dials it.
fn deploy(port: u16) -> hir::Deploy {
    let host = |name: &str, listen: Vec<String>, connect: Vec<String>| hir::Host {
        name: name.into(),
        listen,
        connect,
        processes: Vec::new(),
    };
    let endpoint = format!("tcp/127.0.0.1:{port}");
    hir::Deploy {
        name: None,
        hosts: vec![
            host("peer", vec![endpoint.clone()], Vec::new()),
            host("main", Vec::new(), vec![endpoint]),
        ],
    }
}

async fn open(port: u16, host: &str) -> Result<Arc<HostSession>, BenchError> {
    let options = ZenohOptions { subscriber_wait: IDLE, ..ZenohOptions::default() };
    Sessions::new(options).open(Some(&deploy(port)), Some(host)).await.map_err(failed)
}

fn runtime() -> Result<tokio::runtime::Runtime, BenchError> {
    Ok(tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build()?)
}

fn payload(size: usize) -> Vec<u8> {
    (0..size).map(|i| b'a' + (i % 26) as u8).collect()
}

fn free_port() -> Result<u16, BenchError> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?.local_addr()?.port())
}

/// Measures every case; `peer` makes the command that runs [`run_peer`] with a task given as
/// JSON.
pub fn run(options: &BenchOptions, peer: &dyn Fn(&str) -> Command) -> Result<BenchReport, BenchError> {
    let runtime = runtime()?;
    let repeat = options.repeat.max(1);
    let mut cases = Vec::new();
    let mut ratios = Vec::new();
    for &size in &options.sizes {
        // [bare, kpl]: per repeat, samples/s, round-trip p50 and p99; samples lost.
        let mut rates = [Vec::new(), Vec::new()];
        let mut p50s = [Vec::new(), Vec::new()];
        let mut p99s = [Vec::new(), Vec::new()];
        let mut lost = [0usize; 2];
        for _ in 0..repeat {
            for (k, implementation) in [Implementation::Bare, Implementation::Kpl].into_iter().enumerate() {
                let (rate, missing) = throughput(
                    &runtime,
                    peer,
                    implementation,
                    options.payload,
                    size,
                    messages_for(options.messages, size),
                )?;
                rates[k].push(rate);
                lost[k] += missing;
            }
            for (k, implementation) in [Implementation::Bare, Implementation::Kpl].into_iter().enumerate() {
                let mut round_trips =
                    latency(&runtime, peer, implementation, options.payload, size, options.round_trips)?;
                round_trips.sort_by(f64::total_cmp);
                p50s[k].push(percentile(&round_trips, 0.50));
                p99s[k].push(percentile(&round_trips, 0.99));
            }
        }
        let per_repeat =
            |of: &[Vec<f64>; 2]| -> Vec<f64> { of[1].iter().zip(&of[0]).map(|(k, b)| k / b).collect() };
        ratios.push(Ratios {
            size,
            throughput: Spread::of(per_repeat(&rates)),
            round_trip_p50: Spread::of(per_repeat(&p50s)),
            round_trip_p99: Spread::of(per_repeat(&p99s)),
        });
        for (k, implementation) in [Implementation::Bare, Implementation::Kpl].into_iter().enumerate() {
            cases.push(CaseResult {
                size,
                implementation,
                samples_per_s: median(rates[k].clone()),
                round_trip_p50_us: median(p50s[k].clone()),
                round_trip_p99_us: median(p99s[k].clone()),
                lost: lost[k],
            });
        }
    }
    Ok(BenchReport {
        payload: options.payload,
        messages: options.messages,
        round_trips: options.round_trips,
        repeat,
        cases,
        ratios,
    })
}

/// Samples per throughput run for a payload size.
pub fn messages_for(messages: usize, size: usize) -> usize {
    (messages.saturating_mul(64) / size.max(64)).max(messages / 8).max(2)
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let index = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[index.min(sorted.len() - 1)]
}

fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    percentile(&values, 0.5)
}

/// Starts the peer; returns it with its standard output being read on a thread.
fn start_peer(
    peer: &dyn Fn(&str) -> Command,
    task: &PeerTask,
) -> Result<(std::process::Child, std::thread::JoinHandle<String>), BenchError> {
    let json = serde_json::to_string(task).map_err(failed)?;
    let mut child = peer(&json).stdout(Stdio::piped()).stdin(Stdio::null()).spawn()?;
    let mut stdout = child.stdout.take().ok_or_else(|| BenchError::Peer("no standard output".into()))?;
    let reader = std::thread::spawn(move || {
        let mut out = String::new();
        let _ = stdout.read_to_string(&mut out);
        out
    });
    Ok((child, reader))
}

fn finish_peer(
    mut child: std::process::Child,
    reader: std::thread::JoinHandle<String>,
) -> Result<PeerReport, BenchError> {
    let status = child.wait()?;
    let out = reader.join().map_err(|_| BenchError::Peer("its output could not be read".into()))?;
    if !status.success() {
        return Err(BenchError::Peer(format!("exited with {status}")));
    }
    let line = out.lines().rev().find(|l| l.starts_with('{')).unwrap_or("");
    serde_json::from_str(line).map_err(|e| BenchError::Peer(format!("bad report {line:?}: {e}")))
}

/// Samples/s at the receiving peer, and how many samples did not arrive.
fn throughput(
    runtime: &tokio::runtime::Runtime,
    peer: &dyn Fn(&str) -> Command,
    implementation: Implementation,
    payload_kind: Payload,
    size: usize,
    messages: usize,
) -> Result<(f64, usize), BenchError> {
    let port = free_port()?;
    let task =
        PeerTask { role: Role::Sub, implementation, payload: payload_kind, size, count: messages, port };
    let (child, reader) = start_peer(peer, &task)?;
    let sent = runtime.block_on(async {
        let session = open(port, "main").await?;
        // Producer tokens outlive the session's last samples (see `ZenohSender::token`).
        let mut tokens = Vec::new();
        let stream = key("throughput");
        match (implementation, ros2::message(payload_kind)) {
            (Implementation::Bare, _) => {
                let publisher = session
                    .session
                    .declare_publisher(crate::keys::stream(&stream))
                    .congestion_control(zenoh::qos::CongestionControl::Block)
                    .await
                    .map_err(failed)?;
                wait_for_match(&publisher).await?;
                let bytes = payload_kind.bytes(size)?;
                for _ in 0..messages {
                    publisher.put(bytes.clone()).await.map_err(failed)?;
                }
            }
            (Implementation::Kpl, Some(message)) => {
                let ros2 = crate::ros2::Ros2Session::over(session.session.clone());
                let mut writer = ros2::Writer::declare(&ros2, ros2::THROUGHPUT, &message).await?;
                wait_for_match(writer.publisher()).await?;
                for i in 0..messages {
                    let (valid, value) = message.sample(i);
                    writer.send(valid, &value).await?;
                }
            }
            (Implementation::Kpl, None) => {
                let mut sender =
                    ZenohSender::declare(&session, &stream, "main", BTreeSet::from(["peer".to_string()]))
                        .await
                        .map_err(failed)?;
                if sender.wait_for_subscribers(1).await < 1 {
                    return Err(BenchError::Peer("did not subscribe".into()));
                }
                let value = payload_kind.value(size);
                for i in 0..messages {
                    let t = i as i64;
                    sender.send(&Sample::new(t, t, value.clone())).await;
                }
                sender.end().await;
                tokens.extend(sender.token.take());
            }
        }
        session.session.close().await.map_err(failed)?;
        drop(tokens);
        Ok::<usize, BenchError>(messages)
    })?;
    let report = finish_peer(child, reader)?;
    let seconds = report.elapsed_us.max(1) as f64 / 1e6;
    Ok((report.received.saturating_sub(1) as f64 / seconds, sent.saturating_sub(report.received)))
}

/// Round-trip times in microseconds.
fn latency(
    runtime: &tokio::runtime::Runtime,
    peer: &dyn Fn(&str) -> Command,
    implementation: Implementation,
    payload_kind: Payload,
    size: usize,
    round_trips: usize,
) -> Result<Vec<f64>, BenchError> {
    let warmup = round_trips / 10;
    let port = free_port()?;
    let task = PeerTask {
        role: Role::Pong,
        implementation,
        payload: payload_kind,
        size,
        count: warmup + round_trips,
        port,
    };
    let (child, reader) = start_peer(peer, &task)?;
    let times = runtime.block_on(async {
        let session = open(port, "main").await?;
        let mut tokens = Vec::new();
        let mut times = Vec::with_capacity(round_trips);
        match (implementation, ros2::message(payload_kind)) {
            (Implementation::Bare, _) => {
                let pong = session
                    .session
                    .declare_subscriber(crate::keys::stream(&key("pong")))
                    .await
                    .map_err(failed)?;
                let ping = session
                    .session
                    .declare_publisher(crate::keys::stream(&key("ping")))
                    .congestion_control(zenoh::qos::CongestionControl::Block)
                    .await
                    .map_err(failed)?;
                wait_for_match(&ping).await?;
                let bytes = payload_kind.bytes(size)?;
                for i in 0..warmup + round_trips {
                    let start = Instant::now();
                    ping.put(bytes.clone()).await.map_err(failed)?;
                    let reply = tokio::time::timeout(IDLE, pong.recv_async())
                        .await
                        .map_err(|_| BenchError::Peer("no pong".into()))?
                        .map_err(failed)?;
                    std::hint::black_box(reply.payload().len());
                    if i >= warmup {
                        times.push(start.elapsed().as_secs_f64() * 1e6);
                    }
                }
            }
            (Implementation::Kpl, Some(message)) => {
                let ros2 = crate::ros2::Ros2Session::over(session.session.clone());
                let pong = ros2::Reader::declare(&ros2, ros2::PONG, &message, session.options.queue).await?;
                let mut ping = ros2::Writer::declare(&ros2, ros2::PING, &message).await?;
                wait_for_match(ping.publisher()).await?;
                for i in 0..warmup + round_trips {
                    let (valid, value) = message.sample(i);
                    let start = Instant::now();
                    ping.send(valid, &value).await?;
                    let Some((back, reply)) = pong.recv(IDLE).await? else {
                        return Err(BenchError::Peer("no pong".into()));
                    };
                    if i >= warmup {
                        times.push(start.elapsed().as_secs_f64() * 1e6);
                    }
                    if back != valid || !message.is_sent(&reply) {
                        return Err(BenchError::Failed(format!("pong {i} is not the message sent")));
                    }
                }
            }
            (Implementation::Kpl, None) => {
                let mut pong = ZenohReceiver::declare(&session, &key("pong"), payload_kind.ty(), "main")
                    .await
                    .map_err(failed)?;
                let mut ping = ZenohSender::declare(
                    &session,
                    &key("ping"),
                    "main",
                    BTreeSet::from(["peer".to_string()]),
                )
                .await
                .map_err(failed)?;
                if ping.wait_for_subscribers(1).await < 1 {
                    return Err(BenchError::Peer("did not subscribe".into()));
                }
                let value = payload_kind.value(size);
                for i in 0..warmup + round_trips {
                    let t = i as i64;
                    let start = Instant::now();
                    ping.send(&Sample::new(t, t, value.clone())).await;
                    match tokio::time::timeout(IDLE, pong.recv()).await {
                        Ok(Some(Remote::Sample(sample))) => {
                            std::hint::black_box(sample);
                        }
                        other => return Err(BenchError::Peer(format!("expected a pong, got {other:?}"))),
                    }
                    if i >= warmup {
                        times.push(start.elapsed().as_secs_f64() * 1e6);
                    }
                }
                // As the runtime does: the end of `ping` (which the other side confirms), then
                // the end of `pong`, which this side confirms by receiving it (the other side's
                // `end` waits for that; a receiver dropped before it left that wait to run out).
                ping.end().await;
                let _ = tokio::time::timeout(IDLE, pong.recv()).await;
                drop(pong);
                tokens.extend(ping.token.take());
            }
        }
        session.session.close().await.map_err(failed)?;
        drop(tokens);
        Ok::<Vec<f64>, BenchError>(times)
    })?;
    finish_peer(child, reader)?;
    Ok(times)
}

async fn wait_for_match(publisher: &zenoh::pubsub::Publisher<'_>) -> Result<(), BenchError> {
    let deadline = Instant::now() + IDLE;
    while !publisher.matching_status().await.map_err(failed)?.matching() {
        if Instant::now() > deadline {
            return Err(BenchError::Peer("did not subscribe".into()));
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    Ok(())
}

/// The other process: receives (or sends back) samples as `task` says.
pub fn run_peer(task: &PeerTask) -> Result<PeerReport, BenchError> {
    let runtime = runtime()?;
    runtime.block_on(async {
        let session = open(task.port, "peer").await?;
        let mut tokens = Vec::new();
        let ros2_message = ros2::message(task.payload);
        let ros2 = crate::ros2::Ros2Session::over(session.session.clone());
        let report = match (task.role, task.implementation, &ros2_message) {
            (Role::Sub, Implementation::Kpl, Some(message)) => {
                let reader =
                    ros2::Reader::declare(&ros2, ros2::THROUGHPUT, message, session.options.queue).await?;
                let mut report = PeerReport::default();
                let mut first = None;
                while report.received < task.count {
                    let Some(sample) = reader.recv(IDLE).await? else { break };
                    std::hint::black_box(sample);
                    first.get_or_insert_with(Instant::now);
                    report.received += 1;
                }
                report.elapsed_us = first.map_or(0, |f| f.elapsed().as_micros() as u64);
                report
            }
            (Role::Pong, Implementation::Kpl, Some(message)) => {
                let mut pong = ros2::Writer::declare(&ros2, ros2::PONG, message).await?;
                let ping = ros2::Reader::declare(&ros2, ros2::PING, message, session.options.queue).await?;
                let mut report = PeerReport::default();
                while report.received < task.count {
                    let Some((valid, value)) = ping.recv(IDLE).await? else { break };
                    pong.send(valid, &value).await?;
                    report.received += 1;
                }
                // Let the last pong leave before the session closes.
                tokio::time::sleep(Duration::from_millis(100)).await;
                report
            }
            (Role::Sub, Implementation::Bare, _) => {
                let sub = session
                    .session
                    .declare_subscriber(crate::keys::stream(&key("throughput")))
                    .with(zenoh::handlers::FifoChannel::new(session.options.queue))
                    .await
                    .map_err(failed)?;
                let mut report = PeerReport::default();
                let mut first = None;
                while report.received < task.count {
                    let Ok(Ok(sample)) = tokio::time::timeout(IDLE, sub.recv_async()).await else { break };
                    std::hint::black_box(sample.payload().to_bytes().len());
                    first.get_or_insert_with(Instant::now);
                    report.received += 1;
                }
                report.elapsed_us = first.map_or(0, |f| f.elapsed().as_micros() as u64);
                report
            }
            (Role::Sub, Implementation::Kpl, _) => {
                let mut receiver =
                    ZenohReceiver::declare(&session, &key("throughput"), task.payload.ty(), "peer")
                        .await
                        .map_err(failed)?;
                let mut report = PeerReport::default();
                let mut first = None;
                loop {
                    match tokio::time::timeout(IDLE, receiver.recv()).await {
                        Ok(Some(Remote::Sample(sample))) => {
                            std::hint::black_box(sample);
                            first.get_or_insert_with(Instant::now);
                            report.received += 1;
                            if report.received == task.count {
                                report.elapsed_us = first.map_or(0, |f| f.elapsed().as_micros() as u64);
                            }
                        }
                        Ok(Some(Remote::Malformed { error, .. })) => return Err(BenchError::Failed(error)),
                        _ => break,
                    }
                }
                if report.received < task.count {
                    report.elapsed_us = first.map_or(0, |f| f.elapsed().as_micros() as u64);
                }
                drop(receiver);
                report
            }
            (Role::Pong, Implementation::Bare, _) => {
                let pong = session
                    .session
                    .declare_publisher(crate::keys::stream(&key("pong")))
                    .congestion_control(zenoh::qos::CongestionControl::Block)
                    .await
                    .map_err(failed)?;
                let ping = session
                    .session
                    .declare_subscriber(crate::keys::stream(&key("ping")))
                    .await
                    .map_err(failed)?;
                let mut report = PeerReport::default();
                while report.received < task.count {
                    let Ok(Ok(sample)) = tokio::time::timeout(IDLE, ping.recv_async()).await else { break };
                    pong.put(sample.payload().to_bytes().into_owned()).await.map_err(failed)?;
                    report.received += 1;
                }
                report
            }
            (Role::Pong, Implementation::Kpl, _) => {
                let mut pong = ZenohSender::declare(
                    &session,
                    &key("pong"),
                    "peer",
                    BTreeSet::from(["main".to_string()]),
                )
                .await
                .map_err(failed)?;
                let mut ping = ZenohReceiver::declare(&session, &key("ping"), task.payload.ty(), "peer")
                    .await
                    .map_err(failed)?;
                let mut report = PeerReport::default();
                while let Ok(Some(Remote::Sample(sample))) = tokio::time::timeout(IDLE, ping.recv()).await {
                    pong.send(&sample).await;
                    report.received += 1;
                }
                drop(ping);
                pong.end().await;
                tokens.extend(pong.token.take());
                report
            }
        };
        session.session.close().await.map_err(failed)?;
        drop(tokens);
        Ok(report)
    })
}
