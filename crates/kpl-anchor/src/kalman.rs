//! Kalman link units: a world object's position and velocity estimated from its percepts by a
//! constant-velocity Kalman filter, instead of copied from each percept (whose position is noisy
//! and whose velocity is the tracker's noisier guess).
//!
//! - `anchor.kalman`: one position measurement per state, the linked-from object's `pos`, and
//!   with `velocity_noise_mps` also its `vel` (a tracker's velocity, which tells at once when a
//!   car speeds up, brakes or turns, where the positions alone tell it only after some states).
//! - `anchor.fuse(other)`: the same filter, also updated with a second source given as an extra
//!   input stream of the link (a roadside radar's detections, another sensor's objects): at each
//!   state, the `other` object closest to the filter's estimate within `gate_m` is a second
//!   position measurement with its own noise. A state without a sample of `other` (no
//!   approximation) is one measurement only.
//!
//! The filter is the object's memory (key `kalman`, [`crate::stateful`]): it outlives links, so a
//! world object reacquired after a gap continues its estimate (the gap widens its uncertainty,
//! and the new percept counts for more), and every link into the object whose unit is a Kalman
//! unit updates the same filter: two sensors' links into one world object fuse their
//! measurements. The state's `vel` is the filter's, so prediction (`constant_velocity`) moves
//! on with the estimated velocity.
//!
//! The model: state x = (px, py, vx, vy); between two states dt apart, x' = F x with
//! F = [[I, dt I], [0, I]], and process noise for white-noise acceleration of spectral density
//! q (m²/s³) per axis, Q = q [[dt³/3 I, dt²/2 I], [dt²/2 I, dt I]]; a position measurement
//! z = H x + v with H = [I 0] and v ~ N(0, r I); with a velocity measurement too, z = x + v
//! with v ~ N(0, diag(r, r, r_v, r_v)). A measurement older than the filter's time (links step
//! independently) is applied at the filter's time.
//!
//! **Smoothing** (`smooth: 2s`): the unit also keeps the filter's steps over the last `smooth`
//! in the object's memory ([`crate::smoother::FixedLag`]) and sets `smoothed_pos` and
//! `smoothed_vel`, when the linked-to type declares them, to the fixed-lag smoothed estimate of
//! the object `smooth` before the state's valid time, given every measurement up to it: a
//! refined, later view of an earlier time (the state at valid time t says where the object was
//! at t - `smooth`). An object younger than `smooth` gets the smoothed estimate of its first
//! state. `pos` and `vel` stay the filter's, so association and prediction are as without it.
//! Every Kalman unit into the object feeds the smoother once one of them smooths (the first
//! one's lag counts).
//!
//! **A percept's own covariance.** When the linked-from object carries `pos_cov`, `[σ_xx, σ_xy,
//! σ_yy]` in m² (what `camera.georeference` propagates from the pixel and pose noise), that
//! matrix is the position measurement's covariance R instead of `position_noise_m² I`: a far,
//! oblique percept (a long ellipse along the line of sight) moves the estimate less, and mostly
//! across the line of sight. A `pos_cov` that is not three finite numbers of a positive definite
//! matrix is refused (the unit's error; the object keeps its state).

use std::sync::Arc;

use kpl_core::{Record, RecordType, Time, Value};
use nalgebra::{Matrix2, Matrix2x4, Matrix4, Vector2, Vector4};

/// The position covariance a record carries (`pos_cov`: `[σ_xx, σ_xy, σ_yy]`), if any; an
/// error when it is there but not a positive definite covariance.
pub fn position_covariance(record: &Record) -> Result<Option<Matrix2<f64>>, String> {
    let Some(value) = record.get("pos_cov") else { return Ok(None) };
    let bad = || {
        format!("`pos_cov` must be [σ_xx, σ_xy, σ_yy] of a positive definite covariance (m²), found {value}")
    };
    let Value::List(items) = value else { return Err(bad()) };
    let numbers: Option<Vec<f64>> = items.iter().map(Value::as_f64).collect();
    match numbers.as_deref() {
        Some([xx, xy, yy])
            if [*xx, *xy, *yy].iter().all(|v| v.is_finite())
                && *xx > 0.0
                && *yy > 0.0
                && xx * yy - xy * xy > 0.0 =>
        {
            Ok(Some(Matrix2::new(*xx, *xy, *xy, *yy)))
        }
        _ => Err(bad()),
    }
}

