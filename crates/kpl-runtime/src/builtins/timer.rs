//! `timer(period, count)`: emits 0, 1, 2, ... at the start of the run and then once every period.

use kpl_core::{Time, Value, ValueType};
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};

use crate::context::SourceContext;
use crate::process::{BoxFuture, ProcessError, Source};
use crate::registry::Registry;

struct Timer {
    period: Time,
    count: i64,
}

impl Source for Timer {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let start = ctx.clock.now();
            let mut k: i64 = 0;
            // How far behind its period the timer fell at worst (a tick emitted late).
            let mut worst_lag: Time = 0;
            while self.count == 0 || k < self.count {
                let t = start + k * self.period;
                if !ctx.wait_until(t).await {
                    break;
                }
                worst_lag = worst_lag.max(ctx.now() - t);
                ctx.emit(t, Value::Int(k)).await;
                k += 1;
            }
            // A tick is late when the one after it was due before it went out: the timer did not
            // keep its period (its consumers, or the machine, were slower). Jitter of a loaded
            // machine (below 10 ms) is not worth a warning.
            if worst_lag > self.period && worst_lag > 10_000 {
                let elapsed = ctx.now() - start;
                let due = (elapsed / self.period + 1).min(if self.count > 0 { self.count } else { i64::MAX });
                ctx.warn(format!(
                    "could not keep its period of {}: it made {k} tick(s) in {}, its period implies {due}; \
                     at worst a tick went out {} late (each tick keeps its scheduled valid time)",
                    seconds(self.period),
                    seconds(elapsed),
                    seconds(worst_lag)
                ));
            }
            Ok(())
        })
    }

    fn ends_by_itself(&self) -> bool {
        self.count > 0
    }
}

/// A duration in microseconds, as a person reads it: `10 us`, `2.5 ms`, `12.0 s`.
fn seconds(us: Time) -> String {
    match us {
        ..1_000 => format!("{us} us"),
        1_000..1_000_000 => format!("{:.1} ms", us as f64 / 1e3),
        _ => format!("{:.1} s", us as f64 / 1e6),
    }
}

pub(super) fn register(registry: &mut Registry) {
    registry.add_source(
        Entry::new(EntryKind::Source, "timer", "Emits 0, 1, 2, ... at the start and then once every period.")
            .param(Param::required("period", ParamType::Duration, "time between samples"))
            .param(Param::optional(
                "count",
                ParamType::Int,
                Value::Int(0),
                "samples to emit (0: until the run ends)",
            ))
            .output(TypeReq::Exact(ValueType::Int)),
        |ctx| {
            let period = match ctx.param("period") {
                Some(Value::Duration(us)) if *us > 0 => *us,
                _ => return Err(ctx.error("`period` must be a duration above zero")),
            };
            let count = ctx.param("count").and_then(Value::as_i64).unwrap_or(0).max(0);
            Ok(Box::new(Timer { period, count }))
        },
    );
}
