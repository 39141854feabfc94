//! Georeferencing with an honest uncertainty: a pixel's point on the ground and its 2 x 2
//! covariance, propagated to first order from the pixel's noise and the pose's (position,
//! platform attitude, gimbal angles, and the ground's height) through the Jacobian of the
//! ground intersection: `Σ_g = J_px Σ_px J_pxᵀ + J_pose Σ_pose J_poseᵀ`.
//!
//! The Jacobian is analytic. With `m = (x, y, 1)` the pixel's undistorted normalised point,
//! `d = R_wc m` its ray and `s = ground_z - C_z`, the ground point is `g = C_xy + s d_xy / d_z`, so
//! `∂g/∂d = s [[1/d_z, 0, -d_x/d_z²], [0, 1/d_z, -d_y/d_z²]]`; the pixel enters through
//! `∂m/∂pixel = J_lens⁻¹ diag(1/fx, 1/fy)`, each angle θ through `∂d/∂θ = (∂R_wc/∂θ) m`, the
//! camera's height through `-d_xy / d_z`, its horizontal position one to one, the ground's height
//! through `d_xy / d_z`. A far, oblique pixel gets a large, elongated covariance; a pixel straight
//! below a camera a small, round one. A [`Georeferencer`] holds what one pose shares (the rotation
//! and its derivatives), so a frame's boxes cost a few dozen multiplications each.
//!
//! ```
//! use kpl_camera::{Attitude, Camera, Distortion, Georeferencer, Gimbal, Intrinsics, Pose, PoseNoise};
//! let k = Intrinsics::from_fov(1920.0, 1080.0, 60f64.to_radians()).unwrap();
//! let pose = Pose::new([0.0, 0.0, 100.0], Attitude::level(0.0), Gimbal { pan: 0.0, tilt: 45f64.to_radians() });
//! let camera = Camera::new(k, Distortion::default(), pose).unwrap();
//! let noise = PoseNoise { attitude_sd: [0.5f64.to_radians(); 3], ..PoseNoise::default() };
//! let geo = Georeferencer::new(&camera, noise, 0.0);
//! let near = geo.ground([960.0, 1000.0], 2.0).unwrap();
//! let far = geo.ground([960.0, 100.0], 2.0).unwrap();
//! assert!(far.cov[(0, 0)] > 4.0 * near.cov[(0, 0)], "the far one is less certain along the view");
//! ```

use nalgebra::{Matrix2, Matrix2x3, Matrix3, Vector2, Vector3};

use crate::camera::Camera;
use crate::error::GroundError;

/// Standard deviations of a pose: the camera's position (east, north, up; metres: a GPS), the
/// platform's attitude (roll, pitch, yaw; radians: an IMU), the gimbal's angles (pan, tilt;
/// radians) and the ground plane's height (metres). Independent of each other.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseNoise {
    pub position_sd: [f64; 3],
    pub attitude_sd: [f64; 3],
    pub gimbal_sd: [f64; 2],
    pub ground_sd: f64,
}

impl PoseNoise {
    /// Whether every standard deviation is a finite number at least 0.
    pub fn is_valid(&self) -> bool {
        self.position_sd
            .iter()
            .chain(&self.attitude_sd)
            .chain(&self.gimbal_sd)
            .chain(std::iter::once(&self.ground_sd))
            .all(|v| v.is_finite() && *v >= 0.0)
    }

    /// The variances of the angles in [`crate::pose::ANGLES`]' order.
    fn angle_variances(&self) -> [f64; 5] {
        let [r, p, y] = self.attitude_sd;
        let [pan, tilt] = self.gimbal_sd;
        [r * r, p * p, y * y, pan * pan, tilt * tilt]
    }
}

/// A point on the ground with its covariance (m²).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundEstimate {
    pub pos: [f64; 2],
    pub cov: Matrix2<f64>,
}

impl GroundEstimate {
    /// The covariance as `[σ_xx, σ_xy, σ_yy]` (m²).
    pub fn cov_entries(&self) -> [f64; 3] {
        [self.cov[(0, 0)], self.cov[(0, 1)], self.cov[(1, 1)]]
    }

    /// The squared Mahalanobis distance of `point` from the estimate (`None` when the covariance
    /// is singular).
    pub fn mahalanobis2(&self, point: [f64; 2]) -> Option<f64> {
        let e = Vector2::new(point[0] - self.pos[0], point[1] - self.pos[1]);
        let inverse = self.cov.try_inverse()?;
        Some((e.transpose() * inverse * e)[0])
    }

