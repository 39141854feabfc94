//! Handing a linkage structure from one engine to another: the engine of the next region when a
//! car drives across a region border (issue 28: anchoring partitioned by region over cores, and
//! over hosts). The structure is a derived object (a world object) and every object linked from it
//! (its on-road object, its car, ...), each with its symbol, its state and status, what stateful
//! link units keep about it, the instances of the links out of it (the object it is linked to and
//! the residual of the maintain condition, or the residual of the establish condition while
//! unlinked: [`kpl_mtl::Handover`]s) and the structure's prediction in progress. Percepts stay
//! with their source: the link from the percept that fed the structure is left behind, and the
//! receiving engine links its own percept of the car to the world object by the reestablish
//! condition, as it does after any occlusion, so the structure goes on under its symbols.
//!
//! [`Anchoring::hand_over`] takes the structure out (changes `unlinked` and `removed`, cause
//! `handed_over`); [`Anchoring::take_over`] puts it in (changes `created` and `linked`, cause
//! `handed_over`), checking it first: an unknown type or link, a symbol the engine already uses or
//! a malformed residual is refused and the engine is unchanged. Symbols stay unique across the
//! engines without asking each other when each numbers its new symbols in its own residue class
//! ([`crate::store::Numbering::region`]).
//!
//! Not carried: the candidates of an unlinked instance and its identifications (they are about
//! the handing engine's objects), the branch objects of a split prediction (the receiving engine
//! starts the prediction again from the structure's state), and identifications that named the
//! objects.

use std::collections::HashMap;
use std::sync::Arc;

use kpl_core::{Time, Value};

use crate::change::{Cause, Change, ChangeKind};
use crate::engine::{Anchoring, StepOutput};
use crate::predict::PredictionStart;
use crate::stateful::UnitMemory;
use crate::store::{ObjectKey, Origin, PredictionRun};

/// A structure taken out of one engine, to be taken over by another of the same spec.
#[derive(Debug, Clone)]
pub struct StructureHandover {
    /// The valid time of the handing engine's last step: the receiving engine's next step is
    /// after it.
    pub time: Time,
    /// The objects, the handed root first; links refer to them by index.
    pub objects: Vec<HandedObject>,
    /// The instances of the links out of the objects.
    pub instances: Vec<HandedInstance>,
}

/// One object of a handed structure.
#[derive(Debug, Clone)]
pub struct HandedObject {
    pub ty: Arc<str>,
    pub symbol: Arc<str>,
    /// A percept (the root of a structure handed over with the percept that feeds it, within one
    /// process whose engines share their sources): the source that lists it, whether the last
    /// snapshot listed it and when one last did.
    pub source: Option<Arc<str>>,
    pub present: bool,
    pub last_seen: Time,
    pub created: Time,
    /// The state (a record whose `id` is the symbol) and its valid time.
    pub state: Value,
    pub state_time: Time,
    pub measured: bool,
    pub predicted: bool,
    pub predicted_since: Option<Time>,
    pub last_anchored: Time,
    pub names: Vec<Arc<str>>,
    /// What stateful link units keep about the object, by the unit's key (within one process).
    pub memory: Vec<(Arc<str>, UnitMemory)>,
    /// The root of the predicted structure the object is on (an index of the handover).
    pub prediction_root: Option<usize>,
    /// The prediction in progress of the structure this object is the root of.
    pub prediction: Option<HandedPrediction>,
}

/// A prediction in progress: the object whose model predicts, the path to it from the root
/// (indices of the handover) and where the model started.
#[derive(Debug, Clone)]
pub struct HandedPrediction {
    pub owner: usize,
    pub path: Vec<usize>,
    pub start: PredictionStart,
    pub n_hypotheses: usize,
    pub ended: bool,
}

/// The instance of a link out of a handed object.
#[derive(Debug, Clone)]
pub struct HandedInstance {
    pub link: Arc<str>,
    /// Index of the object it is the instance of.
    pub from: usize,
    /// Index of the object it is linked to; `None` while unlinked.
    pub to: Option<usize>,
    /// The maintain condition while linked, the establish condition while not.
    pub condition: HandedCondition,
}

