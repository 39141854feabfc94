//! What serving costs (docs/performance.md, "Seeing a run"): 1,000 objects at 10 Hz pushed into a
//! view's hub and served by its Foxglove WebSocket server to two clients (Foxglove's protocol
//! client, `tests/node/foxglove_client.mjs`), against a baseline in the same run that makes the
//! same samples and serves nothing. Reports the CPU time per second of the process (one core =
//! 100 %) and the latency from a sample entering the hub to its scene update arriving at a client.
//!
//!     cargo test --release -p kpl-view --test serve_load -- --ignored --nocapture
//!
//! A measurement, not a test: it asserts only that every client got every frame. Needs Node with
//! tests/node's packages (scripts/test installs them).
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::print_stderr, clippy::disallowed_methods)] // a benchmark harness: it times what it serves

use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant, SystemTime};

use kpl_core::{Record, Value};
use kpl_mcap::foxglove::Role;
use kpl_mcap::scene::Scene;
use kpl_runtime::Sample;
use kpl_view::hub::Hub;

const OBJECTS: usize = 1000;
const HZ: u64 = 10;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// CPU time of this process so far (user + system), from /proc/self/stat.
fn cpu() -> Duration {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap();
    let fields: Vec<&str> = stat.rsplit_once(')').unwrap().1.split_whitespace().collect();
    let ticks: u64 = fields[11].parse::<u64>().unwrap() + fields[12].parse::<u64>().unwrap();
    Duration::from_millis(ticks * 10) // USER_HZ is 100 on Linux
}

fn now_us() -> i64 {
    SystemTime::now().duration_since(SystemTime::UNIX_EPOCH).unwrap().as_micros() as i64
}

/// Frame `i` of the workload: objects driving along parallel lines.
fn frame(i: u64) -> Value {
    let t = i as f64 / HZ as f64;
    let objects: Vec<Value> = (0..OBJECTS)
        .map(|k| {
            Value::Record(Arc::new(Record {
                id: Some(format!("co{k}").into()),
                fields: vec![
                    ("pos".into(), Value::Vec2([(k % 50) as f64 * 40.0 + 20.0 * t, (k / 50) as f64 * 10.0])),
                    ("vel".into(), Value::Vec2([20.0, 0.0])),
                    ("size".into(), Value::Float(4.5)),
                    ("measured".into(), Value::Bool(k % 7 != 0)),
                ],
            }))
        })
        .collect();
    Value::List(objects.into())
}

/// Makes `frames` frames at 10 Hz in real time, pushing each into `hub` when given; the CPU time
/// it took and the wall time.
fn drive(frames: u64, hub: Option<(&Hub, kpl_view::hub::HubStream)>) -> (Duration, Duration) {
    let (cpu0, wall0) = (cpu(), Instant::now());
    let period = Duration::from_millis(1000 / HZ);
    for i in 0..frames {
        let value = frame(i);
        let t = now_us();
        if let Some((hub, stream)) = hub {
            hub.push(stream, &Sample::new(t, t, value));
        } else {
            std::hint::black_box(&value);
        }
        let next = wall0 + period * (i as u32 + 1);
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    (cpu() - cpu0, wall0.elapsed())
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

#[test]
#[ignore = "a measurement for docs/performance.md: cargo test --release -p kpl-view --test serve_load -- --ignored --nocapture"]
fn serving_1000_objects_at_10_hz_to_two_clients() {
    let seconds: u64 = std::env::var("KPL_VIEW_SECONDS").ok().and_then(|s| s.parse().ok()).unwrap_or(20);
    let frames = seconds * HZ;
    // Baseline: the same samples, made and dropped.
    let (base_cpu, base_wall) = drive(frames / 2, None);

    let hub = Hub::new(Scene::default(), "load", true);
    let stream = hub.add_stream("cars", Role::Objects);
    let subscribers = Arc::new(AtomicUsize::new(0));
    let server = kpl_view::foxglove_server::serve(
        &hub,
        "127.0.0.1:0",
        &[("cars".to_string(), Role::Objects)],
        "load",
        subscribers.clone(),
    )
    .unwrap();
    let dir = std::env::temp_dir().join(format!("kpl-serve-load-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let clients: Vec<(Child, PathBuf)> = (0..2)
        .map(|i| {
            let out = dir.join(format!("client{i}.jsonl"));
            let child = Command::new("node")
                .arg(root().join("tests/node/foxglove_client.mjs"))
                .args([server.url.as_str(), out.to_str().unwrap(), &(seconds + 30).to_string()])
                .spawn()
                .unwrap();
            (child, out)
        })
        .collect();
    for _ in 0..300 {
        if subscribers.load(Ordering::Relaxed) >= 2 {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(subscribers.load(Ordering::Relaxed) >= 2, "both clients subscribed");
    let (serve_cpu, serve_wall) = drive(frames, Some((&hub, stream)));
    std::thread::sleep(Duration::from_secs(1));
    server.stop();

    let base = base_cpu.as_secs_f64() / base_wall.as_secs_f64();
    let serve = serve_cpu.as_secs_f64() / serve_wall.as_secs_f64();
    let mut latencies = Vec::new();
    for (mut child, out) in clients {
        assert!(child.wait().unwrap().success());
        let text = std::fs::read_to_string(&out).unwrap();
        let mut received = 0;
        for line in text.lines() {
            let m: serde_json::Value = serde_json::from_str(line).unwrap();
            if m["topic"] != "/kpl/cars" {
                continue;
            }
            received += 1;
            let sent_us = m["log_time"].as_str().unwrap().parse::<i64>().unwrap() / 1000;
            latencies.push((m["arrived"].as_i64().unwrap() - sent_us) as f64 / 1000.0);
        }
        assert_eq!(received, frames, "{}: every frame", out.display());
    }
    latencies.sort_by(f64::total_cmp);
    eprintln!(
        "{OBJECTS} objects at {HZ} Hz for {seconds} s to 2 clients: {:.1} % of one core serving \
         ({:.1} % with the workload, {:.1} % for the workload alone); latency hub -> client \
         p50 {:.1} ms, p95 {:.1} ms, max {:.1} ms ({} frames)",
        (serve - base) * 100.0,
        serve * 100.0,
        base * 100.0,
        percentile(&latencies, 0.5),
        percentile(&latencies, 0.95),
        latencies.last().copied().unwrap_or(0.0),
        latencies.len(),
    );
    let _ = std::fs::remove_dir_all(&dir);
}
