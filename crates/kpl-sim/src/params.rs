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

macro_rules! declare_params {
    ($( #[doc = $doc:literal] $name:ident : $ty:ty, $kpl_ty:literal = $default:expr; )*) => {
        /// Parameters of a simulated UAV tracker run. Missing fields take their defaults.
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        #[serde(deny_unknown_fields, default)]
        pub struct Params {
            $( #[doc = $doc] pub $name: $ty, )*
        }

        impl Default for Params {
            fn default() -> Params {
                Params { $( $name: $default, )* }
            }
        }

        const PARAM_TABLE: &[(&str, &str, &str)] = &[ $( (stringify!($name), $kpl_ty, $doc), )* ];
    };
}

declare_params! {
    /// Built-in road network: `crossing`, `bridge` or `grid_town` (unused when `network_file` is set).
    scenario: String, "string" = "crossing".to_string();
    /// Road network JSON file to use instead of a built-in scenario (see docs/simulator.md).
    network_file: Option<String>, "string" = None;
    /// Width of `grid_town` in blocks.
    grid_blocks_x: u32, "int" = 10;
    /// Height of `grid_town` in blocks.
    grid_blocks_y: u32, "int" = 10;
    /// Side of a `grid_town` block (distance between crossings), in metres.
    block_m: f64, "float" = 100.0;
    /// Seed of all randomness; the same seed and parameters give the same frames.
    seed: u64, "int" = 0;
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
    /// Name, type, default and description of every parameter, in declaration order.
    pub fn describe() -> Vec<ParamInfo> {
        let defaults = serde_json::to_value(Params::default()).unwrap_or_default();
        PARAM_TABLE
            .iter()
            .map(|&(name, ty, doc)| ParamInfo {
                name,
                ty,
                default: defaults.get(name).map(ToString::to_string).unwrap_or_default(),
                doc: doc.trim(),
            })
            .collect()
    }

    /// Reads parameters from a JSON object; unknown names are an error, missing ones default.
    pub fn from_json(json: serde_json::Value) -> Result<Params, ParamsError> {
        let params: Params = serde_json::from_value(json)?;
        params.validate()?;
        Ok(params)
    }

    /// Reads parameters given as named KPL values (`seed: 7, noise_m: 1.5`). Durations are taken
    /// in seconds, so `false_positive_duration_s: 500ms` means 0.5.
    pub fn from_args<'a>(
        args: impl IntoIterator<Item = (&'a str, &'a Value)>,
    ) -> Result<Params, ParamsError> {
        let mut object = serde_json::Map::new();
        for (name, value) in args {
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
        Ok(())
    }

    /// The frame period in microseconds (at least 1).
    pub fn period_us(&self) -> i64 {
        ((1e6 / self.rate_hz).round() as i64).max(1)
    }

    /// The road network these parameters name: the built-in scenario, or `network_file` read
    /// from disk (the only I/O this crate does outside explicit load/save calls).
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
