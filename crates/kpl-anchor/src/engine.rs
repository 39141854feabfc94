//! The anchoring engine of one spec: its object store, a [`LinkProcess`] per link specification,
//! the prediction models, forgetting and identifications, advanced one state at a time by
//! [`Anchoring::step`] with the snapshots of its percept sources. Pure and synchronous: time is an
//! argument, nothing reads a clock, and the same inputs give the same outputs (ordered maps,
//! creation order everywhere).
//!
//! One step at time t:
//!
//! 1. **Percepts.** Each source's snapshot lists the percepts it tracks at t. A new id is a new
//!    percept object (`created`, cause `source`); a percept its source no longer lists is absent
//!    (no state now, links kept) until it has not been listed for its type's forget time (0 when
//!    the spec gives none for the percept type), then removed (`removed`, cause `lost`) together
//!    with its links (`unlinked`, cause `from_removed`).
//! 2. **Prediction.** Every object (not a percept) with no incoming link from a present object is
//!    the root of a structure that is not fed: its state is predicted. The model is that of the most
//!    specific object of the structure that has one, following the links out of the root while
//!    each next object is a subtype of the root's type and has no other incoming link (the
//!    paper: "since wo1 is linked to an on-road object it is also possible to use this hypothesis
//!    to further restrict the predicted movements"). That object is predicted from the state it
//!    had when prediction began; the objects between the root and it take the attributes they
//!    share with it; objects beyond it follow through their link units as usual. A model may give
//!    several hypotheses (`along_roads` at crossings); the root is then a candidate at each.
//! 3. **Link processes**, in the order of the type hierarchy (links out of a type after all links
//!    into it), each one step (see [`crate::link`]).
//! 4. **Identifications** of existing objects: an object of the asked type whose state satisfies
//!    the description resolves the identification.
//! 5. **Grounding.** An object is anchored exactly when it is a percept or has an incoming link
//!    from an anchored object.
//! 6. **Forgetting.** An object not anchored for its type's forget time (since it was last
//!    anchored, or created) is removed (`removed`, cause `forgotten`). Partial objects of pending
//!    identifications are kept.

use std::collections::BTreeMap;
use std::sync::Arc;

use kpl_core::{Record, RecordType, Time, Value};
use kpl_mtl::ProgressorGroup;
use kpl_semantic::hir;
use kpl_syntax::ast;

use crate::change::{Cause, Change, ChangeKind};
use crate::conditions::{LinkConditions, LinkState, description_formula};
use crate::error::{BuildError, IdentifyError, StepError};
use crate::implementations::Implementations;
use crate::link::{Condition, LinkIdentification, LinkProcess};
use crate::networks::Networks;
use crate::predict::PredictionModel;
use crate::records::{check_fields, overlay};
use crate::store::{LinkId, ObjectKey, Origin, PredictionRun, Store, TypeId};

/// What an engine is built with besides the spec.
#[derive(Debug, Clone, Default)]
pub struct AnchorConfig {
    pub implementations: Implementations,
    /// Road networks for link units and models; pre-filled entries are used instead of loading.
    pub networks: Networks,
}

/// A problem with one object or condition during a step; the step went on without it.
#[derive(Debug, Clone, PartialEq)]
pub struct Warning {
    pub time: Time,
    pub message: String,
}

/// At most this many warnings are kept per step; the rest are counted.
pub const MAX_WARNINGS_PER_STEP: usize = 100;

/// What one step produced.
#[derive(Debug, Clone, Default)]
pub struct StepOutput {
    pub time: Time,
    pub changes: Vec<Change>,
    pub warnings: Vec<Warning>,
    /// Warnings beyond [`MAX_WARNINGS_PER_STEP`].
    pub suppressed_warnings: usize,
}

impl StepOutput {
    pub(crate) fn warn(&mut self, time: Time, message: String) {
        if self.warnings.len() < MAX_WARNINGS_PER_STEP {
            self.warnings.push(Warning { time, message });
        } else {
            self.suppressed_warnings += 1;
        }
    }

    /// The changes as the `changes` stream carries them: a list of records.
    pub fn changes_value(&self) -> Value {
        Value::List(self.changes.iter().map(Change::to_value).collect())
    }
}

