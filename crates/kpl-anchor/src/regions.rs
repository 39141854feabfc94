//! Anchoring partitioned by region (issue 28: several cores, one process): one engine per cell of
//! a grid over the plane, each with the percepts of its cell, stepped side by side on worker
//! threads, and a car's structure handed from one engine to the next when it crosses a border
//! ([`crate::handover`]), so it keeps its symbols.
//!
//! One step at time t:
//!
//! 1. **Routing.** Each percept goes to the region its source's earlier snapshots put it in while
//!    it stays within that region's cell widened by the margin, and otherwise to the region of the
//!    cell it is in (a percept seen for the first time, or seen again after more than
//!    [`FORGET_ROUTE`], goes to its cell's region). The margin keeps a car that stands on a border
//!    from going back and forth.
//! 2. **Percepts move with their structures.** When a percept moves from region r to region q,
//!    its percept object in r and the structure it feeds (every object linked from it) are handed
//!    to q before the step, with the links between them and their conditions' residuals: q goes on
//!    with the car as r would have (the regions' engines share their sources, so the percept keeps
//!    its id).
//! 3. **The engines step**, each with its own percepts, on up to `workers` threads (region i on
//!    thread i mod workers). Engines share nothing, so the outputs do not depend on the number of
//!    workers: a run with 1 and with N workers is the same, change for change
//!    (`tests/regions.rs`).
//! 4. **Predicted structures that drift out.** A structure no present percept feeds whose root is
//!    outside its region's widened cell is handed to the region of its position (a car predicted
//!    across a border while unseen).
//!
//! Symbols are unique across the regions without asking: region i of n numbers its symbols i + 1
//! modulo n ([`crate::store::Numbering::region`]). Handovers happen between steps in a fixed order
//! (regions in index order, objects in creation order).

use std::sync::Arc;

use rustc_hash::FxHashMap;

use kpl_core::{Time, Value};
use kpl_semantic::hir;

use crate::engine::{AnchorConfig, Anchoring, Snapshot, StepOutput};
use crate::error::{BuildError, StepError};
use crate::records::value_position;
use crate::store::{Numbering, Origin, TypeId};

/// A percept not listed for this long is routed afresh by its position.
pub const FORGET_ROUTE: Time = 2_000_000;

/// Regions: a grid of `cols` x `rows` cells over a rectangle (points outside belong to the
/// nearest cell).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegionGrid {
    pub min: [f64; 2],
    pub max: [f64; 2],
    pub cols: u32,
    pub rows: u32,
    /// How far (metres) a percept or structure may go past its region's cell before it moves.
    pub margin: f64,
}

impl RegionGrid {
    pub fn len(&self) -> usize {
        (self.cols.max(1) * self.rows.max(1)) as usize
    }

    pub fn is_empty(&self) -> bool {
        false
    }

    fn cell_size(&self) -> [f64; 2] {
        [
            (self.max[0] - self.min[0]) / f64::from(self.cols.max(1)),
            (self.max[1] - self.min[1]) / f64::from(self.rows.max(1)),
        ]
    }

    /// The region of a point (row-major: `row * cols + col`).
    pub fn region_of(&self, p: [f64; 2]) -> usize {
        let size = self.cell_size();
        let index = |x: f64, min: f64, size: f64, n: u32| {
            let i = ((x - min) / size).floor();
            if i.is_nan() || i < 0.0 { 0 } else { (i as u64).min(u64::from(n.max(1)) - 1) as u32 }
        };
        let col = index(p[0], self.min[0], size[0], self.cols);
        let row = index(p[1], self.min[1], size[1], self.rows);
        (row * self.cols.max(1) + col) as usize
    }

