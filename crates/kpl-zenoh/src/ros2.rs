//! `ros2.subscribe` and `ros2.publish`: ROS 2 topics as streams, over zenoh as rmw_zenoh speaks
//! them (keys, the 33-byte attachment, CDR, liveliness tokens of a node and its endpoints; the
//! wire itself is `kpl-ros2`'s). docs/ros2.md describes both.
//!
//! ```kpl
//! source markers : list<VisionPercept> = ros2.subscribe(
//!   topic: "/tracker/markers", type: "visualization_msgs/msg/MarkerArray",
//!   each: "markers", identity: "id", map: ["pos = pose.position", "size = scale.x"])
//! sink cars = ros2.publish(onroad_car, topic: "/kpl/cars", type: "visualization_msgs/msg/MarkerArray",
//!   each: "markers", map: ["ns = symbol", "id = number", "pose.position = pos"])
//! ```
//!
//! A run's ROS 2 endpoints share one zenoh session per router (peer mode, connected to the
//! router, multicast scouting off), apart from the session of the streams between hosts: ROS 2's
//! graph is its own.

use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock, Weak};
use std::time::Duration;

use kpl_core::{Time, Value, ValueType};
use kpl_ros2::mapping::{InMap, MapError, OutMap};
use kpl_ros2::wire::{self, Attachment, EntityKind, Node, Qos};
use kpl_ros2::{Schema, topic};
use kpl_runtime::clock::ClockKind;
use kpl_runtime::context::SourceContext;
use kpl_runtime::process::{AsyncUnit, BoxFuture, Emitter, Input, ProcessError, Source};
use kpl_runtime::registry::{BuildContext, BuildError, Registry};
use kpl_semantic::registry::{CallTypes, Entry, EntryKind, Param, ParamProblem, ParamType, TypeReq};
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::Publisher;
use zenoh::qos::CongestionControl;
use zenoh::sample::SampleKind;

/// The router the command line names (`kpl run --ros2-router`), over a spec's `router`.
static ROUTER: OnceLock<Mutex<Option<String>>> = OnceLock::new();

/// Sets the router every ROS 2 endpoint of this process connects to (`kpl run --ros2-router`).
pub fn set_router(endpoint: Option<String>) {
    if let Ok(mut router) = ROUTER.get_or_init(|| Mutex::new(None)).lock() {
        *router = endpoint;
    }
}

fn command_line_router() -> Option<String> {
    ROUTER.get().and_then(|r| r.lock().ok()).and_then(|r| r.clone())
}

/// A year: how long a source without `--for` waits.
const FAR: Time = 365 * 24 * 3600 * 1_000_000;

fn common_params(entry: Entry) -> Entry {
    entry
        .param(Param::required("topic", ParamType::Str, "the ROS 2 topic (`/tracker/markers`; relative names are in `namespace`)"))
        .param(Param::required("type", ParamType::Str, "the message type, `package/msg/Name` (shipped, or in `msgs`)"))
        .param(Param::optional("each", ParamType::Str, Value::str(""), "an array of the message whose elements are the objects of a list stream (`markers`)"))
        .param(Param::optional("map", ParamType::List(Box::new(ParamType::Str)), Value::List(Arc::from(Vec::new())), "the mapping, one entry per field (docs/ros2.md)"))
        .param(Param::optional("domain", ParamType::Int, Value::Int(0), "the ROS 2 domain id"))
        .param(Param::optional("namespace", ParamType::Str, Value::str("/"), "the node's namespace"))
        .param(Param::optional("node", ParamType::Str, Value::str("kpl"), "the node's name, as ROS 2 tools list it"))
        .param(Param::optional("router", ParamType::Str, Value::str(""), "the zenoh router or peer to connect to (default: `kpl run --ros2-router`, else tcp/localhost:7447)"))
        .param(Param::optional("msgs", ParamType::Str, Value::str(""), "a folder of the user's own `.msg` files (`<package>/msg/<Name>.msg`), relative to the spec"))
        .param(Param::optional("reliability", ParamType::Choice(vec!["reliable".into(), "best_effort".into()]), Value::str("reliable"), "QoS reliability"))
        .param(Param::optional("durability", ParamType::Choice(vec!["volatile".into(), "transient_local".into()]), Value::str("volatile"), "QoS durability (transient_local is declared but not honoured: docs/ros2.md)"))
        .param(Param::optional("depth", ParamType::Int, Value::Int(10), "QoS history depth: messages kept while the run is busy (keep last)"))
}

