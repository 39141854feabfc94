//! One worker process of a process unit: started, greeted, called with a bounded wait, told to
//! quit or killed. Its standard output carries the protocol's frames (read by a thread of its
//! own, so a call can wait with a timeout); its standard error is kpl's.

use std::io::{BufReader, BufWriter, Write};
use std::path::PathBuf;
use std::process::{Child, ChildStdin, Command, ExitStatus, Stdio};
use std::sync::mpsc::{Receiver, RecvTimeoutError, sync_channel};
use std::time::Duration;

use super::protocol::{self, Frame, Hello, Ready, WorkerError};

/// How to start a worker.
#[derive(Debug, Clone)]
pub struct Launch {
    pub interpreter: PathBuf,
    /// Arguments after the interpreter (`-m kpl.unit`).
    pub args: Vec<String>,
    pub hello: Hello,
    /// How long loading the unit may take.
    pub start_timeout: Duration,
}

/// What went wrong with the worker itself (not the unit's own error).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Trouble {
    /// It did not answer in time.
    Hung(Duration),
    /// It exited, or closed its output; how, if known.
    Died(String),
    /// It said something the protocol does not allow.
    Protocol(String),
}

impl std::fmt::Display for Trouble {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Trouble::Hung(t) => write!(
                f,
                "did not answer within {} (the unit's `timeout`)",
                kpl_core::format_micros(t.as_micros() as i64)
            ),
            Trouble::Died(how) => write!(f, "its worker process {how}"),
            Trouble::Protocol(what) => write!(f, "its worker broke the protocol: {what}"),
        }
    }
}

/// A worker's answer to a call.
#[derive(Debug)]
pub enum Answer {
    /// No output this time.
    Nothing,
    /// One KPL wire sample message.
    Output(Vec<u8>),
    /// The unit raised.
    Raised(WorkerError),
}

/// A running worker.
pub struct Worker {
    child: Child,
    stdin: BufWriter<ChildStdin>,
    frames: Receiver<std::io::Result<Option<Frame>>>,
    pub ready: Ready,
}

impl std::fmt::Debug for Worker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Worker").field("pid", &self.child.id()).finish()
    }
}

/// Why a worker could not be started.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum StartError {
    /// The interpreter could not be run at all.
    Spawn(String),
    /// The worker refused the unit (import error, no such function, a parameter it lacks).
    Refused(WorkerError),
    Trouble(Trouble),
}

impl Worker {
    /// Starts a worker and waits for it to load the unit.
    pub fn start(launch: &Launch) -> Result<Worker, StartError> {
        let mut child = Command::new(&launch.interpreter)
            .args(&launch.args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| StartError::Spawn(format!("cannot run `{}`: {e}", launch.interpreter.display())))?;
        let (Some(stdin), Some(stdout)) = (child.stdin.take(), child.stdout.take()) else {
            let _ = child.kill();
            return Err(StartError::Spawn("the worker has no standard input or output".into()));
        };
        // One frame ahead at most: the worker answers one call at a time.
        let (tx, frames) = sync_channel(1);
        std::thread::Builder::new()
            .name("kpl-unit-reader".into())
            .spawn(move || {
                let mut reader = BufReader::with_capacity(1 << 16, stdout);
                loop {
                    let frame = protocol::read_frame(&mut reader);
                    let last = !matches!(frame, Ok(Some(_)));
                    if tx.send(frame).is_err() || last {
                        break;
                    }
                }
            })
            .map_err(|e| StartError::Spawn(format!("cannot start a reader thread: {e}")))?;
        let mut worker = Worker {
            child,
            stdin: BufWriter::with_capacity(1 << 16, stdin),
            frames,
            ready: Ready { protocol: 0, wire: 0, kind: String::new(), implementation: String::new() },
        };
        let hello = serde_json::to_vec(&launch.hello).map_err(|e| StartError::Spawn(e.to_string()))?;
        if let Err(e) = worker.send(protocol::HELLO, &hello) {
            return Err(StartError::Trouble(worker.died(&e)));
        }
        match worker.receive(launch.start_timeout) {
            Ok(Frame { kind: protocol::READY, body }) => {
                let ready: Ready = serde_json::from_slice(&body).map_err(|e| {
                    StartError::Trouble(Trouble::Protocol(format!("a ready frame that is not JSON: {e}")))
                })?;
                if ready.protocol != protocol::PROTOCOL {
                    let what =
                        format!("it speaks protocol {}, kpl speaks {}", ready.protocol, protocol::PROTOCOL);
                    return Err(StartError::Trouble(Trouble::Protocol(what)));
                }
                worker.ready = ready;
                Ok(worker)
            }
            Ok(Frame { kind: protocol::ERROR, body }) => Err(StartError::Refused(worker_error(&body))),
            Ok(Frame { kind, .. }) => Err(StartError::Trouble(Trouble::Protocol(format!(
                "expected ready, got a `{}` frame",
                kind as char
            )))),
            Err(trouble) => Err(StartError::Trouble(trouble)),
        }
    }

