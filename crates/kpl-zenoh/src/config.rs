//! Where a host's zenoh session listens and what it connects to, and the session's configuration:
//! peer mode, multicast scouting off, explicit endpoints (docs/streams.md, "On the wire").
//!
//! Endpoints come from the spec's `deploy` section; a host that gives none gets loopback
//! defaults, so the hosts of one spec find each other on one machine without any setup:
//!
//! - **listen**: the host's `listen` endpoints; without them, none if the host gives `connect`
//!   endpoints (it only dials out), else `tcp/127.0.0.1:<base + i>` where `i` is the host's
//!   position in the deploy section and `base` is 7447 (`KPL_ZENOH_PORT_BASE`);
//! - **connect**: the host's `connect` endpoints; without them, the listen endpoints of every host
//!   before it in the deploy section, so each pair of hosts links once, the later one dialling.
//!
//! A run without `--host` (a spec using `zenoh.subscribe` or `zenoh.publish` to talk to programs
//! outside it) counts as the first host of the default scheme: it listens on
//! `tcp/127.0.0.1:<base>`. A zenoh configuration file (`KPL_ZENOH_CONFIG`) is the starting point
//! when given (TLS certificates, access control, ...); endpoints of the deploy section replace its
//! own, and the defaults apply only when neither gives any.

use std::path::PathBuf;
use std::time::Duration;

use kpl_runtime::transport::TransportError;
use kpl_semantic::hir;

/// The zenoh default port: host `i` of the default scheme listens on `DEFAULT_PORT_BASE + i`.
pub const DEFAULT_PORT_BASE: u16 = 7447;
/// How long a publisher waits for its subscribers at start-up by default.
pub const DEFAULT_SUBSCRIBER_WAIT: Duration = Duration::from_secs(30);
/// The default capacity of a subscriber's queue in front of the runtime.
pub const DEFAULT_QUEUE: usize = 4096;

/// Options of the zenoh sessions of one process.
#[derive(Debug, Clone, PartialEq)]
pub struct ZenohOptions {
    /// A zenoh configuration file (JSON5) to start from (`KPL_ZENOH_CONFIG`).
    pub config_file: Option<PathBuf>,
    /// The first port of the loopback defaults (`KPL_ZENOH_PORT_BASE`).
    pub port_base: u16,
    /// How long a publisher waits at start-up for the hosts that consume its stream
    /// (`KPL_ZENOH_WAIT`, seconds).
    pub subscriber_wait: Duration,
    /// Samples buffered per subscription before zenoh's receiving thread waits (back-pressure
    /// to the publisher, which then blocks: nothing is dropped).
    pub queue: usize,
}

impl Default for ZenohOptions {
    fn default() -> ZenohOptions {
        ZenohOptions {
            config_file: None,
            port_base: DEFAULT_PORT_BASE,
            subscriber_wait: DEFAULT_SUBSCRIBER_WAIT,
            queue: DEFAULT_QUEUE,
        }
    }
}

impl ZenohOptions {
    /// The defaults, changed by the environment variables `KPL_ZENOH_CONFIG` (a zenoh config file),
    /// `KPL_ZENOH_PORT_BASE` (a port) and `KPL_ZENOH_WAIT` (seconds).
    pub fn from_env() -> Result<ZenohOptions, TransportError> {
        Self::from_vars(|name| std::env::var(name).ok())
    }

    /// As [`ZenohOptions::from_env`], reading variables through `var`.
    pub fn from_vars(var: impl Fn(&str) -> Option<String>) -> Result<ZenohOptions, TransportError> {
        let mut options = ZenohOptions::default();
        if let Some(path) = var("KPL_ZENOH_CONFIG").filter(|p| !p.is_empty()) {
            options.config_file = Some(PathBuf::from(path));
        }
        if let Some(base) = var("KPL_ZENOH_PORT_BASE").filter(|p| !p.is_empty()) {
            options.port_base = base.trim().parse().map_err(|_| {
                TransportError(format!("KPL_ZENOH_PORT_BASE=`{base}` is not a port number (1-65535)"))
            })?;
        }
        if let Some(wait) = var("KPL_ZENOH_WAIT").filter(|p| !p.is_empty()) {
            let seconds: f64 =
                wait.trim().parse().ok().filter(|s: &f64| s.is_finite() && *s >= 0.0).ok_or_else(|| {
                    TransportError(format!("KPL_ZENOH_WAIT=`{wait}` is not a number of seconds"))
                })?;
            options.subscriber_wait = Duration::from_secs_f64(seconds);
        }
        Ok(options)
    }
}