/// One source's snapshot at the step's time: every object of type `ty` it reports now, as a
/// `Value::List` of `Value::Record`s with `id`s.
#[derive(Debug, Clone, Copy)]
pub struct Snapshot<'a> {
    pub source: &'a str,
    pub ty: &'a str,
    pub objects: &'a Value,
}

#[derive(Debug)]
pub(crate) struct TypeInfo {
    pub name: Arc<str>,
    pub record: Arc<RecordType>,
    pub links_into: Vec<LinkId>,
    pub model: Option<Arc<dyn PredictionModel>>,
    pub forget: Option<Time>,
}

/// A pending or completed identification.
#[derive(Debug)]
pub(crate) struct Identification {
    pub name: Arc<str>,
    pub ty: TypeId,
    /// The partial object's symbol.
    pub symbol: Arc<str>,
    pub partial: ObjectKey,
    pub done: bool,
    /// The object it resolved to.
    pub object: Option<ObjectKey>,
    /// The description alone, for existing objects (`this`): the group of its conditions, one
    /// per existing object.
    description: ProgressorGroup,
    existing: BTreeMap<ObjectKey, Condition>,
}

/// What a link process reads and writes during a step.
pub(crate) struct StepCtx<'a> {
    pub time: Time,
    pub step: u64,
    pub store: &'a mut Store,
    pub types: &'a [TypeInfo],
    pub identifications: &'a mut [Identification],
    pub out: &'a mut StepOutput,
}

/// The anchoring of one spec.
#[derive(Debug)]
pub struct Anchoring {
    pub(crate) types: Vec<TypeInfo>,
    /// Types in the order of the link hierarchy (every link goes from an earlier to a later one).
    pub(crate) type_order: Vec<TypeId>,
    /// `subtype[a][b]`: type a is b or inherits from it.
    subtype: Vec<Vec<bool>>,
    pub(crate) links: Vec<LinkProcess>,
    link_order: Vec<LinkId>,
    pub(crate) store: Store,
    source_ids: BTreeMap<String, u32>,
    source_percepts: Vec<Vec<ObjectKey>>,
    pub(crate) identifications: Vec<Identification>,
    pub(crate) last_time: Option<Time>,
    step: u64,
    /// Changes made between steps (identifications asked), reported with the next step.
    pending: Vec<Change>,
    notes: Vec<String>,
    keys: Vec<ObjectKey>,
    hypotheses: Vec<Record>,
}

impl Anchoring {
    /// Builds the engine of a checked spec: its types, links (with their units and compiled
    /// conditions), prediction models, forget times and identifications.
    pub fn from_spec(spec: &hir::Spec, config: AnchorConfig) -> Result<Anchoring, BuildError> {
        Anchoring::from_spec_links(spec, config, None)
    }

