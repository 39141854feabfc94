//! The runtime's [`Transport`] over zenoh: one publisher per stream a host sends to other hosts,
//! one subscriber per stream it receives, samples in the format of [`crate::codec`] on the keys of
//! [`crate::keys`].
//!
//! - **Nothing is lost at start-up.** A publisher waits ([`ZenohSender::wait_for_subscribers`]) until
//!   every consuming host has declared its subscriber (each declares a liveliness token beside it)
//!   and zenoh reports a matching subscriber, up to `KPL_ZENOH_WAIT`; a host subscribes to all the
//!   streams it receives before it waits on its own publishers, so hosts sending to each other do
//!   not wait for each other.
//! - **Nothing is dropped under load.** Publishers use zenoh's `Block` congestion control and
//!   subscribers a bounded queue: a slow consumer slows its producer down.
//! - **The end travels.** When a producer ends, an end-of-stream message follows its last
//!   sample, and the producer waits (up to `KPL_ZENOH_WAIT`) until every consuming host has it
//!   before its process may close the session; a subscriber whose producing host goes away
//!   without one (a crash) ends the stream too, with a warning, instead of waiting forever.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;
use std::time::{Duration, Instant};

use kpl_core::ValueType;
use kpl_runtime::Sample;
use kpl_runtime::process::BoxFuture;
use kpl_runtime::run::TransportFactory;
use kpl_runtime::transport::{Remote, RemoteReceiver, RemoteSender, StreamKey, Transport, TransportError};
use kpl_semantic::hir;
use zenoh::handlers::FifoChannelHandler;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::CongestionControl;
use zenoh::sample::SampleKind;

use crate::codec::{self, Message};
use crate::keys;
use crate::session::{HostSession, Sessions};

/// Opens the [`ZenohTransport`] of a host (what `kpl run --host` uses).
#[derive(Debug, Clone)]
pub struct ZenohFactory {
    sessions: Arc<Sessions>,
}

impl ZenohFactory {
    pub fn new(sessions: Arc<Sessions>) -> ZenohFactory {
        ZenohFactory { sessions }
    }
}

impl TransportFactory for ZenohFactory {
    fn open<'a>(
        &'a self,
        spec: &'a hir::Spec,
        host: &'a str,
    ) -> BoxFuture<'a, Result<Arc<dyn Transport>, TransportError>> {
        Box::pin(async move {
            let session = self.sessions.open(spec.deploy.as_ref(), Some(host)).await?;
            let transport: Arc<dyn Transport> = Arc::new(ZenohTransport::new(session, spec, host));
            Ok(transport)
        })
    }
}

/// A produced stream: `(producer, port)`.
type Stream = (String, Option<String>);

/// Streams between the hosts of one spec, seen from one host.
pub struct ZenohTransport {
    session: Arc<HostSession>,
    host: String,
    /// The declared type of every stream of the spec, to decode values with.
    types: BTreeMap<Stream, ValueType>,
    /// For each stream this host produces, the other hosts that consume it.
    consumers: BTreeMap<Stream, BTreeSet<String>>,
    /// The streams this host receives from other hosts.
    inbound: Vec<Stream>,
    /// Receivers declared ahead of the runtime asking for them, by key.
    declared: tokio::sync::Mutex<Option<BTreeMap<StreamKey, ZenohReceiver>>>,
    /// The producer tokens of this host's publishers, kept until the session closes: zenoh sends
    /// an undeclaration ahead of data still queued, so a token dropped with its publisher could
    /// reach a subscriber before the stream's last samples and end it early.
    tokens: std::sync::Mutex<Vec<LivelinessToken>>,
}

impl std::fmt::Debug for ZenohTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZenohTransport").field("host", &self.host).field("inbound", &self.inbound).finish()
    }
}