    /// Whether `p` is within region `r`'s cell widened by the margin (the outer cells reach to
    /// infinity on their outer sides).
    pub fn holds(&self, r: usize, p: [f64; 2]) -> bool {
        let cols = self.cols.max(1) as usize;
        let (col, row) = ((r % cols) as f64, (r / cols) as f64);
        let size = self.cell_size();
        let within = |x: f64, min: f64, size: f64, i: f64, n: u32| {
            let lo = if i == 0.0 { f64::NEG_INFINITY } else { min + i * size - self.margin };
            let hi = if i + 1.0 >= f64::from(n.max(1)) {
                f64::INFINITY
            } else {
                min + (i + 1.0) * size + self.margin
            };
            x >= lo && x < hi
        };
        within(p[0], self.min[0], size[0], col, self.cols)
            && within(p[1], self.min[1], size[1], row, self.rows)
    }
}

/// A source's percepts: id -> (region, time last listed).
type Routes = FxHashMap<Arc<str>, (usize, Time)>;

/// Counts over a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RegionStats {
    /// Structures handed from one region to another with the percept that feeds them, or
    /// drifting out while predicted.
    pub followed: u64,
    pub drifted: u64,
    /// Handovers the receiving region refused (the structure went back where it came from).
    pub refused: u64,
    /// Percepts that moved to another region.
    pub percepts_moved: u64,
}

/// Anchoring of one spec partitioned over the regions of a grid.
#[derive(Debug)]
pub struct Regional {
    pub grid: RegionGrid,
    pub engines: Vec<Anchoring>,
    /// Per source (by name): its percepts' routes.
    routes: Vec<(Arc<str>, Routes)>,
    /// The types a structure is handed over by: those linked from percept types.
    roots: Vec<TypeId>,
    pub stats: RegionStats,
}

/// A structure leaving its region while no present percept feeds it: its root, the region of its
/// position, and the (absent) percepts linked to it, by (source, id).
struct Drift {
    ty: Arc<str>,
    symbol: Arc<str>,
    to: usize,
    percepts: Vec<(Arc<str>, Arc<str>)>,
}

/// What one step of every region produced, by region (handovers included).
#[derive(Debug, Default)]
pub struct RegionalStep {
    pub outputs: Vec<StepOutput>,
}

