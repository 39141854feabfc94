//! Rendering a simulated frame to boxes: a pinhole camera at 320x240, each object's silhouette as
//! the convex hull of its projected outline, ground-truth boxes (the whole object, hidden or not,
//! clipped to the image) and depth-ordered occlusion: sample points of an object's silhouette are
//! hidden by any nearer object's silhouette. Contained objects are not rendered.

use kpl_core::BBox;

use crate::formats::{HEIGHT, SceneCamera, WIDTH};
use crate::scene::{ObjectState, Shape, SimObject};

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

/// A pinhole camera looking at a point with the world's z axis up.
#[derive(Debug, Clone, Copy)]
pub struct Camera {
    location: V3,
    right: V3,
    down: V3,
    forward: V3,
    focal: f64,
}

impl Camera {
    pub fn new(c: &SceneCamera) -> Camera {
        let forward = normalize(sub(c.look_at, c.location));
        let right = normalize(cross(forward, [0.0, 0.0, 1.0]));
        let down = cross(forward, right);
        Camera { location: c.location, right, down, forward, focal: c.focal_px }
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

    fn distance(&self, p: V3) -> f64 {
        let d = sub(p, self.location);
        dot(d, d).sqrt()
    }
}

/// What the renderer knows of one object in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Rendered {
    /// The full box clipped to the image, `None` when the object is entirely outside it.
    pub bbox: Option<BBox>,
    /// Fraction of its silhouette that is in the image and not hidden (0 when contained).
    pub visible_fraction: f64,
    /// The box of the visible part (what a detector sees), when anything is visible.
    pub visible_bbox: Option<BBox>,
}

/// Silhouette outline points of an object in 3D.
fn outline(object: &SimObject, state: &ObjectState, camera: &Camera) -> Vec<V3> {
    let [x, y, z] = state.position;
    let s = object.half;
    let circle = |centre: V3, radius: f64, n: usize| -> Vec<V3> {
        (0..n)
            .map(|k| {
                let a = k as f64 / n as f64 * std::f64::consts::TAU;
                [centre[0] + radius * a.cos(), centre[1] + radius * a.sin(), centre[2]]
            })
            .collect()
    };
    match object.shape {
        Shape::Sphere | Shape::Snitch => {
            // The circle perpendicular to the line of sight.
            let c = [x, y, z + s];
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
            let h = 0.8 * s;
            let (sin, cos) = state.yaw.sin_cos();
            let mut pts = Vec::with_capacity(8);
            for (dx, dy) in [(-h, -h), (h, -h), (h, h), (-h, h)] {
                let (rx, ry) = (dx * cos - dy * sin, dx * sin + dy * cos);
                pts.push([x + rx, y + ry, z]);
                pts.push([x + rx, y + ry, z + 2.0 * h]);
            }
            pts
        }
        Shape::Cylinder => {
            let r = 0.8 * s;
            let mut pts = circle([x, y, z], r, 12);
            pts.extend(circle([x, y, z + 2.0 * r], r, 12));
            pts
        }
        Shape::Cone => {
            let mut pts = circle([x, y, z], s, 12);
            pts.push([x, y, z + 2.0 * s]);
            pts
        }
    }
}

/// Height of an object's centre above its base.
fn centre_height(object: &SimObject) -> f64 {
    match object.shape {
        Shape::Cube | Shape::Cylinder => 0.8 * object.half,
        Shape::Sphere | Shape::Snitch | Shape::Cone => object.half,
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
        .map(|(object, state)| {
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
            let [x, y, z] = state.position;
            Drawn {
                hull: hull(projected),
                bbox: BBox::new(x1, y1, x2, y2),
                depth: camera.distance([x, y, z + centre_height(object)]),
                drawn: !state.contained && x1.is_finite(),
            }
        })
        .collect();
    // An object under a cone whose rim is below the object's top is inside it: hidden whatever
    // the depth order says (a cone coming down over it, or just lifting off it).
    let inside_cone = |i: usize| {
        let [x, y, z] = states[i].position;
        let top = z + 2.0 * centre_height(&objects[i]);
        objects.iter().zip(states).enumerate().any(|(j, (cone, cs))| {
            j != i
                && cone.shape == Shape::Cone
                && !cs.contained
                && cs.position[2] < top
                && cone.half > objects[i].half
                && ((cs.position[0] - x).powi(2) + (cs.position[1] - y).powi(2)).sqrt()
                    < cone.half - 0.5 * objects[i].half
        })
    };
    drawn
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let bbox = if d.bbox.x1.is_finite() { clip(d.bbox) } else { None };
            if !d.drawn || inside_cone(i) {
                return Rendered { bbox, visible_fraction: 0.0, visible_bbox: None };
            }
            let occluders: Vec<&Drawn> = drawn
                .iter()
                .enumerate()
                .filter(|&(j, o)| {
                    j != i
                        && o.drawn
                        && o.depth < d.depth
                        && o.bbox.x1 < d.bbox.x2
                        && d.bbox.x1 < o.bbox.x2
                        && o.bbox.y1 < d.bbox.y2
                        && d.bbox.y1 < o.bbox.y2
                })
                .map(|(_, o)| o)
                .collect();
            let (w, h) = (d.bbox.width() / GRID as f64, d.bbox.height() / GRID as f64);
            let (mut total, mut seen) = (0usize, 0usize);
            let mut vis = BBox::new(f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
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
                        vis = BBox::new(
                            vis.x1.min(p[0] - w / 2.0),
                            vis.y1.min(p[1] - h / 2.0),
                            vis.x2.max(p[0] + w / 2.0),
                            vis.y2.max(p[1] + h / 2.0),
                        );
                    }
                }
            }
            let visible_fraction = if total == 0 { 0.0 } else { seen as f64 / total as f64 };
            let visible_bbox = (seen > 0)
                .then(|| {
                    BBox::new(
                        vis.x1.max(d.bbox.x1),
                        vis.y1.max(d.bbox.y1),
                        vis.x2.min(d.bbox.x2),
                        vis.y2.min(d.bbox.y2),
                    )
                })
                .and_then(clip);
            Rendered { bbox, visible_fraction, visible_bbox }
        })
        .collect()
}
