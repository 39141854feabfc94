//! Change records: what happened to the object linkage structures at one step, with the cause.
//! A link's `changes` output carries, at each valid time with changes, a list of these records
//! (`docs/anchoring.md` has the exact shapes).

use std::fmt;
use std::sync::Arc;

use kpl_core::{Record, Time, Value};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ChangeKind {
    /// An object appeared: a percept listed by its source, an object created by a link's
    /// establish condition, or a partial object asked for by an identification.
    Created,
    /// A link was made from `from` to `symbol`.
    Linked,
    /// The link from `from` to `symbol` was removed.
    Unlinked,
    /// `symbol` (the root of a structure with no incoming link) is now predicted, or the number
    /// of its hypotheses changed.
    Predicted,
    /// `symbol` was removed.
    Removed,
    /// An identification was completed: `symbol` now stands for the object asked for by `name`.
    Identified,
}

impl ChangeKind {
    pub fn as_str(self) -> &'static str {
        match self {
            ChangeKind::Created => "created",
            ChangeKind::Linked => "linked",
            ChangeKind::Unlinked => "unlinked",
            ChangeKind::Predicted => "predicted",
            ChangeKind::Removed => "removed",
            ChangeKind::Identified => "identified",
        }
    }
}

impl fmt::Display for ChangeKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Why a change happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Cause {
    /// A percept listed by its source for the first time.
    Source,
    /// The establish condition of `link` became true for `from`.
    Establish,
    /// The reestablish condition of `link` became true for `from` and `symbol`.
    Reestablish,
    /// An identification asked for the object (created), or was completed through a link.
    Identify,
    /// An existing object satisfied an identification's description.
    Description,
    /// The maintain condition of `link` became false.
    Maintain,
    /// The linked-from object was removed.
    FromRemoved,
    /// The linked-to object was removed.
    ToRemoved,
    /// The structure has no incoming link: its state is predicted.
    NoIncomingLink,
    /// The prediction split into more hypotheses (or fewer: routes that left the map merge); a
    /// branch object was created for a new hypothesis.
    Branch,
    /// The prediction ended (every route reached a dead end or the network's border): the
    /// structure keeps its last state, unanchored, until it is forgotten or reacquired.
    Ended,
    /// A branch object whose structure was reacquired (or fed again), or whose hypothesis ended.
    Pruned,
    /// A percept no longer listed by its source.
    Lost,
    /// Not anchored for the forget time.
    Forgotten,
    /// A partial object whose identification resolved to an existing object.
    Resolved,
    /// The object went to (`removed`, `unlinked`) or came from (`created`, `linked`) another
    /// engine with its structure (`crate::handover`).
    HandedOver,
}

impl Cause {
    pub fn as_str(self) -> &'static str {
        match self {
            Cause::Source => "source",
            Cause::Establish => "establish",
            Cause::Reestablish => "reestablish",
            Cause::Identify => "identify",
            Cause::Description => "description",
            Cause::Maintain => "maintain",
            Cause::FromRemoved => "from_removed",
            Cause::ToRemoved => "to_removed",
            Cause::NoIncomingLink => "no_incoming_link",
            Cause::Branch => "branch",
            Cause::Ended => "ended",
            Cause::Lost => "lost",
            Cause::Forgotten => "forgotten",
            Cause::Resolved => "resolved",
            Cause::Pruned => "pruned",
            Cause::HandedOver => "handed_over",
        }
    }
}

/// One change.
#[derive(Debug, Clone, PartialEq)]
pub struct Change {
    pub time: Time,
    pub kind: ChangeKind,
    /// The object changed (for links: the linked-to object).
    pub symbol: Arc<str>,
    /// Its type.
    pub ty: Arc<str>,
    pub cause: Cause,
    /// The link specification involved.
    pub link: Option<Arc<str>>,
    /// The linked-from object.
    pub from: Option<Arc<str>>,
    /// `predicted`: the model; `linked` by reestablish from a predicted object: the model too.
    pub model: Option<Arc<str>>,
    /// `predicted`: the number of hypotheses; `linked`: how many the object had.
    pub hypotheses: Option<u32>,
    /// `linked`: which hypothesis (0 = most likely) the reacquired object was matched with.
    pub hypothesis: Option<u32>,
    /// `identified` and `created` by an identification: the name asked for.
    pub name: Option<Arc<str>>,
    /// `created` and `removed` of a branch object: the object whose prediction it branches from.
    pub branch_of: Option<Arc<str>>,
}