/// A link condition as it is handed over.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum HandedCondition {
    Pending(kpl_mtl::Handover),
    Decided(bool),
}

/// Why a structure could not be handed over or taken over; the engine is unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HandoverError {
    #[error("no object `{symbol}` of type `{ty}` in this engine")]
    NoObject { ty: String, symbol: String },
    #[error(
        "`{0}` is not made by links (a percept stays with its source; a branch object goes with its root)"
    )]
    NotDerived(String),
    #[error("type `{0}` is not declared in this engine")]
    UnknownType(String),
    #[error("link `{0}` is not in this engine, or does not go between these objects' types")]
    UnknownLink(String),
    #[error("`{0}` is already an object of this engine")]
    SymbolInUse(String),
    #[error("the handover {0}")]
    Malformed(String),
    #[error("a condition of link `{link}`: {error}")]
    Condition { link: String, error: kpl_mtl::HandoverError },
}

impl Anchoring {
    /// Takes the structure of derived object `symbol` of type `ty` out of this engine (see the
    /// module's documentation), at the engine's last step; the changes say what left.
    pub fn hand_over(
        &mut self,
        ty: &str,
        symbol: &str,
    ) -> Result<(StructureHandover, StepOutput), HandoverError> {
        let no_object = || HandoverError::NoObject { ty: ty.to_string(), symbol: symbol.to_string() };
        let t = self.type_id(ty).ok_or_else(no_object)?;
        let root = self.store.by_symbol(t, symbol).ok_or_else(no_object)?;
        let root_object = self.store.get(root).ok_or_else(no_object)?;
        let handable = match root_object.origin {
            Origin::Derived => root_object.branch_of.is_none(),
            Origin::Percept { .. } => true,
            Origin::Partial => false,
        };
        if !handable {
            return Err(HandoverError::NotDerived(symbol.to_string()));
        }
        let time = self.last_time.unwrap_or(root_object.state_time);
        // The structure: the root and every object linked from it, root first.
        let mut keys = vec![root];
        let mut k = 0;
        while k < keys.len() {
            if let Some(object) = self.store.get(keys[k]) {
                for (_, to) in &object.outgoing {
                    let derived = self.store.get(*to).is_some_and(|o| o.origin == Origin::Derived);
                    if derived && !keys.contains(to) {
                        keys.push(*to);
                    }
                }
            }
            k += 1;
        }
        let index: HashMap<ObjectKey, usize> = keys.iter().enumerate().map(|(i, k)| (*k, i)).collect();
        let mut out = StepOutput { time, ..StepOutput::default() };
        let mut objects = Vec::with_capacity(keys.len());
        let mut instances = Vec::new();
        for key in &keys {
            let Some(object) = self.store.get(*key) else { continue };
            // A split prediction's branch objects stay behind (pruned below): the receiving
            // engine starts its prediction again.
            let prediction =
                object.prediction.as_ref().filter(|run| run.branches.is_empty()).and_then(|run| {
                    Some(HandedPrediction {
                        owner: *index.get(&run.owner)?,
                        path: run.path.iter().map(|k| index.get(k).copied()).collect::<Option<_>>()?,
                        start: run.start.clone(),
                        n_hypotheses: run.n_hypotheses,
                        ended: run.ended,
                    })
                });
            let source = match object.origin {
                Origin::Percept { source } => self.source_name(source).map(Arc::from),
                _ => None,
            };
            objects.push(HandedObject {
                ty: self.types[object.ty as usize].name.clone(),
                symbol: object.symbol.clone(),
                source,
                present: object.present,
                last_seen: object.last_seen,
                created: object.created,
                state: object.value.clone(),
                state_time: object.state_time,
                measured: object.measured,
                predicted: object.predicted,
                predicted_since: object.predicted_since,
                last_anchored: object.last_anchored,
                names: object.names.clone(),
                memory: object.memory.clone(),
                prediction_root: object.prediction_root.and_then(|r| index.get(&r).copied()),
                prediction,
            });
            for link in &self.links {
                if link.from_ty != object.ty {
                    continue;
                }
                let Some((to, condition)) = link.hand_over_instance(*key) else { continue };
                let to = match to {
                    Some(to) => match index.get(&to) {
                        Some(i) => Some(*i),
                        // Linked to an object that stays (not made by links): not carried.
                        None => continue,
                    },
                    None => None,
                };
                instances.push(HandedInstance { link: link.name.clone(), from: index[key], to, condition });
            }
        }
        self.take_out(&keys, &index, time, &mut out);
        Ok((StructureHandover { time, objects, instances }, out))
    }

