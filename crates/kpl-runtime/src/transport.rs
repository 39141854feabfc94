//! Streams between hosts. The runtime knows only these traits; `kpl-zenoh` implements them over
//! zenoh (the only crate that depends on zenoh). A stream is identified by a [`StreamKey`]; the
//! transport turns it into its own addresses (key expressions) and encodes samples on the wire
//! with their valid and available times.

use std::sync::Arc;

use crate::process::BoxFuture;
use crate::sample::Sample;

/// Which stream: a producer's output in one spec.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct StreamKey {
    /// The spec's name (its file stem).
    pub spec: String,
    /// The producing process.
    pub producer: String,
    /// A named output, or `None` for the default one.
    pub port: Option<String>,
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
    /// Bytes that do not decode: counted as malformed input, with where they came from.
    Malformed {
        location: String,
        error: String,
    },
}

/// Publishes one stream to other hosts.
pub trait RemoteSender: Send + Sync {
    fn send<'a>(&'a mut self, sample: &'a Sample) -> BoxFuture<'a, ()>;
    /// Tells the subscribers the stream has ended.
    fn end(&mut self) -> BoxFuture<'_, ()>;
    /// Waits (up to the transport's timeout) until `n` subscribers are connected, so that no
    /// sample is published into the void at start-up. Returns how many there are.
    fn wait_for_subscribers(&mut self, n: usize) -> BoxFuture<'_, usize>;
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
    /// Closes the session.
    fn close(self: Arc<Self>) -> BoxFuture<'static, ()>;
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("transport: {0}")]
pub struct TransportError(pub String);