use crate::records::{fill, position, value_position, velocity};
use crate::smoother::FixedLag;
use crate::stateful::{UnitCall, UnitMemory};
use crate::units::LinkUnit;

/// The memory key of the Kalman units: one filter per object, whichever link updates it.
pub const MEMORY_KEY: &str = "kalman";

/// The attributes a smoothing Kalman unit sets, when the linked-to type declares them: the
/// smoothed position and velocity of the object `smooth` before the state's valid time.
pub const SMOOTHED_ATTRIBUTES: [&str; 2] = ["smoothed_pos", "smoothed_vel"];

/// What the Kalman units keep about one object (its memory under [`MEMORY_KEY`]).
#[derive(Debug, Clone)]
pub struct Estimate {
    pub filter: CvFilter,
    /// The filter's recent steps, once a unit into the object smooths.
    pub smoother: Option<FixedLag>,
}

/// A constant-velocity Kalman filter in the plane.
#[derive(Debug, Clone, PartialEq)]
pub struct CvFilter {
    /// (px, py, vx, vy)
    pub x: Vector4<f64>,
    pub p: Matrix4<f64>,
    /// The valid time of the estimate.
    pub time: Time,
}

/// Why a measurement was not taken in.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FilterError {
    #[error("the innovation covariance is singular (measurement noise 0 and no uncertainty left)")]
    Singular,
    #[error("the estimate is not finite after the update")]
    NotFinite,
}

impl CvFilter {
    /// A filter started at `pos` (variance `pos_var` per axis) with velocity `vel` (variance
    /// `vel_var` per axis).
    pub fn new(pos: [f64; 2], vel: [f64; 2], pos_var: f64, vel_var: f64, time: Time) -> CvFilter {
        CvFilter::with_position_covariance(pos, vel, Matrix2::identity() * pos_var, vel_var, time)
    }

    /// A filter started at `pos` with covariance `pos_cov` and velocity `vel` (variance `vel_var`
    /// per axis).
    pub fn with_position_covariance(
        pos: [f64; 2],
        vel: [f64; 2],
        pos_cov: Matrix2<f64>,
        vel_var: f64,
        time: Time,
    ) -> CvFilter {
        let mut p = Matrix4::from_diagonal(&Vector4::new(0.0, 0.0, vel_var, vel_var));
        p.fixed_view_mut::<2, 2>(0, 0).copy_from(&pos_cov);
        CvFilter { x: Vector4::new(pos[0], pos[1], vel[0], vel[1]), p, time }
    }

    pub fn position(&self) -> [f64; 2] {
        [self.x[0], self.x[1]]
    }

    pub fn velocity(&self) -> [f64; 2] {
        [self.x[2], self.x[3]]
    }

    /// The constant-velocity model's transition over `dt` seconds: F = [[I, dt I], [0, I]].
    pub fn transition(dt: f64) -> Matrix4<f64> {
        let mut f = Matrix4::identity();
        f[(0, 2)] = dt;
        f[(1, 3)] = dt;
        f
    }

    /// The estimate moved on to `time` (a time before the filter's leaves it where it is).
    pub fn predict(&mut self, time: Time, q: f64) {
        let dt = (time.saturating_sub(self.time)).max(0) as f64 / 1e6;
        if dt == 0.0 {
            return;
        }
        let f = CvFilter::transition(dt);
        let (a, b, c) = (q * dt.powi(3) / 3.0, q * dt.powi(2) / 2.0, q * dt);
        let mut noise = Matrix4::zeros();
        for axis in 0..2 {
            noise[(axis, axis)] = a;
            noise[(axis, axis + 2)] = b;
            noise[(axis + 2, axis)] = b;
            noise[(axis + 2, axis + 2)] = c;
        }
        self.x = f * self.x;
        self.p = f * self.p * f.transpose() + noise;
        self.time = time;
    }

