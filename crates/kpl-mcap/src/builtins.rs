//! `file.mcap`: the MCAP recording sink (`sink r = file.mcap(a, b, path: "r.mcap")`) and replay
//! source (`source s : T = file.mcap(path: "r.mcap", stream: "a")`), beside `file.jsonl`
//! (docs/streams.md, "MCAP files").

use std::path::PathBuf;

use kpl_core::{Value, ValueType};
use kpl_runtime::builtins::{ReplaySetup, ReplayTimes, StreamFilter, replay_entry};
use kpl_runtime::clock::ClockKind;
use kpl_runtime::context::SourceContext;
use kpl_runtime::process::{BoxFuture, Emitter, Input, ProcessError, Source, SyncUnit, Unit};
use kpl_runtime::registry::Registry;
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};

use crate::foxglove::{Role, ViewChannels, ViewId, Views};
use crate::read::{Event, Reader};
use crate::scene::Scene;
use crate::write::{Compression, Recorder, StreamId};

struct Replay {
    reader: Option<Reader>,
    display: String,
    filter: StreamFilter,
    ty: ValueType,
    clock: ClockKind,
}

impl Source for Replay {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let Some(mut reader) = self.reader.take() else { return Ok(()) };
            let mut times = ReplayTimes::new(self.clock);
            while let Some(event) = reader.next_event(&mut self.filter, &self.ty) {
                let (sample, location) = match event {
                    Event::Sample { sample, location, .. } => (sample, location),
                    Event::Malformed { location, error } => {
                        ctx.malformed(&location, error)?;
                        continue;
                    }
                };
                let Some(sample) = times.admit(ctx, &location, sample)? else { continue };
                if !ctx.wait_until(sample.available).await {
                    break;
                }
                ctx.emit_sample(sample).await;
                if ctx.unconsumed() {
                    break;
                }
            }
            if let Some(warning) = self.filter.warning(&self.display) {
                ctx.warn(warning);
            }
            Ok(())
        })
    }
}

struct Record {
    path: PathBuf,
    compression: Compression,
    /// Each input's stream name and type, in port order.
    streams: Vec<(String, ValueType)>,
    recorder: Option<(Recorder, Vec<StreamId>)>,
    /// Foxglove's views of the inputs (`foxglove: true`), a view per input in port order.
    views: Option<(Views, Vec<ViewId>, ViewChannels)>,
    messages: Vec<crate::foxglove::ViewMessage>,
}

impl Record {
    /// The file, created with a channel per input the first time it is needed.
    fn recorder(&mut self) -> Result<&mut (Recorder, Vec<StreamId>), ProcessError> {
        if self.recorder.is_none() {
            let failed = |e: crate::write::WriteError| ProcessError::failed(e.to_string());
            let mut recorder = Recorder::create(&self.path, self.compression).map_err(failed)?;
            let mut ids = Vec::with_capacity(self.streams.len());
            for (name, ty) in &self.streams {
                ids.push(recorder.add_stream(name, ty).map_err(failed)?);
            }
            self.recorder = Some((recorder, ids));
        }
        self.recorder.as_mut().ok_or_else(|| ProcessError::failed("no recorder"))
    }
}

impl Unit for Record {
    fn on_input(&mut self, input: &Input<'_>, _out: &mut Emitter) -> Result<(), ProcessError> {
        let Some((port, sample)) = input.trigger_sample() else { return Ok(()) };
        self.recorder()?;
        let Some((recorder, ids)) = self.recorder.as_mut() else { return Ok(()) };
        let Some(id) = ids.get(port) else { return Ok(()) };
        let failed = |e: crate::write::WriteError| ProcessError::failed(e.to_string());
        recorder.write(*id, sample).map_err(failed)?;
        if let Some((views, view_ids, channels)) = &mut self.views
            && let Some(view) = view_ids.get(port)
        {
            self.messages.clear();
            views.messages(*view, sample, &mut self.messages);
            for message in &self.messages {
                channels.write(recorder, message).map_err(failed)?;
            }
        }
        Ok(())
    }

    fn on_end(&mut self, _out: &mut Emitter) -> Result<(), ProcessError> {
        // Create the file even when nothing arrived, so a run's outputs always exist.
        self.recorder()?;
        match self.recorder.take() {
            Some((recorder, _)) => recorder.finish().map_err(|e| ProcessError::failed(e.to_string())),
            None => Ok(()),
        }
    }
}

/// Registers `file.mcap` (source and sink), `ros2.replay` and `ros2.bag`.
pub fn register(registry: &mut Registry) {
    crate::replay_ros2::register(registry);
    crate::bag_sink::register(registry);
    registry.add_source(
        replay_entry(
            "file.mcap",
            "Replays samples from an MCAP file: a KPL recording, or JSON messages of another tool (docs/streams.md).",
            "only messages of the channel with this topic (empty: all)",
        ),
        |ctx| {
            let ReplaySetup { path, filter, ty, clock } = ReplaySetup::from_context(ctx);
            let reader =
                Reader::open(&path).map_err(|e| ctx.error(format!("cannot open {}: {e}", path.display())))?;
            Ok(Box::new(Replay { reader: Some(reader), display: path.display().to_string(), filter, ty, clock }))
        },
    );
    registry.add_unit(
        Entry::new(
            EntryKind::Sink,
            "file.mcap",
            "Records samples in an MCAP file, a channel per stream with its JSON schema (docs/streams.md).",
        )
        .variadic(1, "in", TypeReq::Any, "streams to record")
        .param(Param::required(
            "path",
            ParamType::Str,
            "file to write, relative to the run's --out directory",
        ))
        .param(Param::optional(
            "compression",
            ParamType::Choice(Compression::NAMES.iter().map(|n| (*n).to_string()).collect()),
            Value::str("zstd"),
            "how chunks are compressed",
        ))
        .param(Param::optional(
            "foxglove",
            ParamType::Bool,
            Value::Bool(true),
            "also write Foxglove's views of the streams (objects, percepts, situations, roads, occluders, camera) for its 3D panel",
        )),
        |ctx| {
            let path = ctx.output_path(ctx.param("path").and_then(Value::as_str).unwrap_or("out.mcap"));
            let compression = ctx
                .param("compression")
                .and_then(Value::as_str)
                .and_then(Compression::from_name)
                .unwrap_or(Compression::Zstd);
            let streams =
                ctx.process.inputs.iter().map(|i| (i.stream.name.clone(), i.stream.ty.clone())).collect();
            let views = ctx.param("foxglove").and_then(Value::as_bool).unwrap_or(true).then(|| {
                let scene = Scene::from_spec(ctx.spec, ctx.spec_dir);
                for problem in &scene.problems {
                    ctx.stats.warn(format!("the view's scene: {problem}"));
                }
                let mut views = Views::new(std::sync::Arc::new(scene));
                let ids = ctx
                    .process
                    .inputs
                    .iter()
                    .map(|i| views.add_stream(&i.stream.name, Role::of_stream(ctx.spec, &i.stream)))
                    .collect();
                (views, ids, ViewChannels::default())
            });
            Ok(Box::new(SyncUnit(Record { path, compression, streams, recorder: None, views, messages: Vec::new() })))
        },
    );
}
