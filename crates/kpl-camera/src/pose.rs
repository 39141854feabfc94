//! Where a camera is and where it looks: the platform's position and attitude (a UAV, or a mast
//! for a fixed camera) and a gimbal or pan-tilt unit on it.
//!
//! Conventions (the project's: x east, y north, z up, metres; headings counter-clockwise from
//! east):
//! - **Platform** (body axes forward, left, up): `yaw` is the heading of its nose
//!   (counter-clockwise from east), `pitch` raises the nose, `roll` lowers the right side. Body to
//!   world: `R_wb = Rz(yaw) · Ry(-pitch) · Rx(roll)`.
//! - **Gimbal** (the same axes, forward along the optical axis): `pan` turns the camera to the left
//!   of the nose, `tilt` lowers it below the platform's horizon (π/2 looks straight down). Gimbal
//!   to body: `R_bg = Rz(pan) · Ry(tilt)`.
//! - **Camera** (OpenCV's axes: x right, y down, z along the optical axis): `R_gc` maps them to
//!   the gimbal's (z forward, x to the right = -left, y down = -up).
//!
//! The camera's rotation to world is `R_wc = R_wb · R_bg · R_gc`; a world point `X` is at
//! `R_wcᵀ (X - C)` in the camera's axes, `C` the camera's centre. [`Pose::rotation_derivatives`]
//! gives `∂R_wc / ∂θ` for each angle, which the uncertainty propagation needs.
//!
//! ```
//! use kpl_camera::{Attitude, Gimbal, Pose};
//! // Hovering at 100 m, nose east, camera straight down.
//! let pose = Pose::new([0.0, 0.0, 100.0], Attitude::level(0.0), Gimbal::nadir());
//! let r = pose.rotation();
//! // The optical axis (camera z) points down; the image's right (camera x) points south.
//! assert!((r[(2, 2)] + 1.0).abs() < 1e-12 && (r[(1, 0)] + 1.0).abs() < 1e-12);
//! ```

use nalgebra::{Matrix3, Vector3};

/// The platform's attitude, radians.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Attitude {
    /// Lowers the right side.
    pub roll: f64,
    /// Raises the nose.
    pub pitch: f64,
    /// The nose's heading, counter-clockwise from east.
    pub yaw: f64,
}

impl Attitude {
    /// Level flight with the nose at `yaw`.
    pub fn level(yaw: f64) -> Attitude {
        Attitude { roll: 0.0, pitch: 0.0, yaw }
    }
}

/// The gimbal's (or pan-tilt unit's) angles relative to the platform, radians.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Gimbal {
    /// Turns the camera to the left of the nose.
    pub pan: f64,
    /// Lowers the camera below the platform's horizon (π/2: straight down).
    pub tilt: f64,
}

impl Gimbal {
    /// Straight down.
    pub fn nadir() -> Gimbal {
        Gimbal { pan: 0.0, tilt: std::f64::consts::FRAC_PI_2 }
    }
}

/// A camera's pose: its centre in the world (metres) and its orientation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub position: [f64; 3],
    pub attitude: Attitude,
    pub gimbal: Gimbal,
}

/// The angles of a pose in the order the derivatives and noise use: roll, pitch, yaw, pan, tilt.
pub const ANGLES: [&str; 5] = ["roll", "pitch", "yaw", "pan", "tilt"];

fn rx(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}

