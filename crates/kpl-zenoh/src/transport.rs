//! The runtime's [`Transport`] over zenoh: one publisher per stream a host sends to other hosts,
//! one subscriber per stream it receives, samples in the format of [`crate::codec`] on the keys of
//! [`crate::keys`], each with its [`crate::envelope`] (producing host, run, sequence number, and
//! with keys an authentication tag).
//!
//! - **Hosts come and go.** Each host declares a liveliness token and watches the others' (up,
//!   gone, back: logged, and counted in the report). A stream does not end when its producing host
//!   goes away (a crash, a freeze past zenoh's lease, a lost link): its receiver waits up to
//!   `KPL_ZENOH_GIVE_UP` for the host to come back, and the stream resumes, in either direction,
//!   when it does; only then does the receiver give up and end the input as cut short. Sequence
//!   numbers say how many samples were lost meanwhile.
//! - **Start-up waits run at once.** [`Transport::start`] waits for the hosts consuming every
//!   stream this host sends, all streams together, saying every five seconds who is missing.
//! - **The end is durable.** A producer that finishes answers queries for its stream's end and
//!   waits (up to `KPL_ZENOH_WAIT`) until every consuming host confirms it has the end, so a host
//!   that subscribes late, or was away when the end went out, still ends its input.
//! - **Strangers are refused and counted.** A receiver accepts a message only from the host the
//!   spec places the producer on, with a valid tag when the deployment has keys, and with a
//!   sequence number that moves forward; everything else is refused and counted.
//! - **Nothing is dropped under load.** Publishers use zenoh's `Block` congestion control and
//!   subscribers a bounded queue: a slow consumer slows its producer down.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use kpl_core::ValueType;
use kpl_runtime::Sample;
use kpl_runtime::process::BoxFuture;
use kpl_runtime::run::{RunConfig, TransportFactory};
use kpl_runtime::stats::Malformed;
use kpl_runtime::transport::{
    HostReport, InboundEnding, InboundReport, OutboundReport, Remote, RemoteReceiver, RemoteSender,
    StreamKey, Transport, TransportError, TransportReport,
};
use kpl_semantic::hir;
use zenoh::Wait;
use zenoh::handlers::FifoChannelHandler;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::CongestionControl;
use zenoh::query::{Queryable, Reply};
use zenoh::sample::SampleKind;

use crate::codec::{self, Message};
use crate::credentials::Secret;
use crate::envelope::{Envelope, Refusal, Sequence};
use crate::keys;
use crate::session::{HostSession, Sessions};

/// How often a start-up wait says who it is still waiting for (after a first report at 1 s).
const REPORT_EVERY: Duration = Duration::from_secs(5);

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
        config: &'a RunConfig,
    ) -> BoxFuture<'a, Result<Arc<dyn Transport>, TransportError>> {
        Box::pin(async move {
            let host = config
                .host
                .as_deref()
                .ok_or_else(|| TransportError("streams between hosts need a host (--host)".into()))?;
            let plan = Plan::new(spec, host, &config.deployment(spec), &config.spec_name);
            let keys = self.sessions.options()?.keys.is_some();
            let access_control = keys.then(|| plan.access_control());
            let session = self.sessions.open_with(spec.deploy.as_ref(), Some(host), access_control).await?;
            let transport: Arc<dyn Transport> = Arc::new(ZenohTransport::new(session, plan).await?);
            Ok(transport)
        })
    }
}

/// A produced stream: `(producer, port)`.
type Stream = (String, Option<String>);

/// The streams between one host and the others, from the spec.
#[derive(Debug, Clone)]
pub struct Plan {
    pub deployment: String,
    pub spec_name: String,
    pub host: String,
    /// Every host of the deploy section, this one included.
    pub hosts: Vec<String>,
    /// The declared type of every stream of the spec, to decode values with.
    types: BTreeMap<Stream, ValueType>,
    /// For each stream this host produces, the other hosts that consume it.
    outbound: BTreeMap<Stream, BTreeSet<String>>,
    /// For each stream this host receives from another host, that host.
    inbound: BTreeMap<Stream, String>,
}

impl Plan {
    pub fn new(spec: &hir::Spec, host: &str, deployment: &str, spec_name: &str) -> Plan {
        let mut types = BTreeMap::new();
        for process in &spec.processes {
            if let Some(ty) = &process.output {
                types.insert((process.name.clone(), None), ty.clone());
            }
            for (port, ty) in &process.ports {
                types.insert((process.name.clone(), Some(port.clone())), ty.clone());
            }
        }
        let mut outbound: BTreeMap<Stream, BTreeSet<String>> = BTreeMap::new();
        let mut inbound = BTreeMap::new();
        for consumer in &spec.processes {
            let consumer_host = spec.host_of(consumer.id).unwrap_or_default();
            for input in &consumer.inputs {
                let producer = &spec.processes[input.stream.producer];
                let producer_host = spec.host_of(producer.id).unwrap_or_default();
                let stream = (producer.name.clone(), input.stream.port.clone());
                if producer_host == host && consumer_host != host {
                    outbound.entry(stream).or_default().insert(consumer_host.to_string());
                } else if consumer_host == host && producer_host != host {
                    inbound.insert(stream, producer_host.to_string());
                }
            }
        }
        Plan {
            deployment: deployment.to_string(),
            spec_name: spec_name.to_string(),
            host: host.to_string(),
            hosts: spec.deploy.iter().flat_map(|d| d.hosts.iter().map(|h| h.name.clone())).collect(),
            types,
            outbound,
            inbound,
        }
    }

