//! Seeing a run: what KPL knows (each level's anchored objects, the percepts, the situations
//! recognised) shown while a run goes, or from a recording, in two places:
//!
//! - Foxglove: a live Foxglove WebSocket server (Foxglove's own SDK, the `foxglove` crate)
//!   serving the streams in Foxglove's well-known schemas ([`kpl_mcap::foxglove`], the same
//!   views an MCAP recording has), the run's clock as the server's time ([`foxglove_server`]);
//! - a browser: a small page served by `kpl` itself, its assets in the binary, drawing the map,
//!   the objects, the camera footprint and occluders, a time slider, the situations and
//!   counters per level ([`page`]).
//!
//! A [`hub::Hub`] holds what is shown ([`timeline::Timeline`]); the `view.live` sink
//! ([`builtins`]) feeds it from a run (`kpl run --view ADDR --foxglove ADDR` adds that sink), and
//! [`recording::load`] from files (`kpl view`). Nothing here reads the run's clock: times are the
//! samples'.
//!
//! ```no_run
//! use kpl_mcap::foxglove::Role;
//! use kpl_mcap::scene::Scene;
//! use kpl_view::hub::Hub;
//!
//! let hub = Hub::new(Scene::default(), "a run", true);
//! let cars = hub.add_stream("cars", Role::Objects);
//! let page = kpl_view::page::serve(&hub, "127.0.0.1:0")?;
//! println!("open {}", page.url);
//! # let _ = cars;
//! # Ok::<(), String>(())
//! ```

pub mod builtins;
pub mod foxglove_server;
pub mod hub;
pub mod page;
pub mod recording;
pub mod timeline;

pub use builtins::register;

/// `HOST:PORT` split, for the servers (`127.0.0.1:0` for any free port).
pub fn split_addr(addr: &str) -> Result<(String, u16), String> {
    let (host, port) = addr
        .rsplit_once(':')
        .ok_or_else(|| format!("`{addr}` is not HOST:PORT (e.g. 127.0.0.1:8080, port 0 for any free one)"))?;
    let port = port.parse().map_err(|_| format!("`{addr}`: `{port}` is not a port number"))?;
    let host = host.trim_start_matches('[').trim_end_matches(']');
    if host.is_empty() {
        return Err(format!("`{addr}` names no host (e.g. 127.0.0.1:{port})"));
    }
    Ok((host.to_string(), port))
}
