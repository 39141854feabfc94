//! A fixed camera calibrated from point pairs: the homography from image to ground estimated
//! from at least four pairs (a pixel and the ground point it shows), by the normalised direct
//! linear transform (Hartley and Zisserman, algorithm 4.2): both point sets moved to their
//! centroid and scaled to a mean distance of √2, `h` the eigenvector of `AᵀA` with the smallest
//! eigenvalue, then undone. The fit reports its residual on the ground (root mean square and
//! largest, metres) so a user sees a bad pair; a degenerate set (fewer than four pairs, three of
//! four on one line) is refused.
//!
//! ```
//! use kpl_camera::Homography;
//! // Four corners of a 10 m x 5 m rectangle seen as a trapezoid.
//! let pairs = [
//!     ([100.0, 400.0], [0.0, 0.0]), ([500.0, 400.0], [10.0, 0.0]),
//!     ([400.0, 100.0], [10.0, 5.0]), ([200.0, 100.0], [0.0, 5.0]),
//! ];
//! let fit = Homography::estimate(&pairs).unwrap();
//! assert!(fit.rms < 1e-9);
//! let g = fit.homography.apply([300.0, 400.0]).unwrap();
//! assert!((g[0] - 5.0).abs() < 1e-9 && g[1].abs() < 1e-9);
//! ```

use nalgebra::{Matrix2, Matrix3, SMatrix, SymmetricEigen, Vector3};

/// A plane-to-plane projective map, image to ground: `g ~ H (u, v, 1)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Homography {
    pub h: Matrix3<f64>,
}

/// A homography estimated from point pairs, with its residuals on the ground.
#[derive(Debug, Clone, PartialEq)]
pub struct Fit {
    pub homography: Homography,
    /// Root mean square of the pairs' ground distances from where the homography puts their
    /// pixels, metres.
    pub rms: f64,
    /// The largest of those distances, metres, and the index of its pair.
    pub max: f64,
    pub worst: usize,
    /// Each pair's distance, metres.
    pub residuals: Vec<f64>,
}

/// Why no homography could be estimated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HomographyError {
    #[error("a homography needs at least 4 point pairs, found {0}")]
    TooFewPairs(usize),
    #[error("point pair {0} is not four finite numbers")]
    NotFinite(usize),
    #[error("the point pairs do not fix a homography (three of four on one line, or points repeated)")]
    Degenerate,
}

/// A similarity that moves points to their centroid and scales them to a mean distance of √2.
fn normalizer(points: impl Iterator<Item = [f64; 2]> + Clone) -> Option<Matrix3<f64>> {
    let n = points.clone().count() as f64;
    let (sx, sy) = points.clone().fold((0.0, 0.0), |(x, y), p| (x + p[0], y + p[1]));
    let (cx, cy) = (sx / n, sy / n);
    let mean = points.map(|p| (p[0] - cx).hypot(p[1] - cy)).sum::<f64>() / n;
    if !(mean > 0.0 && mean.is_finite()) {
        return None;
    }
    let s = std::f64::consts::SQRT_2 / mean;
    Some(Matrix3::new(s, 0.0, -s * cx, 0.0, s, -s * cy, 0.0, 0.0, 1.0))
}

fn apply(h: &Matrix3<f64>, p: [f64; 2]) -> Option<[f64; 2]> {
    let q = h * Vector3::new(p[0], p[1], 1.0);
    let out = [q[0] / q[2], q[1] / q[2]];
    (q[2] != 0.0 && out[0].is_finite() && out[1].is_finite()).then_some(out)
}

/// Whether three points are (nearly) on one line, relative to their spread.
fn collinear(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> bool {
    let cross = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
    let scale =
        [(a, b), (b, c), (a, c)].iter().map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1])).fold(0.0, f64::max);
    cross.abs() <= 1e-9 * scale * scale
}