    /// The engine of some of a spec's links only (those one host runs; `None`: all). A type no
    /// chosen link leads into is fed by snapshots, as percepts are (its objects come from another
    /// host); identifications of such types are left to that host.
    pub fn from_spec_links(
        spec: &hir::Spec,
        config: AnchorConfig,
        only: Option<&[String]>,
    ) -> Result<Anchoring, BuildError> {
        let AnchorConfig { implementations, mut networks } = config;
        let mut types: Vec<TypeInfo> = spec
            .types
            .iter()
            .map(|record| TypeInfo {
                name: record.name.clone(),
                record: record.clone(),
                links_into: Vec::new(),
                model: None,
                forget: spec.forget.after(&record.name),
            })
            .collect();
        let type_id =
            |name: &str, types: &[TypeInfo]| types.iter().position(|t| &*t.name == name).map(|i| i as TypeId);
        let subtype: Vec<Vec<bool>> = types
            .iter()
            .map(|a| types.iter().map(|b| spec.types.is_subtype(&a.name, &b.name)).collect())
            .collect();

        let mut links = Vec::new();
        for process in &spec.processes {
            let hir::ProcessKind::Link(link) = &process.kind else { continue };
            if only.is_some_and(|names| !names.contains(&process.name)) {
                continue;
            }
            let unknown =
                |ty: &str| BuildError::UnknownType { link: process.name.clone(), ty: ty.to_string() };
            let from_ty = type_id(&link.from_type, &types).ok_or_else(|| unknown(&link.from_type))?;
            let to_ty = type_id(&link.to_type, &types).ok_or_else(|| unknown(&link.to_type))?;
            let factory =
                implementations.link_unit(&link.via.entry).ok_or_else(|| BuildError::UnknownLinkUnit {
                    link: process.name.clone(),
                    entry: link.via.entry.clone(),
                    known: implementations.link_unit_names().collect::<Vec<_>>().join(", "),
                })?;
            let unit = factory(&link.via.params, &mut networks)
                .map_err(|message| BuildError::Implementation { entry: link.via.entry.clone(), message })?;
            let conditions =
                LinkConditions::compile(link, unit.functions()).map_err(|e| BuildError::Condition {
                    link: process.name.clone(),
                    condition: e.condition,
                    messages: e.messages,
                })?;
            let id = links.len() as LinkId;
            types[to_ty as usize].links_into.push(id);
            links.push(LinkProcess::new(
                Arc::from(process.name.as_str()),
                from_ty,
                to_ty,
                link.via.entry.clone(),
                unit,
                conditions,
            ));
        }

        // The hierarchy: types ordered so that every link goes forward (Kahn's algorithm,
        // declaration order among types that are ready together).
        let n = types.len();
        let mut indegree = vec![0usize; n];
        for link in &links {
            indegree[link.to_ty as usize] += 1;
        }
        let mut type_order: Vec<TypeId> = Vec::with_capacity(n);
        let mut done = vec![false; n];
        while type_order.len() < n {
            let Some(next) = (0..n).find(|&t| !done[t] && indegree[t] == 0) else {
                let types_in_cycle =
                    (0..n).filter(|&t| !done[t]).map(|t| types[t].name.to_string()).collect();
                return Err(BuildError::Cycle { types: types_in_cycle });
            };
            done[next] = true;
            type_order.push(next as TypeId);
            for link in links.iter().filter(|l| l.from_ty as usize == next) {
                indegree[link.to_ty as usize] -= 1;
            }
        }
        let rank: Vec<usize> = {
            let mut rank = vec![0; n];
            for (i, t) in type_order.iter().enumerate() {
                rank[*t as usize] = i;
            }
            rank
        };
        let mut link_order: Vec<LinkId> = (0..links.len() as LinkId).collect();
        link_order.sort_by_key(|&l| (rank[links[l as usize].from_ty as usize], l));

        for prediction in &spec.predictions {
            let Some(ty) = type_id(&prediction.ty, &types) else { continue };
            let factory =
                implementations.model(&prediction.model.entry).ok_or_else(|| BuildError::UnknownModel {
                    ty: prediction.ty.clone(),
                    entry: prediction.model.entry.clone(),
                    known: implementations.model_names().collect::<Vec<_>>().join(", "),
                })?;
            let model = factory(&prediction.model.params, &mut networks).map_err(|message| {
                BuildError::Implementation { entry: prediction.model.entry.clone(), message }
            })?;
            types[ty as usize].model = Some(model);
        }

        // A percept type is forgotten only when the spec says so for that type (`forget
        // VisionPercept after 600ms`): the default forget time is about derived objects.
        for ty in &mut types {
            if ty.links_into.is_empty() {
                ty.forget = spec.forget.per_type.get(&*ty.name).copied();
            }
        }

        let mut notes = Vec::new();
        for link in &links {
            if link.conditions.gate.is_none() {
                notes.push(format!(
                    "link `{}`: the reestablish condition bounds no distance between `from` and `to`, so every unlinked {} is a candidate of every unlinked {} (cost grows with their product)",
                    link.name, types[link.to_ty as usize].name, types[link.from_ty as usize].name
                ));
            }
        }

        let store = Store::new(types.iter().map(|t| t.record.symbol.clone()).collect());
        let mut engine = Anchoring {
            types,
            type_order,
            subtype,
            links,
            link_order,
            store,
            source_ids: BTreeMap::new(),
            source_percepts: Vec::new(),
            identifications: Vec::new(),
            last_time: None,
            step: 0,
            pending: Vec::new(),
            notes,
            keys: Vec::new(),
            hypotheses: Vec::new(),
        };
        for ident in &spec.identifications {
            if engine.type_id(&ident.ty).is_some_and(|t| engine.types[t as usize].links_into.is_empty()) {
                continue;
            }
            engine.identify(&ident.name, &ident.ty, &ident.description).map_err(|e| {
                BuildError::Identification { name: ident.name.clone(), message: e.to_string() }
            })?;
        }
        Ok(engine)
    }

