//! `view.live`: the sink that shows its input streams while a run goes, to Foxglove
//! (`foxglove: "127.0.0.1:8765"`) and in a browser (`http: "127.0.0.1:8080"`). Where each server
//! listens is logged when it starts (`kpl run` prints it). `kpl run --view ADDR --foxglove ADDR`
//! adds one over the spec's objects, percepts and monitors.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use kpl_core::Value;
use kpl_mcap::foxglove::Role;
use kpl_mcap::scene::Scene;
use kpl_runtime::process::{Emitter, Input, ProcessError, SyncUnit, Unit};
use kpl_runtime::registry::Registry;
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};

use crate::foxglove_server::FoxgloveServer;
use crate::hub::{Hub, HubStream};
use crate::page::PageServer;

struct Live {
    hub: Arc<Hub>,
    streams: Vec<HubStream>,
    page: Option<PageServer>,
    foxglove: Option<FoxgloveServer>,
    /// Before the first sample: wait this many tenths of a second at most for a Foxglove client
    /// to subscribe to all `channels` of the streams.
    wait_tenths: u64,
    subscribers: Arc<AtomicUsize>,
    channels: usize,
}

impl Unit for Live {
    fn on_input(&mut self, input: &Input<'_>, _out: &mut Emitter) -> Result<(), ProcessError> {
        let Some((port, sample)) = input.trigger_sample() else { return Ok(()) };
        while self.wait_tenths > 0 && self.subscribers.load(Ordering::Relaxed) < self.channels {
            std::thread::sleep(Duration::from_millis(100));
            self.wait_tenths -= 1;
        }
        self.wait_tenths = 0;
        if let Some(stream) = self.streams.get(port) {
            self.hub.push(*stream, sample);
        }
        Ok(())
    }

    fn on_end(&mut self, _out: &mut Emitter) -> Result<(), ProcessError> {
        self.hub.finish();
        if let Some(foxglove) = self.foxglove.take() {
            foxglove.stop();
        }
        if let Some(page) = self.page.take() {
            page.stop();
        }
        Ok(())
    }
}

/// Registers `view.live`.
pub fn register(registry: &mut Registry) {
    registry.add_unit(
        Entry::new(
            EntryKind::Sink,
            "view.live",
            "Shows streams while the run goes: to Foxglove over its WebSocket protocol, and as a page in a browser (docs/view.md).",
        )
        .variadic(1, "in", TypeReq::Any, "streams to show: objects of links, percepts, monitors")
        .param(Param::optional(
            "http",
            ParamType::Str,
            Value::str(""),
            "HOST:PORT of the page (port 0: any free one; empty: no page)",
        ))
        .param(Param::optional(
            "foxglove",
            ParamType::Str,
            Value::str(""),
            "HOST:PORT of the Foxglove WebSocket server (port 0: any free one; empty: none)",
        ))
        .param(Param::optional(
            "wait_for_client",
            ParamType::Duration,
            Value::Duration(0),
            "before the first sample, wait this long at most for a Foxglove client to subscribe",
        )),
        |ctx| {
            let text = |name| ctx.param(name).and_then(Value::as_str).unwrap_or("").to_string();
            let (http, foxglove) = (text("http"), text("foxglove"));
            if http.is_empty() && foxglove.is_empty() {
                return Err(ctx.error("view.live needs `http` (the page) or `foxglove` (the WebSocket server), or both"));
            }
            let scene = Scene::from_spec(ctx.spec, ctx.spec_dir);
            for problem in &scene.problems {
                ctx.stats.warn(format!("the view's scene: {problem}"));
            }
            let title = ctx.out_dir.file_name().map_or_else(String::new, |n| n.to_string_lossy().into_owned());
            let hub = Hub::new(scene, &title, true);
            let roles: Vec<(String, Role)> = ctx
                .process
                .inputs
                .iter()
                .map(|i| (i.stream.name.clone(), Role::of_stream(ctx.spec, &i.stream)))
                .collect();
            let streams = roles.iter().map(|(name, role)| hub.add_stream(name, *role)).collect();
            let subscribers = Arc::new(AtomicUsize::new(0));
            let foxglove = if foxglove.is_empty() {
                None
            } else {
                let server = crate::foxglove_server::serve(&hub, &foxglove, &roles, "kpl", subscribers.clone())
                    .map_err(|e| ctx.error(e))?;
                tracing::info!("view: Foxglove WebSocket server at {}", server.url);
                Some(server)
            };
            let page = if http.is_empty() {
                None
            } else {
                let server = crate::page::serve(&hub, &http).map_err(|e| ctx.error(e))?;
                tracing::info!("view: the page at {}", server.url);
                Some(server)
            };
            let wait = match ctx.param("wait_for_client") {
                Some(Value::Duration(us)) => *us,
                _ => 0,
            };
            let wait_tenths = if foxglove.is_some() { u64::try_from(wait / 100_000).unwrap_or(0) } else { 0 };
            let channels = roles.iter().filter(|(_, role)| matches!(role, Role::Objects | Role::Points | Role::Verdicts)).count();
            Ok(Box::new(SyncUnit(Live { hub, streams, page, foxglove, wait_tenths, subscribers, channels })))
        },
    );
}
