//! Lens distortion: the Brown-Conrady model as OpenCV defines it (`cv::projectPoints` with the
//! coefficients `(k1, k2, p1, p2, k3)`): a point `(x, y)` on the normalised image plane, with
//! `r² = x² + y²`, is seen at
//!
//! ```text
//! x_d = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2 x²)
//! y_d = y (1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y²) + 2 p2 x y
//! ```
//!
//! Undistortion has no closed form; [`Distortion::undistort`] solves it by Newton's method with
//! the model's Jacobian (to 1e-15, where OpenCV's `undistortPoints` iterates a fixed-point scheme
//! a fixed number of times), and says when it does not converge: outside the radius where the
//! model is one-to-one the equation has no unique answer.
//!
//! ```
//! use kpl_camera::Distortion;
//! let lens = Distortion { k1: -0.2, k2: 0.05, p1: 0.001, p2: -0.0005, k3: 0.0 };
//! let seen = lens.distort([0.3, -0.2]);
//! let back = lens.undistort(seen).unwrap();
//! assert!((back[0] - 0.3).abs() < 1e-12 && (back[1] + 0.2).abs() < 1e-12);
//! ```

use nalgebra::Matrix2;

use crate::error::CameraError;

/// Radial (`k1`, `k2`, `k3`) and tangential (`p1`, `p2`) coefficients, OpenCV's order and
/// meaning. All zero: no distortion.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Distortion {
    pub k1: f64,
    pub k2: f64,
    pub p1: f64,
    pub p2: f64,
    pub k3: f64,
}

/// Newton steps before undistortion gives up.
const MAX_ITERATIONS: usize = 100;

/// The largest radius on the normalised image plane a lens model is used for (tan 84°).
pub const MAX_RADIUS: f64 = 9.5;

impl Distortion {
    /// The coefficients in OpenCV's order `[k1, k2, p1, p2, k3]` (fewer: the rest are 0; an
    /// empty list is no distortion); refused when more than five or not finite.
    pub fn from_opencv(coefficients: &[f64]) -> Result<Distortion, CameraError> {
        if coefficients.len() > 5 || !coefficients.iter().all(|c| c.is_finite()) {
            return Err(CameraError::Distortion);
        }
        let c = |i: usize| coefficients.get(i).copied().unwrap_or(0.0);
        Ok(Distortion { k1: c(0), k2: c(1), p1: c(2), p2: c(3), k3: c(4) })
    }

    /// Whether every coefficient is zero.
    pub fn is_none(&self) -> bool {
        *self == Distortion::default()
    }

    /// Where the lens puts the undistorted normalised point `p`.
    pub fn distort(&self, p: [f64; 2]) -> [f64; 2] {
        let [x, y] = p;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        [
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        ]
    }

    /// The Jacobian of [`Distortion::distort`] at `p` (rows: x_d, y_d; columns: x, y).
    pub fn jacobian(&self, p: [f64; 2]) -> Matrix2<f64> {
        let [x, y] = p;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        // d radial / d r² = k1 + 2 k2 r² + 3 k3 r⁴; d r² / dx = 2x.
        let d_radial = self.k1 + r2 * (2.0 * self.k2 + 3.0 * self.k3 * r2);
        let (drx, dry) = (2.0 * x * d_radial, 2.0 * y * d_radial);
        Matrix2::new(
            radial + x * drx + 2.0 * self.p1 * y + 6.0 * self.p2 * x,
            x * dry + 2.0 * self.p1 * x + 2.0 * self.p2 * y,
            y * drx + 2.0 * self.p1 * x + 2.0 * self.p2 * y,
            radial + y * dry + 6.0 * self.p1 * y + 2.0 * self.p2 * x,
        )
    }

