//! A calibrated camera in the world: intrinsics, lens distortion and pose. Its two directions:
//! [`Camera::pixel_of`] (a world point's pixel) and [`Camera::ground_point`] (a pixel's point on
//! the ground plane `z = ground_z`), and what it sees of the ground, [`Camera::footprint`].
//!
//! ```
//! use kpl_camera::{Attitude, Camera, Distortion, Gimbal, Intrinsics, Pose};
//! let k = Intrinsics::from_fov(1000.0, 800.0, 90f64.to_radians()).unwrap(); // fx = 500
//! let pose = Pose::new([0.0, 0.0, 100.0], Attitude::level(0.0), Gimbal::nadir());
//! let camera = Camera::new(k, Distortion::default(), pose).unwrap();
//! // 50 pixels right of the centre, looking down from 100 m with f = 500: 10 m to the south.
//! let ground = camera.ground_point([550.0, 400.0], 0.0).unwrap();
//! assert!((ground[0]).abs() < 1e-9 && (ground[1] + 10.0).abs() < 1e-9);
//! let pixel = camera.pixel_of([ground[0], ground[1], 0.0]).unwrap();
//! assert!((pixel[0] - 550.0).abs() < 1e-9 && (pixel[1] - 400.0).abs() < 1e-9);
//! ```

use nalgebra::{Matrix3, Vector3};

use crate::distortion::Distortion;
use crate::error::{CameraError, GroundError};
use crate::intrinsics::Intrinsics;
use crate::pose::Pose;

/// A camera: what it is (intrinsics, lens) and where it is (pose), with its rotation cached.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    intrinsics: Intrinsics,
    distortion: Distortion,
    pose: Pose,
    /// `R_wc`: camera axes to world.
    rotation: Matrix3<f64>,
    /// Where the lens model is one-to-one (radius on the normalised image plane).
    lens_radius: f64,
}

/// Points per image side when the footprint's outline follows a distorted image's border.
const BORDER_POINTS_DISTORTED: usize = 8;
/// Points of the arc at the footprint's range along the horizon, where the horizon is in view.
const HORIZON_ARC_POINTS: usize = 8;

impl Camera {
    pub fn new(intrinsics: Intrinsics, distortion: Distortion, pose: Pose) -> Result<Camera, CameraError> {
        if !pose.is_finite() {
            return Err(CameraError::Pose);
        }
        Ok(Camera {
            intrinsics,
            distortion,
            rotation: pose.rotation(),
            pose,
            lens_radius: distortion.valid_radius(),
        })
    }

    /// The same camera at another pose.
    pub fn with_pose(&self, pose: Pose) -> Result<Camera, CameraError> {
        Camera::new(self.intrinsics, self.distortion, pose)
    }

    pub fn intrinsics(&self) -> &Intrinsics {
        &self.intrinsics
    }

    pub fn distortion(&self) -> &Distortion {
        &self.distortion
    }

    pub fn pose(&self) -> &Pose {
        &self.pose
    }

    /// `R_wc`, the camera's axes in world coordinates.
    pub fn rotation(&self) -> &Matrix3<f64> {
        &self.rotation
    }

    fn centre(&self) -> Vector3<f64> {
        Vector3::from(self.pose.position)
    }

    /// A world point in the camera's axes (x right, y down, z along the optical axis).
    pub fn to_camera(&self, world: [f64; 3]) -> [f64; 3] {
        let p = self.rotation.transpose() * (Vector3::from(world) - self.centre());
        [p[0], p[1], p[2]]
    }

    /// The pixel where a world point appears (lens distortion included), whether inside the
    /// image or not; `None` when it is not in front of the camera, or so far off its axis that
    /// the lens model no longer holds (beyond [`Distortion::valid_radius`]).
    pub fn pixel_of(&self, world: [f64; 3]) -> Option<[f64; 2]> {
        let [x, y, z] = self.to_camera(world);
        if z.is_nan() || z <= 0.0 {
            return None;
        }
        let (xn, yn) = (x / z, y / z);
        // Beyond the lens model's one-to-one radius a point would fold back into the image.
        if xn.hypot(yn) > self.lens_radius {
            return None;
        }
        let seen = self.distortion.distort([xn, yn]);
        let pixel = self.intrinsics.pixel(seen);
        (pixel[0].is_finite() && pixel[1].is_finite()).then_some(pixel)
    }

    /// Whether the camera sees a world point: in front of it and inside the image.
    pub fn sees(&self, world: [f64; 3]) -> bool {
        self.pixel_of(world).is_some_and(|p| self.intrinsics.contains(p))
    }

    /// The undistorted normalised image point `(x, y)` of a pixel (its ray is `(x, y, 1)` in the
    /// camera's axes).
    pub fn normalized(&self, pixel: [f64; 2]) -> Result<[f64; 2], GroundError> {
        if !(pixel[0].is_finite() && pixel[1].is_finite()) {
            return Err(GroundError::NotFinite);
        }
        self.distortion
            .undistort_within(self.intrinsics.normalized(pixel), self.lens_radius)
            .ok_or(GroundError::Undistort)
    }

