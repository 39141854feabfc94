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
//!   waits (up to `KPL_ZENOH_WAIT`) until every consuming host acknowledges the end, so a host
//!   that subscribes late, or was away when the end went out, still ends its input.
//! - **Strangers are refused and counted.** A receiver accepts a message only from the host the
//!   spec places the producer on, with a valid tag when the deployment has keys, and only once
//!   (its incarnation and sequence number); everything else is refused and counted. Nothing a
//!   sender claims shuts the producer out.
//! - **Nothing is dropped under load, and zenoh never waits on a consumer.** A subscription queues
//!   what arrives at once; consuming hosts acknowledge what they took ([`crate::flow`]), and a
//!   producer keeps at most a window unacknowledged per consuming host: a slow consumer slows its
//!   producer down without stalling the link. Consuming hosts count as there only while their
//!   authenticated acknowledgments come.
//! - **The end is acknowledged on arrival.** A consuming host tells the producer it has the end as
//!   soon as it arrives, and asks for it every 2 s while the stream is open and its producer there.
//! - **Two runs of one host meet: both stop.** Each host says every second which process runs it
//!   (its hello, authenticated); hearing another process run this host is an error naming both.
//! - **A host that waits says for what**, every few seconds.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use kpl_core::ValueType;
use kpl_runtime::Sample;
use kpl_runtime::process::BoxFuture;
use kpl_runtime::run::{RunConfig, TransportFactory};
use kpl_runtime::stats::Malformed;
use kpl_runtime::transport::{
    HostReport, InboundEnding, InboundReport, InboundRun, OutboundReport, Remote, RemoteReceiver,
    RemoteSender, StreamKey, Transport, TransportError, TransportReport,
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
            let deployment = config.deployment(spec);
            let plan = Plan::new(spec, host, &deployment, &config.spec_name);
            let options = self.sessions.options()?;
            if options.keys.is_none() && !options.insecure {
                let dir = crate::credentials::default_dir(&config.spec_dir, &config.spec_name, &deployment);
                let made = crate::credentials::made_on_first_use(&dir, &deployment, &plan.hosts).map_err(|e| {
                    TransportError(format!(
                        "cannot make the keys of deployment `{deployment}` in {}: {e} (give a keys folder with --keys, \
                         or run without keys with --insecure)",
                        dir.display()
                    ))
                })?;
                tracing::info!(
                    "host `{host}`: keys of deployment `{deployment}` {} {} (hosts on other machines: `kpl keys` and --keys)",
                    if made { "made in" } else { "from" },
                    dir.display()
                );
                self.sessions.configure(|o| o.first_use_keys = Some(dir));
            }
            // Access control tells hosts apart by their certificates: it is for `tls/` links.
            let access_control = options.keys.is_some().then(|| plan.access_control());
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
            .map(|h| serde_json::json!({ "id": subject(h), "cert_common_names": [h] }))
            .collect();
        let mut rules = Vec::new();
        let mut policies = Vec::new();
        for (i, (stream, producer_host)) in self.inbound.iter().enumerate() {
            // Every host but the producer's, this one included: a peer showing this host's own
            // certificate is not this host.
            let others: Vec<String> =
                self.hosts.iter().filter(|h| *h != producer_host).map(|h| subject(h)).collect();
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
    /// The end queryables of this host's streams, kept until the session closes: the runtime
    /// drops a stream's sender once its end went out, but a host that comes later asks for it.
    ends: Mutex<Vec<Queryable<()>>>,
    hosts: Arc<HostWatch>,
    outbound: Mutex<Vec<Arc<Outbound>>>,
    inbound: Mutex<Vec<Arc<Mutex<InboundReport>>>>,
    /// What this host's receivers acknowledge: closing waits for the ends they have to go out.
    acks: Mutex<Vec<Arc<AckState>>>,
    /// Another process running this host of the deployment, once heard of.
    clash: Arc<Clash>,
    hello: tokio::task::JoinHandle<()>,
    _hellos: Subscriber<()>,
    _host_watch: Subscriber<()>,
}

/// This process's hello, and what it hears of other processes claiming its host.
///
/// Every host says every second, on `kpl/DEPLOYMENT/SPEC/@hello/HOST` with its envelope (tagged
/// with the deployment's secret), which process runs it: the envelope's incarnation is random for
/// each process, the payload `KPH`, version 1, and the process id (u32). A hello naming this host
/// from another process, tagged with the deployment's keys, is two deployments of one spec with
/// the same name and keys meeting (two runs of the same spec on one machine, linked): both stop
/// with an error naming the other, before either records the other's samples.
struct Clash {
    host: String,
    key: String,
    instance: u64,
    secret: Option<Secret>,
    found: Mutex<Option<String>>,
    heard: tokio::sync::Notify,
    deployment: String,
    spec: String,
}

impl Clash {
    fn new(plan: &Plan, secret: Option<Secret>) -> Clash {
        Clash {
            host: plan.host.clone(),
            key: keys::hello(&plan.deployment, &plan.spec_name, &plan.host),
            instance: random_u64(),
            secret,
            found: Mutex::new(None),
            heard: tokio::sync::Notify::new(),
            deployment: plan.deployment.clone(),
            spec: plan.spec_name.clone(),
        }
    }

    fn payload() -> Vec<u8> {
        let mut out = b"KPH\x01".to_vec();
        out.extend_from_slice(&std::process::id().to_le_bytes());
        out
    }

    fn on_hello(&self, sample: &zenoh::sample::Sample) {
        let key_expr = sample.key_expr().as_str();
        if key_expr != self.key {
            return;
        }
        let payload = sample.payload().to_bytes();
        let attachment = sample.attachment().map(|a| a.to_bytes());
        let Ok(envelope) = Envelope::open(attachment.as_deref(), key_expr, &payload, self.secret.as_ref())
        else {
            return;
        };
        if envelope.host != self.host || envelope.incarnation == self.instance || payload.len() != 8 {
            return;
        }
        let mut pid = [0u8; 4];
        pid.copy_from_slice(&payload[4..8]);
        let why = format!(
            "host `{}` of deployment `{}` of spec `{}` runs twice: in this process ({}) and in process {} \
             (its run {:016x}); two runs of one spec with the same deployment name and keys met: give one \
             of them another name (--deployment NAME)",
            self.host,
            self.deployment,
            self.spec,
            std::process::id(),
            u32::from_le_bytes(pid),
            envelope.incarnation
        );
        if let Ok(mut found) = self.found.lock()
            && found.is_none()
        {
            *found = Some(why);
            self.heard.notify_waiters();
        }
    }

    fn found(&self) -> Option<String> {
        self.found.lock().ok().and_then(|f| f.clone())
    }
}

/// Says every second which process runs this host (until the transport closes).
async fn say_hello(session: zenoh::Session, clash: Arc<Clash>) {
    let payload = Clash::payload();
    for number in 0u64.. {
        let envelope = Envelope {
            host: clash.host.clone(),
            incarnation: clash.instance,
            sequence: number,
            unfinished: false,
        };
        let attachment = envelope.seal(&clash.key, &payload, clash.secret.as_ref());
        if session.is_closed() {
            return;
        }
        if let Err(e) = session.put(clash.key.clone(), payload.clone()).attachment(attachment).await {
            tracing::debug!("cannot say hello: {e}");
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
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
        let clash = Arc::new(Clash::new(&plan, session.credentials.as_ref().map(|c| c.secret.clone())));
        let hears = clash.clone();
        let hellos = session
            .session
            .declare_subscriber(keys::hellos(&plan.deployment, &plan.spec_name))
            .callback(move |hello| hears.on_hello(&hello))
            .await
            .map_err(|e| error("cannot hear the other hosts", e))?;
        let hello = tokio::spawn(say_hello(session.session.clone(), clash.clone()));
        Ok(ZenohTransport {
            session,
            plan,
            declared: tokio::sync::Mutex::new(None),
            tokens: Arc::new(Mutex::new(vec![token])),
            ends: Mutex::new(Vec::new()),
            hosts,
            outbound: Mutex::new(Vec::new()),
            inbound: Mutex::new(Vec::new()),
            acks: Mutex::new(Vec::new()),
            clash,
            hello,
            _hellos: hellos,
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
            )
            .await?;
            if let Ok(mut acks) = self.acks.lock() {
                acks.push(receiver.acks.clone());
            }
            receivers.insert(key, receiver);
        }
        *declared = Some(receivers);
        Ok(())
    }

    /// Waits (at most [`FLUSH_ENDS`]) until the acknowledgment of every end this host has went
    /// out: a consumer that closes its session first leaves the producer waiting for an end it
    /// has (the acknowledging task may not have run yet since the end arrived).
    async fn flush_ends(&self) {
        let acks = self.acks.lock().map(|a| a.clone()).unwrap_or_default();
        let step = Duration::from_millis(10);
        for _ in 0..FLUSH_ENDS.as_millis() / step.as_millis() {
            if !acks.iter().any(|a| a.end_unsent()) {
                return;
            }
            tokio::time::sleep(step).await;
        }
        tracing::warn!("the acknowledgment of a stream's end did not go out within {FLUSH_ENDS:?}");
    }

    /// Who is still missing: for each consuming host not subscribed yet, the streams it lacks.
    fn missing(&self) -> BTreeMap<String, Vec<String>> {
        let mut missing: BTreeMap<String, Vec<String>> = BTreeMap::new();
        for outbound in self.outbound.lock().map(|o| o.clone()).unwrap_or_default() {
            for host in outbound.awaited() {
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
            if let Some(end) = sender.end_queryable.take()
                && let Ok(mut ends) = self.ends.lock()
            {
                ends.push(end);
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

    fn failed(&self) -> BoxFuture<'_, String> {
        Box::pin(async move {
            loop {
                let heard = self.clash.heard.notified();
                tokio::pin!(heard);
                heard.as_mut().enable();
                if let Some(why) = self.clash.found() {
                    return why;
                }
                heard.await;
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
            self.hello.abort();
            self.declared.lock().await.take();
            self.flush_ends().await;
            if let Ok(mut tokens) = self.tokens.lock() {
                tokens.clear();
            }
            if let Ok(mut ends) = self.ends.lock() {
                ends.clear();
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

/// A consuming host of a stream, as its producer sees it.
#[derive(Debug, Default)]
struct Consumer {
    /// Its subscriber token is there.
    token: bool,
    /// When its last authenticated acknowledgment arrived.
    last_ack: Option<Instant>,
    /// Its receiver's run, and the last acknowledgment number from it (older ones are replays).
    instance: Option<(u64, u64)>,
    /// How far it took this run of the producer.
    acked: Option<u64>,
    /// It has the end of this run.
    end: bool,
    /// It has the end of an earlier run of this producer (it does not subscribe again).
    ended_earlier: bool,
    /// The producer's count of samples when the consumer was first heard from (its credit
    /// starts there until it acknowledges a sample of this run).
    joined_at: u64,
    /// Whether it counted as present at the last look.
    present: bool,
}

/// What a stream's publisher shares with the transport and zenoh's callbacks.
struct Outbound {
    key: StreamKey,
    ack_prefix: String,
    consumers: BTreeSet<String>,
    incarnation: u64,
    secret: Option<Secret>,
    /// Samples unacknowledged per consuming host at most.
    window: u64,
    published: std::sync::atomic::AtomicU64,
    state: Mutex<BTreeMap<String, Consumer>>,
    /// The consuming hosts that subscribed at some point of this run.
    seen: Mutex<BTreeSet<String>>,
    /// The end, once the stream finished: what the end queryable answers.
    ended: Mutex<Option<(Vec<u8>, Vec<u8>)>>,
    report: Mutex<OutboundReport>,
    /// Woken by acknowledgments and tokens.
    changed: tokio::sync::Notify,
}

impl Outbound {
    fn present(consumer: &Consumer, now: Instant) -> bool {
        consumer.token && consumer.last_ack.is_some_and(|t| now.duration_since(t) < crate::flow::STALE)
    }

    /// Updates who is present: `(credit limit, absent hosts)`. The limit is the count of samples
    /// this producer may have published before it waits (`u64::MAX`: nobody to wait for).
    fn credit(&self) -> (u64, Vec<String>) {
        let now = Instant::now();
        let published = self.published.load(std::sync::atomic::Ordering::Relaxed);
        let mut limit = u64::MAX;
        let mut absent = Vec::new();
        let Ok(mut state) = self.state.lock() else { return (limit, absent) };
        for host in &self.consumers {
            let consumer = state.entry(host.clone()).or_default();
            let present = Self::present(consumer, now);
            if present && !consumer.present {
                consumer.joined_at = published;
            }
            consumer.present = present;
            if present {
                if !consumer.end {
                    let base =
                        consumer.acked.unwrap_or(consumer.joined_at).max(consumer.joined_at.min(published));
                    limit = limit.min(base.saturating_add(self.window));
                }
            } else {
                absent.push(host.clone());
            }
        }
        (limit, absent)
    }

    fn absent(&self) -> Vec<String> {
        self.credit().1
    }

    /// The consuming hosts the start-up waits for: absent, and without the end of an earlier
    /// run of this stream (a host that has it does not subscribe again).
    fn awaited(&self) -> Vec<String> {
        let absent = self.absent();
        let Ok(state) = self.state.lock() else { return absent };
        absent.into_iter().filter(|h| !state.get(h).is_some_and(|c| c.ended_earlier)).collect()
    }

    fn on_subscriber_token(&self, token: &zenoh::sample::Sample) {
        let Some(host) = keys::token_host(token.key_expr().as_str()) else { return };
        if !self.consumers.contains(&host) {
            return;
        }
        if token.kind() == SampleKind::Put
            && let Ok(mut seen) = self.seen.lock()
        {
            seen.insert(host.clone());
        }
        if let Ok(mut state) = self.state.lock() {
            state.entry(host).or_default().token = token.kind() == SampleKind::Put;
        }
        self.changed.notify_waiters();
    }

    /// An acknowledgment: taken only from a consuming host, with its envelope (and tag, with keys).
    fn on_ack(&self, sample: &zenoh::sample::Sample) {
        let key_expr = sample.key_expr().as_str();
        let Some(host) = key_expr.strip_prefix(&self.ack_prefix).and_then(keys::unescape_chunk) else {
            return;
        };
        if !self.consumers.contains(&host) {
            return;
        }
        let payload = sample.payload().to_bytes();
        let attachment = sample.attachment().map(|a| a.to_bytes());
        let refuse = |why: String| {
            tracing::debug!(stream = %self.key.stream_name(), "acknowledgment from `{host}` refused: {why}");
            if let Ok(mut report) = self.report.lock() {
                report.refused_acks += 1;
            }
        };
        let envelope = match Envelope::open(attachment.as_deref(), key_expr, &payload, self.secret.as_ref()) {
            Ok(e) if e.host == host => e,
            Ok(e) => return refuse(format!("it names host `{}`", e.host)),
            Err(refusal) => return refuse(refusal.to_string()),
        };
        let Some(ack) = crate::flow::Ack::decode(&payload) else {
            return refuse("not an acknowledgment".into());
        };
        let Ok(mut state) = self.state.lock() else { return };
        let consumer = state.entry(host).or_default();
        match consumer.instance {
            Some((instance, number)) if instance == envelope.incarnation && envelope.sequence <= number => {
                return;
            }
            Some((instance, _)) if instance == envelope.incarnation => {}
            _ => {
                // A new run of the consumer's receiver: its progress starts again.
                consumer.acked = None;
                consumer.end = false;
            }
        }
        consumer.instance = Some((envelope.incarnation, envelope.sequence));
        consumer.last_ack = Some(Instant::now());
        match ack.run {
            Some((incarnation, position)) if incarnation == self.incarnation => {
                consumer.acked = Some(consumer.acked.unwrap_or(0).max(position));
                consumer.end |= ack.end;
            }
            Some(_) => consumer.ended_earlier = ack.end,
            None => {}
        }
        drop(state);
        self.changed.notify_waiters();
    }

    /// Counts a sample published while some consuming hosts were not there.
    fn count_missed(&self, absent: &[String]) {
        if absent.is_empty() {
            return;
        }
        if let Ok(mut report) = self.report.lock() {
            for host in absent {
                match report.missed.iter_mut().find(|(h, _)| h == host) {
                    Some((_, n)) => *n += 1,
                    None => report.missed.push((host.clone(), 1)),
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
    /// The count of samples this producer may reach before it looks at its credit again.
    credit_until: u64,
    /// The consuming hosts absent at the last look (then each sample is counted missed for them).
    absent: Vec<String>,
    checked_at: u64,
    _subscribers: Subscriber<()>,
    _acks: Subscriber<()>,
    /// The queryable that answers with the stream's end, once it has ended. Dropping it with the
    /// sender (the runtime drops a stream's outputs once their end went out) would leave a host
    /// that comes later without the end: keep it until the session closes, as
    /// [`ZenohTransport`] does.
    pub end_queryable: Option<Queryable<()>>,
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
pub(crate) fn random_u64() -> u64 {
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
    /// the subscription to their acknowledgments, and the queryable that answers with the
    /// stream's end.
    pub async fn declare(
        session: &HostSession,
        key: &StreamKey,
        host: &str,
        consumers: BTreeSet<String>,
    ) -> Result<ZenohSender, TransportError> {
        let key_expr = keys::stream(key);
        let error = |what: &str, e: zenoh::Error| TransportError(format!("{what} `{key_expr}`: {e}"));
        let incarnation = random_u64();
        let secret = session.credentials.as_ref().map(|c| c.secret.clone());
        let state = Arc::new(Outbound {
            key: key.clone(),
            ack_prefix: keys::ack(key, "").trim_end_matches('%').to_string(),
            consumers,
            incarnation,
            secret: secret.clone(),
            window: session.options.queue.max(1) as u64,
            published: std::sync::atomic::AtomicU64::new(0),
            state: Mutex::new(BTreeMap::new()),
            seen: Mutex::new(BTreeSet::new()),
            ended: Mutex::new(None),
            report: Mutex::new(OutboundReport {
                stream: key.stream_name(),
                incarnation: format!("{incarnation:016x}"),
                ..OutboundReport::default()
            }),
            changed: tokio::sync::Notify::new(),
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
        let acks = session
            .session
            .declare_subscriber(keys::acks(key))
            .callback(move |ack| watch.on_ack(&ack))
            .await
            .map_err(|e| error("cannot hear the consumers of", e))?;
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
            incarnation,
            secret,
            last_len: 64,
            failures: 0,
            credit_until: 0,
            absent: Vec::new(),
            checked_at: 0,
            _subscribers: subscribers,
            _acks: acks,
            end_queryable: Some(end),
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

    /// Looks at who is there and waits, if need be, until every consuming host that is there has
    /// taken enough of the stream for one more sample (the window), saying so when it waits long.
    async fn wait_for_credit(&mut self) {
        let start = Instant::now();
        let mut next_report = start + REPORT_EVERY;
        loop {
            let notified = self.state.changed.notified();
            tokio::pin!(notified);
            notified.as_mut().enable();
            let (limit, absent) = self.state.credit();
            self.absent = absent;
            self.checked_at = self.published;
            if limit > self.published {
                self.credit_until = limit;
                if Instant::now() >= start + REPORT_EVERY {
                    tracing::info!(stream = %self.key_expr, "consumers took samples again after {:.1} s", start.elapsed().as_secs_f64());
                }
                return;
            }
            if Instant::now() >= next_report {
                tracing::info!(
                    "stream `{}`: waiting {:.0} s so far for the consuming host(s) to take samples ({} unacknowledged at most)",
                    self.key_expr,
                    start.elapsed().as_secs_f64(),
                    self.state.window
                );
                next_report += REPORT_EVERY;
            }
            tokio::select! {
                () = &mut notified => {}
                () = tokio::time::sleep(Duration::from_millis(100)) => {}
            }
        }
    }

    /// Waits until `n` of the consuming hosts are there (subscribed and acknowledging), or until
    /// the wait is over. Returns how many are.
    pub async fn wait_for_subscribers(&mut self, n: usize) -> usize {
        let deadline = Instant::now() + self.wait;
        loop {
            let present = self.state.consumers.len() - self.state.absent().len();
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

    /// Waits until every consuming host seen during this run acknowledges it has the end, or
    /// until the wait is over; meanwhile a host that subscribes late gets the end from the end
    /// queryable.
    async fn wait_for_consumers_to_finish(&self) {
        let start = Instant::now();
        let deadline = start + self.wait;
        let mut next_report = start + REPORT_EVERY;
        loop {
            // A host never seen during this run has not started (or cannot reach this one): it
            // is not waited for, and gets the end from the queryable while this host runs.
            let seen = self.state.seen.lock().map(|s| s.clone()).unwrap_or_default();
            let missing: Vec<String> = match self.state.state.lock() {
                Ok(state) => self
                    .state
                    .consumers
                    .iter()
                    .filter(|h| seen.contains(*h) && !state.get(*h).is_some_and(|c| c.end))
                    .cloned()
                    .collect(),
                Err(_) => Vec::new(),
            };
            if missing.is_empty() {
                tracing::debug!(stream = %self.key_expr, waited = ?start.elapsed(), "every consumer has the end");
                return;
            }
            let now = Instant::now();
            if now >= deadline {
                tracing::warn!(
                    "stream `{}`: host(s) {} did not confirm the end within {:.1} s; leaving anyway \
                     (KPL_ZENOH_WAIT=SECONDS waits longer); the run is incomplete",
                    self.key_expr,
                    missing.iter().map(|h| format!("`{h}`")).collect::<Vec<_>>().join(", "),
                    self.wait.as_secs_f64()
                );
                if let Ok(mut report) = self.state.report.lock() {
                    report.end_not_confirmed = missing;
                }
                return;
            }
            if now >= next_report {
                tracing::info!(
                    "stream `{}`: waiting for host(s) {} to confirm the end: {:.0} s of {:.0} s",
                    self.key_expr,
                    missing.iter().map(|h| format!("`{h}`")).collect::<Vec<_>>().join(", "),
                    (now - start).as_secs_f64(),
                    self.wait.as_secs_f64()
                );
                next_report = now + REPORT_EVERY;
            }
            let notified = self.state.changed.notified();
            tokio::select! {
                () = notified => {}
                () = tokio::time::sleep(Duration::from_millis(50)) => {}
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
            // Who is there changes rarely: look every 64 samples, or when the credit runs out.
            if self.published >= self.credit_until || self.published >= self.checked_at + 64 {
                self.wait_for_credit().await;
            }
            self.state.count_missed(&self.absent);
            let attachment = self.envelope(false).seal(&self.key_expr, &bytes, self.secret.as_ref());
            if self.put(bytes, attachment).await {
                self.published += 1;
                self.state.published.store(self.published, std::sync::atomic::Ordering::Relaxed);
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

/// What zenoh delivered on a stream, queued at once (zenoh's threads never wait on a consumer).
struct Inbox {
    queue: Mutex<std::collections::VecDeque<zenoh::sample::Sample>>,
    arrived: tokio::sync::Notify,
    /// Past this many queued messages (twice the window: only a sender that ignores the credit
    /// gets there), samples are dropped; their sequence numbers then count them as lost.
    capacity: usize,
    dropped: std::sync::atomic::AtomicU64,
}

impl Inbox {
    fn push(&self, sample: zenoh::sample::Sample) {
        let Ok(mut queue) = self.queue.lock() else { return };
        // An end is always kept: it says how many samples the stream had.
        if queue.len() >= self.capacity && !codec::is_end(&sample.payload().to_bytes()) {
            self.dropped.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            return;
        }
        queue.push_back(sample);
        drop(queue);
        self.arrived.notify_one();
    }

    fn pop(&self) -> Option<zenoh::sample::Sample> {
        self.queue.lock().ok()?.pop_front()
    }

    fn is_empty(&self) -> bool {
        self.queue.lock().map_or(true, |q| q.is_empty())
    }
}

/// What a receiver acknowledges, shared with the task that sends the acknowledgments.
/// How long closing a host waits for the acknowledgments of the ends it has to go out.
const FLUSH_ENDS: Duration = Duration::from_secs(2);

#[derive(Default)]
struct AckState {
    ack: Mutex<crate::flow::Ack>,
    /// The last acknowledgment handed to zenoh.
    sent: Mutex<crate::flow::Ack>,
    /// Send now (progress, the end, or the receiver closing).
    wake: tokio::sync::Notify,
    closing: std::sync::atomic::AtomicBool,
}

impl AckState {
    fn ack(&self) -> crate::flow::Ack {
        self.ack.lock().map(|a| *a).unwrap_or_default()
    }

    /// The consumer has an end whose acknowledgment has not gone out yet.
    fn end_unsent(&self) -> bool {
        let ack = self.ack();
        ack.end && self.sent.lock().map(|s| *s != ack).unwrap_or(false)
    }

    /// The consumer took the producer's run `incarnation` up to `position`.
    fn progress(&self, incarnation: u64, position: u64) {
        if let Ok(mut ack) = self.ack.lock() {
            match ack.run {
                Some((i, p)) if i == incarnation => ack.run = Some((i, p.max(position))),
                _ => *ack = crate::flow::Ack { run: Some((incarnation, position)), end: false },
            }
        }
    }

    /// The consumer has the end of run `incarnation`, which published `published` samples.
    fn end(&self, incarnation: u64, published: u64) {
        if let Ok(mut ack) = self.ack.lock() {
            *ack = crate::flow::Ack { run: Some((incarnation, published)), end: true };
        }
        self.wake.notify_one();
    }
}

/// Sends a receiver's acknowledgments: at once when woken, else every [`crate::flow::HEARTBEAT`].
/// A receiver that closes without the end sends a last one and stops; one that has the end keeps
/// saying so until the session closes, so that a producer that starts again does not wait for it.
async fn acknowledge(
    session: zenoh::Session,
    key: StreamKey,
    host: String,
    secret: Option<Secret>,
    state: Arc<AckState>,
) {
    let ack_key = keys::ack(&key, &host);
    let publisher = match session
        .declare_publisher(ack_key.clone())
        .congestion_control(CongestionControl::Drop)
        .priority(zenoh::qos::Priority::InteractiveHigh)
        .await
    {
        Ok(p) => p,
        Err(e) => {
            tracing::warn!(stream = %keys::stream(&key), "cannot acknowledge: {e}");
            return;
        }
    };
    let instance = random_u64();
    let mut number = 0u64;
    loop {
        let closing = state.closing.load(std::sync::atomic::Ordering::Relaxed);
        let ack = state.ack();
        let payload = ack.encode();
        let envelope =
            Envelope { host: host.clone(), incarnation: instance, sequence: number, unfinished: false };
        let attachment = envelope.seal(&ack_key, &payload, secret.as_ref());
        number += 1;
        // Progress may be dropped under congestion (the next one says more); the end may not.
        let put = if ack.end {
            session
                .put(&ack_key, payload)
                .attachment(attachment)
                .congestion_control(CongestionControl::Block)
                .priority(zenoh::qos::Priority::InteractiveHigh)
                .await
        } else {
            publisher.put(payload).attachment(attachment).await
        };
        match put {
            Ok(()) => {
                if let Ok(mut sent) = state.sent.lock() {
                    *sent = ack;
                }
            }
            Err(e) => {
                if session.is_closed() {
                    return;
                }
                tracing::debug!("cannot acknowledge on `{ack_key}`: {e}");
            }
        }
        if closing && !ack.end {
            return;
        }
        tokio::select! {
            () = state.wake.notified() => {}
            () = tokio::time::sleep(crate::flow::HEARTBEAT) => {}
        }
        if session.is_closed() {
            return;
        }
    }
}

/// Receives one stream from another host.
pub struct ZenohReceiver {
    inbox: Arc<Inbox>,
    _data: Subscriber<()>,
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
    /// When to ask for the end again (while the producer is there and the stream open).
    next_end_query: Instant,
    /// When something last arrived, and when to say next what this host waits for.
    next_report: Instant,
    acks: Arc<AckState>,
    /// The position last told to the acknowledging task.
    acked: u64,
    window: u64,
    report: Arc<Mutex<InboundReport>>,
    _token: LivelinessToken,
}

impl Drop for ZenohReceiver {
    fn drop(&mut self) {
        self.acks.closing.store(true, std::sync::atomic::Ordering::Relaxed);
        self.acks.wake.notify_one();
    }
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

/// How often a receiver asks the producing host for the end while the stream is open.
const END_QUERY_EVERY: Duration = Duration::from_secs(2);
/// How long a receiver waits in silence before it says what it waits for (then again as long).
const SILENCE: Duration = Duration::from_secs(10);

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
        Self::declare_with(session, key, ty, host, None, report).await
    }

    /// As [`ZenohReceiver::declare`], accepting messages only from `producer_host` (when given),
    /// and counting into `report`.
    pub async fn declare_with(
        session: &HostSession,
        key: &StreamKey,
        ty: ValueType,
        host: &str,
        producer_host: Option<String>,
        report: Arc<Mutex<InboundReport>>,
    ) -> Result<ZenohReceiver, TransportError> {
        let key_expr = keys::stream(key);
        let error = |what: &str, e: zenoh::Error| TransportError(format!("{what} `{key_expr}`: {e}"));
        let window = session.options.queue.max(1);
        let inbox = Arc::new(Inbox {
            queue: Mutex::new(std::collections::VecDeque::new()),
            arrived: tokio::sync::Notify::new(),
            capacity: 2 * window + 64,
            dropped: std::sync::atomic::AtomicU64::new(0),
        });
        let secret = session.credentials.as_ref().map(|c| c.secret.clone());
        let acks = Arc::new(AckState::default());
        let (into, confirm, expected, tag_key, end_key) =
            (inbox.clone(), acks.clone(), producer_host.clone(), secret.clone(), key_expr.clone());
        let data = session
            .session
            .declare_subscriber(key_expr.clone())
            .callback(move |sample| {
                // The end is acknowledged as soon as it reaches this host, before the samples
                // queued ahead of it are taken: the producer need not wait for a slow consumer.
                let payload = sample.payload().to_bytes();
                if codec::is_end(&payload)
                    && let Some(expected) = &expected
                    && let Ok(envelope) = Envelope::open(
                        sample.attachment().map(|a| a.to_bytes()).as_deref(),
                        &end_key,
                        &payload,
                        tag_key.as_ref(),
                    )
                    && envelope.host == *expected
                    && !envelope.unfinished
                {
                    confirm.end(envelope.incarnation, envelope.sequence);
                }
                into.push(sample);
            })
            .await
            .map_err(|e| error("cannot subscribe to", e))?;
        let producers = session
            .session
            .liveliness()
            .declare_subscriber(keys::publisher_tokens(key))
            .history(true)
            .await
            .map_err(|e| error("cannot watch the producer of", e))?;
        tokio::spawn(acknowledge(
            session.session.clone(),
            key.clone(),
            host.to_string(),
            secret.clone(),
            acks.clone(),
        ));
        // Declared after the subscriber: a publisher that sees the token finds the subscriber.
        let token = session
            .session
            .liveliness()
            .declare_token(keys::subscriber_token(key, host))
            .await
            .map_err(|e| error("cannot declare the subscriber token of", e))?;
        let now = Instant::now();
        let mut receiver = ZenohReceiver {
            inbox,
            _data: data,
            producers: Some(producers),
            session: session.session.clone(),
            key: key.clone(),
            key_expr,
            ty,
            host: host.to_string(),
            producer_host,
            secret,
            sequence: Sequence::default(),
            messages: 0,
            presence: Presence::Never(now),
            give_up: session.options.give_up,
            end_query: None,
            next_end_query: now + END_QUERY_EVERY,
            next_report: now + SILENCE,
            acks,
            acked: 0,
            window: window as u64,
            report,
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
        self.next_end_query = Instant::now() + END_QUERY_EVERY;
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

    /// Copies what the sequence numbers say into the report.
    fn update_report(&self) {
        if let Ok(mut report) = self.report.lock() {
            report.lost = self.sequence.lost();
            report.producer_restarts = self.sequence.restarts();
            report.runs = self
                .sequence
                .runs()
                .iter()
                .map(|r| InboundRun {
                    incarnation: format!("{:016x}", r.incarnation),
                    joined_at: r.joined_at,
                    received: r.received,
                    lost: r.lost(),
                    ended: r.ended,
                })
                .collect();
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
            // Outside a deployment the envelope is not checked, but it still says how far the
            // stream went (for the acknowledgments).
            None => Envelope::open(attachment, &self.key_expr, payload, self.secret.as_ref()).ok(),
        };
        let decoded = codec::decode(payload, &self.ty);
        // A message from the producer that does not decode still takes its place in the stream.
        let is_end = matches!(decoded, Ok(Message::End { .. }));
        if let Some(envelope) = &envelope {
            if self.producer_host.is_some() {
                let lost_before = self.sequence.lost();
                match self.sequence.accept(envelope, is_end) {
                    Ok(accepted) => {
                        if accepted.restarted {
                            tracing::warn!(stream = %self.key_expr, "the producer started again");
                        }
                        let lost = self.sequence.lost();
                        if lost > lost_before {
                            tracing::warn!(stream = %self.key_expr, "{} sample(s) lost on the way", lost - lost_before);
                        }
                        self.update_report();
                    }
                    Err(refusal) => {
                        self.refuse(&refusal);
                        return Outcome::Skip;
                    }
                }
            }
            if !is_end {
                let position = envelope.sequence.saturating_add(1);
                self.acks.progress(envelope.incarnation, position);
                if position >= self.acked + self.window / 4 || position < self.acked {
                    self.acked = position;
                    self.acks.wake.notify_one();
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
                if let Some(envelope) = &envelope {
                    self.acks.end(envelope.incarnation, envelope.sequence);
                }
                Outcome::Deliver(Remote::End)
            }
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

    /// Says, after a silence, what this host is waiting for on this stream.
    fn report_silence(&mut self) {
        let producer = self.producer_host.clone().unwrap_or_default();
        let state = match self.presence {
            Presence::Never(since) => {
                format!(
                    "not seen yet ({:.0} s of {:.0} s)",
                    since.elapsed().as_secs_f64(),
                    self.give_up.as_secs_f64()
                )
            }
            Presence::Here => "up".to_string(),
            Presence::Gone(since) => {
                format!(
                    "away for {:.0} s of {:.0} s",
                    since.elapsed().as_secs_f64(),
                    self.give_up.as_secs_f64()
                )
            }
        };
        let received = self.report.lock().map(|r| r.received).unwrap_or(0);
        tracing::info!(
            "host `{}`: waiting for stream `{}` from host `{producer}` ({state}): {received} sample(s) so far, no end yet",
            self.host,
            self.key.stream_name()
        );
        self.next_report = Instant::now() + SILENCE;
    }
}

enum Event {
    Message(zenoh::sample::Sample),
    Token(Option<zenoh::sample::Sample>),
    Reply(Option<Reply>),
    GiveUp,
    AskForTheEnd,
    Silence,
}

impl RemoteReceiver for ZenohReceiver {
    fn recv(&mut self) -> BoxFuture<'_, Option<Remote>> {
        Box::pin(async move {
            loop {
                if let Some(message) = self.inbox.pop() {
                    self.next_report = Instant::now() + SILENCE;
                    if let Outcome::Deliver(remote) = self.handle(&message) {
                        return Some(remote);
                    }
                    continue;
                }
                let dropped = self.inbox.dropped.swap(0, std::sync::atomic::Ordering::Relaxed);
                if dropped > 0 {
                    tracing::warn!(stream = %self.key_expr, "{dropped} sample(s) dropped: more arrived than the window allows");
                }
                let give_up_at = match (self.producer_host.is_some(), self.presence) {
                    (true, Presence::Never(since) | Presence::Gone(since)) => Some(since + self.give_up),
                    _ => None,
                };
                let ask_at = (self.producer_host.is_some()
                    && matches!(self.presence, Presence::Here)
                    && self.end_query.is_none())
                .then_some(self.next_end_query);
                let report_at = self.producer_host.is_some().then_some(self.next_report);
                let inbox = self.inbox.clone();
                let arrived = inbox.arrived.notified();
                tokio::pin!(arrived);
                arrived.as_mut().enable();
                if !self.inbox.is_empty() {
                    continue;
                }
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
                let at = |when: Option<Instant>| async move {
                    match when {
                        Some(at) => tokio::time::sleep_until(at.into()).await,
                        None => std::future::pending().await,
                    }
                };
                let event = tokio::select! {
                    biased;
                    () = &mut arrived => match inbox.pop() {
                        Some(message) => Event::Message(message),
                        None => continue,
                    },
                    token = producers => Event::Token(token),
                    reply = replies => Event::Reply(reply),
                    () = at(give_up_at) => Event::GiveUp,
                    () = at(ask_at) => Event::AskForTheEnd,
                    () = at(report_at) => Event::Silence,
                };
                match event {
                    Event::Message(message) => {
                        self.next_report = Instant::now() + SILENCE;
                        if let Outcome::Deliver(remote) = self.handle(&message) {
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
                        if self.inbox.is_empty() {
                            return Some(self.cut_short());
                        }
                    }
                    Event::AskForTheEnd => self.query_end().await,
                    Event::Silence => self.report_silence(),
                }
            }
        })
    }
}

impl ZenohReceiver {
    fn handle(&mut self, message: &zenoh::sample::Sample) -> Outcome {
        let payload = message.payload().to_bytes();
        let attachment = message.attachment().map(|a| a.to_bytes());
        self.on_message(&payload, attachment.as_deref())
    }
}
