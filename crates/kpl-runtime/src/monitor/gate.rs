//! The gate of a pair monitor (`forall a: Car . forall b: Car . φ`): a distance read off φ's
//! top-level conjuncts (`close(a, b, d)`, `xydist(a, b) < d`, `dist(a.pos, b.pos) <= d`) beyond
//! which φ is false at once, so only pairs within it are progressed; and the grid that finds
//! them, so the cost grows with the number of objects and their neighbours, not with the number
//! of pairs.

use std::collections::HashMap;

use kpl_syntax::ast::{self, BinaryOp, ExprKind};

/// What `close(a, b, d)` adds to `d` for the gate: `close` measures along the road, between the
/// centres of lanes that may lie side by side (a gate is a straight-line distance).
pub const CLOSE_LATERAL_MARGIN_M: f64 = 15.0;

/// The gate distance of a body over the variables `a` and `b`, if one of its top-level conjuncts
/// requires the two to be within a distance.
pub fn pair_gate(body: &ast::Expr, a: &str, b: &str) -> Option<f64> {
    let conjuncts: Vec<&ast::Expr> = match &body.kind {
        ExprKind::And(items) => items.iter().collect(),
        _ => vec![body],
    };
    conjuncts.into_iter().filter_map(|c| conjunct_gate(c, a, b)).reduce(f64::min)
}

fn conjunct_gate(expr: &ast::Expr, a: &str, b: &str) -> Option<f64> {
    match &expr.kind {
        ExprKind::Call { func, args } if func.name == "close" && args.len() == 3 => {
            let d = number(&args[2])?;
            names_both(&args[0], &args[1], a, b).then_some(d + CLOSE_LATERAL_MARGIN_M)
        }
        ExprKind::Binary { op, lhs, rhs } => {
            let (distance, bound) = match op {
                BinaryOp::Lt | BinaryOp::Le => (lhs, rhs),
                BinaryOp::Gt | BinaryOp::Ge => (rhs, lhs),
                _ => return None,
            };
            let d = number(bound)?;
            let ExprKind::Call { func, args } = &distance.kind else { return None };
            ((func.name == "xydist" || func.name == "dist")
                && args.len() == 2
                && names_both(&args[0], &args[1], a, b))
            .then_some(d)
        }
        _ => None,
    }
}

fn number(expr: &ast::Expr) -> Option<f64> {
    match &expr.kind {
        ExprKind::Number(n) => Some(n.as_f64()).filter(|d| d.is_finite() && *d >= 0.0),
        _ => None,
    }
}

/// `x` and `y` name the two variables (or their `pos`), in either order.
fn names_both(x: &ast::Expr, y: &ast::Expr, a: &str, b: &str) -> bool {
    match (var_of(x), var_of(y)) {
        (Some(x), Some(y)) => (x == a && y == b) || (x == b && y == a),
        _ => false,
    }
}

fn var_of(expr: &ast::Expr) -> Option<&str> {
    let ExprKind::Path(path) = &expr.kind else { return None };
    match path.segments.as_slice() {
        [var] => Some(var.name.as_str()),
        [var, pos] if pos.name == "pos" => Some(var.name.as_str()),
        _ => None,
    }
}

/// Positions in square cells one gate wide: the neighbours of a point are in its cell and the
/// eight around it.
#[derive(Debug, Default)]
pub struct Grid {
    radius: f64,
    cells: HashMap<(i64, i64), Vec<usize>>,
}

impl Grid {
    pub fn new(radius: f64) -> Grid {
        Grid { radius: radius.max(1e-3), cells: HashMap::new() }
    }

    fn cell(&self, p: [f64; 2]) -> (i64, i64) {
        let c = |x: f64| (x / self.radius).floor().clamp(-1e15, 1e15) as i64;
        (c(p[0]), c(p[1]))
    }

    pub fn insert(&mut self, item: usize, p: [f64; 2]) {
        if p[0].is_finite() && p[1].is_finite() {
            let cell = self.cell(p);
            self.cells.entry(cell).or_default().push(item);
        }
    }

    /// The items within the gate of `p` (by the positions `at` gives), in no particular order.
    pub fn near(&self, p: [f64; 2], at: impl Fn(usize) -> Option<[f64; 2]>, out: &mut Vec<usize>) {
        if !(p[0].is_finite() && p[1].is_finite()) {
            return;
        }
        let (cx, cy) = self.cell(p);
        for dx in -1..=1 {
            for dy in -1..=1 {
                let Some(items) = self.cells.get(&(cx + dx, cy + dy)) else { continue };
                for &item in items {
                    if at(item).is_some_and(|q| (q[0] - p[0]).hypot(q[1] - p[1]) <= self.radius) {
                        out.push(item);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;

    fn gate(formula: &str) -> Option<f64> {
        let formula = kpl_syntax::parse_formula(formula).unwrap();
        let ExprKind::Quantified { body, .. } = &formula.kind else { panic!() };
        let ExprKind::Quantified { body, .. } = &body.kind else { panic!() };
        pair_gate(body, "a", "b")
    }

    #[test]
    fn gates_are_read_off_top_level_conjuncts() {
        assert_eq!(gate("forall a: Car . forall b: Car . close(a, b, 50.0) and behind(a, b)"), Some(65.0));
        assert_eq!(gate("forall a: Car . forall b: Car . xydist(a.pos, b.pos) < 30.0 and p"), Some(30.0));
        assert_eq!(gate("forall a: Car . forall b: Car . 20 > dist(b, a)"), Some(20.0));
        assert_eq!(
            gate("forall a: Car . forall b: Car . close(a, b, 50.0) and xydist(a, b) < 10"),
            Some(10.0)
        );
        // Under a temporal operator, negated, or in a disjunction: no gate.
        assert_eq!(gate("forall a: Car . forall b: Car . eventually close(a, b, 50.0)"), None);
        assert_eq!(gate("forall a: Car . forall b: Car . close(a, b, 50.0) or p"), None);
        assert_eq!(gate("forall a: Car . forall b: Car . not (xydist(a, b) > 5)"), None);
        assert_eq!(gate("forall a: Car . forall b: Car . close(a, c, 50.0)"), None);
    }

    #[test]
    fn the_grid_finds_exactly_the_neighbours() {
        let points: Vec<[f64; 2]> =
            (0..200).map(|i| [(i * 37 % 101) as f64 * 3.1, (i * 53 % 97) as f64 * 2.7]).collect();
        let mut grid = Grid::new(12.0);
        for (i, p) in points.iter().enumerate() {
            grid.insert(i, *p);
        }
        for p in &points {
            let mut near = Vec::new();
            grid.near(*p, |i| points.get(i).copied(), &mut near);
            near.sort_unstable();
            let brute: Vec<usize> = (0..points.len())
                .filter(|&i| (points[i][0] - p[0]).hypot(points[i][1] - p[1]) <= 12.0)
                .collect();
            assert_eq!(near, brute);
        }
    }
}