    /// The direction of a pixel's ray in world coordinates (not normalised: `R_wc (x, y, 1)`).
    pub fn ray(&self, pixel: [f64; 2]) -> Result<[f64; 3], GroundError> {
        let [x, y] = self.normalized(pixel)?;
        let d = self.rotation * Vector3::new(x, y, 1.0);
        Ok([d[0], d[1], d[2]])
    }

    /// Where a pixel's ray meets the ground plane `z = ground_z`, in front of the camera.
    pub fn ground_point(&self, pixel: [f64; 2], ground_z: f64) -> Result<[f64; 2], GroundError> {
        let d = self.ray(pixel)?;
        self.meet_ground(d, ground_z).ok_or(GroundError::AboveHorizon)
    }

    /// Where the ray `d` from the camera's centre meets `z = ground_z`, if it does in front.
    fn meet_ground(&self, d: [f64; 3], ground_z: f64) -> Option<[f64; 2]> {
        let c = self.pose.position;
        let t = (ground_z - c[2]) / d[2];
        (t > 0.0 && t.is_finite()).then(|| [c[0] + t * d[0], c[1] + t * d[1]])
    }

    /// What the camera sees of the ground plane `z = ground_z`, within `max_range` metres
    /// (horizontally) of the camera: a polygon that follows the image's border clockwise in the
    /// image (top-left, top-right, bottom-right, bottom-left; several points per side when the
    /// lens distorts). Where the border is below the horizon its points are where their rays meet
    /// the ground (cut at `max_range` in their direction when farther); where the horizon crosses
    /// the border the ground goes on to the horizon, so the polygon goes out to `max_range` in
    /// the horizon's direction there and follows an arc at `max_range` along the horizon's part
    /// inside the image. Empty when the camera sees no ground.
    pub fn footprint(&self, ground_z: f64, max_range: f64) -> Vec<[f64; 2]> {
        let (w, h) = (self.intrinsics.width, self.intrinsics.height);
        let per_side = if self.distortion.is_none() { 1 } else { BORDER_POINTS_DISTORTED };
        let corners = [[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]];
        let mut border = Vec::with_capacity(4 * per_side);
        for side in 0..4 {
            let (a, b) = (corners[side], corners[(side + 1) % 4]);
            for k in 0..per_side {
                let u = k as f64 / per_side as f64;
                border.push([a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1])]);
            }
        }
        let below = |pixel: [f64; 2]| {
            self.ray(pixel).is_ok_and(|d| d[2] < 0.0 && (ground_z - self.pose.position[2]) < 0.0)
        };
        let n = border.len();
        let Some(start) = (0..n).find(|&i| below(border[i])) else { return Vec::new() };
        let mut polygon = Vec::new();
        let mut above_from: Option<[f64; 2]> = None;
        for k in 0..=n {
            let (i, j) = ((start + k) % n, (start + k + 1) % n);
            let (a, b) = (border[i], border[j]);
            if k == n {
                break;
            }
            if below(a)
                && let Some(p) = self.ground_within(a, ground_z, max_range)
            {
                polygon.push(p);
            }
            match (below(a), below(b)) {
                (true, false) => {
                    let crossing = self.horizon_crossing(a, b, &below);
                    polygon.extend(self.at_range(crossing, max_range));
                    above_from = Some(crossing);
                }
                (false, true) => {
                    let crossing = self.horizon_crossing(b, a, &below);
                    if let Some(from) = above_from.take() {
                        // The arc along the horizon's part inside the image.
                        for step in 1..HORIZON_ARC_POINTS {
                            let t = step as f64 / HORIZON_ARC_POINTS as f64;
                            let pixel = [
                                from[0] + t * (crossing[0] - from[0]),
                                from[1] + t * (crossing[1] - from[1]),
                            ];
                            polygon.extend(self.at_range(pixel, max_range));
                        }
                    }
                    polygon.extend(self.at_range(crossing, max_range));
                }
                _ => {}
            }
        }
        polygon
    }

    /// The last pixel below the horizon on the segment from `below_pixel` to `above_pixel`.
    fn horizon_crossing(
        &self,
        below_pixel: [f64; 2],
        above_pixel: [f64; 2],
        below: &impl Fn([f64; 2]) -> bool,
    ) -> [f64; 2] {
        let (mut lo, mut hi) = (0.0, 1.0);
        let at = |t: f64| {
            [
                below_pixel[0] + t * (above_pixel[0] - below_pixel[0]),
                below_pixel[1] + t * (above_pixel[1] - below_pixel[1]),
            ]
        };
        for _ in 0..60 {
            let mid = (lo + hi) / 2.0;
            if below(at(mid)) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        at(lo)
    }

    /// The point `max_range` metres from the camera in the horizontal direction of a pixel's ray.
    fn at_range(&self, pixel: [f64; 2], max_range: f64) -> Option<[f64; 2]> {
        let d = self.ray(pixel).ok()?;
        let horizontal = d[0].hypot(d[1]);
        let c = self.pose.position;
        (horizontal > 0.0)
            .then(|| [c[0] + max_range * d[0] / horizontal, c[1] + max_range * d[1] / horizontal])
    }

    /// Where a pixel's ray meets the ground, cut at `max_range` in its direction.
    fn ground_within(&self, pixel: [f64; 2], ground_z: f64, max_range: f64) -> Option<[f64; 2]> {
        let c = self.pose.position;
        match self.ground_point(pixel, ground_z) {
            Ok(g) if (g[0] - c[0]).hypot(g[1] - c[1]) <= max_range => Some(g),
            _ => self.at_range(pixel, max_range),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::{Attitude, Gimbal};

    fn nadir(at: [f64; 3]) -> Camera {
        let k = Intrinsics::new(500.0, 500.0, 500.0, 400.0, 1000.0, 800.0).unwrap();
        Camera::new(k, Distortion::default(), Pose::new(at, Attitude::level(0.0), Gimbal::nadir())).unwrap()
    }

    #[test]
    fn straight_down_from_100_m() {
        let camera = nadir([10.0, 20.0, 100.0]);
        // Image up is the nose (east), image right is south: f = 500 at 100 m is 5 px per metre.
        let g = camera.ground_point([500.0, 300.0], 0.0).unwrap();
        assert!((g[0] - 30.0).abs() < 1e-9 && (g[1] - 20.0).abs() < 1e-9, "{g:?}");
        let g = camera.ground_point([600.0, 400.0], 0.0).unwrap();
        assert!((g[0] - 10.0).abs() < 1e-9 && g[1].abs() < 1e-9, "{g:?}");
        // The footprint: 1000 x 800 px at 5 px/m is 200 m (north-south) by 160 m (east-west).
        let footprint = camera.footprint(0.0, 1e4);
        let expected = [[90.0, 120.0], [90.0, -80.0], [-70.0, -80.0], [-70.0, 120.0]];
        assert_eq!(footprint.len(), 4);
        for (p, e) in footprint.iter().zip(expected) {
            assert!((p[0] - e[0]).abs() < 1e-9 && (p[1] - e[1]).abs() < 1e-9, "{footprint:?}");
        }
        // A point on a raised ground plane is nearer: at z = 50, 5 px is half a metre.
        let g = camera.ground_point([505.0, 400.0], 50.0).unwrap();
        assert!((g[1] - 19.5).abs() < 1e-9, "{g:?}");
        assert!(camera.sees([10.0, 20.0, 0.0]) && !camera.sees([10.0, 200.0, 0.0]));
        assert!(camera.pixel_of([10.0, 20.0, 200.0]).is_none(), "above the camera is behind it");
    }

    #[test]
    fn an_oblique_view_has_a_horizon() {
        let k = Intrinsics::new(500.0, 500.0, 500.0, 400.0, 1000.0, 800.0).unwrap();
        // Looking east, 10° down, from 50 m: the top of the image is above the horizon.
        let pose =
            Pose::new([0.0, 0.0, 50.0], Attitude::level(0.0), Gimbal { pan: 0.0, tilt: 10f64.to_radians() });
        let camera = Camera::new(k, Distortion::default(), pose).unwrap();
        assert_eq!(camera.ground_point([500.0, 0.0], 0.0), Err(GroundError::AboveHorizon));
        // The centre ray: 50 m / tan 10° ahead.
        let g = camera.ground_point([500.0, 400.0], 0.0).unwrap();
        assert!((g[0] - 50.0 / 10f64.to_radians().tan()).abs() < 1e-6 && g[1].abs() < 1e-9);
        let footprint = camera.footprint(0.0, 1000.0);
        // Bottom corners on the ground, then up the left side to the horizon, the arc, and down
        // the right side: the horizon crosses both sides.
        assert_eq!(footprint.len(), 2 + 2 + HORIZON_ARC_POINTS - 1, "{footprint:?}");
        assert!(footprint[2..footprint.len() - 1].iter().all(|p| (p[0].hypot(p[1]) - 1000.0).abs() < 1e-6));
        // Looking up sees no ground.
        let up = Pose::new([0.0, 0.0, 50.0], Attitude::level(0.0), Gimbal { pan: 0.0, tilt: -1.0 });
        assert!(Camera::new(k, Distortion::default(), up).unwrap().footprint(0.0, 1000.0).is_empty());
    }

    #[test]
    fn refuses_a_pose_that_is_not_finite() {
        let k = Intrinsics::new(1.0, 1.0, 0.0, 0.0, 1.0, 1.0).unwrap();
        let pose = Pose::new([f64::NAN, 0.0, 0.0], Attitude::default(), Gimbal::default());
        assert_eq!(Camera::new(k, Distortion::default(), pose), Err(CameraError::Pose));
    }
}
