//! A uniform grid over the plane that maps each cell to the items (segments, polygons) that may
//! matter for a query in it, so that geometry queries look at a few cells instead of the whole
//! network. Stored compactly: one offsets array and one items array (no per-cell vectors).

use crate::geom::{Point, dist_to_segment};

/// Most cells a grid may have; bigger networks get coarser cells.
const MAX_CELLS: f64 = 4.0e6;

#[derive(Debug, Clone)]
pub struct Grid {
    origin: Point,
    cell: f64,
    nx: usize,
    ny: usize,
    /// Items of cell `c` are `items[offsets[c]..offsets[c + 1]]`.
    offsets: Vec<u32>,
    items: Vec<u32>,
}

/// Collects `(cell, item)` pairs, then freezes them into a [`Grid`].
#[derive(Debug)]
pub struct GridBuilder {
    origin: Point,
    cell: f64,
    nx: usize,
    ny: usize,
    pairs: Vec<(u32, u32)>,
}

impl GridBuilder {
    /// A grid covering `lo..hi` with cells of about `cell` metres (coarser if that would make
    /// too many cells).
    pub fn new(lo: Point, hi: Point, cell: f64) -> GridBuilder {
        GridBuilder::with_max_cells(lo, hi, cell, MAX_CELLS)
    }

    /// [`GridBuilder::new`] with at most about `max_cells` cells.
    pub fn with_max_cells(lo: Point, hi: Point, cell: f64, max_cells: f64) -> GridBuilder {
        let width = (hi[0] - lo[0]).max(1.0);
        let height = (hi[1] - lo[1]).max(1.0);
        let mut cell = cell.max(1.0);
        if (width / cell) * (height / cell) > max_cells {
            cell = (width * height / max_cells).sqrt();
        }
        let nx = (width / cell).ceil() as usize + 1;
        let ny = (height / cell).ceil() as usize + 1;
        GridBuilder { origin: lo, cell, nx, ny, pairs: Vec::new() }
    }

    fn cell_range(&self, lo: Point, hi: Point) -> (usize, usize, usize, usize) {
        let clamp_x =
            |x: f64| (((x - self.origin[0]) / self.cell).floor().max(0.0) as usize).min(self.nx - 1);
        let clamp_y =
            |y: f64| (((y - self.origin[1]) / self.cell).floor().max(0.0) as usize).min(self.ny - 1);
        (clamp_x(lo[0]), clamp_x(hi[0]), clamp_y(lo[1]), clamp_y(hi[1]))
    }

    /// Adds `item` to every cell that the segment `a`-`b` widened by `margin` touches.
    pub fn insert_segment(&mut self, item: u32, a: Point, b: Point, margin: f64) {
        let lo = [a[0].min(b[0]) - margin, a[1].min(b[1]) - margin];
        let hi = [a[0].max(b[0]) + margin, a[1].max(b[1]) + margin];
        let (x0, x1, y0, y1) = self.cell_range(lo, hi);
        let half_diagonal = self.cell * std::f64::consts::FRAC_1_SQRT_2;
        for iy in y0..=y1 {
            for ix in x0..=x1 {
                let centre = [
                    self.origin[0] + (ix as f64 + 0.5) * self.cell,
                    self.origin[1] + (iy as f64 + 0.5) * self.cell,
                ];
                if dist_to_segment(centre, a, b) <= half_diagonal + margin {
                    self.pairs.push(((iy * self.nx + ix) as u32, item));
                }
            }
        }
    }

    /// Adds `item` to every cell that the box `lo..hi` touches.
    pub fn insert_box(&mut self, item: u32, lo: Point, hi: Point) {
        let (x0, x1, y0, y1) = self.cell_range(lo, hi);
        for iy in y0..=y1 {
            for ix in x0..=x1 {
                self.pairs.push(((iy * self.nx + ix) as u32, item));
            }
        }
    }

    pub fn build(mut self) -> Grid {
        self.pairs.sort_unstable();
        self.pairs.dedup();
        let n_cells = self.nx * self.ny;
        let mut offsets = vec![0u32; n_cells + 1];
        for &(cell, _) in &self.pairs {
            offsets[cell as usize + 1] += 1;
        }
        for c in 0..n_cells {
            offsets[c + 1] += offsets[c];
        }
        let items = self.pairs.iter().map(|&(_, item)| item).collect();
        Grid { origin: self.origin, cell: self.cell, nx: self.nx, ny: self.ny, offsets, items }
    }
}

impl Grid {
    fn cell_index(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let fx = (x - self.origin[0]) / self.cell;
        let fy = (y - self.origin[1]) / self.cell;
        if !(fx >= 0.0 && fy >= 0.0) {
            return None; // also rejects NaN
        }
        let (ix, iy) = (fx as usize, fy as usize);
        (ix < self.nx && iy < self.ny).then_some((ix, iy))
    }

    fn cell_items(&self, ix: usize, iy: usize) -> &[u32] {
        let c = iy * self.nx + ix;
        &self.items[self.offsets[c] as usize..self.offsets[c + 1] as usize]
    }

    /// The items registered in the cell containing `p` (empty outside the grid).
    pub fn at(&self, p: Point) -> &[u32] {
        match self.cell_index(p[0], p[1]) {
            Some((ix, iy)) => self.cell_items(ix, iy),
            None => &[],
        }
    }

    /// Calls `visit` for the items of every cell within `radius` of `p` (an item may be visited
    /// more than once).
    pub fn for_each_near(&self, p: Point, radius: f64, mut visit: impl FnMut(u32)) {
        if !(p[0].is_finite() && p[1].is_finite() && radius.is_finite()) {
            return;
        }
        let lo_x = ((p[0] - radius - self.origin[0]) / self.cell).floor();
        let hi_x = ((p[0] + radius - self.origin[0]) / self.cell).floor();
        let lo_y = ((p[1] - radius - self.origin[1]) / self.cell).floor();
        let hi_y = ((p[1] + radius - self.origin[1]) / self.cell).floor();
        if hi_x < 0.0 || hi_y < 0.0 || lo_x >= self.nx as f64 || lo_y >= self.ny as f64 {
            return;
        }
        let x0 = lo_x.max(0.0) as usize;
        let y0 = lo_y.max(0.0) as usize;
        let x1 = (hi_x as usize).min(self.nx - 1);
        let y1 = (hi_y as usize).min(self.ny - 1);
        for iy in y0..=y1 {
            for ix in x0..=x1 {
                for &item in self.cell_items(ix, iy) {
                    visit(item);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_land_in_the_cells_they_cross() {
        let mut builder = GridBuilder::new([0.0, 0.0], [100.0, 100.0], 10.0);
        builder.insert_segment(7, [5.0, 5.0], [95.0, 95.0], 0.0);
        builder.insert_segment(8, [50.0, 0.0], [50.0, 10.0], 2.0);
        let grid = builder.build();
        assert_eq!(grid.at([55.0, 55.0]), &[7]);
        assert_eq!(grid.at([55.0, 5.0]), &[8]);
        assert!(grid.at([5.0, 95.0]).is_empty());
        assert!(grid.at([-5.0, 5.0]).is_empty());
        assert!(grid.at([f64::NAN, 5.0]).is_empty());
        let mut near = Vec::new();
        grid.for_each_near([45.0, 25.0], 12.0, |i| near.push(i));
        near.sort_unstable();
        near.dedup();
        assert_eq!(near, vec![7, 8]);
    }
}
