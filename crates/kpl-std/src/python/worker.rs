//! One worker process of a process unit: started, greeted, called with a bounded wait, told to
//! quit or killed. Its standard output carries the protocol's frames, read by the calling thread
//! itself; a watchdog thread kills a worker that does not answer within the call's timeout (its
//! output then ends, which ends the read). The watchdog wakes at deadlines only, never once per
//! call, so a call costs two pipe writes and two wake-ups (kpl's and the worker's). Its standard
//! error is kpl's.

use std::io::{BufReader, BufWriter, Write};
use std::path::PathBuf;
use std::process::{Child, ChildStdin, ChildStdout, Command, ExitStatus, Stdio};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

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
    child: Arc<Mutex<Child>>,
    pid: u32,
    stdin: BufWriter<ChildStdin>,
    stdout: BufReader<ChildStdout>,
    watch: Arc<Watch>,
    pub ready: Ready,
}

impl std::fmt::Debug for Worker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Worker").field("pid", &self.pid).finish()
    }
}

/// The watchdog's shortest sleep while no call is under way.
const MIN_IDLE: Duration = Duration::from_millis(10);

/// What the watchdog of a worker watches: the call under way and its deadline.
#[derive(Default)]
struct Watch {
    state: Mutex<Watched>,
    wake: Condvar,
}

#[derive(Default)]
struct Watched {
    /// The deadline of the call (or the start) under way; `None` between calls.
    deadline: Option<Instant>,
    /// How long the watchdog sleeps while no call is under way (it then looks again).
    idle: Duration,
    /// When the watchdog wakes next, if it sleeps.
    wakes_at: Option<Instant>,
    /// The watchdog killed the worker for the call under way.
    fired: bool,
    quit: bool,
}

impl Watch {
    /// A call starts: the worker must answer within `timeout`.
    // The deadline is the wall clock's whatever the run's clock: a hung worker is a real wait.
    #[allow(clippy::disallowed_methods)]
    fn arm(&self, timeout: Duration) {
        let Ok(mut s) = self.state.lock() else { return };
        s.fired = false;
        s.deadline = Instant::now().checked_add(timeout);
        s.idle = s.idle.min(timeout).max(MIN_IDLE);
        // Calls with the same timeout find the watchdog asleep until an earlier deadline (or for
        // at most `idle`): it wakes before this one untold, so a call costs no wake-up of it.
        // Only a shorter deadline than it sleeps for (the first call after the start) tells it.
        if let (Some(deadline), Some(wakes_at)) = (s.deadline, s.wakes_at)
            && deadline < wakes_at
        {
            self.wake.notify_all();
        }
    }

    /// The call is over: whether the watchdog killed the worker meanwhile.
    fn disarm(&self) -> bool {
        match self.state.lock() {
            Ok(mut s) => {
                s.deadline = None;
                s.fired
            }
            Err(_) => false,
        }
    }

    fn quit(&self) {
        if let Ok(mut s) = self.state.lock() {
            s.quit = true;
        }
        self.wake.notify_all();
    }
}

/// Kills the worker when a call outlives its deadline; ends when told to or when the worker is
/// gone.
#[allow(clippy::disallowed_methods)] // see Watch::arm
fn watchdog(watch: Arc<Watch>, child: Arc<Mutex<Child>>) {
    let Ok(mut s) = watch.state.lock() else { return };
    loop {
        if s.quit {
            return;
        }
        let now = Instant::now();
        let wait = match s.deadline {
            Some(deadline) if now >= deadline => {
                s.fired = true;
                s.deadline = None;
                if let Ok(mut child) = child.lock() {
                    let _ = child.kill();
                }
                s.idle
            }
            Some(deadline) => deadline - now,
            None => s.idle,
        };
        s.wakes_at = now.checked_add(wait);
        s = match watch.wake.wait_timeout(s, wait) {
            Ok((s, _)) => s,
            Err(_) => return,
        };
        s.wakes_at = None;
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
            let _ = child.wait();
            return Err(StartError::Spawn("the worker has no standard input or output".into()));
        };
        let pid = child.id();
        let child = Arc::new(Mutex::new(child));
        let watch = Arc::new(Watch::default());
        if let Ok(mut s) = watch.state.lock() {
            s.idle = launch.start_timeout.max(MIN_IDLE);
        }
        let (watched, killed) = (watch.clone(), child.clone());
        if let Err(e) = std::thread::Builder::new()
            .name("kpl-unit-watchdog".into())
            .spawn(move || watchdog(watched, killed))
        {
            if let Ok(mut child) = child.lock() {
                let _ = child.kill();
                let _ = child.wait();
            }
            return Err(StartError::Spawn(format!("cannot start a watchdog thread: {e}")));
        }
        let mut worker = Worker {
            child,
            pid,
            stdin: BufWriter::with_capacity(1 << 16, stdin),
            stdout: BufReader::with_capacity(1 << 16, stdout),
            watch,
            ready: Ready { protocol: 0, wire: 0, kind: String::new(), implementation: String::new() },
        };
        let hello = serde_json::to_vec(&launch.hello).map_err(|e| StartError::Spawn(e.to_string()))?;
        match worker.exchange(protocol::HELLO, &hello, launch.start_timeout) {
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
        match self.exchange(protocol::CALL, body, timeout)? {
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
        let step = Duration::from_millis(10);
        let mut waited = Duration::ZERO;
        while waited < grace {
            if let Some(Ok(Some(_))) = self.with_child(Child::try_wait) {
                return;
            }
            std::thread::sleep(step);
            waited += step;
        }
        self.kill();
    }

    /// Kills the worker and reaps it.
    pub fn kill(self) {
        self.with_child(|child| {
            let _ = child.kill();
            let _ = child.wait();
        });
    }

    pub fn pid(&self) -> u32 {
        self.pid
    }

    fn with_child<T>(&self, f: impl FnOnce(&mut Child) -> T) -> Option<T> {
        self.child.lock().ok().map(|mut child| f(&mut child))
    }

    fn send(&mut self, kind: u8, body: &[u8]) -> std::io::Result<()> {
        protocol::write_frame(&mut self.stdin, kind, body)?;
        self.stdin.flush()
    }

    /// Sends a frame and reads the worker's answer on this thread; the watchdog ends both (by
    /// killing the worker) when they take longer than `timeout`.
    fn exchange(&mut self, kind: u8, body: &[u8], timeout: Duration) -> Result<Frame, Trouble> {
        self.watch.arm(timeout);
        let frame = self.send(kind, body).and_then(|()| protocol::read_frame(&mut self.stdout));
        if self.watch.disarm() {
            self.with_child(Child::wait);
            return Err(Trouble::Hung(timeout));
        }
        match frame {
            Ok(Some(frame)) => Ok(frame),
            Ok(None) => Err(self.died(&"it closed its output")),
            Err(e) => Err(self.died(&e)),
        }
    }

    /// The worker is gone (or going): how it ended, once it has.
    fn died(&mut self, what: &dyn std::fmt::Display) -> Trouble {
        let mut status = None;
        for _ in 0..50 {
            if let Some(Ok(Some(s))) = self.with_child(Child::try_wait) {
                status = Some(s);
                break;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        match status {
            Some(status) => Trouble::Died(describe_exit(status)),
            None => {
                self.with_child(|child| {
                    let _ = child.kill();
                    let _ = child.wait();
                });
                Trouble::Died(format!("stopped answering ({what}) and was killed"))
            }
        }
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.watch.quit();
        self.with_child(|child| {
            if let Ok(None) = child.try_wait() {
                let _ = child.kill();
                let _ = child.wait();
            }
        });
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
