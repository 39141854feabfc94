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

use crate::branches;
use crate::change::{Cause, Change, ChangeKind};
use crate::conditions::{LinkConditions, LinkState, description_formula, forget_formula};
use crate::error::{BuildError, IdentifyError, StepError};
use crate::implementations::Implementations;
use crate::link::{Condition, LinkIdentification, LinkProcess};
use crate::networks::Networks;
use crate::predict::PredictionModel;
use crate::records::{check_fields, overlay};
use crate::status;
use crate::store::{LinkId, ObjectKey, Origin, PredictionRun, StateOrigin, Store, TypeId};

/// What an engine is built with besides the spec.
#[derive(Debug, Clone, Default)]
pub struct AnchorConfig {
    pub implementations: Implementations,
    /// Road networks for link units and models; pre-filled entries are used instead of loading.
    pub networks: Networks,
    /// The host's functions that conditions may call besides the built-ins and their unit's
    /// predicates (the runtime's registry: `in_view`, `pixel`, `footprint`).
    pub functions: Vec<kpl_mtl::Function>,
    /// The numbers of new symbols (one region's of several: [`crate::store::Numbering::region`]).
    pub numbering: crate::store::Numbering,
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
    /// `forget ... after T when C`: the shorter time and the condition on the object's state.
    pub sooner: Option<Sooner>,
    /// Links of the spec lead into the type, but none of this engine's (they run on another
    /// host): its objects come from snapshots that say whether they were measured.
    pub made_elsewhere: bool,
}

/// The shorter forget time of a type and its condition (`this` is the object), evaluated on the
/// object's state at each step (one state of its group per evaluation).
#[derive(Debug)]
pub(crate) struct Sooner {
    pub after: Time,
    pub group: ProgressorGroup,
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

/// One `from` stream of a link at the state of one of its steps ([`Anchoring::step_link`]): the
/// stream's name (for a type fed by snapshots, the source its objects belong to), the valid time
/// of its sample (earlier than the step's when the sample is held over, `use most recent`), and
/// the snapshot.
#[derive(Debug, Clone, Copy)]
pub struct FromSnapshot<'a> {
    pub stream: &'a str,
    pub valid: Time,
    pub objects: &'a Value,
}

