//! Plane geometry on `[f64; 2]` points in metres: vector arithmetic, polylines with arc-length
//! parameterisation and projection, lateral offsetting, Bézier connectors and polygon tests.
//!
//! Headings are radians, counter-clockwise from the +x axis (east = 0, north = pi/2).

/// A point or vector in the plane, in metres.
pub type Point = [f64; 2];

pub fn add(a: Point, b: Point) -> Point {
    [a[0] + b[0], a[1] + b[1]]
}

pub fn sub(a: Point, b: Point) -> Point {
    [a[0] - b[0], a[1] - b[1]]
}

pub fn scale(a: Point, k: f64) -> Point {
    [a[0] * k, a[1] * k]
}

pub fn dot(a: Point, b: Point) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// The z component of the 3-d cross product: positive when `b` is to the left of `a`.
pub fn cross(a: Point, b: Point) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

pub fn norm(a: Point) -> f64 {
    a[0].hypot(a[1])
}

pub fn dist(a: Point, b: Point) -> f64 {
    norm(sub(a, b))
}

/// The unit vector of a heading.
pub fn unit(heading: f64) -> Point {
    [heading.cos(), heading.sin()]
}

/// The heading of a non-zero vector.
pub fn heading_of(v: Point) -> f64 {
    v[1].atan2(v[0])
}

/// The vector rotated a quarter turn counter-clockwise (to the left of `v`).
pub fn left_normal(v: Point) -> Point {
    [-v[1], v[0]]
}

/// The absolute difference of two headings, in `[0, pi]`.
pub fn heading_difference(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    if d > std::f64::consts::PI { std::f64::consts::TAU - d } else { d }
}

/// The closest point to `p` on the segment `a`-`b`, as the fraction along it in `[0, 1]`.
pub fn project_on_segment(p: Point, a: Point, b: Point) -> f64 {
    let ab = sub(b, a);
    let len2 = dot(ab, ab);
    if len2 <= 0.0 { 0.0 } else { (dot(sub(p, a), ab) / len2).clamp(0.0, 1.0) }
}

/// The distance from `p` to the segment `a`-`b`.
pub fn dist_to_segment(p: Point, a: Point, b: Point) -> f64 {
    let t = project_on_segment(p, a, b);
    dist(p, add(a, scale(sub(b, a), t)))
}

/// Whether `dist_to_segment(p, a, b) <= r`, with the same answer, computing the exact distance
/// (a `hypot`) only when the squared distance is too near `r * r` to tell.
pub fn within_segment(p: Point, a: Point, b: Point, r: f64) -> bool {
    if r.is_nan() || r < 0.0 {
        return dist_to_segment(p, a, b) <= r;
    }
    let d2 = dist2_to_segment(p, a, b);
    let r2 = r * r;
    if d2 > r2 * (1.0 + 1e-9) + 1e-300 {
        false
    } else if d2 < r2 * (1.0 - 1e-9) {
        true
    } else {
        dist_to_segment(p, a, b) <= r
    }
}

/// The squared distance from `p` to the segment `a`-`b` (no `hypot`: for comparisons that can
/// afford its rounding, which is about that of one ulp of the distance).
pub fn dist2_to_segment(p: Point, a: Point, b: Point) -> f64 {
    let t = project_on_segment(p, a, b);
    let d = sub(p, add(a, scale(sub(b, a), t)));
    dot(d, d)
}

/// Where a point projects onto a polyline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    /// Arc length from the polyline's start to the projected point.
    pub offset: f64,
    /// The projected point.
    pub point: Point,
    /// Signed distance of the query point from the polyline: positive to the left.
    pub lateral: f64,
    /// The index of the segment the point projects onto.
    pub segment: usize,
}

/// An open polyline with at least two points and positive length, with cumulative arc lengths.
#[derive(Debug, Clone, PartialEq)]
pub struct Polyline {
    points: Vec<Point>,
    /// `cumulative[i]` is the arc length from `points[0]` to `points[i]`.
    cumulative: Vec<f64>,
}

