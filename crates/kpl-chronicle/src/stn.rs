//! Simple temporal networks: metric constraints `lo <= t(later) - t(earlier) <= hi` between event
//! times, their consistency and their minimal network by shortest paths over the distance graph.
//!
//! The distance graph has an edge `earlier -> later` of weight `hi` and an edge `later -> earlier`
//! of weight `-lo` per constraint. The network is consistent iff that graph has no negative cycle
//! (Dechter, Meiri and Pearl); then the shortest distance `d[i][j]` is the tightest upper bound of
//! `t(j) - t(i)` that the constraints imply (Floyd-Warshall, `O(n^3)` for `n` events). When it is
//! inconsistent, Bellman-Ford from a virtual source finds one negative cycle, reported as the
//! constraints that form it.
//!
//! ```
//! use kpl_chronicle::stn::{Constraint, Stn};
//! let s = 1_000_000; // one second in microseconds
//! let c = |later, earlier, lo, hi| Constraint { later, earlier, lo: Some(lo), hi: Some(hi) };
//! let net = Stn::new(3, vec![c(1, 0, s, 10 * s), c(2, 1, s, 10 * s)]);
//! let minimal = net.minimal().unwrap();
//! assert_eq!(minimal.upper(0, 2), Some(20 * s)); // t2 - t0 <= 20 s
//! assert_eq!(minimal.lower(0, 2), Some(2 * s)); // t2 - t0 >= 2 s
//! let tight = Stn::new(3, vec![c(1, 0, s, 10 * s), c(2, 1, s, 10 * s), c(2, 0, 0, s)]);
//! assert_eq!(tight.minimal().unwrap_err().constraints, vec![0, 1, 2]);
//! ```

use kpl_core::Time;

/// `lo <= t(later) - t(earlier) <= hi`; `None` is an infinite bound (`-inf` for `lo`, `inf` for
/// `hi`). Events are numbered `0..n`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Constraint {
    pub later: usize,
    pub earlier: usize,
    pub lo: Option<Time>,
    pub hi: Option<Time>,
}

/// A network of `n` events and the constraints between them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stn {
    pub n: usize,
    pub constraints: Vec<Constraint>,
}

/// The constraints (indices into [`Stn::constraints`]) on a negative cycle of the distance graph:
/// together they cannot all hold.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NegativeCycle {
    /// Sorted, each once.
    pub constraints: Vec<usize>,
}

/// The minimal network of a consistent [`Stn`]: for every pair, the tightest bounds implied.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Minimal {
    n: usize,
    /// `d[i * n + j]`: the least upper bound of `t(j) - t(i)`, `None` when unbounded.
    d: Vec<Option<Time>>,
}

/// One edge of the distance graph: `t(to) - t(from) <= weight`, from constraint `constraint`.
struct Edge {
    from: usize,
    to: usize,
    weight: Time,
    constraint: usize,
}

impl Stn {
    pub fn new(n: usize, constraints: Vec<Constraint>) -> Stn {
        Stn { n, constraints }
    }

    fn edges(&self) -> Vec<Edge> {
        let mut edges = Vec::new();
        for (k, c) in self.constraints.iter().enumerate() {
            if let Some(hi) = c.hi {
                edges.push(Edge { from: c.earlier, to: c.later, weight: hi, constraint: k });
            }
            if let Some(lo) = c.lo {
                edges.push(Edge { from: c.later, to: c.earlier, weight: lo.saturating_neg(), constraint: k });
            }
        }
        edges
    }

    /// The minimal network, or the constraints on a negative cycle if the network is inconsistent.
    /// Constraints naming an event `>= n` are ignored (the caller checks names).
    pub fn minimal(&self) -> Result<Minimal, NegativeCycle> {
        let n = self.n;
        let mut d: Vec<Option<Time>> = vec![None; n * n];
        for i in 0..n {
            d[i * n + i] = Some(0);
        }
        for e in self.edges().iter().filter(|e| e.from < n && e.to < n) {
            let slot = &mut d[e.from * n + e.to];
            *slot = Some(slot.map_or(e.weight, |w| w.min(e.weight)));
        }
        for k in 0..n {
            for i in 0..n {
                let Some(ik) = d[i * n + k] else { continue };
                for j in 0..n {
                    if let Some(kj) = d[k * n + j] {
                        let through = ik.saturating_add(kj);
                        let slot = &mut d[i * n + j];
                        if slot.is_none_or(|w| through < w) {
                            *slot = Some(through);
                        }
                    }
                }
            }
        }
        if (0..n).any(|i| d[i * n + i].is_some_and(|w| w < 0)) {
            return Err(self.negative_cycle());
        }
        Ok(Minimal { n, d })
    }

    /// Bellman-Ford from a virtual source joined to every event by a zero edge; the last edge
    /// relaxed in round `n + 1` leads back into a negative cycle. Only called when one exists.
    fn negative_cycle(&self) -> NegativeCycle {
        let n = self.n;
        let edges: Vec<Edge> = self.edges().into_iter().filter(|e| e.from < n && e.to < n).collect();
        let mut dist: Vec<Time> = vec![0; n];
        let mut pred: Vec<Option<usize>> = vec![None; n];
        let mut last = None;
        for _ in 0..=n {
            last = None;
            for (index, e) in edges.iter().enumerate() {
                let through = dist[e.from].saturating_add(e.weight);
                if through < dist[e.to] {
                    dist[e.to] = through;
                    pred[e.to] = Some(index);
                    last = Some(e.to);
                }
            }
            if last.is_none() {
                break;
            }
        }
        let Some(mut v) = last else { return NegativeCycle { constraints: Vec::new() } };
        // Walk back n steps to be sure to stand on the cycle, then collect it.
        for _ in 0..n {
            if let Some(p) = pred[v] {
                v = edges[p].from;
            }
        }
        let start = v;
        let mut constraints = Vec::new();
        for _ in 0..=n {
            let Some(p) = pred[v] else { break };
            constraints.push(edges[p].constraint);
            v = edges[p].from;
            if v == start {
                break;
            }
        }
        constraints.sort_unstable();
        constraints.dedup();
        NegativeCycle { constraints }
    }
}

impl Minimal {
    /// The number of events.
    pub fn len(&self) -> usize {
        self.n
    }
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }
    /// The least upper bound of `t(j) - t(i)`, `None` when unbounded.
    pub fn upper(&self, i: usize, j: usize) -> Option<Time> {
        self.d[i * self.n + j]
    }
    /// The greatest lower bound of `t(j) - t(i)`, `None` when unbounded (`-inf`).
    pub fn lower(&self, i: usize, j: usize) -> Option<Time> {
        self.d[j * self.n + i].map(Time::saturating_neg)
    }
    /// Whether `t(j) - t(i) = delta` is allowed.
    pub fn allows(&self, i: usize, j: usize, delta: Time) -> bool {
        self.upper(i, j).is_none_or(|hi| delta <= hi) && self.lower(i, j).is_none_or(|lo| delta >= lo)
    }
    /// A pair of events with no upper bound between their times, if any: a partial instance
    /// holding one of them could wait for the other forever.
    pub fn unbounded_pair(&self) -> Option<(usize, usize)> {
        (0..self.n).flat_map(|i| (0..self.n).map(move |j| (i, j))).find(|&(i, j)| self.upper(i, j).is_none())
    }
    /// The longest time between two of the events (the network's window), `None` if unbounded.
    pub fn window(&self) -> Option<Time> {
        self.d.iter().try_fold(0, |acc: Time, w| w.map(|w| acc.max(w)))
    }
}
