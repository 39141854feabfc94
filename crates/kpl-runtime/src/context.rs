//! What a running process can use: its outputs, the clock, the stop signal, its counters.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use kpl_core::{Time, Value};

use crate::clock::{Clock, RunEnd};
use crate::edge::{Closed, EdgeSender};
use crate::process::ProcessError;
use crate::sample::Sample;
use crate::stats::{Malformed, ProcessStats, RunStats};
use crate::transport::RemoteSender;

/// Asks every source to stop (Ctrl-C or SIGTERM, the end of `--for`, a failure in a `--strict`
/// run).
#[derive(Debug, Clone, Default)]
pub struct StopSignal {
    stopped: Arc<AtomicBool>,
    /// Stopped because the run was interrupted, not because it was done.
    interrupted: Arc<AtomicBool>,
    notify: Arc<tokio::sync::Notify>,
}

impl StopSignal {
    pub fn stop(&self) {
        self.stopped.store(true, Ordering::SeqCst);
        self.notify.notify_waiters();
    }

    /// Stops because the run was interrupted (a signal, a `--strict` failure): streams to other
    /// hosts then end as unfinished, and their consumers wait for this host to come back.
    pub fn interrupt(&self) {
        self.interrupted.store(true, Ordering::SeqCst);
        self.stop();
    }

    pub fn is_interrupted(&self) -> bool {
        self.interrupted.load(Ordering::SeqCst)
    }

    /// Resolves once the run is interrupted (not when it merely stops).
    pub async fn interrupted(&self) {
        loop {
            let notified = self.notify.notified();
            if self.is_interrupted() {
                return;
            }
            notified.await;
        }
    }

    pub fn is_stopped(&self) -> bool {
        self.stopped.load(Ordering::SeqCst)
    }

    /// Resolves once the run is asked to stop.
    pub async fn stopped(&self) {
        loop {
            let notified = self.notify.notified();
            if self.is_stopped() {
                return;
            }
            notified.await;
        }
    }
}

/// The output ports of a process: for each port, the edges to local consumers and the remote
/// publishers (streams going to other hosts).
#[derive(Default)]
pub struct Outputs {
    pub(crate) ports: Vec<Port>,
    /// Whether the run was interrupted, when the outputs close.
    stop: StopSignal,
}

#[derive(Default)]
pub(crate) struct Port {
    pub(crate) local: Vec<EdgeSender>,
    pub(crate) remote: Vec<Box<dyn RemoteSender>>,
}

impl std::fmt::Debug for Outputs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Outputs").field("ports", &self.ports.len()).finish()
    }
}

impl Outputs {
    pub(crate) fn with_ports(n: usize, stop: StopSignal) -> Outputs {
        Outputs { ports: (0..n).map(|_| Port::default()).collect(), stop }
    }

    /// Sends a sample to every consumer of output `port`. A consumer that has stopped is
    /// forgotten; the others still get the sample.
    pub async fn send(&mut self, port: usize, sample: Sample) {
        let Some(p) = self.ports.get_mut(port) else { return };
        let mut gone = Vec::new();
        let last = p.local.len().wrapping_sub(1);
        let mut sample = Some(sample);
        for (i, sender) in p.local.iter().enumerate() {
            // The last local consumer takes the sample itself unless remote hosts need it too;
            // the others get clones (which share the payload).
            let s = if i == last && p.remote.is_empty() { sample.take() } else { sample.clone() };
            let Some(s) = s else { break };
            if sender.send(s).await == Err(Closed) {
                gone.push(i);
            }
        }
        for i in gone.into_iter().rev() {
            p.local.remove(i);
        }
        if let Some(sample) = &sample {
            for remote in &mut p.remote {
                remote.send(sample).await;
            }
        }
    }

    /// Whether nothing consumes any output (a sink, or a process whose consumers all stopped).
    pub fn is_empty(&self) -> bool {
        self.ports.iter().all(|p| p.local.is_empty() && p.remote.is_empty())
    }

    /// Ends every output: local consumers see the end of their input, remote ones an end marker
    /// (saying whether the stream is finished or its run was interrupted).
    pub async fn close(&mut self) {
        let finished = !self.stop.is_interrupted();
        for port in &mut self.ports {
            port.local.clear();
            for remote in &mut port.remote {
                // A finished stream's end may wait for its consumers to confirm it; Ctrl-C or
                // SIGTERM cuts that wait short (the end itself has gone out by then).
                tokio::select! {
                    () = remote.end(finished) => {}
                    () = self.stop.interrupted(), if finished => {}
                }
            }
            port.remote.clear();
        }
    }
}

