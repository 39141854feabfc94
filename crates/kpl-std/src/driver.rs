//! Runs a spec's simulated trackers (`source NAME : TYPE = sim.uav_tracker(...)`) straight into
//! the anchoring engine, without the stream runtime: each tracker frame becomes the snapshot of
//! its source at the frame's time. The simulator's ground truth (which car each percept shows)
//! comes along, so runs can be scored: [`IdentityScore`] counts, for every car, how often the
//! symbols anchored to it change.
//!
//! ```
//! use kpl_std::driver::SimDriver;
//! let spec = kpl_std::check_text(r#"
//!     type VisionPercept symbol vp { pos: vec2, vel: vec2, size: float }
//!     type WorldObject   symbol wo { pos: vec2, vel: vec2 }
//!     source tracker : list<VisionPercept> = sim.uav_tracker(scenario: "crossing", seed: 1, n_cars: 3)
//!     link vision_world : VisionPercept -> WorldObject via anchor.world_from_percept {
//!       establish   eventually[1s, inf] true
//!       reestablish eventually[0, 1s] xydist(from.pos, to.pos) < 10.0
//!       maintain    true
//!     }
//!     predict WorldObject = constant_velocity
//! "#).unwrap();
//! let mut driver = SimDriver::from_spec(&spec, Default::default()).unwrap();
//! let mut steps = 0;
//! driver.run_until(2_000_000, |_| steps += 1).unwrap();
//! assert_eq!(steps, 21); // 10 Hz from 0 to 2 s
//! ```

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use kpl_core::{Time, Value};
use kpl_semantic::hir;
use kpl_sim::{CarId, Frame, Params, PerceptSource, UavTrackerSim};