/// A host's endpoints, and whether they were given or are the loopback defaults.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Endpoints {
    pub listen: Vec<String>,
    pub connect: Vec<String>,
    /// Whether the deploy section gave any endpoint for this host.
    pub explicit: bool,
}

/// The endpoints of `host` (a host of `deploy`), or of a run without `--host` when `host` is
/// `None`.
pub fn endpoints(
    deploy: Option<&hir::Deploy>,
    host: Option<&str>,
    port_base: u16,
) -> Result<Endpoints, TransportError> {
    let default_listen = |i: usize| -> Result<String, TransportError> {
        let port = u16::try_from(i).ok().and_then(|i| port_base.checked_add(i)).ok_or_else(|| {
            TransportError(format!(
                "the default port of host {i} is past 65535 (KPL_ZENOH_PORT_BASE={port_base})"
            ))
        })?;
        Ok(format!("tcp/127.0.0.1:{port}"))
    };
    let (Some(deploy), Some(host)) = (deploy, host) else {
        return Ok(Endpoints { listen: vec![default_listen(0)?], connect: Vec::new(), explicit: false });
    };
    let index = deploy
        .hosts
        .iter()
        .position(|h| h.name == host)
        .ok_or_else(|| TransportError(format!("the deploy section has no host `{host}`")))?;
    let listen_of = |i: usize| -> Result<Vec<String>, TransportError> {
        let h = &deploy.hosts[i];
        if !h.listen.is_empty() {
            Ok(h.listen.clone())
        } else if !h.connect.is_empty() {
            Ok(Vec::new())
        } else {
            Ok(vec![default_listen(i)?])
        }
    };
    let this = &deploy.hosts[index];
    let connect = if this.connect.is_empty() {
        let mut all = Vec::new();
        for i in 0..index {
            for endpoint in listen_of(i)? {
                if !all.contains(&endpoint) {
                    all.push(endpoint);
                }
            }
        }
        all
    } else {
        this.connect.clone()
    };
    let endpoints = Endpoints {
        listen: listen_of(index)?,
        connect,
        explicit: !this.listen.is_empty() || !this.connect.is_empty(),
    };
    for endpoint in endpoints.listen.iter().chain(&endpoints.connect) {
        check_protocol(endpoint)?;
    }
    Ok(endpoints)
}

/// The link protocols this build of kpl has.
pub fn protocols() -> &'static [&'static str] {
    if cfg!(feature = "tls") { &["tcp", "tls"] } else { &["tcp"] }
}

fn check_protocol(endpoint: &str) -> Result<(), TransportError> {
    let protocol = endpoint.split('/').next().unwrap_or("");
    if protocols().contains(&protocol) {
        return Ok(());
    }
    let hint = if protocol == "tls" {
        "build kpl with TLS: `cargo build --release --features kpl/zenoh-tls`".to_string()
    } else {
        format!("this build of kpl has the zenoh transports {}", protocols().join(", "))
    };
    Err(TransportError(format!("endpoint `{endpoint}`: `{protocol}` links are not built in ({hint})")))
}

