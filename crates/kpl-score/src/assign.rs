//! Linear sum assignment, dense and sparse.
//!
//! [`min_cost`] solves the rectangular assignment problem exactly with the shortest augmenting
//! path method (Jonker–Volgenant as described by Crouse, "On implementing 2D rectangular
//! assignment algorithms", 2016), the method SciPy's `linear_sum_assignment` uses, with the same
//! order of visiting columns, so that ties are broken alike where they can be.
//!
//! The metrics ask two sparse questions, answered per connected component of the pairs that can
//! be matched (a component's optimum does not depend on the others, and a frame of a thousand
//! objects splits into many small problems):
//! - [`gated`]: as many pairs as possible, then the smallest total cost: py-motmetrics' matching,
//!   which gives unmatchable pairs a cost so large that one of them never pays off;
//! - [`max_weight`]: the largest total weight: TrackEval's HOTA matching and the identity
//!   measures' global assignment.

/// A pair that may be matched, and its cost or weight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Edge {
    pub row: usize,
    pub col: usize,
    pub value: f64,
}

/// The assignment of smallest total cost of a dense `rows` × `cols` matrix (row-major, finite
/// entries): `min(rows, cols)` pairs `(row, col)`, ordered by row.
pub fn min_cost(cost: &[f64], rows: usize, cols: usize) -> Vec<(usize, usize)> {
    debug_assert_eq!(cost.len(), rows * cols);
    if rows == 0 || cols == 0 {
        return Vec::new();
    }
    if rows <= cols {
        return solve(cost, rows, cols);
    }
    // More rows than columns: solve the transpose, as SciPy does.
    let mut transposed = vec![0.0; cost.len()];
    for r in 0..rows {
        for c in 0..cols {
            transposed[c * rows + r] = cost[r * cols + c];
        }
    }
    let mut pairs: Vec<(usize, usize)> =
        solve(&transposed, cols, rows).into_iter().map(|(c, r)| (r, c)).collect();
    pairs.sort_unstable();
    pairs
}

/// Shortest augmenting paths for `rows <= cols`.
fn solve(cost: &[f64], rows: usize, cols: usize) -> Vec<(usize, usize)> {
    const NONE: usize = usize::MAX;
    let mut u = vec![0.0; rows];
    let mut v = vec![0.0; cols];
    let mut shortest = vec![f64::INFINITY; cols];
    let mut path = vec![NONE; cols];
    let mut col_of_row = vec![NONE; rows];
    let mut row_of_col = vec![NONE; cols];
    let mut seen_row = vec![false; rows];
    let mut seen_col = vec![false; cols];
    let mut remaining: Vec<usize> = Vec::with_capacity(cols);
    for current in 0..rows {
        shortest.fill(f64::INFINITY);
        seen_row.fill(false);
        seen_col.fill(false);
        remaining.clear();
        remaining.extend((0..cols).rev());
        let mut min_val = 0.0;
        let mut i = current;
        let sink = loop {
            seen_row[i] = true;
            let mut lowest = f64::INFINITY;
            let mut index = NONE;
            for (it, &j) in remaining.iter().enumerate() {
                let reduced = min_val + cost[i * cols + j] - u[i] - v[j];
                if reduced < shortest[j] {
                    path[j] = i;
                    shortest[j] = reduced;
                }
                // Among equally short paths prefer one that ends at a free column.
                if shortest[j] < lowest || (shortest[j] == lowest && row_of_col[j] == NONE) {
                    lowest = shortest[j];
                    index = it;
                }
            }
            if index == NONE {
                // Only non-finite costs reach here; callers pass finite ones.
                return Vec::new();
            }
            min_val = lowest;
            let j = remaining[index];
            seen_col[j] = true;
            remaining.swap_remove(index);
            if row_of_col[j] == NONE {
                break j;
            }
            i = row_of_col[j];
        };
        // Dual update.
        u[current] += min_val;
        for r in 0..rows {
            if seen_row[r] && r != current {
                u[r] += min_val - shortest[col_of_row[r]];
            }
        }
        for c in 0..cols {
            if seen_col[c] {
                v[c] -= min_val - shortest[c];
            }
        }
        // Augment along the path.
        let mut j = sink;
        loop {
            let r = path[j];
            row_of_col[j] = r;
            std::mem::swap(&mut col_of_row[r], &mut j);
            if r == current {
                break;
            }
        }
    }
    col_of_row.iter().enumerate().filter(|&(_, &c)| c != NONE).map(|(r, &c)| (r, c)).collect()
}