    /// Takes in a position measurement `z` with variance `r` per axis (Joseph form, so the
    /// covariance stays symmetric and positive).
    pub fn update(&mut self, z: [f64; 2], r: f64) -> Result<(), FilterError> {
        self.update_with_covariance(z, Matrix2::identity() * r)
    }

    /// Takes in a position measurement `z` with covariance `noise` (Joseph form).
    pub fn update_with_covariance(&mut self, z: [f64; 2], noise: Matrix2<f64>) -> Result<(), FilterError> {
        let h = Matrix2x4::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0);
        let innovation = Vector2::new(z[0], z[1]) - h * self.x;
        let s = h * self.p * h.transpose() + noise;
        let s_inv = s.try_inverse().ok_or(FilterError::Singular)?;
        let gain = self.p * h.transpose() * s_inv;
        let x = self.x + gain * innovation;
        let i_kh = Matrix4::identity() - gain * h;
        let p = i_kh * self.p * i_kh.transpose() + gain * noise * gain.transpose();
        if !(x.iter().all(|v| v.is_finite()) && p.iter().all(|v| v.is_finite())) {
            return Err(FilterError::NotFinite);
        }
        self.x = x;
        self.p = p;
        Ok(())
    }

    /// Takes in a measurement of both position `z` (variance `r` per axis) and velocity `v`
    /// (variance `r_v` per axis), independent of each other (Joseph form).
    pub fn update_with_velocity(
        &mut self,
        z: [f64; 2],
        r: f64,
        v: [f64; 2],
        r_v: f64,
    ) -> Result<(), FilterError> {
        self.update_with_velocity_covariance(z, Matrix2::identity() * r, v, r_v)
    }

    /// [`CvFilter::update_with_velocity`] with the position's covariance a matrix.
    pub fn update_with_velocity_covariance(
        &mut self,
        z: [f64; 2],
        pos_cov: Matrix2<f64>,
        v: [f64; 2],
        r_v: f64,
    ) -> Result<(), FilterError> {
        let mut noise = Matrix4::from_diagonal(&Vector4::new(0.0, 0.0, r_v, r_v));
        noise.fixed_view_mut::<2, 2>(0, 0).copy_from(&pos_cov);
        let innovation = Vector4::new(z[0], z[1], v[0], v[1]) - self.x;
        let s = self.p + noise;
        let s_inv = s.try_inverse().ok_or(FilterError::Singular)?;
        let gain = self.p * s_inv;
        let x = self.x + gain * innovation;
        let i_k = Matrix4::identity() - gain;
        let p = i_k * self.p * i_k.transpose() + gain * noise * gain.transpose();
        if !(x.iter().all(|v| v.is_finite()) && p.iter().all(|v| v.is_finite())) {
            return Err(FilterError::NotFinite);
        }
        self.x = x;
        self.p = p;
        Ok(())
    }

    /// The standard deviation of the position estimate (the root of the mean of the two axes'
    /// variances), metres.
    pub fn position_sd(&self) -> f64 {
        ((self.p[(0, 0)] + self.p[(1, 1)]) / 2.0).max(0.0).sqrt()
    }
}

/// The parameters of a Kalman unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KalmanParams {
    /// Standard deviation of the linked-from object's position, per axis (m).
    pub position_noise_m: f64,
    /// Standard deviation of the initial velocity, per axis (m/s): the first velocity is the
    /// linked-from object's `vel` (0 without one), trusted this much.
    pub initial_velocity_sd_mps: f64,
    /// Spectral density of the white-noise acceleration (m²/s³): how fast the velocity may change.
    pub acceleration_noise: f64,
    /// Standard deviation of the linked-from object's `vel`, per axis (m/s), when it is a
    /// measurement too (a tracker's velocity); `None`: only its position is measured.
    pub velocity_noise_mps: Option<f64>,
    /// The lag of the smoothed attributes (µs; [`SMOOTHED_ATTRIBUTES`]); `None`: not smoothed.
    pub smooth: Option<Time>,
}

