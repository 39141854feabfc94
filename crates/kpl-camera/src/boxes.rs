//! Boxes in pixels as trackers write them: `[left, top, width, height]` (MOTChallenge's
//! convention), their intersection over union, and distances between them. The IoU is computed as
//! py-motmetrics' `boxiou` computes it (corners `left + width`, `top + height`; no overlap is 0;
//! areas of zero are 0), so a pair at a threshold is the same pair for the reference tools.
//!
//! ```
//! use kpl_camera::PixelBox;
//! let a = PixelBox::new(0.0, 0.0, 10.0, 10.0);
//! let b = PixelBox::new(5.0, 0.0, 10.0, 10.0);
//! assert_eq!(a.iou(&b), 50.0 / 150.0);
//! assert_eq!(a.centre(), [5.0, 5.0]);
//! ```

/// A box in pixels: its top-left corner and its size.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PixelBox {
    pub left: f64,
    pub top: f64,
    pub width: f64,
    pub height: f64,
}

impl PixelBox {
    pub const fn new(left: f64, top: f64, width: f64, height: f64) -> PixelBox {
        PixelBox { left, top, width, height }
    }

    /// From `[left, top, width, height]`.
    pub fn from_array(b: [f64; 4]) -> PixelBox {
        PixelBox::new(b[0], b[1], b[2], b[3])
    }

    /// As `[left, top, width, height]`.
    pub fn to_array(&self) -> [f64; 4] {
        [self.left, self.top, self.width, self.height]
    }

    /// The box around points (their bounding box), `None` for no points.
    pub fn around(points: impl IntoIterator<Item = [f64; 2]>) -> Option<PixelBox> {
        let mut it = points.into_iter();
        let first = it.next()?;
        let (mut lo, mut hi) = (first, first);
        for p in it {
            lo = [lo[0].min(p[0]), lo[1].min(p[1])];
            hi = [hi[0].max(p[0]), hi[1].max(p[1])];
        }
        Some(PixelBox::new(lo[0], lo[1], hi[0] - lo[0], hi[1] - lo[1]))
    }

    pub fn right(&self) -> f64 {
        self.left + self.width
    }

    pub fn bottom(&self) -> f64 {
        self.top + self.height
    }

    pub fn centre(&self) -> [f64; 2] {
        [self.left + self.width / 2.0, self.top + self.height / 2.0]
    }

    /// The middle of the bottom side (where a standing person or a car seen from the side meets
    /// the ground).
    pub fn bottom_centre(&self) -> [f64; 2] {
        [self.left + self.width / 2.0, self.top + self.height]
    }

    /// Whether all four numbers are finite and the sides not negative.
    pub fn is_valid(&self) -> bool {
        self.to_array().iter().all(|v| v.is_finite()) && self.width >= 0.0 && self.height >= 0.0
    }

    /// The area (0 for a box with a negative side).
    pub fn area(&self) -> f64 {
        (self.right() - self.left).max(0.0) * (self.bottom() - self.top).max(0.0)
    }

    /// The area of the overlap of two boxes.
    pub fn intersection(&self, other: &PixelBox) -> f64 {
        let w = (self.right().min(other.right()) - self.left.max(other.left)).max(0.0);
        let h = (self.bottom().min(other.bottom()) - self.top.max(other.top)).max(0.0);
        w * h
    }

    /// Intersection over union, in [0, 1]; 0 when they do not overlap.
    pub fn iou(&self, other: &PixelBox) -> f64 {
        let i = self.intersection(other);
        if i == 0.0 {
            return 0.0;
        }
        let u = self.area() + other.area() - i;
        if u > 0.0 { i / u } else { 0.0 }
    }

    /// The fraction of this box's area that `other` covers (intersection over this area).
    pub fn covered_by(&self, other: &PixelBox) -> f64 {
        let area = self.area();
        if area > 0.0 { self.intersection(other) / area } else { 0.0 }
    }

    /// The distance between the two boxes' centres, pixels.
    pub fn centre_distance(&self, other: &PixelBox) -> f64 {
        let (a, b) = (self.centre(), other.centre());
        (a[0] - b[0]).hypot(a[1] - b[1])
    }

    /// The box moved by `d` pixels.
    pub fn shifted(&self, d: [f64; 2]) -> PixelBox {
        PixelBox { left: self.left + d[0], top: self.top + d[1], ..*self }
    }

    /// How far the box is from the nearest border of an image `width` by `height`, pixels: its
    /// nearest side's distance, 0 or less for a box at or over the border (one the detector
    /// clipped there). A point is a box of no size.
    pub fn border_distance(&self, width: f64, height: f64) -> f64 {
        self.left.min(self.top).min(width - self.right()).min(height - self.bottom())
    }

    /// The part inside an image `width` by `height` (`None` when nothing is).
    pub fn clipped(&self, width: f64, height: f64) -> Option<PixelBox> {
        let (l, t) = (self.left.max(0.0), self.top.max(0.0));
        let (r, b) = (self.right().min(width), self.bottom().min(height));
        (r > l && b > t).then(|| PixelBox::new(l, t, r - l, b - t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_worked_border_distances() {
        // 100 x 50 image.
        assert_eq!(PixelBox::new(10.0, 20.0, 30.0, 5.0).border_distance(100.0, 50.0), 10.0);
        assert_eq!(PixelBox::new(60.0, 20.0, 38.0, 5.0).border_distance(100.0, 50.0), 2.0);
        assert_eq!(PixelBox::new(0.0, 20.0, 30.0, 5.0).border_distance(100.0, 50.0), 0.0, "clipped");
        assert_eq!(PixelBox::new(40.0, 45.0, 10.0, 8.0).border_distance(100.0, 50.0), -3.0, "over it");
        assert_eq!(PixelBox::new(50.0, 24.0, 0.0, 0.0).border_distance(100.0, 50.0), 24.0, "a point");
    }

    #[test]
    fn hand_worked_overlaps() {
        let a = PixelBox::new(0.0, 0.0, 4.0, 2.0);
        assert_eq!(a.iou(&a), 1.0);
        assert_eq!(a.iou(&PixelBox::new(4.0, 0.0, 4.0, 2.0)), 0.0, "touching is no overlap");
        // Overlap 2 x 1 = 2; union 8 + 8 - 2 = 14.
        let b = PixelBox::new(2.0, 1.0, 4.0, 2.0);
        assert_eq!(a.iou(&b), 2.0 / 14.0);
        assert_eq!(a.iou(&b), b.iou(&a));
        assert_eq!(a.covered_by(&b), 0.25);
        assert_eq!(PixelBox::new(0.0, 0.0, 0.0, 5.0).iou(&a), 0.0, "no area");
        assert_eq!(a.centre_distance(&b), 5f64.sqrt());
        assert_eq!(
            PixelBox::around([[3.0, 1.0], [1.0, 4.0], [2.0, 2.0]]),
            Some(PixelBox::new(1.0, 1.0, 2.0, 3.0))
        );
        assert_eq!(
            PixelBox::new(-5.0, 2.0, 10.0, 10.0).clipped(8.0, 6.0),
            Some(PixelBox::new(0.0, 2.0, 5.0, 4.0))
        );
        assert_eq!(PixelBox::new(10.0, 2.0, 10.0, 10.0).clipped(8.0, 6.0), None);
        assert!(!PixelBox::new(0.0, 0.0, -1.0, 1.0).is_valid());
    }
}