/// The zenoh configuration of a session with these endpoints.
pub fn session_config(
    endpoints: &Endpoints,
    options: &ZenohOptions,
) -> Result<zenoh::Config, TransportError> {
    let mut config = match &options.config_file {
        Some(path) => zenoh::Config::from_file(path).map_err(|e| {
            TransportError(format!("cannot read the zenoh configuration {}: {e}", path.display()))
        })?,
        None => zenoh::Config::default(),
    };
    let from_file = options.config_file.is_some();
    let set = |config: &mut zenoh::Config, key: &str, value: String| {
        config
            .insert_json5(key, &value)
            .map_err(|e| TransportError(format!("cannot set zenoh's `{key}` to {value}: {e}")))
    };
    set(&mut config, "mode", "\"peer\"".into())?;
    set(&mut config, "scouting/multicast/enabled", "false".into())?;
    // Dial again soon when the other host is not up yet (zenoh's default waits 1 s, then 2, 4).
    set(
        &mut config,
        "connect/retry",
        "{ period_init_ms: 100, period_max_ms: 1000, period_increase_factor: 2.0 }".into(),
    )?;
    let file_has = |config: &zenoh::Config, key: &str| {
        config.get_json(key).is_ok_and(|json| json.trim() != "[]" && json.trim() != "null")
    };
    let keep_file_endpoints = from_file
        && !endpoints.explicit
        && (file_has(&config, "listen/endpoints") || file_has(&config, "connect/endpoints"));
    if !keep_file_endpoints {
        set(&mut config, "listen/endpoints", json_list(&endpoints.listen))?;
        set(&mut config, "connect/endpoints", json_list(&endpoints.connect))?;
    }
    Ok(config)
}