impl Default for KalmanParams {
    fn default() -> KalmanParams {
        KalmanParams {
            position_noise_m: 1.0,
            initial_velocity_sd_mps: 3.0,
            acceleration_noise: 2.0,
            velocity_noise_mps: None,
            smooth: None,
        }
    }
}

/// The second source of `anchor.fuse`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FuseParams {
    /// Standard deviation of the other source's positions, per axis (m).
    pub other_noise_m: f64,
    /// An `other` object farther than this from the estimate is not this object (m).
    pub gate_m: f64,
}

impl Default for FuseParams {
    fn default() -> FuseParams {
        FuseParams { other_noise_m: 1.0, gate_m: 5.0 }
    }
}

/// `anchor.kalman` (without a second source) and `anchor.fuse` (with one).
#[derive(Debug, Clone)]
pub struct Kalman {
    params: KalmanParams,
    fuse: Option<FuseParams>,
    key: Arc<str>,
}

impl Kalman {
    pub fn new(params: KalmanParams, fuse: Option<FuseParams>) -> Kalman {
        Kalman { params, fuse, key: Arc::from(MEMORY_KEY) }
    }

    /// The filter moved on to this state's time (the same as the result for a new filter), and
    /// after taking in this state's measurements: `from`'s position, and with a second source
    /// the `other` object closest to the estimate within the gate.
    fn filter(&self, call: &UnitCall<'_>, pos: [f64; 2]) -> Result<(CvFilter, CvFilter), String> {
        let r = self.params.position_noise_m.powi(2);
        // The percept's own covariance when it carries one (a georeferenced percept).
        let r_pos = position_covariance(call.from)?.unwrap_or_else(|| Matrix2::identity() * r);
        let (predicted, mut filter) = match call.memory.get::<Estimate>() {
            Some(previous) => {
                let mut filter = previous.filter.clone();
                filter.predict(call.time, self.params.acceleration_noise);
                let predicted = filter.clone();
                match (self.params.velocity_noise_mps, velocity(call.from)) {
                    (Some(sd), Some(vel)) => filter.update_with_velocity_covariance(pos, r_pos, vel, sd * sd),
                    _ => filter.update_with_covariance(pos, r_pos),
                }
                .map_err(|e| e.to_string())?;
                (predicted, filter)
            }
            None => {
                let vel = velocity(call.from).unwrap_or([0.0, 0.0]);
                // A measured velocity is trusted as such from the first state on.
                let vel_sd = match (self.params.velocity_noise_mps, velocity(call.from)) {
                    (Some(sd), Some(_)) => sd.min(self.params.initial_velocity_sd_mps),
                    _ => self.params.initial_velocity_sd_mps,
                };
                let start = CvFilter::with_position_covariance(pos, vel, r_pos, vel_sd * vel_sd, call.time);
                (start.clone(), start)
            }
        };
        if let (Some(fuse), Some(Some(other))) = (self.fuse, call.inputs.first())
            && let Some(z) = closest_within(other, filter.position(), fuse.gate_m)
        {
            filter.update(z, fuse.other_noise_m.powi(2)).map_err(|e| e.to_string())?;
        }
        Ok((predicted, filter))
    }
}

/// Keeps a step of the object's filter in its memory, and in its smoother if it has one or
/// `lag` asks for one; the smoothed estimate when `lag` is set.
fn remember(
    memory: &mut UnitMemory,
    predicted: CvFilter,
    filter: CvFilter,
    lag: Option<Time>,
    q: f64,
) -> Option<CvFilter> {
    let Some(estimate) = memory.get_mut::<Estimate>() else {
        // The object's first state: its smoother, if any, starts with it.
        let smoother = lag.map(|lag| {
            let mut smoother = FixedLag::new(lag, q);
            smoother.push(predicted, filter.clone());
            smoother
        });
        let smoothed = smoother.as_ref().and_then(FixedLag::smoothed_so_far);
        memory.set(Estimate { filter, smoother });
        return smoothed;
    };
    if estimate.smoother.is_none() {
        estimate.smoother = lag.map(|lag| FixedLag::new(lag, q));
    }
    if let Some(smoother) = &mut estimate.smoother {
        smoother.push(predicted, filter.clone());
    }
    estimate.filter = filter;
    lag.and(estimate.smoother.as_ref()).and_then(FixedLag::smoothed_so_far)
}

