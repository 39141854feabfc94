//! The live Foxglove WebSocket server of a view: Foxglove's own SDK (the `foxglove` crate)
//! serves the hub's channels (Foxglove's schemas, [`kpl_mcap::foxglove`]) with the run's clock
//! as the server's time. A client that subscribes to a still topic (roads, occluders, a fixed
//! camera) is sent its last message at once.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use foxglove::websocket::{Capability, ChannelView, Client, ServerListener};
use foxglove::{Context, PartialMetadata, WebSocketServer, WebSocketServerHandle};
use kpl_mcap::foxglove::Role;

use crate::hub::{Hub, Latched, lock};

/// Messages a client is sent when it subscribes to a still topic.
struct Latch {
    context: Arc<Context>,
    latched: Latched,
    /// Subscriptions to the streams' channels (not the scene's), for `wait_for_client`.
    subscribers: Arc<AtomicUsize>,
}

impl ServerListener for Latch {
    fn on_subscribe(&self, client: Client, channel: ChannelView) {
        if channel.topic().starts_with("/kpl/") && !SCENE_TOPICS.contains(&channel.topic()) {
            self.subscribers.fetch_add(1, Ordering::Relaxed);
        }
        let Some((data, log_time)) = lock(&self.latched).get(channel.topic()).cloned() else { return };
        if let Some(raw) = self.context.get_channel_by_topic(channel.topic()) {
            raw.log_with_meta_to_sink(&data, PartialMetadata::with_log_time(log_time), client.sink_id());
        }
    }
}

/// The topics of the scene (not of a stream).
const SCENE_TOPICS: [&str; 3] = ["/kpl/roads", "/kpl/occluders", "/kpl/camera"];

/// A running Foxglove WebSocket server.
#[derive(Debug)]
pub struct FoxgloveServer {
    hub: Arc<Hub>,
    handle: Option<Arc<WebSocketServerHandle>>,
    /// `ws://HOST:PORT`.
    pub url: String,
}

/// How many messages a client may lag behind before the oldest are dropped (per client).
const BACKLOG: usize = 4096;

/// How long a server that stops keeps serving its connected clients first: the SDK drops what
/// is still queued for a client when it stops and says nothing of how much that is, so a client
/// that keeps up gets the run's last messages only if the queue has this long to drain.
const LINGER: Duration = Duration::from_secs(2);

/// Serves the hub's streams (`streams`: name and role) to Foxglove at `addr` (`HOST:PORT`, port 0
/// for any free one).
/// `subscribers` counts the subscriptions to the streams' channels.
pub fn serve(
    hub: &Arc<Hub>,
    addr: &str,
    streams: &[(String, Role)],
    name: &str,
    subscribers: Arc<AtomicUsize>,
) -> Result<FoxgloveServer, String> {
    let (host, port) = crate::split_addr(addr)?;
    let context = Context::new();
    let mut live = hub.open_channels(context.clone(), streams);
    let listener = Arc::new(Latch { context: context.clone(), latched: live.latched.clone(), subscribers });
    let server = WebSocketServer::new()
        .name(name)
        .context(&context)
        .bind(host.clone(), port)
        .capabilities([Capability::Time])
        .listener(listener)
        .message_backlog_size(BACKLOG);
    // Started on a thread of its own: the SDK runs it on its own tokio runtime, never on the one
    // that drives the run (a simulated run's clock is paused).
    let handle = std::thread::spawn(move || server.start_blocking())
        .join()
        .map_err(|_| "the Foxglove server's thread failed".to_string())?
        .map_err(|e| format!("cannot serve Foxglove at {addr}: {e}"))?;
    let handle = Arc::new(handle);
    let url = format!("ws://{host}:{}", handle.port());
    let clock = handle.clone();
    live.clock = Some(Arc::new(move |ns| clock.broadcast_time(ns)));
    *lock(&hub.live) = Some(live);
    Ok(FoxgloveServer { hub: hub.clone(), handle: Some(handle), url })
}

impl FoxgloveServer {
    /// Stops serving: connected clients are served for up to [`LINGER`] more (until they all
    /// disconnect), then disconnected.
    pub fn stop(mut self) {
        if let Some(handle) = &self.handle {
            let step = Duration::from_millis(50);
            let mut left = LINGER.as_millis() / step.as_millis();
            while handle.client_count() > 0 && left > 0 {
                std::thread::sleep(step);
                left -= 1;
            }
        }
        self.shutdown();
    }

    fn shutdown(&mut self) {
        let Some(handle) = self.handle.take() else { return };
        // The hub's clock holds the other reference to the handle: let it go first.
        drop(lock(&self.hub.live).take());
        let stop = move || {
            if let Ok(handle) = Arc::try_unwrap(handle) {
                handle.stop().wait_blocking();
            }
        };
        // Off the caller's thread: the SDK waits on its own runtime, which may not be entered
        // from a thread that drives another.
        let _ = std::thread::spawn(stop).join();
    }
}

impl Drop for FoxgloveServer {
    fn drop(&mut self) {
        self.shutdown();
    }
}
