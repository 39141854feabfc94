//! Streams between hosts. The runtime knows only these traits; `kpl-zenoh` implements them over
//! zenoh (the only crate that depends on zenoh). A stream is identified by a [`StreamKey`]; the
//! transport turns it into its own addresses (key expressions) and encodes samples on the wire
//! with their valid and available times.
//!
//! Hosts come and go: a receiver does not end its stream when the producing host goes away, only
//! when the producer ends it ([`Remote::End`]) or when the transport gives up on the producing
//! host ([`Remote::CutShort`]). What happened between the hosts (who was up, what was lost,
//! refused or cut short) is the transport's [`TransportReport`], part of the run's report.

use std::sync::Arc;

use serde::Serialize;

use crate::process::BoxFuture;
use crate::sample::Sample;
use crate::stats::Malformed;

/// Which stream: a producer's output in one spec, in one deployment of it.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct StreamKey {
    /// The deployment's name: deployments of one spec never exchange samples.
    pub deployment: String,
    /// The spec's name (its file stem).
    pub spec: String,
    /// The producing process.
    pub producer: String,
    /// A named output, or `None` for the default one.
    pub port: Option<String>,
}

impl StreamKey {
    /// How the stream is named in reports: `producer` or `producer.port`.
    pub fn stream_name(&self) -> String {
        match &self.port {
            Some(port) => format!("{}.{port}", self.producer),
            None => self.producer.clone(),
        }
    }
}

impl std::fmt::Display for StreamKey {
    /// `spec/producer` or `spec/producer.port`: the stream as the spec names it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.port {
            None => write!(f, "{}/{}", self.spec, self.producer),
            Some(port) => write!(f, "{}/{}.{port}", self.spec, self.producer),
        }
    }
}

/// What arrives from another host.
#[derive(Debug, Clone, PartialEq)]
pub enum Remote {
    Sample(Sample),
    /// The producer ended the stream.
    End,
    /// The transport gave up on the stream (its producing host is gone, or never came): the
    /// input ends here, and the run says it was cut short.
    CutShort(String),
    /// Bytes that do not decode: counted as malformed input, with where they came from.
    Malformed {
        location: String,
        error: String,
    },
}

/// Publishes one stream to other hosts.
pub trait RemoteSender: Send + Sync {
    fn send<'a>(&'a mut self, sample: &'a Sample) -> BoxFuture<'a, ()>;
    /// Tells the subscribers the stream has ended: `finished` when the producer is done, not
    /// when its run was interrupted (then the consumers wait for the producing host to come
    /// back, as after a crash).
    fn end(&mut self, finished: bool) -> BoxFuture<'_, ()>;
}

/// Receives one stream from another host.
pub trait RemoteReceiver: Send {
    /// `None` when the transport is closed.
    fn recv(&mut self) -> BoxFuture<'_, Option<Remote>>;
}

/// Opens remote streams; one per host process.
pub trait Transport: Send + Sync {
    fn publisher<'a>(
        &'a self,
        key: &'a StreamKey,
    ) -> BoxFuture<'a, Result<Box<dyn RemoteSender>, TransportError>>;
    fn subscriber<'a>(
        &'a self,
        key: &'a StreamKey,
    ) -> BoxFuture<'a, Result<Box<dyn RemoteReceiver>, TransportError>>;
    /// Called once every publisher and subscriber is declared, before any sample flows: waits
    /// (bounded by the transport's own limit) until the hosts consuming this host's streams are
    /// there, all streams at once, saying who is missing while it waits. The run may drop this
    /// future (Ctrl-C).
    fn start(&self) -> BoxFuture<'_, ()>;
    /// Resolves when the transport cannot go on (another process runs this host of the same
    /// deployment): why. The run then stops and reports it as a failure. Never, by default.
    fn failed(&self) -> BoxFuture<'_, String> {
        Box::pin(std::future::pending())
    }
    /// What happened between the hosts so far.
    fn report(&self) -> TransportReport;
    /// Closes the session.
    fn close(self: Arc<Self>) -> BoxFuture<'static, ()>;
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("transport: {0}")]
pub struct TransportError(pub String);