/// The position of the object in `objects` (a list of records with `pos`, or one record)
/// closest to `to`, if within `gate`.
fn closest_within(objects: &Value, to: [f64; 2], gate: f64) -> Option<[f64; 2]> {
    let distance = |p: [f64; 2]| (p[0] - to[0]).hypot(p[1] - to[1]);
    let positions: Vec<[f64; 2]> = match objects {
        Value::List(items) => items.iter().filter_map(value_position).collect(),
        other => value_position(other).into_iter().collect(),
    };
    positions
        .into_iter()
        .filter(|p| distance(*p) <= gate)
        .min_by(|a, b| distance(*a).total_cmp(&distance(*b)))
}

impl LinkUnit for Kalman {
    /// Without memory or time (never called by the engine): the first estimate, the
    /// linked-from object's position and velocity.
    fn compute(
        &self,
        from: &Record,
        previous: Option<&Record>,
        to: &RecordType,
        symbol: &Arc<str>,
    ) -> Result<Record, String> {
        if position(from).is_none() {
            return Err("a Kalman filter needs a `pos` (vec2) to measure".to_string());
        }
        Ok(fill(to, symbol, from, previous))
    }

    fn compute_with(&self, call: &mut UnitCall<'_>) -> Result<Record, String> {
        let Some(pos) = position(call.from) else {
            return Err("a Kalman filter needs a `pos` (vec2) to measure".to_string());
        };
        let (predicted, filter) = self.filter(call, pos)?;
        let mut record = fill(call.to, call.symbol, call.from, call.previous);
        let (position, velocity) = (filter.position(), filter.velocity());
        let smoothed =
            remember(call.memory, predicted, filter, self.params.smooth, self.params.acceleration_noise);
        for (name, value) in &mut record.fields {
            match (&**name, &smoothed) {
                ("pos", _) => *value = Value::Vec2(position),
                ("vel", _) if matches!(value, Value::Vec2(_)) => *value = Value::Vec2(velocity),
                ("smoothed_pos", Some(s)) if matches!(value, Value::Vec2(_)) => {
                    *value = Value::Vec2(s.position())
                }
                ("smoothed_vel", Some(s)) if matches!(value, Value::Vec2(_)) => {
                    *value = Value::Vec2(s.velocity())
                }
                _ => {}
            }
        }
        Ok(record)
    }

