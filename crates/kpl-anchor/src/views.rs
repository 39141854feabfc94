//! What the engine shows: the snapshot of a type (a link's output stream), the world model (every
//! object with its state and status), read-only views of objects and link instances, and
//! [`Anchoring::describe`], a one-line-per-object text of the structures that tests compare.

use std::fmt::Write as _;
use std::sync::Arc;

use kpl_core::{Record, Time, Value};

use crate::engine::Anchoring;
use crate::link::InstanceState;
use crate::status;
use crate::store::{Object, ObjectKey, Origin};

/// How an object's state is known.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Status {
    /// Grounded in at least one percept.
    Anchored,
    /// Not grounded; its state comes from a prediction model.
    Predicted,
    /// Not grounded and not predicted (its type and structure have no model): its last state.
    Unanchored,
    /// Asked for by an identification, not completed: no state.
    Partial,
}

impl Status {
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Anchored => "anchored",
            Status::Predicted => "predicted",
            Status::Unanchored => "unanchored",
            Status::Partial => "partial",
        }
    }
}

/// One object as the world model shows it.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectView {
    pub symbol: Arc<str>,
    pub ty: Arc<str>,
    pub status: Status,
    pub anchored: bool,
    /// Its state derives, through links, from a percept sample of its valid time.
    pub measured: bool,
    pub predicted: bool,
    /// Since when it has not been measured (`None` while measured).
    pub predicted_since: Option<Time>,
    pub state: Value,
    /// All prediction hypotheses when there are several (`state` is the first).
    pub hypotheses: Vec<Value>,
    /// (link, symbol) of the objects linked to this one.
    pub from: Vec<(Arc<str>, Arc<str>)>,
    /// (link, symbol) of the objects this one is linked to.
    pub to: Vec<(Arc<str>, Arc<str>)>,
    pub last_anchored: Time,
    pub names: Vec<Arc<str>>,
}

/// A link instance as tests and tools see it: `None` verdicts are pending.
#[derive(Debug, Clone, PartialEq)]
pub enum InstanceView {
    Unlinked {
        establish: Option<bool>,
        /// (candidate symbol, reestablish verdict)
        candidates: Vec<(Arc<str>, Option<bool>)>,
        /// (identification name, verdict)
        identifications: Vec<(Arc<str>, Option<bool>)>,
    },
    Linked {
        to: Arc<str>,
        maintain: Option<bool>,
    },
}

fn verdict_text(v: Option<bool>) -> &'static str {
    match v {
        None => "?",
        Some(true) => "true",
        Some(false) => "false",
    }
}

impl Anchoring {
    fn status(&self, object: &Object) -> Status {
        match object.origin {
            Origin::Partial => Status::Partial,
            _ if object.anchored => Status::Anchored,
            _ if object.predicted => Status::Predicted,
            _ => Status::Unanchored,
        }
    }

    fn view(&self, object: &Object) -> ObjectView {
        let symbol_of =
            |k: ObjectKey| self.store.get(k).map(|o| o.symbol.clone()).unwrap_or_else(|| Arc::from("?"));
        let link_name = |l: u32| self.links[l as usize].name.clone();
        ObjectView {
            symbol: object.symbol.clone(),
            ty: self.types[object.ty as usize].name.clone(),
            status: self.status(object),
            anchored: object.anchored,
            measured: object.measured,
            predicted: object.predicted,
            predicted_since: object.predicted_since,
            state: object.value.clone(),
            hypotheses: object.hypotheses.clone(),
            from: object.incoming.iter().map(|(l, k)| (link_name(*l), symbol_of(*k))).collect(),
            to: object.outgoing.iter().map(|(l, k)| (link_name(*l), symbol_of(*k))).collect(),
            last_anchored: object.last_anchored,
            names: object.names.clone(),
        }
    }

    /// Every object, by type in the order of the hierarchy, then creation order.
    pub fn objects(&self) -> Vec<ObjectView> {
        self.type_order
            .iter()
            .flat_map(|t| self.store.objects_of(*t))
            .filter_map(|k| self.store.get(k))
            .map(|o| self.view(o))
            .collect()
    }

    /// The object of type `ty` with this symbol.
    pub fn object(&self, ty: &str, symbol: &str) -> Option<ObjectView> {
        let ty = self.type_id(ty)?;
        self.store.by_symbol(ty, symbol).and_then(|k| self.store.get(k)).map(|o| self.view(o))
    }

