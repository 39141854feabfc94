//! The parameters of the `sim.uav_tracker` source: one struct with serde defaults, and a table of
//! name, type, default and one-line description per parameter (generated from the same
//! declaration, so the two cannot drift apart) for `kpl list`.
//!
//! ```
//! use kpl_sim::Params;
//! let params = Params::from_json(serde_json::json!({ "scenario": "bridge", "noise_m": 1.5 })).unwrap();
//! assert_eq!(params.rate_hz, 10.0);
//! assert!(Params::describe().iter().any(|p| p.name == "dropout"));
//! ```

use std::path::Path;

use kpl_core::Value;
use serde::{Deserialize, Serialize};

use crate::camera::{Camera, CameraError};
use crate::error::ParamsError;
use kpl_roads::RoadNetwork;
use kpl_roads::scenarios::{self, GridTownSize};

/// One parameter as shown to users.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ParamInfo {
    pub name: &'static str,
    /// The KPL type of the value (`int`, `float`, `string`).
    pub ty: &'static str,
    /// The default, as JSON.
    pub default: String,
    pub doc: &'static str,
}

/// Declares a parameter struct whose missing fields take their defaults, with the table of its
/// fields (name, KPL type, doc) and `describe()`, which signatures and `kpl list` show.
macro_rules! declare_params {
    (
        $(#[doc = $struct_doc:literal])* struct $name_of_struct:ident, table $table:ident;
        $( #[doc = $doc:literal] $name:ident : $ty:ty, $kpl_ty:literal = $default:expr; )*
    ) => {
        $(#[doc = $struct_doc])*
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        #[serde(deny_unknown_fields, default)]
        pub struct $name_of_struct {
            $( #[doc = $doc] pub $name: $ty, )*
        }

        impl Default for $name_of_struct {
            fn default() -> $name_of_struct {
                $name_of_struct { $( $name: $default, )* }
            }
        }

        const $table: &[(&str, &str, &str)] = &[ $( (stringify!($name), $kpl_ty, $doc), )* ];

        impl $name_of_struct {
            /// Name, type, default and description of every parameter, in declaration order.
            pub fn describe() -> Vec<$crate::params::ParamInfo> {
                let defaults = serde_json::to_value($name_of_struct::default()).unwrap_or_default();
                $table
                    .iter()
                    .map(|&(name, ty, doc)| $crate::params::ParamInfo {
                        name,
                        ty,
                        default: defaults.get(name).map(ToString::to_string).unwrap_or_default(),
                        doc: doc.trim(),
                    })
                    .collect()
            }
        }
    };
}
pub(crate) use declare_params;

declare_params! {
    /// Parameters of a simulated UAV tracker run. Missing fields take their defaults.
    struct Params, table PARAM_TABLE;
    /// Built-in road network: `crossing`, `bridge` or `grid_town` (unused when `network_file` is set).
    scenario: String, "string" = "crossing".to_string();
    /// Road network file to use instead of a built-in scenario: SUMO `.net.xml` or the project's JSON, either gzipped (docs/roads.md).
    network_file: Option<String>, "string" = None;
    /// Recorded traffic to observe instead of simulated cars: SUMO FCD output (`.xml`, `.xml.gz`) or rows (time, id, x, y[, heading, length, width]) as JSON lines or CSV; needs `network_file`.
    traffic_file: Option<String>, "string" = None;
    /// SUMO route or additional file with the `vType`s of the recorded vehicles (their lengths and widths); SUMO's defaults otherwise.
    vtypes_file: Option<String>, "string" = None;
    /// Corners [x, y] of the camera's footprint: world coordinates, or relative to the camera when `camera_path` is set. Empty: the camera sees everything.
    footprint: Vec<[f64; 2]>, "list<list<float>>" = Vec::new();
    /// Width and height [w, h] of a rectangular footprint centred on the camera (instead of `footprint`; needs `camera_path`).
    footprint_size_m: Vec<f64>, "list<float>" = Vec::new();
    /// Waypoints [seconds, x, y] of the camera's centre, followed in straight lines (one waypoint: a fixed camera).
    camera_path: Vec<[f64; 3]>, "list<list<float>>" = Vec::new();
    /// Occluders as polygons (lists of [x, y] corners), each hiding everything under it.
    occluders: Vec<Vec<[f64; 2]>>, "list<list<list<float>>>" = Vec::new();
    /// Occluder file: JSON (`{"occluders": [...]}`) or SUMO polygons (`.poly.xml`), see docs/roads.md.
    occluders_file: Option<String>, "string" = None;
    /// Width of `grid_town` in blocks.
    grid_blocks_x: u32, "int" = 10;
    /// Height of `grid_town` in blocks.
    grid_blocks_y: u32, "int" = 10;
    /// Side of a `grid_town` block (distance between crossings), in metres.
    block_m: f64, "float" = 100.0;
    /// Seed of all randomness; the same seed and parameters give the same frames.
    seed: u64, "int" = 0;
    /// Simulated traffic that every tracker of a run with the same `seed`, network and traffic parameters shares (several UAVs over the same cars); the tracker's own noise still differs per source. Without it each source's traffic differs.
    shared_traffic: bool, "bool" = false;
    /// Percept ids are this followed by a number (`vp1`, `vp2`, ...); two trackers of one run need different prefixes.
    percept_prefix: String, "string" = "vp".to_string();
    /// Tracker frames per second.
    rate_hz: f64, "float" = 10.0;
    /// Number of cars on the network; a car that leaves the map is replaced by a new one.
    n_cars: u32, "int" = 4;
    /// Spread of the cars' desired speeds around the speed limit (relative standard deviation).
    speed_sd: f64, "float" = 0.1;
    /// Standard deviation of percept position noise on each axis, in metres.
    noise_m: f64, "float" = 1.0;
    /// Standard deviation of percept velocity noise on each axis, in m/s.
    vel_noise_mps: f64, "float" = 0.5;
    /// Standard deviation of percept size noise, in metres.
    size_noise_m: f64, "float" = 0.2;
    /// Probability that a visible car is not detected in a frame.
    dropout: f64, "float" = 0.05;
    /// A track missing for more than this many frames is dropped: the car gets a new percept id.
    max_gap_frames: u32, "int" = 5;
    /// Expected number of new false-positive blobs per second over the whole scene.
    false_positive_rate: f64, "float" = 0.2;
    /// Fraction of false positives that appear on a road (the others appear off-road).
    false_positive_on_road: f64, "float" = 0.5;
    /// Mean lifetime of a false positive, in seconds.
    false_positive_duration_s: f64, "float" = 0.5;
}

impl Params {
    /// Reads parameters from a JSON object; unknown names are an error, missing ones default, and
    /// a parameter set (to other than its default) where it would have no effect is an error too.
    pub fn from_json(json: serde_json::Value) -> Result<Params, ParamsError> {
        let params: Params = serde_json::from_value(json)?;
        params.validate()?;
        params.check_effects()?;
        Ok(params)
    }

    /// Refuses parameters that would be accepted and ignored.
    fn check_effects(&self) -> Result<(), ParamsError> {
        let defaults = Params::default();
        let conflict = |name: &'static str, reason: &'static str| Err(ParamsError::NoEffect { name, reason });
        if self.traffic_file.is_some() {
            if self.n_cars != defaults.n_cars {
                return conflict("n_cars", "the traffic comes from `traffic_file`");
            }
            if self.speed_sd != defaults.speed_sd {
                return conflict("speed_sd", "the traffic comes from `traffic_file`");
            }
            if self.network_file.is_none() {
                return Err(ParamsError::Needs {
                    name: "traffic_file",
                    needs: "network_file",
                    reason: "the network the traffic was recorded on",
                });
            }
        } else if self.vtypes_file.is_some() {
            return conflict("vtypes_file", "there is no `traffic_file`");
        }
        if !self.footprint.is_empty() && !self.footprint_size_m.is_empty() {
            return conflict("footprint_size_m", "`footprint` gives the footprint already");
        }
        if !self.footprint_size_m.is_empty() && self.camera_path.is_empty() {
            return Err(ParamsError::Needs {
                name: "footprint_size_m",
                needs: "camera_path",
                reason: "where the rectangle's centre is",
            });
        }
        if !self.camera_path.is_empty() && self.footprint.is_empty() && self.footprint_size_m.is_empty() {
            return conflict("camera_path", "there is no `footprint` or `footprint_size_m`");
        }
        Ok(())
    }

    /// Reads parameters given as named KPL values (`seed: 7, noise_m: 1.5`). Durations are taken
    /// in seconds, so `false_positive_duration_s: 500ms` means 0.5; an empty string for a file
    /// parameter, or an empty list, means "not set" (the checker fills in those defaults).
    pub fn from_args<'a>(
        args: impl IntoIterator<Item = (&'a str, &'a Value)>,
    ) -> Result<Params, ParamsError> {
        let mut object = serde_json::Map::new();
        for (name, value) in args {
            let unset = match value {
                Value::Str(s) => s.is_empty() && name.ends_with("_file"),
                Value::List(items) => items.is_empty(),
                _ => false,
            };
            if unset {
                continue;
            }
            let json = match value {
                Value::Duration(us) => serde_json::json!(*us as f64 / 1e6),
                other => other.to_json(),
            };
            object.insert(name.to_string(), json);
        }
        Params::from_json(serde_json::Value::Object(object))
    }

    /// Checks every range; the first parameter out of range is reported.
    pub fn validate(&self) -> Result<(), ParamsError> {
        fn range(
            name: &'static str,
            value: f64,
            lo: f64,
            hi: f64,
            expected: &'static str,
        ) -> Result<(), ParamsError> {
            if value.is_finite() && (lo..=hi).contains(&value) {
                Ok(())
            } else {
                Err(ParamsError::OutOfRange { name, expected, found: value.to_string() })
            }
        }
        if self.network_file.is_none() && !scenarios::NAMES.contains(&self.scenario.as_str()) {
            return Err(ParamsError::UnknownScenario { name: self.scenario.clone() });
        }
        // 200 x 200 blocks is a 20 km town at the default block size and some 400 MB of lanes.
        range("grid_blocks_x", f64::from(self.grid_blocks_x), 1.0, 200.0, "between 1 and 200")?;
        range("grid_blocks_y", f64::from(self.grid_blocks_y), 1.0, 200.0, "between 1 and 200")?;
        range("block_m", self.block_m, 30.0, 10_000.0, "between 30 and 10000")?;
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= 1000.0) {
            return Err(ParamsError::OutOfRange {
                name: "rate_hz",
                expected: "above 0 and at most 1000",
                found: self.rate_hz.to_string(),
            });
        }
        range("n_cars", f64::from(self.n_cars), 0.0, 1_000_000.0, "at most 1000000")?;
        range("speed_sd", self.speed_sd, 0.0, 0.5, "between 0 and 0.5")?;
        range("noise_m", self.noise_m, 0.0, 1000.0, "between 0 and 1000")?;
        range("vel_noise_mps", self.vel_noise_mps, 0.0, 1000.0, "between 0 and 1000")?;
        range("size_noise_m", self.size_noise_m, 0.0, 100.0, "between 0 and 100")?;
        range("dropout", self.dropout, 0.0, 1.0, "a probability between 0 and 1")?;
        range("false_positive_rate", self.false_positive_rate, 0.0, 1.0e5, "between 0 and 100000")?;
        range("false_positive_on_road", self.false_positive_on_road, 0.0, 1.0, "a fraction between 0 and 1")?;
        range(
            "false_positive_duration_s",
            self.false_positive_duration_s,
            0.001,
            3600.0,
            "between 0.001 and 3600",
        )?;
        let size_ok =
            |size: &[f64]| size.len() == 2 && size.iter().all(|v| v.is_finite() && *v > 0.0 && *v <= 1e6);
        if !self.footprint_size_m.is_empty() && !size_ok(&self.footprint_size_m) {
            return Err(ParamsError::OutOfRange {
                name: "footprint_size_m",
                expected: "[width, height] in metres, each above 0 and at most 1000000",
                found: format!("{:?}", self.footprint_size_m),
            });
        }
        self.camera()?;
        Ok(())
    }

    /// The camera these parameters describe.
    pub fn camera(&self) -> Result<Camera, ParamsError> {
        let camera_error = |e: CameraError| ParamsError::Camera(e);
        let shape = if self.footprint_size_m.len() == 2 {
            Camera::rectangle(self.footprint_size_m[0], self.footprint_size_m[1])
        } else {
            self.footprint.clone()
        };
        if shape.is_empty() {
            return Ok(Camera::Everything);
        }
        if self.camera_path.is_empty() {
            return Camera::fixed(shape).map_err(camera_error);
        }
        let path = self.camera_path.iter().map(|&[t, x, y]| (t, [x, y])).collect();
        Camera::moving(shape, path).map_err(camera_error)
    }

    /// The frame period in microseconds (at least 1).
    pub fn period_us(&self) -> i64 {
        ((1e6 / self.rate_hz).round() as i64).max(1)
    }

    /// The road network these parameters name: the built-in scenario, or `network_file` read
    /// from disk (SUMO or JSON).
    pub fn load_network(&self) -> Result<RoadNetwork, ParamsError> {
        match &self.network_file {
            Some(path) => Ok(RoadNetwork::load(Path::new(path))?),
            None => {
                let size = GridTownSize {
                    blocks_x: self.grid_blocks_x,
                    blocks_y: self.grid_blocks_y,
                    block_m: self.block_m,
                };
                let file = scenarios::by_name(&self.scenario, size)
                    .ok_or_else(|| ParamsError::UnknownScenario { name: self.scenario.clone() })?;
                Ok(RoadNetwork::build(&file)?)
            }
        }
    }
}
