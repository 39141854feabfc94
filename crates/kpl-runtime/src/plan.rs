//! The plan of a run on one host, between the checked spec and the runtime: which processes run
//! here (and as what), every edge into them with the policy its consumer applies and the bound of
//! its queue, the streams this host publishes to other hosts, and those it subscribes to. It is
//! built without tokio ([`Plan::new`]) and printed as text ([`Plan::render`]), so how a spec is
//! wired is tested from data (`crates/kpl-runtime/tests/plans.rs`: `specs/plan/NAME.kpl` beside
//! `NAME.plan`); [`crate::run::run_async`] executes a plan.
//!
//! ```
//! use kpl_runtime::plan::{Plan, Target};
//! let registry = kpl_runtime::Registry::with_builtins();
//! let spec = kpl_semantic::check_text(
//!     "source ticks : int = timer(period: 100ms)\n\
//!      stream slow = ticks with sample every 1s\n\
//!      sink out = console(slow)\n",
//!     registry.signatures(),
//! )
//! .unwrap();
//! let plan = Plan::new(&spec, &Target::all("demo")).unwrap();
//! assert_eq!(plan.processes.len(), 2);
//! assert!(plan.render(&spec).contains("edge slow: ticks.out -> out.in0 (use most recent, sample every 1s"));
//! ```

use std::collections::BTreeMap;
use std::fmt::Write as _;

use kpl_semantic::hir::{self, ProcessId};
use kpl_syntax::ast::Overflow;

use crate::transport::StreamKey;

/// Which part of a spec a run executes, and how its streams between hosts are named.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Target {
    /// One host of the deploy section (`--host`), or `None` for every process.
    pub host: Option<String>,
    /// The deployment's name (part of every stream key).
    pub deployment: String,
    /// The spec's name (its file stem), part of every stream key.
    pub spec_name: String,
}

impl Target {
    /// Every process of the spec, on this host alone.
    pub fn all(spec_name: &str) -> Target {
        Target {
            host: None,
            deployment: crate::run::DEFAULT_DEPLOYMENT.to_string(),
            spec_name: spec_name.to_string(),
        }
    }
}

/// Why a spec cannot be planned for a target.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PlanError {
    #[error("--host {0}: the spec has no deploy section")]
    NoDeploySection(String),
    #[error("--host {host}: the deploy section has the hosts {known}")]
    UnknownHost { host: String, known: String },
}

/// How a planned process is built from the registry.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Role {
    Source {
        entry: String,
    },
    Compute {
        entry: String,
    },
    Sink {
        entry: String,
    },
    /// A link process (the registry's link-process factory).
    Link {
        via: String,
    },
    /// A monitor, built by the runtime itself.
    Monitor,
    /// A chronicle's recogniser (the registry's chronicle factory).
    Chronicle,
}

/// A process that runs on this host.
#[derive(Debug, Clone)]
pub struct PlannedProcess {
    pub id: ProcessId,
    pub name: String,
    pub role: Role,
    /// Output ports: the default one and the named ones, in this order.
    pub ports: Vec<String>,
}

/// Where an edge's samples come from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Origin {
    /// A process on this host, at one of its output ports.
    Local { producer: ProcessId, port: usize },
    /// Another host, by the stream's key ([`Plan::subscriptions`] feeds it).
    Remote { key: StreamKey },
}

/// A stream into a local consumer's input, with its consumer's policy.
#[derive(Debug, Clone)]
pub struct Edge {
    /// The stream's name as the spec writes it.
    pub stream: String,
    pub consumer: ProcessId,
    /// The consumer's input this edge is, in the order of its inputs.
    pub input: usize,
    pub origin: Origin,
    pub policy: hir::Policy,
    /// The queue's bound and what happens when it is full (a feedback edge drops its oldest
    /// sample rather than block the cycle it closes).
    pub capacity: usize,
    pub overflow: Overflow,
}

/// A local stream that processes on other hosts consume.
#[derive(Debug, Clone)]
pub struct Publication {
    pub producer: ProcessId,
    pub port: usize,
    pub key: StreamKey,
}

