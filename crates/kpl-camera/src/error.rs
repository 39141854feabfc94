//! Why a camera, a homography or a ground point cannot be had.

/// A camera model that cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CameraError {
    #[error("intrinsics: {0}")]
    Intrinsics(&'static str),
    #[error("distortion: at most five finite coefficients (k1, k2, p1, p2, k3)")]
    Distortion,
    #[error("pose: every coordinate and angle must be a finite number")]
    Pose,
}

/// Why a pixel has no point on the ground.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum GroundError {
    #[error("the pixel's ray does not reach the ground in front of the camera (at or above the horizon)")]
    AboveHorizon,
    #[error("the lens model cannot be undone at this pixel (beyond where the distortion is one-to-one)")]
    Undistort,
    #[error("the pixel is not a pair of finite numbers")]
    NotFinite,
}