    /// The object with this symbol, whatever its type.
    pub fn find(&self, symbol: &str) -> Option<ObjectView> {
        self.type_order
            .iter()
            .find_map(|t| self.store.by_symbol(*t, symbol))
            .and_then(|k| self.store.get(k))
            .map(|o| self.view(o))
    }

    /// The percepts a structure is grounded in: the percepts from which links lead to `symbol`.
    pub fn grounded_in(&self, symbol: &str) -> Vec<Arc<str>> {
        let Some(start) = self.type_order.iter().find_map(|t| self.store.by_symbol(*t, symbol)) else {
            return Vec::new();
        };
        let mut out = Vec::new();
        let mut stack = vec![start];
        let mut seen = Vec::new();
        while let Some(key) = stack.pop() {
            if seen.contains(&key) {
                continue;
            }
            seen.push(key);
            let Some(object) = self.store.get(key) else { continue };
            if matches!(object.origin, Origin::Percept { .. }) {
                out.push(object.symbol.clone());
            }
            stack.extend(object.incoming.iter().map(|(_, k)| *k));
        }
        out.sort();
        out
    }

    /// The objects reached from the object `symbol` by following links (the first link out of
    /// each): (type, symbol), not including the start. From a percept: its world object, on-road
    /// object, car.
    pub fn chain(&self, symbol: &str) -> Vec<(Arc<str>, Arc<str>)> {
        let Some(mut key) = self.type_order.iter().find_map(|t| self.store.by_symbol(*t, symbol)) else {
            return Vec::new();
        };
        let mut out = Vec::new();
        for _ in 0..self.types.len() {
            let Some(next) = self.store.get(key).and_then(|o| o.outgoing.first()).map(|(_, k)| *k) else {
                break;
            };
            let Some(object) = self.store.get(next) else { break };
            out.push((self.types[object.ty as usize].name.clone(), object.symbol.clone()));
            key = next;
        }
        out
    }

    /// The snapshot of a type at the last step: the states of its objects (not partial ones), in
    /// creation order, each a record whose `id` is the symbol. This is what a link into the type
    /// outputs. `None` for an unknown type.
    pub fn snapshot(&self, ty: &str) -> Option<Value> {
        let ty = self.type_id(ty)?;
        let items: Vec<Value> = self
            .store
            .objects_of(ty)
            .filter_map(|k| self.store.get(k))
            .filter(|o| !o.is_partial())
            .map(|o| o.value.clone())
            .collect();
        Some(Value::List(items.into()))
    }

    /// The world model: one record per object (`docs/anchoring.md`: `id`, `type`, `status`,
    /// `anchored`, `measured`, `predicted`, `predicted_since` when not measured, `state`, `from`,
    /// `to`, `grounded_in`,
    /// `last_anchored`, and `hypotheses` / `names` when there are any).
    pub fn world_model(&self) -> Value {
        let symbols = |list: &[(Arc<str>, Arc<str>)]| {
            Value::List(list.iter().map(|(_, s)| Value::Str(s.clone())).collect())
        };
        let items: Vec<Value> = self
            .objects()
            .into_iter()
            .map(|v| {
                let mut fields: Vec<(Arc<str>, Value)> = vec![
                    ("type".into(), Value::Str(v.ty.clone())),
                    ("status".into(), Value::str(v.status.as_str())),
                    ("anchored".into(), Value::Bool(v.anchored)),
                    ("measured".into(), Value::Bool(v.measured)),
                    ("predicted".into(), Value::Bool(v.predicted)),
                ];
                if let Some(since) = v.predicted_since.filter(|_| !v.measured) {
                    fields.push(("predicted_since".into(), Value::Int(since)));
                }
                // A branch of a prediction: how likely, and of which object.
                for name in [status::LIKELIHOOD, status::BRANCH_OF] {
                    if let Some(value) = v.state.as_record().and_then(|r| r.get(name)) {
                        fields.push((name.into(), value.clone()));
                    }
                }
                fields.extend([
                    ("state".into(), state_without_id(&v.state)),
                    ("from".into(), symbols(&v.from)),
                    ("to".into(), symbols(&v.to)),
                    (
                        "grounded_in".into(),
                        Value::List(self.grounded_in(&v.symbol).into_iter().map(Value::Str).collect()),
                    ),
                    ("last_anchored".into(), Value::Int(v.last_anchored)),
                ]);
                if !v.hypotheses.is_empty() {
                    fields.push((
                        "hypotheses".into(),
                        Value::List(v.hypotheses.iter().map(state_without_id).collect()),
                    ));
                }
                if !v.names.is_empty() {
                    fields.push((
                        "names".into(),
                        Value::List(v.names.iter().cloned().map(Value::Str).collect()),
                    ));
                }
                Value::Record(Arc::new(Record { id: Some(v.symbol.clone()), fields }))
            })
            .collect();
        Value::List(items.into())
    }

