//! The implementations of link units and prediction models by registered name, as a spec names
//! them (`via anchor.snap_to_lane(...)`, `predict OnRoadObject = along_roads(...)`). Users add
//! their own with [`Implementations::add_link_unit`] and [`Implementations::add_model`]; their
//! signatures go into the checker's registry (see [`crate::registry`]).

use std::collections::BTreeMap;
use std::fmt;
use std::sync::Arc;

use kpl_core::Value;

use crate::kalman::{FuseParams, Kalman, KalmanParams};
use crate::networks::Networks;
use crate::predict::{AlongRoads, ConstantVelocity, DEFAULT_MAX_HYPOTHESES, PredictionModel, Stationary};
use crate::units::{Copy, LinkUnit, SnapToLane, WorldFromPercept};

/// The parameters of a call, defaults filled in (`hir::Call::params`).
pub type Params = BTreeMap<String, Value>;

/// Builds a link unit from its parameters.
pub type LinkUnitFactory =
    Arc<dyn Fn(&Params, &mut Networks) -> Result<Arc<dyn LinkUnit>, String> + Send + Sync>;
/// Builds a prediction model from its parameters.
pub type ModelFactory =
    Arc<dyn Fn(&Params, &mut Networks) -> Result<Arc<dyn PredictionModel>, String> + Send + Sync>;

/// Link units and prediction models by name.
#[derive(Clone)]
pub struct Implementations {
    link_units: BTreeMap<String, LinkUnitFactory>,
    models: BTreeMap<String, ModelFactory>,
}

impl fmt::Debug for Implementations {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Implementations")
            .field("link_units", &self.link_units.keys().collect::<Vec<_>>())
            .field("models", &self.models.keys().collect::<Vec<_>>())
            .finish()
    }
}

impl Default for Implementations {
    /// The built-in link units and prediction models.
    fn default() -> Implementations {
        let mut i = Implementations { link_units: BTreeMap::new(), models: BTreeMap::new() };
        i.add_link_unit("anchor.copy", |_, _| Ok(Arc::new(Copy)));
        i.add_link_unit("anchor.world_from_percept", |_, _| Ok(Arc::new(WorldFromPercept)));
        i.add_link_unit("anchor.snap_to_lane", |params, networks| {
            let unit =
                SnapToLane::new(networks.resolve(params)?).with_min_heading_speed(min_heading_speed(params)?);
            Ok(Arc::new(unit))
        });
        i.add_link_unit("anchor.kalman", |params, _| Ok(Arc::new(Kalman::new(kalman_params(params)?, None))));
        i.add_link_unit("anchor.fuse", |params, _| {
            let defaults = FuseParams::default();
            let fuse = FuseParams {
                other_noise_m: positive(params, "other_noise_m", defaults.other_noise_m)?,
                gate_m: positive(params, "gate_m", defaults.gate_m)?,
            };
            Ok(Arc::new(Kalman::new(kalman_params(params)?, Some(fuse))))
        });
        i.add_model("constant_velocity", |_, _| Ok(Arc::new(ConstantVelocity)));
        i.add_model("stationary", |_, _| Ok(Arc::new(Stationary)));
        i.add_model("along_roads", |params, networks| {
            let max = match params.get("max_hypotheses") {
                None => DEFAULT_MAX_HYPOTHESES,
                Some(Value::Int(n)) if (1..=1000).contains(n) => *n as usize,
                Some(other) => {
                    return Err(format!("max_hypotheses must be an int from 1 to 1000, found {other}"));
                }
            };
            let forget_at_end = match params.get("forget_at_end") {
                None => false,
                Some(Value::Bool(b)) => *b,
                Some(other) => return Err(format!("forget_at_end must be true or false, found {other}")),
            };
            let model = AlongRoads::new(networks.resolve(params)?, max)
                .with_min_heading_speed(min_heading_speed(params)?)
                .with_forget_at_end(forget_at_end);
            Ok(Arc::new(model))
        });
        i
    }
}

/// The `min_heading_speed` parameter (m/s) of the road units and models.
fn min_heading_speed(params: &Params) -> Result<f64, String> {
    match params.get("min_heading_speed") {
        None => Ok(crate::units::MIN_HEADING_SPEED_MPS),
        Some(value) => match value.as_f64() {
            Some(v) if (0.0..=100.0).contains(&v) => Ok(v),
            _ => Err(format!("min_heading_speed must be a speed from 0 to 100 m/s, found {value}")),
        },
    }
}

/// A float parameter that must be finite and positive (its default when not given).
fn positive(params: &Params, name: &str, default: f64) -> Result<f64, String> {
    match params.get(name) {
        None => Ok(default),
        Some(v) => match v.as_f64() {
            Some(x) if x.is_finite() && x > 0.0 => Ok(x),
            _ => Err(format!("`{name}` must be a positive number, found {v}")),
        },
    }
}

/// The longest lag `smooth` takes (µs): a minute of steps at 10 Hz, well under the smoother's
/// bound ([`crate::smoother::MAX_STEPS`]).
const MAX_SMOOTH: kpl_core::Time = 60_000_000;

/// The filter parameters of `anchor.kalman` and `anchor.fuse`.
fn kalman_params(params: &Params) -> Result<KalmanParams, String> {
    let defaults = KalmanParams::default();
    Ok(KalmanParams {
        position_noise_m: positive(params, "position_noise_m", defaults.position_noise_m)?,
        initial_velocity_sd_mps: positive(
            params,
            "initial_velocity_sd_mps",
            defaults.initial_velocity_sd_mps,
        )?,
        acceleration_noise: positive(params, "acceleration_noise", defaults.acceleration_noise)?,
        // 0 (the default): the linked-from object's velocity is not a measurement.
        velocity_noise_mps: match params.get("velocity_noise_mps") {
            None => defaults.velocity_noise_mps,
            Some(v) => match v.as_f64() {
                Some(x) if x.is_finite() && x > 0.0 => Some(x),
                Some(0.0) => None,
                _ => return Err(format!("`velocity_noise_mps` must be a number, 0 or more, found {v}")),
            },
        },
        // 0 (the default): not smoothed.
        smooth: match params.get("smooth") {
            None | Some(Value::Duration(0)) => None,
            Some(Value::Duration(lag)) if (1..=MAX_SMOOTH).contains(lag) => Some(*lag),
            Some(v) => return Err(format!("`smooth` must be a duration from 0s to 60s, found {v}")),
        },
    })
}

impl Implementations {
    pub fn add_link_unit(
        &mut self,
        name: &str,
        factory: impl Fn(&Params, &mut Networks) -> Result<Arc<dyn LinkUnit>, String> + Send + Sync + 'static,
    ) {
        self.link_units.insert(name.to_string(), Arc::new(factory));
    }

    pub fn add_model(
        &mut self,
        name: &str,
        factory: impl Fn(&Params, &mut Networks) -> Result<Arc<dyn PredictionModel>, String>
        + Send
        + Sync
        + 'static,
    ) {
        self.models.insert(name.to_string(), Arc::new(factory));
    }

    pub fn link_unit(&self, name: &str) -> Option<&LinkUnitFactory> {
        self.link_units.get(name)
    }

    pub fn model(&self, name: &str) -> Option<&ModelFactory> {
        self.models.get(name)
    }

    pub fn link_unit_names(&self) -> impl Iterator<Item = &str> {
        self.link_units.keys().map(String::as_str)
    }

    pub fn model_names(&self) -> impl Iterator<Item = &str> {
        self.models.keys().map(String::as_str)
    }
}
