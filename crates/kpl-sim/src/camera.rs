//! The UAV camera's footprint: the part of the ground it sees, a polygon (or a rectangle) that is
//! either fixed or carried along a path. Outside it nothing is detected. The path is a list of
//! waypoints `(seconds from the start, x, y)` for the footprint's centre, followed in straight
//! lines; before the first waypoint the camera is at the first, after the last at the last.
//!
//! ```
//! use kpl_sim::camera::Camera;
//! // A 200 m x 100 m view flying east at 10 m/s.
//! let camera = Camera::moving(Camera::rectangle(200.0, 100.0), vec![(0.0, [0.0, 0.0]), (10.0, [100.0, 0.0])]).unwrap();
//! assert!(camera.sees([90.0, 0.0], 0));
//! assert!(!camera.sees([-90.0, 0.0], 10_000_000)); // 10 s later the camera is 100 m further east
//! ```

use kpl_core::Time;
use kpl_roads::geom::{self, Point, bounds_of, point_in_polygon};

/// Where the camera looks.
#[derive(Debug, Clone, PartialEq)]
pub enum Camera {
    /// It sees the whole network.
    Everything,
    /// A fixed polygon in world coordinates.
    Fixed(Vec<Point>),
    /// A polygon given relative to the camera's centre, which follows waypoints
    /// `(microseconds from the start, centre)`.
    Moving { shape: Vec<Point>, path: Vec<(Time, Point)> },
}

/// A camera that cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CameraError {
    #[error("the camera footprint needs at least 3 corners with finite coordinates")]
    Footprint,
    #[error("the camera path needs waypoints [seconds, x, y] with finite numbers and increasing times")]
    Path,
}

impl Camera {
    /// A rectangle `width` by `height` metres centred on the origin, axis-aligned.
    pub fn rectangle(width: f64, height: f64) -> Vec<Point> {
        let (w, h) = (width / 2.0, height / 2.0);
        vec![[-w, -h], [w, -h], [w, h], [-w, h]]
    }

    /// A fixed footprint in world coordinates.
    pub fn fixed(polygon: Vec<Point>) -> Result<Camera, CameraError> {
        check_polygon(&polygon)?;
        Ok(Camera::Fixed(polygon))
    }

    /// A footprint of `shape` (relative to the centre) whose centre follows `path`: waypoints
    /// (seconds from the start, centre).
    pub fn moving(shape: Vec<Point>, path: Vec<(f64, Point)>) -> Result<Camera, CameraError> {
        check_polygon(&shape)?;
        if path.is_empty() {
            return Err(CameraError::Path);
        }
        let mut waypoints = Vec::with_capacity(path.len());
        for (seconds, centre) in path {
            let ok = seconds.is_finite()
                && seconds.abs() < 1e9
                && centre.iter().all(|c| c.is_finite())
                && waypoints
                    .last()
                    .is_none_or(|&(t, _): &(Time, Point)| ((seconds * 1e6).round() as Time) > t);
            if !ok {
                return Err(CameraError::Path);
            }
            waypoints.push(((seconds * 1e6).round() as Time, centre));
        }
        Ok(Camera::Moving { shape, path: waypoints })
    }

    /// The camera's centre `elapsed` microseconds after the start (`None` for a fixed footprint).
    pub fn centre_at(&self, elapsed: Time) -> Option<Point> {
        let Camera::Moving { path, .. } = self else { return None };
        let i = path.partition_point(|&(t, _)| t <= elapsed);
        Some(match (i.checked_sub(1).map(|j| path[j]), path.get(i)) {
            (Some((ta, a)), Some(&(tb, b))) => {
                let u = (elapsed - ta) as f64 / (tb - ta) as f64;
                geom::add(a, geom::scale(geom::sub(b, a), u))
            }
            (Some((_, a)), None) => a,
            (None, Some(&(_, b))) => b,
            (None, None) => [0.0, 0.0],
        })
    }

    /// The footprint in world coordinates `elapsed` microseconds after the start (`None`: the
    /// camera sees everything).
    pub fn footprint_at(&self, elapsed: Time) -> Option<Vec<Point>> {
        match self {
            Camera::Everything => None,
            Camera::Fixed(polygon) => Some(polygon.clone()),
            Camera::Moving { shape, .. } => {
                let centre = self.centre_at(elapsed).unwrap_or([0.0, 0.0]);
                Some(shape.iter().map(|&p| geom::add(p, centre)).collect())
            }
        }
    }

    /// Whether the camera sees `pos` `elapsed` microseconds after the start.
    pub fn sees(&self, pos: Point, elapsed: Time) -> bool {
        match self {
            Camera::Everything => true,
            Camera::Fixed(polygon) => point_in_polygon(pos, polygon),
            Camera::Moving { shape, .. } => {
                let centre = self.centre_at(elapsed).unwrap_or([0.0, 0.0]);
                point_in_polygon(geom::sub(pos, centre), shape)
            }
        }
    }

    /// The bounding box of the footprint at `elapsed`, if it has one.
    pub fn bounds_at(&self, elapsed: Time) -> Option<(Point, Point)> {
        self.footprint_at(elapsed).map(|polygon| bounds_of(&polygon))
    }
}

fn check_polygon(polygon: &[Point]) -> Result<(), CameraError> {
    if polygon.len() >= 3
        && polygon
            .iter()
            .all(|p| p[0].is_finite() && p[1].is_finite() && p[0].abs() < 1e7 && p[1].abs() < 1e7)
    {
        Ok(())
    } else {
        Err(CameraError::Footprint)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, reason = "tests")]
    use super::*;

    #[test]
    fn fixed_and_moving_footprints() {
        let fixed = Camera::fixed(vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]]).unwrap();
        assert!(fixed.sees([5.0, 5.0], 0) && fixed.sees([5.0, 5.0], 1_000_000_000));
        assert!(!fixed.sees([15.0, 5.0], 0));
        assert!(Camera::Everything.sees([1e6, -1e6], 0));
        let path = vec![(1.0, [0.0, 0.0]), (3.0, [20.0, 0.0]), (4.0, [20.0, 10.0])];
        let moving = Camera::moving(Camera::rectangle(4.0, 2.0), path).unwrap();
        assert_eq!(moving.centre_at(0), Some([0.0, 0.0]), "at the first waypoint before it");
        assert_eq!(moving.centre_at(2_000_000), Some([10.0, 0.0]));
        assert_eq!(moving.centre_at(3_500_000), Some([20.0, 5.0]));
        assert_eq!(moving.centre_at(99_000_000), Some([20.0, 10.0]), "at the last waypoint after it");
        assert!(moving.sees([11.9, 0.9], 2_000_000));
        assert!(!moving.sees([12.1, 0.0], 2_000_000));
        assert_eq!(moving.bounds_at(2_000_000), Some(([8.0, -1.0], [12.0, 1.0])));
        assert_eq!(Camera::fixed(vec![[0.0, 0.0], [1.0, 1.0]]), Err(CameraError::Footprint));
        assert_eq!(Camera::moving(Camera::rectangle(1.0, 1.0), vec![]), Err(CameraError::Path));
        let backwards = vec![(2.0, [0.0, 0.0]), (1.0, [1.0, 0.0])];
        assert_eq!(Camera::moving(Camera::rectangle(1.0, 1.0), backwards), Err(CameraError::Path));
    }
}