/// What happened between the hosts of a deployment, seen from one host.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct TransportReport {
    pub deployment: String,
    pub host: String,
    /// The other hosts of the deployment this host exchanges streams with.
    pub hosts: Vec<HostReport>,
    /// Streams received from other hosts.
    pub inbound: Vec<InboundReport>,
    /// Streams sent to other hosts.
    pub outbound: Vec<OutboundReport>,
}

impl TransportReport {
    /// The inputs whose producing host was given up on, with why.
    pub fn cut_short(&self) -> Vec<String> {
        self.inbound
            .iter()
            .filter_map(|s| match &s.ending {
                InboundEnding::CutShort(why) => Some(format!("`{}` from host `{}`: {why}", s.stream, s.from)),
                _ => None,
            })
            .collect()
    }

    /// The streams sent to other hosts whose end some consuming host did not confirm.
    pub fn end_not_confirmed(&self) -> Vec<String> {
        self.outbound
            .iter()
            .filter(|s| !s.end_not_confirmed.is_empty())
            .map(|s| {
                let hosts: Vec<String> = s.end_not_confirmed.iter().map(|h| format!("`{h}`")).collect();
                format!("the end of `{}` was not confirmed by host(s) {}", s.stream, hosts.join(", "))
            })
            .collect()
    }

    /// The streams from other hosts of which not one sample arrived.
    pub fn received_nothing(&self) -> Vec<String> {
        self.inbound.iter().filter(|s| s.received == 0).map(|s| s.stream.clone()).collect()
    }
}

/// Another host, as this one saw it.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct HostReport {
    pub host: String,
    /// Seconds from the start of this host until the other was first seen (`None`: never).
    pub first_seen_s: Option<f64>,
    /// How often it went away (crashed, frozen past zenoh's lease, stopped, link lost).
    pub lost: u64,
    /// How often it came back after going away.
    pub returned: u64,
    /// Seconds it was away in total, while this host ran (after it was first seen).
    pub away_s: f64,
    /// Whether it was there when this host's report was made.
    pub up_at_end: bool,
}

/// A stream received from another host.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct InboundReport {
    /// `producer` or `producer.port`.
    pub stream: String,
    /// The host the spec places its producer on.
    pub from: String,
    /// Samples accepted.
    pub received: u64,
    /// Samples the producer published that never arrived (gaps in its sequence numbers: published
    /// while this host was down or its link was lost, or before it subscribed).
    pub lost: u64,
    /// How often the producer started again (a new run of its host).
    pub producer_restarts: u64,
    /// Messages refused: not from the producing host of this deployment (no or a wrong
    /// authentication tag, another host's name, a replayed sequence number).
    pub refused: u64,
    pub refused_examples: Vec<Malformed>,
    pub ending: InboundEnding,
    /// What arrived of each run of the producer (a restart is a new run), in the order they
    /// were first seen; `received` and `lost` above are their sums.
    pub runs: Vec<InboundRun>,
}

/// What arrived of one run of a producer.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct InboundRun {
    /// The run's incarnation, 16 hexadecimal digits (the producer's `OutboundReport::incarnation`).
    pub incarnation: String,
    /// The sequence number of the first sample that arrived: what the run published before was
    /// published before this host subscribed (counted in `lost`).
    pub joined_at: u64,
    pub received: u64,
    /// Samples of the run that never arrived (as far as this host knows: with the run's end,
    /// every sample it published).
    pub lost: u64,
    /// Whether the run's end arrived (then `received + lost` is what it published).
    pub ended: bool,
}

/// How a stream from another host ended.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum InboundEnding {
    /// It had not ended when the run stopped (Ctrl-C, `--for`).
    #[default]
    Open,
    /// Its producer ended it.
    End,
    /// Given up on: its producing host was gone for too long, or never came.
    CutShort(String),
}

/// A stream sent to other hosts.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct OutboundReport {
    pub stream: String,
    /// This run's incarnation, 16 hexadecimal digits (what consumers report of it in `runs`).
    pub incarnation: String,
    /// Samples published.
    pub published: u64,
    /// For each consuming host: samples published while it was not subscribed (lost for it).
    pub missed: Vec<(String, u64)>,
    /// Consuming hosts that did not confirm they had the end of the stream before this host
    /// stopped waiting (`KPL_ZENOH_WAIT`).
    pub end_not_confirmed: Vec<String>,
    /// Acknowledgments refused: not from a consuming host of this deployment (no or a wrong
    /// envelope or tag).
    pub refused_acks: u64,
}