impl ZenohTransport {
    pub fn new(session: Arc<HostSession>, spec: &hir::Spec, host: &str) -> ZenohTransport {
        let local: BTreeSet<hir::ProcessId> = spec
            .deploy
            .iter()
            .flat_map(|d| d.hosts.iter().filter(|h| h.name == host).flat_map(|h| h.processes.iter().copied()))
            .collect();
        let mut types = BTreeMap::new();
        for process in &spec.processes {
            if let Some(ty) = &process.output {
                types.insert((process.name.clone(), None), ty.clone());
            }
            for (port, ty) in &process.ports {
                types.insert((process.name.clone(), Some(port.clone())), ty.clone());
            }
        }
        let mut consumers: BTreeMap<Stream, BTreeSet<String>> = BTreeMap::new();
        let mut inbound = BTreeSet::new();
        for consumer in &spec.processes {
            for input in &consumer.inputs {
                let producer = &spec.processes[input.stream.producer];
                let stream = (producer.name.clone(), input.stream.port.clone());
                match (local.contains(&producer.id), local.contains(&consumer.id)) {
                    (true, false) => {
                        let other = spec.host_of(consumer.id).unwrap_or_default().to_string();
                        consumers.entry(stream).or_default().insert(other);
                    }
                    (false, true) => {
                        inbound.insert(stream);
                    }
                    _ => {}
                }
            }
        }
        ZenohTransport {
            session,
            host: host.to_string(),
            types,
            consumers,
            inbound: inbound.into_iter().collect(),
            declared: tokio::sync::Mutex::new(None),
            tokens: std::sync::Mutex::new(Vec::new()),
        }
    }

    fn value_type(&self, key: &StreamKey) -> ValueType {
        self.types.get(&(key.producer.clone(), key.port.clone())).cloned().unwrap_or(ValueType::Any)
    }

    /// Subscribes to every stream this host receives, once, before any publisher waits.
    async fn declare_inbound(&self, spec_name: &str) -> Result<(), TransportError> {
        let mut declared = self.declared.lock().await;
        if declared.is_some() {
            return Ok(());
        }
        let mut receivers = BTreeMap::new();
        for (producer, port) in &self.inbound {
            let key =
                StreamKey { spec: spec_name.to_string(), producer: producer.clone(), port: port.clone() };
            let receiver = self.declare_receiver(&key).await?;
            receivers.insert(key, receiver);
        }
        *declared = Some(receivers);
        Ok(())
    }

    async fn declare_receiver(&self, key: &StreamKey) -> Result<ZenohReceiver, TransportError> {
        ZenohReceiver::declare(&self.session, key, self.value_type(key), &self.host).await
    }
}

impl Transport for ZenohTransport {
    fn publisher<'a>(
        &'a self,
        key: &'a StreamKey,
    ) -> BoxFuture<'a, Result<Box<dyn RemoteSender>, TransportError>> {
        Box::pin(async move {
            self.declare_inbound(&key.spec).await?;
            let hosts =
                self.consumers.get(&(key.producer.clone(), key.port.clone())).cloned().unwrap_or_default();
            let mut sender = ZenohSender::declare(&self.session, key, &self.host, hosts).await?;
            if let Some(token) = sender.token.take()
                && let Ok(mut tokens) = self.tokens.lock()
            {
                tokens.push(token);
            }
            Ok(Box::new(sender) as Box<dyn RemoteSender>)
        })
    }

    fn subscriber<'a>(
        &'a self,
        key: &'a StreamKey,
    ) -> BoxFuture<'a, Result<Box<dyn RemoteReceiver>, TransportError>> {
        Box::pin(async move {
            self.declare_inbound(&key.spec).await?;
            let early = self.declared.lock().await.as_mut().and_then(|d| d.remove(key));
            let receiver = match early {
                Some(receiver) => receiver,
                None => self.declare_receiver(key).await?,
            };
            Ok(Box::new(receiver) as Box<dyn RemoteReceiver>)
        })
    }

    fn close(self: Arc<Self>) -> BoxFuture<'static, ()> {
        Box::pin(async move {
            self.declared.lock().await.take();
            if let Ok(mut tokens) = self.tokens.lock() {
                tokens.clear();
            }
            if let Err(e) = self.session.session.close().await {
                tracing::warn!("closing the zenoh session of {}: {e}", self.session.describe());
            }
        })
    }
}