    /// Removes a handed structure's objects: links into it from objects that stay are undone
    /// (their instances unlinked again), its instances and objects dropped.
    fn take_out(
        &mut self,
        keys: &[ObjectKey],
        index: &HashMap<ObjectKey, usize>,
        time: Time,
        out: &mut StepOutput,
    ) {
        for key in keys {
            let Some(object) = self.store.get(*key) else { continue };
            let (symbol, ty) = (object.symbol.clone(), object.ty);
            let incoming = object.incoming.clone();
            let branches = object.prediction.as_ref().map(|run| run.branches.clone()).unwrap_or_default();
            for (l, from) in incoming {
                if index.contains_key(&from) {
                    continue;
                }
                self.links[l as usize].reset_instance(from);
                self.store.unlink(l, from, *key);
                if let Some(source) = self.store.get(from) {
                    out.changes.push(
                        Change::new(
                            time,
                            ChangeKind::Unlinked,
                            symbol.clone(),
                            self.types[ty as usize].name.clone(),
                            Cause::HandedOver,
                        )
                        .link(&self.links[l as usize].name)
                        .from(&source.symbol),
                    );
                }
            }
            self.prune(branches, time, out);
        }
        for key in keys {
            let Some(object) = self.store.get(*key) else { continue };
            let (symbol, ty) = (object.symbol.clone(), object.ty);
            for link in &mut self.links {
                if link.from_ty == ty {
                    link.drop_instance(*key);
                }
            }
            self.store.remove(*key);
            out.changes.push(Change::new(
                time,
                ChangeKind::Removed,
                symbol,
                self.types[ty as usize].name.clone(),
                Cause::HandedOver,
            ));
        }
    }

    /// Puts a structure handed over by another engine of the same spec into this one (see the
    /// module's documentation). It is checked first; refused, nothing changes.
    pub fn take_over(&mut self, handover: &StructureHandover) -> Result<StepOutput, HandoverError> {
        let plan = self.check_handover(handover)?;
        let time = self.last_time.map_or(handover.time, |t| t.max(handover.time));
        let mut out = StepOutput { time, ..StepOutput::default() };
        let mut keys = Vec::with_capacity(handover.objects.len());
        for (object, ty) in handover.objects.iter().zip(&plan.types) {
            let origin = match &object.source {
                Some(name) => Origin::Percept { source: self.source_id(name) },
                None => Origin::Derived,
            };
            let key = self.store.insert(
                *ty,
                object.symbol.clone(),
                origin,
                kpl_core::Record::default(),
                object.created,
            );
            if let Origin::Percept { source } = origin {
                self.source_percepts[source as usize].push(key);
            }
            if let Some(o) = self.store.get_mut(key) {
                o.present = object.present;
                o.last_seen = object.last_seen;
                o.anchored = object.source.is_some();
                o.value = object.state.clone();
                o.state_time = object.state_time;
                o.measured = object.measured;
                o.predicted = object.predicted;
                o.predicted_since = object.predicted_since;
                o.last_anchored = object.last_anchored;
                o.names = object.names.clone();
                o.memory = object.memory.clone();
            }
            keys.push(key);
        }
        for (instance, l) in handover.instances.iter().zip(&plan.links) {
            let from = keys[instance.from];
            let to = instance.to.map(|i| keys[i]);
            if let Err(error) = self.links[*l as usize].take_over_instance(from, to, &instance.condition) {
                // Undone: the instances taken over so far and the objects.
                for key in &keys {
                    for link in &mut self.links {
                        link.drop_instance(*key);
                    }
                    self.store.remove(*key);
                }
                return Err(HandoverError::Condition { link: instance.link.to_string(), error });
            }
            if let Some(to) = to {
                self.store.link(*l, from, to);
            }
        }
        for (object, key) in handover.objects.iter().zip(&keys) {
            let prediction = object.prediction.as_ref().map(|p| {
                Box::new(PredictionRun {
                    owner: keys[p.owner],
                    path: p.path.iter().map(|i| keys[*i]).collect(),
                    start: p.start.clone(),
                    n_hypotheses: p.n_hypotheses,
                    ended: p.ended,
                    branches: Vec::new(),
                })
            });
            if let Some(o) = self.store.get_mut(*key) {
                o.prediction_root = object.prediction_root.map(|i| keys[i]);
                o.prediction = prediction;
            }
            out.changes.push(Change::new(
                time,
                ChangeKind::Created,
                object.symbol.clone(),
                object.ty.clone(),
                Cause::HandedOver,
            ));
        }
        for instance in &handover.instances {
            if let Some(to) = instance.to {
                let (from, to) = (&handover.objects[instance.from], &handover.objects[to]);
                out.changes.push(
                    Change::new(
                        time,
                        ChangeKind::Linked,
                        to.symbol.clone(),
                        to.ty.clone(),
                        Cause::HandedOver,
                    )
                    .link(&instance.link)
                    .from(&from.symbol),
                );
            }
        }
        Ok(out)
    }

