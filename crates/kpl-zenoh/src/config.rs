//! Where a host's zenoh session listens and what it connects to, and the session's configuration:
//! peer mode, multicast scouting off, explicit endpoints, and with a deployment's keys mutual TLS
//! and access control (docs/streams.md, "On the wire").
//!
//! Endpoints come from the spec's `deploy` section; a host that gives none gets loopback
//! defaults, so the hosts of one spec find each other on one machine without any setup:
//!
//! - **listen**: the host's `listen` endpoints; without them, none if the host gives `connect`
//!   endpoints (it only dials out), else `tcp/127.0.0.1:<base + i>` (`tls/...` with keys) where
//!   `i` is the host's position in the deploy section and `base` is 7447 (`KPL_ZENOH_PORT_BASE`);
//! - **connect**: the host's `connect` endpoints; without them, the listen endpoints of every host
//!   before it in the deploy section, so each pair of hosts links once, the later one dialling.
//!
//! A run without `--host` (a spec using `zenoh.subscribe` or `zenoh.publish` to talk to programs
//! outside it) counts as the first host of the default scheme: it listens on
//! `tcp/127.0.0.1:<base>`. A zenoh configuration file (`KPL_ZENOH_CONFIG`) is merged with these
//! defaults: what it sets is kept (transport tuning, its own TLS files, access control rules),
//! except what KPL needs (peer mode, multicast scouting off); its endpoints are used when the
//! deploy section gives none, and the loopback defaults when neither does. With keys, KPL's TLS
//! files and access-control rules are added to the file's.

use std::path::PathBuf;
use std::time::Duration;

use kpl_runtime::transport::TransportError;
use kpl_semantic::hir;

use crate::credentials::Credentials;

/// The zenoh default port: host `i` of the default scheme listens on `DEFAULT_PORT_BASE + i`.
pub const DEFAULT_PORT_BASE: u16 = 7447;
/// How long a host waits for other hosts by default: at start-up for the hosts consuming its
/// streams, at the end for them to have the end, and for a producing host that is gone.
pub const DEFAULT_SUBSCRIBER_WAIT: Duration = Duration::from_secs(30);
/// How long a host waits by default for a producing host that went away (or never came) before it
/// ends the streams from it as cut short.
pub const DEFAULT_GIVE_UP: Duration = Duration::from_secs(120);
/// The default capacity of a subscriber's queue in front of the runtime.
pub const DEFAULT_QUEUE: usize = 4096;

/// Options of the zenoh sessions of one process.
#[derive(Debug, Clone, PartialEq)]
pub struct ZenohOptions {
    /// A zenoh configuration file (JSON5) merged with the defaults (`KPL_ZENOH_CONFIG`).
    pub config_file: Option<PathBuf>,
    /// The first port of the loopback defaults (`KPL_ZENOH_PORT_BASE`).
    pub port_base: u16,
    /// How long a host waits for the others (`KPL_ZENOH_WAIT`, seconds): at start-up for the
    /// hosts that consume its streams (then it goes on, and they get the streams from when they
    /// come), and at the end for them to confirm they have the end.
    pub subscriber_wait: Duration,
    /// How long a host waits for a producing host that went away or never came before it ends
    /// the streams from it as cut short (`KPL_ZENOH_GIVE_UP`, seconds).
    pub give_up: Duration,
    /// Samples buffered per subscription before zenoh's receiving thread waits (back-pressure
    /// to the publisher, which then blocks: nothing is dropped).
    pub queue: usize,
    /// The deployment's keys folder (`--keys`, `KPL_KEYS`): mutual TLS between the hosts, access
    /// control, and authentication tags on every message.
    pub keys: Option<PathBuf>,
    /// Without a keys folder, the keys made on first use for this deployment
    /// ([`crate::credentials::default_dir`]): authentication tags on every message, `tcp/` links
    /// by default.
    pub first_use_keys: Option<PathBuf>,
    /// No keys at all (`kpl run --insecure`): anyone who reaches a host's port can send it
    /// samples, end its streams, or pretend to be a host of the deployment.
    pub insecure: bool,
}

impl Default for ZenohOptions {
    fn default() -> ZenohOptions {
        ZenohOptions {
            config_file: None,
            port_base: DEFAULT_PORT_BASE,
            subscriber_wait: DEFAULT_SUBSCRIBER_WAIT,
            give_up: DEFAULT_GIVE_UP,
            queue: DEFAULT_QUEUE,
            keys: None,
            first_use_keys: None,
            insecure: false,
        }
    }
}