    /// The distance from the estimate within which the true point lies with probability `p`
    /// (0 < p < 1), if the error is Gaussian with this covariance: `P(|e| <= r) = p`. With the
    /// error written as `ρ (√λ1 cos φ, √λ2 sin φ)` (`ρ` Rayleigh, `φ` uniform: the whitened
    /// error in polar coordinates), `P(|e| <= r)` is the mean over `φ` of
    /// `1 - exp(-r² / (2 (λ1 cos² φ + λ2 sin² φ)))`, smooth whatever the ellipse's shape;
    /// `r` is found by bisection. The median error is `error_quantile(0.5)`.
    pub fn error_quantile(&self, p: f64) -> f64 {
        let eigen = nalgebra::SymmetricEigen::new(self.cov);
        let (l1, l2) = (eigen.eigenvalues[0].max(0.0), eigen.eigenvalues[1].max(0.0));
        const STEPS: usize = 256;
        let cdf = |r: f64| {
            let mut sum = 0.0;
            for k in 0..STEPS {
                let phi = (k as f64 + 0.5) * std::f64::consts::TAU / STEPS as f64;
                let s = l1 * phi.cos().powi(2) + l2 * phi.sin().powi(2);
                sum += if s > 0.0 { -(-r * r / (2.0 * s)).exp_m1() } else { 1.0 };
            }
            sum / STEPS as f64
        };
        let (mut lo, mut hi) = (0.0, 10.0 * l1.max(l2).sqrt());
        for _ in 0..100 {
            let mid = (lo + hi) / 2.0;
            if cdf(mid) < p {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        (lo + hi) / 2.0
    }

    /// The semi-axes of the 1-sigma ellipse (metres), largest first, and the heading of the
    /// largest (radians counter-clockwise from east).
    pub fn ellipse(&self) -> ([f64; 2], f64) {
        let eigen = nalgebra::SymmetricEigen::new(self.cov);
        let (i, j) = if eigen.eigenvalues[0] >= eigen.eigenvalues[1] { (0, 1) } else { (1, 0) };
        let axis = eigen.eigenvectors.column(i);
        ([eigen.eigenvalues[i].max(0.0).sqrt(), eigen.eigenvalues[j].max(0.0).sqrt()], axis[1].atan2(axis[0]))
    }
}

/// Georeferencing at one pose: the camera, the pose's noise, the ground's height, and the
/// rotation's derivatives computed once.
#[derive(Debug, Clone)]
pub struct Georeferencer<'a> {
    camera: &'a Camera,
    noise: PoseNoise,
    angle_variances: [f64; 5],
    ground_z: f64,
    derivatives: [Matrix3<f64>; 5],
}

impl<'a> Georeferencer<'a> {
    pub fn new(camera: &'a Camera, noise: PoseNoise, ground_z: f64) -> Georeferencer<'a> {
        Georeferencer {
            camera,
            noise,
            angle_variances: noise.angle_variances(),
            ground_z,
            derivatives: camera.pose().rotation_derivatives(),
        }
    }

    pub fn camera(&self) -> &Camera {
        self.camera
    }

    /// The ground point of `pixel` and its covariance, for a pixel measured with standard
    /// deviation `pixel_sd` (pixels, per axis) and the pose's noise.
    pub fn ground(&self, pixel: [f64; 2], pixel_sd: f64) -> Result<GroundEstimate, GroundError> {
        let camera = self.camera;
        let [x, y] = camera.normalized(pixel)?;
        let m = Vector3::new(x, y, 1.0);
        let d = camera.rotation() * m;
        let c = camera.pose().position;
        let s = self.ground_z - c[2];
        let t = s / d[2];
        if !(t > 0.0 && t.is_finite()) {
            return Err(GroundError::AboveHorizon);
        }
        let pos = [c[0] + t * d[0], c[1] + t * d[1]];
        let g_d =
            Matrix2x3::new(1.0 / d[2], 0.0, -d[0] / (d[2] * d[2]), 0.0, 1.0 / d[2], -d[1] / (d[2] * d[2]))
                * s;
        let mut cov = Matrix2::zeros();
        // The pixel: ∂m/∂pixel through the lens and the focal lengths.
        if pixel_sd > 0.0 {
            let k = camera.intrinsics();
            let lens = camera.distortion().jacobian([x, y]).try_inverse().ok_or(GroundError::Undistort)?;
            let dm = lens * Matrix2::new(1.0 / k.fx, 0.0, 0.0, 1.0 / k.fy);
            let r2 = camera.rotation().fixed_view::<3, 2>(0, 0) * dm;
            let j = g_d * r2;
            cov += j * j.transpose() * (pixel_sd * pixel_sd);
        }
        // The angles.
        for (derivative, variance) in self.derivatives.iter().zip(self.angle_variances) {
            if variance > 0.0 {
                let j = g_d * (derivative * m);
                cov += j * j.transpose() * variance;
            }
        }
        // The camera's position and the ground's height.
        let [sx, sy, sz] = self.noise.position_sd;
        cov[(0, 0)] += sx * sx;
        cov[(1, 1)] += sy * sy;
        let lever = Vector2::new(d[0] / d[2], d[1] / d[2]);
        let height_variance = sz * sz + self.noise.ground_sd * self.noise.ground_sd;
        if height_variance > 0.0 {
            cov += lever * lever.transpose() * height_variance;
        }
        if !cov.iter().all(|v| v.is_finite()) {
            return Err(GroundError::AboveHorizon);
        }
        Ok(GroundEstimate { pos, cov })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::distortion::Distortion;
    use crate::intrinsics::Intrinsics;
    use crate::pose::{Attitude, Gimbal, Pose};

    fn camera(tilt_deg: f64) -> Camera {
        let k = Intrinsics::new(500.0, 500.0, 500.0, 400.0, 1000.0, 800.0).unwrap();
        let pose = Pose::new(
            [0.0, 0.0, 100.0],
            Attitude::level(0.0),
            Gimbal { pan: 0.0, tilt: tilt_deg.to_radians() },
        );
        Camera::new(k, Distortion::default(), pose).unwrap()
    }

    #[test]
    fn hand_worked_nadir_covariances() {
        let camera = camera(90.0);
        // Pixel noise only: 5 px per metre at the centre, so 2 px is 0.4 m on each axis.
        let geo = Georeferencer::new(&camera, PoseNoise::default(), 0.0);
        let e = geo.ground([500.0, 400.0], 2.0).unwrap();
        assert!((e.cov[(0, 0)] - 0.16).abs() < 1e-12 && (e.cov[(1, 1)] - 0.16).abs() < 1e-12);
        assert!(e.cov[(0, 1)].abs() < 1e-12);
        // Yaw noise only: the centre does not move, a point 20 m south moves by 20 m · σ east-west.
        let sd = 0.01;
        let noise = PoseNoise { attitude_sd: [0.0, 0.0, sd], ..PoseNoise::default() };
        let geo = Georeferencer::new(&camera, noise, 0.0);
        assert!(geo.ground([500.0, 400.0], 0.0).unwrap().cov.norm() < 1e-20);
        let e = geo.ground([600.0, 400.0], 0.0).unwrap();
        assert!((e.pos[1] + 20.0).abs() < 1e-9);
        assert!(
            (e.cov[(0, 0)] - (20.0 * sd).powi(2)).abs() < 1e-12 && e.cov[(1, 1)].abs() < 1e-12,
            "{}",
            e.cov
        );
        // Pitch noise at the centre of a nadir view: 100 m · σ along the nose (east), to first order.
        let noise = PoseNoise { attitude_sd: [0.0, sd, 0.0], ..PoseNoise::default() };
        let e = Georeferencer::new(&camera, noise, 0.0).ground([500.0, 400.0], 0.0).unwrap();
        assert!((e.cov[(0, 0)] - 1.0).abs() < 1e-9 && e.cov[(1, 1)].abs() < 1e-12, "{}", e.cov);
        // Height noise at the centre moves nothing; horizontal position noise adds as it is.
        let noise = PoseNoise { position_sd: [1.0, 2.0, 5.0], ..PoseNoise::default() };
        let e = Georeferencer::new(&camera, noise, 0.0).ground([500.0, 400.0], 0.0).unwrap();
        assert!((e.cov[(0, 0)] - 1.0).abs() < 1e-12 && (e.cov[(1, 1)] - 4.0).abs() < 1e-12);
        // ... and at 20 m south, 5 m of height is 1 m along the ray.
        let e = Georeferencer::new(&camera, noise, 0.0).ground([600.0, 400.0], 0.0).unwrap();
        assert!((e.cov[(1, 1)] - (4.0 + 1.0)).abs() < 1e-12, "{}", e.cov);
        let (axes, _) = e.ellipse();
        assert!((axes[0] - 5f64.sqrt()).abs() < 1e-9 && (axes[1] - 1.0).abs() < 1e-9);
    }

    #[test]
    fn the_jacobian_matches_finite_differences() {
        // Compare the propagated covariance of one parameter at a time with a numeric derivative.
        let k = Intrinsics::new(800.0, 780.0, 640.0, 360.0, 1280.0, 720.0).unwrap();
        let lens = Distortion { k1: -0.25, k2: 0.07, p1: 0.001, p2: -0.002, k3: 0.0 };
        let pose = Pose::new(
            [5.0, -3.0, 80.0],
            Attitude { roll: 0.03, pitch: -0.02, yaw: 0.7 },
            Gimbal { pan: 0.2, tilt: 0.9 },
        );
        let camera = Camera::new(k, lens, pose).unwrap();
        let pixel = [1000.0, 500.0];
        let g0 = camera.ground_point(pixel, 0.0).unwrap();
        let h = 1e-6;
        let numeric = |moved: Camera, pixel: [f64; 2]| {
            let g = moved.ground_point(pixel, 0.0).unwrap();
            [(g[0] - g0[0]) / h, (g[1] - g0[1]) / h]
        };
        let check = |noise: PoseNoise, pixel_sd: f64, j: [f64; 2]| {
            let e = Georeferencer::new(&camera, noise, 0.0).ground(pixel, pixel_sd).unwrap();
            let expected = [j[0] * j[0], j[0] * j[1], j[1] * j[1]];
            for (a, b) in e.cov_entries().iter().zip(expected) {
                assert!((a - b).abs() < 1e-4 * (1.0 + b.abs()), "{:?} vs {expected:?}", e.cov_entries());
            }
        };
        let mut p = pose;
        p.attitude.roll += h;
        check(
            PoseNoise { attitude_sd: [1.0, 0.0, 0.0], ..PoseNoise::default() },
            0.0,
            numeric(camera.with_pose(p).unwrap(), pixel),
        );
        let mut p = pose;
        p.attitude.pitch += h;
        check(
            PoseNoise { attitude_sd: [0.0, 1.0, 0.0], ..PoseNoise::default() },
            0.0,
            numeric(camera.with_pose(p).unwrap(), pixel),
        );
        let mut p = pose;
        p.gimbal.tilt += h;
        check(
            PoseNoise { gimbal_sd: [0.0, 1.0], ..PoseNoise::default() },
            0.0,
            numeric(camera.with_pose(p).unwrap(), pixel),
        );
        let mut p = pose;
        p.position[2] += h;
        check(
            PoseNoise { position_sd: [0.0, 0.0, 1.0], ..PoseNoise::default() },
            0.0,
            numeric(camera.with_pose(p).unwrap(), pixel),
        );
        // The pixel's u alone: a noise of 1 px on u only is not expressible, so compare the
        // sum of both axes' outer products.
        let ju = numeric(camera.clone(), [pixel[0] + h, pixel[1]]);
        let jv = numeric(camera.clone(), [pixel[0], pixel[1] + h]);
        let e = Georeferencer::new(&camera, PoseNoise::default(), 0.0).ground(pixel, 1.0).unwrap();
        let expected =
            [ju[0] * ju[0] + jv[0] * jv[0], ju[0] * ju[1] + jv[0] * jv[1], ju[1] * ju[1] + jv[1] * jv[1]];
        for (a, b) in e.cov_entries().iter().zip(expected) {
            assert!((a - b).abs() < 1e-4 * (1.0 + b.abs()), "{:?} vs {expected:?}", e.cov_entries());
        }
    }

    #[test]
    fn error_quantiles_of_known_distributions() {
        // Isotropic σ = 2: |e| is Rayleigh, median σ √(2 ln 2).
        let e = GroundEstimate { pos: [0.0; 2], cov: Matrix2::identity() * 4.0 };
        assert!((e.error_quantile(0.5) - 2.0 * (2.0 * 2f64.ln()).sqrt()).abs() < 1e-9);
        assert!((e.error_quantile(0.95) - 2.0 * (-2.0 * 0.05f64.ln()).sqrt()).abs() < 1e-9);
        // Nearly one-dimensional: the median of |N(0, 9)| is 3 · 0.6745.
        let e = GroundEstimate { pos: [0.0; 2], cov: Matrix2::new(9.0, 0.0, 0.0, 1e-12) };
        assert!((e.error_quantile(0.5) - 3.0 * 0.674_489_750_196).abs() < 1e-4, "{}", e.error_quantile(0.5));
    }

    #[test]
    fn above_the_horizon_is_refused() {
        let camera = camera(10.0);
        let geo = Georeferencer::new(&camera, PoseNoise::default(), 0.0);
        assert_eq!(geo.ground([500.0, 0.0], 1.0), Err(GroundError::AboveHorizon));
        assert_eq!(geo.ground([f64::NAN, 0.0], 1.0), Err(GroundError::NotFinite));
        assert!(!PoseNoise { ground_sd: -1.0, ..PoseNoise::default() }.is_valid());
        assert!(PoseNoise::default().is_valid());
    }
}