    fn memory_key(&self) -> Option<&Arc<str>> {
        Some(&self.key)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Gaussian noise (Box-Muller), so the test needs no distribution crate.
    fn gauss(rng: &mut ChaCha8Rng, sd: f64) -> f64 {
        let (u, v): (f64, f64) = (rng.random::<f64>().max(1e-12), rng.random());
        sd * (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }

    #[test]
    fn a_still_filter_keeps_its_estimate_and_grows_its_uncertainty() {
        let mut f = CvFilter::new([1.0, 2.0], [3.0, 0.0], 1.0, 4.0, 0);
        f.predict(0, 1.0);
        assert_eq!(f.position(), [1.0, 2.0]);
        f.predict(2_000_000, 1.0);
        assert_eq!(f.position(), [7.0, 2.0]);
        // P = F P F' + Q: px variance 1 + 4 * 2² + q * 2³ / 3.
        assert!((f.p[(0, 0)] - (1.0 + 16.0 + 8.0 / 3.0)).abs() < 1e-12, "{}", f.p);
        assert!((f.p - f.p.transpose()).norm() < 1e-12);
        // A measurement in the past is applied now.
        f.predict(1_000_000, 1.0);
        assert_eq!(f.time, 2_000_000);
    }

    #[test]
    fn an_update_weighs_the_measurement_by_the_variances() {
        let mut f = CvFilter::new([0.0, 0.0], [0.0, 0.0], 1.0, 1.0, 0);
        f.update([2.0, -2.0], 1.0).unwrap();
        // Equal variances: halfway, and half the variance.
        assert!((f.position()[0] - 1.0).abs() < 1e-12 && (f.position()[1] + 1.0).abs() < 1e-12);
        assert!((f.p[(0, 0)] - 0.5).abs() < 1e-12);
        let mut exact = CvFilter::new([0.0, 0.0], [0.0, 0.0], 0.0, 0.0, 0);
        assert_eq!(exact.update([1.0, 1.0], 0.0), Err(FilterError::Singular));
    }

    #[test]
    fn a_percepts_covariance_weighs_it_per_direction() {
        // The estimate has variance 1 on each axis; a measurement 2 m off on each axis, trusted
        // along x (variance 1) and hardly along y (variance 99), moves it 1 m in x and 0.02 m in y.
        let mut f = CvFilter::new([0.0, 0.0], [0.0, 0.0], 1.0, 1.0, 0);
        f.update_with_covariance([2.0, 2.0], Matrix2::new(1.0, 0.0, 0.0, 99.0)).unwrap();
        assert!(
            (f.position()[0] - 1.0).abs() < 1e-12 && (f.position()[1] - 0.02).abs() < 1e-12,
            "{:?}",
            f.position()
        );
        // A record's `pos_cov`.
        let numbers = |v: &[f64]| Value::List(v.iter().map(|x| Value::Float(*x)).collect::<Vec<_>>().into());
        let record = |cov: Value| Record { id: None, fields: vec![("pos_cov".into(), cov)] };
        assert_eq!(
            position_covariance(&record(numbers(&[4.0, 1.0, 2.0]))),
            Ok(Some(Matrix2::new(4.0, 1.0, 1.0, 2.0)))
        );
        assert!(position_covariance(&record(numbers(&[1.0, 2.0, 1.0]))).is_err(), "not positive definite");
        assert!(position_covariance(&record(numbers(&[1.0, 0.0]))).is_err());
        assert_eq!(position_covariance(&Record::default()), Ok(None));
    }

    #[test]
    fn a_velocity_measurement_is_weighed_by_its_variance_too() {
        let mut f = CvFilter::new([0.0, 0.0], [10.0, 0.0], 1.0, 1.0, 0);
        f.update_with_velocity([2.0, 0.0], 1.0, [14.0, 2.0], 1.0).unwrap();
        // Independent axes and equal variances: halfway in position and in velocity.
        assert!((f.position()[0] - 1.0).abs() < 1e-12 && f.position()[1].abs() < 1e-12);
        assert!((f.velocity()[0] - 12.0).abs() < 1e-12 && (f.velocity()[1] - 1.0).abs() < 1e-12);
        assert!((f.p[(2, 2)] - 0.5).abs() < 1e-12 && (f.p[(0, 0)] - 0.5).abs() < 1e-12);
        // A velocity 4 times as certain as the estimate counts 4 times as much.
        let mut f = CvFilter::new([0.0, 0.0], [0.0, 0.0], 1.0, 1.0, 0);
        f.update_with_velocity([0.0, 0.0], 1.0, [5.0, 0.0], 0.25).unwrap();
        assert!((f.velocity()[0] - 4.0).abs() < 1e-12, "{:?}", f.velocity());
    }

    /// A target that speeds up (2 m/s² for 3 s), measured at 10 Hz with 1 m position noise and
    /// 0.5 m/s velocity noise: a filter that also measures the velocity follows the change, one
    /// that measures positions only lags behind it.
    #[test]
    fn measured_velocities_follow_an_acceleration() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let speed = |t: f64| if t < 2.0 { 8.0 } else { 8.0 + 2.0 * (t - 2.0).min(3.0) };
        let (mut pos_only, mut with_vel) = (
            CvFilter::new([0.0, 0.0], [8.0, 0.0], 1.0, 1.0, 0),
            CvFilter::new([0.0, 0.0], [8.0, 0.0], 1.0, 1.0, 0),
        );
        let (mut x, mut worst) = (0.0, [0.0f64, 0.0f64]);
        for step in 1..=60 {
            let t = step as f64 / 10.0;
            x += speed(t) * 0.1;
            let z = [x + gauss(&mut rng, 1.0), gauss(&mut rng, 1.0)];
            let v = [speed(t) + gauss(&mut rng, 0.5), gauss(&mut rng, 0.5)];
            pos_only.predict(step * 100_000, 2.0);
            pos_only.update(z, 1.0).unwrap();
            with_vel.predict(step * 100_000, 2.0);
            with_vel.update_with_velocity(z, 1.0, v, 0.25).unwrap();
            worst[0] = worst[0].max((pos_only.velocity()[0] - speed(t)).abs());
            worst[1] = worst[1].max((with_vel.velocity()[0] - speed(t)).abs());
        }
        assert!(worst[1] < 1.2 && worst[0] > 2.0 * worst[1], "worst velocity errors {worst:?}");
    }

    /// A target moving at constant velocity, measured with 1 m noise at 10 Hz: after a few
    /// seconds the filter's position error is well below the measurements', and its velocity
    /// close to the truth, though it started from a wrong one.
    #[test]
    fn the_filter_beats_its_measurements_on_a_constant_velocity_target() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let truth = |t: f64| [10.0 + 12.0 * t, -5.0 + 3.0 * t];
        let mut f = CvFilter::new(truth(0.0), [0.0, 0.0], 1.0, 100.0, 0);
        let (mut raw, mut filtered, mut n) = (0.0, 0.0, 0);
        for step in 1..=200 {
            let t = step as f64 / 10.0;
            let p = truth(t);
            let z = [p[0] + gauss(&mut rng, 1.0), p[1] + gauss(&mut rng, 1.0)];
            f.predict(step * 100_000, 0.5);
            f.update(z, 1.0).unwrap();
            if step > 30 {
                raw += (z[0] - p[0]).powi(2) + (z[1] - p[1]).powi(2);
                let e = f.position();
                filtered += (e[0] - p[0]).powi(2) + (e[1] - p[1]).powi(2);
                n += 1;
            }
        }
        let (raw, filtered) = ((raw / n as f64).sqrt(), (filtered / n as f64).sqrt());
        assert!(filtered < 0.6 * raw, "filtered {filtered:.2} m vs raw {raw:.2} m");
        let v = f.velocity();
        assert!((v[0] - 12.0).abs() < 1.0 && (v[1] - 3.0).abs() < 1.0, "{v:?}");
        assert!(f.position_sd() < 1.0);
    }