    /// Remarks about the spec worth a user's attention (a link without a gate).
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// The time of the last step.
    pub fn time(&self) -> Option<Time> {
        self.last_time
    }

    pub(crate) fn type_id(&self, name: &str) -> Option<TypeId> {
        self.types.iter().position(|t| &*t.name == name).map(|i| i as TypeId)
    }

    /// Whether objects of a type come from snapshots (percepts, or objects made on another host)
    /// rather than from links of this engine.
    pub fn is_fed_by_snapshots(&self, ty: &str) -> bool {
        self.type_id(ty).is_some_and(|t| self.types[t as usize].links_into.is_empty())
    }

    /// The link of this engine that reports a change: its own `link`, else for an object of a
    /// type made by links the first link into it, else (a percept type) the first link from it.
    pub fn link_of_change(&self, change: &Change) -> Option<&str> {
        if let Some(link) = &change.link {
            return self.links.iter().find(|l| l.name == *link).map(|l| &*l.name);
        }
        let ty = self.type_id(&change.ty)?;
        let into = self.types[ty as usize].links_into.first().map(|l| &*self.links[*l as usize].name);
        into.or_else(|| self.links.iter().find(|l| l.from_ty == ty).map(|l| &*l.name))
    }

    /// The type a link leads to.
    pub fn link_to_type(&self, link: &str) -> Option<&str> {
        self.links.iter().find(|l| &*l.name == link).map(|l| &*self.types[l.to_ty as usize].name)
    }

    /// The declared object types, in the order of the hierarchy.
    pub fn type_names(&self) -> Vec<&str> {
        self.type_order.iter().map(|t| &*self.types[*t as usize].name).collect()
    }

    /// The link specifications, in the order they run.
    pub fn link_names(&self) -> Vec<&str> {
        self.link_order.iter().map(|l| &*self.links[*l as usize].name).collect()
    }

    /// Counters of a link process.
    pub fn link_stats(&self, link: &str) -> Option<crate::link::LinkStats> {
        self.links.iter().find(|l| &*l.name == link).map(|l| l.stats)
    }

    /// The gate distance of a link, when its reestablish condition bounds one.
    pub fn link_gate(&self, link: &str) -> Option<f64> {
        self.links.iter().find(|l| &*l.name == link).and_then(|l| l.conditions.gate)
    }

    /// Number of objects in the store.
    pub fn n_objects(&self) -> usize {
        self.store.len()
    }

    /// Asks for an object by description (top-down identification): adds a partial object of
    /// type `ty`, named `name`, with a fresh symbol, which anchoring then tries to complete. An
    /// unlinked object p of a link `A -> ty` is linked to it when `reestablish(p, x) and
    /// description(x)` becomes true, x being what the link's unit makes of p; an existing object
    /// of type `ty` resolves it when its state satisfies the description. Either is reported as
    /// `identified`. Returns the partial object's symbol.
    pub fn identify(
        &mut self,
        name: &str,
        ty: &str,
        description: &ast::Expr,
    ) -> Result<Arc<str>, IdentifyError> {
        let ty_id = self.type_id(ty).ok_or_else(|| IdentifyError::UnknownType(ty.to_string()))?;
        let links_into = self.types[ty_id as usize].links_into.clone();
        if links_into.is_empty() {
            return Err(IdentifyError::NoLinkInto(ty.to_string()));
        }
        if self.identifications.iter().any(|i| &*i.name == name)
            || self.store.all().any(|o| o.names.iter().any(|n| &**n == name))
        {
            return Err(IdentifyError::NameInUse(name.to_string()));
        }
        let description_only = description_formula(description).map_err(IdentifyError::Description)?;
        let mut per_link = Vec::new();
        for &l in &links_into {
            let formula = self.links[l as usize]
                .conditions
                .identification(description)
                .map_err(IdentifyError::Description)?;
            per_link.push((l, formula));
        }
        let symbol = self.store.new_symbol(ty_id);
        let time = self.last_time.unwrap_or(0);
        let partial = self.store.insert(ty_id, symbol.clone(), Origin::Partial, Record::default(), time);
        let name: Arc<str> = Arc::from(name);
        if let Some(o) = self.store.get_mut(partial) {
            o.names.push(name.clone());
        }
        let ident = self.identifications.len();
        for (l, formula) in per_link {
            self.links[l as usize].identifications.push(LinkIdentification::new(ident, formula));
        }
        self.identifications.push(Identification {
            name: name.clone(),
            ty: ty_id,
            symbol: symbol.clone(),
            partial,
            done: false,
            object: None,
            description: ProgressorGroup::new(description_only),
            existing: BTreeMap::new(),
        });
        self.pending.push(
            Change::new(
                time,
                ChangeKind::Created,
                symbol.clone(),
                self.types[ty_id as usize].name.clone(),
                Cause::Identify,
            )
            .name(&name),
        );
        Ok(symbol)
    }