impl Homography {
    /// The homography that maps each pair's pixel to its ground point best (in the algebraic
    /// sense of the normalised DLT), with the residuals.
    pub fn estimate(pairs: &[([f64; 2], [f64; 2])]) -> Result<Fit, HomographyError> {
        if pairs.len() < 4 {
            return Err(HomographyError::TooFewPairs(pairs.len()));
        }
        if let Some(i) = pairs.iter().position(|(p, g)| !p.iter().chain(g).all(|v| v.is_finite())) {
            return Err(HomographyError::NotFinite(i));
        }
        if pairs.len() == 4 {
            for side in [0, 1] {
                let pts: Vec<[f64; 2]> = pairs.iter().map(|(p, g)| if side == 0 { *p } else { *g }).collect();
                for skip in 0..4 {
                    let three: Vec<[f64; 2]> = (0..4).filter(|&i| i != skip).map(|i| pts[i]).collect();
                    if collinear(three[0], three[1], three[2]) {
                        return Err(HomographyError::Degenerate);
                    }
                }
            }
        }
        let t_image = normalizer(pairs.iter().map(|(p, _)| *p)).ok_or(HomographyError::Degenerate)?;
        let t_ground = normalizer(pairs.iter().map(|(_, g)| *g)).ok_or(HomographyError::Degenerate)?;
        let mut ata = SMatrix::<f64, 9, 9>::zeros();
        for (p, g) in pairs {
            let p = t_image * Vector3::new(p[0], p[1], 1.0);
            let g = t_ground * Vector3::new(g[0], g[1], 1.0);
            let (x, y) = (p[0], p[1]);
            let (gx, gy) = (g[0], g[1]);
            let rows = [
                [-x, -y, -1.0, 0.0, 0.0, 0.0, gx * x, gx * y, gx],
                [0.0, 0.0, 0.0, -x, -y, -1.0, gy * x, gy * y, gy],
            ];
            for row in rows {
                let r = SMatrix::<f64, 9, 1>::from_row_slice(&row);
                ata += r * r.transpose();
            }
        }
        let eigen = SymmetricEigen::new(ata);
        let mut order: Vec<usize> = (0..9).collect();
        order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
        let (smallest, next) = (eigen.eigenvalues[order[0]], eigen.eigenvalues[order[1]]);
        let largest = eigen.eigenvalues[order[8]];
        // A unique answer needs a one-dimensional null space (up to noise).
        if next.is_nan() || next <= 1e-10 * largest || !smallest.is_finite() {
            return Err(HomographyError::Degenerate);
        }
        let v = eigen.eigenvectors.column(order[0]);
        let hn = Matrix3::new(v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8]);
        let back = t_ground.try_inverse().ok_or(HomographyError::Degenerate)?;
        let mut h = back * hn * t_image;
        let scale = h[(2, 2)];
        if scale.abs() > 1e-300 {
            h /= scale;
        }
        if h.determinant().abs() < 1e-300 || !h.iter().all(|v| v.is_finite()) {
            return Err(HomographyError::Degenerate);
        }
        let homography = Homography { h };
        let residuals: Vec<f64> = pairs
            .iter()
            .map(|(p, g)| homography.apply(*p).map_or(f64::INFINITY, |q| (q[0] - g[0]).hypot(q[1] - g[1])))
            .collect();
        let rms = (residuals.iter().map(|r| r * r).sum::<f64>() / residuals.len() as f64).sqrt();
        let (worst, max) = residuals
            .iter()
            .copied()
            .enumerate()
            .fold((0, 0.0), |best, (i, r)| if r > best.1 { (i, r) } else { best });
        if !rms.is_finite() {
            return Err(HomographyError::Degenerate);
        }
        Ok(Fit { homography, rms, max, worst, residuals })
    }

    /// The ground point of a pixel (`None` on the line the homography sends to infinity).
    pub fn apply(&self, pixel: [f64; 2]) -> Option<[f64; 2]> {
        apply(&self.h, pixel)
    }

    /// The inverse map, ground to image.
    pub fn inverse(&self) -> Option<Homography> {
        self.h.try_inverse().map(|h| Homography { h })
    }

    /// `∂g / ∂pixel` at a pixel.
    pub fn jacobian(&self, pixel: [f64; 2]) -> Option<Matrix2<f64>> {
        let q = self.h * Vector3::new(pixel[0], pixel[1], 1.0);
        if q[2] == 0.0 {
            return None;
        }
        let w2 = q[2] * q[2];
        let mut j = Matrix2::zeros();
        for col in 0..2 {
            for row in 0..2 {
                j[(row, col)] = (self.h[(row, col)] * q[2] - q[row] * self.h[(2, col)]) / w2;
            }
        }
        j.iter().all(|v| v.is_finite()).then_some(j)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use crate::distortion::Distortion;
    use crate::intrinsics::Intrinsics;
    use crate::pose::{Attitude, Gimbal, Pose};

    #[test]
    fn recovers_a_cameras_ground_homography() {
        // A camera on a 12 m mast looking north-east, 30° down: its ground-to-image map is a
        // homography; any four ground points and their pixels recover it.
        let k = Intrinsics::new(900.0, 900.0, 640.0, 360.0, 1280.0, 720.0).unwrap();
        let pose = Pose::new([0.0, 0.0, 12.0], Attitude::level(0.8), Gimbal { pan: 0.0, tilt: 0.5 });
        let camera = Camera::new(k, Distortion::default(), pose).unwrap();
        let grounds = [[20.0, 15.0], [35.0, 20.0], [25.0, 40.0], [12.0, 22.0], [30.0, 30.0], [18.0, 33.0]];
        let pairs: Vec<_> =
            grounds.iter().map(|g| (camera.pixel_of([g[0], g[1], 0.0]).unwrap(), *g)).collect();
        let fit = Homography::estimate(&pairs[..4]).unwrap();
        assert!(fit.rms < 1e-8 && fit.max < 1e-8, "{fit:?}");
        for (pixel, ground) in &pairs[4..] {
            let g = fit.homography.apply(*pixel).unwrap();
            assert!((g[0] - ground[0]).abs() < 1e-7 && (g[1] - ground[1]).abs() < 1e-7);
            let back = fit.homography.inverse().unwrap().apply(g).unwrap();
            assert!((back[0] - pixel[0]).abs() < 1e-6 && (back[1] - pixel[1]).abs() < 1e-6);
            // The Jacobian against finite differences.
            let j = fit.homography.jacobian(*pixel).unwrap();
            let h = 1e-4;
            let plus = fit.homography.apply([pixel[0] + h, pixel[1]]).unwrap();
            assert!(((plus[0] - g[0]) / h - j[(0, 0)]).abs() < 1e-6);
            assert!(((plus[1] - g[1]) / h - j[(1, 0)]).abs() < 1e-6);
        }
        // One wrong pair among six: the residual says so and names it.
        let mut bad = pairs.clone();
        bad[2].1[0] += 3.0;
        let fit = Homography::estimate(&bad).unwrap();
        assert!(fit.rms > 0.1 && fit.worst == 2, "{fit:?}");
    }

    #[test]
    fn degenerate_sets_are_refused() {
        let square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let line = [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [0.0, 1.0]];
        let pairs = |a: [[f64; 2]; 4], b: [[f64; 2]; 4]| -> Vec<_> { a.into_iter().zip(b).collect() };
        assert_eq!(Homography::estimate(&pairs(square, square)[..3]), Err(HomographyError::TooFewPairs(3)));
        assert_eq!(Homography::estimate(&pairs(line, square)), Err(HomographyError::Degenerate));
        assert_eq!(Homography::estimate(&pairs(square, line)), Err(HomographyError::Degenerate));
        let repeated = [[0.0, 0.0]; 4];
        assert_eq!(Homography::estimate(&pairs(repeated, square)), Err(HomographyError::Degenerate));
        let mut nan = pairs(square, square);
        nan[1].1[0] = f64::NAN;
        assert_eq!(Homography::estimate(&nan), Err(HomographyError::NotFinite(1)));
        let fit = Homography::estimate(&pairs(square, square)).unwrap();
        assert!((fit.homography.h - Matrix3::identity()).norm() < 1e-12);
    }
}
