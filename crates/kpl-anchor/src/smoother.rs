//! A fixed-lag Rauch-Tung-Striebel smoother over a [`CvFilter`]'s steps: the estimate of an
//! object `lag` before its newest measurement, refined with every measurement since.
//!
//! A filter's estimate at time t uses the measurements up to t; the smoothed one uses those up to
//! t + lag too. With the simulated tracker's noise (1 m per axis at 10 Hz, velocity 0.5 m/s), the
//! filter's position error has a standard deviation of about 0.22 m whatever its process noise,
//! and a smoother with a lag of 2 s about 0.17 m (docs/situations.md#weaving, where this is what
//! a weaving chronicle needs; a test checks both figures). `anchor.kalman(smooth: 2s)` drives it
//! ([`crate::kalman`]): the smoothed estimate is an attribute of the object's state, for a time
//! `lag` before the state's valid time.
//!
//! Each step keeps the filter's prediction to the measurement's time and its estimate after the
//! measurement; [`FixedLag::smoothed`] runs the smoother's backward pass from the newest step to
//! the oldest kept one (the last step at or before the newest time minus the lag), and from there
//! to exactly the newest time minus the lag: that time need not be a step's (a missed detection,
//! an occlusion), so the oldest step's estimate is first predicted on to it with the filter's own
//! motion model. The result is the mean and covariance of the state at that time given every
//! measurement taken in, the same as a batch solution of the whole linear-Gaussian problem with a
//! state at that time (the tests check it against one).
//!
//! ```
//! use kpl_anchor::kalman::CvFilter;
//! use kpl_anchor::smoother::FixedLag;
//!
//! let mut filter = CvFilter::new([0.0, 0.0], [10.0, 0.0], 1.0, 1.0, 0);
//! let mut smoother = FixedLag::new(1_000_000, 2.0); // 1 s, the filter's acceleration noise
//! smoother.push(filter.clone(), filter.clone());
//! for k in 1..=20_i64 {
//!     let time = k * 100_000; // 10 Hz
//!     filter.predict(time, 2.0);
//!     let predicted = filter.clone();
//!     filter.update([k as f64, 0.0], 1.0).unwrap();
//!     smoother.push(predicted, filter.clone());
//! }
//! let smoothed = smoother.smoothed().unwrap();
//! assert_eq!(smoothed.time, 1_000_000); // the state 1 s before the newest
//! assert!(smoothed.p[(0, 0)] < 1.0);
//! ```

use std::borrow::Cow;
use std::collections::VecDeque;

use kpl_core::Time;

use crate::kalman::CvFilter;

/// The most steps a smoother keeps, whatever its lag and the measurements' rate (10 minutes at
/// 10 Hz): the oldest are dropped beyond, and the smoothed state is then less than `lag` old.
pub const MAX_STEPS: usize = 6_000;

/// One step of the filter: its prediction to the measurement's time, and its estimate after it.
#[derive(Debug, Clone, PartialEq)]
struct Step {
    predicted: CvFilter,
    updated: CvFilter,
}

/// The steps of one object's filter over the last `lag` (µs) and a little more.
#[derive(Debug, Clone, PartialEq)]
pub struct FixedLag {
    lag: Time,
    /// The filter's acceleration noise (its `predict`'s `q`), to predict between steps.
    q: f64,
    steps: VecDeque<Step>,
}

impl FixedLag {
    /// A smoother whose estimate is `lag` (µs) older than the newest measurement, over a filter
    /// that predicts with the acceleration noise `q` ([`CvFilter::predict`]).
    pub fn new(lag: Time, q: f64) -> FixedLag {
        FixedLag { lag: lag.max(0), q, steps: VecDeque::new() }
    }

    /// Takes in one step of the filter: `predicted`, the filter moved on to the measurement's time
    /// ([`CvFilter::predict`]), and `updated`, the filter after the measurement. The first step of
    /// a filter is its start, both the same. A step at the last one's time is another measurement
    /// taken in at that time (`anchor.fuse`'s second sensor): it replaces the last step's estimate
    /// and keeps its prediction. A step before it (a filter started again, or time gone back)
    /// starts the smoother over.
    pub fn push(&mut self, predicted: CvFilter, updated: CvFilter) {
        if let Some(last) = self.steps.back_mut() {
            if updated.time == last.updated.time {
                last.updated = updated;
                return;
            }
            if updated.time < last.updated.time {
                self.steps.clear();
            }
        }
        let newest = updated.time;
        self.steps.push_back(Step { predicted, updated });
        // Keep the last step at or before `newest - lag`, and the ones after it.
        while self.steps.len() > MAX_STEPS
            || self.steps.get(1).is_some_and(|next| next.updated.time <= newest.saturating_sub(self.lag))
        {
            self.steps.pop_front();
        }
    }