    fn key(&self, (producer, port): &Stream) -> StreamKey {
        StreamKey {
            deployment: self.deployment.clone(),
            spec: self.spec_name.clone(),
            producer: producer.clone(),
            port: port.clone(),
        }
    }

    fn value_type(&self, key: &StreamKey) -> ValueType {
        self.types.get(&(key.producer.clone(), key.port.clone())).cloned().unwrap_or(ValueType::Any)
    }

    /// zenoh's access control for this host in a deployment with keys: a stream's data, its
    /// producer's token and its end are accepted from no host of the deployment but the one the
    /// spec places its producer on (hosts are told apart by the common names of their
    /// certificates). Links without a certificate are left to the envelopes' tags, which refuse
    /// and count what does not come from the deployment.
    pub fn access_control(&self) -> serde_json::Value {
        let subject = |host: &str| format!("kpl-host-{host}");
        let subjects: Vec<serde_json::Value> = self
            .hosts
            .iter()
            .filter(|h| **h != self.host)
            .map(|h| serde_json::json!({ "id": subject(h), "cert_common_names": [h] }))
            .collect();
        let mut rules = Vec::new();
        let mut policies = Vec::new();
        for (i, (stream, producer_host)) in self.inbound.iter().enumerate() {
            let others: Vec<String> = self
                .hosts
                .iter()
                .filter(|h| *h != producer_host && **h != self.host)
                .map(|h| subject(h))
                .collect();
            if others.is_empty() {
                continue;
            }
            let key = self.key(stream);
            let ids = [format!("kpl-{i}-data"), format!("kpl-{i}-token"), format!("kpl-{i}-end")];
            rules.push(serde_json::json!({
                "id": ids[0], "permission": "deny", "flows": ["ingress"],
                "messages": ["put", "delete"], "key_exprs": [keys::stream(&key)],
            }));
            rules.push(serde_json::json!({
                "id": ids[1], "permission": "deny", "flows": ["ingress"],
                "messages": ["liveliness_token"], "key_exprs": [keys::publisher_tokens(&key)],
            }));
            rules.push(serde_json::json!({
                "id": ids[2], "permission": "deny", "flows": ["ingress"],
                "messages": ["reply"], "key_exprs": [keys::end(&key)],
            }));
            policies.push(serde_json::json!({ "rules": ids, "subjects": others }));
        }
        serde_json::json!({
            "enabled": !policies.is_empty(),
            "default_permission": "allow",
            "rules": rules,
            "subjects": subjects,
            "policies": policies,
        })
    }
}

/// Streams between the hosts of one spec, seen from one host.
pub struct ZenohTransport {
    session: Arc<HostSession>,
    plan: Plan,
    /// Receivers declared ahead of the runtime asking for them, by key.
    declared: tokio::sync::Mutex<Option<BTreeMap<StreamKey, ZenohReceiver>>>,
    /// Tokens kept until the session closes: this host's own, the ends it confirmed, and its
    /// publishers' (zenoh sends an undeclaration ahead of data still queued).
    tokens: Arc<Mutex<Vec<LivelinessToken>>>,
    hosts: Arc<HostWatch>,
    outbound: Mutex<Vec<Arc<Outbound>>>,
    inbound: Mutex<Vec<Arc<Mutex<InboundReport>>>>,
    _host_watch: Subscriber<()>,
}

impl std::fmt::Debug for ZenohTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZenohTransport").field("host", &self.plan.host).finish()
    }
}

impl ZenohTransport {
    /// Declares this host's liveliness token and starts watching the other hosts'.
    pub async fn new(session: Arc<HostSession>, plan: Plan) -> Result<ZenohTransport, TransportError> {
        let error = |what: &str, e: zenoh::Error| TransportError(format!("{what}: {e}"));
        let hosts = Arc::new(HostWatch::new(&plan, session.options.give_up));
        let watch = hosts.clone();
        let host_watch = session
            .session
            .liveliness()
            .declare_subscriber(keys::host_tokens(&plan.deployment, &plan.spec_name))
            .history(true)
            .callback(move |token| watch.on_token(&token))
            .await
            .map_err(|e| error("cannot watch the other hosts", e))?;
        let token = session
            .session
            .liveliness()
            .declare_token(keys::host_token(&plan.deployment, &plan.spec_name, &plan.host))
            .await
            .map_err(|e| error("cannot declare this host's token", e))?;
        Ok(ZenohTransport {
            session,
            plan,
            declared: tokio::sync::Mutex::new(None),
            tokens: Arc::new(Mutex::new(vec![token])),
            hosts,
            outbound: Mutex::new(Vec::new()),
            inbound: Mutex::new(Vec::new()),
            _host_watch: host_watch,
        })
    }

