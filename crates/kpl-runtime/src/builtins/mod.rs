//! The runtime's own processes and functions: `timer`, JSON-lines replay and recording
//! (`file.jsonl`), `console`, `kpl.merge`, and the formula functions (`kpl-mtl`'s built-ins plus
//! `vec2`).

mod console;
mod functions;
mod jsonl;
mod merge;
mod replay;
mod timer;

use crate::registry::Registry;

pub(crate) fn register(registry: &mut Registry) {
    timer::register(registry);
    jsonl::register(registry);
    console::register(registry);
    merge::register(registry);
    functions::register(registry);
}

pub use jsonl::{SampleLine, decode_line, encode_line, read_line};
pub use replay::{ReplaySetup, ReplayTimes, StreamFilter, replay_entry};
