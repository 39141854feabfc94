//! The knowledge processes a runtime runs, as traits: [`Source`] brings samples in, [`Unit`] (and
//! [`AsyncUnit`]) turns input samples into output samples; sinks are units without outputs.
//!
//! A computational unit in DyKnow's sense is "latest inputs + own state -> output sample": a
//! [`Unit`] is called with the sample that arrived (or, when it asks for synchronized inputs,
//! with a whole state of samples sharing one valid time) and the latest sample of every input,
//! and emits through an [`Emitter`]. Units are plain synchronous Rust; a unit that must wait
//! (a link process gathering replies from its per-object instances) implements [`AsyncUnit`].
//!
//! ```
//! use kpl_core::Value;
//! use kpl_runtime::process::{Emitter, Input, ProcessError, Unit};
//!
//! /// Emits the running sum of an integer stream.
//! struct Sum(i64);
//!
//! impl Unit for Sum {
//!     fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
//!         if let Some(Value::Int(x)) = input.trigger_value() {
//!             self.0 += x;
//!             out.emit(Value::Int(self.0));
//!         }
//!         Ok(())
//!     }
//! }
//! ```

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;

use kpl_core::{Time, Value};

use crate::sample::Sample;

pub type BoxFuture<'a, T> = Pin<Box<dyn Future<Output = T> + Send + 'a>>;

/// Why a process failed or stopped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProcessError {
    /// The process cannot go on.
    #[error("{0}")]
    Failed(String),
    /// Malformed input in a `--strict` run.
    #[error("malformed input at {location}: {error} (--strict stops the run)")]
    Strict { location: String, error: String },
    /// A unit failed and its policy is to stop the run (a Python unit's `on_error: "stop"`).
    #[error("{0} (the unit's policy stops the run)")]
    Stop(String),
}

impl ProcessError {
    pub fn failed(message: impl Into<String>) -> ProcessError {
        ProcessError::Failed(message.into())
    }
}

/// What made a unit run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Trigger {
    /// A sample arrived on this input port.
    Sample(usize),
    /// A synchronized state is complete (or its max delay has passed).
    State,
}

/// What a unit sees when it runs.
#[derive(Debug)]
pub struct Input<'a> {
    /// The clock time now.
    pub now: Time,
    /// The valid time of the triggering sample or state.
    pub valid: Time,
    pub trigger: Trigger,
    /// For each input port, in the order of the process's inputs: the latest sample (or, for a
    /// synchronized unit, the state's sample at `valid`, approximated by the most recent one).
    pub values: &'a [Option<Sample>],
    /// The names of the input streams, in port order.
    pub names: &'a [Arc<str>],
}

impl Input<'_> {
    /// The value that triggered this call (`None` for a synchronized state).
    pub fn trigger_value(&self) -> Option<&Value> {
        match self.trigger {
            Trigger::Sample(port) => self.values.get(port)?.as_ref().map(|s| &s.value),
            Trigger::State => None,
        }
    }

    /// The sample that triggered this call and its port (`None` for a synchronized state, or
    /// when the port holds no sample).
    pub fn trigger_sample(&self) -> Option<(usize, &Sample)> {
        match self.trigger {
            Trigger::Sample(port) => self.values.get(port)?.as_ref().map(|s| (port, s)),
            Trigger::State => None,
        }
    }

    /// The current value of input port `port`.
    pub fn value(&self, port: usize) -> Option<&Value> {
        self.values.get(port)?.as_ref().map(|s| &s.value)
    }
}

/// Collects what a unit emits; the runtime sends it on after the call returns.
#[derive(Debug)]
pub struct Emitter {
    now: Time,
    valid: Time,
    ports: Arc<[String]>,
    pub(crate) out: Vec<(usize, Sample)>,
    pub(crate) unknown_ports: Vec<String>,
}

impl Emitter {
    /// `ports` are the names of the outputs after the default one (output 0).
    pub fn new(ports: Arc<[String]>) -> Emitter {
        Emitter { now: 0, valid: 0, ports, out: Vec::new(), unknown_ports: Vec::new() }
    }