/// A stream from another host and the local edges it feeds.
#[derive(Debug, Clone)]
pub struct Subscription {
    pub key: StreamKey,
    /// Indices into [`Plan::edges`].
    pub edges: Vec<usize>,
}

/// What one host runs (see the module doc).
#[derive(Debug, Clone)]
pub struct Plan {
    pub target: Target,
    /// The local processes, in the spec's order.
    pub processes: Vec<PlannedProcess>,
    /// Every input of every local process, consumer by consumer (in the deploy section's order of
    /// the host's processes, which is the order a producer hands a sample to its consumers).
    pub edges: Vec<Edge>,
    pub publications: Vec<Publication>,
    pub subscriptions: Vec<Subscription>,
}

impl Plan {
    /// The plan of `target` for a checked spec.
    pub fn new(spec: &hir::Spec, target: &Target) -> Result<Plan, PlanError> {
        let local = local_processes(spec, target.host.as_deref())?;
        let local_set: std::collections::BTreeSet<ProcessId> = local.iter().copied().collect();
        let is_local = |id: ProcessId| local_set.contains(&id);
        let key = |producer: ProcessId, port: Option<&str>| StreamKey {
            deployment: target.deployment.clone(),
            spec: target.spec_name.clone(),
            producer: spec.processes[producer].name.clone(),
            port: port.map(str::to_string),
        };

        let processes = local_set.iter().map(|&id| planned_process(&spec.processes[id])).collect();

        let mut edges = Vec::new();
        let mut subscriptions: BTreeMap<StreamKey, Vec<usize>> = BTreeMap::new();
        for &consumer in &local {
            for (input, stream_input) in spec.processes[consumer].inputs.iter().enumerate() {
                let stream = &stream_input.stream;
                let policy = stream.policy.clone();
                let overflow = if policy.feedback { Overflow::DropOldest } else { policy.queue.overflow };
                let capacity = usize::try_from(policy.queue.capacity).unwrap_or(usize::MAX);
                let origin = if is_local(stream.producer) {
                    let port = port_index(&spec.processes[stream.producer], stream.port.as_deref());
                    Origin::Local { producer: stream.producer, port }
                } else {
                    let key = key(stream.producer, stream.port.as_deref());
                    subscriptions.entry(key.clone()).or_default().push(edges.len());
                    Origin::Remote { key }
                };
                edges.push(Edge {
                    stream: stream.name.clone(),
                    consumer,
                    input,
                    origin,
                    policy,
                    capacity,
                    overflow,
                });
            }
        }

        // Streams produced here and consumed on another host: one publication each, however
        // many remote consumers it has.
        let mut published = std::collections::BTreeSet::new();
        for consumer in spec.processes.iter().filter(|p| !is_local(p.id)) {
            for input in &consumer.inputs {
                if is_local(input.stream.producer) {
                    published.insert((input.stream.producer, input.stream.port.clone()));
                }
            }
        }
        let publications = published
            .into_iter()
            .map(|(producer, port)| Publication {
                producer,
                port: port_index(&spec.processes[producer], port.as_deref()),
                key: key(producer, port.as_deref()),
            })
            .collect();

        Ok(Plan {
            target: target.clone(),
            processes,
            edges,
            publications,
            subscriptions: subscriptions
                .into_iter()
                .map(|(key, edges)| Subscription { key, edges })
                .collect(),
        })
    }

    /// Whether this host exchanges streams with another one.
    pub fn needs_transport(&self) -> bool {
        !self.publications.is_empty() || !self.subscriptions.is_empty()
    }