/// Adds `ros2.subscribe` and `ros2.publish` to a registry (`kpl_std::assemble` does). Their
/// sessions are their own, one per router, apart from the session of the streams between hosts.
pub fn register(registry: &mut Registry) {
    registry.add_source(
        common_params(Entry::new(
            EntryKind::Source,
            "ros2.subscribe",
            "A ROS 2 topic over rmw_zenoh as a stream: CDR messages mapped into values (docs/ros2.md). Ends when the topic's publishers have gone for `idle`. Needs --clock wall.",
        ))
        .param(Param::optional("identity", ParamType::Str, Value::str(""), "the field that identifies an object (a track id): the record's symbol is the type's prefix and its value"))
        .param(Param::optional("stamp", ParamType::Str, Value::str(""), "the valid time: a builtin_interfaces/Time field (default `header.stamp`, else the arrival time)"))
        .param(Param::optional("idle", ParamType::Duration, Value::Duration(3_000_000), "end after the topic's last publisher has been gone this long"))
        .output(TypeReq::Any)
        .checked_by(check_subscribe),
        |ctx| {
            needs_wall_clock(ctx)?;
            let common = Common::new(ctx)?;
            let output = ctx.process.output.clone().unwrap_or(ValueType::Any);
            let spec = topic::in_spec(params(ctx));
            let map = InMap::compile(&common.schema, &spec, &output).map_err(|e| map_error(ctx, &e))?;
            let idle = match ctx.param("idle") {
                Some(Value::Duration(d)) => *d,
                _ => 3_000_000,
            };
            Ok(Box::new(Subscribe { common, map, idle }))
        },
    );
    registry.add_unit(
        common_params(Entry::new(
            EntryKind::Sink,
            "ros2.publish",
            "Publishes a stream as a ROS 2 topic over rmw_zenoh: values mapped into CDR messages (docs/ros2.md). Needs --clock wall.",
        ))
        .input("in", TypeReq::Any, "the stream to publish")
        .checked_by(check_publish),
        |ctx| {
            needs_wall_clock(ctx)?;
            let common = Common::new(ctx)?;
            let input = ctx.process.inputs.first().map_or(ValueType::Any, |i| i.stream.ty.clone());
            let spec = topic::out_spec(params(ctx));
            let map = OutMap::compile(common.schema.clone(), &spec, &input).map_err(|e| map_error(ctx, &e))?;
            Ok(Box::new(Publish { common, map, open: None, buffer: Vec::new(), published: 0, failures: 0 }))
        },
    );
}

/// `kpl check` of `ros2.subscribe`: its type (shipped, or of `msgs` beside the spec), and its
/// mapping against the type and the stream's.
fn check_subscribe(call: &CallTypes<'_>) -> Vec<ParamProblem> {
    let Some(output) = call.output else { return Vec::new() };
    topic::check_in(call.params, output, call.dir).err().map(topic::param_problem).into_iter().collect()
}

/// `kpl check` of `ros2.publish`: its type, and its mapping against the type and the input's.
fn check_publish(call: &CallTypes<'_>) -> Vec<ParamProblem> {
    let Some(input) = call.inputs.first() else { return Vec::new() };
    topic::check_out(call.params, input, call.dir).err().map(topic::param_problem).into_iter().collect()
}

fn needs_wall_clock(ctx: &BuildContext<'_>) -> Result<(), BuildError> {
    match ctx.clock {
        ClockKind::Wall => Ok(()),
        ClockKind::Sim => {
            Err(ctx
                .error("ROS 2 topics are exchanged with other programs in real time; run with --clock wall"))
        }
    }
}

/// The call's parameters (defaults filled in by the checker).
fn params<'c>(ctx: &'c BuildContext<'_>) -> &'c BTreeMap<String, Value> {
    static NONE: BTreeMap<String, Value> = BTreeMap::new();
    ctx.call().map_or(&NONE, |c| &c.params)
}

fn map_error(ctx: &BuildContext<'_>, e: &MapError) -> BuildError {
    ctx.error(topic::describe(params(ctx), e))
}

