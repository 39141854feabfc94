//! `kpl launch`: every host of a spec's deployment as a child process on this machine (for
//! development and tests), each host's outputs and log under one folder, and one summary. It
//! prints the command that starts each host elsewhere, too.
//!
//! Each child is `kpl run SPEC --host HOST --clock wall --out OUT/HOST --quiet` with the
//! deployment's name (and keys); its standard error goes to `OUT/HOST/kpl.log` and, prefixed
//! with the host's name, to this command's. Ctrl-C and SIGTERM reach every child (the children
//! stop cleanly and write their summaries), and the summary is made from their `summary.json`.

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};
use std::time::Duration;

use clap::Args as ClapArgs;
use kpl_core::Time;

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  kpl launch specs/zenoh/two_hosts.kpl --out out/two\n  kpl launch specs/zenoh/two_hosts.kpl --tls --for 10s\n  kpl launch specs/zenoh/two_hosts.kpl --dry-run      # only print each host's command\n\nHosts without endpoints in the deploy section use loopback ports from KPL_ZENOH_PORT_BASE (7447);\nwhen those are taken (by anything, or by another launch still running), launch picks free ones.\nOne launch at a time per --out folder. Without --keys, --tls or --insecure the hosts use the keys\nmade on first use for the spec's deployment (as `kpl run --host` does). Outputs go to OUT/HOST, logs to OUT/HOST/kpl.log, the\ncombined summary to OUT/launch.json.\nExit status: 0 every host done, else the first host's failing status (1 failed, 3 incomplete),\n130 / 143 when interrupted by Ctrl-C / SIGTERM, 1 the spec has errors, 2 usage or I/O errors."
)]
pub struct Args {
    /// The spec to launch (it needs a deploy section).
    pub spec: PathBuf,
    /// Folder of the hosts' outputs (default: out/SPEC).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Stop every host after this much wall-clock time, e.g. 30s.
    #[arg(long = "for", value_parser = super::run::parse_duration)]
    pub duration: Option<Time>,
    /// The deployment's name (default: the spec's `deploy NAME`, else `default`).
    #[arg(long)]
    pub deployment: Option<String>,
    /// The deployment's keys folder (`kpl keys`): mutual TLS, access control, authenticated
    /// messages.
    #[arg(long, conflicts_with = "tls")]
    pub keys: Option<PathBuf>,
    /// Make keys for this launch in OUT/keys (kept for the next launch) and use them.
    #[arg(long)]
    pub tls: bool,
    /// Run every host without keys (`kpl run --insecure`). Without --keys, --tls or this, the
    /// hosts authenticate each other with the keys made on first use for the spec's deployment.
    #[arg(long, conflicts_with_all = ["keys", "tls"])]
    pub insecure: bool,
    /// Seed of every random process.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Stop a host at its first malformed input.
    #[arg(long)]
    pub strict: bool,
    /// Print each host's command and launch nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Do not relay the hosts' logs.
    #[arg(long, short)]
    pub quiet: bool,
}

/// What one host did, for the combined summary.
#[derive(Debug, serde::Serialize)]
struct HostOutcome {
    host: String,
    exit_code: Option<i32>,
    out: PathBuf,
    /// The host's `summary.json`, when it wrote one.
    report: Option<serde_json::Value>,
}

