//! Rendering a simulated frame to boxes: CLEVR's pinhole camera at 320x240, each object's silhouette
//! as the convex hull of its projected outline, the ground-truth box as OPNet's fork of CATER's
//! renderer writes it (the bounds of the whole object's projection clamped to the image, rounded as
//! Python rounds, `[x, y, w, h]`), and depth-ordered occlusion: sample points of an object's
//! silhouette are hidden by any nearer object's silhouette, and an object under a cone is hidden.
//!
//! Objects are CLEVR's unit shapes scaled by their size and centred on their location: a cube of
//! half extent `s`, a sphere (and the snitch) of radius `s`, a cylinder of radius `s` and height
//! `2s`, a cone of base radius `s` from `z - s` to its apex at `z + s`.

use kpl_core::BBox;

use crate::formats::{HEIGHT, WIDTH};
use crate::sim::{FOCAL_PX, ObjectState, Shape, SimObject, camera_axes};

/// Below this visible fraction an object counts as not visible (and perfect perception omits it).
pub const VISIBLE_FRACTION: f64 = 0.1;
/// Sample grid per object (GRID x GRID points over its box) for the visible fraction.
const GRID: usize = 8;

type V3 = [f64; 3];

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
fn normalize(a: V3) -> V3 {
    let n = dot(a, a).sqrt().max(1e-12);
    [a[0] / n, a[1] / n, a[2] / n]
}

/// CLEVR's camera at a location, with its base orientation.
#[derive(Debug, Clone, Copy)]
pub struct Camera {
    location: V3,
    right: V3,
    down: V3,
    forward: V3,
    focal: f64,
}

impl Camera {
    pub fn new(location: [f64; 3]) -> Camera {
        let [right, down, forward] = camera_axes();
        Camera { location, right, down, forward, focal: FOCAL_PX }
    }

    /// Pixel coordinates, or `None` behind the camera.
    pub fn project(&self, p: V3) -> Option<[f64; 2]> {
        let d = sub(p, self.location);
        let z = dot(d, self.forward);
        if z <= 1e-6 {
            return None;
        }
        Some([
            WIDTH / 2.0 + self.focal * dot(d, self.right) / z,
            HEIGHT / 2.0 + self.focal * dot(d, self.down) / z,
        ])
    }

    /// CLEVR's `pixel_coords`: rounded pixel position and depth along the view.
    pub fn pixel_coords(&self, p: V3) -> [f64; 3] {
        let z = dot(sub(p, self.location), self.forward);
        let [u, v] = self.project(p).unwrap_or([0.0, 0.0]);
        [u.round(), v.round(), z]
    }

    fn distance(&self, p: V3) -> f64 {
        let d = sub(p, self.location);
        dot(d, d).sqrt()
    }
}

/// What the renderer knows of one object in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Rendered {
    /// The ground-truth box `[x, y, w, h]` as written to `<video>_bb.json`.
    pub ground_truth: [i32; 4],
    /// The whole box clipped to the image, `None` when the object is entirely outside it.
    pub bbox: Option<BBox>,
    /// Fraction of its silhouette that is in the image and not hidden (0 under a cone).
    pub visible_fraction: f64,
}

