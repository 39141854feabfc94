//! Gating: the spatial index a link process builds at each state over the objects that are
//! candidates for reestablish (the unlinked objects of its `to` type, one entry per hypothesis),
//! so that each unlinked `from` object looks only at the few within the gate distance instead of
//! at all of them. A uniform grid with cells one gate wide, kept as a sorted vector: building is a
//! sort, a query is nine binary searches, and the order of results is deterministic.

/// One indexed position: an object (by the caller's key) and which of its hypotheses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateEntry<K> {
    pub key: K,
    pub hypothesis: u32,
    pub pos: [f64; 2],
}

/// Positions in cells of side `radius`; objects without a position are in every answer.
#[derive(Debug, Clone)]
pub struct GateGrid<K> {
    radius: f64,
    cells: Vec<((i32, i32), GateEntry<K>)>,
    unplaced: Vec<K>,
}

impl<K: Copy + Ord> GateGrid<K> {
    /// An empty grid for a gate distance (at least a millimetre).
    pub fn new(radius: f64) -> GateGrid<K> {
        GateGrid { radius: radius.max(1e-3), cells: Vec::new(), unplaced: Vec::new() }
    }

    pub fn radius(&self) -> f64 {
        self.radius
    }

    pub fn clear(&mut self) {
        self.cells.clear();
        self.unplaced.clear();
    }

    fn cell(&self, pos: [f64; 2]) -> (i32, i32) {
        let c = |x: f64| (x / self.radius).floor().clamp(i32::MIN as f64, i32::MAX as f64) as i32;
        (c(pos[0]), c(pos[1]))
    }

    pub fn insert(&mut self, key: K, hypothesis: u32, pos: [f64; 2]) {
        if pos[0].is_finite() && pos[1].is_finite() {
            let cell = self.cell(pos);
            self.cells.push((cell, GateEntry { key, hypothesis, pos }));
        } else {
            self.unplaced.push(key);
        }
    }

    /// An object whose position is unknown: a candidate for every query.
    pub fn insert_unplaced(&mut self, key: K) {
        self.unplaced.push(key);
    }

    /// Call once after inserting and before querying.
    pub fn finish(&mut self) {
        self.cells.sort_by(|a, b| {
            a.0.cmp(&b.0).then(a.1.key.cmp(&b.1.key)).then(a.1.hypothesis.cmp(&b.1.hypothesis))
        });
        self.unplaced.sort();
        self.unplaced.dedup();
    }

    /// The keys with some hypothesis within the gate distance of `pos` (`<=`), each once, sorted,
    /// followed by the unplaced ones. `pos` `None`: every key.
    pub fn near(&self, pos: Option<[f64; 2]>, out: &mut Vec<K>) {
        out.clear();
        match pos {
            Some(pos) if pos[0].is_finite() && pos[1].is_finite() => {
                let (cx, cy) = self.cell(pos);
                let r2 = self.radius * self.radius;
                for dx in -1..=1 {
                    for dy in -1..=1 {
                        let cell = (cx.saturating_add(dx), cy.saturating_add(dy));
                        let start = self.cells.partition_point(|e| e.0 < cell);
                        for (c, entry) in &self.cells[start..] {
                            if *c != cell {
                                break;
                            }
                            let (ddx, ddy) = (entry.pos[0] - pos[0], entry.pos[1] - pos[1]);
                            if ddx * ddx + ddy * ddy <= r2 {
                                out.push(entry.key);
                            }
                        }
                    }
                }
            }
            _ => out.extend(self.cells.iter().map(|(_, e)| e.key)),
        }
        out.sort();
        out.dedup();
        out.extend(self.unplaced.iter().copied());
    }

    pub fn len(&self) -> usize {
        self.cells.len() + self.unplaced.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// The grid answers exactly what a scan of every entry answers.
        #[test]
        fn grid_equals_a_full_scan(
            points in proptest::collection::vec((-50.0f64..50.0, -50.0f64..50.0), 0..60),
            queries in proptest::collection::vec((-60.0f64..60.0, -60.0f64..60.0), 1..10),
            radius in 0.5f64..20.0,
        ) {
            let mut grid = GateGrid::new(radius);
            for (i, (x, y)) in points.iter().enumerate() {
                grid.insert(i / 2, (i % 2) as u32, [*x, *y]);
            }
            grid.finish();
            let mut got = Vec::new();
            for (qx, qy) in queries {
                grid.near(Some([qx, qy]), &mut got);
                let mut want: Vec<usize> = points
                    .iter()
                    .enumerate()
                    .filter(|(_, (x, y))| (x - qx).powi(2) + (y - qy).powi(2) <= radius * radius)
                    .map(|(i, _)| i / 2)
                    .collect();
                want.sort();
                want.dedup();
                prop_assert_eq!(&got, &want);
            }
        }
    }

    #[test]
    fn unplaced_and_unknown_positions() {
        let mut grid = GateGrid::new(5.0);
        grid.insert(1u32, 0, [0.0, 0.0]);
        grid.insert(2, 0, [100.0, 0.0]);
        grid.insert_unplaced(3);
        grid.finish();
        let mut out = Vec::new();
        grid.near(Some([1.0, 1.0]), &mut out);
        assert_eq!(out, vec![1, 3]);
        grid.near(None, &mut out);
        assert_eq!(out, vec![1, 2, 3]);
    }
}