    /// The instance of link `link` for the object `from` (by symbol).
    pub fn instance(&self, link: &str, from: &str) -> Option<InstanceView> {
        let process = self.links.iter().find(|l| &*l.name == link)?;
        let key = self.store.by_symbol(process.from_ty, from)?;
        let instance = process.instance(key)?;
        let symbol_of =
            |k: ObjectKey| self.store.get(k).map(|o| o.symbol.clone()).unwrap_or_else(|| Arc::from("?"));
        Some(match &instance.state {
            InstanceState::Linked { to, maintain } => {
                InstanceView::Linked { to: symbol_of(*to), maintain: maintain.verdict() }
            }
            InstanceState::Unlinked(u) => InstanceView::Unlinked {
                establish: u.establish.verdict(),
                candidates: u
                    .candidates
                    .iter()
                    .filter(|c| self.store.get(c.to).is_some())
                    .map(|c| (symbol_of(c.to), c.condition.verdict()))
                    .collect(),
                identifications: u
                    .identifications
                    .iter()
                    .map(|(i, c)| (self.identifications[*i].name.clone(), c.verdict()))
                    .collect(),
            },
        })
    }

    /// The structures as text, one line per object (by type in hierarchy order, then creation
    /// order): its symbol, status (`anchored`, `predicted`, `unanchored`, `partial`), the number of
    /// hypotheses when several, its names, then for each link out of its type the instance:
    /// `link: -> wo1 maintain ?` when linked, `link: establish ?, reestablish wo1 ?` when not
    /// (`?` pending, `true`, `false`).
    pub fn describe(&self) -> String {
        let mut text = String::new();
        for &ty in &self.type_order {
            for key in self.store.objects_of(ty) {
                let Some(object) = self.store.get(key) else { continue };
                let _ = write!(text, "{} {}", object.symbol, self.status(object).as_str());
                if let Some(owner) = object.branch_of.and_then(|o| self.store.get(o)) {
                    let _ = write!(text, " (branch of {})", owner.symbol);
                }
                if object.hypotheses.len() > 1 {
                    let _ = write!(text, " ({} hypotheses)", object.hypotheses.len());
                }
                if !object.names.is_empty() {
                    let names: Vec<&str> = object.names.iter().map(|n| &**n).collect();
                    let _ = write!(text, " [{}]", names.join(", "));
                }
                for link in self.links.iter().filter(|l| l.from_ty == ty) {
                    let _ = write!(text, " | {}: ", link.name);
                    match self.instance(&link.name, &object.symbol) {
                        None => text.push_str("not started"),
                        Some(InstanceView::Linked { to, maintain }) => {
                            let _ = write!(text, "-> {to} maintain {}", verdict_text(maintain));
                        }
                        Some(InstanceView::Unlinked { establish, candidates, identifications }) => {
                            let _ = write!(text, "establish {}", verdict_text(establish));
                            for (symbol, v) in candidates {
                                let _ = write!(text, ", reestablish {symbol} {}", verdict_text(v));
                            }
                            for (name, v) in identifications {
                                let _ = write!(text, ", identify {name} {}", verdict_text(v));
                            }
                        }
                    }
                }
                text.push('\n');
            }
        }
        text
    }
}

/// An object's state as the world model shows it: its attributes, without `id` and the status
/// attributes (the world model's record has those itself).
fn state_without_id(value: &Value) -> Value {
    match value {
        Value::Record(r) => {
            let fields = r.fields.iter().filter(|(name, _)| !status::is_status(name)).cloned().collect();
            Value::Record(Arc::new(Record { id: None, fields }))
        }
        other => other.clone(),
    }
}