/// Publishes one stream to the other hosts.
pub struct ZenohSender {
    publisher: Publisher<'static>,
    session: zenoh::Session,
    key: StreamKey,
    key_expr: String,
    /// The hosts that consume this stream (their names).
    consumers: BTreeSet<String>,
    wait: Duration,
    published: u64,
    /// Encoded size of the last sample, to size the next buffer.
    last_len: usize,
    failures: u64,
    /// The producer's liveliness token. Dropping it (with the sender) right after [`end`] can
    /// overtake the end: keep it until the session closes, as [`ZenohTransport`] does.
    ///
    /// [`end`]: RemoteSender::end
    pub token: Option<LivelinessToken>,
}

impl std::fmt::Debug for ZenohSender {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZenohSender")
            .field("key", &self.key_expr)
            .field("published", &self.published)
            .finish()
    }
}

impl ZenohSender {
    /// Declares a publisher on `key` (and the producer's liveliness token).
    pub async fn declare(
        session: &HostSession,
        key: &StreamKey,
        host: &str,
        consumers: BTreeSet<String>,
    ) -> Result<ZenohSender, TransportError> {
        let key_expr = keys::stream(key);
        let error = |what: &str, e: zenoh::Error| TransportError(format!("{what} `{key_expr}`: {e}"));
        let publisher = session
            .session
            .declare_publisher(key_expr.clone())
            .congestion_control(CongestionControl::Block)
            .await
            .map_err(|e| error("cannot publish on", e))?;
        let token = session
            .session
            .liveliness()
            .declare_token(keys::publisher_token(key, host))
            .await
            .map_err(|e| error("cannot declare the publisher token of", e))?;
        Ok(ZenohSender {
            publisher,
            session: session.session.clone(),
            key: key.clone(),
            key_expr,
            consumers,
            wait: session.options.subscriber_wait,
            published: 0,
            last_len: 64,
            failures: 0,
            token: Some(token),
        })
    }

    async fn put(&mut self, bytes: Vec<u8>) -> bool {
        match self.publisher.put(bytes).await {
            Ok(()) => true,
            Err(e) => {
                self.failures += 1;
                if self.failures == 1 {
                    tracing::warn!(stream = %self.key_expr, "cannot publish: {e}");
                }
                false
            }
        }
    }

