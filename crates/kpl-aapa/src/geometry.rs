//! Box arithmetic in image space: centres, sizes, overlap, the alignment cost of eq. (1) and the
//! transforms used by camera compensation and attachments.

use kpl_core::BBox;

pub(crate) fn centre(b: &BBox) -> [f64; 2] {
    b.center()
}

pub(crate) fn size(b: &BBox) -> [f64; 2] {
    [b.width(), b.height()]
}

/// Bottom centre: where an object standing on a surface touches it, in the image.
pub(crate) fn bottom_centre(b: &BBox) -> [f64; 2] {
    [(b.x1 + b.x2) / 2.0, b.y2]
}

/// Square root of the area, never zero.
pub(crate) fn scale(b: &BBox) -> f64 {
    (b.width().max(1e-6) * b.height().max(1e-6)).sqrt()
}

pub(crate) fn from_bottom_centre(p: [f64; 2], size: [f64; 2]) -> BBox {
    BBox::new(p[0] - size[0] / 2.0, p[1] - size[1], p[0] + size[0] / 2.0, p[1])
}

pub(crate) fn translate(b: &BBox, d: [f64; 2]) -> BBox {
    BBox::new(b.x1 + d[0], b.y1 + d[1], b.x2 + d[0], b.y2 + d[1])
}

/// Boxes overlap with positive area (the paper's `p ∩ π ≠ ∅`; touching edges do not count).
pub fn intersects(a: &BBox, b: &BBox) -> bool {
    a.x1 < b.x2 && b.x1 < a.x2 && a.y1 < b.y2 && b.y1 < a.y2
}

/// The box lies entirely outside the image.
pub(crate) fn outside(b: &BBox, width: f64, height: f64) -> bool {
    b.x2 <= 0.0 || b.y2 <= 0.0 || b.x1 >= width || b.y1 >= height
}

fn squared_distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
}

/// Eq. (1): `tau * (d(pos) + d(size))` with `d` the squared Euclidean distance over box centres and
/// (width, height); `tau` is 1 when the types agree and `type_mismatch` otherwise.
pub fn alignment_cost(percept: &BBox, anchor: &BBox, same_type: bool, type_mismatch: f64) -> f64 {
    let tau = if same_type { 1.0 } else { type_mismatch };
    tau * (squared_distance(centre(percept), centre(anchor)) + squared_distance(size(percept), size(anchor)))
}

pub(crate) fn is_valid(b: &BBox) -> bool {
    [b.x1, b.y1, b.x2, b.y2].iter().all(|v| v.is_finite()) && b.x1 <= b.x2 && b.y1 <= b.y2
}