/// What both ends have: the topic, its type and the node.
pub(crate) struct Common {
    router: String,
    domain: u32,
    namespace: String,
    node: String,
    topic: String,
    schema: Arc<Schema>,
    hash: String,
    dds: String,
    qos: Qos,
}

impl Common {
    fn new(ctx: &BuildContext<'_>) -> Result<Common, BuildError> {
        let str_param = |name: &str| ctx.param(name).and_then(Value::as_str).unwrap_or("").to_string();
        let namespace = str_param("namespace");
        if !namespace.starts_with('/') || (namespace.len() > 1 && wire::check_topic(&namespace).is_err()) {
            return Err(
                ctx.error(format!("`namespace`: `{namespace}` is not a ROS 2 namespace (`/`, `/robot`)"))
            );
        }
        let topic = str_param("topic");
        wire::check_topic(&topic).map_err(|e| ctx.error(format!("`topic`: {e}")))?;
        let node = str_param("node");
        if wire::check_topic(&node).is_err() || node.contains('/') {
            return Err(ctx.error(format!("`node`: `{node}` is not a ROS 2 node name")));
        }
        let domain = ctx.param("domain").and_then(Value::as_i64).unwrap_or(0);
        let domain = u32::try_from(domain)
            .ok()
            .filter(|d| *d <= 232)
            .ok_or_else(|| ctx.error(format!("`domain`: {domain} is not a ROS 2 domain id (0 to 232)")))?;
        let schema = topic::schema_in(params(ctx), &ctx.input_path("")).map_err(|e| map_error(ctx, &e))?;
        let depth = ctx.param("depth").and_then(Value::as_i64).unwrap_or(10);
        let depth = u32::try_from(depth)
            .ok()
            .filter(|d| *d > 0)
            .ok_or_else(|| ctx.error(format!("`depth`: {depth} is not a history depth (1 or more)")))?;
        let qos = Qos {
            reliable: str_param("reliability") != "best_effort",
            transient_local: str_param("durability") == "transient_local",
            depth: Some(depth),
        };
        let router = command_line_router()
            .or_else(|| Some(str_param("router")).filter(|r| !r.is_empty()))
            .unwrap_or_else(|| wire::DEFAULT_ROUTER.to_string());
        Ok(Common {
            router,
            domain,
            topic: wire::qualify(&namespace, &topic),
            namespace,
            node,
            hash: schema.type_hash(),
            dds: schema.name().dds_name(),
            schema,
            qos,
        })
    }

    /// A topic of a shipped type, reliable with history `depth`, on node `node` in `/` of domain
    /// 0 (`kpl bench ros2`'s topics).
    pub(crate) fn shipped(topic: &str, type_name: &str, node: &str, depth: u32) -> Result<Common, String> {
        let schema = kpl_ros2::Definitions::builtin().schema_of(type_name).map_err(|e| e.to_string())?;
        Ok(Common {
            router: String::new(),
            domain: 0,
            namespace: "/".into(),
            node: node.into(),
            topic: topic.into(),
            hash: schema.type_hash(),
            dds: schema.name().dds_name(),
            schema,
            qos: Qos { reliable: true, transient_local: false, depth: Some(depth) },
        })
    }

    pub(crate) fn schema(&self) -> &Arc<Schema> {
        &self.schema
    }

    /// The data key of the topic's messages of this type.
    pub(crate) fn data_key(&self) -> String {
        wire::topic_key(self.domain, &self.topic, &self.dds, &self.hash)
    }

    /// Why a message on data key `key` is refused when that key's type hash is not the type's.
    fn hash_refusal(&self, key: &str) -> String {
        let hash = key.rsplit('/').next().unwrap_or("");
        format!("type hash {hash}, expected {} ({})", self.hash, self.schema.name())
    }

    fn warn_qos(&self, warn: impl Fn(String)) {
        if self.qos.transient_local {
            warn(format!(
                "`{}`: durability transient_local is declared in the graph but not honoured (kpl keeps no history for late subscribers and asks none of publishers)",
                self.topic
            ));
        }
    }
}

/// A node: its domain, namespace and name.
type NodeKey = (u32, String, String);

/// A zenoh session for ROS 2, shared by the endpoints of a run that use the same router, with
/// the nodes declared on it.
pub(crate) struct Ros2Session {
    pub(crate) session: zenoh::Session,
    zid: String,
    next_id: AtomicU64,
    /// The declared nodes by (domain, namespace, name): their ids and tokens.
    nodes: tokio::sync::Mutex<HashMap<NodeKey, (u64, LivelinessToken)>>,
}

