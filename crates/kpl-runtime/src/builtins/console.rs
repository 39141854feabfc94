//! `console(a, b, ...)`: prints each sample as a JSON line on standard output (its purpose is to
//! print, so it writes to the process's stdout directly).

use std::io::Write;

use kpl_semantic::registry::{Entry, EntryKind, TypeReq};

use crate::process::{Emitter, Input, ProcessError, SyncUnit, Unit};
use crate::registry::Registry;

struct Console;

impl Unit for Console {
    fn on_input(&mut self, input: &Input<'_>, _out: &mut Emitter) -> Result<(), ProcessError> {
        let Some((port, sample)) = input.trigger_sample() else { return Ok(()) };
        let stream = input.names.get(port).map_or("", |n| n);
        let line = super::encode_line(stream, sample);
        let mut stdout = std::io::stdout().lock();
        // A closed stdout (`kpl run ... | head`) must not fail the run.
        let _ = writeln!(stdout, "{line}");
        Ok(())
    }

    fn on_end(&mut self, _out: &mut Emitter) -> Result<(), ProcessError> {
        let _ = std::io::stdout().lock().flush();
        Ok(())
    }
}

pub(super) fn register(registry: &mut Registry) {
    registry.add_unit(
        Entry::new(EntryKind::Sink, "console", "Prints each sample as a JSON line on standard output.")
            .variadic(1, "in", TypeReq::Any, "streams to print"),
        |_| Ok(Box::new(SyncUnit(Console))),
    );
}