impl Change {
    pub fn new(time: Time, kind: ChangeKind, symbol: Arc<str>, ty: Arc<str>, cause: Cause) -> Change {
        Change {
            time,
            kind,
            symbol,
            ty,
            cause,
            link: None,
            from: None,
            model: None,
            hypotheses: None,
            hypothesis: None,
            name: None,
            branch_of: None,
        }
    }

    pub fn link(mut self, link: &Arc<str>) -> Change {
        self.link = Some(link.clone());
        self
    }

    pub fn from(mut self, from: &Arc<str>) -> Change {
        self.from = Some(from.clone());
        self
    }

    pub fn model(mut self, model: &str) -> Change {
        self.model = Some(Arc::from(model));
        self
    }

    pub fn hypotheses(mut self, n: usize) -> Change {
        self.hypotheses = Some(u32::try_from(n).unwrap_or(u32::MAX));
        self
    }

    pub fn hypothesis(mut self, i: u32) -> Change {
        self.hypothesis = Some(i);
        self
    }

    pub fn name(mut self, name: &Arc<str>) -> Change {
        self.name = Some(name.clone());
        self
    }

    pub fn branch_of(mut self, owner: &Arc<str>) -> Change {
        self.branch_of = Some(owner.clone());
        self
    }

    /// The record a `changes` stream carries: `kind`, `time`, `symbol`, `type`, `cause`, then
    /// `link`, `from`, `model`, `name`, `branch_of`, `hypotheses`, `hypothesis` when set.
    pub fn to_value(&self) -> Value {
        let s = |x: &str| Value::str(x);
        let mut fields: Vec<(Arc<str>, Value)> = vec![
            ("kind".into(), s(self.kind.as_str())),
            ("time".into(), Value::Int(self.time)),
            ("symbol".into(), Value::Str(self.symbol.clone())),
            ("type".into(), Value::Str(self.ty.clone())),
            ("cause".into(), s(self.cause.as_str())),
        ];
        let optional = [
            ("link", &self.link),
            ("from", &self.from),
            ("model", &self.model),
            ("name", &self.name),
            ("branch_of", &self.branch_of),
        ];
        for (name, value) in optional {
            if let Some(v) = value {
                fields.push((name.into(), Value::Str(v.clone())));
            }
        }
        if let Some(n) = self.hypotheses {
            fields.push(("hypotheses".into(), Value::Int(i64::from(n))));
        }
        if let Some(i) = self.hypothesis {
            fields.push(("hypothesis".into(), Value::Int(i64::from(i))));
        }
        Value::Record(Arc::new(Record { id: None, fields }))
    }
}

impl fmt::Display for Change {
    /// `linked wo1 <- vp2 (vision_world, reestablish)`, as the tests and logs show it.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} {}", self.kind, self.symbol)?;
        if let Some(from) = &self.from {
            write!(f, " <- {from}")?;
        }
        write!(f, " ({}", self.cause.as_str())?;
        if let Some(link) = &self.link {
            write!(f, ", {link}")?;
        }
        if let Some(model) = &self.model {
            write!(f, ", {model}")?;
        }
        if let Some(n) = self.hypotheses {
            match self.hypothesis {
                Some(i) => write!(f, ", hypothesis {} of {n}", i + 1)?,
                None => write!(f, ", {n} hypotheses")?,
            }
        }
        if let Some(name) = &self.name {
            write!(f, ", {name}")?;
        }
        if let Some(owner) = &self.branch_of {
            write!(f, ", branch of {owner}")?;
        }
        f.write_str(")")
    }
}