    /// The state at the newest time minus the lag given every measurement taken in. `None`
    /// before the steps span the lag (or when a prediction's covariance cannot be inverted).
    pub fn smoothed(&self) -> Option<CvFilter> {
        let oldest = self.steps.front()?;
        let newest = self.steps.back()?;
        if oldest.updated.time > newest.updated.time.saturating_sub(self.lag) {
            return None;
        }
        self.smoothed_so_far()
    }

    /// As [`FixedLag::smoothed`], also before the steps span the lag: then the smoothed state of
    /// the first step (less than `lag` before the newest).
    pub fn smoothed_so_far(&self) -> Option<CvFilter> {
        let newest = self.steps.back()?;
        let at = newest.updated.time.saturating_sub(self.lag);
        let mut smoothed = newest.updated.clone();
        for j in (0..self.steps.len() - 1).rev() {
            let (step, next) = (&self.steps[j], &self.steps[j + 1]);
            // The oldest step is before `at`: its estimate predicted on to `at` is the filtered
            // state there, which the backward pass refines as any other.
            let filtered = if j == 0 && step.updated.time < at {
                let mut between = step.updated.clone();
                between.predict(at, self.q);
                Cow::Owned(between)
            } else {
                Cow::Borrowed(&step.updated)
            };
            smoothed = backward(&filtered, next, &smoothed)?;
        }
        Some(smoothed)
    }
}

/// One step of the backward pass: the state of `filtered` (the filter's estimate at its time)
/// given every measurement, from the smoothed state of the `next` step.
fn backward(filtered: &CvFilter, next: &Step, smoothed: &CvFilter) -> Option<CvFilter> {
    let dt = (next.predicted.time.saturating_sub(filtered.time)).max(0) as f64 / 1e6;
    let f = CvFilter::transition(dt);
    let gain = filtered.p * f.transpose() * next.predicted.p.try_inverse()?;
    let x = filtered.x + gain * (smoothed.x - next.predicted.x);
    let p = filtered.p + gain * (smoothed.p - next.predicted.p) * gain.transpose();
    Some(CvFilter { x, p, time: filtered.time })
}