impl Ros2Session {
    async fn open(router: &str) -> Result<Arc<Ros2Session>, ProcessError> {
        static OPEN: OnceLock<tokio::sync::Mutex<HashMap<String, Weak<Ros2Session>>>> = OnceLock::new();
        let mut open = OPEN.get_or_init(Default::default).lock().await;
        if let Some(session) = open.get(router).and_then(Weak::upgrade) {
            return Ok(session);
        }
        let mut config = zenoh::Config::default();
        let json = |s: &str| serde_json::Value::String(s.to_string()).to_string();
        for (key, value) in [
            ("mode", json("peer")),
            ("connect/endpoints", format!("[{}]", json(router))),
            ("listen/endpoints", "[]".to_string()),
            ("scouting/multicast/enabled", "false".to_string()),
            (
                "connect/retry",
                "{ period_init_ms: 100, period_max_ms: 1000, period_increase_factor: 2.0 }".to_string(),
            ),
        ] {
            config
                .insert_json5(key, &value)
                .map_err(|e| ProcessError::failed(format!("cannot set zenoh's `{key}` to {value}: {e}")))?;
        }
        let session = crate::session::open_off_thread(config)
            .await
            .map_err(|e| ProcessError::failed(format!("cannot connect to the ROS 2 router {router}: {e}")))?;
        tracing::info!(router, "ROS 2 session open");
        let zid = session.zid().to_string();
        let session =
            Arc::new(Ros2Session { session, zid, next_id: AtomicU64::new(0), nodes: Default::default() });
        open.insert(router.to_string(), Arc::downgrade(&session));
        Ok(session)
    }

    /// ROS 2 endpoints on a session of the caller's (`kpl bench ros2`'s, between its two
    /// processes), not shared with a run's.
    pub(crate) fn over(session: zenoh::Session) -> Arc<Ros2Session> {
        let zid = session.zid().to_string();
        Arc::new(Ros2Session { session, zid, next_id: AtomicU64::new(0), nodes: Default::default() })
    }

    fn next_id(&self) -> u64 {
        self.next_id.fetch_add(1, Ordering::Relaxed)
    }

    /// The node, declared (its liveliness token) the first time.
    async fn node(&self, common: &Common) -> Result<Node, ProcessError> {
        let mut nodes = self.nodes.lock().await;
        let key = (common.domain, common.namespace.clone(), common.node.clone());
        let node_id =
            match nodes.get(&key) {
                Some((id, _)) => *id,
                None => {
                    let id = self.next_id();
                    let node = self.describe_node(common, id);
                    let token =
                        self.session.liveliness().declare_token(node.token()).await.map_err(|e| {
                            ProcessError::failed(format!("cannot declare the ROS 2 node: {e}"))
                        })?;
                    nodes.insert(key, (id, token));
                    id
                }
            };
        Ok(self.describe_node(common, node_id))
    }

    fn describe_node(&self, common: &Common, node_id: u64) -> Node {
        Node {
            domain: common.domain,
            session_id: self.zid.clone(),
            node_id,
            namespace: common.namespace.clone(),
            name: common.node.clone(),
        }
    }

    pub(crate) async fn endpoint_token(
        &self,
        common: &Common,
        kind: EntityKind,
    ) -> Result<(u64, LivelinessToken), ProcessError> {
        let node = self.node(common).await?;
        let id = self.next_id();
        let key = node.endpoint_token(id, kind, &common.topic, &common.dds, &common.hash, &common.qos);
        let token = self.session.liveliness().declare_token(key).await.map_err(|e| {
            ProcessError::failed(format!("cannot declare the ROS 2 endpoint of `{}`: {e}", common.topic))
        })?;
        Ok((id, token))
    }
}

struct Subscribe {
    common: Common,
    map: InMap,
    idle: Time,
}

/// The lost messages of each publisher (by GID): gaps in its sequence numbers.
#[derive(Default)]
struct Sequences {
    last: HashMap<[u8; 16], i64>,
    lost: u64,
}

impl Sequences {
    fn see(&mut self, a: &Attachment) {
        if let Some(last) = self.last.insert(a.gid, a.sequence_number)
            && a.sequence_number > last + 1
        {
            self.lost += (a.sequence_number - last - 1) as u64;
        }
    }
}