impl Polyline {
    /// Builds a polyline, dropping consecutive duplicate points. `None` when fewer than two
    /// distinct points remain or a coordinate is not finite.
    pub fn new(points: Vec<Point>) -> Option<Polyline> {
        let mut kept: Vec<Point> = Vec::with_capacity(points.len());
        for p in points {
            if !(p[0].is_finite() && p[1].is_finite()) {
                return None;
            }
            if kept.last().is_none_or(|&q| dist(p, q) > 1e-9) {
                kept.push(p);
            }
        }
        if kept.len() < 2 {
            return None;
        }
        let mut cumulative = Vec::with_capacity(kept.len());
        let mut total = 0.0;
        cumulative.push(0.0);
        for w in kept.windows(2) {
            total += dist(w[0], w[1]);
            cumulative.push(total);
        }
        Some(Polyline { points: kept, cumulative })
    }

    pub fn points(&self) -> &[Point] {
        &self.points
    }

    pub fn length(&self) -> f64 {
        self.cumulative.last().copied().unwrap_or(0.0)
    }

    pub fn n_segments(&self) -> usize {
        self.points.len() - 1
    }

    /// The segment `i` as its two end points and the arc length at its start.
    pub fn segment(&self, i: usize) -> (Point, Point, f64) {
        (self.points[i], self.points[i + 1], self.cumulative[i])
    }

    fn segment_at(&self, offset: f64) -> usize {
        // The last segment whose start is at or before `offset`.
        let i = self.cumulative.partition_point(|&c| c <= offset);
        i.saturating_sub(1).min(self.n_segments() - 1)
    }

    /// The point at arc length `offset`, clamped to the polyline.
    pub fn point_at(&self, offset: f64) -> Point {
        let offset = offset.clamp(0.0, self.length());
        let i = self.segment_at(offset);
        let (a, b, start) = self.segment(i);
        let len = self.cumulative[i + 1] - start;
        let t = if len > 0.0 { (offset - start) / len } else { 0.0 };
        add(a, scale(sub(b, a), t))
    }

    /// The heading of the segment at arc length `offset`, clamped to the polyline.
    pub fn heading_at(&self, offset: f64) -> f64 {
        let i = self.segment_at(offset.clamp(0.0, self.length()));
        let (a, b, _) = self.segment(i);
        heading_of(sub(b, a))
    }

    pub fn start_heading(&self) -> f64 {
        self.heading_at(0.0)
    }

    pub fn end_heading(&self) -> f64 {
        let (a, b, _) = self.segment(self.n_segments() - 1);
        heading_of(sub(b, a))
    }

    pub fn start(&self) -> Point {
        self.points[0]
    }

    pub fn end(&self) -> Point {
        self.points[self.points.len() - 1]
    }

    /// Projects `p` onto segment `i`.
    pub fn project_on(&self, p: Point, i: usize) -> Projection {
        let (a, b, start) = self.segment(i);
        let t = project_on_segment(p, a, b);
        let ab = sub(b, a);
        let point = add(a, scale(ab, t));
        let d = dist(p, point);
        let side = cross(ab, sub(p, a));
        let lateral = if side < 0.0 { -d } else { d };
        Projection { offset: start + t * norm(ab), point, lateral, segment: i }
    }

    /// Projects `p` onto the nearest point of the whole polyline (linear in its segments).
    pub fn project(&self, p: Point) -> Projection {
        let mut best = self.project_on(p, 0);
        for i in 1..self.n_segments() {
            let candidate = self.project_on(p, i);
            if candidate.lateral.abs() < best.lateral.abs() {
                best = candidate;
            }
        }
        best
    }

    /// The part between arc lengths `from` and `to` (clamped; `None` when shorter than 1 mm).
    pub fn slice(&self, from: f64, to: f64) -> Option<Polyline> {
        let from = from.clamp(0.0, self.length());
        let to = to.clamp(0.0, self.length());
        if to - from < 1e-3 {
            return None;
        }
        let mut points = vec![self.point_at(from)];
        for (i, &c) in self.cumulative.iter().enumerate() {
            if c > from && c < to {
                points.push(self.points[i]);
            }
        }
        points.push(self.point_at(to));
        Polyline::new(points)
    }