fn json_list(items: &[String]) -> String {
    serde_json::to_string(items).unwrap_or_else(|_| "[]".into())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn deploy(hosts: &[(&str, &[&str], &[&str])]) -> hir::Deploy {
        hir::Deploy {
            hosts: hosts
                .iter()
                .map(|(name, listen, connect)| hir::Host {
                    name: name.to_string(),
                    listen: listen.iter().map(|s| s.to_string()).collect(),
                    connect: connect.iter().map(|s| s.to_string()).collect(),
                    processes: Vec::new(),
                })
                .collect(),
        }
    }

    fn of(d: &hir::Deploy, host: &str) -> (Vec<String>, Vec<String>) {
        let e = endpoints(Some(d), Some(host), 7447).unwrap();
        (e.listen, e.connect)
    }

    fn strings(items: &[&str]) -> Vec<String> {
        items.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn loopback_defaults_link_every_pair_once() {
        let d = deploy(&[("a", &[], &[]), ("b", &[], &[]), ("c", &[], &[])]);
        assert_eq!(of(&d, "a"), (strings(&["tcp/127.0.0.1:7447"]), vec![]));
        assert_eq!(of(&d, "b"), (strings(&["tcp/127.0.0.1:7448"]), strings(&["tcp/127.0.0.1:7447"])));
        assert_eq!(
            of(&d, "c"),
            (strings(&["tcp/127.0.0.1:7449"]), strings(&["tcp/127.0.0.1:7447", "tcp/127.0.0.1:7448"]))
        );
        assert!(!endpoints(Some(&d), Some("a"), 7447).unwrap().explicit);
        let e = endpoints(Some(&d), Some("c"), 20000).unwrap();
        assert_eq!(e.listen, strings(&["tcp/127.0.0.1:20002"]));
    }

    #[test]
    fn given_endpoints_are_kept() {
        // The layout of docs/language.md: one host listens, the other dials it.
        let d = deploy(&[("uav", &["tcp/127.0.0.1:9000"], &[]), ("ground", &[], &["tcp/127.0.0.1:9000"])]);
        assert_eq!(of(&d, "uav"), (strings(&["tcp/127.0.0.1:9000"]), vec![]));
        assert_eq!(of(&d, "ground"), (vec![], strings(&["tcp/127.0.0.1:9000"])));
        // A host without endpoints dials the ones before it that listen.
        let d = deploy(&[("a", &["tcp/0.0.0.0:9000"], &[]), ("b", &[], &[])]);
        assert_eq!(of(&d, "b"), (strings(&["tcp/127.0.0.1:7448"]), strings(&["tcp/0.0.0.0:9000"])));
    }

    #[test]
    fn without_a_host_the_first_default() {
        let e = endpoints(None, None, 7500).unwrap();
        assert_eq!((e.listen, e.connect), (strings(&["tcp/127.0.0.1:7500"]), vec![]));
    }

    #[test]
    fn errors_are_clear() {
        let d = deploy(&[("a", &["udp/127.0.0.1:9000"], &[])]);
        let err = endpoints(Some(&d), Some("a"), 7447).unwrap_err().to_string();
        assert!(err.contains("`udp` links are not built in"), "{err}");
        assert!(endpoints(Some(&d), Some("zz"), 7447).unwrap_err().to_string().contains("no host `zz`"));
        let many = deploy(&[("a", &[], &[]), ("b", &[], &[])]);
        let err = endpoints(Some(&many), Some("b"), 65535).unwrap_err().to_string();
        assert!(err.contains("past 65535"), "{err}");
        if !cfg!(feature = "tls") {
            let d = deploy(&[("a", &["tls/127.0.0.1:9000"], &[])]);
            let err = endpoints(Some(&d), Some("a"), 7447).unwrap_err().to_string();
            assert!(err.contains("features kpl/zenoh-tls"), "{err}");
        }
    }

    #[test]
    fn options_from_the_environment() {
        let vars = |pairs: &'static [(&'static str, &'static str)]| {
            move |name: &str| pairs.iter().find(|(n, _)| *n == name).map(|(_, v)| v.to_string())
        };
        assert_eq!(ZenohOptions::from_vars(vars(&[])).unwrap(), ZenohOptions::default());
        let o = ZenohOptions::from_vars(vars(&[("KPL_ZENOH_PORT_BASE", "17000"), ("KPL_ZENOH_WAIT", "2.5")]))
            .unwrap();
        assert_eq!((o.port_base, o.subscriber_wait), (17000, Duration::from_millis(2500)));
        let err = ZenohOptions::from_vars(vars(&[("KPL_ZENOH_PORT_BASE", "70000")])).unwrap_err();
        assert!(err.to_string().contains("not a port number"), "{err}");
        assert!(ZenohOptions::from_vars(vars(&[("KPL_ZENOH_WAIT", "-1")])).is_err());
    }

    #[test]
    fn the_session_is_a_peer_without_multicast() {
        let e = Endpoints { listen: strings(&["tcp/127.0.0.1:7447"]), connect: vec![], explicit: false };
        let config = session_config(&e, &ZenohOptions::default()).unwrap();
        assert_eq!(config.get_json("mode").unwrap(), "\"peer\"");
        assert_eq!(config.get_json("scouting/multicast/enabled").unwrap(), "false");
        assert_eq!(config.get_json("listen/endpoints").unwrap(), "[\"tcp/127.0.0.1:7447\"]");
        assert_eq!(config.get_json("connect/endpoints").unwrap(), "[]");
    }

    #[test]
    fn a_config_file_is_the_starting_point() {
        let dir = std::env::temp_dir().join(format!("kpl-zenoh-config-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("z.json5");
        std::fs::write(
            &path,
            "{ listen: { endpoints: [\"tcp/127.0.0.1:9999\"] }, scouting: { multicast: { enabled: true } } }",
        )
        .unwrap();
        let options = ZenohOptions { config_file: Some(path.clone()), ..ZenohOptions::default() };
        let defaults =
            Endpoints { listen: strings(&["tcp/127.0.0.1:7447"]), connect: vec![], explicit: false };
        let config = session_config(&defaults, &options).unwrap();
        assert_eq!(config.get_json("listen/endpoints").unwrap(), "[\"tcp/127.0.0.1:9999\"]");
        assert_eq!(config.get_json("scouting/multicast/enabled").unwrap(), "false");
        let given = Endpoints { explicit: true, ..defaults };
        let config = session_config(&given, &options).unwrap();
        assert_eq!(config.get_json("listen/endpoints").unwrap(), "[\"tcp/127.0.0.1:7447\"]");
        std::fs::write(&path, "{ not json").unwrap();
        let err = session_config(&given, &options).unwrap_err().to_string();
        assert!(err.contains("cannot read the zenoh configuration"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