fn ry(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

fn rz(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

/// The cross-product matrix of a unit axis: `d/da R(a) = R(a) · [axis]×`.
fn generator(axis: usize) -> Matrix3<f64> {
    let mut e = Vector3::zeros();
    e[axis] = 1.0;
    e.cross_matrix()
}

/// OpenCV's camera axes in the gimbal's (forward, left, up): x → -left, y → -up, z → forward.
fn camera_in_gimbal() -> Matrix3<f64> {
    Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0)
}

impl Pose {
    pub fn new(position: [f64; 3], attitude: Attitude, gimbal: Gimbal) -> Pose {
        Pose { position, attitude, gimbal }
    }

    /// Whether every number is finite.
    pub fn is_finite(&self) -> bool {
        let a = self.attitude;
        self.position.iter().all(|v| v.is_finite())
            && [a.roll, a.pitch, a.yaw, self.gimbal.pan, self.gimbal.tilt].iter().all(|v| v.is_finite())
    }

    /// The camera's rotation to world, `R_wc` (its columns are the camera's x, y and z axes in
    /// world coordinates).
    pub fn rotation(&self) -> Matrix3<f64> {
        let a = self.attitude;
        let g = self.gimbal;
        rz(a.yaw) * ry(-a.pitch) * rx(a.roll) * rz(g.pan) * ry(g.tilt) * camera_in_gimbal()
    }

    /// `∂R_wc / ∂θ` for θ = roll, pitch, yaw, pan, tilt ([`ANGLES`]).
    pub fn rotation_derivatives(&self) -> [Matrix3<f64>; 5] {
        let a = self.attitude;
        let g = self.gimbal;
        let (yaw, pitch, roll) = (rz(a.yaw), ry(-a.pitch), rx(a.roll));
        let (pan, tilt, cam) = (rz(g.pan), ry(g.tilt), camera_in_gimbal());
        let (gx, gy, gz) = (generator(0), generator(1), generator(2));
        [
            yaw * pitch * roll * gx * pan * tilt * cam,
            // Ry(-pitch)' with respect to pitch is -Ry(-pitch) [e_y]×.
            -(yaw * pitch * gy * roll * pan * tilt * cam),
            yaw * gz * pitch * roll * pan * tilt * cam,
            yaw * pitch * roll * pan * gz * tilt * cam,
            yaw * pitch * roll * pan * tilt * gy * cam,
        ]
    }

    /// The direction the camera looks in (its optical axis), in world coordinates.
    pub fn optical_axis(&self) -> [f64; 3] {
        let z = self.rotation().column(2).into_owned();
        [z[0], z[1], z[2]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn angles(pose: &mut Pose, i: usize) -> &mut f64 {
        match i {
            0 => &mut pose.attitude.roll,
            1 => &mut pose.attitude.pitch,
            2 => &mut pose.attitude.yaw,
            3 => &mut pose.gimbal.pan,
            _ => &mut pose.gimbal.tilt,
        }
    }

    #[test]
    fn hand_worked_orientations() {
        // Nose north, camera forward and level: the optical axis points north, image right east.
        let pose = Pose::new([0.0; 3], Attitude::level(std::f64::consts::FRAC_PI_2), Gimbal::default());
        let r = pose.rotation();
        assert!((r.column(2) - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-12);
        assert!((r.column(0) - Vector3::new(1.0, 0.0, 0.0)).norm() < 1e-12);
        assert!((r.column(1) - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-12, "image down is down");
        // Tilted 30° down: the axis drops by sin 30°.
        let tilted = Pose::new([0.0; 3], Attitude::level(0.0), Gimbal { pan: 0.0, tilt: 30f64.to_radians() });
        let axis = tilted.optical_axis();
        assert!((axis[0] - 30f64.to_radians().cos()).abs() < 1e-12 && (axis[2] + 0.5).abs() < 1e-12);
        // Nose up by 10° lifts a level camera's axis by 10°; rolling right turns the image's right down.
        let up = Pose::new(
            [0.0; 3],
            Attitude { pitch: 10f64.to_radians(), ..Attitude::level(0.0) },
            Gimbal::default(),
        );
        assert!((up.optical_axis()[2] - 10f64.to_radians().sin()).abs() < 1e-12);
        let rolled = Pose::new([0.0; 3], Attitude { roll: 0.1, ..Attitude::level(0.0) }, Gimbal::default());
        assert!(rolled.rotation()[(2, 0)] < 0.0, "the image's right goes down");
        // Panning left by 90° from a nose east looks north.
        let panned =
            Pose::new([0.0; 3], Attitude::level(0.0), Gimbal { pan: std::f64::consts::FRAC_PI_2, tilt: 0.0 });
        assert!((panned.optical_axis()[1] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn rotations_are_orthonormal_and_derivatives_match_differences() {
        let mut pose = Pose::new(
            [1.0, 2.0, 3.0],
            Attitude { roll: 0.05, pitch: -0.08, yaw: 1.2 },
            Gimbal { pan: 0.3, tilt: 1.1 },
        );
        let r = pose.rotation();
        assert!((r.transpose() * r - Matrix3::identity()).norm() < 1e-12);
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        let derivatives = pose.rotation_derivatives();
        for (i, derivative) in derivatives.iter().enumerate() {
            let h = 1e-6;
            let mut plus = pose;
            *angles(&mut plus, i) += h;
            let mut minus = pose;
            *angles(&mut minus, i) -= h;
            let numeric = (plus.rotation() - minus.rotation()) / (2.0 * h);
            assert!((numeric - derivative).norm() < 1e-8, "{}", ANGLES[i]);
        }
        *angles(&mut pose, 0) = f64::NAN;
        assert!(!pose.is_finite());
    }
}