    /// The same points in the opposite order.
    pub fn reversed(&self) -> Polyline {
        let mut points = self.points.clone();
        points.reverse();
        let total = self.length();
        let cumulative = self.cumulative.iter().rev().map(|c| total - c).collect();
        Polyline { points, cumulative }
    }

    /// The polyline shifted sideways by `lateral` metres (positive to the left), with mitred
    /// joints; the miter is limited so that sharp bends do not shoot out.
    pub fn offset(&self, lateral: f64) -> Option<Polyline> {
        if lateral == 0.0 {
            return Some(self.clone());
        }
        let n = self.points.len();
        let directions: Vec<Point> = self
            .points
            .windows(2)
            .map(|w| {
                let d = sub(w[1], w[0]);
                scale(d, 1.0 / norm(d))
            })
            .collect();
        let mut shifted = Vec::with_capacity(n);
        for i in 0..n {
            let normal = if i == 0 {
                left_normal(directions[0])
            } else if i == n - 1 {
                left_normal(directions[n - 2])
            } else {
                let a = left_normal(directions[i - 1]);
                let b = left_normal(directions[i]);
                let sum = add(a, b);
                let len = norm(sum);
                if len < 1e-6 {
                    a
                } else {
                    // The miter: along the bisector, long enough to keep both sides parallel.
                    let bisector = scale(sum, 1.0 / len);
                    let cos_half = dot(bisector, a).max(0.25);
                    scale(bisector, 1.0 / cos_half)
                }
            };
            shifted.push(add(self.points[i], scale(normal, lateral)));
        }
        Polyline::new(shifted)
    }

    /// The axis-aligned bounding box as `(min, max)`.
    pub fn bounds(&self) -> (Point, Point) {
        bounds_of(&self.points)
    }
}

/// The bounding box of non-empty points as `(min, max)`.
pub fn bounds_of(points: &[Point]) -> (Point, Point) {
    let mut lo = [f64::INFINITY, f64::INFINITY];
    let mut hi = [f64::NEG_INFINITY, f64::NEG_INFINITY];
    for p in points {
        lo = [lo[0].min(p[0]), lo[1].min(p[1])];
        hi = [hi[0].max(p[0]), hi[1].max(p[1])];
    }
    (lo, hi)
}

/// A cubic Bézier from `p0` leaving with `heading0` to `p3` arriving with `heading3`, sampled into
/// a polyline. The handles are 0.39 of the chord, which traces a near-circular arc for a right
/// angle turn and a straight line when the ends are aligned.
pub fn connector_curve(p0: Point, heading0: f64, p3: Point, heading3: f64) -> Option<Polyline> {
    let chord = dist(p0, p3);
    let handle = 0.39 * chord;
    let p1 = add(p0, scale(unit(heading0), handle));
    let p2 = sub(p3, scale(unit(heading3), handle));
    let n = ((chord / 1.0).ceil() as usize).clamp(4, 24);
    let points = (0..=n)
        .map(|k| {
            let t = k as f64 / n as f64;
            let u = 1.0 - t;
            let w = [u * u * u, 3.0 * u * u * t, 3.0 * u * t * t, t * t * t];
            [
                w[0] * p0[0] + w[1] * p1[0] + w[2] * p2[0] + w[3] * p3[0],
                w[0] * p0[1] + w[1] * p1[1] + w[2] * p2[1] + w[3] * p3[1],
            ]
        })
        .collect();
    Polyline::new(points)
}