    /// The types and links of a handover in this engine, after checking that everything in it
    /// refers to what exists (and nothing to what is already here).
    fn check_handover(&self, handover: &StructureHandover) -> Result<Plan, HandoverError> {
        let malformed = |what: String| HandoverError::Malformed(what);
        let n = handover.objects.len();
        if n == 0 {
            return Err(malformed("has no object".to_string()));
        }
        let mut types = Vec::with_capacity(n);
        for (i, object) in handover.objects.iter().enumerate() {
            let ty =
                self.type_id(&object.ty).ok_or_else(|| HandoverError::UnknownType(object.ty.to_string()))?;
            // A percept only with its source, as the root; a derived object only of a type links
            // make here.
            let percept_type = self.types[ty as usize].links_into.is_empty();
            if percept_type != object.source.is_some() || (object.source.is_some() && i != 0) {
                return Err(HandoverError::NotDerived(object.symbol.to_string()));
            }
            if self.store.by_symbol(ty, &object.symbol).is_some()
                || handover.objects[..i].iter().any(|o| o.symbol == object.symbol && o.ty == object.ty)
            {
                return Err(HandoverError::SymbolInUse(object.symbol.to_string()));
            }
            let id_ok = object.state.as_record().is_some_and(|r| r.id.as_deref() == Some(&*object.symbol));
            if !id_ok {
                return Err(malformed(format!(
                    "has a state of `{}` that is not a record of that symbol",
                    object.symbol
                )));
            }
            let in_range = |i: &usize| *i < n;
            if let Some(p) = &object.prediction
                && !(in_range(&p.owner) && p.path.iter().all(in_range))
            {
                return Err(malformed(format!(
                    "has a prediction of `{}` with an object it does not carry",
                    object.symbol
                )));
            }
            if object.prediction_root.is_some_and(|r| r >= n) {
                return Err(malformed(format!(
                    "has `{}` on a prediction of an object it does not carry",
                    object.symbol
                )));
            }
            types.push(ty);
        }
        let mut links = Vec::with_capacity(handover.instances.len());
        let mut seen = Vec::new();
        for instance in &handover.instances {
            let unknown = || HandoverError::UnknownLink(instance.link.to_string());
            let l = self.links.iter().position(|x| x.name == instance.link).ok_or_else(unknown)?;
            let link = &self.links[l];
            if instance.from >= n || instance.to.is_some_and(|t| t >= n) {
                return Err(malformed(format!(
                    "has an instance of `{}` with an object it does not carry",
                    instance.link
                )));
            }
            if link.from_ty != types[instance.from] || instance.to.is_some_and(|t| link.to_ty != types[t]) {
                return Err(unknown());
            }
            if seen.contains(&(l, instance.from)) {
                return Err(malformed(format!("has two instances of `{}` for one object", instance.link)));
            }
            seen.push((l, instance.from));
            links.push(l as u32);
        }
        Ok(Plan { types, links })
    }
}

/// Where a checked handover's objects and instances go.
struct Plan {
    types: Vec<crate::store::TypeId>,
    links: Vec<crate::store::LinkId>,
}