    /// How far from the optical axis (radius on the normalised image plane) the model is
    /// one-to-one: up to the first radius where `r (1 + k1 r² + k2 r⁴ + k3 r⁶)` stops growing
    /// (barrel distortion folds back beyond it, and a point there would appear inside the image
    /// again), at most [`MAX_RADIUS`] (about 84° off the axis). Tangential terms are left out of
    /// this bound (they are hundreds of times smaller).
    pub fn valid_radius(&self) -> f64 {
        if self.k1 == 0.0 && self.k2 == 0.0 && self.k3 == 0.0 {
            return MAX_RADIUS;
        }
        let slope = |r: f64| {
            let r2 = r * r;
            1.0 + r2 * (3.0 * self.k1 + r2 * (5.0 * self.k2 + r2 * 7.0 * self.k3))
        };
        let steps = 4000;
        let mut last = 0.0;
        for i in 1..=steps {
            let r = MAX_RADIUS * i as f64 / steps as f64;
            if slope(r).is_nan() || slope(r) <= 0.0 {
                // Refine the fold by bisection between the last good radius and this one.
                let (mut lo, mut hi) = (last, r);
                for _ in 0..60 {
                    let mid = (lo + hi) / 2.0;
                    if slope(mid) > 0.0 {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                return lo;
            }
            last = r;
        }
        MAX_RADIUS
    }

    /// The undistorted normalised point the lens shows at `d` within the one-to-one region
    /// ([`Distortion::valid_radius`]), or `None` when there is none.
    pub fn undistort(&self, d: [f64; 2]) -> Option<[f64; 2]> {
        self.undistort_within(d, self.valid_radius())
    }

    /// [`Distortion::undistort`] with the one-to-one radius given (a camera keeps it).
    pub fn undistort_within(&self, d: [f64; 2], max_radius: f64) -> Option<[f64; 2]> {
        if self.is_none() {
            return Some(d);
        }
        let inside = |p: [f64; 2]| p[0].hypot(p[1]) <= max_radius;
        let mut p = if inside(d) { d } else { [d[0] * 0.5, d[1] * 0.5] };
        for _ in 0..MAX_ITERATIONS {
            let seen = self.distort(p);
            let residual = [seen[0] - d[0], seen[1] - d[1]];
            let scale = 1.0 + d[0].abs() + d[1].abs();
            if residual[0].abs().max(residual[1].abs()) <= 1e-15 * scale {
                return Some(p);
            }
            let inverse = self.jacobian(p).try_inverse()?;
            let step = inverse * nalgebra::Vector2::new(residual[0], residual[1]);
            // Damped: a step that would leave the one-to-one region is halved until it does not.
            let mut factor = 1.0;
            let mut next = [p[0] - step[0], p[1] - step[1]];
            while !inside(next) && factor > 1e-6 {
                factor /= 2.0;
                next = [p[0] - factor * step[0], p[1] - factor * step[1]];
            }
            if !(inside(next) && next[0].is_finite() && next[1].is_finite()) {
                return None;
            }
            p = next;
        }
        // Close enough when the last steps only shuffle rounding errors.
        let seen = self.distort(p);
        ((seen[0] - d[0]).abs().max((seen[1] - d[1]).abs()) <= 1e-12).then_some(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_hand_worked_point() {
        // x = 0.5, y = 0: r² = 0.25; radial = 1 + 0.1·0.25 = 1.025; p2 term = 0.01·(0.25 + 0.5).
        let lens = Distortion { k1: 0.1, p2: 0.01, ..Distortion::default() };
        let d = lens.distort([0.5, 0.0]);
        assert!((d[0] - (0.5 * 1.025 + 0.0075)).abs() < 1e-15, "{d:?}");
        assert!(d[1].abs() < 1e-15, "p1 = 0 and y = 0: {d:?}");
        let back = lens.undistort(d).unwrap();
        assert!((back[0] - 0.5).abs() < 1e-14 && back[1].abs() < 1e-14);
    }

    #[test]
    fn the_jacobian_matches_finite_differences() {
        let lens = Distortion { k1: -0.28, k2: 0.09, p1: 0.0012, p2: -0.0007, k3: -0.01 };
        for p in [[0.1, 0.2], [-0.4, 0.3], [0.6, -0.5], [0.0, 0.0]] {
            let j = lens.jacobian(p);
            let h = 1e-7;
            for axis in 0..2 {
                let mut plus = p;
                let mut minus = p;
                plus[axis] += h;
                minus[axis] -= h;
                let (a, b) = (lens.distort(plus), lens.distort(minus));
                for row in 0..2 {
                    let numeric = (a[row] - b[row]) / (2.0 * h);
                    assert!((numeric - j[(row, axis)]).abs() < 1e-7, "{p:?} {row} {axis}");
                }
            }
        }
    }

    #[test]
    fn coefficients_in_opencv_order() {
        let lens = Distortion::from_opencv(&[1.0, 2.0, 3.0, 4.0, 5.0]).unwrap();
        assert_eq!(lens, Distortion { k1: 1.0, k2: 2.0, p1: 3.0, p2: 4.0, k3: 5.0 });
        assert_eq!(Distortion::from_opencv(&[0.1]).unwrap().k2, 0.0);
        assert!(Distortion::from_opencv(&[]).unwrap().is_none());
        assert!(Distortion::from_opencv(&[0.0; 6]).is_err());
        assert!(Distortion::from_opencv(&[f64::INFINITY]).is_err());
    }

    #[test]
    fn undistortion_says_when_there_is_no_answer() {
        // Strong barrel distortion folds back beyond r ≈ 1.29: x_d = x (1 - 0.2 x²) peaks at 0.86.
        let lens = Distortion { k1: -0.2, ..Distortion::default() };
        assert!((lens.valid_radius() - (1.0f64 / 0.6).sqrt()).abs() < 1e-12);
        assert!(lens.undistort([0.9, 0.0]).is_none());
        assert!(lens.undistort([0.5, 0.0]).is_some());
        // Within reach of the fold, Newton's first step would cross it: damping keeps it inside.
        let back = lens.undistort([0.86, 0.0]).unwrap();
        assert!(back[0] < lens.valid_radius() && (lens.distort(back)[0] - 0.86).abs() < 1e-12);
    }
}