/// The convex hull of points, counter-clockwise, without collinear points (Andrew's monotone chain).
pub fn convex_hull(points: &[Point]) -> Vec<Point> {
    let mut pts: Vec<Point> = points.to_vec();
    pts.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    pts.dedup_by(|a, b| dist(*a, *b) < 1e-9);
    if pts.len() < 3 {
        return pts;
    }
    let mut hull: Vec<Point> = Vec::with_capacity(pts.len() * 2);
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &Point>> =
            if pass == 0 { Box::new(pts.iter()) } else { Box::new(pts.iter().rev()) };
        for &p in iter {
            while hull.len() >= start + 2
                && cross(sub(hull[hull.len() - 1], hull[hull.len() - 2]), sub(p, hull[hull.len() - 2])) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

/// Whether `p` lies inside (or on the border of) a polygon, by the even-odd rule.
pub fn point_in_polygon(p: Point, polygon: &[Point]) -> bool {
    let n = polygon.len();
    if n < 3 {
        return false;
    }
    let mut inside = false;
    let mut j = n - 1;
    for i in 0..n {
        let (a, b) = (polygon[i], polygon[j]);
        if dist_to_segment(p, a, b) < 1e-9 {
            return true;
        }
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                inside = !inside;
            }
        }
        j = i;
    }
    inside
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, reason = "tests")]
    use super::*;

    proptest::proptest! {
        /// The shortcut through the squared distance answers as the exact distance does, also
        /// for radii at the distance itself and a rounding away from it.
        #[test]
        fn within_segment_agrees_with_the_exact_distance(
            p in proptest::array::uniform2(-1e4f64..1e4),
            a in proptest::array::uniform2(-1e4f64..1e4),
            b in proptest::array::uniform2(-1e4f64..1e4),
            r in 0.0f64..2e4,
        ) {
            let d = dist_to_segment(p, a, b);
            for r in [r, d, d.next_up(), d.next_down(), d * (1.0 + 1e-12), d * (1.0 - 1e-12), 0.0] {
                proptest::prop_assert_eq!(within_segment(p, a, b, r), d <= r, "r = {}", r);
            }
            let d2 = dist2_to_segment(p, a, b);
            proptest::prop_assert!((d2.sqrt() - d).abs() <= 4.0 * f64::EPSILON * d.max(f64::MIN_POSITIVE));
        }
    }

    #[test]
    fn polyline_arc_length_and_projection() {
        let line = Polyline::new(vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]]).unwrap();
        assert_eq!(line.length(), 20.0);
        assert_eq!(line.point_at(15.0), [10.0, 5.0]);
        assert_eq!(line.point_at(-3.0), [0.0, 0.0]);
        let p = line.project([4.0, 2.0]);
        assert_eq!(p.offset, 4.0);
        assert_eq!(p.lateral, 2.0);
        let p = line.project([12.0, 6.0]);
        assert_eq!(p.offset, 16.0);
        assert_eq!(p.lateral, -2.0, "right of the northbound segment");
    }

    #[test]
    fn offsetting_keeps_sides_parallel() {
        let line = Polyline::new(vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]]).unwrap();
        let left = line.offset(1.0).unwrap();
        assert_eq!(left.points(), &[[0.0, 1.0], [9.0, 1.0], [9.0, 10.0]]);
        let back = left.reversed();
        assert_eq!(back.start(), [9.0, 10.0]);
        assert!((back.length() - left.length()).abs() < 1e-12);
    }

    #[test]
    fn hull_and_polygon() {
        let hull = convex_hull(&[[0.0, 0.0], [2.0, 0.0], [1.0, 1.0], [2.0, 2.0], [0.0, 2.0], [1.0, 0.0]]);
        assert_eq!(hull.len(), 4);
        assert!(point_in_polygon([1.0, 1.0], &hull));
        assert!(point_in_polygon([2.0, 1.0], &hull), "border counts as inside");
        assert!(!point_in_polygon([2.1, 1.0], &hull));
    }

    #[test]
    fn right_angle_connector_is_near_circular() {
        let curve = connector_curve([0.0, 0.0], 0.0, [5.0, 5.0], std::f64::consts::FRAC_PI_2).unwrap();
        // A quarter circle of radius 5 centred at (0, 5): the midpoint is close to radius 5.
        let mid = curve.point_at(curve.length() / 2.0);
        assert!((dist(mid, [0.0, 5.0]) - 5.0).abs() < 0.1, "{mid:?}");
        assert!((curve.length() - 5.0 * std::f64::consts::FRAC_PI_2).abs() < 0.1);
    }

    #[test]
    fn heading_differences_wrap() {
        assert!((heading_difference(0.1, std::f64::consts::TAU - 0.1) - 0.2).abs() < 1e-12);
        assert!((heading_difference(0.0, std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
    }
}
