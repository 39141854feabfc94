//! A pinhole camera's intrinsics: focal lengths and principal point in pixels, and the image's
//! size. Pixel coordinates follow OpenCV: `u` to the right, `v` down, the centre of the top-left
//! pixel at (0, 0); a point `(x, y, z)` in the camera frame (x right, y down, z along the optical
//! axis) is at `(fx x / z + cx, fy y / z + cy)` before lens distortion.
//!
//! ```
//! use kpl_camera::Intrinsics;
//! // 1920 x 1080 pixels, 90 degrees horizontal field of view.
//! let k = Intrinsics::from_fov(1920.0, 1080.0, 90f64.to_radians()).unwrap();
//! assert!((k.fx - 960.0).abs() < 1e-9 && k.cx == 960.0 && k.cy == 540.0);
//! let n = k.normalized([1920.0, 540.0]);
//! assert!((n[0] - 1.0).abs() < 1e-12 && n[1] == 0.0);
//! ```

use crate::error::CameraError;

/// Focal lengths `fx`, `fy` and principal point `cx`, `cy` in pixels; the image is `width` by
/// `height` pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub width: f64,
    pub height: f64,
}

/// The largest image side accepted, pixels.
const MAX_SIDE_PX: f64 = 1e6;

impl Intrinsics {
    /// Intrinsics from their values; refused unless every number is finite, the focal lengths
    /// and the image's sides are positive (sides at most a million pixels).
    pub fn new(
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        width: f64,
        height: f64,
    ) -> Result<Intrinsics, CameraError> {
        let all = [fx, fy, cx, cy, width, height];
        if !all.iter().all(|v| v.is_finite()) {
            return Err(CameraError::Intrinsics("every value must be a finite number"));
        }
        if fx <= 0.0 || fy <= 0.0 {
            return Err(CameraError::Intrinsics("the focal lengths must be above 0"));
        }
        if !(width > 0.0 && height > 0.0 && width <= MAX_SIDE_PX && height <= MAX_SIDE_PX) {
            return Err(CameraError::Intrinsics(
                "the image's sides must be above 0 and at most 1000000 pixels",
            ));
        }
        Ok(Intrinsics { fx, fy, cx, cy, width, height })
    }

    /// Square pixels, the principal point at the image's centre, and the horizontal field of
    /// view `hfov` (radians, between 0 and π).
    pub fn from_fov(width: f64, height: f64, hfov: f64) -> Result<Intrinsics, CameraError> {
        if !(hfov.is_finite() && hfov > 0.0 && hfov < std::f64::consts::PI) {
            return Err(CameraError::Intrinsics("the field of view must be between 0 and 180 degrees"));
        }
        let f = width / 2.0 / (hfov / 2.0).tan();
        Intrinsics::new(f, f, width / 2.0, height / 2.0, width, height)
    }

    /// The horizontal field of view, radians.
    pub fn hfov(&self) -> f64 {
        2.0 * (self.width / 2.0 / self.fx).atan()
    }

    /// The point on the normalised image plane (z = 1) of a pixel, before undistortion.
    pub fn normalized(&self, pixel: [f64; 2]) -> [f64; 2] {
        [(pixel[0] - self.cx) / self.fx, (pixel[1] - self.cy) / self.fy]
    }

    /// The pixel of a point on the normalised image plane.
    pub fn pixel(&self, normalized: [f64; 2]) -> [f64; 2] {
        [self.fx * normalized[0] + self.cx, self.fy * normalized[1] + self.cy]
    }

    /// Whether a pixel lies in the image: `0 <= u <= width` and `0 <= v <= height`.
    pub fn contains(&self, pixel: [f64; 2]) -> bool {
        (0.0..=self.width).contains(&pixel[0]) && (0.0..=self.height).contains(&pixel[1])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_of_view_and_refusals() {
        let k = Intrinsics::from_fov(640.0, 480.0, 60f64.to_radians()).unwrap();
        assert!((k.hfov() - 60f64.to_radians()).abs() < 1e-12);
        // tan(30°) = 1/√3: f = 320 √3.
        assert!((k.fx - 320.0 * 3f64.sqrt()).abs() < 1e-9);
        assert_eq!(k.pixel(k.normalized([10.0, 20.0])), [10.0, 20.0]);
        assert!(k.contains([0.0, 480.0]) && !k.contains([-0.1, 0.0]) && !k.contains([0.0, 480.5]));
        assert!(Intrinsics::new(0.0, 1.0, 0.0, 0.0, 10.0, 10.0).is_err());
        assert!(Intrinsics::new(1.0, 1.0, f64::NAN, 0.0, 10.0, 10.0).is_err());
        assert!(Intrinsics::new(1.0, 1.0, 0.0, 0.0, 0.0, 10.0).is_err());
        assert!(Intrinsics::from_fov(10.0, 10.0, 0.0).is_err());
        assert!(Intrinsics::from_fov(10.0, 10.0, std::f64::consts::PI).is_err());
    }
}