/// What a link process reads and writes during a step.
pub(crate) struct StepCtx<'a> {
    pub time: Time,
    /// Branch objects whose structure was reacquired: removed after the link's step.
    pub pruned: Vec<ObjectKey>,
    pub store: &'a mut Store,
    pub types: &'a [TypeInfo],
    pub identifications: &'a mut [Identification],
    pub out: &'a mut StepOutput,
    /// The current values of the streams conditions name (slots from `conditions::ENV`).
    pub env: &'a [Option<Value>],
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
    pub(crate) source_percepts: Vec<Vec<ObjectKey>>,
    /// The valid time of each source's last snapshot taken in.
    source_times: Vec<Option<Time>>,
    pub(crate) identifications: Vec<Identification>,
    pub(crate) last_time: Option<Time>,
    step: u64,
    /// Changes made between steps (identifications asked), reported with the next step of the
    /// link that reports them (the first link into the type), or of any link when there is none.
    pending: Vec<(Option<LinkId>, Change)>,
    notes: Vec<String>,
    keys: Vec<ObjectKey>,
    hypotheses: Vec<Record>,
    /// The streams conditions name, in slot order, and their values at the current step.
    env_names: Vec<Arc<str>>,
    env: Vec<Option<Value>>,
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
        let AnchorConfig { implementations, mut networks, functions, numbering } = config;
        // The streams the conditions name (the links' `env` inputs and the forget conditions'),
        // one slot each, the same in every condition.
        let mut env_names: Vec<Arc<str>> = spec
            .processes
            .iter()
            .flat_map(|p| {
                p.inputs.iter().filter(|i| i.port == "env").map(|i| Arc::from(i.stream.name.as_str()))
            })
            .chain(spec.forget.sooner.values().flat_map(|s| s.streams.iter().map(|n| Arc::from(n.as_str()))))
            .collect();
        env_names.sort();
        env_names.dedup();
        let mut types: Vec<TypeInfo> = spec
            .types
            .iter()
            .map(|record| own_names(record))
            .map(|record| TypeInfo {
                name: record.name.clone(),
                forget: spec.forget.after(&record.name),
                record,
                links_into: Vec::new(),
                model: None,
                sooner: None,
                made_elsewhere: false,
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
            let mut condition_functions = functions.clone();
            condition_functions.extend(unit.functions());
            let conditions = LinkConditions::compile(link, condition_functions, &env_names).map_err(|e| {
                BuildError::Condition {
                    link: process.name.clone(),
                    condition: e.condition,
                    messages: e.messages,
                }
            })?;
            let id = links.len() as LinkId;
            types[to_ty as usize].links_into.push(id);
            let mut link_process = LinkProcess::new(
                Arc::from(process.name.as_str()),
                from_ty,
                to_ty,
                link.via.entry.clone(),
                unit,
                conditions,
            );
            // The names a source of its `from` objects goes by: each input stream and its producer.
            for input in process.inputs.iter().filter(|i| i.port == "from") {
                link_process.from_sources.push(input.stream.name.clone());
                if let Some(producer) = spec.processes.get(input.stream.producer) {
                    link_process.from_sources.push(producer.name.clone());
                }
            }
            links.push(link_process);
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

        for ty in &mut types {
            ty.made_elsewhere = ty.links_into.is_empty()
                && spec
                    .processes
                    .iter()
                    .any(|p| matches!(&p.kind, hir::ProcessKind::Link(l) if *l.to_type == *ty.name));
        }

        // A percept type is forgotten only when the spec says so for that type (`forget
        // VisionPercept after 600ms`): the default forget time is about derived objects.
        for ty in &mut types {
            if ty.links_into.is_empty() {
                ty.forget = spec.forget.per_type.get(&*ty.name).copied();
                continue;
            }
            // `forget ... after T when C` for the derived objects of the type.
            if let Some(sooner) = spec.forget.sooner(&ty.name) {
                let formula =
                    forget_formula(&sooner.condition, functions.clone(), &env_names).map_err(|messages| {
                        BuildError::Condition {
                            link: format!("forget {}", ty.name),
                            condition: "when",
                            messages,
                        }
                    })?;
                ty.sooner = Some(Sooner { after: sooner.after, group: ProgressorGroup::new(formula) });
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

        let mut store = Store::new(types.iter().map(|t| t.record.symbol.clone()).collect());
        store.set_numbering(numbering);
        let mut engine = Anchoring {
            types,
            type_order,
            subtype,
            links,
            link_order,
            store,
            source_ids: BTreeMap::new(),
            source_percepts: Vec::new(),
            source_times: Vec::new(),
            identifications: Vec::new(),
            last_time: None,
            step: 0,
            pending: Vec::new(),
            notes,
            keys: Vec::new(),
            hypotheses: Vec::new(),
            env: vec![None; env_names.len()],
            env_names,
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
        self.pending.push((
            links_into.first().copied(),
            Change::new(
                time,
                ChangeKind::Created,
                symbol.clone(),
                self.types[ty_id as usize].name.clone(),
                Cause::Identify,
            )
            .name(&name),
        ));
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

    /// The name of the source a percept's `Origin::Percept { source }` refers to.
    pub(crate) fn source_name(&self, source: u32) -> Option<&str> {
        self.source_ids.iter().find(|(_, id)| **id == source).map(|(name, _)| name.as_str())
    }

    pub(crate) fn source_id(&mut self, source: &str) -> u32 {
        if let Some(id) = self.source_ids.get(source) {
            return *id;
        }
        let id = self.source_percepts.len() as u32;
        self.source_ids.insert(source.to_string(), id);
        self.source_percepts.push(Vec::new());
        self.source_times.push(None);
        id
    }

    /// Advances every link to `time` (after the previous step's) with the snapshots of the
    /// sources that report at this time (at most one per source): each link, in the order of
    /// the hierarchy, takes one step ([`Anchoring::step_link`]) whose `from` objects are the
    /// percepts listed at this time, or for a link from a type made by links, every object of
    /// that type as the links before it left it. A source without a snapshot at this time has
    /// no state now: its percepts are not stepped (nothing is held over). On error nothing
    /// changes.
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
        for (_, mut change) in self.pending.drain(..) {
            change.time = time;
            out.changes.push(change);
        }
        for (input, ty) in resolved {
            self.ingest(time, input.source, ty, input.objects, &mut out);
        }
        let mut from = Vec::new();
        for k in 0..self.link_order.len() {
            let l = self.link_order[k];
            from.clear();
            self.current_objects(l, time, &mut from);
            self.run_link(l, time, &from, &[], &mut out);
        }
        Ok(out)
    }

    /// One step of one link process at `time`, with its own input state, as the runtime runs a
    /// link process: the snapshots of its `from` streams at this state (a stream without a
    /// sample now is left out; a snapshot held over from an earlier valid time, `use most
    /// recent`, counts as not measured now) and its unit's extra inputs. Snapshots of a type no
    /// link of this engine leads into (percepts, or objects made on another host) are taken into
    /// the store first (once per stream and time). Then: objects of the link's type due to be
    /// forgotten are not predicted, the others without an incoming link are; the link's
    /// instances of the objects in the state progress their conditions; identifications of its
    /// type are matched; grounding and forgetting follow. Each link steps in strictly increasing
    /// time; links step independently (a link downstream may lag behind). On error nothing
    /// changes.
    pub fn step_link_env(
        &mut self,
        link: &str,
        time: Time,
        from: &[FromSnapshot<'_>],
        extra: &[Option<Value>],
        env: &[(&str, &Value)],
    ) -> Result<StepOutput, StepError> {
        for (slot, name) in self.env.iter_mut().zip(&self.env_names) {
            *slot = env.iter().find(|(n, _)| *n == &**name).map(|(_, v)| (*v).clone());
        }
        let output = self.step_link(link, time, from, extra);
        self.env.iter_mut().for_each(|v| *v = None);
        output
    }

    /// The names of the streams the spec's conditions read (a link's `env` inputs and forget
    /// conditions'): what [`Anchoring::step_link_env`] takes.
    pub fn env_names(&self) -> &[Arc<str>] {
        &self.env_names
    }

    /// One step of one link process (see [`Anchoring::step_link_env`] for conditions that name
    /// streams: here they have no value).
    pub fn step_link(
        &mut self,
        link: &str,
        time: Time,
        from: &[FromSnapshot<'_>],
        extra: &[Option<Value>],
    ) -> Result<StepOutput, StepError> {
        let l = self
            .links
            .iter()
            .position(|x| &*x.name == link)
            .ok_or_else(|| StepError::UnknownLink(link.to_string()))? as LinkId;
        if let Some(previous) = self.links[l as usize].last_time
            && time <= previous
        {
            return Err(StepError::TimeNotIncreasing { time, previous });
        }
        self.last_time = Some(self.last_time.map_or(time, |t| t.max(time)));
        self.step += 1;
        let mut out = StepOutput { time, ..StepOutput::default() };
        let from_ty = self.links[l as usize].from_ty;
        let fed = self.types[from_ty as usize].links_into.is_empty();
        let mut objects = Vec::new();
        for snapshot in from {
            let current = snapshot.valid == time;
            if fed && current {
                let source = self.source_id(snapshot.stream);
                if self.source_times[source as usize].is_none_or(|t| t < time) {
                    self.ingest(time, snapshot.stream, from_ty, snapshot.objects, &mut out);
                }
            }
            let Value::List(items) = snapshot.objects else {
                if !fed {
                    out.warn(
                        time,
                        format!(
                            "link `{link}`: input `{}` is {}, expected a list of objects; ignored",
                            snapshot.stream,
                            with_article(snapshot.objects.kind())
                        ),
                    );
                }
                continue;
            };
            for item in items.iter() {
                let Some(id) = item.as_record().and_then(|r| r.id.as_deref()) else { continue };
                let Some(key) = self.store.by_symbol(from_ty, id) else { continue };
                if objects.iter().any(|(k, _)| *k == key) {
                    continue;
                }
                let Some(object) = self.store.get(key) else { continue };
                let value = if fed && current {
                    // What the store took in (its status attributes set), unless it is another
                    // source's object.
                    if object.last_seen != time || !object.present {
                        continue;
                    }
                    object.value.clone()
                } else if current {
                    item.clone()
                } else {
                    status::held(item, time)
                };
                objects.push((key, value));
            }
        }
        self.run_link(l, time, &objects, extra, &mut out);
        Ok(out)
    }

    /// The `from` objects of link `l` in [`Anchoring::step`]: the percepts listed at `time` by the
    /// sources the link reads (a source no link from the type names goes to all of them), or
    /// every (not partial) object of a type made by links.
    fn current_objects(&self, l: LinkId, time: Time, out: &mut Vec<(ObjectKey, Value)>) {
        let ty = self.links[l as usize].from_ty;
        let fed = self.types[ty as usize].links_into.is_empty();
        let read_by = |source: u32, link: &LinkProcess| {
            self.source_name(source).is_some_and(|n| link.from_sources.iter().any(|s| s == n))
        };
        for key in self.store.objects_of(ty) {
            let Some(object) = self.store.get(key) else { continue };
            let current = match object.origin {
                Origin::Percept { source } if fed => {
                    object.present
                        && object.last_seen == time
                        && (read_by(source, &self.links[l as usize])
                            || !self.links.iter().any(|other| other.from_ty == ty && read_by(source, other)))
                }
                _ => !object.is_partial(),
            };
            if current {
                out.push((key, object.value.clone()));
            }
        }
    }

    /// A link's step on the objects of its state (see [`Anchoring::step_link`]).
    fn run_link(
        &mut self,
        l: LinkId,
        time: Time,
        from: &[(ObjectKey, Value)],
        extra: &[Option<Value>],
        out: &mut StepOutput,
    ) {
        let mut k = 0;
        while k < self.pending.len() {
            if self.pending[k].0 == Some(l) {
                let (_, mut change) = self.pending.remove(k);
                change.time = time;
                out.changes.push(change);
            } else {
                k += 1;
            }
        }
        let to_ty = self.links[l as usize].to_ty;
        self.predict(to_ty, time, out);
        let mut cx = StepCtx {
            time,
            pruned: Vec::new(),
            store: &mut self.store,
            types: &self.types,
            identifications: &mut self.identifications,
            out,
            env: &self.env,
        };
        self.links[l as usize].run(l, &mut cx, from, extra);
        let pruned = std::mem::take(&mut cx.pruned);
        self.prune(pruned, time, out);
        self.links[l as usize].last_time = Some(time);
        self.match_descriptions(to_ty, time, out);
        self.ground(to_ty, time);
        self.forget(to_ty, time, out);
    }

    fn ingest(&mut self, time: Time, source: &str, ty: TypeId, objects: &Value, out: &mut StepOutput) {
        let source_id = self.source_id(source);
        self.source_times[source_id as usize] = Some(time);
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
        // Objects of a type links make elsewhere (another host) say whether they were measured;
        // percepts listed now are.
        let derived_elsewhere = self.types[ty as usize].made_elsewhere;
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
            let origin = if derived_elsewhere && !status::is_measured(item) {
                StateOrigin::HELD
            } else {
                StateOrigin::MEASURED
            };
            let key = match self.store.by_symbol(ty, &id) {
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
                    key
                }
                None => {
                    let key = self.store.insert(
                        ty,
                        id.clone(),
                        Origin::Percept { source: source_id },
                        Record::default(),
                        time,
                    );
                    if let Some(object) = self.store.get_mut(key) {
                        object.anchored = true;
                    }
                    out.changes.push(Change::new(
                        time,
                        ChangeKind::Created,
                        id,
                        type_name.clone(),
                        Cause::Source,
                    ));
                    key
                }
            };
            let step = self.step;
            let Some(object) = self.store.get_mut(key) else { continue };
            object.set_state_value(item, time, origin);
            object.seen_step = step;
            object.present = true;
            object.last_seen = time;
            listed.push(key);
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
                object.keep_state_unmeasured(time);
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
        let branches = object.prediction.as_ref().map(|run| run.branches.clone()).unwrap_or_default();
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
        self.prune(branches, time, out);
    }

    /// Removes branch objects (`removed`, cause `pruned`).
    pub(crate) fn prune(&mut self, mut branches: Vec<ObjectKey>, time: Time, out: &mut StepOutput) {
        branches.sort_by_key(|k| self.store.get(*k).map(|o| o.seq));
        for key in branches {
            let owner = self.store.get(key).and_then(|b| b.branch_of).and_then(|o| self.store.get(o));
            let owner = owner.map(|o| o.symbol.clone());
            let before = out.changes.len();
            self.remove_object(key, Cause::Pruned, time, out);
            if let (Some(owner), Some(change)) =
                (owner, out.changes.get_mut(before..).and_then(|c| c.last_mut()))
            {
                change.branch_of = Some(owner);
            }
        }
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

    /// Whether `key` is on the predicted structure of its root: its state then comes from the
    /// root's prediction, not from its link unit.
    pub(crate) fn on_prediction_path(store: &Store, key: ObjectKey) -> bool {
        let Some(root) = store.get(key).and_then(|o| o.prediction_root) else { return false };
        store.get(root).and_then(|r| r.prediction.as_ref()).is_some_and(|run| run.path.contains(&key))
    }

    /// Predicts the objects of type `ty` that have no incoming link from a present object (the
    /// roots of structures nothing feeds), with their structures; ends the prediction of those
    /// fed again. An object due to be forgotten at this step is left alone.
    fn predict(&mut self, ty: TypeId, time: Time, out: &mut StepOutput) {
        let mut keys = std::mem::take(&mut self.keys);
        keys.clear();
        keys.extend(self.store.objects_of(ty));
        for &root in &keys {
            let Some(object) = self.store.get(root) else { continue };
            // Branch objects are predicted with the structure they branch from.
            if object.origin != Origin::Derived || object.branch_of.is_some() {
                continue;
            }
            let fed = object.incoming.iter().any(|(_, p)| self.store.get(*p).is_some_and(|p| p.present));
            if fed {
                if object.prediction.is_some()
                    && let Some(run) = self.store.get_mut(root).and_then(|o| o.prediction.take())
                {
                    // Fed again: an ended prediction no longer dooms the structure.
                    if run.ended {
                        for key in self.prediction_path(root).0 {
                            if let Some(o) = self.store.get_mut(key) {
                                o.forget_now = false;
                            }
                        }
                    }
                    self.prune(run.branches, time, out);
                }
                continue;
            }
            let doomed = !object.anchored && self.forget_due(root, time, out);
            if !doomed {
                self.predict_structure(root, time, out);
            }
        }
        self.keys = keys;
    }

    fn predict_structure(&mut self, root: ObjectKey, time: Time, out: &mut StepOutput) {
        let (mut path, owner_index) = self.prediction_path(root);
        // The whole structure (the objects above the model's owner too, a car over its on-road
        // object), for a model that forgets it when the prediction ends.
        let structure = path.clone();
        let Some(owner_index) = owner_index else {
            // No model: the last state is kept, no longer measured.
            if let Some(o) = self.store.get_mut(root) {
                let run = o.prediction.take();
                o.keep_state_unmeasured(time);
                self.prune(run.map(|r| r.branches).unwrap_or_default(), time, out);
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
            previous => {
                self.prune(previous.map(|r| r.branches).unwrap_or_default(), time, out);
                let Some(state) = owner_state else { return };
                let state = Arc::new(status::without_branch((*state).clone()));
                let start = model.start(state, owner_time);
                Box::new(PredictionRun {
                    owner,
                    path: path.clone(),
                    start,
                    n_hypotheses: 0,
                    branches: Vec::new(),
                    ended: false,
                })
            }
        };
        if run.ended || model.ended(&run.start, time) {
            // Every route reached a dead end or the border: the structure stays where the
            // prediction left it, unanchored and not predicted, until it is forgotten; branch
            // objects following other routes are pruned.
            if !run.ended {
                run.ended = true;
                out.changes.push(
                    Change::new(time, ChangeKind::Predicted, root_symbol, root_type, Cause::Ended)
                        .model(model.name()),
                );
                for &key in &path {
                    if let Some(object) = self.store.get_mut(key) {
                        object.predicted = false;
                        object.hypotheses.clear();
                    }
                }
                if model.forget_when_ended() {
                    for &key in &structure {
                        if let Some(object) = self.store.get_mut(key) {
                            object.forget_now = true;
                        }
                    }
                }
                let branches = std::mem::take(&mut run.branches);
                self.prune(branches, time, out);
            }
            if let Some(o) = self.store.get_mut(root) {
                o.prediction = Some(run);
            }
            return;
        }
        let mut raw = std::mem::take(&mut self.hypotheses);
        raw.clear();
        model.predict(&run.start, time, &mut raw);
        if raw.is_empty() {
            raw.push((*run.start.state).clone());
        }
        // Most likely first.
        let likely =
            branches::likelihoods(run.start.lane.as_ref().map(|l| l.heading), &run.start.state, &raw);
        let mut order: Vec<usize> = (0..raw.len()).collect();
        order.sort_by(|&a, &b| likely[b].total_cmp(&likely[a]).then(a.cmp(&b)));
        let hypotheses: Vec<(Record, f64)> =
            order.iter().map(|&i| (status::without_branch(raw[i].clone()), likely[i])).collect();
        self.hypotheses = raw;
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
        let followers = self.follow_branches(&mut run, root, &hypotheses, model.name(), time, out);
        let split = hypotheses.len() > 1;
        let mine = followers.iter().position(|f| *f == Some(owner)).unwrap_or(0);
        for (i, &key) in path.iter().enumerate() {
            let Some(object) = self.store.get_mut(key) else { continue };
            let base = status::without_branch(object.record().map(|r| (**r).clone()).unwrap_or_default());
            let state_of = |h: &Record, likelihood: f64| {
                if i == owner_index {
                    let record = Record { id: Some(object.symbol.clone()), fields: h.fields.clone() };
                    if split { status::with_branch(record, likelihood, None) } else { record }
                } else {
                    overlay(&base, h)
                }
            };
            let (h, likelihood) = &hypotheses[mine];
            let own = state_of(h, *likelihood);
            let all: Vec<Record> =
                if split { hypotheses.iter().map(|(h, l)| state_of(h, *l)).collect() } else { Vec::new() };
            object.set_state(own, time, StateOrigin::PREDICTED);
            let status = object.status();
            object.hypotheses =
                all.into_iter().map(|r| Value::Record(Arc::new(status::with_status(r, status)))).collect();
            object.prediction_root = Some(root);
        }
        // The branch objects follow their hypotheses.
        let owner_symbol = self.store.get(owner).map(|o| o.symbol.clone());
        for (h, follower) in followers.iter().enumerate() {
            let Some(key) = *follower else { continue };
            if key == owner {
                continue;
            }
            let Some(object) = self.store.get_mut(key) else { continue };
            let (state, likelihood) = &hypotheses[h];
            let record = Record { id: Some(object.symbol.clone()), fields: state.fields.clone() };
            let record = status::with_branch(record, *likelihood, owner_symbol.as_ref());
            object.set_state(record, time, StateOrigin::PREDICTED);
            object.prediction_root = Some(root);
        }
        if let Some(o) = self.store.get_mut(root) {
            o.prediction = Some(run);
        }
    }

    /// Which object follows each hypothesis (most likely first): the owner and the run's branch
    /// objects keep following theirs (matched by state distance), a hypothesis no object follows
    /// gets a new branch object (`created`, cause `branch`), and a branch object whose hypothesis
    /// ended is pruned. Updates `run.branches`.
    fn follow_branches(
        &mut self,
        run: &mut PredictionRun,
        root: ObjectKey,
        hypotheses: &[(Record, f64)],
        model: &str,
        time: Time,
        out: &mut StepOutput,
    ) -> Vec<Option<ObjectKey>> {
        let owner = run.owner;
        let mut followers: Vec<Option<ObjectKey>> = vec![None; hypotheses.len()];
        let previous: Vec<ObjectKey> = std::iter::once(owner).chain(run.branches.iter().copied()).collect();
        let values: Vec<Value> = previous
            .iter()
            .map(|k| self.store.get(*k).map_or(Value::Bool(false), |o| o.value.clone()))
            .collect();
        let refs: Vec<&Value> = values.iter().collect();
        let records: Vec<Record> = hypotheses.iter().map(|(h, _)| h.clone()).collect();
        let assignment = branches::assign(&refs, &records, |v, h| {
            crate::link::state_distance(v, &Value::Record(Arc::new(h.clone())))
        });
        let mut ended = Vec::new();
        for (i, a) in assignment.into_iter().enumerate() {
            match a {
                Some(h) => followers[h] = Some(previous[i]),
                None if i > 0 => ended.push(previous[i]),
                None => {}
            }
        }
        self.prune(ended, time, out);
        // New hypotheses get branch objects of the owner's type.
        let Some(owner_obj) = self.store.get(owner) else { return followers };
        let (ty, owner_symbol, last_anchored) =
            (owner_obj.ty, owner_obj.symbol.clone(), owner_obj.last_anchored);
        let type_name = self.types[ty as usize].name.clone();
        for (h, follower) in followers.iter_mut().enumerate() {
            if follower.is_some() || hypotheses.len() < 2 {
                continue;
            }
            let symbol = self.store.new_symbol(ty);
            let key = self.store.insert(ty, symbol.clone(), Origin::Derived, hypotheses[h].0.clone(), time);
            if let Some(branch) = self.store.get_mut(key) {
                branch.branch_of = Some(owner);
                branch.prediction_root = Some(root);
                branch.last_anchored = last_anchored;
            }
            out.changes.push(
                Change::new(time, ChangeKind::Created, symbol, type_name.clone(), Cause::Branch)
                    .model(model)
                    .branch_of(&owner_symbol),
            );
            *follower = Some(key);
        }
        run.branches = followers.iter().flatten().copied().filter(|k| *k != owner).collect();
        followers
    }

    /// Pending identifications of type `ty` that an existing object's state satisfies.
    fn match_descriptions(&mut self, ty: TypeId, time: Time, out: &mut StepOutput) {
        for i in 0..self.identifications.len() {
            if self.identifications[i].done || self.identifications[i].ty != ty {
                continue;
            }
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
                if object.origin != Origin::Derived || object.branch_of.is_some() {
                    continue;
                }
                let condition =
                    ident.existing.entry(key).or_insert_with(|| Condition::start(&mut ident.description));
                let Condition::Pending(_) = condition else { continue };
                let state = LinkState { from: &object.value, to: None, this: Some(&object.value), env: &[] };
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

    /// Grounds the objects of `ty` (the type of the link that stepped; the types after it are
    /// grounded by the steps of the links into them): anchored exactly when a percept, or linked
    /// from an anchored object.
    fn ground(&mut self, ty: TypeId, time: Time) {
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
                    object.last_anchored = object.last_anchored.max(time);
                }
            }
        }
        self.keys = keys;
    }

    /// Removes the objects of `ty` not anchored for its forget time.
    /// Also removes those whose prediction ended with a model that forgets them at once.
    fn forget(&mut self, ty: TypeId, time: Time, out: &mut StepOutput) {
        let mut doomed = Vec::new();
        let mut keys = std::mem::take(&mut self.keys);
        keys.clear();
        keys.extend(self.store.objects_of(ty));
        for &key in &keys {
            let Some(object) = self.store.get(key) else { continue };
            if object.origin == Origin::Derived && !object.anchored && self.forget_due(key, time, out) {
                doomed.push(key);
            }
        }
        self.keys = keys;
        for key in doomed {
            self.remove_object(key, Cause::Forgotten, time, out);
        }
    }
}

impl Anchoring {
    /// Whether a derived object that is not anchored is due to be forgotten at `time`: its
    /// structure's prediction ended with a model that forgets at once, it has not been anchored
    /// for its type's forget time, or for the shorter time of `forget ... after T when C` and
    /// its state now satisfies `C` (a condition that cannot be evaluated does not hold, and
    /// says why in a warning).
    fn forget_due(&mut self, key: ObjectKey, time: Time, out: &mut StepOutput) -> bool {
        let Some(object) = self.store.get(key) else { return false };
        let unanchored_for = time.saturating_sub(object.last_anchored);
        let info = &mut self.types[object.ty as usize];
        if object.forget_now || info.forget.is_some_and(|after| unanchored_for >= after) {
            return true;
        }
        let Some(sooner) = info.sooner.as_mut() else { return false };
        if unanchored_for < sooner.after {
            return false;
        }
        let state = LinkState { from: &object.value, to: None, this: Some(&object.value), env: &self.env };
        let mut condition = Condition::start(&mut sooner.group);
        let verdict = condition.step(&mut sooner.group, time, &state);
        condition.release(&mut sooner.group);
        match verdict {
            Ok(verdict) => verdict == Some(true),
            Err(e) => {
                out.warn(
                    time,
                    format!(
                        "forget condition of {} on {}: {e}; not forgotten sooner",
                        info.name, object.symbol
                    ),
                );
                false
            }
        }
    }
}

/// A copy of a record type whose names are this engine's own: the states it makes share their
/// attribute names (reference counts touched at every state), and engines of several regions
/// stepping on different threads must not share those counters.
fn own_names(record: &RecordType) -> Arc<RecordType> {
    Arc::new(RecordType {
        name: Arc::from(&*record.name),
        parent: record.parent.as_deref().map(Arc::from),
        symbol: Arc::from(&*record.symbol),
        fields: record
            .fields
            .iter()
            .map(|f| kpl_core::FieldType { name: Arc::from(&*f.name), ty: f.ty.clone() })
            .collect(),
    })
}

/// `an int`, `a list`.
fn with_article(kind: &str) -> String {
    let vowel = kind.starts_with(['a', 'e', 'i', 'o', 'u']);
    format!("{} {kind}", if vowel { "an" } else { "a" })
}