/// What a [`crate::process::Source`] runs with.
pub struct SourceContext {
    pub name: String,
    pub clock: Clock,
    pub(crate) outputs: Outputs,
    pub(crate) stop: StopSignal,
    /// Where the run ends (`--for`), if set: later samples are not emitted.
    pub(crate) run_end: Option<Arc<RunEnd>>,
    pub(crate) strict: bool,
    pub stats: Arc<ProcessStats>,
    pub(crate) run_stats: Arc<RunStats>,
}

impl std::fmt::Debug for SourceContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SourceContext").field("name", &self.name).field("end", &self.end()).finish()
    }
}

impl SourceContext {
    pub fn now(&self) -> Time {
        self.clock.now()
    }

    /// The clock time the run ends at (`--for`), if set. On the simulated clock it can move
    /// once, by a source's first wait for a date ([`RunEnd`]); until then it is the earliest.
    pub fn end(&self) -> Option<Time> {
        self.run_end.as_ref().map(|end| end.earliest())
    }

    /// Whether the source should stop now (Ctrl-C, `--for` reached, a strict failure).
    pub fn should_stop(&self) -> bool {
        self.stop.is_stopped() || self.end().is_some_and(|end| self.clock.now() > end)
    }

    /// Waits until clock time `t`. Returns false if the run stops first, or if `t` is past the
    /// run's end (the sample at `t` must then not be emitted): the source then waits for the
    /// end itself, so a run lasts its `--for` on either clock, even when its last sample came
    /// earlier. The first wait of a simulated run fixes where a dated replay's `--for` counts
    /// from ([`RunEnd`]).
    pub async fn wait_until(&self, t: Time) -> bool {
        if let Some(end) = self.run_end.as_ref().map(|end| end.fixed(t))
            && t > end
        {
            self.run_stats.reached_end.store(true, Ordering::Relaxed);
            tokio::select! {
                biased;
                () = self.stop.stopped() => {}
                () = self.clock.sleep_until(end) => {}
            }
            return false;
        }
        tokio::select! {
            biased;
            () = self.stop.stopped() => false,
            () = self.clock.sleep_until(t) => !self.stop.is_stopped(),
        }
    }

    /// Emits a value on the default output, valid at `valid`, available now.
    pub async fn emit(&mut self, valid: Time, value: Value) {
        let now = self.clock.now();
        self.emit_sample(Sample::new(valid, now, value)).await;
    }

    /// Emits a value on output `port` (0 is the default output, then the named ones in the
    /// order of the registry entry's ports), valid at `valid`, available now.
    pub async fn emit_port(&mut self, port: usize, valid: Time, value: Value) {
        let now = self.clock.now();
        self.run_stats.source_sample(now);
        self.outputs.send(port, Sample::new(valid, now, value)).await;
    }

    /// Emits a sample on the default output as it is (replay keeps recorded times).
    pub async fn emit_sample(&mut self, sample: Sample) {
        self.run_stats.source_sample(sample.available);
        self.outputs.send(0, sample).await;
    }

    /// Counts a malformed input and says where it came from; in a `--strict` run it is an error
    /// that stops the run.
    pub fn malformed(
        &self,
        location: impl Into<String>,
        error: impl Into<String>,
    ) -> Result<(), ProcessError> {
        let malformed = Malformed { location: location.into(), error: error.into() };
        tracing::debug!(process = %self.name, location = %malformed.location, "malformed input: {}", malformed.error);
        if self.strict {
            return Err(ProcessError::Strict { location: malformed.location, error: malformed.error });
        }
        self.stats.malformed(malformed);
        Ok(())
    }

    /// Warns about something that is probably not what the spec meant, in the run's summary
    /// (and in the log at once).
    pub fn warn(&self, warning: impl Into<String>) {
        let warning = warning.into();
        tracing::debug!(process = %self.name, "warning: {warning}");
        self.stats.warn(warning);
    }

    /// Whether every consumer of this source has stopped.
    pub fn unconsumed(&self) -> bool {
        self.outputs.is_empty()
    }
}