/// The connected components of the edges: for each, its edges (indices into `edges`).
fn components(rows: usize, cols: usize, edges: &[Edge]) -> Vec<Vec<usize>> {
    // Union-find over rows (0..rows) and columns (rows..rows+cols).
    let mut parent: Vec<usize> = (0..rows + cols).collect();
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    for e in edges {
        let a = find(&mut parent, e.row);
        let b = find(&mut parent, rows + e.col);
        if a != b {
            parent[a.max(b)] = a.min(b);
        }
    }
    let mut by_root: std::collections::BTreeMap<usize, Vec<usize>> = std::collections::BTreeMap::new();
    for (k, e) in edges.iter().enumerate() {
        let root = find(&mut parent, e.row);
        by_root.entry(root).or_default().push(k);
    }
    by_root.into_values().collect()
}

/// A component as a dense matrix: its rows and columns in increasing order, and each edge's cell.
struct Dense {
    rows: Vec<usize>,
    cols: Vec<usize>,
    cells: Vec<Option<f64>>,
}

fn dense(edges: &[Edge], component: &[usize]) -> Dense {
    let mut rows: Vec<usize> = component.iter().map(|&k| edges[k].row).collect();
    let mut cols: Vec<usize> = component.iter().map(|&k| edges[k].col).collect();
    rows.sort_unstable();
    rows.dedup();
    cols.sort_unstable();
    cols.dedup();
    let mut cells = vec![None; rows.len() * cols.len()];
    for &k in component {
        let e = edges[k];
        let (Ok(r), Ok(c)) = (rows.binary_search(&e.row), cols.binary_search(&e.col)) else { continue };
        cells[r * cols.len() + c] = Some(e.value);
    }
    Dense { rows, cols, cells }
}

/// The most pairs, then the smallest total cost, among `edges` (costs finite, at most one edge
/// per pair); unmatched rows and columns stay unmatched. Pairs ordered by row.
pub fn gated(rows: usize, cols: usize, edges: &[Edge]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for component in components(rows, cols, edges) {
        let d = dense(edges, &component);
        if d.rows.len() == 1 || d.cols.len() == 1 {
            // One row or one column: the cheapest edge.
            if let Some((idx, _)) = d
                .cells
                .iter()
                .enumerate()
                .filter_map(|(i, c)| c.map(|v| (i, v)))
                .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)))
            {
                out.push((d.rows[idx / d.cols.len()], d.cols[idx % d.cols.len()]));
            }
            continue;
        }
        // A missing pair costs more than any assignment that avoids it could save.
        let largest = d.cells.iter().flatten().fold(0.0_f64, |m, v| m.max(v.abs())) + 1.0;
        let r = d.rows.len().min(d.cols.len()) as f64;
        let missing = 2.0 * r * largest + 1.0;
        let matrix: Vec<f64> = d.cells.iter().map(|c| c.unwrap_or(missing)).collect();
        for (r, c) in min_cost(&matrix, d.rows.len(), d.cols.len()) {
            if d.cells[r * d.cols.len() + c].is_some() {
                out.push((d.rows[r], d.cols[c]));
            }
        }
    }
    out.sort_unstable();
    out
}

