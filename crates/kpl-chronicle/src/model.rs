//! A chronicle as the recogniser sees it: numbered parameters, event nodes that are patterns over
//! event sources, metric constraints between the nodes' times, and conditions between two nodes.
//! [`Chronicle::compile`] closes the network and checks what recognition needs.

use kpl_core::Time;
use thiserror::Error;

use crate::stn::{self, Minimal, Stn};

/// An event source: a predicate over objects, a monitor's verdict or a chronicle's recognitions.
/// The caller numbers them; the recogniser only compares them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SourceId(pub u32);

/// An occurrence: the source's value for the objects `args` became `value` at `time`. A predicate
/// or a verdict (a fluent) has a value between its events; a recognition is a point event with
/// `value: true`.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Event<O> {
    pub source: SourceId,
    pub args: Vec<O>,
    pub value: bool,
    pub time: Time,
}

/// A node of the chronicle: an event of `source` whose `value` is the given one, on the objects
/// bound to the parameters `args` (indices into the chronicle's parameters).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pattern {
    pub source: SourceId,
    pub args: Vec<usize>,
    pub value: bool,
}

impl Pattern {
    /// Whether `event` is one of this pattern's: its source, its value, as many objects.
    pub fn matches<O>(&self, event: &Event<O>) -> bool {
        self.source == event.source && self.value == event.value && self.args.len() == event.args.len()
    }
}

/// The fluent `source(args)` is true throughout `[time(from), time(to)]`: its last event at or
/// before `time(from)` says true, and none in `(time(from), time(to)]` says false.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Hold {
    pub source: SourceId,
    pub args: Vec<usize>,
    pub from: usize,
    pub to: usize,
}

/// No event matching `pattern` occurs strictly between `time(from)` and `time(to)`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Never {
    pub pattern: Pattern,
    pub from: usize,
    pub to: usize,
}

/// A chronicle with `params` parameters, its nodes, constraints (between node indices) and
/// conditions.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Chronicle {
    pub name: String,
    /// The source its recognitions are events of (for chronicles that use them).
    pub source: SourceId,
    pub params: usize,
    pub events: Vec<Pattern>,
    pub constraints: Vec<stn::Constraint>,
    pub holds: Vec<Hold>,
    pub nevers: Vec<Never>,
}

/// Why a chronicle cannot be recognised. `kpl check` reports the same with spans.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ModelError {
    #[error("chronicle `{0}` has no events")]
    NoEvents(String),
    #[error("chronicle `{chronicle}`: a node, condition or constraint names something out of range")]
    OutOfRange { chronicle: String },
    #[error("chronicle `{chronicle}`: parameter {param} is bound by no event")]
    Unbound { chronicle: String, param: usize },
    #[error("chronicle `{chronicle}`: its constraints cannot all hold (constraints {:?})", cycle.constraints)]
    Inconsistent { chronicle: String, cycle: stn::NegativeCycle },
    #[error("chronicle `{chronicle}`: events {0} and {1} have no bound between their times", pair.0, pair.1)]
    Unbounded { chronicle: String, pair: (usize, usize) },
    #[error("chronicle `{chronicle}`: a condition's `to` event may come before its `from` event")]
    ConditionOrder { chronicle: String },
}

/// A chronicle ready for recognition: its minimal network and its window.
#[derive(Debug, Clone)]
pub struct Compiled {
    pub chronicle: Chronicle,
    pub minimal: Minimal,
    /// The longest time between two of its events.
    pub window: Time,
}

impl Chronicle {
    /// Closes the network and checks that every parameter is bound by an event, that the network
    /// is consistent and bounded (so partial instances have deadlines), and that every condition's
    /// `from` event comes no later than its `to` event.
    pub fn compile(self) -> Result<Compiled, ModelError> {
        let name = self.name.clone();
        let n = self.events.len();
        if n == 0 {
            return Err(ModelError::NoEvents(name));
        }
        let in_range = |args: &[usize]| args.iter().all(|&a| a < self.params);
        let ok = self.events.iter().all(|p| in_range(&p.args))
            && self.constraints.iter().all(|c| c.later < n && c.earlier < n)
            && self.holds.iter().all(|h| in_range(&h.args) && h.from < n && h.to < n)
            && self.nevers.iter().all(|c| in_range(&c.pattern.args) && c.from < n && c.to < n);
        if !ok {
            return Err(ModelError::OutOfRange { chronicle: name });
        }
        if let Some(param) = (0..self.params).find(|p| !self.events.iter().any(|e| e.args.contains(p))) {
            return Err(ModelError::Unbound { chronicle: name, param });
        }
        let minimal = Stn::new(n, self.constraints.clone())
            .minimal()
            .map_err(|cycle| ModelError::Inconsistent { chronicle: name.clone(), cycle })?;
        if let Some(pair) = minimal.unbounded_pair() {
            return Err(ModelError::Unbounded { chronicle: name, pair });
        }
        let ordered = |from: usize, to: usize| minimal.lower(from, to).is_some_and(|lo| lo >= 0);
        if !self.holds.iter().all(|h| ordered(h.from, h.to))
            || !self.nevers.iter().all(|c| ordered(c.from, c.to))
        {
            return Err(ModelError::ConditionOrder { chronicle: name });
        }
        let window = minimal.window().unwrap_or(0);
        Ok(Compiled { chronicle: self, minimal, window })
    }
}