    /// [`Anchoring::identify`] with the description as text (`xydist(this.pos, vec2(120.0, 40.0)) < 20.0`).
    pub fn identify_text(
        &mut self,
        name: &str,
        ty: &str,
        description: &str,
    ) -> Result<Arc<str>, IdentifyError> {
        let expr = kpl_syntax::parse_formula(description)
            .map_err(|d| IdentifyError::Description(d.into_iter().map(|d| d.message).collect()))?;
        self.identify(name, ty, &expr)
    }

    /// Whether the identification `name` is completed, and the symbol it stands for.
    pub fn identified(&self, name: &str) -> Option<Arc<str>> {
        let ident = self.identifications.iter().find(|i| &*i.name == name)?;
        let key = ident.object.filter(|_| ident.done)?;
        self.store.get(key).map(|o| o.symbol.clone())
    }

    fn source_id(&mut self, source: &str) -> u32 {
        if let Some(id) = self.source_ids.get(source) {
            return *id;
        }
        let id = self.source_percepts.len() as u32;
        self.source_ids.insert(source.to_string(), id);
        self.source_percepts.push(Vec::new());
        id
    }

    /// Advances to `time` (after the previous step's) with the snapshots of the sources that
    /// report at this time (at most one per source); sources without a snapshot keep their
    /// percepts as they were. On error nothing changes.
    pub fn step(&mut self, time: Time, inputs: &[Snapshot<'_>]) -> Result<StepOutput, StepError> {
        if let Some(previous) = self.last_time
            && time <= previous
        {
            return Err(StepError::TimeNotIncreasing { time, previous });
        }
        let mut resolved = Vec::with_capacity(inputs.len());
        for input in inputs {
            let ty = self.type_id(input.ty).ok_or_else(|| StepError::UnknownType {
                source_name: input.source.to_string(),
                ty: input.ty.to_string(),
            })?;
            if let Some(&l) = self.types[ty as usize].links_into.first() {
                return Err(StepError::NotAPerceptType {
                    source_name: input.source.to_string(),
                    ty: input.ty.to_string(),
                    link: self.links[l as usize].name.to_string(),
                });
            }
            resolved.push((input, ty));
        }
        self.last_time = Some(time);
        self.step += 1;
        let mut out = StepOutput { time, ..StepOutput::default() };
        for mut change in self.pending.drain(..) {
            change.time = time;
            out.changes.push(change);
        }
        self.store.for_each_mut(|o| {
            if !matches!(o.origin, Origin::Percept { .. }) {
                o.measured_at = None;
                o.predicted = false;
                o.on_prediction_path = false;
            }
        });
        for (input, ty) in resolved {
            self.ingest(time, input.source, ty, input.objects, &mut out);
        }
        self.predict(time, &mut out);
        for k in 0..self.link_order.len() {
            let l = self.link_order[k];
            let mut cx = StepCtx {
                time,
                step: self.step,
                store: &mut self.store,
                types: &self.types,
                identifications: &mut self.identifications,
                out: &mut out,
            };
            self.links[l as usize].run(l, &mut cx, &mut self.keys);
        }
        self.match_descriptions(time, &mut out);
        self.ground(time);
        self.forget(time, &mut out);
        Ok(out)
    }

    fn ingest(&mut self, time: Time, source: &str, ty: TypeId, objects: &Value, out: &mut StepOutput) {
        let source_id = self.source_id(source);
        let Value::List(items) = objects else {
            out.warn(
                time,
                format!(
                    "snapshot from `{source}` is {}, expected a list of objects; ignored",
                    with_article(objects.kind())
                ),
            );
            return;
        };
        let type_record = self.types[ty as usize].record.clone();
        let type_name = self.types[ty as usize].name.clone();
        let mut listed = Vec::with_capacity(items.len());
        for item in items.iter() {
            let Value::Record(record) = item else {
                out.warn(
                    time,
                    format!(
                        "snapshot from `{source}`: an item is {}, not an object; skipped",
                        with_article(item.kind())
                    ),
                );
                continue;
            };
            let Some(id) = record.id.clone() else {
                out.warn(time, format!("snapshot from `{source}`: an object without an `id`; skipped"));
                continue;
            };
            if let Err(problem) = check_fields(record, &type_record) {
                out.warn(time, format!("snapshot from `{source}`: {id} {problem}; skipped"));
                continue;
            }
            match self.store.by_symbol(ty, &id) {
                Some(key) => {
                    let step = self.step;
                    let Some(object) = self.store.get_mut(key) else { continue };
                    if object.origin != (Origin::Percept { source: source_id }) {
                        out.warn(time, format!("snapshot from `{source}`: {id} is already an object of another source; skipped"));
                        continue;
                    }
                    if object.seen_step == step {
                        out.warn(
                            time,
                            format!("snapshot from `{source}`: {id} is listed twice; the second is skipped"),
                        );
                        continue;
                    }
                    object.value = item.clone();
                    object.state_time = time;
                    object.measured_at = Some(time);
                    object.seen_step = step;
                    object.present = true;
                    object.last_seen = time;
                    listed.push(key);
                }
                None => {
                    let key = self.store.insert(
                        ty,
                        id.clone(),
                        Origin::Percept { source: source_id },
                        (**record).clone(),
                        time,
                    );
                    if let Some(object) = self.store.get_mut(key) {
                        object.measured_at = Some(time);
                        object.seen_step = self.step;
                        object.anchored = true;
                    }
                    listed.push(key);
                    out.changes.push(Change::new(
                        time,
                        ChangeKind::Created,
                        id,
                        type_name.clone(),
                        Cause::Source,
                    ));
                }
            }
        }
        // Percepts not listed: absent until the type's forget time has passed, then removed.
        let grace = self.types[ty as usize].forget.unwrap_or(0);
        let previous = std::mem::take(&mut self.source_percepts[source_id as usize]);
        for key in previous {
            let Some(object) = self.store.get_mut(key) else { continue };
            if object.seen_step == self.step {
                continue;
            }
            if time.saturating_sub(object.last_seen) >= grace {
                self.remove_object(key, Cause::Lost, time, out);
            } else {
                object.present = false;
                listed.push(key);
            }
        }
        self.source_percepts[source_id as usize] = listed;
    }

    /// Removes an object with its links; the link instances involved go back to unlinked (a
    /// removed `to`) or away (a removed `from`).
    fn remove_object(&mut self, key: ObjectKey, cause: Cause, time: Time, out: &mut StepOutput) {
        let Some(object) = self.store.get(key) else { return };
        let (symbol, ty) = (object.symbol.clone(), object.ty);
        let (incoming, outgoing) = (object.incoming.clone(), object.outgoing.clone());
        let type_name = self.types[ty as usize].name.clone();
        for (l, to) in outgoing {
            if let Some(target) = self.store.get(to) {
                let link = &self.links[l as usize];
                out.changes.push(
                    Change::new(
                        time,
                        ChangeKind::Unlinked,
                        target.symbol.clone(),
                        self.types[target.ty as usize].name.clone(),
                        Cause::FromRemoved,
                    )
                    .link(&link.name)
                    .from(&symbol),
                );
            }
        }
        for (l, from) in incoming {
            self.links[l as usize].reset_instance(from);
            if let Some(source) = self.store.get(from) {
                out.changes.push(
                    Change::new(
                        time,
                        ChangeKind::Unlinked,
                        symbol.clone(),
                        type_name.clone(),
                        Cause::ToRemoved,
                    )
                    .link(&self.links[l as usize].name)
                    .from(&source.symbol),
                );
            }
        }
        for link in &mut self.links {
            if link.from_ty == ty {
                link.drop_instance(key);
            }
        }
        self.store.remove(key);
        out.changes.push(Change::new(time, ChangeKind::Removed, symbol, type_name, cause));
    }

    /// The structure predicted from `root`: the path from the root to the object whose model
    /// predicts it (module doc), and that object's index in the path.
    fn prediction_path(&self, root: ObjectKey) -> (Vec<ObjectKey>, Option<usize>) {
        let mut path = vec![root];
        let Some(root_obj) = self.store.get(root) else { return (path, None) };
        let root_ty = root_obj.ty as usize;
        let mut owner = self.types[root_ty].model.is_some().then_some(0);
        let mut current = root;
        for _ in 0..self.types.len() {
            let Some(object) = self.store.get(current) else { break };
            let next = object.outgoing.iter().map(|(_, k)| *k).find(|k| {
                self.store.get(*k).is_some_and(|t| {
                    t.origin == Origin::Derived
                        && t.incoming.len() == 1
                        && self.subtype[t.ty as usize][root_ty]
                })
            });
            let Some(next) = next else { break };
            path.push(next);
            if self.store.get(next).is_some_and(|t| self.types[t.ty as usize].model.is_some()) {
                owner = Some(path.len() - 1);
            }
            current = next;
        }
        (path, owner)
    }

    fn predict(&mut self, time: Time, out: &mut StepOutput) {
        for ti in 0..self.type_order.len() {
            let ty = self.type_order[ti];
            if self.types[ty as usize].links_into.is_empty() {
                continue;
            }
            let mut keys = std::mem::take(&mut self.keys);
            keys.clear();
            keys.extend(self.store.objects_of(ty));
            for &root in &keys {
                let Some(object) = self.store.get(root) else { continue };
                if object.origin != Origin::Derived {
                    continue;
                }
                let fed = object.incoming.iter().any(|(_, p)| self.store.get(*p).is_some_and(|p| p.present));
                if fed {
                    if object.prediction.is_some()
                        && let Some(o) = self.store.get_mut(root)
                    {
                        o.prediction = None;
                    }
                    continue;
                }
                self.predict_structure(root, time, out);
            }
            self.keys = keys;
        }
    }

    fn predict_structure(&mut self, root: ObjectKey, time: Time, out: &mut StepOutput) {
        let (mut path, owner_index) = self.prediction_path(root);
        let Some(owner_index) = owner_index else {
            if let Some(o) = self.store.get_mut(root) {
                o.prediction = None;
            }
            return;
        };
        path.truncate(owner_index + 1);
        let owner = path[owner_index];
        let Some(owner_obj) = self.store.get(owner) else { return };
        let Some(model) = self.types[owner_obj.ty as usize].model.clone() else { return };
        let (owner_state, owner_time) = (owner_obj.record().cloned(), owner_obj.state_time);
        let Some(root_obj) = self.store.get_mut(root) else { return };
        let (root_symbol, root_type) =
            (root_obj.symbol.clone(), self.types[root_obj.ty as usize].name.clone());
        let mut run = match root_obj.prediction.take() {
            Some(run) if run.owner == owner && run.path == path => run,
            _ => {
                let Some(state) = owner_state else { return };
                let start = model.start(state, owner_time);
                Box::new(PredictionRun { owner, path: path.clone(), start, n_hypotheses: 0 })
            }
        };
        let mut hypotheses = std::mem::take(&mut self.hypotheses);
        hypotheses.clear();
        model.predict(&run.start, time, &mut hypotheses);
        if hypotheses.is_empty() {
            hypotheses.push((*run.start.state).clone());
        }
        if run.n_hypotheses == 0 {
            let mut change =
                Change::new(time, ChangeKind::Predicted, root_symbol, root_type, Cause::NoIncomingLink)
                    .model(model.name());
            if hypotheses.len() > 1 {
                change = change.hypotheses(hypotheses.len());
            }
            out.changes.push(change);
        } else if run.n_hypotheses != hypotheses.len() {
            out.changes.push(
                Change::new(time, ChangeKind::Predicted, root_symbol, root_type, Cause::Branch)
                    .model(model.name())
                    .hypotheses(hypotheses.len()),
            );
        }
        run.n_hypotheses = hypotheses.len();
        for (i, &key) in path.iter().enumerate() {
            let Some(object) = self.store.get_mut(key) else { continue };
            let values: Vec<Value> = if i == owner_index {
                hypotheses
                    .iter()
                    .map(|h| {
                        Value::Record(Arc::new(Record {
                            id: Some(object.symbol.clone()),
                            fields: h.fields.clone(),
                        }))
                    })
                    .collect()
            } else {
                let base = object.record().cloned().unwrap_or_default();
                hypotheses.iter().map(|h| Value::Record(Arc::new(overlay(&base, h)))).collect()
            };
            object.value = values[0].clone();
            object.hypotheses = if values.len() > 1 { values } else { Vec::new() };
            object.state_time = time;
            object.measured_at = None;
            object.predicted = true;
            object.on_prediction_path = true;
        }
        if let Some(o) = self.store.get_mut(root) {
            o.prediction = Some(run);
        }
        self.hypotheses = hypotheses;
    }

    fn match_descriptions(&mut self, time: Time, out: &mut StepOutput) {
        for i in 0..self.identifications.len() {
            if self.identifications[i].done {
                continue;
            }
            let ty = self.identifications[i].ty;
            let mut keys = std::mem::take(&mut self.keys);
            keys.clear();
            keys.extend(self.store.objects_of(ty));
            let store = &self.store;
            let ident = &mut self.identifications[i];
            let group = &mut ident.description;
            ident.existing.retain(|k, condition| {
                let present = store.get(*k).is_some();
                if !present {
                    condition.release(group);
                }
                present
            });
            let mut found = None;
            for &key in &keys {
                let Some(object) = store.get(key) else { continue };
                if object.origin != Origin::Derived {
                    continue;
                }
                let condition =
                    ident.existing.entry(key).or_insert_with(|| Condition::start(&mut ident.description));
                let Condition::Pending(_) = condition else { continue };
                let state = LinkState { from: &object.value, to: None, this: Some(&object.value) };
                match condition.step(&mut ident.description, time, &state) {
                    Ok(Some(verdict)) => {
                        if verdict && found.is_none() {
                            found = Some(key);
                        }
                    }
                    Ok(None) => {}
                    Err(e) => out.warn(
                        time,
                        format!(
                            "identification `{}` on {}: {e}; the state was skipped",
                            ident.name, object.symbol
                        ),
                    ),
                }
            }
            self.keys = keys;
            let Some(key) = found else { continue };
            let ident = &mut self.identifications[i];
            ident.done = true;
            ident.object = Some(key);
            for condition in std::mem::take(&mut ident.existing).into_values() {
                condition.release(&mut ident.description);
            }
            let (name, partial) = (ident.name.clone(), ident.partial);
            let Some(object) = self.store.get_mut(key) else { continue };
            object.names.push(name.clone());
            let (symbol, type_name) = (object.symbol.clone(), self.types[object.ty as usize].name.clone());
            self.remove_object(partial, Cause::Resolved, time, out);
            out.changes.push(
                Change::new(time, ChangeKind::Identified, symbol, type_name, Cause::Description).name(&name),
            );
        }
    }

    fn ground(&mut self, time: Time) {
        for ti in 0..self.type_order.len() {
            let ty = self.type_order[ti];
            let mut keys = std::mem::take(&mut self.keys);
            keys.clear();
            keys.extend(self.store.objects_of(ty));
            for &key in &keys {
                let Some(object) = self.store.get(key) else { continue };
                let anchored = match object.origin {
                    Origin::Percept { .. } => true,
                    Origin::Partial => false,
                    Origin::Derived => {
                        object.incoming.iter().any(|(_, p)| self.store.get(*p).is_some_and(|p| p.anchored))
                    }
                };
                if let Some(object) = self.store.get_mut(key) {
                    object.anchored = anchored;
                    if anchored {
                        object.last_anchored = time;
                    }
                }
            }
            self.keys = keys;
        }
    }

    fn forget(&mut self, time: Time, out: &mut StepOutput) {
        let mut doomed = Vec::new();
        for &ty in &self.type_order {
            let Some(after) = self.types[ty as usize].forget else { continue };
            for key in self.store.objects_of(ty) {
                let Some(object) = self.store.get(key) else { continue };
                if object.origin == Origin::Derived
                    && !object.anchored
                    && time.saturating_sub(object.last_anchored) >= after
                {
                    doomed.push(key);
                }
            }
        }
        for key in doomed {
            self.remove_object(key, Cause::Forgotten, time, out);
        }
    }
}

/// `an int`, `a list`.
fn with_article(kind: &str) -> String {
    let vowel = kind.starts_with(['a', 'e', 'i', 'o', 'u']);
    format!("{} {kind}", if vowel { "an" } else { "a" })
}
