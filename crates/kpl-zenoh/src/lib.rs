//! Streams between hosts over zenoh, and zenoh streams to and from programs outside a spec. The
//! runtime (`kpl-runtime`) knows only its `Transport` traits; this is the one crate that depends on
//! zenoh.
//!
//! - [`keys`]: the key expressions of streams (`kpl/<deployment>/<spec>/<producer>[/<port>]`) and
//!   tokens;
//! - [`codec`]: the wire format, one encode and one decode function (docs/streams.md);
//! - [`envelope`]: who sent a message, its place in its stream, and its authentication tag;
//! - [`flow`]: consuming hosts acknowledge what they took; producers keep a window of credit;
//! - [`config`]: each host's endpoints (the deploy section, or loopback defaults) and its session's
//!   configuration: peer mode, multicast scouting off, explicit endpoints, and with keys mutual TLS
//!   and access control;
//! - [`credentials`]: a deployment's keys (`kpl keys`) and what each host reads of them;
//! - [`Sessions`]: the one zenoh session of a host process;
//! - [`ZenohFactory`] / [`ZenohTransport`]: what `kpl run --host` sends streams through;
//! - `zenoh.subscribe` and `zenoh.publish` ([`register`]);
//! - [`ros2`]: `ros2.subscribe` and `ros2.publish`, ROS 2 topics over rmw_zenoh (the wire is
//!   `kpl-ros2`'s);
//! - [`bench`]: `kpl bench zenoh`, against bare zenoh code.
//!
//! zenoh needs a multi-threaded tokio runtime: `kpl run` uses one with `--clock wall`, which is
//! what runs between hosts and with programs outside need.
// The transport's liveliness, start-up waits and give-up times are real time whatever the run's
// clock (zenoh runs on the wall clock), and `kpl bench zenoh` times work: this crate reads the
// system's clocks (clippy.toml's `disallowed-methods` keeps the rest of the workspace on the
// runtime's `Clock`).
#![allow(clippy::disallowed_methods)]

pub mod bench;
pub mod codec;
pub mod config;
pub mod credentials;
pub mod envelope;
pub mod flow;
pub mod keys;
mod outside;
pub mod ros2;
mod session;
mod transport;

use std::sync::Arc;

pub use config::ZenohOptions;
pub use session::{HostSession, Sessions};
pub use transport::{Plan, ZenohFactory, ZenohReceiver, ZenohSender, ZenohTransport};

/// Adds `zenoh.subscribe` and `zenoh.publish` to a registry; they use this process's session
/// ([`Sessions::process`]), the same one as [`factory`]. ROS 2's topics register themselves
/// apart ([`ros2::register`]; `kpl_std::assemble` adds both).
pub fn register(registry: &mut kpl_runtime::Registry) {
    register_with(registry, Sessions::process());
}

/// As [`register`], with the given sessions.
pub fn register_with(registry: &mut kpl_runtime::Registry, sessions: Arc<Sessions>) {
    registry.set_link_protocols(config::protocols());
    outside::register(registry, sessions);
}

/// The transport of `kpl run --host`, on this process's session ([`Sessions::process`]).
pub fn factory() -> ZenohFactory {
    ZenohFactory::new(Sessions::process())
}