impl ZenohOptions {
    /// The defaults, changed by the environment variables `KPL_ZENOH_CONFIG` (a zenoh config file),
    /// `KPL_ZENOH_PORT_BASE` (a port), `KPL_ZENOH_WAIT` and `KPL_ZENOH_GIVE_UP` (seconds) and
    /// `KPL_KEYS` (a keys folder).
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
        let seconds =
            |name: &str| -> Result<Option<Duration>, TransportError> {
                let Some(text) = var(name).filter(|p| !p.is_empty()) else { return Ok(None) };
                let seconds: f64 =
                    text.trim().parse().ok().filter(|s: &f64| s.is_finite() && *s >= 0.0).ok_or_else(
                        || TransportError(format!("{name}=`{text}` is not a number of seconds")),
                    )?;
                Ok(Some(Duration::from_secs_f64(seconds.min(1e9))))
            };
        if let Some(wait) = seconds("KPL_ZENOH_WAIT")? {
            options.subscriber_wait = wait;
        }
        if let Some(give_up) = seconds("KPL_ZENOH_GIVE_UP")? {
            options.give_up = give_up;
        }
        if let Some(keys) = var("KPL_KEYS").filter(|p| !p.is_empty()) {
            options.keys = Some(PathBuf::from(keys));
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
/// `None`. The loopback defaults are `tls/` links when `tls` (a deployment with keys).
pub fn endpoints(
    deploy: Option<&hir::Deploy>,
    host: Option<&str>,
    port_base: u16,
    tls: bool,
) -> Result<Endpoints, TransportError> {
    let scheme = if tls { "tls" } else { "tcp" };
    let default_listen = |i: usize| -> Result<String, TransportError> {
        let port = u16::try_from(i).ok().and_then(|i| port_base.checked_add(i)).ok_or_else(|| {
            TransportError(format!(
                "the default port of host {i} is past 65535 (KPL_ZENOH_PORT_BASE={port_base})"
            ))
        })?;
        Ok(format!("{scheme}/127.0.0.1:{port}"))
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

/// The link protocols of kpl's zenoh (what `kpl check` accepts in a deploy section).
pub fn protocols() -> &'static [&'static str] {
    &["tcp", "tls"]
}

fn check_protocol(endpoint: &str) -> Result<(), TransportError> {
    let protocol = endpoint.split('/').next().unwrap_or("");
    if protocols().contains(&protocol) {
        return Ok(());
    }
    Err(TransportError(format!(
        "endpoint `{endpoint}`: `{protocol}` links are not built in (kpl links hosts over {})",
        protocols().join(" and ")
    )))
}

/// What a host's session needs beyond its endpoints when its deployment has keys.
#[derive(Debug, Clone)]
pub struct Security {
    pub credentials: Credentials,
    /// The access-control section (zenoh's `access_control`) for this host.
    pub access_control: Option<serde_json::Value>,
}

/// The zenoh configuration of a session with these endpoints.
pub fn session_config(
    endpoints: &Endpoints,
    options: &ZenohOptions,
    security: Option<&Security>,
) -> Result<zenoh::Config, TransportError> {
    let mut config = match &options.config_file {
        Some(path) => zenoh::Config::from_file(path).map_err(|e| {
            TransportError(format!("cannot read the zenoh configuration {}: {e}", path.display()))
        })?,
        None => zenoh::Config::default(),
    };
    let defaults = zenoh::Config::default();
    // What the file sets differs from zenoh's defaults (which listen on every interface).
    let file_sets = |config: &zenoh::Config, key: &str| {
        options.config_file.is_some() && config.get_json(key).ok() != defaults.get_json(key).ok()
    };
    let keep_file_endpoints = !endpoints.explicit
        && (file_sets(&config, "listen/endpoints") || file_sets(&config, "connect/endpoints"));
    let file_tls = file_sets(&config, "transport/link/tls/root_ca_certificate")
        || file_sets(&config, "transport/link/tls/listen_certificate");
    let file_access_control = if file_sets(&config, "access_control") {
        config.get_json("access_control").ok().and_then(|json| serde_json::from_str(&json).ok())
    } else {
        None
    };
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
    if !keep_file_endpoints {
        set(&mut config, "listen/endpoints", json_list(&endpoints.listen))?;
        set(&mut config, "connect/endpoints", json_list(&endpoints.connect))?;
    }
    let uses_tls = |list: &[String]| list.iter().any(|e| e.starts_with("tls/"));
    match security {
        Some(security) => {
            let c = &security.credentials;
            let path = |p: &std::path::Path| json_string(&p.display().to_string());
            for (key, value) in [
                ("transport/link/tls/root_ca_certificate", path(&c.ca)),
                ("transport/link/tls/listen_certificate", path(&c.certificate)),
                ("transport/link/tls/listen_private_key", path(&c.private_key)),
                ("transport/link/tls/connect_certificate", path(&c.certificate)),
                ("transport/link/tls/connect_private_key", path(&c.private_key)),
                ("transport/link/tls/enable_mtls", "true".into()),
                // The deployment's own authority signs only its hosts; which host is on the other
                // side is its certificate's common name, which access control checks.
                ("transport/link/tls/verify_name_on_connect", "false".into()),
            ] {
                set(&mut config, key, value)?;
            }
            if let Some(rules) = &security.access_control {
                let merged = merge_access_control(file_access_control, rules.clone());
                set(&mut config, "access_control", merged.to_string())?;
            }
        }
        None if !file_tls && (uses_tls(&endpoints.listen) || uses_tls(&endpoints.connect)) => {
            return Err(TransportError(
                "`tls/` endpoints need the deployment's keys: make them with `kpl keys SPEC --out KEYS` \
                 and run every host with `--keys KEYS` (or give TLS files in a KPL_ZENOH_CONFIG file)"
                    .into(),
            ));
        }
        None => {}
    }
    Ok(config)
}

/// The file's access-control section with KPL's rules, subjects and policies added (KPL's
/// default permission when the file has none).
fn merge_access_control(file: Option<serde_json::Value>, ours: serde_json::Value) -> serde_json::Value {
    let Some(mut merged) =
        file.filter(|f| f.get("enabled").and_then(serde_json::Value::as_bool) == Some(true))
    else {
        return ours;
    };
    for list in ["rules", "subjects", "policies"] {
        let extra = ours.get(list).and_then(serde_json::Value::as_array).cloned().unwrap_or_default();
        match merged.get_mut(list).and_then(serde_json::Value::as_array_mut) {
            Some(items) => items.extend(extra),
            None => {
                if let Some(object) = merged.as_object_mut() {
                    object.insert(list.to_string(), serde_json::Value::Array(extra));
                }
            }
        }
    }
    merged
}

fn json_list(items: &[String]) -> String {
    serde_json::to_string(items).unwrap_or_else(|_| "[]".into())
}

fn json_string(text: &str) -> String {
    serde_json::to_string(text).unwrap_or_else(|_| "\"\"".into())
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
            name: None,
        }
    }

    fn of(d: &hir::Deploy, host: &str) -> (Vec<String>, Vec<String>) {
        let e = endpoints(Some(d), Some(host), 7447, false).unwrap();
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
        assert!(!endpoints(Some(&d), Some("a"), 7447, false).unwrap().explicit);
        let e = endpoints(Some(&d), Some("c"), 20000, false).unwrap();
        assert_eq!(e.listen, strings(&["tcp/127.0.0.1:20002"]));
        let e = endpoints(Some(&d), Some("c"), 20000, true).unwrap();
        assert_eq!(e.listen, strings(&["tls/127.0.0.1:20002"]));
        assert_eq!(e.connect, strings(&["tls/127.0.0.1:20000", "tls/127.0.0.1:20001"]));
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
        let e = endpoints(None, None, 7500, false).unwrap();
        assert_eq!((e.listen, e.connect), (strings(&["tcp/127.0.0.1:7500"]), vec![]));
    }

    #[test]
    fn errors_are_clear() {
        let d = deploy(&[("a", &["udp/127.0.0.1:9000"], &[])]);
        let err = endpoints(Some(&d), Some("a"), 7447, false).unwrap_err().to_string();
        assert!(err.contains("`udp` links are not built in"), "{err}");
        assert!(
            endpoints(Some(&d), Some("zz"), 7447, false).unwrap_err().to_string().contains("no host `zz`")
        );
        let many = deploy(&[("a", &[], &[]), ("b", &[], &[])]);
        let err = endpoints(Some(&many), Some("b"), 65535, false).unwrap_err().to_string();
        assert!(err.contains("past 65535"), "{err}");
        // TLS is built in, but needs keys.
        let d = deploy(&[("a", &["tls/127.0.0.1:9000"], &[])]);
        let e = endpoints(Some(&d), Some("a"), 7447, false).unwrap();
        let err = session_config(&e, &ZenohOptions::default(), None).unwrap_err().to_string();
        assert!(err.contains("need the deployment's keys"), "{err}");
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
        let o = ZenohOptions::from_vars(vars(&[("KPL_ZENOH_GIVE_UP", "7"), ("KPL_KEYS", "k")])).unwrap();
        assert_eq!((o.give_up, o.keys), (Duration::from_secs(7), Some(PathBuf::from("k"))));
        let err = ZenohOptions::from_vars(vars(&[("KPL_ZENOH_GIVE_UP", "soon")])).unwrap_err();
        assert!(err.to_string().contains("KPL_ZENOH_GIVE_UP=`soon`"), "{err}");
    }

    #[test]
    fn the_session_is_a_peer_without_multicast() {
        let e = Endpoints { listen: strings(&["tcp/127.0.0.1:7447"]), connect: vec![], explicit: false };
        let config = session_config(&e, &ZenohOptions::default(), None).unwrap();
        assert_eq!(config.get_json("mode").unwrap(), "\"peer\"");
        assert_eq!(config.get_json("scouting/multicast/enabled").unwrap(), "false");
        assert_eq!(config.get_json("listen/endpoints").unwrap(), "[\"tcp/127.0.0.1:7447\"]");
        assert_eq!(config.get_json("connect/endpoints").unwrap(), "[]");
    }

    #[test]
    fn a_config_file_merges_with_the_defaults() {
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
        let config = session_config(&defaults, &options, None).unwrap();
        assert_eq!(config.get_json("listen/endpoints").unwrap(), "[\"tcp/127.0.0.1:9999\"]");
        assert_eq!(config.get_json("scouting/multicast/enabled").unwrap(), "false");
        let given = Endpoints { explicit: true, ..defaults.clone() };
        let config = session_config(&given, &options, None).unwrap();
        assert_eq!(config.get_json("listen/endpoints").unwrap(), "[\"tcp/127.0.0.1:7447\"]");

        // A file without endpoints (only tuning, or only access control) keeps the loopback
        // defaults, not zenoh's (every interface, a random port).
        std::fs::write(
            &path,
            "{ transport: { link: { tx: { lease: 2000 } } }, access_control: { enabled: true, default_permission: 'allow', rules: [], subjects: [], policies: [] } }",
        )
        .unwrap();
        let config = session_config(&defaults, &options, None).unwrap();
        assert_eq!(config.get_json("listen/endpoints").unwrap(), "[\"tcp/127.0.0.1:7447\"]");
        assert_eq!(config.get_json("transport/link/tx/lease").unwrap(), "2000");
        assert_eq!(config.get_json("access_control/enabled").unwrap(), "true");

        std::fs::write(&path, "{ not json").unwrap();
        let err = session_config(&given, &options, None).unwrap_err().to_string();
        assert!(err.contains("cannot read the zenoh configuration"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn access_control_rules_are_added_to_the_files() {
        let ours = serde_json::json!({
            "enabled": true, "default_permission": "allow",
            "rules": [{"id": "kpl-1"}], "subjects": [{"id": "kpl-host-a"}], "policies": [{"rules": ["kpl-1"]}],
        });
        assert_eq!(merge_access_control(None, ours.clone()), ours);
        let file = serde_json::json!({
            "enabled": true, "default_permission": "deny",
            "rules": [{"id": "mine"}], "subjects": [], "policies": [],
        });
        let merged = merge_access_control(Some(file), ours.clone());
        assert_eq!(merged["default_permission"], "deny", "the file's default stays");
        assert_eq!(merged["rules"], serde_json::json!([{"id": "mine"}, {"id": "kpl-1"}]));
        assert_eq!(merged["subjects"], serde_json::json!([{"id": "kpl-host-a"}]));
        let disabled = serde_json::json!({"enabled": false});
        assert_eq!(merge_access_control(Some(disabled), ours.clone()), ours);
    }
}