/// An object's outline points in 3D.
fn outline(object: &SimObject, state: &ObjectState, camera: &Camera) -> Vec<V3> {
    let c = state.position;
    let s = object.size;
    let (sy, cy) = state.yaw.sin_cos();
    let (st, ct) = state.tilt.sin_cos();
    // Local -> world: about the object's y axis by the tilt, then about z by the yaw.
    let place = |p: V3| {
        let q = [ct * p[0] + st * p[2], p[1], -st * p[0] + ct * p[2]];
        [c[0] + cy * q[0] - sy * q[1], c[1] + sy * q[0] + cy * q[1], c[2] + q[2]]
    };
    let circle = |z: f64, radius: f64, n: usize| -> Vec<V3> {
        (0..n)
            .map(|k| {
                let a = k as f64 / n as f64 * std::f64::consts::TAU;
                place([radius * a.cos(), radius * a.sin(), z])
            })
            .collect()
    };
    match object.shape {
        Shape::Sphere | Shape::Snitch if object.elongation != 1.0 => {
            // An ellipsoid, `elongation` times longer along its own x axis than across, turned
            // with the object (hard scenes' winged snitch).
            let (a, b) = (s * object.elongation.sqrt(), s / object.elongation.sqrt());
            let mut pts = Vec::with_capacity(6 * 12 + 2);
            pts.push(place([0.0, 0.0, b]));
            pts.push(place([0.0, 0.0, -b]));
            for i in 1..=6 {
                let polar = i as f64 / 7.0 * std::f64::consts::PI;
                for k in 0..12 {
                    let t = k as f64 / 12.0 * std::f64::consts::TAU;
                    let (sp, cp) = polar.sin_cos();
                    pts.push(place([a * sp * t.cos(), b * sp * t.sin(), b * cp]));
                }
            }
            pts
        }
        Shape::Sphere | Shape::Snitch => {
            // The circle perpendicular to the line of sight.
            let v = normalize(sub(c, camera.location));
            let a = normalize(cross(v, [0.0, 0.0, 1.0]));
            let b = cross(v, a);
            (0..16)
                .map(|k| {
                    let t = k as f64 / 16.0 * std::f64::consts::TAU;
                    let (ct, st) = (t.cos() * s, t.sin() * s);
                    [c[0] + ct * a[0] + st * b[0], c[1] + ct * a[1] + st * b[1], c[2] + ct * a[2] + st * b[2]]
                })
                .collect()
        }
        Shape::Cube => {
            let mut pts = Vec::with_capacity(8);
            for dx in [-s, s] {
                for dy in [-s, s] {
                    for dz in [-s, s] {
                        pts.push(place([dx, dy, dz]));
                    }
                }
            }
            pts
        }
        Shape::Cylinder => {
            let mut pts = circle(-s, s, 12);
            pts.extend(circle(s, s, 12));
            pts
        }
        Shape::Cone => {
            let mut pts = circle(-s, s, 12);
            pts.push(place([0.0, 0.0, s]));
            pts
        }
    }
}