    pub(crate) fn begin(&mut self, now: Time, valid: Time) {
        self.now = now;
        self.valid = valid;
    }

    /// Emits on the default output, with the input's valid time.
    pub fn emit(&mut self, value: Value) {
        self.out.push((0, Sample::new(self.valid, self.now, value)));
    }

    /// Emits on the default output with another valid time.
    pub fn emit_at(&mut self, valid: Time, value: Value) {
        self.out.push((0, Sample::new(valid, self.now, value)));
    }

    /// Emits on a named output (such as a link's `changes`).
    pub fn emit_port(&mut self, port: &str, valid: Time, value: Value) {
        match self.ports.iter().position(|p| p == port) {
            Some(i) => self.out.push((i + 1, Sample::new(valid, self.now, value))),
            None => self.unknown_ports.push(port.to_string()),
        }
    }

    pub fn now(&self) -> Time {
        self.now
    }

    pub fn take(&mut self) -> Vec<(usize, Sample)> {
        std::mem::take(&mut self.out)
    }

    /// Moves out what was emitted, keeping the buffer's capacity for the next call.
    pub(crate) fn drain(&mut self) -> std::vec::Drain<'_, (usize, Sample)> {
        self.out.drain(..)
    }
}

/// A synchronous computational unit (or sink).
pub trait Unit: Send + 'static {
    /// Whether the unit wants its inputs merged into states that share a valid time.
    fn synchronized(&self) -> bool {
        false
    }

    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError>;

    /// All inputs have ended: emit what is pending and flush.
    fn on_end(&mut self, _out: &mut Emitter) -> Result<(), ProcessError> {
        Ok(())
    }
}

/// A computational unit that may wait while it runs (for example on process instances it
/// created). Every [`Unit`] is one, through [`SyncUnit`].
pub trait AsyncUnit: Send + 'static {
    fn synchronized(&self) -> bool {
        false
    }

    fn on_input<'a>(
        &'a mut self,
        input: &'a Input<'a>,
        out: &'a mut Emitter,
    ) -> BoxFuture<'a, Result<(), ProcessError>>;

    fn on_end<'a>(&'a mut self, out: &'a mut Emitter) -> BoxFuture<'a, Result<(), ProcessError>>;

    /// The unit as a synchronous [`Unit`], if it is one: the runtime then calls it directly,
    /// without a future per sample.
    fn as_sync(&mut self) -> Option<&mut dyn Unit> {
        None
    }
}

/// Runs a [`Unit`] as an [`AsyncUnit`].
#[derive(Debug)]
pub struct SyncUnit<U>(pub U);

impl<U: Unit> AsyncUnit for SyncUnit<U> {
    fn synchronized(&self) -> bool {
        self.0.synchronized()
    }

    fn on_input<'a>(
        &'a mut self,
        input: &'a Input<'a>,
        out: &'a mut Emitter,
    ) -> BoxFuture<'a, Result<(), ProcessError>> {
        let result = self.0.on_input(input, out);
        Box::pin(std::future::ready(result))
    }

    fn on_end<'a>(&'a mut self, out: &'a mut Emitter) -> BoxFuture<'a, Result<(), ProcessError>> {
        let result = self.0.on_end(out);
        Box::pin(std::future::ready(result))
    }

    fn as_sync(&mut self) -> Option<&mut dyn Unit> {
        Some(&mut self.0)
    }
}

/// A source: brings samples in from outside the graph (a simulator, a file, a timer, a network
/// subscription). It runs as its own task until it is done or the run stops.
pub trait Source: Send + 'static {
    fn run<'a>(
        &'a mut self,
        ctx: &'a mut crate::context::SourceContext,
    ) -> BoxFuture<'a, Result<(), ProcessError>>;

    /// Whether the source ends by itself (a file at its end, a timer with a `count`). A run with
    /// a source that does not, and no `--for`, goes on until it is interrupted; `kpl run` says
    /// so when it starts.
    fn ends_by_itself(&self) -> bool {
        true
    }
}
