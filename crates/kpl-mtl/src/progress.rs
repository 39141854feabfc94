//! Progressing a formula through a stream: [`Progressor`] for the verdict from the first state,
//! [`EveryMonitor`] for the verdict from every state. Both own one [`Engine`] (arena, transition
//! cache) for their whole life; the engine's module doc says how a step works.

use std::collections::HashMap;
use std::sync::Arc;

use kpl_core::Time;

use crate::engine::{Engine, EngineConfig, EngineStats};
use crate::error::EvalError;
use crate::formula::Formula;
use crate::residual::{FALSE, NodeId, TRUE};
use crate::state::State;

/// The time since the previous state, or the error for a time stamp that does not increase.
pub(crate) fn elapsed(last: Option<Time>, time: Time) -> Result<u64, EvalError> {
    match last {
        None => Ok(0),
        Some(previous) if time <= previous => Err(EvalError::TimeNotIncreasing { time, previous }),
        // Between two `i64`s, so it fits a `u64`.
        Some(previous) => Ok((i128::from(time) - i128::from(previous)) as u64),
    }
}

/// Progresses one formula through a stream of states, as a monitor does for its formula. (A
/// link process, which holds thousands of instances of one condition, keeps them in a
/// [`crate::ProgressorGroup`] so that instances in the same situation share their work.)
///
/// ```
/// use std::sync::Arc;
/// use kpl_core::TimeUnit;
/// use kpl_mtl::{Context, Formula, Mtl, Progressor, SlotState, Term, Window};
///
/// let mut ctx = Context::new(TimeUnit::Ms, TimeUnit::Ms);
/// let p = ctx.declare_value("p");
/// // eventually[0, 100] p
/// let f = Formula::new(&Mtl::eventually(Window::bounded(0, 100), Mtl::atom(Term::slot(p))), &ctx).unwrap();
/// let mut progressor = Progressor::new(Arc::new(f));
/// assert_eq!(progressor.step(0, &SlotState::bools(&[false])).unwrap(), None);
/// // Time jumps past the window: decided at once.
/// assert_eq!(progressor.step(250, &SlotState::bools(&[true])).unwrap(), Some(false));
/// assert_eq!(progressor.decided_at(), Some(250));
/// ```
#[derive(Debug)]
pub struct Progressor {
    engine: Engine,
    /// The residual before the first state (the formula itself).
    start: NodeId,
    root: NodeId,
    last_time: Option<Time>,
    verdict: Option<bool>,
    decided_at: Option<Time>,
}

impl Progressor {
    pub fn new(formula: Arc<Formula>) -> Progressor {
        Progressor::with_config(formula, EngineConfig::default())
    }

    pub fn with_config(formula: Arc<Formula>, config: EngineConfig) -> Progressor {
        let mut engine = Engine::new(formula, config);
        let start = engine.start();
        Progressor { engine, start, root: start, last_time: None, verdict: None, decided_at: None }
    }

    pub fn formula(&self) -> &Arc<Formula> {
        &self.engine.formula
    }

    /// Progresses through the state at `time` (strictly after the previous state's). Returns the
    /// verdict once it is certain; afterwards further states change nothing. On error nothing
    /// changes: the state was not consumed.
    pub fn step<S: State + ?Sized>(&mut self, time: Time, state: &S) -> Result<Option<bool>, EvalError> {
        let d = elapsed(self.last_time, time)?;
        if self.verdict.is_some() {
            self.last_time = Some(time);
            return Ok(self.verdict);
        }
        self.engine.begin_state();
        self.root = self.engine.progress(self.root, d, state)?;
        self.last_time = Some(time);
        if self.root <= FALSE {
            self.verdict = Some(self.root == TRUE);
            self.decided_at = Some(time);
        }
        if self.engine.should_collect() {
            let mut roots = [self.root, self.start];
            self.engine.collect(&mut roots);
            [self.root, self.start] = roots;
        }
        Ok(self.verdict)
    }

    /// Ends the stream: what is still open is closed with finite-trace semantics (an
    /// `eventually` or `until` not yet satisfied is false, an `always` not yet violated is true).
    /// `None` when no state was ever given.
    pub fn finish(&mut self) -> Option<bool> {
        if self.verdict.is_none() {
            self.last_time?;
            self.verdict = Some(self.engine.close(self.root));
        }
        self.verdict
    }

    /// The verdict, once certain (or once [`Progressor::finish`] closed the stream).
    pub fn verdict(&self) -> Option<bool> {
        self.verdict
    }

    /// The time of the state at which the verdict became certain; `None` before that, and when
    /// it was decided only by the end of the stream.
    pub fn decided_at(&self) -> Option<Time> {
        self.decided_at
    }

    /// The time of the last state progressed through.
    pub fn last_time(&self) -> Option<Time> {
        self.last_time
    }

    /// Number of distinct nodes of the residual (hash-consed: a shared sub-residual counts once;
    /// a decided formula has size 1; 0 before the first state).
    pub fn residual_size(&self) -> usize {
        self.engine.arena.size(std::iter::once(self.root))
    }

    /// The residual as text, windows relative to the last state's time.
    pub fn residual(&self) -> String {
        let mut out = String::new();
        let _ = self.engine.arena.write(&self.engine.formula, &mut out, self.root);
        out
    }

    /// Starts over, as if no state had been given. What the engine learnt (its arena and
    /// transition cache) is kept.
    pub fn reset(&mut self) {
        self.root = self.start;
        self.last_time = None;
        self.verdict = None;
        self.decided_at = None;
    }