#[cfg(test)]
#[allow(clippy::unwrap_used, reason = "tests")]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector, Matrix2, Matrix4, Vector4};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    const Q: f64 = 2.0;
    const R: f64 = 1.0;
    const R_V: f64 = 0.25;

    /// A filter run over `n` measurements of position and velocity at irregular times, with
    /// every step pushed into a smoother of lag `lag`; returns the smoother, the start, the
    /// times and the measurements.
    #[allow(clippy::type_complexity, reason = "a test's fixture")]
    fn run(seed: u64, n: usize, lag: Time) -> (FixedLag, CvFilter, Vec<Time>, Vec<Vector4<f64>>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let start = CvFilter::with_position_covariance(
            [rng.random_range(-5.0..5.0), 0.0],
            [10.0, rng.random_range(-1.0..1.0)],
            Matrix2::new(2.0, 0.3, 0.3, 1.5),
            4.0,
            0,
        );
        let mut filter = start.clone();
        let mut smoother = FixedLag::new(lag, Q);
        smoother.push(start.clone(), start.clone());
        let (mut times, mut zs) = (Vec::new(), Vec::new());
        let mut time = 0;
        for k in 0..n {
            time += rng.random_range(50_000..150_000);
            let truth = Vector4::new(10.0 * time as f64 / 1e6, (k as f64 / 7.0).sin(), 10.0, 0.3);
            let z = truth + Vector4::from_fn(|_, _| rng.random_range(-1.0..1.0));
            filter.predict(time, Q);
            let predicted = filter.clone();
            filter.update_with_velocity([z[0], z[1]], R, [z[2], z[3]], R_V).unwrap();
            smoother.push(predicted, filter.clone());
            times.push(time);
            zs.push(z);
        }
        (smoother, start, times, zs)
    }

    /// The mean of every state given every measurement, solved at once: the information matrix
    /// of the prior, the motion model and the measurements, written out block by block. The
    /// states are the start's and one at each time of `nodes` (increasing), measured where it has
    /// a measurement.
    fn batch(start: &CvFilter, nodes: &[(Time, Option<Vector4<f64>>)]) -> Vec<Vector4<f64>> {
        let n = nodes.len() + 1;
        let mut info = DMatrix::<f64>::zeros(4 * n, 4 * n);
        let mut vector = DVector::<f64>::zeros(4 * n);
        let add = |info: &mut DMatrix<f64>, i: usize, j: usize, block: &Matrix4<f64>| {
            let mut view = info.view_mut((4 * i, 4 * j), (4, 4));
            view += block;
        };
        let prior = start.p.try_inverse().unwrap();
        add(&mut info, 0, 0, &prior);
        vector.rows_mut(0, 4).copy_from(&(prior * start.x));
        let measurement = Matrix4::from_diagonal(&Vector4::new(1.0 / R, 1.0 / R, 1.0 / R_V, 1.0 / R_V));
        let mut previous = 0;
        for (k, &(time, z)) in nodes.iter().enumerate() {
            let dt = (time - previous) as f64 / 1e6;
            previous = time;
            let mut f = Matrix4::identity();
            f[(0, 2)] = dt;
            f[(1, 3)] = dt;
            let mut q = Matrix4::zeros();
            for axis in 0..2 {
                q[(axis, axis)] = Q * dt.powi(3) / 3.0;
                q[(axis, axis + 2)] = Q * dt.powi(2) / 2.0;
                q[(axis + 2, axis)] = Q * dt.powi(2) / 2.0;
                q[(axis + 2, axis + 2)] = Q * dt;
            }
            // x_{k+1} - F x_k ~ N(0, Q)
            let qi = q.try_inverse().unwrap();
            add(&mut info, k, k, &(f.transpose() * qi * f));
            add(&mut info, k, k + 1, &(-(f.transpose() * qi)));
            add(&mut info, k + 1, k, &(-(qi * f)));
            add(&mut info, k + 1, k + 1, &qi);
            if let Some(z) = z {
                add(&mut info, k + 1, k + 1, &measurement);
                let mut rows = vector.rows_mut(4 * (k + 1), 4);
                rows += measurement * z;
            }
        }
        let mean = info.lu().solve(&vector).unwrap();
        (0..n).map(|k| Vector4::from_iterator(mean.rows(4 * k, 4).iter().copied())).collect()
    }

    #[test]
    fn the_smoothed_state_is_the_batch_solution_given_every_measurement() {
        for seed in 0..40 {
            let n = 60;
            // Lags from about the whole run (60 steps of 50 to 150 ms) to a few steps; the state
            // at the newest time minus the lag falls between two steps (a batch state without a
            // measurement there) except for the lag of exactly the measurements' first time.
            let (_, _, times, _) = run(seed, n, 0);
            let newest = *times.last().unwrap();
            let lag = [2_900_000, 2_000_000, 700_000, 150_000, newest - times[0]][seed as usize % 5];
            let (smoother, start, times, zs) = run(seed, n, lag);
            let smoothed = smoother.smoothed().unwrap();
            let at = newest - lag;
            assert_eq!(smoothed.time, at, "seed {seed}");
            let mut nodes: Vec<(Time, Option<Vector4<f64>>)> =
                times.iter().zip(&zs).map(|(&t, &z)| (t, Some(z))).collect();
            let index = match nodes.iter().position(|&(t, _)| t >= at) {
                Some(i) if nodes[i].0 == at => i + 1,
                Some(i) => {
                    nodes.insert(i, (at, None));
                    i + 1
                }
                None => unreachable!("the lag is not negative"),
            };
            let all = batch(&start, &nodes);
            let error = (smoothed.x - all[index]).abs().max();
            assert!(
                error < 1e-6,
                "seed {seed}, lag {lag}: smoothed {:?}, batch {:?}",
                smoothed.x,
                all[index]
            );
        }
    }

    /// A missed step just after the newest time minus the lag: the estimate is still of that
    /// time (not the step before it), and the state's position there.
    #[test]
    fn a_missed_step_does_not_make_the_estimate_older() {
        let mut filter = CvFilter::new([0.0, 0.0], [14.0, 0.0], R, 1.0, 0);
        let mut smoother = FixedLag::new(2_000_000, Q);
        smoother.push(filter.clone(), filter.clone());
        for k in (1..=40_i64).filter(|k| *k != 21) {
            let time = k * 100_000;
            filter.predict(time, Q);
            let predicted = filter.clone();
            filter.update([14.0 * time as f64 / 1e6, 0.0], R).unwrap();
            smoother.push(predicted, filter.clone());
        }
        // Newest 4.0 s, the estimate of 2.0 s, steps at 2.0 and 2.2 s.
        let smoothed = smoother.smoothed().unwrap();
        assert_eq!(smoothed.time, 2_000_000);
        assert!((smoothed.position()[0] - 28.0).abs() < 0.05, "{:?}", smoothed.position());
        smoother.push(
            {
                let mut p = filter.clone();
                p.predict(4_100_000, Q);
                p
            },
            {
                let mut u = filter.clone();
                u.predict(4_100_000, Q);
                u.update([57.4, 0.0], R).unwrap();
                u
            },
        );
        // Newest 4.1 s: 2.1 s was missed; the estimate is of 2.1 s, between the steps.
        let smoothed = smoother.smoothed().unwrap();
        assert_eq!(smoothed.time, 2_100_000);
        assert!((smoothed.position()[0] - 29.4).abs() < 0.05, "{:?}", smoothed.position());
    }

    #[test]
    fn the_smoothed_state_is_surer_than_the_filtered_one_and_none_before_the_lag() {
        let (smoother, ..) = run(7, 3, 1_000_000);
        assert_eq!(smoother.smoothed(), None, "three steps do not span 1 s");
        let (smoother, ..) = run(7, 60, 1_000_000);
        let smoothed = smoother.smoothed().unwrap();
        let filtered = &smoother.steps[0].updated;
        assert!(
            smoothed.p[(0, 0)] < 0.8 * filtered.p[(0, 0)],
            "{} against {}",
            smoothed.p[(0, 0)],
            filtered.p[(0, 0)]
        );
        // Only the steps within the lag, and the one just before, are kept.
        let newest = smoother.steps.back().unwrap().updated.time;
        assert!(smoother.steps[0].updated.time <= newest - 1_000_000);
        assert!(smoother.steps[1].updated.time > newest - 1_000_000);
    }

    /// The figures of the module's documentation, which docs/situations.md's model computed on
    /// its own: the tracker's noises at 10 Hz, the position's standard deviation filtered and
    /// smoothed with a lag of 2 s.
    #[test]
    fn at_the_trackers_noise_a_two_second_lag_takes_the_error_from_0_22_to_0_17_m() {
        let mut filter = CvFilter::new([0.0, 0.0], [20.0, 0.0], R, 1.0, 0);
        let mut smoother = FixedLag::new(2_000_000, Q);
        smoother.push(filter.clone(), filter.clone());
        for k in 1..=300_i64 {
            filter.predict(k * 100_000, Q);
            let predicted = filter.clone();
            filter.update_with_velocity(filter.position(), R, filter.velocity(), R_V).unwrap();
            smoother.push(predicted, filter.clone());
        }
        let filtered = filter.p[(0, 0)].sqrt();
        let smoothed = smoother.smoothed().unwrap().p[(0, 0)].sqrt();
        assert!((0.215..0.23).contains(&filtered), "filtered {filtered}");
        assert!((0.16..0.175).contains(&smoothed), "smoothed {smoothed}");
    }

    #[test]
    fn a_second_measurement_at_a_time_replaces_the_estimate_a_step_back_starts_over_and_the_steps_are_bounded()
     {
        let (mut smoother, start, ..) = run(3, 30, 500_000);
        let kept = smoother.steps.len();
        assert!(kept > 2);
        // A second measurement at the newest time: the same step, its estimate replaced.
        let mut again = smoother.steps.back().unwrap().updated.clone();
        let before = smoother.smoothed().unwrap();
        again.update(again.position(), R).unwrap();
        smoother.push(again.clone(), again.clone());
        assert_eq!(smoother.steps.len(), kept);
        assert_eq!(smoother.steps.back().unwrap().updated, again);
        assert_ne!(smoother.smoothed().unwrap(), before);
        // A step back in time starts over.
        smoother.push(start.clone(), start);
        assert_eq!(smoother.steps.len(), 1);
        let mut long = FixedLag::new(Time::MAX, Q);
        let mut filter = CvFilter::new([0.0, 0.0], [1.0, 0.0], 1.0, 1.0, 0);
        long.push(filter.clone(), filter.clone());
        for k in 1..(MAX_STEPS as i64 + 100) {
            filter.predict(k * 100_000, Q);
            let predicted = filter.clone();
            filter.update(filter.position(), R).unwrap();
            long.push(predicted, filter.clone());
        }
        assert_eq!(long.steps.len(), MAX_STEPS);
    }
}
