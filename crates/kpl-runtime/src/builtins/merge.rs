//! `kpl.merge(a, b, ...)`: forwards every sample of each input, in arrival order.

use kpl_semantic::registry::{Entry, EntryKind, TypeReq};

use crate::process::{Emitter, Input, ProcessError, SyncUnit, Unit};
use crate::registry::Registry;

struct Merge;

impl Unit for Merge {
    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        if let Some(value) = input.trigger_value() {
            out.emit(value.clone());
        }
        Ok(())
    }
}

pub(super) fn register(registry: &mut Registry) {
    registry.add_unit(
        Entry::new(
            EntryKind::Compute,
            "kpl.merge",
            "Forwards every sample of each of its inputs, in arrival order.",
        )
        .variadic(1, "in", TypeReq::Any, "streams to merge"),
        |_| Ok(Box::new(SyncUnit(Merge))),
    );
}