    /// Waits until every consuming host has received the end of the stream (it then drops its
    /// subscription and token), or until the wait is over. Closing the session earlier would
    /// undeclare this host's tokens ahead of the samples still queued (zenoh sends declarations
    /// before data), and a consumer would take that for the producer going away.
    async fn wait_for_consumers_to_finish(&self) {
        let start = Instant::now();
        let deadline = start + self.wait;
        loop {
            let replies = match self
                .session
                .liveliness()
                .get(keys::subscriber_tokens(&self.key))
                .timeout(Duration::from_secs(2))
                .await
            {
                Ok(replies) => replies,
                Err(e) => {
                    tracing::warn!(stream = %self.key_expr, "cannot see the consuming hosts: {e}");
                    return;
                }
            };
            let mut receiving = BTreeSet::new();
            while let Ok(reply) = replies.recv_async().await {
                if let Ok(token) = reply.result() {
                    receiving.insert(keys::token_host(token.key_expr().as_str()).unwrap_or_default());
                }
            }
            if receiving.is_empty() {
                tracing::debug!(stream = %self.key_expr, waited = ?start.elapsed(), "every consumer has the end");
                return;
            }
            if Instant::now() >= deadline {
                tracing::warn!(
                    "stream `{}`: host(s) {receiving:?} still receiving {:.1} s after the end; closing anyway \
                     (the last samples may not reach them; KPL_ZENOH_WAIT=SECONDS waits longer)",
                    self.key_expr,
                    self.wait.as_secs_f64()
                );
                return;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }

    /// Waits until `n` hosts subscribed (their liveliness tokens) and zenoh matches a
    /// subscriber, or until the wait is over. Returns how many hosts subscribed.
    async fn wait_for(&mut self, n: usize) -> Result<usize, zenoh::Error> {
        let tokens = self
            .session
            .liveliness()
            .declare_subscriber(keys::subscriber_tokens(&self.key))
            .history(true)
            .await?;
        let start = Instant::now();
        let deadline = start + self.wait;
        let mut next_report = start + Duration::from_secs(5);
        let mut hosts = BTreeSet::new();
        loop {
            if hosts.len() >= n && self.publisher.matching_status().await?.matching() {
                tracing::debug!(stream = %self.key_expr, ?hosts, waited = ?start.elapsed(), "subscribers ready");
                return Ok(hosts.len());
            }
            let now = Instant::now();
            if now >= deadline {
                let missing: Vec<&String> = self.consumers.iter().filter(|h| !hosts.contains(*h)).collect();
                tracing::warn!(
                    "stream `{}`: {} of {n} consuming host(s) subscribed within {:.1} s (missing: {missing:?}); \
                     samples published before they subscribe are lost. Start every host of the spec, or wait \
                     longer with KPL_ZENOH_WAIT=SECONDS",
                    self.key_expr,
                    hosts.len(),
                    self.wait.as_secs_f64(),
                );
                return Ok(hosts.len());
            }
            if now >= next_report {
                tracing::info!(stream = %self.key_expr, subscribed = ?hosts, expected = ?self.consumers, "waiting for the consuming hosts");
                next_report = now + Duration::from_secs(5);
            }
            let poll = Duration::from_millis(20).min(deadline - now);
            tokio::select! {
                token = tokens.recv_async() => match token {
                    Ok(token) => {
                        let host = keys::token_host(token.key_expr().as_str()).unwrap_or_default();
                        match token.kind() {
                            SampleKind::Put => hosts.insert(host),
                            SampleKind::Delete => hosts.remove(&host),
                        };
                    }
                    Err(_) => tokio::time::sleep(poll).await,
                },
                () = tokio::time::sleep(poll) => {}
            }
        }
    }
}

impl RemoteSender for ZenohSender {
    fn send<'a>(&'a mut self, sample: &'a Sample) -> BoxFuture<'a, ()> {
        Box::pin(async move {
            let mut bytes = Vec::with_capacity(self.last_len + 16);
            if let Err(e) = codec::encode_sample(sample, &mut bytes) {
                tracing::warn!(stream = %self.key_expr, "{e}");
                return;
            }
            self.last_len = bytes.len();
            if self.put(bytes).await {
                self.published += 1;
            }
        })
    }

    fn end(&mut self) -> BoxFuture<'_, ()> {
        Box::pin(async move {
            let bytes = codec::encode_end(self.published);
            self.put(bytes).await;
            if self.failures > 0 {
                tracing::warn!(stream = %self.key_expr, "{} sample(s) could not be published", self.failures);
            }
            if !self.consumers.is_empty() {
                self.wait_for_consumers_to_finish().await;
            }
        })
    }

    fn wait_for_subscribers(&mut self, n: usize) -> BoxFuture<'_, usize> {
        Box::pin(async move {
            match self.wait_for(n).await {
                Ok(hosts) => hosts,
                Err(e) => {
                    tracing::warn!(stream = %self.key_expr, "cannot wait for subscribers: {e}");
                    0
                }
            }
        })
    }
}

/// Receives one stream from another host.
pub struct ZenohReceiver {
    data: Subscriber<FifoChannelHandler<zenoh::sample::Sample>>,
    /// The producer's liveliness token: `Put` while it is there, `Delete` when it goes away.
    producers: Option<Subscriber<FifoChannelHandler<zenoh::sample::Sample>>>,
    ty: ValueType,
    key_expr: String,
    /// Messages received (for locations of malformed ones) and samples decoded.
    messages: u64,
    samples: u64,
    producer_seen: bool,
    /// The producer's token went away (its host stopped) without an end-of-stream message.
    producer_gone: bool,
    _token: LivelinessToken,
}