impl Source for Subscribe {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let c = &self.common;
            c.warn_qos(|w| ctx.warn(w));
            let session = Ros2Session::open(&c.router).await?;
            let depth = c.qos.depth.unwrap_or(1000) as usize;
            // The exact key, as rmw_zenoh subscribes: a wildcard for the type hash made zenoh
            // route every message anew (a quarter of the throughput; docs/performance.md).
            // Publishers of another type are found by their tokens (`OtherTypes`).
            let subscriber = session
                .session
                .declare_subscriber(c.data_key())
                .with(zenoh::handlers::RingChannel::new(depth))
                .await
                .map_err(|e| ProcessError::failed(format!("cannot subscribe to `{}`: {e}", c.topic)))?;
            let publishers_key =
                format!("{}/{}/*/*/*/MP/*/*/*/{}/**", wire::ADMIN_SPACE, c.domain, wire::mangle(&c.topic));
            let publishers = session
                .session
                .liveliness()
                .declare_subscriber(&publishers_key)
                .history(true)
                .await
                .map_err(|e| {
                    ProcessError::failed(format!("cannot watch the publishers of `{}`: {e}", c.topic))
                })?;
            let (_id, _token) = session.endpoint_token(c, EntityKind::Subscription).await?;
            let mut others = OtherTypes::new();
            let mut alive: HashMap<String, ()> = HashMap::new();
            let mut seen_publisher = false;
            let mut gone_since: Option<Time> = None;
            let mut sequences = Sequences::default();
            let (mut messages, mut wrong_type, mut no_attachment) = (0u64, 0u64, 0u64);
            loop {
                let far = ctx.end().unwrap_or_else(|| ctx.now().saturating_add(FAR));
                let until = match gone_since {
                    Some(t) => far.min(t + self.idle),
                    None => far,
                };
                tokio::select! {
                    biased;
                    token = publishers.recv_async() => {
                        let Ok(token) = token else { break };
                        match token.kind() {
                            SampleKind::Put => {
                                if let Some(warning) = others.see(&session, c, token.key_expr().as_str()).await {
                                    ctx.warn(warning);
                                }
                                alive.insert(token.key_expr().to_string(), ());
                                seen_publisher = true;
                                gone_since = None;
                            }
                            SampleKind::Delete => {
                                alive.remove(token.key_expr().as_str());
                                if alive.is_empty() {
                                    gone_since = Some(ctx.now());
                                }
                            }
                        }
                    }
                    message = subscriber.recv_async() => {
                        let Ok(message) = message else { break };
                        messages += 1;
                        let where_ = || format!("ROS 2 `{}`, message {messages}", c.topic);
                        let (attachment, taken) = take(c, &self.map, &message, ctx.now());
                        if let Some(attachment) = &attachment {
                            sequences.see(attachment);
                        }
                        match taken {
                            Ok((valid, value)) => {
                                if ctx.end().is_some_and(|end| ctx.now() > end) {
                                    break;
                                }
                                ctx.emit(valid, value).await;
                                if ctx.unconsumed() {
                                    break;
                                }
                            }
                            Err(Refused::Attachment(e)) => {
                                no_attachment += 1;
                                ctx.malformed(where_(), e)?;
                            }
                            Err(Refused::TypeHash(e)) => {
                                wrong_type += 1;
                                ctx.malformed(where_(), e)?;
                            }
                            Err(Refused::Malformed(e)) => ctx.malformed(where_(), e)?,
                        }
                    }
                    Some(key) = others.messages.recv() => {
                        messages += 1;
                        wrong_type += 1;
                        ctx.malformed(format!("ROS 2 `{}`, message {messages}", c.topic), c.hash_refusal(&key))?;
                    }
                    _ = ctx.wait_until(until) => {
                        if gone_since.is_some() || ctx.should_stop() || ctx.end().is_some_and(|end| ctx.now() >= end) {
                            break;
                        }
                    }
                }
                if ctx.should_stop() {
                    break;
                }
            }
            for _ in 0..others.overflow.load(Ordering::Relaxed) {
                messages += 1;
                wrong_type += 1;
                ctx.malformed(
                    format!("ROS 2 `{}`", c.topic),
                    "a message of a publisher of another type hash, counted while kpl was busy",
                )?;
            }
            if sequences.lost > 0 {
                ctx.warn(format!("`{}`: {} message(s) lost before kpl took them (gaps in the publishers' sequence numbers; raise `depth`)", c.topic, sequences.lost));
            }
            ctx.stats.result("ROS 2 messages received", messages);
            if wrong_type + no_attachment > 0 {
                ctx.stats
                    .result("ROS 2 messages refused (type hash, attachment)", wrong_type + no_attachment);
            }
            if !seen_publisher {
                ctx.warn(format!("`{}`: no ROS 2 publisher was seen", c.topic));
            }
            Ok(())
        })
    }
}