use kpl_anchor::regions::{RegionGrid, Regional, RegionalStep};
use kpl_anchor::{AnchorConfig, Anchoring, BuildError, Snapshot, StepError, StepOutput};

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DriverError {
    #[error(transparent)]
    Build(#[from] BuildError),
    #[error("source `{name}`: {message}")]
    Source { name: String, message: String },
    #[error("source `{name}` is `{entry}`; this driver runs only `sim.uav_tracker` sources (use `kpl run`)")]
    UnsupportedSource { name: String, entry: String },
    #[error(transparent)]
    Step(#[from] StepError),
}

/// One simulated tracker of the spec.
#[derive(Debug)]
pub struct SimSource {
    pub name: String,
    /// The object type of its percepts.
    pub ty: String,
    pub sim: UavTrackerSim,
}

/// A spec's trackers and its anchoring engine.
#[derive(Debug)]
pub struct SimDriver {
    pub engine: Anchoring,
    pub sources: Vec<SimSource>,
    /// Processes of the spec the driver does not run (computational units, monitors, sinks).
    pub skipped: Vec<String>,
    /// What the engine was built with (the trackers' networks included).
    pub config: AnchorConfig,
}

/// A spec's trackers and its anchoring partitioned by region ([`Regional`]), stepped on up to
/// `workers` threads.
#[derive(Debug)]
pub struct RegionalDriver {
    pub regional: Regional,
    pub sources: Vec<SimSource>,
    pub workers: usize,
}

impl RegionalDriver {
    /// The trackers of `driver` (which has not stepped) and one engine per region of `grid`.
    pub fn new(
        driver: SimDriver,
        spec: &hir::Spec,
        grid: RegionGrid,
        workers: usize,
    ) -> Result<RegionalDriver, DriverError> {
        let regional = Regional::from_spec(spec, &driver.config, grid)?;
        Ok(RegionalDriver { regional, sources: driver.sources, workers })
    }

    /// As [`SimDriver::next_frames`].
    pub fn next_frames(&mut self, until: Time) -> Option<Frames> {
        next_frames(&mut self.sources, until)
    }

    /// One step of every region with these frames.
    pub fn step(&mut self, frames: &Frames) -> Result<RegionalStep, DriverError> {
        let snapshots = snapshots(&self.sources, frames);
        Ok(self.regional.step(frames.time, &snapshots, self.workers)?)
    }
}

/// What one step saw and did.
#[derive(Debug)]
pub struct DriverStep<'a> {
    pub time: Time,
    /// The frames of the trackers that reported at this time: (source name, frame).
    pub frames: Vec<(&'a str, &'a Frame)>,
    pub output: &'a StepOutput,
    pub engine: &'a Anchoring,
}

/// The `sim.uav_tracker` parameters of a call (an empty file name means none), with file names
/// relative to `dir`.
pub fn tracker_params(params: &BTreeMap<String, Value>, dir: &Path) -> Result<Params, String> {
    let resolved: Vec<(&str, Value)> = params
        .iter()
        .map(|(name, value)| match value {
            Value::Str(file) if name.ends_with("_file") && !file.is_empty() => {
                (name.as_str(), Value::str(&dir.join(&**file).to_string_lossy()))
            }
            other => (name.as_str(), other.clone()),
        })
        .collect();
    Params::from_args(resolved.iter().map(|(n, v)| (*n, v))).map_err(|e| e.to_string())
}

impl SimDriver {
    /// The trackers of the spec (every source must be `sim.uav_tracker`) and its engine. A
    /// tracker's road network is given to the engine for its scenario, so that link units and
    /// models naming the same scenario see the same network (a `grid_town` of the tracker's size).
    /// Files are read relative to the working directory.
    pub fn from_spec(spec: &hir::Spec, config: AnchorConfig) -> Result<SimDriver, DriverError> {
        SimDriver::from_spec_in(spec, config, Path::new(""))
    }

    /// As [`SimDriver::from_spec`], reading the files the spec names (networks, recorded
    /// traffic, vehicle types, occluders) relative to `dir`, as `kpl run` reads them relative to
    /// the spec's directory.
    pub fn from_spec_in(
        spec: &hir::Spec,
        mut config: AnchorConfig,
        dir: &Path,
    ) -> Result<SimDriver, DriverError> {
        config.networks = config.networks.with_base_dir(dir);
        let mut sources = Vec::new();
        let mut skipped = Vec::new();
        for process in &spec.processes {
            match &process.kind {
                hir::ProcessKind::Source(call) if call.entry == "sim.uav_tracker" => {
                    let source_error =
                        |message: String| DriverError::Source { name: process.name.clone(), message };
                    let params = tracker_params(&call.params, dir).map_err(source_error)?;
                    let network = Arc::new(params.load_network().map_err(|e| source_error(e.to_string()))?);
                    if params.network_file.is_none() {
                        config.networks.insert(&params.scenario, network.clone());
                    }
                    let sim =
                        UavTrackerSim::new(&params, network, 0).map_err(|e| source_error(e.to_string()))?;
                    let ty = match &process.output {
                        Some(kpl_core::ValueType::List(item)) => match item.as_ref() {
                            kpl_core::ValueType::Record(r) => r.name.to_string(),
                            _ => {
                                return Err(source_error("its output must be a list of objects".to_string()));
                            }
                        },
                        _ => return Err(source_error("its output must be a list of objects".to_string())),
                    };
                    sources.push(SimSource { name: process.name.clone(), ty, sim });
                }
                hir::ProcessKind::Source(call) => {
                    return Err(DriverError::UnsupportedSource {
                        name: process.name.clone(),
                        entry: call.entry.clone(),
                    });
                }
                hir::ProcessKind::Link(_) => {}
                _ => skipped.push(process.name.clone()),
            }
        }
        let engine = Anchoring::from_spec(spec, config.clone())?;
        Ok(SimDriver { engine, sources, skipped, config })
    }

    /// The frames of the trackers that report next, if that is at or before `until` (trackers of
    /// recorded traffic that has ended report no more).
    pub fn next_frames(&mut self, until: Time) -> Option<Frames> {
        next_frames(&mut self.sources, until)
    }

    /// One engine step with these frames.
    pub fn step(&mut self, frames: &Frames) -> Result<StepOutput, DriverError> {
        let snapshots = snapshots(&self.sources, frames);
        Ok(self.engine.step(frames.time, &snapshots)?)
    }

    /// Steps through every tracker frame with time at or before `until`, calling `each` after
    /// every step.
    pub fn run_until(
        &mut self,
        until: Time,
        mut each: impl FnMut(DriverStep<'_>),
    ) -> Result<(), DriverError> {
        while let Some(frames) = self.next_frames(until) {
            let output = self.step(&frames)?;
            let frames_seen: Vec<(&str, &Frame)> =
                frames.frames.iter().map(|(i, frame)| (self.sources[*i].name.as_str(), frame)).collect();
            each(DriverStep {
                time: frames.time,
                frames: frames_seen,
                output: &output,
                engine: &self.engine,
            });
        }
        Ok(())
    }
}

/// The frames of the trackers that report next, if that is at or before `until`.
fn next_frames(sources: &mut [SimSource], until: Time) -> Option<Frames> {
    let time = sources.iter().filter(|s| !s.sim.finished()).map(|s| s.sim.next_frame_time()).min()?;
    if time > until {
        return None;
    }
    let mut frames = Vec::new();
    for (i, source) in sources.iter_mut().enumerate() {
        if !source.sim.finished() && source.sim.next_frame_time() == time {
            frames.push((i, source.sim.next_frame()));
        }
    }
    let values = frames
        .iter()
        .map(|(_, frame)| Value::List(frame.percepts.iter().map(|p| p.to_value()).collect()))
        .collect();
    Some(Frames { time, frames, values })
}

/// The frames as the snapshots of their sources.
fn snapshots<'a>(sources: &'a [SimSource], frames: &'a Frames) -> Vec<Snapshot<'a>> {
    frames
        .frames
        .iter()
        .zip(&frames.values)
        .map(|((i, _), objects)| Snapshot { source: &sources[*i].name, ty: &sources[*i].ty, objects })
        .collect()
}

/// The frames of one time: (index of the source, frame), and each frame's percepts as the
/// snapshot value its source emits.
#[derive(Debug, Clone)]
pub struct Frames {
    pub time: Time,
    pub frames: Vec<(usize, Frame)>,
    pub values: Vec<Value>,
}

/// For every car of the ground truth: which symbols of each type were anchored to it over a run.
/// A car's symbol of a type at a step is the object of that type reached from the car's percept
/// by following links (vp -> wo -> oo -> co); a *switch* is a change from one symbol to another
/// (gaps without a percept or without an object of that type do not count).
#[derive(Debug, Clone, Default)]
pub struct IdentityScore {
    /// (car, type) -> the distinct symbols in the order they were anchored to the car.
    pub symbols: BTreeMap<(CarId, String), Vec<Arc<str>>>,
    /// Steps at which each car was detected.
    pub detected: BTreeMap<CarId, u64>,
    /// (car, type) -> steps at which the car had a symbol of that type.
    pub anchored: BTreeMap<(CarId, String), u64>,
}

impl IdentityScore {
    /// Records one step.
    pub fn record(&mut self, step: &DriverStep<'_>) {
        self.record_with(&step.frames, |_, id| step.engine.chain(id));
    }

    /// Records one step whose structures `chain` gives: (source, percept id) -> the (type,
    /// symbol) of each object reached from the percept, as [`Anchoring::chain`].
    pub fn record_with(
        &mut self,
        frames: &[(&str, &Frame)],
        chain: impl Fn(&str, &str) -> Vec<(Arc<str>, Arc<str>)>,
    ) {
        for (source, frame) in frames {
            for percept in &frame.percepts {
                let PerceptSource::Car(car) = percept.source else { continue };
                *self.detected.entry(car).or_default() += 1;
                for (ty, symbol) in chain(source, &percept.id.to_string()) {
                    *self.anchored.entry((car, ty.to_string())).or_default() += 1;
                    let list = self.symbols.entry((car, ty.to_string())).or_default();
                    if list.last() != Some(&symbol) {
                        list.push(symbol);
                    }
                }
            }
        }
    }

    /// Symbol changes of a type over all cars.
    pub fn switches(&self, ty: &str) -> usize {
        self.symbols.iter().filter(|((_, t), _)| t == ty).map(|(_, list)| list.len().saturating_sub(1)).sum()
    }

    /// Cars that had a symbol of a type at some step.
    pub fn cars_with(&self, ty: &str) -> usize {
        self.symbols.keys().filter(|(_, t)| t == ty).count()
    }
}