impl Regional {
    /// One engine per region of `grid`, each built as [`Anchoring::from_spec`] builds one with
    /// `config`, numbering its symbols as region i of n.
    pub fn from_spec(
        spec: &hir::Spec,
        config: &AnchorConfig,
        grid: RegionGrid,
    ) -> Result<Regional, BuildError> {
        let n = grid.len() as u64;
        let engines = (0..n)
            .map(|i| {
                Anchoring::from_spec(
                    spec,
                    AnchorConfig { numbering: Numbering::region(i, n), ..config.clone() },
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        // The same in every region's engine: they are built from one spec.
        let first = &engines[0];
        let mut roots: Vec<TypeId> = first
            .links
            .iter()
            .filter(|l| first.types[l.from_ty as usize].links_into.is_empty())
            .map(|l| l.to_ty)
            .collect();
        roots.sort_unstable();
        roots.dedup();
        Ok(Regional { grid, engines, routes: Vec::new(), roots, stats: RegionStats::default() })
    }

    /// The region a source's percept is in now (after the last step), if it was routed.
    pub fn region_of_percept(&self, source: &str, id: &str) -> Option<usize> {
        let (_, routes) = self.routes.iter().find(|(s, _)| &**s == source)?;
        routes.get(id).map(|(r, _)| *r)
    }

    /// The routes of a source's percepts (made when it is first seen).
    fn routes_of(&mut self, source: &str) -> usize {
        match self.routes.iter().position(|(s, _)| &**s == source) {
            Some(i) => i,
            None => {
                self.routes.push((Arc::from(source), FxHashMap::default()));
                self.routes.len() - 1
            }
        }
    }

    /// One step of every region at `time` with these snapshots of percepts, on up to `workers`
    /// threads. An error of one region's step stops the step there (the regions before it have
    /// stepped).
    pub fn step(
        &mut self,
        time: Time,
        inputs: &[Snapshot<'_>],
        workers: usize,
    ) -> Result<RegionalStep, StepError> {
        let n = self.engines.len();
        let mut outputs: Vec<StepOutput> =
            (0..n).map(|_| StepOutput { time, ..StepOutput::default() }).collect();
        // 1. Routing.
        let mut routed: Vec<Vec<Vec<Value>>> = vec![vec![Vec::new(); inputs.len()]; n];
        let mut moves: Vec<(usize, usize, &str, Arc<str>)> = Vec::new();
        for (s, input) in inputs.iter().enumerate() {
            let Value::List(items) = input.objects else {
                // Not a list: the first region's engine says so (its warning names the item).
                routed[0][s].push(input.objects.clone());
                continue;
            };
            let source = self.routes_of(input.source);
            let grid = self.grid;
            let routes = &mut self.routes[source].1;
            for item in items.iter() {
                let id = item.as_record().and_then(|r| r.id.as_ref());
                let position = value_position(item);
                let here = position.map_or(0, |p| grid.region_of(p));
                let region = match id {
                    Some(id) => match routes.get_mut(&**id) {
                        Some((r, last)) => {
                            if time - *last > FORGET_ROUTE {
                                *r = here;
                            } else if position.is_some_and(|p| !grid.holds(*r, p)) {
                                moves.push((*r, here, input.ty, id.clone()));
                                *r = here;
                            }
                            *last = time;
                            *r
                        }
                        None => {
                            routes.insert(id.clone(), (here, time));
                            here
                        }
                    },
                    None => here,
                };
                routed[region][s].push(item.clone());
            }
        }
        for (_, routes) in &mut self.routes {
            routes.retain(|_, (_, last)| time - *last <= FORGET_ROUTE);
        }
        // 2. Percepts move with their structures.
        for (from, to, ty, id) in moves {
            self.stats.percepts_moved += 1;
            let linked = !self.engines[from].chain(&id).is_empty();
            if self.move_structure(from, to, ty, &id, &mut outputs) && linked {
                self.stats.followed += 1;
            }
        }
        // 3. The engines step.
        let lists: Vec<Vec<Value>> = routed
            .into_iter()
            .map(|region| region.into_iter().map(|items| Value::List(items.into())).collect())
            .collect();
        let results = self.step_engines(time, inputs, &lists, workers);
        let mut drifts = Vec::with_capacity(n);
        for (out, (result, drift)) in outputs.iter_mut().zip(results) {
            drifts.push(drift);
            // The handovers before the step, then the step's changes.
            let mut stepped = result?;
            let mut changes = std::mem::take(&mut out.changes);
            changes.append(&mut stepped.changes);
            stepped.changes = changes;
            *out = stepped;
        }
        // 4. Predicted structures that drift out, and the routes of their absent percepts with
        // them (so that a percept seen again goes where its structure is).
        for (r, drift) in drifts.into_iter().enumerate() {
            for drift in drift {
                if self.move_structure(r, drift.to, &drift.ty, &drift.symbol, &mut outputs) {
                    self.stats.drifted += 1;
                    for (source, id) in drift.percepts {
                        let routes = self.routes.iter_mut().find(|(s, _)| *s == source);
                        if let Some(route) = routes.and_then(|(_, routes)| routes.get_mut(&id)) {
                            route.0 = drift.to;
                        }
                    }
                }
            }
        }
        Ok(RegionalStep { outputs })
    }

    /// Each region's step and, after it, the structures drifting out of it (worked out on the
    /// region's thread).
    fn step_engines(
        &mut self,
        time: Time,
        inputs: &[Snapshot<'_>],
        lists: &[Vec<Value>],
        workers: usize,
    ) -> Vec<(Result<StepOutput, StepError>, Vec<Drift>)> {
        let (grid, roots) = (self.grid, &self.roots);
        let step = |r: usize, engine: &mut Anchoring| {
            let snapshots: Vec<Snapshot<'_>> = inputs
                .iter()
                .zip(&lists[r])
                .map(|(input, objects)| Snapshot { source: input.source, ty: input.ty, objects })
                .collect();
            let result = engine.step(time, &snapshots);
            let drift = if result.is_ok() { drifting(engine, r, &grid, roots) } else { Vec::new() };
            (result, drift)
        };
        let workers = workers.clamp(1, self.engines.len().max(1));
        if workers == 1 {
            return self.engines.iter_mut().enumerate().map(|(r, engine)| step(r, engine)).collect();
        }
        // Region i on thread i mod workers; results put back in region order.
        let mut done = Vec::with_capacity(self.engines.len());
        let mut shares: Vec<Vec<(usize, &mut Anchoring)>> = (0..workers).map(|_| Vec::new()).collect();
        for (i, engine) in self.engines.iter_mut().enumerate() {
            shares[i % workers].push((i, engine));
        }
        std::thread::scope(|scope| {
            let handles: Vec<_> = shares
                .into_iter()
                .map(|share| {
                    scope.spawn(move || {
                        share.into_iter().map(|(i, engine)| (i, step(i, engine))).collect::<Vec<_>>()
                    })
                })
                .collect();
            for handle in handles {
                match handle.join() {
                    Ok(results) => done.extend(results),
                    Err(panic) => std::panic::resume_unwind(panic),
                }
            }
        });
        done.sort_by_key(|(i, _)| *i);
        done.into_iter().map(|(_, result)| result).collect()
    }

    /// Hands a structure from region `from` to `to`; refused by `to`, it goes back. Whether it
    /// moved.
    fn move_structure(
        &mut self,
        from: usize,
        to: usize,
        ty: &str,
        symbol: &str,
        outputs: &mut [StepOutput],
    ) -> bool {
        if from == to {
            return false;
        }
        let Ok((handover, out)) = self.engines[from].hand_over(ty, symbol) else { return false };
        match self.engines[to].take_over(&handover) {
            Ok(taken) => {
                outputs[from].changes.extend(out.changes);
                outputs[to].changes.extend(taken.changes);
                true
            }
            Err(_) => {
                self.stats.refused += 1;
                // It goes back: the symbols are free again where it came from.
                if let Ok(back) = self.engines[from].take_over(&handover) {
                    outputs[from].changes.extend(out.changes);
                    outputs[from].changes.extend(back.changes);
                }
                false
            }
        }
    }

    /// The structure of a source's percept (as [`Anchoring::chain`]), in the region it is in.
    pub fn chain(&self, source: &str, id: &str) -> Vec<(Arc<str>, Arc<str>)> {
        match self.region_of_percept(source, id) {
            Some(r) => self.engines[r].chain(id),
            None => Vec::new(),
        }
    }
}

/// Structures of region `r` that no present percept feeds and whose root left the region's
/// widened cell.
fn drifting(engine: &Anchoring, r: usize, grid: &RegionGrid, roots: &[TypeId]) -> Vec<Drift> {
    let mut out = Vec::new();
    for &t in roots {
        for key in engine.store.objects_of(t) {
            let Some(object) = engine.store.get(key) else { continue };
            if object.origin != Origin::Derived || object.branch_of.is_some() {
                continue;
            }
            let fed = object.incoming.iter().any(|(_, p)| engine.store.get(*p).is_some_and(|p| p.present));
            let Some(position) = value_position(&object.value) else { continue };
            if fed || grid.holds(r, position) {
                continue;
            }
            let percepts = object
                .incoming
                .iter()
                .filter_map(|(_, p)| {
                    let p = engine.store.get(*p)?;
                    let Origin::Percept { source } = p.origin else { return None };
                    Some((Arc::from(engine.source_name(source)?), p.symbol.clone()))
                })
                .collect();
            out.push(Drift {
                ty: engine.types[t as usize].name.clone(),
                symbol: object.symbol.clone(),
                to: grid.region_of(position),
                percepts,
            });
        }
    }
    out
}
