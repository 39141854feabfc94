//! The page server of a view: a small HTTP server (`tiny_http`) on a thread of its own that
//! serves the page (its HTML, script and style ship in the binary) and what it draws as JSON:
//!
//! | path | what |
//! |---|---|
//! | `/` | the page |
//! | `/api/state` | title, live or recording, running, time span, streams |
//! | `/api/scene` | lanes, occluders, bounds |
//! | `/api/frame?t=MICROS` | each level's objects, the percepts, the camera footprint and the counters at `t` (the latest without `t`) |
//! | `/api/situations` | the situations recognised so far, in the order they were |
//!
//! Requests are answered one at a time; only `GET` is served.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use kpl_core::Time;
use serde::Serialize;
use tiny_http::{Header, Method, Request, Response, Server};

use crate::hub::Hub;

const INDEX: &str = include_str!("../assets/index.html");
const SCRIPT: &str = include_str!("../assets/view.js");
const STYLE: &str = include_str!("../assets/view.css");

/// A running page server.
#[derive(Debug)]
pub struct PageServer {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    /// `http://HOST:PORT/`.
    pub url: String,
}

/// Serves the page of `hub` at `addr` (`HOST:PORT`, port 0 for any free one).
pub fn serve(hub: &Arc<Hub>, addr: &str) -> Result<PageServer, String> {
    let (host, port) = crate::split_addr(addr)?;
    let server =
        Server::http((host.as_str(), port)).map_err(|e| format!("cannot serve the page at {addr}: {e}"))?;
    let port = server.server_addr().to_ip().map_or(port, |a| a.port());
    let url = format!("http://{host}:{port}/");
    let stop = Arc::new(AtomicBool::new(false));
    let thread = {
        let (hub, stop) = (hub.clone(), stop.clone());
        std::thread::Builder::new()
            .name("kpl-view-page".into())
            .spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    match server.recv_timeout(Duration::from_millis(100)) {
                        Ok(Some(request)) => answer(&hub, request),
                        Ok(None) => {}
                        Err(e) => {
                            tracing::warn!("view: the page server stopped: {e}");
                            break;
                        }
                    }
                }
            })
            .map_err(|e| format!("cannot start the page server: {e}"))?
    };
    Ok(PageServer { stop, thread: Some(thread), url })
}

impl PageServer {
    pub fn stop(mut self) {
        self.shutdown();
    }

    fn shutdown(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Drop for PageServer {
    fn drop(&mut self) {
        self.shutdown();
    }
}

fn header(name: &str, value: &str) -> Option<Header> {
    Header::from_bytes(name.as_bytes(), value.as_bytes()).ok()
}

fn respond(request: Request, status: u16, content_type: &str, body: Vec<u8>) {
    let mut response = Response::from_data(body).with_status_code(status);
    for h in [header("Content-Type", content_type), header("Cache-Control", "no-store")].into_iter().flatten()
    {
        response.add_header(h);
    }
    // A client that went away is no concern of the server's.
    let _ = request.respond(response);
}

fn json(request: Request, value: &impl Serialize) {
    match serde_json::to_vec(value) {
        Ok(body) => respond(request, 200, "application/json", body),
        Err(e) => respond(request, 500, "text/plain; charset=utf-8", e.to_string().into_bytes()),
    }
}

/// The `t` of a query string (`t=12500000`).
fn time_of(query: &str) -> Option<Time> {
    query.split('&').find_map(|pair| pair.strip_prefix("t=")?.parse().ok())
}

fn answer(hub: &Hub, request: Request) {
    if *request.method() != Method::Get {
        return respond(request, 405, "text/plain; charset=utf-8", b"only GET".to_vec());
    }
    let url = request.url().to_string();
    let (path, query) = url.split_once('?').unwrap_or((&url, ""));
    match path {
        "/" | "/index.html" => respond(request, 200, "text/html; charset=utf-8", INDEX.as_bytes().to_vec()),
        "/view.js" => respond(request, 200, "text/javascript; charset=utf-8", SCRIPT.as_bytes().to_vec()),
        "/view.css" => respond(request, 200, "text/css; charset=utf-8", STYLE.as_bytes().to_vec()),
        "/api/state" => {
            let state = hub.timeline().state();
            json(request, &state)
        }
        "/api/scene" => {
            let scene = hub.timeline().scene().clone();
            json(request, &*scene)
        }
        "/api/frame" => {
            let frame = hub.timeline().frame(time_of(query));
            json(request, &frame)
        }
        "/api/situations" => {
            let situations: Vec<_> = hub.timeline().situations().cloned().collect();
            json(request, &situations)
        }
        _ => respond(request, 404, "text/plain; charset=utf-8", b"not found".to_vec()),
    }
}
