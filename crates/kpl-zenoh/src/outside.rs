//! `zenoh.subscribe` and `zenoh.publish`: streams to and from programs outside the spec, in the
//! wire format of [`crate::codec`] (docs/streams.md, "On the wire"), on the host's zenoh session.
//!
//! ```kpl
//! source temp : float = zenoh.subscribe(key: "sensors/temp")
//! sink out = zenoh.publish(alerts, key: "kpl/out/alerts", wait_for_subscriber: true)
//! ```
//!
//! Both talk to the outside world in real time, so they need `--clock wall`.

use std::sync::Arc;
use std::time::{Duration, Instant};

use kpl_core::{Time, Value, ValueType};
use kpl_runtime::clock::ClockKind;
use kpl_runtime::context::SourceContext;
use kpl_runtime::process::{AsyncUnit, BoxFuture, Emitter, Input, ProcessError, Source};
use kpl_runtime::registry::{BuildContext, BuildError, Registry};
use kpl_semantic::hir;
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};
use zenoh::handlers::FifoChannelHandler;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::CongestionControl;

use crate::codec::{self, Message};
use crate::keys;
use crate::session::{HostSession, Sessions};

/// A year of clock time: how far a source that has no `--for` waits for the run to stop.
const FAR: Time = 365 * 24 * 3600 * 1_000_000;

pub(crate) fn register(registry: &mut Registry, sessions: Arc<Sessions>) {
    let for_subscribe = sessions.clone();
    registry.add_source(
        Entry::new(
            EntryKind::Source,
            "zenoh.subscribe",
            "Samples from programs outside the spec, published on a zenoh key in KPL's wire format (docs/streams.md). Needs --clock wall.",
        )
        .param(Param::required(
            "key",
            ParamType::Str,
            "zenoh key expression to subscribe to (wildcards allowed: `sensors/*`)",
        ))
        .param(Param::optional(
            "stop_at_end",
            ParamType::Bool,
            Value::Bool(true),
            "end this source at the first end-of-stream message (false: run until the run ends)",
        ))
        .output(TypeReq::Any),
        move |ctx| {
            let key = key_param(ctx, true)?;
            needs_wall_clock(ctx)?;
            Ok(Box::new(Subscribe {
                sessions: for_subscribe.clone(),
                deploy: ctx.spec.deploy.clone(),
                host: ctx.spec.host_of(ctx.process.id).map(String::from),
                key,
                ty: ctx.process.output.clone().unwrap_or(ValueType::Any),
                stop_at_end: ctx.param("stop_at_end").and_then(Value::as_bool).unwrap_or(true),
            }))
        },
    );
    registry.add_unit(
        Entry::new(
            EntryKind::Sink,
            "zenoh.publish",
            "Publishes a stream on a zenoh key in KPL's wire format (docs/streams.md), for programs outside the spec; ends it with an end-of-stream message. Needs --clock wall.",
        )
        .input("in", TypeReq::Any, "the stream to publish")
        .param(Param::required("key", ParamType::Str, "zenoh key to publish on (no wildcards)"))
        .param(Param::optional(
            "wait_for_subscriber",
            ParamType::Bool,
            Value::Bool(false),
            "before the first sample, wait (up to KPL_ZENOH_WAIT, 30 s by default) until a subscriber matches the key",
        )),
        move |ctx| {
            let key = key_param(ctx, false)?;
            needs_wall_clock(ctx)?;
            Ok(Box::new(Publish {
                sessions: sessions.clone(),
                deploy: ctx.spec.deploy.clone(),
                host: ctx.spec.host_of(ctx.process.id).map(String::from),
                key,
                wait: ctx.param("wait_for_subscriber").and_then(Value::as_bool).unwrap_or(false),
                open: None,
                published: 0,
                failures: 0,
            }))
        },
    );
}

fn key_param(ctx: &BuildContext<'_>, wildcards: bool) -> Result<String, BuildError> {
    let key = ctx.param("key").and_then(Value::as_str).unwrap_or("").to_string();
    keys::check_user_key(&key, wildcards).map_err(|e| ctx.error(format!("`key`: {e}")))?;
    Ok(key)
}

fn needs_wall_clock(ctx: &BuildContext<'_>) -> Result<(), BuildError> {
    match ctx.clock {
        ClockKind::Wall => Ok(()),
        ClockKind::Sim => Err(ctx.error(
            "zenoh exchanges samples with programs outside the run in real time; run with --clock wall",
        )),
    }
}

struct Subscribe {
    sessions: Arc<Sessions>,
    deploy: Option<hir::Deploy>,
    host: Option<String>,
    key: String,
    ty: ValueType,
    stop_at_end: bool,
}