    /// Subscribes to every stream this host receives, once, before any publisher waits.
    async fn declare_inbound(&self) -> Result<(), TransportError> {
        let mut declared = self.declared.lock().await;
        if declared.is_some() {
            return Ok(());
        }
        let mut receivers = BTreeMap::new();
        for (stream, producer_host) in &self.plan.inbound {
            let key = self.plan.key(stream);
            let report = Arc::new(Mutex::new(InboundReport {
                stream: key.stream_name(),
                from: producer_host.clone(),
                ..InboundReport::default()
            }));
            if let Ok(mut inbound) = self.inbound.lock() {
                inbound.push(report.clone());
            }
            let receiver = ZenohReceiver::declare_with(
                &self.session,
                &key,
                self.plan.value_type(&key),
                &self.plan.host,
                Some(producer_host.clone()),
                report,
                self.tokens.clone(),
            )
            .await?;
            receivers.insert(key, receiver);
        }
        *declared = Some(receivers);
        Ok(())
    }

    /// Who is still missing: for each consuming host not subscribed yet, the streams it lacks.
    fn missing(&self) -> BTreeMap<String, Vec<String>> {
        let mut missing: BTreeMap<String, Vec<String>> = BTreeMap::new();
        for outbound in self.outbound.lock().map(|o| o.clone()).unwrap_or_default() {
            for host in outbound.absent() {
                missing.entry(host).or_default().push(outbound.key.stream_name());
            }
        }
        missing
    }
}

fn describe_missing(missing: &BTreeMap<String, Vec<String>>) -> String {
    missing
        .iter()
        .map(|(host, streams)| format!("`{host}` ({})", streams.join(", ")))
        .collect::<Vec<_>>()
        .join(", ")
}

