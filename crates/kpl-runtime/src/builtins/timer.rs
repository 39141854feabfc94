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
            while self.count == 0 || k < self.count {
                let t = start + k * self.period;
                if !ctx.wait_until(t).await {
                    break;
                }
                ctx.emit(t, Value::Int(k)).await;
                k += 1;
            }
            Ok(())
        })
    }

    fn ends_by_itself(&self) -> bool {
        self.count > 0
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