    /// What the engine did so far (steps, transition cache hits and misses, collections).
    pub fn stats(&self) -> EngineStats {
        self.engine.stats
    }
}

/// The verdict of the formula evaluated from one state of the stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StartVerdict {
    /// The index of the state the formula is evaluated from (0 for the first state).
    pub start: usize,
    pub verdict: bool,
    /// The time of the state at which the verdict became certain; `None` when only the end of the
    /// stream decided it.
    pub decided_at: Option<Time>,
}

/// The starts of the instances that share one residual, as ranges `[from, to)` of state indices.
type Starts = Vec<(usize, usize)>;

fn push_start(starts: &mut Starts, start: usize) {
    match starts.last_mut() {
        Some((_, to)) if *to == start => *to += 1,
        _ => starts.push((start, start + 1)),
    }
}

/// Evaluates a formula from every state of a stream (`kpl mtl eval --every`, and monitors that
/// emit one verdict per state). All instances share one arena, so instances whose residuals
/// are equal (as for `always p` started at different states) are one node and are progressed
/// once; an instance is kept only until its verdict is certain, so memory follows the number of
/// distinct open residuals, not the length of the stream.
#[derive(Debug)]
pub struct EveryMonitor {
    engine: Engine,
    start: NodeId,
    /// Undecided instances, grouped by residual.
    groups: Vec<(NodeId, Starts)>,
    states: usize,
    last_time: Option<Time>,
    new_roots: Vec<NodeId>,
    index: HashMap<NodeId, usize>,
}

impl EveryMonitor {
    pub fn new(formula: Arc<Formula>) -> EveryMonitor {
        EveryMonitor::with_config(formula, EngineConfig::default())
    }

    pub fn with_config(formula: Arc<Formula>, config: EngineConfig) -> EveryMonitor {
        let mut engine = Engine::new(formula, config);
        let start = engine.start();
        EveryMonitor {
            engine,
            start,
            groups: Vec::new(),
            states: 0,
            last_time: None,
            new_roots: Vec::new(),
            index: HashMap::new(),
        }
    }

    /// Progresses every open instance through the state at `time` and starts one at it; pushes
    /// the verdicts that became certain to `decided`. On error nothing changes.
    pub fn step<S: State + ?Sized>(
        &mut self,
        time: Time,
        state: &S,
        decided: &mut Vec<StartVerdict>,
    ) -> Result<(), EvalError> {
        let d = elapsed(self.last_time, time)?;
        self.engine.begin_state();
        self.new_roots.clear();
        for (root, _) in &self.groups {
            let next = self.engine.progress(*root, d, state)?;
            self.new_roots.push(next);
        }
        let fresh = self.engine.progress(self.start, 0, state)?;

        let mut groups = std::mem::take(&mut self.groups);
        groups.push((NodeId::MAX, vec![(self.states, self.states + 1)]));
        self.new_roots.push(fresh);
        self.index.clear();
        let mut kept: Vec<(NodeId, Starts)> = Vec::with_capacity(groups.len());
        for ((_, mut starts), root) in groups.into_iter().zip(self.new_roots.iter().copied()) {
            if root <= FALSE {
                for (from, to) in starts {
                    decided.extend((from..to).map(|start| StartVerdict {
                        start,
                        verdict: root == TRUE,
                        decided_at: Some(time),
                    }));
                }
                continue;
            }
            match self.index.get(&root) {
                Some(&i) => {
                    // Merge the smaller list into the larger one.
                    if kept[i].1.len() < starts.len() {
                        std::mem::swap(&mut kept[i].1, &mut starts);
                    }
                    for (from, to) in starts {
                        if from + 1 == to {
                            push_start(&mut kept[i].1, from);
                        } else {
                            kept[i].1.push((from, to));
                        }
                    }
                }
                None => {
                    self.index.insert(root, kept.len());
                    kept.push((root, starts));
                }
            }
        }
        self.groups = kept;
        self.states += 1;
        self.last_time = Some(time);
        if self.engine.should_collect() {
            let mut roots: Vec<NodeId> = self.groups.iter().map(|(root, _)| *root).collect();
            roots.push(self.start);
            self.engine.collect(&mut roots);
            self.start = roots[roots.len() - 1];
            for ((root, _), new) in self.groups.iter_mut().zip(roots) {
                *root = new;
            }
        }
        Ok(())
    }

    /// Ends the stream: closes every open instance with finite-trace semantics and pushes its
    /// verdict. The monitor is then empty (and may go on with later states as a new stream would
    /// not; create a new one for that).
    pub fn finish(&mut self, decided: &mut Vec<StartVerdict>) {
        for (root, starts) in self.groups.drain(..) {
            let verdict = self.engine.close(root);
            for (from, to) in starts {
                decided.extend((from..to).map(|start| StartVerdict { start, verdict, decided_at: None }));
            }
        }
    }

    /// Number of distinct residual nodes over all open instances.
    pub fn residual_size(&self) -> usize {
        self.engine.arena.size(self.groups.iter().map(|(root, _)| *root))
    }

    /// Number of open (undecided) instances.
    pub fn open_instances(&self) -> usize {
        self.groups.iter().flat_map(|(_, s)| s.iter()).map(|(from, to)| to - from).sum()
    }

    /// What the engine did so far.
    pub fn stats(&self) -> EngineStats {
        self.engine.stats
    }
}