    /// Calls the unit with a call frame's body and waits at most `timeout` for its answer.
    pub fn call(&mut self, body: &[u8], timeout: Duration) -> Result<Answer, Trouble> {
        if let Err(e) = self.send(protocol::CALL, body) {
            return Err(self.died(&e));
        }
        match self.receive(timeout)? {
            Frame { kind: protocol::OUTPUT, body } if body.is_empty() => Ok(Answer::Nothing),
            Frame { kind: protocol::OUTPUT, body } => Ok(Answer::Output(body)),
            Frame { kind: protocol::ERROR, body } => Ok(Answer::Raised(worker_error(&body))),
            Frame { kind, .. } => {
                Err(Trouble::Protocol(format!("expected an output, got a `{}` frame", kind as char)))
            }
        }
    }

    /// Tells the worker to quit and waits up to `grace` for it; kills it after that.
    pub fn quit(mut self, grace: Duration) {
        let _ = self.send(protocol::QUIT, &[]);
        let _ = self.frames.recv_timeout(grace);
        let step = Duration::from_millis(10);
        let mut waited = Duration::ZERO;
        while waited < grace {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(step);
            waited += step;
        }
        self.kill();
    }

    /// Kills the worker and reaps it.
    pub fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    fn send(&mut self, kind: u8, body: &[u8]) -> std::io::Result<()> {
        protocol::write_frame(&mut self.stdin, kind, body)?;
        self.stdin.flush()
    }

    fn receive(&mut self, timeout: Duration) -> Result<Frame, Trouble> {
        match self.frames.recv_timeout(timeout) {
            Ok(Ok(Some(frame))) => Ok(frame),
            Ok(Ok(None)) => Err(self.died(&"it closed its output")),
            Ok(Err(e)) => Err(self.died(&e)),
            Err(RecvTimeoutError::Timeout) => Err(Trouble::Hung(timeout)),
            Err(RecvTimeoutError::Disconnected) => Err(self.died(&"its output reader stopped")),
        }
    }

    /// The worker is gone (or going): how it ended, once it has.
    fn died(&mut self, what: &dyn std::fmt::Display) -> Trouble {
        let mut status = None;
        for _ in 0..50 {
            if let Ok(Some(s)) = self.child.try_wait() {
                status = Some(s);
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        match status {
            Some(status) => Trouble::Died(describe_exit(status)),
            None => {
                let _ = self.child.kill();
                let _ = self.child.wait();
                Trouble::Died(format!("stopped answering ({what}) and was killed"))
            }
        }
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

fn worker_error(body: &[u8]) -> WorkerError {
    serde_json::from_slice(body).unwrap_or_else(|e| WorkerError {
        error: format!("an error frame that is not JSON ({e}): {}", String::from_utf8_lossy(body)),
        traceback: String::new(),
    })
}

fn describe_exit(status: ExitStatus) -> String {
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        if let Some(signal) = status.signal() {
            return format!("was killed by signal {signal}");
        }
    }
    match status.code() {
        Some(code) => format!("exited with status {code}"),
        None => "exited".to_string(),
    }
}