/// The publishers of a subscription's topic whose tokens declare another type (hash) than its
/// own: rmw_zenoh would not match them, kpl subscribes to each one's exact data key (at most
/// [`OtherTypes::MAX`]) so that their messages are counted as refused, and says so once per type.
struct OtherTypes {
    subscribers: HashMap<String, zenoh::pubsub::Subscriber<()>>,
    sender: tokio::sync::mpsc::Sender<String>,
    /// The data keys of their messages, as they come.
    messages: tokio::sync::mpsc::Receiver<String>,
    /// Messages that came while `messages` was full.
    overflow: Arc<AtomicU64>,
}

impl OtherTypes {
    const MAX: usize = 16;

    fn new() -> OtherTypes {
        let (sender, messages) = tokio::sync::mpsc::channel(256);
        OtherTypes { subscribers: HashMap::new(), sender, messages, overflow: Arc::default() }
    }

    /// A publisher's token: a warning when it declares a type kpl had not seen on the topic.
    async fn see(&mut self, session: &Ros2Session, c: &Common, token: &str) -> Option<String> {
        let (dds, hash) = wire::token_type(token)?;
        if hash == c.hash {
            return None;
        }
        let key = wire::topic_key(c.domain, &c.topic, dds, hash);
        if self.subscribers.contains_key(&key) {
            return None;
        }
        if self.subscribers.len() >= OtherTypes::MAX {
            return Some(format!(
                "`{}`: a publisher of type {dds} with type hash {hash}: its messages are not counted (more than {} types on the topic)",
                c.topic,
                OtherTypes::MAX
            ));
        }
        let (sender, overflow) = (self.sender.clone(), self.overflow.clone());
        let declared = session
            .session
            .declare_subscriber(&key)
            .callback(move |sample| {
                if sender.try_send(sample.key_expr().to_string()).is_err() {
                    overflow.fetch_add(1, Ordering::Relaxed);
                }
            })
            .await;
        let why = match declared {
            Ok(subscriber) => {
                self.subscribers.insert(key, subscriber);
                "its messages are refused and counted"
            }
            Err(_) => "kpl cannot count its messages",
        };
        Some(format!(
            "`{}`: a publisher of type {dds} with type hash {hash}, but {} has type hash {}: {why}",
            c.topic,
            c.schema.name(),
            c.hash
        ))
    }
}

/// Why a message from the wire is not a sample.
pub(crate) enum Refused {
    /// No attachment, or not rmw_zenoh's 33 bytes.
    Attachment(String),
    /// The key's type hash is not the declared type's.
    TypeHash(String),
    /// The CDR does not decode as the type, or the mapping cannot take the message.
    Malformed(String),
}

/// What `ros2.subscribe` makes of one message from the wire: its attachment (when it has one),
/// and its valid time and value, read from the CDR by the mapping's decode plan (`InMap::decode`),
/// or why not. `now` is the valid time of a message whose mapping has no stamp.
pub(crate) fn take(
    c: &Common,
    map: &InMap,
    message: &zenoh::sample::Sample,
    now: Time,
) -> (Option<Attachment>, Result<(Time, Value), Refused>) {
    let attachment = match message.attachment().map(|a| a.to_bytes()) {
        None => Err(wire::AttachmentError::Missing),
        Some(bytes) => Attachment::decode(&bytes),
    };
    let attachment = match attachment {
        Ok(a) => a,
        Err(e) => {
            let why = format!("{e} (rmw_zenoh sends 33 bytes: sequence number, time stamp, GID)");
            return (None, Err(Refused::Attachment(why)));
        }
    };
    let key = message.key_expr().as_str();
    if !key.ends_with(&c.hash) {
        return (Some(attachment), Err(Refused::TypeHash(c.hash_refusal(key))));
    }
    let payload = message.payload().to_bytes();
    let taken = map.decode(&payload).map_err(Refused::Malformed).map(|(valid, value)| {
        let valid =
            valid.unwrap_or_else(|| if map.has_stamp() { attachment.source_timestamp / 1000 } else { now });
        (valid, value)
    });
    (Some(attachment), taken)
}