    /// The plan as text, one line per process, edge, publication and subscription, every
    /// policy in full: what the data-driven tests compare.
    pub fn render(&self, spec: &hir::Spec) -> String {
        let name = |id: ProcessId| spec.processes[id].name.as_str();
        let mut out = String::new();
        let host = self.target.host.as_deref().unwrap_or("(every process)");
        let _ = writeln!(
            out,
            "host {host}, deployment {}, spec {}",
            self.target.deployment, self.target.spec_name
        );
        for process in &self.processes {
            let role = match &process.role {
                Role::Source { entry } => format!("source {entry}"),
                Role::Compute { entry } => format!("compute {entry}"),
                Role::Sink { entry } => format!("sink {entry}"),
                Role::Link { via } => format!("link via {via}"),
                Role::Monitor => "monitor".to_string(),
                Role::Chronicle => "chronicle".to_string(),
            };
            let _ = writeln!(out, "process {}: {role}; outputs [{}]", process.name, process.ports.join(", "));
        }
        for edge in &self.edges {
            let consumer = &spec.processes[edge.consumer];
            let port = consumer.inputs.get(edge.input).map_or("?", |i| i.port.as_str());
            let from = match &edge.origin {
                Origin::Local { producer, port } => {
                    let ports = &self.processes.iter().find(|p| p.id == *producer).map(|p| &p.ports);
                    let port_name = ports.and_then(|p| p.get(*port)).map_or("?", String::as_str);
                    format!("{}.{port_name}", name(*producer))
                }
                Origin::Remote { key } => format!("remote {}/{key}", key.deployment),
            };
            // The queue as the policy gives it, unless the edge overrides it (feedback).
            let queue = if edge.overflow == edge.policy.queue.overflow {
                String::new()
            } else {
                format!("; as a feedback edge: queue {} {}", edge.capacity, overflow_name(edge.overflow))
            };
            let _ = writeln!(
                out,
                "edge {}: {from} -> {}.{port} ({}{queue})",
                edge.stream,
                consumer.name,
                edge.policy.describe(),
            );
        }
        for publication in &self.publications {
            let _ = writeln!(
                out,
                "publish {}/{} from {}",
                publication.key.deployment,
                publication.key,
                name(publication.producer)
            );
        }
        for subscription in &self.subscriptions {
            let streams: Vec<String> = subscription
                .edges
                .iter()
                .map(|&i| {
                    let edge = &self.edges[i];
                    let consumer = &spec.processes[edge.consumer];
                    let port = consumer.inputs.get(edge.input).map_or("?", |i| i.port.as_str());
                    format!("{}.{port}", consumer.name)
                })
                .collect();
            let _ = writeln!(
                out,
                "subscribe {}/{} into {}",
                subscription.key.deployment,
                subscription.key,
                streams.join(", ")
            );
        }
        out
    }
}

fn overflow_name(overflow: Overflow) -> &'static str {
    match overflow {
        Overflow::Block => "block",
        Overflow::DropOldest => "drop oldest",
    }
}

fn planned_process(process: &hir::Process) -> PlannedProcess {
    let role = match &process.kind {
        hir::ProcessKind::Source(call) => Role::Source { entry: call.entry.clone() },
        hir::ProcessKind::Compute(call) => Role::Compute { entry: call.entry.clone() },
        hir::ProcessKind::Sink(call) => Role::Sink { entry: call.entry.clone() },
        hir::ProcessKind::Link(link) => Role::Link { via: link.via.entry.clone() },
        hir::ProcessKind::Monitor(_) => Role::Monitor,
        hir::ProcessKind::Chronicle(_) => Role::Chronicle,
    };
    let mut ports = vec!["out".to_string()];
    ports.extend(process.ports.iter().map(|(n, _)| n.clone()));
    PlannedProcess { id: process.id, name: process.name.clone(), role, ports }
}

/// The processes this run executes: all in the spec's order, or one host's in its deploy
/// section's order.
fn local_processes(spec: &hir::Spec, host: Option<&str>) -> Result<Vec<ProcessId>, PlanError> {
    let Some(host) = host else { return Ok((0..spec.processes.len()).collect()) };
    let deploy = spec.deploy.as_ref().ok_or_else(|| PlanError::NoDeploySection(host.to_string()))?;
    match deploy.hosts.iter().find(|h| h.name == host) {
        Some(h) => Ok(h.processes.clone()),
        None => Err(PlanError::UnknownHost {
            host: host.to_string(),
            known: deploy.hosts.iter().map(|h| h.name.as_str()).collect::<Vec<_>>().join(", "),
        }),
    }
}

/// The index of an output port: 0 for the default output, else 1 + the named port's position.
pub(crate) fn port_index(process: &hir::Process, port: Option<&str>) -> usize {
    match port {
        None => 0,
        Some(name) => process.ports.iter().position(|(n, _)| n == name).map_or(0, |i| i + 1),
    }
}