impl std::fmt::Debug for ZenohReceiver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZenohReceiver").field("key", &self.key_expr).field("samples", &self.samples).finish()
    }
}

impl ZenohReceiver {
    /// Subscribes to `key`, decoding values with `ty`, and declares this host's subscriber token.
    pub async fn declare(
        session: &HostSession,
        key: &StreamKey,
        ty: ValueType,
        host: &str,
    ) -> Result<ZenohReceiver, TransportError> {
        let key_expr = keys::stream(key);
        let error = |what: &str, e: zenoh::Error| TransportError(format!("{what} `{key_expr}`: {e}"));
        let data = session
            .session
            .declare_subscriber(key_expr.clone())
            .with(zenoh::handlers::FifoChannel::new(session.options.queue))
            .await
            .map_err(|e| error("cannot subscribe to", e))?;
        let producers = session
            .session
            .liveliness()
            .declare_subscriber(keys::publisher_tokens(key))
            .history(true)
            .await
            .map_err(|e| error("cannot watch the producer of", e))?;
        // Declared after the subscriber: a publisher that sees the token finds the subscriber.
        let token = session
            .session
            .liveliness()
            .declare_token(keys::subscriber_token(key, host))
            .await
            .map_err(|e| error("cannot declare the subscriber token of", e))?;
        Ok(ZenohReceiver {
            data,
            producers: Some(producers),
            ty,
            key_expr,
            messages: 0,
            samples: 0,
            producer_seen: false,
            producer_gone: false,
            _token: token,
        })
    }

    fn on_message(&mut self, bytes: &[u8]) -> Remote {
        self.messages += 1;
        match codec::decode(bytes, &self.ty) {
            Ok(Message::Sample(sample)) => {
                self.samples += 1;
                Remote::Sample(sample)
            }
            Ok(Message::End { published }) => {
                if published > self.samples {
                    tracing::warn!(
                        stream = %self.key_expr,
                        "the producer published {published} sample(s), {} arrived",
                        self.samples
                    );
                }
                Remote::End
            }
            Err(e) => Remote::Malformed {
                location: format!("zenoh `{}`, message {}", self.key_expr, self.messages),
                error: e.to_string(),
            },
        }
    }
}

impl RemoteReceiver for ZenohReceiver {
    fn recv(&mut self) -> BoxFuture<'_, Option<Remote>> {
        Box::pin(async move {
            loop {
                // Samples that arrived before the producer went away are delivered first.
                if self.producer_gone && self.data.is_empty() {
                    tracing::warn!(
                        stream = %self.key_expr,
                        "the producing host went away without ending the stream; ending it here"
                    );
                    return Some(Remote::End);
                }
                let producers = async {
                    match &self.producers {
                        Some(p) => p.recv_async().await.ok(),
                        None => std::future::pending().await,
                    }
                };
                let event = tokio::select! {
                    biased;
                    message = self.data.recv_async() => Event::Message(message.ok()),
                    token = producers => Event::Token(token),
                };
                match event {
                    Event::Message(None) => return None,
                    Event::Message(Some(message)) => {
                        let bytes = message.payload().to_bytes();
                        return Some(self.on_message(&bytes));
                    }
                    Event::Token(None) => self.producers = None,
                    Event::Token(Some(token)) => match token.kind() {
                        SampleKind::Put => {
                            self.producer_seen = true;
                            self.producer_gone = false;
                        }
                        SampleKind::Delete => self.producer_gone = self.producer_seen,
                    },
                }
            }
        })
    }
}

enum Event {
    Message(Option<zenoh::sample::Sample>),
    Token(Option<zenoh::sample::Sample>),
}