impl Subscribe {
    async fn subscribe(
        &self,
    ) -> Result<(Arc<HostSession>, Subscriber<FifoChannelHandler<zenoh::sample::Sample>>), ProcessError> {
        let session = self
            .sessions
            .open(self.deploy.as_ref(), self.host.as_deref())
            .await
            .map_err(|e| ProcessError::failed(e.to_string()))?;
        let subscriber = session
            .session
            .declare_subscriber(self.key.clone())
            .with(zenoh::handlers::FifoChannel::new(session.options.queue))
            .await
            .map_err(|e| ProcessError::failed(format!("cannot subscribe to `{}`: {e}", self.key)))?;
        Ok((session, subscriber))
    }
}

impl Source for Subscribe {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let (_session, subscriber) = self.subscribe().await?;
            let mut messages = 0u64;
            loop {
                let until = ctx.end().unwrap_or_else(|| ctx.now().saturating_add(FAR));
                let message = tokio::select! {
                    biased;
                    message = subscriber.recv_async() => message,
                    _ = ctx.wait_until(until) => break,
                };
                let Ok(message) = message else { break };
                messages += 1;
                match codec::decode(&message.payload().to_bytes(), &self.ty) {
                    Ok(Message::Sample(sample)) => {
                        if ctx.end().is_some_and(|end| sample.available > end) {
                            break;
                        }
                        ctx.emit_sample(sample).await;
                        if ctx.unconsumed() {
                            break;
                        }
                    }
                    Ok(Message::End { .. }) if self.stop_at_end => break,
                    Ok(Message::End { .. }) => {}
                    Err(e) => {
                        let location = format!("zenoh `{}`, message {messages}", message.key_expr());
                        ctx.malformed(location, e.to_string())?;
                    }
                }
                if ctx.should_stop() {
                    break;
                }
            }
            Ok(())
        })
    }

    fn ends_by_itself(&self) -> bool {
        self.stop_at_end
    }
}

struct Publish {
    sessions: Arc<Sessions>,
    deploy: Option<hir::Deploy>,
    host: Option<String>,
    key: String,
    wait: bool,
    open: Option<(Arc<HostSession>, Publisher<'static>)>,
    published: u64,
    failures: u64,
}

impl Publish {
    async fn publisher(&mut self) -> Result<&Publisher<'static>, ProcessError> {
        if self.open.is_none() {
            let session = self
                .sessions
                .open(self.deploy.as_ref(), self.host.as_deref())
                .await
                .map_err(|e| ProcessError::failed(e.to_string()))?;
            let publisher = session
                .session
                .declare_publisher(self.key.clone())
                .congestion_control(CongestionControl::Block)
                .await
                .map_err(|e| ProcessError::failed(format!("cannot publish on `{}`: {e}", self.key)))?;
            if self.wait {
                wait_for_match(&publisher, &self.key, session.options.subscriber_wait).await;
            }
            self.open = Some((session, publisher));
        }
        match &self.open {
            Some((_, publisher)) => Ok(publisher),
            None => Err(ProcessError::failed("no publisher")),
        }
    }

    async fn put(&mut self, bytes: Vec<u8>) -> Result<(), ProcessError> {
        let result = self.publisher().await?.put(bytes).await;
        if let Err(e) = result {
            self.failures += 1;
            return Err(ProcessError::failed(format!("cannot publish on `{}`: {e}", self.key)));
        }
        Ok(())
    }
}

/// Waits until a subscriber matches `publisher`, or `wait` has passed.
async fn wait_for_match(publisher: &Publisher<'static>, key: &str, wait: Duration) {
    let deadline = Instant::now() + wait;
    loop {
        if publisher.matching_status().await.is_ok_and(|m| m.matching()) {
            return;
        }
        let now = Instant::now();
        if now >= deadline {
            tracing::warn!(
                "`{key}`: no subscriber within {:.1} s; publishing anyway (raise KPL_ZENOH_WAIT to wait longer)",
                wait.as_secs_f64()
            );
            return;
        }
        tokio::time::sleep(Duration::from_millis(20).min(deadline - now)).await;
    }
}

impl AsyncUnit for Publish {
    fn on_input<'a>(
        &'a mut self,
        input: &'a Input<'a>,
        _out: &'a mut Emitter,
    ) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let Some((_, sample)) = input.trigger_sample() else { return Ok(()) };
            let mut bytes = Vec::new();
            codec::encode_sample(sample, &mut bytes).map_err(|e| ProcessError::failed(e.to_string()))?;
            self.put(bytes).await?;
            self.published += 1;
            Ok(())
        })
    }

    fn on_end<'a>(&'a mut self, _out: &'a mut Emitter) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let end = codec::encode_end(self.published);
            self.put(end).await?;
            // Let go of the session: the last user closes it.
            self.open = None;
            if self.failures > 0 {
                return Err(ProcessError::failed(format!(
                    "{} sample(s) could not be published on `{}`",
                    self.failures, self.key
                )));
            }
            Ok(())
        })
    }
}