    /// A world object's type with the smoothed attributes.
    fn smoothed_type() -> RecordType {
        let f = |n: &str| kpl_core::FieldType { name: n.into(), ty: kpl_core::ValueType::Vec2 };
        RecordType {
            name: "WorldObject".into(),
            parent: None,
            symbol: "wo".into(),
            fields: vec![f("pos"), f("vel"), f("smoothed_pos"), f("smoothed_vel")],
        }
    }

    /// The unit over a car at 20 m/s whose lateral position swings (1.5 m, every 8 s), measured
    /// at 10 Hz with the tracker's noises; per state, the record and the true position and
    /// velocity at time `t` (s).
    fn run_unit(smooth: Option<Time>, fuse: Option<FuseParams>) -> Vec<(f64, Record)> {
        let params = KalmanParams { velocity_noise_mps: Some(0.5), smooth, ..KalmanParams::default() };
        let unit = Kalman::new(params, fuse);
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (to, symbol, mut memory) = (smoothed_type(), Arc::from("wo1"), UnitMemory::default());
        let mut out = Vec::new();
        for step in 0..300_i64 {
            let t = step as f64 / 10.0;
            let (p, v) = truth(t);
            let percept = Record {
                id: Some("vp1".into()),
                fields: vec![
                    ("pos".into(), Value::vec2(p[0] + gauss(&mut rng, 1.0), p[1] + gauss(&mut rng, 1.0))),
                    ("vel".into(), Value::vec2(v[0] + gauss(&mut rng, 0.5), v[1] + gauss(&mut rng, 0.5))),
                ],
            };
            // With `fuse`, a second sensor's object where the car is.
            let inputs = [Some(Value::Record(Arc::new(Record {
                id: None,
                fields: vec![("pos".into(), Value::vec2(p[0] + gauss(&mut rng, 1.0), p[1]))],
            })))];
            let previous = out.last().map(|(_, r): &(f64, Record)| r.clone());
            let mut call = UnitCall {
                time: step * 100_000,
                from: &percept,
                previous: previous.as_ref(),
                to: &to,
                symbol: &symbol,
                inputs: if fuse.is_some() { &inputs } else { &[] },
                memory: &mut memory,
            };
            out.push((t, unit.compute_with(&mut call).unwrap()));
        }
        out
    }