pub fn run(args: Args) -> ExitCode {
    let spec = match super::check::load_checked(&args.spec) {
        Ok(spec) => spec,
        Err(code) => return code,
    };
    let Some(deploy) = &spec.deploy else {
        eprintln!("error: {} has no deploy section: nothing to launch", args.spec.display());
        return ExitCode::from(1);
    };
    let stem = args.spec.file_stem().map_or_else(|| "spec".to_string(), |s| s.to_string_lossy().into_owned());
    let out = args.out.clone().unwrap_or_else(|| PathBuf::from("out").join(&stem));
    let deployment = args
        .deployment
        .clone()
        .or_else(|| deploy.name.clone())
        .unwrap_or_else(|| kpl_runtime::run::DEFAULT_DEPLOYMENT.to_string());
    let hosts: Vec<String> = deploy.hosts.iter().map(|h| h.name.clone()).collect();
    let keys = if args.tls { Some(out.join("keys")) } else { args.keys.clone() };

    let host_args = |host: &str, out: Option<&Path>| -> Vec<String> {
        let mut a = vec![
            "run".to_string(),
            args.spec.display().to_string(),
            "--host".into(),
            host.to_string(),
            "--clock".into(),
            "wall".into(),
            "--deployment".into(),
            deployment.clone(),
        ];
        if let Some(keys) = &keys {
            a.extend(["--keys".to_string(), keys.display().to_string()]);
        }
        if args.insecure {
            a.push("--insecure".into());
        }
        if let Some(d) = args.duration {
            a.extend(["--for".to_string(), format!("{d}us")]);
        }
        if args.seed != 0 {
            a.extend(["--seed".to_string(), args.seed.to_string()]);
        }
        if args.strict {
            a.push("--strict".into());
        }
        if let Some(out) = out {
            a.extend(["--out".to_string(), out.display().to_string(), "--quiet".into()]);
        }
        a
    };
    eprintln!("to start each host of deployment `{deployment}` elsewhere, one per machine:");
    for host in &hosts {
        eprintln!("  kpl {}", host_args(host, None).join(" "));
    }
    if deploy.hosts.iter().any(|h| h.listen.is_empty() && h.connect.is_empty()) {
        eprintln!(
            "  (hosts on other machines need `listen` / `connect` endpoints in the deploy section; \
             without them hosts use loopback ports)"
        );
    }
    if keys.is_some() {
        eprintln!("  (each machine needs the keys folder's ca.pem, secret, HOST.pem and HOST.key)");
    }
    if args.dry_run {
        return ExitCode::SUCCESS;
    }

    if let Err(err) = std::fs::create_dir_all(&out) {
        crate::report::io_error(&out, &err);
        return ExitCode::from(2);
    }
    // One launch per output folder: a second one would write into the first one's files.
    let _lock = match claim(&out.join("launch.lock"), &args.spec.display().to_string()) {
        Ok(lock) => lock,
        Err(err) => {
            eprintln!("error: {err}");
            return ExitCode::from(2);
        }
    };
    if args.tls
        && let Some(keys) = &keys
        && let Err(err) = kpl_zenoh::credentials::make(keys, &deployment, &hosts)
    {
        eprintln!("error: cannot make the keys in {}: {err}", keys.display());
        return ExitCode::from(2);
    }
    let (port_base, _ports) = match port_base(hosts.len()) {
        Ok(base) => base,
        Err(err) => {
            eprintln!("error: {err}");
            return ExitCode::from(2);
        }
    };
    let exe = match std::env::current_exe() {
        Ok(exe) => exe,
        Err(err) => {
            eprintln!("error: cannot find the kpl executable to start the hosts: {err}");
            return ExitCode::from(2);
        }
    };

    let signal = Arc::new(AtomicU8::new(0));
    watch_signals(signal.clone());
    let mut children: Vec<(String, Child, std::thread::JoinHandle<()>)> = Vec::new();
    for host in &hosts {
        let host_out = out.join(host);
        if let Err(err) = std::fs::create_dir_all(&host_out) {
            crate::report::io_error(&host_out, &err);
            stop_all(&mut children, "TERM");
            return ExitCode::from(2);
        }
        let mut command = Command::new(&exe);
        command
            .args(host_args(host, Some(&host_out)))
            .env("KPL_ZENOH_PORT_BASE", port_base.to_string())
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        match command.spawn() {
            Ok(mut child) => {
                eprintln!(
                    "host `{host}`: started (process {}), outputs in {}",
                    child.id(),
                    host_out.display()
                );
                let relay = relay_log(child.stderr.take(), host, &host_out.join("kpl.log"), args.quiet);
                children.push((host.clone(), child, relay));
            }
            Err(err) => {
                eprintln!("error: cannot start host `{host}`: {err}");
                stop_all(&mut children, "TERM");
                return ExitCode::from(2);
            }
        }
    }

    // Wait for every host, passing on Ctrl-C and SIGTERM.
    let mut statuses: Vec<Option<i32>> = vec![None; children.len()];
    let mut forwarded = 0u8;
    loop {
        let received = signal.load(Ordering::SeqCst);
        if received != 0 && received != forwarded {
            forwarded = received;
            let name = if received == 15 { "TERM" } else { "INT" };
            eprintln!("SIG{name}: stopping every host");
            for (_, child, _) in &children {
                send_signal(child.id(), name);
            }
        }
        let mut running = false;
        for (i, (_, child, _)) in children.iter_mut().enumerate() {
            if statuses[i].is_some() {
                continue;
            }
            match child.try_wait() {
                Ok(Some(status)) => statuses[i] = Some(status.code().unwrap_or(1)),
                Ok(None) => running = true,
                Err(_) => statuses[i] = Some(1),
            }
        }
        if !running {
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let mut outcomes = Vec::new();
    for ((host, _, relay), status) in children.into_iter().zip(&statuses) {
        let _ = relay.join();
        let host_out = out.join(&host);
        let report = std::fs::read_to_string(host_out.join("summary.json"))
            .ok()
            .and_then(|text| serde_json::from_str(&text).ok());
        outcomes.push(HostOutcome { host, exit_code: *status, out: host_out, report });
    }
    let summary = serde_json::json!({
        "spec": args.spec.display().to_string(),
        "deployment": deployment,
        "hosts": outcomes,
    });
    if let Ok(text) = serde_json::to_string_pretty(&summary) {
        let _ = std::fs::write(out.join("launch.json"), text + "\n");
    }
    let _ = std::io::stderr().lock().write_all(describe(&deployment, &out, &outcomes).as_bytes());
    match signal.load(Ordering::SeqCst) {
        15 => return ExitCode::from(143),
        2 => return ExitCode::from(130),
        _ => {}
    }
    match outcomes.iter().find_map(|o| o.exit_code.filter(|c| *c != 0)) {
        Some(code) => ExitCode::from(u8::try_from(code).unwrap_or(1)),
        None => ExitCode::SUCCESS,
    }
}

/// The combined summary: per host its exit status, how its run ended, and what happened between
/// the hosts.
fn describe(deployment: &str, out: &Path, outcomes: &[HostOutcome]) -> String {
    use std::fmt::Write as _;
    let mut text =
        format!("deployment `{deployment}`: {} host(s), outputs in {}\n", outcomes.len(), out.display());
    for o in outcomes {
        let code = o.exit_code.map_or_else(|| "no status".to_string(), |c| format!("exit {c}"));
        let Some(report) = &o.report else {
            let _ = writeln!(
                text,
                "  host `{}`: {code}, no summary (see {})",
                o.host,
                o.out.join("kpl.log").display()
            );
            continue;
        };
        let ending = report["ending"].as_str().unwrap_or("?");
        let signal = report["signal"].as_str().map(|s| format!(" ({s})")).unwrap_or_default();
        let clock = report["clock_elapsed"].as_f64().unwrap_or(0.0) / 1e6;
        let _ = write!(text, "  host `{}`: {code}, {ending}{signal} after {clock:.1} s", o.host);
        let transport = &report["transport"];
        let sum = |list: &str, field: &str| -> u64 {
            transport[list].as_array().map_or(0, |l| l.iter().filter_map(|s| s[field].as_u64()).sum())
        };
        if transport.is_object() {
            let _ = write!(
                text,
                "; sent {} sample(s), received {}, lost {}, refused {}",
                sum("outbound", "published"),
                sum("inbound", "received"),
                sum("inbound", "lost"),
                sum("inbound", "refused")
            );
        }
        text.push('\n');
        for failure in report["failures"].as_array().into_iter().flatten() {
            let _ = writeln!(text, "    failed: {}", failure.as_str().unwrap_or(""));
        }
        for stream in transport["inbound"].as_array().into_iter().flatten() {
            if let Some(why) = stream["ending"].get("cut_short").and_then(|w| w.as_str()) {
                let _ = writeln!(text, "    cut short: `{}`: {why}", stream["stream"].as_str().unwrap_or(""));
            }
        }
        for host in transport["hosts"].as_array().into_iter().flatten() {
            if host["lost"].as_u64().unwrap_or(0) > 0 {
                let _ = writeln!(
                    text,
                    "    host `{}` went away {} time(s), away {:.1} s",
                    host["host"].as_str().unwrap_or(""),
                    host["lost"],
                    host["away_s"].as_f64().unwrap_or(0.0)
                );
            }
        }
    }
    text
}

/// A file that says a process holds something (an output folder, a port): made with
/// `create_new`, holding the process id and what it is for; removed when dropped. A claim whose
/// process is gone is taken over.
struct Claim(PathBuf);

impl Drop for Claim {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Whether process `pid` runs (on Linux; elsewhere every claim is taken as held).
fn alive(pid: u32) -> bool {
    !Path::new("/proc/self").exists() || Path::new(&format!("/proc/{pid}")).exists()
}

/// Claims `path` for this process (`what`: said to a process that finds it taken).
fn claim(path: &Path, what: &str) -> Result<Claim, String> {
    for _ in 0..3 {
        match std::fs::OpenOptions::new().write(true).create_new(true).open(path) {
            Ok(mut file) => {
                let _ = writeln!(file, "{} {what}", std::process::id());
                return Ok(Claim(path.to_path_buf()));
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                let text = std::fs::read_to_string(path).unwrap_or_default();
                let mut words = text.trim().splitn(2, ' ');
                let pid = words.next().and_then(|p| p.parse::<u32>().ok());
                match pid {
                    Some(pid) if alive(pid) => {
                        return Err(format!(
                            "{} is held by another kpl launch (process {pid}, {}); give this one another --out",
                            path.parent().unwrap_or(path).display(),
                            words.next().unwrap_or("")
                        ));
                    }
                    // Its process is gone: take it over.
                    _ => {
                        let _ = std::fs::remove_file(path);
                    }
                }
            }
            Err(e) => return Err(format!("cannot create {}: {e}", path.display())),
        }
    }
    Err(format!("cannot claim {}", path.display()))
}

/// The first of `n` loopback ports for hosts without endpoints: `KPL_ZENOH_PORT_BASE` when set,
/// else 7447 when its ports are free, else free ones. The ports are claimed (a file per port in
/// the temporary folder's `kpl-ports`) until this launch ends, so two launches started at once
/// never pick the same ones.
fn port_base(n: usize) -> Result<(u16, Vec<Claim>), String> {
    if let Ok(base) = std::env::var("KPL_ZENOH_PORT_BASE")
        && !base.is_empty()
    {
        let base =
            base.trim().parse().map_err(|_| format!("KPL_ZENOH_PORT_BASE=`{base}` is not a port number"))?;
        return Ok((base, Vec::new()));
    }
    let n = u16::try_from(n).map_err(|_| "too many hosts".to_string())?;
    let claims = std::env::temp_dir().join("kpl-ports");
    std::fs::create_dir_all(&claims).map_err(|e| format!("cannot create {}: {e}", claims.display()))?;
    let take = |base: u16| -> Option<Vec<Claim>> {
        base.checked_add(n)?;
        let mut held = Vec::new();
        for port in base..base + n {
            let claim = claim(&claims.join(port.to_string()), "kpl launch").ok()?;
            if std::net::TcpListener::bind(("127.0.0.1", port)).is_err() {
                return None;
            }
            held.push(claim);
        }
        Some(held)
    };
    if let Some(held) = take(kpl_zenoh::config::DEFAULT_PORT_BASE) {
        return Ok((kpl_zenoh::config::DEFAULT_PORT_BASE, held));
    }
    for _ in 0..100 {
        let base = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .map_err(|e| format!("cannot find free ports: {e}"))?
            .port();
        if let Some(held) = take(base) {
            return Ok((base, held));
        }
    }
    Err(format!("no {n} free consecutive ports on 127.0.0.1"))
}

/// Copies a child's standard error to its log file and (unless quiet) to this one's, each line
/// prefixed with the host's name.
fn relay_log(
    from: Option<std::process::ChildStderr>,
    host: &str,
    log: &Path,
    quiet: bool,
) -> std::thread::JoinHandle<()> {
    let host = host.to_string();
    let log = std::fs::File::create(log).ok();
    std::thread::spawn(move || {
        let Some(from) = from else { return };
        let mut log = log.map(std::io::BufWriter::new);
        for line in BufReader::new(from).lines() {
            let Ok(line) = line else { break };
            if let Some(log) = &mut log {
                let _ = writeln!(log, "{line}");
            }
            if !quiet {
                eprintln!("{host} | {line}");
            }
        }
        if let Some(log) = &mut log {
            let _ = log.flush();
        }
    })
}

/// Records Ctrl-C (2) or SIGTERM (15) in `signal`, from a thread of its own.
fn watch_signals(signal: Arc<AtomicU8>) {
    std::thread::spawn(move || {
        let Ok(runtime) = tokio::runtime::Builder::new_current_thread().enable_all().build() else { return };
        runtime.block_on(async move {
            loop {
                let received = kpl_runtime::run::Signal::next().await;
                let number = match received {
                    kpl_runtime::run::Signal::Terminate => 15,
                    kpl_runtime::run::Signal::Interrupt => 2,
                };
                signal.store(number, Ordering::SeqCst);
            }
        });
    });
}

/// Sends a signal (`TERM`, `INT`) to a process with the system's `kill` command (the standard
/// library only sends SIGKILL).
fn send_signal(pid: u32, name: &str) {
    let _ = Command::new("kill").args(["-s", name, &pid.to_string()]).stderr(Stdio::null()).status();
}

fn stop_all(children: &mut [(String, Child, std::thread::JoinHandle<()>)], signal: &str) {
    for (_, child, _) in children.iter_mut() {
        send_signal(child.id(), signal);
        let _ = child.wait();
    }
}