/// The pairs of largest total weight among `edges` (weights positive, at most one edge per pair).
/// Pairs ordered by row.
pub fn max_weight(rows: usize, cols: usize, edges: &[Edge]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for component in components(rows, cols, edges) {
        let d = dense(edges, &component);
        let matrix: Vec<f64> = d.cells.iter().map(|c| c.map_or(0.0, |w| -w)).collect();
        for (r, c) in min_cost(&matrix, d.rows.len(), d.cols.len()) {
            if d.cells[r * d.cols.len() + c].is_some() {
                out.push((d.rows[r], d.cols[c]));
            }
        }
    }
    out.sort_unstable();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every assignment of `min(rows, cols)` pairs, by brute force.
    fn all_assignments(rows: usize, cols: usize) -> Vec<Vec<(usize, usize)>> {
        fn go(
            row: usize,
            rows: usize,
            cols: usize,
            used: &mut Vec<bool>,
            cur: &mut Vec<(usize, usize)>,
            out: &mut Vec<Vec<(usize, usize)>>,
            skips: usize,
        ) {
            if row == rows {
                out.push(cur.clone());
                return;
            }
            for c in 0..cols {
                if !used[c] {
                    used[c] = true;
                    cur.push((row, c));
                    go(row + 1, rows, cols, used, cur, out, skips);
                    cur.pop();
                    used[c] = false;
                }
            }
            if skips > 0 {
                go(row + 1, rows, cols, used, cur, out, skips - 1);
            }
        }
        let mut out = Vec::new();
        go(0, rows, cols, &mut vec![false; cols], &mut Vec::new(), &mut out, rows.saturating_sub(cols));
        out
    }

    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 53) as f64
    }

    #[test]
    fn dense_assignment_is_optimal() {
        let mut seed = 7;
        for rows in 1..=5 {
            for cols in 1..=5 {
                for _ in 0..20 {
                    let cost: Vec<f64> =
                        (0..rows * cols).map(|_| (lcg(&mut seed) * 20.0).round() - 5.0).collect();
                    let got = min_cost(&cost, rows, cols);
                    assert_eq!(got.len(), rows.min(cols));
                    let total =
                        |a: &[(usize, usize)]| a.iter().map(|&(r, c)| cost[r * cols + c]).sum::<f64>();
                    let best = all_assignments(rows, cols)
                        .iter()
                        .filter(|a| a.len() == rows.min(cols))
                        .map(|a| total(a))
                        .fold(f64::INFINITY, f64::min);
                    assert_eq!(total(&got), best, "{rows}x{cols} {cost:?}");
                }
            }
        }
    }

    #[test]
    fn gated_takes_most_pairs_then_least_cost() {
        // Row 0 alone would take column 0 (cost 1), leaving row 1 unmatched; two pairs win.
        let edges = [
            Edge { row: 0, col: 0, value: 1.0 },
            Edge { row: 0, col: 1, value: 2.9 },
            Edge { row: 1, col: 0, value: 2.0 },
        ];
        assert_eq!(gated(2, 2, &edges), vec![(0, 1), (1, 0)]);
        // Maximum weight prefers the single heavy pair.
        let edges = [
            Edge { row: 0, col: 0, value: 3.0 },
            Edge { row: 0, col: 1, value: 1.0 },
            Edge { row: 1, col: 0, value: 1.0 },
        ];
        assert_eq!(max_weight(2, 2, &edges), vec![(0, 0)]);
    }

    #[test]
    fn sparse_matchings_match_brute_force() {
        let mut seed = 11;
        for _ in 0..300 {
            let rows = 1 + (lcg(&mut seed) * 6.0) as usize;
            let cols = 1 + (lcg(&mut seed) * 6.0) as usize;
            let mut edges = Vec::new();
            for r in 0..rows {
                for c in 0..cols {
                    if lcg(&mut seed) < 0.4 {
                        edges.push(Edge { row: r, col: c, value: 0.01 + lcg(&mut seed) * 3.0 });
                    }
                }
            }
            let value = |r: usize, c: usize| edges.iter().find(|e| e.row == r && e.col == c).map(|e| e.value);
            // Best by brute force over every partial assignment restricted to edges.
            let mut best_gated = (0usize, f64::INFINITY);
            let mut best_weight = 0.0_f64;
            for a in all_partial(rows, cols) {
                let vals: Option<Vec<f64>> = a.iter().map(|&(r, c)| value(r, c)).collect();
                let Some(vals) = vals else { continue };
                let (n, s) = (vals.len(), vals.iter().sum::<f64>());
                if n > best_gated.0 || (n == best_gated.0 && s < best_gated.1) {
                    best_gated = (n, s);
                }
                best_weight = best_weight.max(s);
            }
            let g = gated(rows, cols, &edges);
            let gs: f64 = g.iter().map(|&(r, c)| value(r, c).unwrap()).sum();
            assert_eq!(g.len(), best_gated.0, "{edges:?}");
            assert!((gs - best_gated.1).abs() < 1e-9, "{edges:?}");
            let w = max_weight(rows, cols, &edges);
            let ws: f64 = w.iter().map(|&(r, c)| value(r, c).unwrap()).sum();
            assert!((ws - best_weight).abs() < 1e-9, "{edges:?}: {ws} vs {best_weight}");
        }
    }

    /// Every set of pairs with distinct rows and columns.
    fn all_partial(rows: usize, cols: usize) -> Vec<Vec<(usize, usize)>> {
        fn go(
            row: usize,
            rows: usize,
            cols: usize,
            used: u32,
            cur: &mut Vec<(usize, usize)>,
            out: &mut Vec<Vec<(usize, usize)>>,
        ) {
            if row == rows {
                out.push(cur.clone());
                return;
            }
            go(row + 1, rows, cols, used, cur, out);
            for c in 0..cols {
                if used & (1 << c) == 0 {
                    cur.push((row, c));
                    go(row + 1, rows, cols, used | (1 << c), cur, out);
                    cur.pop();
                }
            }
        }
        let mut out = Vec::new();
        go(0, rows, cols, 0, &mut Vec::new(), &mut out);
        out
    }
}