    fn truth(t: f64) -> ([f64; 2], [f64; 2]) {
        let w = std::f64::consts::TAU / 8.0;
        ([20.0 * t, 1.5 * (w * t).sin()], [20.0, 1.5 * w * (w * t).cos()])
    }

    /// The lateral error's root mean square of `attribute` against the truth `lag` seconds
    /// before each state, after the first 5 s.
    fn lateral_rms(states: &[(f64, Record)], attribute: &str, lag: f64) -> f64 {
        let errors: Vec<f64> = states
            .iter()
            .filter(|(t, _)| *t >= 5.0)
            .map(|(t, r)| r.get(attribute).unwrap().as_vec2().unwrap()[1] - truth(t - lag).0[1])
            .collect();
        (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt()
    }

    #[test]
    fn smoothing_sets_the_estimate_of_lag_before() {
        let plain = run_unit(None, None);
        let smoothed = run_unit(Some(2_000_000), None);
        // The filter is the same with and without smoothing.
        for ((_, a), (_, b)) in plain.iter().zip(&smoothed) {
            assert_eq!((a.get("pos"), a.get("vel")), (b.get("pos"), b.get("vel")));
        }
        // Without `smooth` the attributes keep their defaults.
        assert_eq!(plain[100].1.get("smoothed_pos"), Some(&Value::vec2(0.0, 0.0)));
        let filtered = lateral_rms(&plain, "pos", 0.0);
        let refined = lateral_rms(&smoothed, "smoothed_pos", 2.0);
        assert!(refined < 0.85 * filtered, "smoothed {refined:.3} m, filtered {filtered:.3} m");
        // It is the estimate of 2 s before: 40 m behind the filter's, along the road.
        let (t, last) = smoothed.last().unwrap();
        let x = last.get("smoothed_pos").unwrap().as_vec2().unwrap()[0];
        assert!((x - truth(t - 2.0).0[0]).abs() < 1.0, "{x} at {t}");
        let v = last.get("smoothed_vel").unwrap().as_vec2().unwrap();
        assert!((v[0] - 20.0).abs() < 0.5, "{v:?}");
        // The first state (younger than the lag) has its own estimate.
        assert_eq!(smoothed[0].1.get("smoothed_pos"), smoothed[0].1.get("pos"));
        // A second source's measurements go into the smoothed estimate too.
        let fused = run_unit(Some(2_000_000), Some(FuseParams::default()));
        let fused_rms = lateral_rms(&fused, "smoothed_pos", 2.0);
        assert!(fused_rms < refined, "fused {fused_rms:.3} m, one sensor {refined:.3} m");
    }

    #[test]
    fn fuse_takes_the_closest_other_object_within_the_gate() {
        let others = Value::List(
            vec![
                Value::Record(Arc::new(Record {
                    id: None,
                    fields: vec![("pos".into(), Value::vec2(3.0, 0.0))],
                })),
                Value::Record(Arc::new(Record {
                    id: None,
                    fields: vec![("pos".into(), Value::vec2(1.0, 1.0))],
                })),
            ]
            .into(),
        );
        assert_eq!(closest_within(&others, [0.0, 0.0], 5.0), Some([1.0, 1.0]));
        assert_eq!(closest_within(&others, [0.0, 0.0], 1.0), None);
        assert_eq!(closest_within(&Value::Int(3), [0.0, 0.0], 1.0), None);
    }
}