impl Transport for ZenohTransport {
    fn publisher<'a>(
        &'a self,
        key: &'a StreamKey,
    ) -> BoxFuture<'a, Result<Box<dyn RemoteSender>, TransportError>> {
        Box::pin(async move {
            self.declare_inbound().await?;
            let hosts = self
                .plan
                .outbound
                .get(&(key.producer.clone(), key.port.clone()))
                .cloned()
                .unwrap_or_default();
            let mut sender = ZenohSender::declare(&self.session, key, &self.plan.host, hosts).await?;
            if let Some(token) = sender.token.take()
                && let Ok(mut tokens) = self.tokens.lock()
            {
                tokens.push(token);
            }
            if let Ok(mut outbound) = self.outbound.lock() {
                outbound.push(sender.state.clone());
            }
            Ok(Box::new(sender) as Box<dyn RemoteSender>)
        })
    }

    fn subscriber<'a>(
        &'a self,
        key: &'a StreamKey,
    ) -> BoxFuture<'a, Result<Box<dyn RemoteReceiver>, TransportError>> {
        Box::pin(async move {
            self.declare_inbound().await?;
            let early = self.declared.lock().await.as_mut().and_then(|d| d.remove(key));
            // Every stream this host receives was declared, with its producing host, up front.
            let receiver = early.ok_or_else(|| {
                TransportError(format!(
                    "host `{}` receives no stream `{}` from another host in deployment `{}`",
                    self.plan.host,
                    key.stream_name(),
                    self.plan.deployment
                ))
            })?;
            Ok(Box::new(receiver) as Box<dyn RemoteReceiver>)
        })
    }

    fn start(&self) -> BoxFuture<'_, ()> {
        Box::pin(async move {
            let wait = self.session.options.subscriber_wait;
            let start = Instant::now();
            // The first report comes soon, so that a host that waits says so.
            let mut next_report = start + Duration::from_secs(1);
            loop {
                let missing = self.missing();
                if missing.is_empty() {
                    tracing::debug!(waited = ?start.elapsed(), "every consuming host subscribed");
                    return;
                }
                let now = Instant::now();
                if now >= start + wait {
                    tracing::warn!(
                        "host `{}`: went on after {:.0} s without host(s) {} (KPL_ZENOH_WAIT); what they miss is counted, \
                         and they get the streams from when they subscribe",
                        self.plan.host,
                        wait.as_secs_f64(),
                        describe_missing(&missing)
                    );
                    return;
                }
                if now >= next_report {
                    tracing::info!(
                        "host `{}`: waiting for host(s) {}: {:.0} s of {:.0} s",
                        self.plan.host,
                        describe_missing(&missing),
                        (now - start).as_secs_f64(),
                        wait.as_secs_f64()
                    );
                    next_report = now + REPORT_EVERY;
                }
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        })
    }

    fn report(&self) -> TransportReport {
        let snapshot = |list: &Mutex<Vec<Arc<Mutex<InboundReport>>>>| -> Vec<InboundReport> {
            list.lock()
                .map(|l| l.iter().filter_map(|r| r.lock().ok().map(|r| r.clone())).collect())
                .unwrap_or_default()
        };
        let outbound = self
            .outbound
            .lock()
            .map(|o| o.iter().filter_map(|s| s.report.lock().ok().map(|r| r.clone())).collect())
            .unwrap_or_default();
        TransportReport {
            deployment: self.plan.deployment.clone(),
            host: self.plan.host.clone(),
            hosts: self.hosts.report(),
            inbound: snapshot(&self.inbound),
            outbound,
        }
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

/// The other hosts of a deployment, from their liveliness tokens.
struct HostWatch {
    this: String,
    give_up: Duration,
    start: Instant,
    hosts: Mutex<BTreeMap<String, HostState>>,
}

#[derive(Debug, Default)]
struct HostState {
    first_seen: Option<Instant>,
    up: bool,
    lost: u64,
    returned: u64,
    away_since: Option<Instant>,
    away: Duration,
}

impl HostWatch {
    fn new(plan: &Plan, give_up: Duration) -> HostWatch {
        let hosts = plan
            .hosts
            .iter()
            .filter(|h| **h != plan.host)
            .map(|h| (h.clone(), HostState::default()))
            .collect();
        HostWatch { this: plan.host.clone(), give_up, start: Instant::now(), hosts: Mutex::new(hosts) }
    }

    fn on_token(&self, token: &zenoh::sample::Sample) {
        let Some(host) = keys::token_host(token.key_expr().as_str()) else { return };
        let Ok(mut hosts) = self.hosts.lock() else { return };
        let Some(state) = hosts.get_mut(&host) else { return };
        let now = Instant::now();
        match token.kind() {
            SampleKind::Put if !state.up => {
                state.up = true;
                match state.away_since.take() {
                    Some(since) => {
                        state.returned += 1;
                        state.away += now - since;
                        tracing::warn!(
                            "host `{}`: host `{host}` is back after {:.1} s",
                            self.this,
                            (now - since).as_secs_f64()
                        );
                    }
                    None => {
                        state.first_seen = Some(now);
                        tracing::info!("host `{}`: host `{host}` is up", self.this);
                    }
                }
            }
            SampleKind::Delete if state.up => {
                state.up = false;
                state.lost += 1;
                state.away_since = Some(now);
                tracing::warn!(
                    "host `{}`: host `{host}` went away; its streams wait up to {:.0} s for it (KPL_ZENOH_GIVE_UP)",
                    self.this,
                    self.give_up.as_secs_f64()
                );
            }
            _ => {}
        }
    }

    fn report(&self) -> Vec<HostReport> {
        let now = Instant::now();
        let Ok(hosts) = self.hosts.lock() else { return Vec::new() };
        hosts
            .iter()
            .map(|(host, s)| HostReport {
                host: host.clone(),
                first_seen_s: s.first_seen.map(|t| (t - self.start).as_secs_f64()),
                lost: s.lost,
                returned: s.returned,
                away_s: (s.away + s.away_since.map_or(Duration::ZERO, |since| now - since)).as_secs_f64(),
                up_at_end: s.up,
            })
            .collect()
    }
}

/// What a stream's publisher shares with the transport and zenoh's callbacks.
struct Outbound {
    key: StreamKey,
    consumers: BTreeSet<String>,
    /// The consuming hosts subscribed now.
    present: Mutex<BTreeSet<String>>,
    /// The consuming hosts that subscribed at some point of this run.
    seen: Mutex<BTreeSet<String>>,
    /// The consuming hosts that confirmed they have the end.
    done: Mutex<BTreeSet<String>>,
    /// The end, once the stream finished: what the end queryable answers.
    ended: Mutex<Option<(Vec<u8>, Vec<u8>)>>,
    report: Mutex<OutboundReport>,
}

impl Outbound {
    fn absent(&self) -> Vec<String> {
        let present = self.present.lock().map(|p| p.clone()).unwrap_or_default();
        self.consumers.iter().filter(|h| !present.contains(*h)).cloned().collect()
    }

    fn on_subscriber_token(&self, token: &zenoh::sample::Sample) {
        let Some(host) = keys::token_host(token.key_expr().as_str()) else { return };
        if token.kind() == SampleKind::Put
            && let Ok(mut seen) = self.seen.lock()
        {
            seen.insert(host.clone());
        }
        if let Ok(mut present) = self.present.lock() {
            match token.kind() {
                SampleKind::Put => present.insert(host),
                SampleKind::Delete => present.remove(&host),
            };
        }
    }

    fn on_done_token(&self, token: &zenoh::sample::Sample) {
        if token.kind() == SampleKind::Put
            && let Some(host) = keys::token_host(token.key_expr().as_str())
            && let Ok(mut done) = self.done.lock()
        {
            done.insert(host);
        }
    }

    /// Counts a sample published while some consuming hosts were not subscribed.
    fn count_missed(&self) {
        let absent = self.absent();
        if absent.is_empty() {
            return;
        }
        if let Ok(mut report) = self.report.lock() {
            for host in absent {
                match report.missed.iter_mut().find(|(h, _)| *h == host) {
                    Some((_, n)) => *n += 1,
                    None => report.missed.push((host, 1)),
                }
            }
        }
    }
}

/// Publishes one stream to the other hosts.
pub struct ZenohSender {
    publisher: Publisher<'static>,
    key_expr: String,
    host: String,
    state: Arc<Outbound>,
    wait: Duration,
    published: u64,
    incarnation: u64,
    secret: Option<Secret>,
    /// Encoded size of the last sample, to size the next buffer.
    last_len: usize,
    failures: u64,
    /// Whether every consuming host was subscribed at the last check (then a sample costs no
    /// lock).
    all_present: bool,
    checked_at: u64,
    _subscribers: Subscriber<()>,
    _done: Subscriber<()>,
    _end: Queryable<()>,
    /// The producer's liveliness token. Dropping it (with the sender) right after the end can
    /// overtake the end: keep it until the session closes, as [`ZenohTransport`] does.
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

/// A random number for each run of a producer.
fn random_u64() -> u64 {
    let rng = ring::rand::SystemRandom::new();
    ring::rand::generate::<[u8; 8]>(&rng).map(|bytes| u64::from_le_bytes(bytes.expose())).unwrap_or_else(
        |_| {
            let nanos = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos() as u64);
            nanos ^ u64::from(std::process::id()).rotate_left(32)
        },
    )
}

impl ZenohSender {
    /// Declares a publisher on `key` for the hosts `consumers`, the producer's liveliness token,
    /// and the queryable that answers with the stream's end.
    pub async fn declare(
        session: &HostSession,
        key: &StreamKey,
        host: &str,
        consumers: BTreeSet<String>,
    ) -> Result<ZenohSender, TransportError> {
        let key_expr = keys::stream(key);
        let error = |what: &str, e: zenoh::Error| TransportError(format!("{what} `{key_expr}`: {e}"));
        let state = Arc::new(Outbound {
            key: key.clone(),
            consumers,
            present: Mutex::new(BTreeSet::new()),
            seen: Mutex::new(BTreeSet::new()),
            done: Mutex::new(BTreeSet::new()),
            ended: Mutex::new(None),
            report: Mutex::new(OutboundReport { stream: key.stream_name(), ..OutboundReport::default() }),
        });
        let publisher = session
            .session
            .declare_publisher(key_expr.clone())
            .congestion_control(CongestionControl::Block)
            .await
            .map_err(|e| error("cannot publish on", e))?;
        let watch = state.clone();
        let subscribers = session
            .session
            .liveliness()
            .declare_subscriber(keys::subscriber_tokens(key))
            .history(true)
            .callback(move |token| watch.on_subscriber_token(&token))
            .await
            .map_err(|e| error("cannot watch the consumers of", e))?;
        let watch = state.clone();
        let done = session
            .session
            .liveliness()
            .declare_subscriber(keys::done_tokens(key))
            .history(true)
            .callback(move |token| watch.on_done_token(&token))
            .await
            .map_err(|e| error("cannot watch the consumers of", e))?;
        let answer = state.clone();
        let end_key = keys::end(key);
        let end = session
            .session
            .declare_queryable(end_key.clone())
            .callback(move |query| {
                let ended = answer.ended.lock().ok().and_then(|e| e.clone());
                if let Some((payload, attachment)) = ended
                    && let Err(e) = query.reply(end_key.clone(), payload).attachment(attachment).wait()
                {
                    tracing::debug!("cannot answer a query for the end of `{end_key}`: {e}");
                }
            })
            .await
            .map_err(|e| error("cannot keep the end of", e))?;
        let token = session
            .session
            .liveliness()
            .declare_token(keys::publisher_token(key, host))
            .await
            .map_err(|e| error("cannot declare the publisher token of", e))?;
        Ok(ZenohSender {
            publisher,
            key_expr,
            host: host.to_string(),
            state,
            wait: session.options.subscriber_wait,
            published: 0,
            incarnation: random_u64(),
            secret: session.credentials.as_ref().map(|c| c.secret.clone()),
            last_len: 64,
            failures: 0,
            all_present: false,
            checked_at: 0,
            _subscribers: subscribers,
            _done: done,
            _end: end,
            token: Some(token),
        })
    }

    fn envelope(&self, unfinished: bool) -> Envelope {
        Envelope {
            host: self.host.clone(),
            incarnation: self.incarnation,
            sequence: self.published,
            unfinished,
        }
    }

    async fn put(&mut self, payload: Vec<u8>, attachment: Vec<u8>) -> bool {
        match self.publisher.put(payload).attachment(attachment).await {
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

    /// Waits until `n` of the consuming hosts subscribed (their liveliness tokens), or until the
    /// wait is over. Returns how many did.
    pub async fn wait_for_subscribers(&mut self, n: usize) -> usize {
        let deadline = Instant::now() + self.wait;
        loop {
            let present = self.state.present.lock().map(|p| p.len()).unwrap_or(0);
            if present >= n || Instant::now() >= deadline {
                return present;
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }

    /// Ends the stream as finished (see [`RemoteSender::end`]).
    pub async fn end(&mut self) {
        self.end_stream(true).await;
    }

    async fn end_stream(&mut self, finished: bool) {
        let payload = codec::encode_end(self.published);
        let attachment = self.envelope(!finished).seal(&self.key_expr, &payload, self.secret.as_ref());
        if finished && let Ok(mut ended) = self.state.ended.lock() {
            *ended = Some((payload.clone(), attachment.clone()));
        }
        self.put(payload, attachment).await;
        if let Ok(mut report) = self.state.report.lock() {
            report.published = self.published;
        }
        if self.failures > 0 {
            tracing::warn!(stream = %self.key_expr, "{} sample(s) could not be published", self.failures);
        }
        if finished && !self.state.consumers.is_empty() {
            self.wait_for_consumers_to_finish().await;
        }
    }

    /// Waits until every consuming host confirms it has the end (its done token), or until the
    /// wait is over; meanwhile a host that subscribes late gets the end from the end queryable.
    async fn wait_for_consumers_to_finish(&self) {
        let start = Instant::now();
        let deadline = start + self.wait;
        loop {
            let done = self.state.done.lock().map(|d| d.clone()).unwrap_or_default();
            // A host never seen during this run has not started (or cannot reach this one): it
            // is not waited for, and gives up on this host when it comes (KPL_ZENOH_GIVE_UP).
            let seen = self.state.seen.lock().map(|s| s.clone()).unwrap_or_default();
            let missing: Vec<String> = self
                .state
                .consumers
                .iter()
                .filter(|h| seen.contains(*h) && !done.contains(*h))
                .cloned()
                .collect();
            if missing.is_empty() {
                tracing::debug!(stream = %self.key_expr, waited = ?start.elapsed(), "every consumer has the end");
                return;
            }
            if Instant::now() >= deadline {
                tracing::warn!(
                    "stream `{}`: host(s) {missing:?} did not confirm the end within {:.1} s; leaving anyway \
                     (they give up on this host after KPL_ZENOH_WAIT; KPL_ZENOH_WAIT=SECONDS waits longer)",
                    self.key_expr,
                    self.wait.as_secs_f64()
                );
                if let Ok(mut report) = self.state.report.lock() {
                    report.end_not_confirmed = missing;
                }
                return;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
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
            let attachment = self.envelope(false).seal(&self.key_expr, &bytes, self.secret.as_ref());
            // Who is subscribed changes rarely: look every 64 samples while everyone is there.
            if !self.all_present || self.published >= self.checked_at + 64 {
                self.all_present = self.state.absent().is_empty();
                self.checked_at = self.published;
            }
            if !self.all_present {
                self.state.count_missed();
            }
            if self.put(bytes, attachment).await {
                self.published += 1;
                if self.published.is_multiple_of(256)
                    && let Ok(mut report) = self.state.report.lock()
                {
                    report.published = self.published;
                }
            }
        })
    }

    fn end(&mut self, finished: bool) -> BoxFuture<'_, ()> {
        Box::pin(self.end_stream(finished))
    }
}

/// Whether a stream's producing host is there, from its publisher token.
#[derive(Debug, Clone, Copy)]
enum Presence {
    /// Not seen yet, since this instant.
    Never(Instant),
    Here,
    /// Gone (or interrupted) since this instant.
    Gone(Instant),
}

/// Receives one stream from another host.
pub struct ZenohReceiver {
    data: Subscriber<FifoChannelHandler<zenoh::sample::Sample>>,
    /// The producer's liveliness token: `Put` while it is there, `Delete` when it goes away.
    producers: Option<Subscriber<FifoChannelHandler<zenoh::sample::Sample>>>,
    session: zenoh::Session,
    key: StreamKey,
    key_expr: String,
    ty: ValueType,
    host: String,
    /// The host the spec places the producer on; `None`: envelopes are not checked (a receiver
    /// outside a deployment, as in `kpl bench zenoh`).
    producer_host: Option<String>,
    secret: Option<Secret>,
    sequence: Sequence,
    /// Messages received (for locations of malformed ones).
    messages: u64,
    presence: Presence,
    /// How long to wait for an absent producing host (`KPL_ZENOH_GIVE_UP`).
    give_up: Duration,
    /// Replies to a query for the stream's end, while one is under way.
    end_query: Option<FifoChannelHandler<Reply>>,
    report: Arc<Mutex<InboundReport>>,
    keeper: Arc<Mutex<Vec<LivelinessToken>>>,
    _token: LivelinessToken,
}

impl std::fmt::Debug for ZenohReceiver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZenohReceiver").field("key", &self.key_expr).finish()
    }
}

/// What the receiver does with a message.
enum Outcome {
    Deliver(Remote),
    /// Nothing to deliver (refused, or the producer was interrupted).
    Skip,
}

impl ZenohReceiver {
    /// Subscribes to `key`, decoding values with `ty`, and declares this host's subscriber token.
    /// Accepts messages from any host (no envelope check); the transport between the hosts of a
    /// deployment uses [`ZenohReceiver::declare_with`].
    pub async fn declare(
        session: &HostSession,
        key: &StreamKey,
        ty: ValueType,
        host: &str,
    ) -> Result<ZenohReceiver, TransportError> {
        let report =
            Arc::new(Mutex::new(InboundReport { stream: key.stream_name(), ..InboundReport::default() }));
        Self::declare_with(session, key, ty, host, None, report, Arc::default()).await
    }

    /// As [`ZenohReceiver::declare`], accepting messages only from `producer_host` (when given),
    /// counting into `report`, and keeping the token that confirms the end in `keeper`.
    pub async fn declare_with(
        session: &HostSession,
        key: &StreamKey,
        ty: ValueType,
        host: &str,
        producer_host: Option<String>,
        report: Arc<Mutex<InboundReport>>,
        keeper: Arc<Mutex<Vec<LivelinessToken>>>,
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
        let mut receiver = ZenohReceiver {
            data,
            producers: Some(producers),
            session: session.session.clone(),
            key: key.clone(),
            key_expr,
            ty,
            host: host.to_string(),
            producer_host,
            secret: session.credentials.as_ref().map(|c| c.secret.clone()),
            sequence: Sequence::default(),
            messages: 0,
            presence: Presence::Never(Instant::now()),
            give_up: session.options.give_up,
            end_query: None,
            report,
            keeper,
            _token: token,
        };
        // The stream may have ended before this host came.
        receiver.query_end().await;
        Ok(receiver)
    }

    /// Asks the producing host for the stream's end (it answers once the stream has ended).
    async fn query_end(&mut self) {
        if self.producer_host.is_none() {
            return;
        }
        match self
            .session
            .get(keys::end(&self.key))
            .with(zenoh::handlers::FifoChannel::new(4))
            .timeout(Duration::from_secs(10))
            .await
        {
            Ok(replies) => self.end_query = Some(replies),
            Err(e) => tracing::debug!(stream = %self.key_expr, "cannot ask for the end: {e}"),
        }
    }

    fn refuse(&self, refusal: &Refusal) {
        tracing::debug!(stream = %self.key_expr, "refused message {}: {refusal}", self.messages);
        if let Ok(mut report) = self.report.lock() {
            report.refused += 1;
            if report.refused_examples.len() < kpl_runtime::stats::ProcessStats::KEEP {
                report.refused_examples.push(Malformed {
                    location: format!("zenoh `{}`, message {}", self.key_expr, self.messages),
                    error: refusal.to_string(),
                });
            }
        }
    }

    fn on_message(&mut self, payload: &[u8], attachment: Option<&[u8]>) -> Outcome {
        self.messages += 1;
        let envelope = match &self.producer_host {
            Some(expected) => match Envelope::open(attachment, &self.key_expr, payload, self.secret.as_ref())
            {
                Ok(envelope) if envelope.host == *expected => Some(envelope),
                Ok(envelope) => {
                    self.refuse(&Refusal::WrongHost { from: envelope.host, expected: expected.clone() });
                    return Outcome::Skip;
                }
                Err(refusal) => {
                    self.refuse(&refusal);
                    return Outcome::Skip;
                }
            },
            None => None,
        };
        let decoded = codec::decode(payload, &self.ty);
        // A message from the producer that does not decode still takes its place in the stream.
        let is_end = matches!(decoded, Ok(Message::End { .. }));
        if let Some(envelope) = &envelope {
            match self.sequence.accept(envelope, is_end) {
                Ok(accepted) => {
                    if let Ok(mut report) = self.report.lock() {
                        report.lost += accepted.lost;
                        report.producer_restarts += u64::from(accepted.restarted);
                    }
                    if accepted.restarted {
                        tracing::warn!(stream = %self.key_expr, "the producer started again");
                    }
                    if accepted.lost > 0 {
                        tracing::warn!(stream = %self.key_expr, "{} sample(s) lost on the way", accepted.lost);
                    }
                }
                Err(refusal) => {
                    self.refuse(&refusal);
                    return Outcome::Skip;
                }
            }
        }
        let message = match decoded {
            Ok(message) => message,
            Err(e) => {
                return Outcome::Deliver(Remote::Malformed {
                    location: format!("zenoh `{}`, message {}", self.key_expr, self.messages),
                    error: e.to_string(),
                });
            }
        };
        match message {
            Message::Sample(sample) => {
                if let Ok(mut report) = self.report.lock() {
                    report.received += 1;
                }
                Outcome::Deliver(Remote::Sample(sample))
            }
            Message::End { .. } if envelope.as_ref().is_some_and(|e| e.unfinished) => {
                tracing::warn!(
                    stream = %self.key_expr,
                    "the producing host was interrupted; waiting up to {:.0} s for it to come back",
                    self.give_up.as_secs_f64()
                );
                if matches!(self.presence, Presence::Here) {
                    self.presence = Presence::Gone(Instant::now());
                }
                Outcome::Skip
            }
            Message::End { published } => {
                if envelope.is_none()
                    && let Ok(report) = self.report.lock()
                    && published > report.received
                {
                    tracing::warn!(
                        stream = %self.key_expr,
                        "the producer published {published} sample(s), {} arrived",
                        report.received
                    );
                }
                if let Ok(mut report) = self.report.lock() {
                    report.ending = InboundEnding::End;
                }
                self.confirm_end();
                Outcome::Deliver(Remote::End)
            }
        }
    }

    /// Tells the producing host this one has the end (a token it keeps until its session closes).
    fn confirm_end(&self) {
        match self.session.liveliness().declare_token(keys::done_token(&self.key, &self.host)).wait() {
            Ok(token) => {
                if let Ok(mut keeper) = self.keeper.lock() {
                    keeper.push(token);
                }
            }
            Err(e) => tracing::warn!(stream = %self.key_expr, "cannot confirm the end: {e}"),
        }
    }

    fn cut_short(&mut self) -> Remote {
        let producer = self.producer_host.clone().unwrap_or_default();
        let wait = self.give_up.as_secs_f64();
        let why = match self.presence {
            Presence::Never(_) => {
                format!("host `{producer}` did not appear within {wait:.0} s (KPL_ZENOH_GIVE_UP)")
            }
            _ => format!(
                "host `{producer}` went away and did not come back within {wait:.0} s (KPL_ZENOH_GIVE_UP)"
            ),
        };
        if let Ok(mut report) = self.report.lock() {
            report.ending = InboundEnding::CutShort(why.clone());
        }
        Remote::CutShort(format!("stream `{}`: {why}", self.key.stream_name()))
    }

    fn on_producer_token(&mut self, token: &zenoh::sample::Sample) -> bool {
        match token.kind() {
            SampleKind::Put => {
                let returned = !matches!(self.presence, Presence::Here);
                self.presence = Presence::Here;
                returned
            }
            SampleKind::Delete => {
                if matches!(self.presence, Presence::Here) {
                    self.presence = Presence::Gone(Instant::now());
                }
                false
            }
        }
    }
}

enum Event {
    Message(Option<zenoh::sample::Sample>),
    Token(Option<zenoh::sample::Sample>),
    Reply(Option<Reply>),
    GiveUp,
}

impl RemoteReceiver for ZenohReceiver {
    fn recv(&mut self) -> BoxFuture<'_, Option<Remote>> {
        Box::pin(async move {
            loop {
                let give_up_at = match (self.producer_host.is_some(), self.presence) {
                    (true, Presence::Never(since) | Presence::Gone(since)) => Some(since + self.give_up),
                    _ => None,
                };
                let producers = async {
                    match &self.producers {
                        Some(p) => p.recv_async().await.ok(),
                        None => std::future::pending().await,
                    }
                };
                let replies = async {
                    match &self.end_query {
                        Some(r) => r.recv_async().await.ok(),
                        None => std::future::pending().await,
                    }
                };
                let give_up = async {
                    match give_up_at {
                        Some(at) => tokio::time::sleep_until(at.into()).await,
                        None => std::future::pending().await,
                    }
                };
                let event = tokio::select! {
                    biased;
                    message = self.data.recv_async() => Event::Message(message.ok()),
                    token = producers => Event::Token(token),
                    reply = replies => Event::Reply(reply),
                    () = give_up => Event::GiveUp,
                };
                match event {
                    Event::Message(None) => return None,
                    Event::Message(Some(message)) => {
                        let payload = message.payload().to_bytes();
                        let attachment = message.attachment().map(|a| a.to_bytes());
                        if let Outcome::Deliver(remote) = self.on_message(&payload, attachment.as_deref()) {
                            return Some(remote);
                        }
                    }
                    Event::Token(None) => self.producers = None,
                    Event::Token(Some(token)) => {
                        if self.on_producer_token(&token) {
                            // Back (or here at last): the stream may have ended meanwhile.
                            self.query_end().await;
                        }
                    }
                    Event::Reply(None) => self.end_query = None,
                    Event::Reply(Some(reply)) => {
                        if let Ok(sample) = reply.result() {
                            let payload = sample.payload().to_bytes();
                            let attachment = sample.attachment().map(|a| a.to_bytes());
                            if let Outcome::Deliver(remote) = self.on_message(&payload, attachment.as_deref())
                            {
                                return Some(remote);
                            }
                        }
                    }
                    Event::GiveUp => {
                        // Samples that arrived before the give-up are delivered first.
                        if self.data.is_empty() {
                            return Some(self.cut_short());
                        }
                    }
                }
            }
        })
    }
}