/// A declared ROS 2 publisher: its liveliness token, GID and sequence numbers.
pub(crate) struct Open {
    _session: Arc<Ros2Session>,
    publisher: Publisher<'static>,
    _token: LivelinessToken,
    gid: [u8; 16],
    sequence: i64,
}

impl Open {
    /// Declares the publisher of `c`'s topic (and its node's and its own liveliness tokens).
    pub(crate) async fn declare(session: Arc<Ros2Session>, c: &Common) -> Result<Open, ProcessError> {
        let publisher = session
            .session
            .declare_publisher(c.data_key())
            .congestion_control(if c.qos.reliable {
                CongestionControl::Block
            } else {
                CongestionControl::Drop
            })
            .await
            .map_err(|e| ProcessError::failed(format!("cannot publish on `{}`: {e}", c.topic)))?;
        let (id, token) = session.endpoint_token(c, EntityKind::Publisher).await?;
        let gid = wire::gid(&session.zid, id);
        Ok(Open { _session: session, publisher, _token: token, gid, sequence: 0 })
    }

    pub(crate) fn publisher(&self) -> &Publisher<'static> {
        &self.publisher
    }

    /// Puts one CDR message with its attachment: the next sequence number, `now` (microseconds)
    /// as the source time stamp and the publisher's GID.
    pub(crate) async fn put(&mut self, payload: &[u8], now: Time) -> zenoh::Result<()> {
        self.sequence += 1;
        let attachment = Attachment {
            sequence_number: self.sequence,
            source_timestamp: now.saturating_mul(1000),
            gid: self.gid,
        };
        self.publisher.put(payload.to_vec()).attachment(attachment.encode().to_vec()).await
    }
}

/// What `ros2.publish` does with a sample before it goes on the wire: its value written as the
/// CDR of its message (`valid` its stamp) into `buffer` by the mapping's encode plan
/// (`OutMap::encode_into`).
pub(crate) fn encode(
    c: &Common,
    map: &mut OutMap,
    valid: Time,
    value: &Value,
    buffer: &mut Vec<u8>,
) -> Result<(), ProcessError> {
    map.encode_into(valid, value, buffer).map_err(|e| ProcessError::failed(format!("`{}`: {e}", c.topic)))
}

struct Publish {
    common: Common,
    map: OutMap,
    open: Option<Open>,
    buffer: Vec<u8>,
    published: u64,
    failures: u64,
}

impl Publish {
    async fn open(&mut self) -> Result<&mut Open, ProcessError> {
        if self.open.is_none() {
            let session = Ros2Session::open(&self.common.router).await?;
            self.open = Some(Open::declare(session, &self.common).await?);
        }
        self.open.as_mut().ok_or_else(|| ProcessError::failed("no publisher"))
    }
}

impl AsyncUnit for Publish {
    fn on_input<'a>(
        &'a mut self,
        input: &'a Input<'a>,
        _out: &'a mut Emitter,
    ) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let Some((_, sample)) = input.trigger_sample() else { return Ok(()) };
            let mut buffer = std::mem::take(&mut self.buffer);
            encode(&self.common, &mut self.map, sample.valid, &sample.value, &mut buffer)?;
            let topic = self.common.topic.clone();
            let result = self.open().await?.put(&buffer, input.now).await;
            self.buffer = buffer;
            if let Err(e) = result {
                self.failures += 1;
                return Err(ProcessError::failed(format!("cannot publish on `{topic}`: {e}")));
            }
            self.published += 1;
            Ok(())
        })
    }

    fn on_end<'a>(&'a mut self, _out: &'a mut Emitter) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            // Give subscribers a moment to take the last messages before the tokens go.
            if self.open.is_some() {
                tokio::time::sleep(Duration::from_millis(200)).await;
            }
            self.open = None;
            if self.failures > 0 {
                return Err(ProcessError::failed(format!(
                    "{} message(s) could not be published on `{}`",
                    self.failures, self.common.topic
                )));
            }
            Ok(())
        })
    }
}
