//! The hub of a view: the samples of the streams it shows go in (from the `view.live` sink, or
//! from a recording), and the page server and the Foxglove WebSocket server read what they show
//! from it.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard};

use foxglove::{ChannelBuilder, Context, PartialMetadata, RawChannel};
use kpl_core::Time;
use kpl_mcap::foxglove::{Role, ViewId, ViewMessage, ViewSchema, Views, topic_of};
use kpl_mcap::scene::Scene;
use kpl_runtime::Sample;

use crate::timeline::{Timeline, TrackId};

/// A stream of the hub: its place in the timeline and in the Foxglove views.
#[derive(Debug, Clone, Copy)]
pub struct HubStream {
    track: TrackId,
    view: ViewId,
}

/// The last message of each topic (its bytes and log time), for a client that subscribes later.
pub(crate) type Latched = Arc<Mutex<HashMap<String, (Vec<u8>, u64)>>>;

/// The Foxglove side: channels by topic, and the last message of each still topic (the roads,
/// occluders, a fixed camera) for clients that subscribe later.
pub(crate) struct Live {
    pub(crate) context: Arc<Context>,
    channels: HashMap<Arc<str>, Arc<RawChannel>>,
    /// Shared with the server's listener, which sends them to a client that subscribes; never
    /// held while calling into the SDK.
    pub(crate) latched: Latched,
    /// The latest time told to clients, nanoseconds.
    time: u64,
    /// What to tell the server's clients the time is.
    pub(crate) clock: Option<Arc<dyn Fn(u64) + Send + Sync>>,
}

impl std::fmt::Debug for Live {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Live").field("channels", &self.channels.len()).field("time", &self.time).finish()
    }
}

/// What a view shows, shared between the sink that feeds it and the servers that show it.
#[derive(Debug)]
pub struct Hub {
    timeline: Mutex<Timeline>,
    views: Mutex<Views>,
    pub(crate) live: Mutex<Option<Live>>,
}

pub(crate) fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic elsewhere while holding the lock leaves the data as it was: go on with it.
    mutex.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Hub {
    /// A hub for a live run (`live`) or a recording, titled `title`.
    pub fn new(scene: Scene, title: &str, live: bool) -> Arc<Hub> {
        let scene = Arc::new(scene);
        Arc::new(Hub {
            timeline: Mutex::new(Timeline::new(scene.clone(), title, live)),
            views: Mutex::new(Views::new(scene)),
            live: Mutex::new(None),
        })
    }

    pub fn timeline(&self) -> MutexGuard<'_, Timeline> {
        lock(&self.timeline)
    }

    /// Adds a stream to show.
    pub fn add_stream(&self, name: &str, role: Role) -> HubStream {
        let track = self.timeline().add_stream(name, role);
        let view = lock(&self.views).add_stream(name, role);
        HubStream { track, view }
    }

    /// The Foxglove channels of the streams and the scene, made before the first sample so that
    /// a client can subscribe to them before anything is sent.
    pub(crate) fn open_channels(&self, context: Arc<Context>, streams: &[(String, Role)]) -> Live {
        let mut live =
            Live { context, channels: HashMap::new(), latched: Arc::default(), time: 0, clock: None };
        let scene = lock(&self.views).scene().clone();
        let mut topics: Vec<(String, ViewSchema, String)> = Vec::new();
        if !scene.lanes.is_empty() {
            topics.push(("/kpl/roads".into(), ViewSchema::SceneUpdate, "scene".into()));
        }
        if !scene.occluders.is_empty() {
            topics.push(("/kpl/occluders".into(), ViewSchema::SceneUpdate, "scene".into()));
        }
        if scene.camera.is_some() {
            topics.push(("/kpl/camera".into(), ViewSchema::SceneUpdate, "scene".into()));
        }
        topics.push(("/tf".into(), ViewSchema::FrameTransforms, "scene".into()));
        for (name, role) in streams {
            let schema = match role {
                Role::Objects => ViewSchema::SceneUpdate,
                Role::Points => ViewSchema::PointCloud,
                Role::Verdicts => ViewSchema::Log,
                Role::Unknown | Role::Nothing => continue,
            };
            topics.push((topic_of(name), schema, name.clone()));
        }
        for (topic, schema, shows) in topics {
            live.channel(&topic, schema, &shows);
        }
        live
    }

    /// Takes one sample of a stream: into the timeline, and to the Foxglove clients.
    pub fn push(&self, stream: HubStream, sample: &Sample) {
        self.timeline().push(stream.track, sample);
        let mut live = lock(&self.live);
        let Some(live) = live.as_mut() else { return };
        let mut messages = Vec::new();
        lock(&self.views).messages(stream.view, sample, &mut messages);
        for message in &messages {
            live.send(message);
        }
        let now = kpl_mcap::write::mcap_time(sample.valid);
        if now > live.time {
            live.time = now;
            if let Some(clock) = &live.clock {
                clock(now);
            }
        }
    }

    /// The run ended: the page says so.
    pub fn finish(&self) {
        self.timeline().running = false;
    }

    /// The valid time span of what the hub holds.
    pub fn span(&self) -> Option<(Time, Time)> {
        self.timeline().span()
    }
}

impl Live {
    fn channel(&mut self, topic: &str, schema: ViewSchema, shows: &str) -> Option<Arc<RawChannel>> {
        if let Some(channel) = self.channels.get(topic) {
            return Some(channel.clone());
        }
        let channel = ChannelBuilder::new(topic)
            .context(&self.context)
            .message_encoding("protobuf")
            .schema(schema.schema())
            .add_metadata(kpl_mcap::VIEW_KEY, shows)
            .build_raw();
        match channel {
            Ok(channel) => {
                self.channels.insert(topic.into(), channel.clone());
                Some(channel)
            }
            Err(e) => {
                tracing::warn!("view: cannot open the Foxglove channel {topic}: {e}");
                None
            }
        }
    }

    fn send(&mut self, message: &ViewMessage) {
        let shows = if message.stream.is_empty() { "scene" } else { &*message.stream };
        let Some(channel) = self.channel(&message.topic, message.schema, shows) else { return };
        let log_time = kpl_mcap::write::mcap_time(message.log_time);
        if message.stream.is_empty() {
            lock(&self.latched).insert(message.topic.to_string(), (message.data.clone(), log_time));
        }
        channel.log_with_meta(&message.data, PartialMetadata::with_log_time(log_time));
    }
}
