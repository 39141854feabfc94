//! The still parts of what a viewer draws under a run's objects, read from its spec: the road
//! network's lanes (from a simulated tracker's network or scenario, else any process's
//! `network_file`), the occluders (the network's own, the tracker's `occluders` and
//! `occluders_file`) and the camera footprint (fixed, or moving along `camera_path`).
//!
//! [`crate::foxglove`] draws a [`Scene`] as Foxglove entities; `kpl-view` sends it to the page.
//! A spec without a network gives an empty scene: the objects are drawn alone.

use std::path::Path;
use std::sync::Arc;

use kpl_core::{Time, Value};
use kpl_roads::{LaneKind, RoadNetwork};
use kpl_semantic::hir;
use kpl_sim::camera::Camera;
use kpl_sim::params::Params;
use serde::Serialize;

/// A point `[x, y]` on the ground, metres.
pub type Point = [f64; 2];

/// One lane: its middle line and width.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Lane {
    pub name: String,
    pub shape: Vec<Point>,
    pub width: f64,
    /// Inside a junction (a connection between two roads' lanes).
    pub connector: bool,
}

/// The still parts of a view.
#[derive(Clone, Default, Serialize)]
pub struct Scene {
    pub lanes: Vec<Lane>,
    /// Polygons that hide what is under them.
    pub occluders: Vec<Vec<Point>>,
    /// `(min, max)` corners of everything in the scene (the lanes), if anything.
    pub bounds: Option<(Point, Point)>,
    /// The camera, when a simulated tracker has a footprint.
    #[serde(skip)]
    pub camera: Option<Arc<Camera>>,
    /// What could not be read (a network file that does not load): said once by whoever shows
    /// the scene.
    #[serde(skip)]
    pub problems: Vec<String>,
}

impl std::fmt::Debug for Scene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Scene")
            .field("lanes", &self.lanes.len())
            .field("occluders", &self.occluders.len())
            .field("camera", &self.camera.is_some())
            .finish()
    }
}

impl Scene {
    /// The camera footprint at `elapsed` microseconds after the run's start (`None` when the
    /// camera sees everything).
    pub fn footprint_at(&self, elapsed: Time) -> Option<Vec<Point>> {
        self.camera.as_ref()?.footprint_at(elapsed)
    }

    /// Whether the footprint moves (so it is drawn with every frame, not once).
    pub fn camera_moves(&self) -> bool {
        matches!(self.camera.as_deref(), Some(Camera::Moving { .. }))
    }

    /// The scene of a checked spec whose relative file names are relative to `spec_dir`.
    pub fn from_spec(spec: &hir::Spec, spec_dir: &Path) -> Scene {
        let mut scene = Scene::default();
        let mut network: Option<RoadNetwork> = None;
        for process in &spec.processes {
            let call = match &process.kind {
                hir::ProcessKind::Source(call) if call.entry == "sim.uav_tracker" => call,
                _ => continue,
            };
            match tracker_params(call, spec_dir) {
                Ok(params) => {
                    match params.load_network() {
                        Ok(net) => {
                            add_occluders(&mut scene, &params, &net);
                            network.get_or_insert(net);
                        }
                        Err(e) => scene.problems.push(format!("{}: {e}", process.name)),
                    }
                    if let Ok(camera) = params.camera()
                        && !matches!(camera, Camera::Everything)
                        && scene.camera.is_none()
                    {
                        scene.camera = Some(Arc::new(camera));
                    }
                }
                Err(e) => scene.problems.push(format!("{}: {e}", process.name)),
            }
        }
        if network.is_none() {
            network = other_network(spec, spec_dir, &mut scene.problems);
            if let Some(net) = &network {
                scene.occluders.extend(net.occluders().list().iter().map(|o| o.area.clone()));
            }
        }
        if let Some(net) = &network {
            scene.set_network(net);
        }
        scene
    }

    /// Takes the lanes (and bounds) of a network.
    pub fn set_network(&mut self, network: &RoadNetwork) {
        self.lanes = network
            .lanes()
            .iter()
            .map(|lane| Lane {
                name: lane.name.clone(),
                shape: lane.path.points().to_vec(),
                width: lane.width_m,
                connector: matches!(lane.kind, LaneKind::Connector { .. }),
            })
            .collect();
        self.bounds = Some(network.bounds());
    }
}

/// A tracker's parameters as `sim.uav_tracker` reads them (file names relative to the spec).
fn tracker_params(call: &hir::Call, spec_dir: &Path) -> Result<Params, String> {
    let mut args: Vec<(String, Value)> = Vec::new();
    for (name, value) in &call.params {
        match value {
            Value::Str(s) if name.ends_with("_file") && !s.is_empty() => {
                args.push((name.clone(), Value::str(&spec_dir.join(&**s).to_string_lossy())))
            }
            _ => args.push((name.clone(), value.clone())),
        }
    }
    Params::from_args(args.iter().map(|(n, v)| (n.as_str(), v))).map_err(|e| e.to_string())
}

fn add_occluders(scene: &mut Scene, params: &Params, network: &RoadNetwork) {
    scene.occluders.extend(network.occluders().list().iter().map(|o| o.area.clone()));
    scene.occluders.extend(params.occluders.iter().cloned());
    if let Some(file) = &params.occluders_file {
        match kpl_roads::load::read_occluders(Path::new(file), network) {
            Ok(list) => scene.occluders.extend(list.into_iter().map(|o| o.area)),
            Err(e) => scene.problems.push(format!("{file}: {e}")),
        }
    }
}

/// The network a process names with `network_file` (a link unit's, a prediction model's).
fn other_network(spec: &hir::Spec, spec_dir: &Path, problems: &mut Vec<String>) -> Option<RoadNetwork> {
    let calls = spec
        .processes
        .iter()
        .filter_map(|p| match &p.kind {
            hir::ProcessKind::Source(c) | hir::ProcessKind::Compute(c) => Some(c),
            hir::ProcessKind::Link(link) => Some(&link.via),
            _ => None,
        })
        .chain(spec.predictions.iter().map(|p| &p.model));
    for call in calls {
        if let Some(Value::Str(file)) = call.params.get("network_file")
            && !file.is_empty()
        {
            match RoadNetwork::load(&spec_dir.join(&**file)) {
                Ok(net) => return Some(net),
                Err(e) => problems.push(format!("{file}: {e}")),
            }
        }
    }
    None
}
