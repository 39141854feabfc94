//! Consecutive frame alignment (III-B.1b): the optimal assignment of percepts to anchors under the
//! cost of eq. (1), from `pathfinding`'s Kuhn-Munkres, keeping only pairs whose cost is below θ.
//!
//! Costs are capped at θ before solving, so a pair that would be rejected anyway weighs the same as
//! leaving both sides unmatched and cannot pull the optimum away from the pairs that are kept.

use pathfinding::kuhn_munkres::kuhn_munkres_min;
use pathfinding::matrix::Matrix;

/// Integer resolution of the capped costs: θ maps to this many units.
const COST_UNITS: f64 = 1_000_000.0;

/// `cost[r][c]` for `rows` x `cols`; returns the accepted `(row, col)` pairs, each with cost < θ.
pub(crate) fn assign(cost: &[f64], rows: usize, cols: usize, theta: f64) -> Vec<(usize, usize)> {
    if rows == 0 || cols == 0 {
        return Vec::new();
    }
    let to_units = |c: f64| -> i64 {
        let capped = if c.is_nan() { theta } else { c.min(theta) };
        (capped / theta * COST_UNITS).round() as i64
    };
    // Kuhn-Munkres wants no more rows than columns: solve the transpose when needed.
    let transpose = rows > cols;
    let (n_rows, n_cols) = if transpose { (cols, rows) } else { (rows, cols) };
    let mut weights = Vec::with_capacity(rows * cols);
    for r in 0..n_rows {
        for c in 0..n_cols {
            let (orig_r, orig_c) = if transpose { (c, r) } else { (r, c) };
            weights.push(to_units(cost[orig_r * cols + orig_c]));
        }
    }
    let Ok(matrix) = Matrix::from_vec(n_rows, n_cols, weights) else {
        return Vec::new();
    };
    let (_, assignment) = kuhn_munkres_min(&matrix);
    assignment
        .into_iter()
        .enumerate()
        .map(|(r, c)| if transpose { (c, r) } else { (r, c) })
        .filter(|&(r, c)| cost[r * cols + c] < theta)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::assign;

    #[test]
    fn picks_the_optimal_not_the_greedy_assignment() {
        // Greedy on row 0 takes column 0 (cost 1) and forces row 1 onto column 1 (cost 100);
        // the optimum crosses: 2 + 3.
        let cost = [1.0, 2.0, 3.0, 100.0];
        let mut pairs = assign(&cost, 2, 2, 1000.0);
        pairs.sort();
        assert_eq!(pairs, vec![(0, 1), (1, 0)]);
    }

    #[test]
    fn rejects_pairs_at_or_above_theta() {
        let cost = [10.0, 50.0];
        assert_eq!(assign(&cost, 1, 2, 10.0), vec![]);
        assert_eq!(assign(&cost, 1, 2, 10.5), vec![(0, 0)]);
    }

    #[test]
    fn rectangular_both_ways() {
        // 3 rows, 1 column: only the cheapest row gets it.
        let cost = [5.0, 1.0, 7.0];
        assert_eq!(assign(&cost, 3, 1, 100.0), vec![(1, 0)]);
        let cost = [5.0, 1.0, 7.0];
        assert_eq!(assign(&cost, 1, 3, 100.0), vec![(0, 1)]);
    }

    #[test]
    fn a_rejected_pair_does_not_displace_an_acceptable_one() {
        // Row 0 can only take column 0 cheaply; row 1 is far from everything. Capping keeps (0, 0).
        let cost = [1.0, 1e9, 1e9, 1e12];
        assert_eq!(assign(&cost, 2, 2, 100.0), vec![(0, 0)]);
    }
}
