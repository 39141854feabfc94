//! The one zenoh session of a host process. The transport (streams between hosts) and the
//! `zenoh.subscribe` / `zenoh.publish` processes share it: whichever needs it first opens it with
//! the host's endpoints ([`crate::config`]), the others get the same one, and it closes when the
//! run closes its transport or the last user lets go of it.

use std::sync::{Arc, Mutex, OnceLock, Weak};

use kpl_runtime::transport::TransportError;
use kpl_semantic::hir;

use crate::config::{self, Endpoints, Security, ZenohOptions};
use crate::credentials::Credentials;

/// Opens (once) the zenoh session of this process.
#[derive(Debug)]
pub struct Sessions {
    options: Mutex<Result<ZenohOptions, TransportError>>,
    current: tokio::sync::Mutex<Weak<HostSession>>,
}

/// An open session and what it was opened with.
#[derive(Debug)]
pub struct HostSession {
    pub session: zenoh::Session,
    /// The host this process runs (`None`: a run without `--host`).
    pub host: Option<String>,
    pub endpoints: Endpoints,
    pub options: ZenohOptions,
    /// The host's share of its deployment's keys (`--keys`).
    pub credentials: Option<Credentials>,
}

impl HostSession {
    /// How logs and errors name this process: `host `ground``, or `this run`.
    pub fn describe(&self) -> String {
        match &self.host {
            Some(host) => format!("host `{host}`"),
            None => "this run".to_string(),
        }
    }
}

impl Sessions {
    pub fn new(options: ZenohOptions) -> Arc<Sessions> {
        Arc::new(Sessions { options: Mutex::new(Ok(options)), current: tokio::sync::Mutex::new(Weak::new()) })
    }

    /// The sessions of this process, with options from the environment
    /// ([`ZenohOptions::from_env`]); a bad variable is reported when a session is opened.
    pub fn process() -> Arc<Sessions> {
        static PROCESS: OnceLock<Arc<Sessions>> = OnceLock::new();
        PROCESS
            .get_or_init(|| {
                Arc::new(Sessions {
                    options: Mutex::new(ZenohOptions::from_env()),
                    current: tokio::sync::Mutex::new(Weak::new()),
                })
            })
            .clone()
    }

    pub fn options(&self) -> Result<ZenohOptions, TransportError> {
        self.options.lock().map_err(|_| TransportError("the zenoh options are unusable".into()))?.clone()
    }

    /// Changes the options of sessions opened from now on (the command line's `--keys` over the
    /// environment's `KPL_KEYS`).
    pub fn configure(&self, change: impl FnOnce(&mut ZenohOptions)) {
        if let Ok(mut options) = self.options.lock()
            && let Ok(options) = options.as_mut()
        {
            change(options);
        }
    }

    /// The open session, or a new one for `host` of `deploy` (a run without `--host`: `None`).
    /// Must be called on a multi-threaded tokio runtime (zenoh needs one).
    pub async fn open(
        &self,
        deploy: Option<&hir::Deploy>,
        host: Option<&str>,
    ) -> Result<Arc<HostSession>, TransportError> {
        self.open_with(deploy, host, None).await
    }

    /// As [`Sessions::open`], with access-control rules for a new session of a deployment with
    /// keys (the transport between hosts opens the session first, with the rules of its streams).
    pub async fn open_with(
        &self,
        deploy: Option<&hir::Deploy>,
        host: Option<&str>,
        access_control: Option<serde_json::Value>,
    ) -> Result<Arc<HostSession>, TransportError> {
        let options = self.options()?;
        let mut current = self.current.lock().await;
        if let Some(open) = current.upgrade() {
            if open.host.as_deref() != host {
                tracing::debug!(
                    wanted = ?host,
                    "the zenoh session of {} is already open; using it",
                    open.describe()
                );
            }
            return Ok(open);
        }
        let credentials = match (&options.keys, &options.first_use_keys, host) {
            (Some(dir), _, Some(host)) => Some(Credentials::load(dir, host)?),
            (None, Some(dir), Some(host)) => {
                Some(Credentials { made_on_first_use: true, ..Credentials::load(dir, host)? })
            }
            _ => None,
        };
        // A given keys folder makes the loopback defaults `tls/`; keys made on first use keep them
        // `tcp/` (tagged messages; programs outside the deployment still link as before).
        let tls = credentials.as_ref().is_some_and(|c| !c.made_on_first_use);
        let endpoints = config::endpoints(deploy, host, options.port_base, tls)?;
        let security = credentials
            .clone()
            .map(|credentials| Security { credentials, access_control: access_control.clone() });
        let zenoh_config = config::session_config(&endpoints, &options, security.as_ref())?;
        let who = host.map_or_else(|| "this run".to_string(), |h| format!("host `{h}`"));
        let session = open_off_thread(zenoh_config).await.map_err(|e| {
            TransportError(format!(
                "cannot open the zenoh session of {who} (listen {:?}, connect {:?}): {e}",
                endpoints.listen, endpoints.connect
            ))
        })?;
        tracing::info!(listen = ?endpoints.listen, connect = ?endpoints.connect, keys = credentials.is_some(), "zenoh session of {who} open");
        let open =
            Arc::new(HostSession { session, host: host.map(String::from), endpoints, options, credentials });
        *current = Arc::downgrade(&open);
        Ok(open)
    }
}

/// Opens a zenoh session on a thread of its own.
///
/// `zenoh::open(..).await` does not yield: it blocks the calling thread in a `block_on` of
/// zenoh's own runtime (nested in `block_in_place`), which parks on the same thread-local parker
/// as a `block_on` that called it. A wake-up of that outer task while the session opens (which can
/// take a connect retry, hundreds of milliseconds) is then taken by the inner `block_on` and lost:
/// two hosts run by `run_async` in one task (`tokio::join!`) hung that way, one waiting forever
/// for a timer that had fired. On a thread of the blocking pool nothing else waits on its parker.
pub(crate) async fn open_off_thread(config: zenoh::Config) -> Result<zenoh::Session, String> {
    use zenoh::Wait;
    match tokio::task::spawn_blocking(move || zenoh::open(config).wait()).await {
        Ok(opened) => opened.map_err(|e| e.to_string()),
        Err(e) => Err(format!("the thread opening the session failed: {e}")),
    }
}