/// Convex hull, counter-clockwise (Andrew's monotone chain).
fn hull(mut pts: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    pts.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    pts.dedup();
    if pts.len() < 3 {
        return pts;
    }
    let turn =
        |o: [f64; 2], a: [f64; 2], b: [f64; 2]| (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    let mut lower: Vec<[f64; 2]> = Vec::new();
    for &p in &pts {
        while lower.len() >= 2 && turn(lower[lower.len() - 2], lower[lower.len() - 1], p) <= 0.0 {
            lower.pop();
        }
        lower.push(p);
    }
    let mut upper: Vec<[f64; 2]> = Vec::new();
    for &p in pts.iter().rev() {
        while upper.len() >= 2 && turn(upper[upper.len() - 2], upper[upper.len() - 1], p) <= 0.0 {
            upper.pop();
        }
        upper.push(p);
    }
    lower.pop();
    upper.pop();
    lower.extend(upper);
    lower
}

fn inside_hull(h: &[[f64; 2]], p: [f64; 2]) -> bool {
    if h.len() < 3 {
        return false;
    }
    (0..h.len()).all(|i| {
        let (a, b) = (h[i], h[(i + 1) % h.len()]);
        (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) >= 0.0
    })
}

fn clip(b: BBox) -> Option<BBox> {
    let c = BBox::new(b.x1.max(0.0), b.y1.max(0.0), b.x2.min(WIDTH), b.y2.min(HEIGHT));
    (c.x1 < c.x2 && c.y1 < c.y2).then_some(c)
}

/// OPNet's `camera_view_bounds_2d` box from projected bounds: each bound clamped to the image, then
/// `[round(x1), round(y1), round(x2 - x1), round(y2 - y1)]` with Python's rounding (ties to even).
fn ground_truth_box(x1: f64, y1: f64, x2: f64, y2: f64) -> [i32; 4] {
    let (x1, x2) = (x1.clamp(0.0, WIDTH), x2.clamp(0.0, WIDTH));
    let (y1, y2) = (y1.clamp(0.0, HEIGHT), y2.clamp(0.0, HEIGHT));
    [x1, y1, x2 - x1, y2 - y1].map(|v| v.round_ties_even() as i32)
}

/// Whether object `i` is under a cone: a larger cone whose base is below its top and whose axis is
/// close enough that it is inside the cone (coming down over it, standing on it or lifting off it).
fn under_cone(i: usize, objects: &[SimObject], states: &[ObjectState]) -> bool {
    let [x, y, z] = states[i].position;
    let (size, top) = (objects[i].size, states[i].position[2] + objects[i].size);
    objects.iter().zip(states).enumerate().any(|(j, (cone, cs))| {
        j != i
            && cone.shape == Shape::Cone
            && cone.size > size
            && cs.position[2] - cone.size < top
            && cs.position[2] - cone.size > z - size - 0.5
            && ((cs.position[0] - x).powi(2) + (cs.position[1] - y).powi(2)).sqrt() < cone.size - 0.5 * size
    })
}

/// Renders one frame.
pub fn render(camera: &Camera, objects: &[SimObject], states: &[ObjectState]) -> Vec<Rendered> {
    struct Drawn {
        hull: Vec<[f64; 2]>,
        bbox: BBox,
        depth: f64,
        drawn: bool,
    }
    let drawn: Vec<Drawn> = objects
        .iter()
        .zip(states)
        .enumerate()
        .map(|(i, (object, state))| {
            let projected: Vec<[f64; 2]> =
                outline(object, state, camera).into_iter().filter_map(|p| camera.project(p)).collect();
            let (mut x1, mut y1, mut x2, mut y2) =
                (f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
            for p in &projected {
                x1 = x1.min(p[0]);
                y1 = y1.min(p[1]);
                x2 = x2.max(p[0]);
                y2 = y2.max(p[1]);
            }
            Drawn {
                hull: hull(projected),
                bbox: BBox::new(x1, y1, x2, y2),
                depth: camera.distance(state.position),
                drawn: x1.is_finite() && !under_cone(i, objects, states),
            }
        })
        .collect();
    drawn
        .iter()
        .map(|d| {
            let finite = d.bbox.x1.is_finite();
            let ground_truth = if finite {
                ground_truth_box(d.bbox.x1, d.bbox.y1, d.bbox.x2, d.bbox.y2)
            } else {
                [0, 0, 0, 0]
            };
            let bbox = if finite { clip(d.bbox) } else { None };
            if !d.drawn {
                return Rendered { ground_truth, bbox, visible_fraction: 0.0 };
            }
            let occluders: Vec<&Drawn> = drawn
                .iter()
                .filter(|o| {
                    o.drawn
                        && o.depth < d.depth
                        && o.bbox.x1 < d.bbox.x2
                        && d.bbox.x1 < o.bbox.x2
                        && o.bbox.y1 < d.bbox.y2
                        && d.bbox.y1 < o.bbox.y2
                })
                .collect();
            let (w, h) = (d.bbox.width() / GRID as f64, d.bbox.height() / GRID as f64);
            let (mut total, mut seen) = (0usize, 0usize);
            for gx in 0..GRID {
                for gy in 0..GRID {
                    let p = [d.bbox.x1 + (gx as f64 + 0.5) * w, d.bbox.y1 + (gy as f64 + 0.5) * h];
                    if !inside_hull(&d.hull, p) {
                        continue;
                    }
                    total += 1;
                    let in_image = p[0] >= 0.0 && p[0] < WIDTH && p[1] >= 0.0 && p[1] < HEIGHT;
                    let hidden = occluders.iter().any(|o| {
                        p[0] >= o.bbox.x1
                            && p[0] <= o.bbox.x2
                            && p[1] >= o.bbox.y1
                            && p[1] <= o.bbox.y2
                            && inside_hull(&o.hull, p)
                    });
                    if in_image && !hidden {
                        seen += 1;
                    }
                }
            }
            let visible_fraction = if total == 0 { 0.0 } else { seen as f64 / total as f64 };
            Rendered { ground_truth, bbox, visible_fraction }
        })
        .collect()
}
