//! One AAPA cycle (paper III-B): camera movement alignment, consecutive frame alignment, new
//! anchors, action effects (attachments), hypothesis reasoning (attached, occluded, out of view,
//! lost), confidence, attachment following and the relations of the world state.
//!
//! [`Aapa::step`] is a pure function of the previous world state and this cycle's inputs; the
//! caller feeds each output back in (paper Fig. 2). No clock is read: time is an argument.
//!
//! ```
//! use kpl_aapa::{Aapa, Params, Percept, WorldState};
//! use kpl_core::BBox;
//!
//! let aapa = Aapa::new(Params::default()).unwrap();
//! let mut world = WorldState::default();
//! for (i, x) in [10.0, 12.0, 14.0].into_iter().enumerate() {
//!     let percepts = [Percept::new("cube0", "cube", BBox::new(x, 10.0, x + 20.0, 30.0))];
//!     world = aapa.step(i as i64 * 33_333, &percepts, &[], None, &world).unwrap();
//! }
//! let cube = world.anchor("cube0").unwrap();
//! assert!((cube.confidence - 0.2).abs() < 1e-9); // 0 when first seen, +0.1 per aligned cycle
//! ```

use std::borrow::Cow;
use std::collections::{HashMap, HashSet};

use kpl_core::{BBox, Time};

use crate::align::assign;
use crate::error::AapaError;
use crate::geometry::{
    alignment_cost, bottom_centre, centre, from_bottom_centre, intersects, is_valid, outside, scale, size,
    translate,
};
use crate::params::{ActionRule, ChildPlacement, Effect, MotionProfile, Params};
use crate::types::{
    Action, ActionPhase, Anchor, AnchorStatus, Attachment, Binding, CameraPose, Candidate, Percept, Relation,
    StillBox, Symbol, WorldState,
};

/// The AAPA algorithm with its parameters. Holds no per-run state: that is the world state.
#[derive(Debug, Clone)]
pub struct Aapa {
    params: Params,
}

/// One anchor while a cycle is being computed.
#[derive(Debug)]
struct Work {
    anchor: Anchor,
    /// Aligned to a percept (or created from one) this cycle.
    aligned: bool,
    /// Box centre last cycle after camera compensation, if the anchor was seen last cycle.
    previous_centre: Option<[f64; 2]>,
    /// Confidence at the start of this cycle (`-inf` for anchors created this cycle).
    previous_confidence: f64,
    removed: bool,
    /// The box before this cycle's alignment, and the type of the percept aligned to it (if any).
    box_before: BBox,
    percept_type: Option<Symbol>,
}

impl Aapa {
    pub fn new(params: Params) -> Result<Aapa, AapaError> {
        validate(&params)?;
        Ok(Aapa { params })
    }

    pub fn params(&self) -> &Params {
        &self.params
    }

    /// One cycle at `time` (microseconds, after the previous cycle's): `percepts` detected this
    /// frame, `actions` reported since the last cycle, the camera pose if the camera can move, and
    /// the world state the previous cycle returned (`WorldState::default()` at the start).
    pub fn step(
        &self,
        time: Time,
        percepts: &[Percept],
        actions: &[Action],
        camera: Option<&CameraPose>,
        previous: &WorldState,
    ) -> Result<WorldState, AapaError> {
        self.cycle(time, percepts, actions, camera, Cow::Borrowed(previous))
    }

    /// [`Aapa::step`] taking the previous world state by value, for the usual loop
    /// `world = aapa.step_from(.., world)?`: its anchors move into the new state instead of being
    /// copied.
    pub fn step_from(
        &self,
        time: Time,
        percepts: &[Percept],
        actions: &[Action],
        camera: Option<&CameraPose>,
        previous: WorldState,
    ) -> Result<WorldState, AapaError> {
        self.cycle(time, percepts, actions, camera, Cow::Owned(previous))
    }

    fn cycle(
        &self,
        time: Time,
        percepts: &[Percept],
        actions: &[Action],
        camera: Option<&CameraPose>,
        previous: Cow<'_, WorldState>,
    ) -> Result<WorldState, AapaError> {
        let p = &self.params;
        self.validate_inputs(time, percepts, actions, &previous)?;
        let (previous_time, previous_camera) = (previous.time, previous.camera);
        let (previous_anchors, mut bindings) = match previous {
            Cow::Borrowed(w) => (w.anchors.clone(), w.bindings.clone()),
            Cow::Owned(w) => (w.anchors, w.bindings),
        };
        let dt_seconds = previous_time.map(|t| (time - t) as f64 / 1e6);
        let mut notes = Vec::new();

        // Anchors of the previous cycle (a malformed state with duplicate symbols keeps the first).
        let mut used_symbols: HashSet<Symbol> =
            HashSet::with_capacity(previous_anchors.len() + percepts.len());
        let mut work: Vec<Work> = Vec::with_capacity(previous_anchors.len() + percepts.len());
        for anchor in previous_anchors {
            if !used_symbols.insert(anchor.symbol.clone()) {
                notes.push(format!("duplicate anchor `{}` in the previous state ignored", anchor.symbol));
                continue;
            }
            let seen_last_cycle =
                anchor.status == AnchorStatus::Visible && Some(anchor.last_seen) == previous_time;
            work.push(Work {
                previous_centre: seen_last_cycle.then(|| centre(&anchor.bbox)),
                previous_confidence: anchor.confidence,
                box_before: anchor.bbox,
                anchor,
                aligned: false,
                removed: false,
                percept_type: None,
            });
        }

        // 1a. Camera movement alignment.
        if let Some(pose) = camera {
            self.compensate_camera(pose, previous_camera.as_ref(), &mut work)?;
        }

        // Motion prediction for objects an action is moving (extension).
        if p.extensions.predict_motion
            && let Some(previous_time) = previous_time
        {
            predict_motion(&mut work, previous_time, time, p.extensions.motion_profile);
        }

        // 1b. Consecutive frame alignment.
        let cols = work.len();
        let still = still_anchors(&work, &bindings, p.extensions.still_stays);
        let mut cost = Vec::with_capacity(percepts.len() * cols);
        for percept in percepts {
            for (w, &still) in work.iter().zip(&still) {
                if w.anchor.attachment.as_ref().is_some_and(|a| a.hidden) {
                    // Contained: it cannot be what was perceived.
                    cost.push(f64::INFINITY);
                    continue;
                }
                let same_type = percept.object_type == w.anchor.object_type;
                let mut c = alignment_cost(&percept.bbox, &w.anchor.bbox, same_type, p.type_mismatch);
                if still && moved_away(&percept.bbox, &w.anchor.bbox) {
                    c *= STILL_MOVED_FACTOR;
                }
                let tentative = p.extensions.established_first && w.anchor.confidence < ESTABLISHED;
                cost.push(if tentative { 2.0 * c } else { c });
            }
        }
        let pairs = assign(&cost, percepts.len(), cols, p.theta);
        let mut percept_used = vec![false; percepts.len()];
        for (r, c) in pairs {
            percept_used[r] = true;
            let percept = &percepts[r];
            let w = &mut work[c];
            let observed = if p.extensions.restore_partial_boxes {
                restore_partial_box(&mut w.anchor, r, percepts)
            } else {
                percept.bbox
            };
            w.box_before = w.anchor.bbox;
            w.percept_type = Some(percept.object_type.clone());
            let new_centre = centre(&observed);
            w.anchor.velocity = match (w.previous_centre, dt_seconds) {
                (Some(old), Some(dt)) if dt > 0.0 => {
                    let measured = [(new_centre[0] - old[0]) / dt, (new_centre[1] - old[1]) / dt];
                    let v = w.anchor.velocity;
                    if v == [0.0, 0.0] {
                        measured
                    } else {
                        [(v[0] + measured[0]) / 2.0, (v[1] + measured[1]) / 2.0]
                    }
                }
                _ => [0.0, 0.0],
            };
            if w.anchor.moving && w.anchor.moving_since.is_some() {
                record_track(&mut w.anchor, time, &observed);
            }
            w.anchor.bbox =
                if p.extensions.average_still { average_still(&mut w.anchor, observed) } else { observed };
            vote_type(&mut w.anchor, &percept.object_type);
            w.anchor.confidence = (w.anchor.confidence + p.conf_plus).min(1.0);
            w.anchor.status = AnchorStatus::Visible;
            w.anchor.last_seen = time;
            if percept.colour.is_some() {
                w.anchor.colour = percept.colour;
            }
            w.aligned = true;
        }

        // New percepts become new anchors with confidence 0 (III-B.2c), named apart from every
        // anchor so far (`used_symbols` holds exactly the symbols of `work`).
        for (percept, _) in percepts.iter().zip(&percept_used).filter(|(_, used)| !**used) {
            let symbol = fresh_symbol(percept, &used_symbols);
            used_symbols.insert(symbol.clone());
            work.push(Work {
                anchor: Anchor {
                    colour: percept.colour,
                    last_percept_box: Some([
                        percept.bbox.x1,
                        percept.bbox.y1,
                        percept.bbox.x2,
                        percept.bbox.y2,
                    ]),
                    ..Anchor::new(
                        symbol,
                        percept.object_type.clone(),
                        percept.bbox,
                        AnchorStatus::Visible,
                        time,
                    )
                },
                aligned: true,
                previous_centre: None,
                previous_confidence: f64::NEG_INFINITY,
                removed: false,
                box_before: percept.bbox,
                percept_type: Some(percept.object_type.clone()),
            });
        }

        if p.extensions.reacquire {
            self.reacquire(&mut work, time, &mut notes);
        }

        // Effects of actions: attachments (III-B.2b) and motion. Actions moving one of several
        // identical objects wait for its motion to tell which (bindings).
        self.decide_bindings(&mut bindings, time, &mut work, &mut notes);
        // What the actions starting this cycle move (a stack that slides: its contents move too).
        let starting: HashSet<Symbol> = actions
            .iter()
            .filter(|a| a.phase == ActionPhase::Started)
            .filter_map(|a| a.args.first().cloned())
            .collect();
        for action in actions {
            self.apply_action(action, actions, &starting, time, &mut work, &mut bindings, &mut notes);
        }
        forget_stale_bindings(&mut bindings, time, &mut notes);
        if p.extensions.merge_duplicates {
            merge_duplicates(&mut work, &mut bindings, &mut notes);
        }

        // 2. Hypothesis reasoning and confidence for anchors not aligned this cycle.
        let index = symbol_index(&work);
        let maintained_by_attachment: Vec<bool> =
            (0..work.len()).map(|i| has_anchored_ancestor(i, &work, &index, p.theta_anch)).collect();
        for (i, w) in work.iter_mut().enumerate() {
            if w.aligned {
                continue;
            }
            let anchored = w.anchor.is_anchored(p.theta_anch);
            w.anchor.status = if maintained_by_attachment[i] {
                AnchorStatus::Attached
            } else if anchored && percepts.iter().any(|pc| intersects(&w.anchor.bbox, &pc.bbox)) {
                AnchorStatus::Occluded
            } else if anchored && p.image.is_some_and(|img| !inside(&w.anchor.bbox, img.width, img.height)) {
                AnchorStatus::OutOfView
            } else {
                let kept = w.anchor.confidence >= ESTABLISHED
                    && ((time - w.anchor.last_seen) as f64) <= p.extensions.keep_lost * 1e6;
                if !kept {
                    w.anchor.confidence -= p.conf_minus;
                }
                AnchorStatus::Lost
            };
            if w.anchor.confidence < 0.0 {
                w.removed = true;
            }
        }
        let removed: HashSet<Symbol> =
            work.iter().filter(|w| w.removed).map(|w| w.anchor.symbol.clone()).collect();
        work.retain(|w| !w.removed);
        for w in &mut work {
            if let Some(att) = &w.anchor.attachment
                && removed.contains(&att.parent)
            {
                notes
                    .push(format!("`{}` detached: its parent `{}` was dropped", w.anchor.symbol, att.parent));
                w.anchor.attachment = None;
            }
        }

        // Children follow their parents, parents first.
        self.follow_parents(&mut work, time);

        // 3. The world state: relations and what is passed on for inference.
        let mut relations = Vec::new();
        for w in &mut work {
            w.anchor.for_inference = w.anchor.confidence >= p.theta_inf;
            if let Some(att) = &w.anchor.attachment {
                relations.push(Relation {
                    name: "attached".into(),
                    args: [w.anchor.symbol.clone(), att.parent.clone()],
                });
                if let Some(rel) = &att.relation {
                    relations.push(rel.clone());
                }
            }
        }
        if p.spatial_relations {
            spatial_relations(&work, &mut relations);
        }
        Ok(WorldState {
            time: Some(time),
            camera: camera.copied().or(previous_camera),
            anchors: work.into_iter().map(|w| w.anchor).collect(),
            relations,
            notes,
            bindings,
        })
    }

    /// Applies one action event: directly when its moving object (argument 0) is known; a `started`
    /// event naming a type several anchors share opens a binding instead, and the matching
    /// `completed` event closes it.
    #[allow(clippy::too_many_arguments, reason = "one action of the cycle, on the cycle's state")]
    fn apply_action(
        &self,
        action: &Action,
        cycle: &[Action],
        starting: &HashSet<Symbol>,
        time: Time,
        work: &mut Vec<Work>,
        bindings: &mut Vec<Binding>,
        notes: &mut Vec<String>,
    ) {
        let theta_anch = self.params.theta_anch;
        if self.rules_for(action).next().is_none() {
            return;
        }
        // An action that puts its moving object over another, single object (`_contain(cone,
        // snitch)`) is decided, when it completes, by where that object is: the anchor of the type
        // nearest it, among all of the type that are not themselves inside something, whatever the
        // order of motion suggested (identical objects swap places in the image while they move).
        // If every one of the type is inside something (or there is none), the container is
        // inferred over the object (extension `infer_hidden`).
        if self.params.extensions.identity_by_place
            && action.phase == ActionPhase::Completed
            && self.attaches_to_mover(action)
            && names_single_other(action, work)
        {
            let open = open_binding(action, time, bindings);
            let by_type = action
                .args
                .first()
                .is_some_and(|m| !work.iter().any(|w| !w.removed && w.anchor.symbol == *m));
            let nearest = nearest_to_other(action, work, theta_anch).or_else(|| {
                let infer = by_type && self.params.extensions.infer_hidden && self.hides_in_mover(action);
                infer.then(|| infer_container(action, time, work, theta_anch, notes)).flatten()
            });
            if let Some(nearest) = nearest {
                self.bind_nearest(open, &nearest, action, time, work, bindings, notes);
                self.apply_bound(action, &nearest, time, work, notes);
                return;
            }
        }
        let by_type = action
            .args
            .first()
            .is_some_and(|arg| !work.iter().any(|w| !w.removed && w.anchor.symbol == *arg));
        let movers = match (by_type, self.params.extensions.identity_by_place) {
            (false, _) => Vec::new(),
            (true, true) => self.movers(action, cycle, starting, work),
            (true, false) => action.args.first().map_or_else(Vec::new, |arg| candidates(arg, work)),
        };
        if movers.len() <= 1 {
            match movers.first() {
                // The one object of the type the action can be moving.
                Some(&i) => {
                    let symbol = work[i].anchor.symbol.clone();
                    self.apply_bound(action, &symbol, time, work, notes);
                }
                None => {
                    for rule in self.rules_for(action) {
                        apply_rule(rule, action, time, work, &self.params, notes);
                    }
                }
            }
            return;
        }
        match action.phase {
            ActionPhase::Started => {
                let taken = bound_symbols(bindings);
                let candidates = movers
                    .into_iter()
                    .filter(|&i| !taken.contains(&work[i].anchor.symbol))
                    .map(|i| Candidate {
                        symbol: work[i].anchor.symbol.clone(),
                        start: centre(&work[i].anchor.bbox),
                        onset: None,
                        moving_at_start: moved_this_cycle(&work[i]),
                    })
                    .collect();
                bindings.push(Binding {
                    action: action.clone(),
                    started: time,
                    candidates,
                    bound: None,
                    completed: false,
                });
            }
            ActionPhase::Completed => {
                let open = open_binding(action, time, bindings);
                let actor = match open {
                    Some(i) => {
                        let symbol = match bindings[i].bound.clone() {
                            Some(symbol) => Some(symbol),
                            None => {
                                self.reassign_nearest(i, action, time, work, bindings, notes);
                                let taken = bound_symbols(bindings);
                                let symbol = near_other(action, &bindings[i], work, theta_anch, &taken)
                                    .or_else(|| first_mover(&bindings[i], work, &taken, 0.0))
                                    .or_else(|| {
                                        resolve(&action.args[0], work, theta_anch)
                                            .map(|k| work[k].anchor.symbol.clone())
                                    });
                                if let Some(symbol) = &symbol {
                                    let started = bindings[i].action.clone();
                                    self.apply_bound(&started, symbol, time, work, notes);
                                }
                                symbol
                            }
                        };
                        bindings[i].bound = symbol.clone();
                        bindings[i].completed = true;
                        symbol
                    }
                    None => resolve(&action.args[0], work, theta_anch).map(|k| work[k].anchor.symbol.clone()),
                };
                match actor {
                    Some(symbol) => self.apply_bound(action, &symbol, time, work, notes),
                    None => {
                        notes.push(format!("action `{}`: no anchor for `{}`", action.name, action.args[0]))
                    }
                }
            }
        }
    }

    /// Applies an action's rules with its moving object named by symbol.
    fn apply_bound(
        &self,
        action: &Action,
        symbol: &Symbol,
        time: Time,
        work: &mut Vec<Work>,
        notes: &mut Vec<String>,
    ) {
        let mut bound = action.clone();
        bound.args[0] = symbol.clone();
        for rule in self.rules_for(&bound) {
            apply_rule(rule, &bound, time, work, &self.params, notes);
        }
    }

    /// The anchors an action naming its moving object by type can be moving: those of the type
    /// (the established ones, if any) that are not inside another, since a contained object moves
    /// only with its container; if all are inside another, those, unless the action puts its mover
    /// over something or takes it off what it holds (a contained cone is picked up by no one).
    ///
    /// Among several, an object inside one of them whose own move of the same kind starts (or ends)
    /// in the same cycle, with the same expected end, tells which: its outermost container (CATER
    /// records a stack's contents sliding with it), when that is one of them and no other action
    /// of that kind on the type starts or ends with it.
    fn movers(
        &self,
        action: &Action,
        cycle: &[Action],
        starting: &HashSet<Symbol>,
        work: &[Work],
    ) -> Vec<usize> {
        let Some(arg) = action.args.first() else { return Vec::new() };
        let acts_on_others = self.rules_for(action).any(|r| {
            r.effects.iter().any(|e| {
                matches!(e, Effect::Attach { parent: 0, child, .. } if *child != 0)
                    || matches!(e, Effect::DetachChildren { parent: 0 })
            })
        });
        let hidden = |i: usize| work[i].anchor.attachment.as_ref().is_some_and(|a| a.hidden);
        let of_type: Vec<usize> =
            (0..work.len()).filter(|&i| !work[i].removed && work[i].anchor.object_type == *arg).collect();
        // An object inside another moves only with it: those whose outermost container is moving or
        // starting to (a stack that slides), else the free ones of the type.
        let index = symbol_index(work);
        let carried: Vec<usize> = of_type
            .iter()
            .copied()
            .filter(|&i| hidden(i))
            .filter(|&i| {
                let root = &work[root_of(i, work, &index)].anchor;
                root.moving || starting.contains(&root.symbol) || starting.contains(&root.object_type)
            })
            .collect();
        let free: Vec<usize> = of_type.iter().copied().filter(|&i| !hidden(i)).collect();
        let all = if !carried.is_empty() && !acts_on_others {
            carried
        } else if free.is_empty() && !acts_on_others {
            of_type
        } else {
            free
        };
        let established: Vec<usize> =
            all.iter().copied().filter(|&i| work[i].anchor.confidence >= ESTABLISHED).collect();
        let all = if established.is_empty() { all } else { established };
        if all.len() > 1
            && let Some(container) = container_of_co_mover(action, cycle, &all, work, &index)
        {
            return vec![container];
        }
        all
    }

    /// Whether an action's rules attach something to its moving object (argument 0 is a parent).
    fn attaches_to_mover(&self, action: &Action) -> bool {
        self.rules_for(action).any(|r| {
            r.effects.iter().any(|e| matches!(e, Effect::Attach { parent: 0, child, .. } if *child != 0))
        })
    }

    /// The box a parent's children follow: its own, or for a noisy detector's (`average_still`) seen
    /// carrier in a move that follows one profile, the fitted box (the detector's noise smoothed
    /// over the move).
    fn carrier_box(&self, parent: &Work, time: Time) -> BBox {
        let a = &parent.anchor;
        if !(self.params.extensions.average_still && a.moving && parent.aligned) {
            return a.bbox;
        }
        match (a.moving_since, a.moving_until) {
            (Some(since), Some(until)) if until > since => {
                fit_move(&a.move_track, since, until, SMOOTH_TOLERANCE).map_or(a.bbox, |path| path.bbox(time))
            }
            _ => a.bbox,
        }
    }

    /// Whether an action's rules hide something inside its moving object (`_contain`).
    fn hides_in_mover(&self, action: &Action) -> bool {
        self.rules_for(action).any(|r| {
            r.effects.iter().any(|e| matches!(e, Effect::Attach { parent: 0, hides_child: true, .. }))
        })
    }

    /// The completing action of binding `open` (if it has one) is decided for `nearest`: its started
    /// effects go to `nearest` (undone on the anchor they went to, if another); an open action on the
    /// type that had been given `nearest` by the order of motion gets another candidate.
    #[allow(clippy::too_many_arguments, reason = "one step of apply_action, on its state")]
    fn bind_nearest(
        &self,
        open: Option<usize>,
        nearest: &Symbol,
        action: &Action,
        time: Time,
        work: &mut Vec<Work>,
        bindings: &mut [Binding],
        notes: &mut Vec<String>,
    ) {
        let Some(i) = open else { return };
        if let Some(j) = bindings.iter().position(|b| b.bound.as_ref() == Some(nearest))
            && j != i
            && !(bindings[j].completed && names_single_other(&bindings[j].action, work))
        {
            let taken = bound_symbols(bindings);
            let other = bindings[j]
                .candidates
                .iter()
                .chain(&bindings[i].candidates)
                .map(|c| c.symbol.clone())
                .find(|s| s != nearest && !taken.contains(s));
            notes.push(format!(
                "action `{}` rebound from `{nearest}` to `{}`: `{nearest}` is nearest `{}`",
                bindings[j].action.name,
                other.as_deref().unwrap_or("nothing"),
                action.args.get(1).map_or("", |a| a.as_ref())
            ));
            if !bindings[j].completed {
                if let Some(w) = work.iter_mut().find(|w| w.anchor.symbol == *nearest) {
                    stop_moving(&mut w.anchor);
                }
                if let Some(other) = &other {
                    let started = bindings[j].action.clone();
                    self.apply_bound(&started, other, time, work, notes);
                }
            }
            bindings[j].bound = other;
        }
        if bindings[i].bound.as_ref() != Some(nearest) {
            if let Some(previous) = bindings[i].bound.clone()
                && let Some(w) = work.iter_mut().find(|w| w.anchor.symbol == previous)
            {
                stop_moving(&mut w.anchor);
            }
            let started = bindings[i].action.clone();
            self.apply_bound(&started, nearest, time, work, notes);
        }
        bindings[i].bound = Some(nearest.clone());
        bindings[i].completed = true;
    }

    /// An action that names another, single object (`_contain(cone, snitch)`) is decided by where
    /// that object is when it completes, the surest evidence there is. If the candidate nearest it
    /// was taken by another action on the type that was decided only by the order of motion (a
    /// lift shows before a slide that started earlier), that other action gets another candidate.
    fn reassign_nearest(
        &self,
        i: usize,
        action: &Action,
        time: Time,
        work: &mut Vec<Work>,
        bindings: &mut [Binding],
        notes: &mut Vec<String>,
    ) {
        let Some(nearest) = near_other(action, &bindings[i], work, self.params.theta_anch, &[]) else {
            return;
        };
        let Some(j) = bindings.iter().position(|b| b.bound.as_ref() == Some(&nearest)) else { return };
        if j == i || names_single_other(&bindings[j].action, work) {
            return;
        }
        let taken = bound_symbols(bindings);
        let Some(other) = bindings[j]
            .candidates
            .iter()
            .map(|c| c.symbol.clone())
            .find(|s| *s != nearest && !taken.contains(s))
        else {
            return;
        };
        notes.push(format!(
            "action `{}` rebound from `{nearest}` to `{other}`: `{}` is nearest `{}`",
            bindings[j].action.name,
            nearest,
            action.args.get(1).map_or("", |a| a.as_ref())
        ));
        if let Some(w) = work.iter_mut().find(|w| w.anchor.symbol == nearest) {
            stop_moving(&mut w.anchor);
        }
        if !bindings[j].completed {
            let started = bindings[j].action.clone();
            self.apply_bound(&started, &other, time, work, notes);
        }
        bindings[j].bound = Some(other);
    }

    /// Notes which candidates started moving, decides the open bindings (oldest first) whose
    /// moving object now shows, and applies their started effects.
    fn decide_bindings(
        &self,
        bindings: &mut [Binding],
        time: Time,
        work: &mut Vec<Work>,
        notes: &mut Vec<String>,
    ) {
        for binding in bindings.iter_mut().filter(|b| b.bound.is_none()) {
            for c in binding.candidates.iter_mut().filter(|c| c.onset.is_none()) {
                if displacement(c, work).is_some_and(|d| d >= ONSET_PX) {
                    c.onset = Some(time);
                }
            }
        }
        let mut order: Vec<usize> = (0..bindings.len()).collect();
        order.sort_by_key(|&k| bindings[k].started);
        for k in order {
            let b = &bindings[k];
            if b.bound.is_some() || names_single_other(&b.action, work) {
                continue;
            }
            // Two actions on the type started together: the order of motion cannot tell which is
            // which; wait for their completion.
            let twin = bindings.iter().enumerate().any(|(j, o)| {
                j != k
                    && o.bound.is_none()
                    && o.started == b.started
                    && o.action.args.first() == b.action.args.first()
            });
            if twin {
                continue;
            }
            let taken = bound_symbols(bindings);
            if let Some(symbol) = first_mover(&bindings[k], work, &taken, BINDING_MIN_MOVE) {
                self.apply_bound(&bindings[k].action, &symbol, time, work, notes);
                bindings[k].bound = Some(symbol);
            }
        }
    }

    fn validate_inputs(
        &self,
        time: Time,
        percepts: &[Percept],
        actions: &[Action],
        previous: &WorldState,
    ) -> Result<(), AapaError> {
        if let Some(previous_time) = previous.time
            && time <= previous_time
        {
            return Err(AapaError::TimeNotIncreasing { time, previous: previous_time });
        }
        for percept in percepts {
            if !is_valid(&percept.bbox) {
                let b = percept.bbox;
                return Err(AapaError::InvalidBox {
                    label: percept.label.to_string(),
                    x1: b.x1,
                    y1: b.y1,
                    x2: b.x2,
                    y2: b.y2,
                });
            }
        }
        for action in actions {
            for rule in self.rules_for(action) {
                let need = rule.arity();
                if action.args.len() < need {
                    return Err(AapaError::ActionArity {
                        name: action.name.to_string(),
                        got: action.args.len(),
                        need,
                    });
                }
            }
        }
        Ok(())
    }

    fn rules_for<'a>(&'a self, action: &'a Action) -> impl Iterator<Item = &'a ActionRule> + 'a {
        self.params.action_rules.iter().filter(move |r| *r.action == *action.name && r.phase == action.phase)
    }

    /// III-B.1a: move every anchor by the image motion the camera's translation causes for points
    /// on the work surface (`p + |c_{t+1} - c_t|` in the paper, with the depth change as a zoom).
    fn compensate_camera(
        &self,
        pose: &CameraPose,
        old: Option<&CameraPose>,
        work: &mut [Work],
    ) -> Result<(), AapaError> {
        let model = self.params.camera.ok_or(AapaError::NoCameraModel)?;
        let depth_new = model.surface_z - pose.z;
        if !(pose.x.is_finite() && pose.y.is_finite() && depth_new.is_finite() && depth_new > 0.0) {
            return Err(AapaError::InvalidCameraPose);
        }
        let Some(old) = old else { return Ok(()) };
        let depth_old = model.surface_z - old.z;
        if depth_old.is_nan() || depth_old <= 0.0 {
            return Ok(());
        }
        let zoom = depth_old / depth_new;
        let shift =
            [-model.focal_px * (pose.x - old.x) / depth_new, -model.focal_px * (pose.y - old.y) / depth_new];
        if zoom == 1.0 && shift == [0.0, 0.0] {
            return Ok(());
        }
        let [cx, cy] = model.principal;
        let map = |u: f64, v: f64| [cx + (u - cx) * zoom + shift[0], cy + (v - cy) * zoom + shift[1]];
        for w in work {
            let b = w.anchor.bbox;
            let [x1, y1] = map(b.x1, b.y1);
            let [x2, y2] = map(b.x2, b.y2);
            w.anchor.bbox = BBox::new(x1, y1, x2, y2);
            if let Some(c) = w.previous_centre {
                w.previous_centre = Some(map(c[0], c[1]));
            }
            w.anchor.velocity = [w.anchor.velocity[0] * zoom, w.anchor.velocity[1] * zoom];
            if let Some(att) = &mut w.anchor.attachment {
                att.offset = [att.offset[0] * zoom, att.offset[1] * zoom];
                att.size = [att.size[0] * zoom, att.size[1] * zoom];
                att.parent_scale *= zoom;
                att.parent_size = [att.parent_size[0] * zoom, att.parent_size[1] * zoom];
            }
        }
        Ok(())
    }

    /// Extension: a confirmed new anchor of a type whose older anchor is unseen, of about the same
    /// size, takes the old symbol (the object moved out of θ's reach while hidden, or leapt).
    fn reacquire(&self, work: &mut [Work], time: Time, notes: &mut Vec<String>) {
        let p = &self.params;
        let index = symbol_index(work);
        for n in 0..work.len() {
            let new_symbol = &work[n].anchor.symbol;
            let confirmed_now = work[n].aligned
                && work[n].previous_confidence < p.theta_anch
                && work[n].anchor.is_anchored(p.theta_anch)
                && !work[n].removed
                && work[n].anchor.attachment.is_none()
                && !work
                    .iter()
                    .any(|w| w.anchor.attachment.as_ref().is_some_and(|a| a.parent == *new_symbol));
            if !confirmed_now {
                continue;
            }
            let best = (0..work.len())
                .filter(|&m| {
                    let (old, new) = (&work[m], &work[n]);
                    m != n
                        && !old.aligned
                        && !old.removed
                        && old.anchor.is_anchored(p.theta_anch)
                        && old.anchor.object_type == new.anchor.object_type
                        && old.anchor.first_seen < new.anchor.first_seen
                        && similar_size(&old.anchor.bbox, &new.anchor.bbox)
                        && !has_anchored_ancestor(m, work, &index, p.theta_anch)
                        // H1 (`still_stays`): an object no action has moved since it was last
                        // seen is where it was; a detection elsewhere is another (a false one).
                        && (!p.extensions.still_stays
                            || old.anchor.moving
                            || old.anchor.last_moved.is_some_and(|t| t >= old.anchor.last_seen)
                            || !moved_away(&new.anchor.bbox, &old.anchor.bbox))
                })
                .min_by(|&a, &b| {
                    let cost =
                        |m: usize| alignment_cost(&work[n].anchor.bbox, &work[m].anchor.bbox, true, 1.0);
                    cost(a).total_cmp(&cost(b))
                });
            let Some(m) = best else { continue };
            let new = work[n].anchor.clone();
            let old = &mut work[m];
            notes.push(format!(
                "`{}` re-acquired (was anchored as `{}` for {} µs)",
                old.anchor.symbol,
                new.symbol,
                time - new.first_seen
            ));
            old.anchor.bbox = new.bbox;
            old.anchor.velocity = new.velocity;
            old.anchor.status = AnchorStatus::Visible;
            old.anchor.last_seen = time;
            old.anchor.confidence = (old.anchor.confidence + p.conf_plus).min(1.0);
            stop_moving(&mut old.anchor);
            if new.colour.is_some() {
                old.anchor.colour = new.colour;
            }
            old.aligned = true;
            work[n].removed = true;
        }
    }

    /// Places every child that is not seen but maintained by its attachment relative to its
    /// parent; refreshes the geometry of children that are seen.
    fn follow_parents(&self, work: &mut [Work], time: Time) {
        let index = symbol_index(work);
        let depth = |mut i: usize| {
            let mut d = 0;
            while let Some(att) = &work[i].anchor.attachment {
                match index.get(&att.parent) {
                    Some(&parent) if d < work.len() => {
                        i = parent;
                        d += 1;
                    }
                    _ => break,
                }
            }
            d
        };
        let mut order: Vec<usize> =
            (0..work.len()).filter(|&i| work[i].anchor.attachment.is_some()).collect();
        let depths: Vec<usize> = (0..work.len()).map(depth).collect();
        order.sort_by_key(|&i| depths[i]);
        for i in order {
            let Some(att) = work[i].anchor.attachment.clone() else { continue };
            let Some(&parent) = index.get(&att.parent) else { continue };
            let parent_box = self.carrier_box(&work[parent], time);
            let parent_moving = work[parent].anchor.moving;
            let parent_seen_still = work[parent].aligned && !parent_moving;
            let w = &mut work[i];
            if att.provisional && !w.aligned {
                if parent_seen_still {
                    // The parent is seen where it came over the child: the geometry is fixed from
                    // the child's box, which has not moved.
                    let mut geometry = geometry_of(&w.anchor.bbox, att.parent, &parent_box, att.relation);
                    geometry.hidden = att.hidden;
                    w.anchor.attachment = Some(geometry);
                    continue;
                }
                if parent_moving && let Some(a) = &mut w.anchor.attachment {
                    a.provisional = false;
                }
            }
            if att.settling && !w.aligned {
                if !parent_moving {
                    // A noisy detector's parent standing still: the child inside has not moved;
                    // the geometry is measured again against the parent's averaged box.
                    let mut geometry = geometry_of(&w.anchor.bbox, att.parent, &parent_box, att.relation);
                    geometry.hidden = att.hidden;
                    geometry.settling = true;
                    w.anchor.attachment = Some(geometry);
                    continue;
                }
                if let Some(a) = &mut w.anchor.attachment {
                    a.settling = false;
                }
            }
            if w.aligned {
                let mut geometry = geometry_of(&w.anchor.bbox, att.parent, &parent_box, att.relation);
                geometry.hidden = att.hidden;
                w.anchor.attachment = Some(geometry);
            } else if w.anchor.status == AnchorStatus::Attached {
                let k = if self.params.extensions.scale_attached {
                    scale(&parent_box) / att.parent_scale
                } else {
                    1.0
                };
                // The offset scales with the parent's width and height (a carried object's offset
                // in the image follows its carrier's shape, not only its size).
                let [kx, ky] = match att.parent_size {
                    [w0, h0] if self.params.extensions.scale_attached && w0 > 0.0 && h0 > 0.0 => {
                        [parent_box.width() / w0, parent_box.height() / h0]
                    }
                    _ => [k, k],
                };
                let base = bottom_centre(&parent_box);
                let reference = [base[0] + att.offset[0] * kx, base[1] + att.offset[1] * ky];
                // Its size too: an object under a cone that comes nearer the camera grows as the cone's
                // box does, in width and height apart (the view from above foreshortens heights).
                let followed = from_bottom_centre(reference, [att.size[0] * kx, att.size[1] * ky]);
                if followed != w.anchor.bbox {
                    // Carried: the boxes seen of it before are not where it is now.
                    w.anchor.still = None;
                }
                w.anchor.bbox = followed;
            }
        }
    }
}

fn validate(p: &Params) -> Result<(), AapaError> {
    let bad = |name, reason: &str| Err(AapaError::InvalidParam { name, reason: reason.to_owned() });
    if !(p.theta.is_finite() && p.theta > 0.0) {
        return bad("theta", "must be a positive number");
    }
    if !(p.type_mismatch.is_finite() && p.type_mismatch >= 1.0) {
        return bad("type_mismatch", "must be a number >= 1");
    }
    if !(0.0..=1.0).contains(&p.theta_anch) {
        return bad("theta_anch", "must be in [0, 1]");
    }
    if !(p.theta_anch..=1.0).contains(&p.theta_inf) {
        return bad("theta_inf", "must be in [theta_anch, 1]");
    }
    if !(p.conf_plus > 0.0 && p.conf_plus <= 1.0) {
        return bad("conf_plus", "must be in (0, 1]");
    }
    if !(p.conf_minus > 0.0 && p.conf_minus <= 1.0) {
        return bad("conf_minus", "must be in (0, 1]");
    }
    if !(p.extensions.keep_lost.is_finite() && p.extensions.keep_lost >= 0.0) {
        return bad("keep_lost", "must be a number of seconds, 0 or more");
    }
    let [w, c] = p.extensions.infer_hidden_box;
    if !(w.is_finite() && w > 0.0 && c.is_finite()) {
        return bad("infer_hidden_box", "width must be a positive number and the centre finite");
    }
    if let Some(img) = p.image
        && !(img.width > 0.0 && img.height > 0.0 && img.width.is_finite() && img.height.is_finite())
    {
        return bad("image", "width and height must be positive");
    }
    if let Some(cam) = p.camera
        && !(cam.focal_px > 0.0 && cam.focal_px.is_finite() && cam.surface_z.is_finite())
    {
        return bad("camera", "focal_px must be positive and surface_z finite");
    }
    Ok(())
}

/// The box is entirely inside the image (a detector misses objects cut by the border).
fn inside(b: &BBox, width: f64, height: f64) -> bool {
    !outside(b, width, height) && b.x1 >= 0.0 && b.y1 >= 0.0 && b.x2 <= width && b.y2 <= height
}

/// Moves unseen anchors that an action is moving (extension). With the ease-in-out profile and a
/// known start and end, the velocity last measured (at time fraction `u0`) fixes the displacement of
/// the whole move, `D = v T / s'(u0)`, and the anchor advances by `D (s(u) - s(u_prev))`; near
/// either end of the move (`s'(u0)` small) that estimate is unstable and the constant velocity
/// model is used instead. With the fitted profile, the positions seen during the move choose the
/// profile and the displacement ([`fit_move`]), and the anchor is placed on that path.
fn predict_motion(work: &mut [Work], previous_time: Time, time: Time, profile: MotionProfile) {
    let ease = |u: f64| {
        let u = u.clamp(0.0, 1.0);
        u * u * (3.0 - 2.0 * u)
    };
    for w in work.iter_mut().filter(|w| w.anchor.moving) {
        let end = w.anchor.moving_until.map_or(time, |until| until.min(time));
        let dt = (end - previous_time).max(0) as f64 / 1e6;
        let v = w.anchor.velocity;
        // A move fitted from where it was seen, once it is out of sight (a one-step prediction for
        // an object seen last cycle is the measured velocity's, below).
        let fitted = match (profile, w.anchor.moving_since, w.anchor.moving_until) {
            (MotionProfile::Fitted, Some(since), Some(until))
                if !w.aligned && w.previous_centre.is_none() && until > since =>
            {
                fit_move(&w.anchor.move_track, since, until, FIT_TOLERANCE)
            }
            _ => None,
        };
        if let Some(path) = fitted {
            let target = path.at(end);
            let now = centre(&w.anchor.bbox);
            w.anchor.bbox = translate(&w.anchor.bbox, [target[0] - now[0], target[1] - now[1]]);
        } else if !w.aligned
            && v != [0.0, 0.0]
            && dt > 0.0
            && w.anchor.moving_since.is_none_or(|since| w.anchor.last_seen >= since)
        {
            // (Only a velocity measured during this move: one from before it says nothing of it.)
            let mut shift = [v[0] * dt, v[1] * dt];
            if let (MotionProfile::EaseInOut | MotionProfile::Fitted, Some(since), Some(until)) =
                (profile, w.anchor.moving_since, w.anchor.moving_until)
                && until > since
            {
                let duration = (until - since) as f64;
                let fraction = |t: Time| (t - since) as f64 / duration;
                let u0 = fraction(w.anchor.last_seen).clamp(0.0, 1.0);
                let slope = 6.0 * u0 * (1.0 - u0);
                if slope >= 0.3 {
                    let seconds = duration / 1e6;
                    let progress = ease(fraction(end)) - ease(fraction(previous_time));
                    shift = [v[0] * seconds / slope * progress, v[1] * seconds / slope * progress];
                }
            }
            w.anchor.bbox = translate(&w.anchor.bbox, shift);
        }
        if w.anchor.moving_until.is_some_and(|until| time >= until) {
            stop_moving(&mut w.anchor);
        }
    }
}

/// Positions seen during a move kept at most (a move of CATER's lasts at most 45 frames).
const MOVE_TRACK_MAX: usize = 120;

/// Notes where a moving object's box centre is seen.
fn record_track(anchor: &mut Anchor, time: Time, b: &BBox) {
    if anchor.move_track.len() >= MOVE_TRACK_MAX {
        // Keep the start, where the path begins.
        anchor.move_track.remove(1);
    }
    let [x, y] = centre(b);
    anchor.move_track.push([time as f64, x, y, b.width(), b.height()]);
}

/// The path of a move fitted to how it was seen: the box's centre and size along one profile.
#[derive(Debug, Clone, Copy)]
struct MovePath {
    /// Centre x, y, width, height at the start and their change over the whole move.
    from: [f64; 4],
    change: [f64; 4],
    profile: fn(f64) -> f64,
    since: Time,
    until: Time,
}

impl MovePath {
    fn state(&self, t: Time) -> [f64; 4] {
        let u = ((t - self.since) as f64 / (self.until - self.since) as f64).clamp(0.0, 1.0);
        let s = (self.profile)(u);
        std::array::from_fn(|k| self.from[k] + self.change[k] * s)
    }

    fn at(&self, t: Time) -> [f64; 2] {
        let [x, y, ..] = self.state(t);
        [x, y]
    }

    /// The box at time `t`.
    fn bbox(&self, t: Time) -> BBox {
        let [x, y, w, h] = self.state(t);
        BBox::new(x - w / 2.0, y - h / 2.0, x + w / 2.0, y + h / 2.0)
    }
}

/// The profiles a move is fitted with; smooth first, which wins unless another fits clearly
/// better (residual below [`CLEARLY_BETTER`] of smooth's).
const PROFILES: [fn(f64) -> f64; 4] =
    [|u| u * u * (3.0 - 2.0 * u), |u| u, |u| u * u, |u| 1.0 - (1.0 - u) * (1.0 - u)];
const CLEARLY_BETTER: f64 = 0.5;
/// How far (root mean square, pixels plus a share of the move's length) the positions seen may lie
/// from the best fit for it to be used to continue a move unseen, and to smooth a detector's boxes
/// of a carrier that is seen.
const FIT_TOLERANCE: [f64; 2] = [1.0, 0.03];
const SMOOTH_TOLERANCE: [f64; 2] = [3.0, 0.06];

/// Fits the positions seen since a move started (`track[0]` is where it started) with each of
/// [`PROFILES`]: for profile `s`, the displacement `D` minimising `Σ |from + D s(u_i) - x_i|²`; the
/// sizes along the best one likewise. The fit needs a position seen at least a tenth into the move
/// that has moved a pixel or more, and positions within `tolerance` (`[px, share of the move]`, root
/// mean square) of the fit.
fn fit_move(track: &[[f64; 5]], since: Time, until: Time, tolerance: [f64; 2]) -> Option<MovePath> {
    let (first, seen) = track.split_first()?;
    let [_, fx, fy, fw, fh] = *first;
    let duration = (until - since) as f64;
    let u = |t: f64| ((t - since as f64) / duration).clamp(0.0, 1.0);
    let last = seen.last()?;
    let moved = ((last[1] - fx).powi(2) + (last[2] - fy).powi(2)).sqrt();
    if u(last[0]) < 0.1 || moved < 1.0 {
        return None;
    }
    // Least squares of `value - start = D s(u)` for one dimension of the track.
    let slope = |profile: fn(f64) -> f64, k: usize, start: f64| -> Option<f64> {
        let (mut ss, mut sv) = (0.0, 0.0);
        for p in seen {
            let s = profile(u(p[0]));
            ss += s * s;
            sv += s * (p[k] - start);
        }
        (ss > 1e-9).then(|| sv / ss)
    };
    let mut best: Option<(f64, usize, [f64; 2])> = None;
    let mut smooth_residual = f64::INFINITY;
    for (k, profile) in PROFILES.iter().enumerate() {
        let (Some(dx), Some(dy)) = (slope(*profile, 1, fx), slope(*profile, 2, fy)) else { continue };
        let residual: f64 = seen
            .iter()
            .map(|p| {
                let s = profile(u(p[0]));
                (fx + dx * s - p[1]).powi(2) + (fy + dy * s - p[2]).powi(2)
            })
            .sum();
        if k == 0 {
            smooth_residual = residual;
        }
        let better = match best {
            None => true,
            Some((r, _, _)) => residual < r && residual < CLEARLY_BETTER * smooth_residual,
        };
        if better {
            best = Some((residual, k, [dx, dy]));
        }
    }
    let (residual, k, [dx, dy]) = best?;
    // A path that no single profile follows (a lift, a move across and a descent) is not
    // extrapolated by one.
    let rms = (residual / seen.len() as f64).sqrt();
    let length = (dx * dx + dy * dy).sqrt();
    if rms > tolerance[0] + tolerance[1] * length {
        return None;
    }
    let profile = PROFILES[k];
    let dw = slope(profile, 3, fw).unwrap_or(0.0);
    let dh = slope(profile, 4, fh).unwrap_or(0.0);
    Some(MovePath { from: [fx, fy, fw, fh], change: [dx, dy, dw, dh], profile, since, until })
}

/// Extension `merge_duplicates`: two anchors of one type on the same spot (boxes overlapping at an
/// IoU of [`DUPLICATE_IOU`] or more, of similar size), neither moving nor inside the other (directly
/// or through a chain of attachments), are one object anchored twice (a detector that reported it twice, or under another class for a
/// while): the younger is merged into the older, which keeps the newer sighting, the attachment
/// (if only the younger had one) and the children.
fn merge_duplicates(work: &mut [Work], bindings: &mut [Binding], notes: &mut Vec<String>) {
    for i in 0..work.len() {
        for j in 0..work.len() {
            if i == j || work[i].removed || work[j].removed {
                continue;
            }
            let (a, b) = (&work[i].anchor, &work[j].anchor);
            // `i` the older, `j` the younger.
            let same = a.object_type == b.object_type
                && (a.first_seen, &a.symbol) < (b.first_seen, &b.symbol)
                && !a.moving
                && !b.moving
                && !(a.attachment.is_some() && b.attachment.is_some())
                && similar_size(&a.bbox, &b.bbox)
                && iou(&a.bbox, &b.bbox) >= DUPLICATE_IOU;
            if !same {
                continue;
            }
            // One inside the other, directly or through a chain (a cone put over what holds its
            // twin's contents stands where its twin is): two objects, not one. Merging them would
            // attach the survivor to itself.
            let index = symbol_index(work);
            if is_ancestor(i, j, work, &index) || is_ancestor(j, i, work, &index) {
                continue;
            }
            let younger = work[j].anchor.clone();
            let (aligned, percept_type) = (work[j].aligned, work[j].percept_type.clone());
            work[j].removed = true;
            let old = &mut work[i];
            notes.push(format!(
                "`{}` merged into `{}`: one object anchored twice",
                younger.symbol, old.anchor.symbol
            ));
            if aligned && !old.aligned {
                old.anchor.bbox = younger.bbox;
                old.anchor.status = younger.status;
                old.anchor.still = younger.still;
                old.aligned = true;
                old.percept_type = percept_type;
            }
            old.anchor.last_seen = old.anchor.last_seen.max(younger.last_seen);
            old.anchor.confidence = old.anchor.confidence.max(younger.confidence);
            if old.anchor.attachment.is_none() {
                old.anchor.attachment = younger.attachment;
            }
            let survivor = old.anchor.symbol.clone();
            for w in work.iter_mut() {
                if let Some(att) = &mut w.anchor.attachment
                    && att.parent == younger.symbol
                {
                    att.parent = survivor.clone();
                }
            }
            for b in bindings.iter_mut() {
                if b.bound.as_ref() == Some(&younger.symbol) {
                    b.bound = Some(survivor.clone());
                }
                b.candidates.retain(|c| c.symbol != younger.symbol);
            }
        }
    }
}

/// The overlap from which two anchors of one type are one object ([`merge_duplicates`]).
const DUPLICATE_IOU: f64 = 0.7;

fn iou(a: &BBox, b: &BBox) -> f64 {
    let w = (a.x2.min(b.x2) - a.x1.max(b.x1)).max(0.0);
    let h = (a.y2.min(b.y2) - a.y1.max(b.y1)).max(0.0);
    let inter = w * h;
    let union = a.width() * a.height() + b.width() * b.height() - inter;
    if union <= 0.0 { 0.0 } else { inter / union }
}

/// Extension `average_still`: an object that no action moves stands still (H1), so the boxes seen
/// of it are one box plus the detector's noise. While it is not moving and each new box stays within
/// [`STILL_PX`] pixels (plus 5 % of its size) of the mean so far, the anchor's box is that mean (of at
/// most [`STILL_MAX`] boxes, so it can follow a slow drift). A box that strays is a detector's
/// outlier and left out, unless [`STILL_STRAYS`] do in a row (the object did move): then the mean
/// starts again there.
fn average_still(anchor: &mut Anchor, observed: BBox) -> BBox {
    let obs = [observed.x1, observed.y1, observed.x2, observed.y2];
    let restart = StillBox { mean: obs, count: 1, strays: 0 };
    let next = match anchor.still {
        Some(still) if !anchor.moving && !anchor.turning => {
            let m = still.mean;
            let tolerance = STILL_PX + 0.05 * scale(&observed);
            let near = (0..4).all(|k| (obs[k] - m[k]).abs() <= tolerance);
            if near {
                let n = (still.count + 1).min(STILL_MAX);
                let w = 1.0 / f64::from(n);
                StillBox { mean: std::array::from_fn(|k| m[k] + (obs[k] - m[k]) * w), count: n, strays: 0 }
            } else if still.count >= STILL_STRAYS && still.strays + 1 < STILL_STRAYS {
                StillBox { strays: still.strays + 1, ..still }
            } else {
                restart
            }
        }
        _ => restart,
    };
    anchor.still = Some(next);
    let [x1, y1, x2, y2] = next.mean;
    BBox::new(x1, y1, x2, y2)
}

/// Extension `still_stays`: the anchors no action may be moving (H1): established, not moving or
/// turning, not attached (a child moves with its parent), and not one that an undecided action on
/// identical objects may be moving.
fn still_anchors(work: &[Work], bindings: &[Binding], on: bool) -> Vec<bool> {
    if !on {
        return vec![false; work.len()];
    }
    let undecided: HashSet<&Symbol> = bindings
        .iter()
        .filter(|b| b.bound.is_none() && !b.completed)
        .flat_map(|b| b.candidates.iter().map(|c| &c.symbol))
        .collect();
    work.iter()
        .map(|w| {
            let a = &w.anchor;
            !a.moving
                && !a.turning
                && a.attachment.is_none()
                && a.confidence >= ESTABLISHED
                && !undecided.contains(&a.symbol)
        })
        .collect()
}

/// Extension `still_stays`: whether a percept lies further from an anchor's box than a detector's
/// noise explains (its centre more than [`STILL_MOVED_PX`] plus a fifth of the box's smaller side
/// away).
fn moved_away(percept: &BBox, anchor: &BBox) -> bool {
    let [a, b] = [centre(percept), centre(anchor)];
    let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
    d > STILL_MOVED_PX + 0.2 * anchor.width().min(anchor.height())
}

const STILL_MOVED_PX: f64 = 3.0;
/// How much dearer it is for an object no action moves to take a percept that lies away from it.
const STILL_MOVED_FACTOR: f64 = 10.0;

/// How far (pixels, plus 5 % of the box's size) a box of a still object may stray from the mean.
const STILL_PX: f64 = 3.0;
/// Boxes averaged at most for a still object.
const STILL_MAX: u32 = 60;
/// Boxes in a row that must stray from the mean of a still object before it starts again (fewer
/// are a detector's outliers); also the boxes a mean needs before it is kept against a stray.
const STILL_STRAYS: u32 = 3;

/// The move an action started is over (or no longer believed): no motion state is left.
fn stop_moving(anchor: &mut Anchor) {
    if anchor.moving {
        // Moved until now (or as long as it was believed to be moving).
        anchor.last_moved = anchor.moving_until.max(anchor.moving_since).or(anchor.last_moved);
    }
    anchor.moving = false;
    anchor.moving_until = None;
    anchor.moving_since = None;
    anchor.move_track = Vec::new();
}

/// Whether two boxes could be the same object seen twice: their scales (square roots of the areas)
/// within a factor 1.5 of each other.
fn similar_size(a: &BBox, b: &BBox) -> bool {
    let ratio = scale(a) / scale(b);
    (1.0 / 1.5..=1.5).contains(&ratio)
}

/// Where each anchor is in `work`, by symbol. Only attachments' parents are looked up in it, so a
/// cycle without attachments (most cycles) builds none.
fn symbol_index(work: &[Work]) -> HashMap<Symbol, usize> {
    if work.iter().all(|w| w.anchor.attachment.is_none()) {
        return HashMap::new();
    }
    work.iter().enumerate().filter(|(_, w)| !w.removed).map(|(i, w)| (w.anchor.symbol.clone(), i)).collect()
}

/// III-B.2b: kept if some ancestor in the attachment hierarchy is anchored.
fn has_anchored_ancestor(i: usize, work: &[Work], index: &HashMap<Symbol, usize>, theta_anch: f64) -> bool {
    let mut current = i;
    for _ in 0..work.len() {
        let Some(att) = &work[current].anchor.attachment else { return false };
        let Some(&parent) = index.get(&att.parent) else { return false };
        if work[parent].anchor.is_anchored(theta_anch) {
            return true;
        }
        current = parent;
    }
    false
}

/// The outermost ancestor of an anchor in the attachment hierarchy (itself if it has no parent).
fn root_of(i: usize, work: &[Work], index: &HashMap<Symbol, usize>) -> usize {
    let mut current = i;
    for _ in 0..work.len() {
        match work[current].anchor.attachment.as_ref().and_then(|a| index.get(&a.parent)) {
            Some(&parent) => current = parent,
            None => break,
        }
    }
    current
}

/// The one candidate (of `candidates`, the anchors `action`'s type may mean) that is the outermost
/// container of a hidden object whose own action of the same name and phase comes in the same
/// cycle with the same expected end: the contents of a stack move with it, and CATER records their
/// move too. `None` if another action like `action` on its type comes with it (which of two
/// stacks moving together holds the object is then not told), or if no candidate or several are.
fn container_of_co_mover(
    action: &Action,
    cycle: &[Action],
    candidates: &[usize],
    work: &[Work],
    index: &HashMap<Symbol, usize>,
) -> Option<usize> {
    let like = |a: &Action| {
        a.name == action.name && a.phase == action.phase && a.expected_end == action.expected_end
    };
    let own_type = action.args.first()?;
    if cycle.iter().filter(|a| like(a) && a.args.first() == Some(own_type)).count() != 1 {
        return None;
    }
    let mut found: Option<usize> = None;
    for other in cycle.iter().filter(|a| like(a) && a.args.first() != Some(own_type)) {
        let Some(arg) = other.args.first() else { continue };
        for i in (0..work.len()).filter(|&i| {
            !work[i].removed
                && (work[i].anchor.symbol == *arg || work[i].anchor.object_type == *arg)
                && work[i].anchor.attachment.as_ref().is_some_and(|a| a.hidden)
        }) {
            let root = root_of(i, work, index);
            if candidates.contains(&root) {
                match found {
                    Some(f) if f != root => return None,
                    _ => found = Some(root),
                }
            }
        }
    }
    found
}

fn is_ancestor(candidate: usize, of: usize, work: &[Work], index: &HashMap<Symbol, usize>) -> bool {
    let mut current = of;
    for _ in 0..work.len() {
        let Some(att) = &work[current].anchor.attachment else { return false };
        let Some(&parent) = index.get(&att.parent) else { return false };
        if parent == candidate {
            return true;
        }
        current = parent;
    }
    false
}

fn geometry_of(child: &BBox, parent_symbol: Symbol, parent: &BBox, relation: Option<Relation>) -> Attachment {
    let c = bottom_centre(child);
    let p = bottom_centre(parent);
    Attachment {
        parent: parent_symbol,
        relation,
        offset: [c[0] - p[0], c[1] - p[1]],
        size: size(child),
        parent_scale: scale(parent),
        parent_size: size(parent),
        hidden: false,
        provisional: false,
        settling: false,
    }
}

/// How far (pixels) the moving object of a binding must have moved before the binding is decided.
const BINDING_MIN_MOVE: f64 = 2.0;
/// Bindings kept at most; beyond, the oldest are dropped (a source that starts actions and never
/// completes them must not grow the world state without bound).
const MAX_BINDINGS: usize = 64;

/// The anchors of a type.
/// The anchors of a type an action can mean: those established (confidence of at least
/// [`ESTABLISHED`]) if there are any, else all. A short-lived false detection of the type is then no
/// rival to the object that has been there all along.
fn candidates(object_type: &str, work: &[Work]) -> Vec<usize> {
    let all: Vec<usize> = (0..work.len())
        .filter(|&i| !work[i].removed && &*work[i].anchor.object_type == object_type)
        .collect();
    let established: Vec<usize> =
        all.iter().copied().filter(|&i| work[i].anchor.confidence >= ESTABLISHED).collect();
    if established.is_empty() { all } else { established }
}

/// The confidence from which an anchor counts as established for action arguments.
const ESTABLISHED: f64 = 0.5;

fn bound_symbols(bindings: &[Binding]) -> Vec<Symbol> {
    bindings.iter().filter_map(|b| b.bound.clone()).collect()
}

/// How far (pixels) a candidate must move from where it was when the action started to count as
/// having started moving.
const ONSET_PX: f64 = 1.0;

/// Whether an anchor was seen this cycle at least ONSET_PX from where it was the cycle before.
fn moved_this_cycle(w: &Work) -> bool {
    let (before, now) = (centre(&w.box_before), centre(&w.anchor.bbox));
    w.aligned && (now[0] - before[0]).hypot(now[1] - before[1]) >= ONSET_PX
}

/// How far a candidate is from where it was when the action started (`None` if it is gone).
fn displacement(c: &Candidate, work: &[Work]) -> Option<f64> {
    let w = work.iter().find(|w| !w.removed && w.anchor.symbol == c.symbol)?;
    let now = centre(&w.anchor.bbox);
    Some(((now[0] - c.start[0]).powi(2) + (now[1] - c.start[1]).powi(2)).sqrt())
}

/// The candidate of a binding that started moving first (ties: the one that moved furthest), once
/// it has moved at least `min_move` pixels and no other candidate started in the same cycle unless
/// it moved less than half as far; candidates already moving when the action started are left
/// out. With `min_move` 0 (the action is over), simply that candidate (one already moving then
/// only if no other was seen to start), or the one that moved furthest if none was seen to start.
fn first_mover(binding: &Binding, work: &[Work], taken: &[Symbol], min_move: f64) -> Option<Symbol> {
    let mut moves: Vec<(Option<Time>, f64, &Symbol)> = binding
        .candidates
        .iter()
        .filter(|c| !taken.contains(&c.symbol))
        .filter_map(|c| Some((c.onset, displacement(c, work)?, &c.symbol)))
        .collect();
    // A candidate that was moving already when the action started moves for an earlier action:
    // it is the action's only if none that was still starts to move before the action ends.
    let fresh =
        |symbol: &Symbol| binding.candidates.iter().any(|c| c.symbol == *symbol && !c.moving_at_start);
    if min_move > 0.0 || moves.iter().any(|m| m.0.is_some() && fresh(m.2)) {
        moves.retain(|m| fresh(m.2));
    }
    // Earliest onset first (none last), then the furthest.
    moves.sort_by(|a, b| {
        let onset = |o: Option<Time>| o.unwrap_or(Time::MAX);
        onset(a.0).cmp(&onset(b.0)).then(b.1.total_cmp(&a.1))
    });
    let &(onset, distance, symbol) = moves.first()?;
    if min_move <= 0.0 {
        return Some(symbol.clone());
    }
    let onset = onset?;
    let rival = moves.iter().skip(1).find(|m| m.0 == Some(onset));
    let clear = distance >= min_move && rival.is_none_or(|r| distance >= 2.0 * r.1 + 0.5);
    clear.then(|| symbol.clone())
}

/// The anchor of a type (other than `to`) whose box's bottom centre is nearest `to`'s.
fn nearest(object_type: &str, to: usize, work: &[Work]) -> Option<usize> {
    let target = bottom_centre(&work[to].anchor.bbox);
    candidates(object_type, work).into_iter().filter(|&i| i != to).min_by(|&a, &b| {
        let d = |i: usize| {
            let p = bottom_centre(&work[i].anchor.bbox);
            (p[0] - target[0]).powi(2) + (p[1] - target[1]).powi(2)
        };
        d(a).total_cmp(&d(b))
    })
}

/// Whether an action names, besides its moving object, another argument that is a single anchor
/// (by symbol or as the only one of its type).
fn names_single_other(action: &Action, work: &[Work]) -> bool {
    action.args.iter().skip(1).any(|arg| {
        work.iter().any(|w| !w.removed && w.anchor.symbol == *arg) || candidates(arg, work).len() == 1
    })
}

/// The open binding an action event completes: the one of the same action and arguments whose
/// expected end is nearest.
fn open_binding(action: &Action, time: Time, bindings: &[Binding]) -> Option<usize> {
    bindings
        .iter()
        .enumerate()
        .filter(|(_, b)| !b.completed && b.action.name == action.name && b.action.args == action.args)
        .min_by_key(|(_, b)| b.action.expected_end.map_or(0, |e| (e - time).abs()))
        .map(|(i, _)| i)
}

/// The single other object an action names besides its moving object, if there is one.
fn single_other(action: &Action, work: &[Work], theta_anch: f64) -> Option<usize> {
    action.args.iter().skip(1).find_map(|arg| {
        let single =
            work.iter().any(|w| !w.removed && w.anchor.symbol == *arg) || candidates(arg, work).len() == 1;
        if single { resolve(arg, work, theta_anch) } else { None }
    })
}

/// For an action that names a type as its moving object and another, single object: the anchor of
/// that type (the established ones, if any) nearest that object, among those not inside another
/// (a contained object comes over nothing). `None` if the moving object is named by symbol.
fn nearest_to_other(action: &Action, work: &[Work], theta_anch: f64) -> Option<Symbol> {
    let mover = action.args.first()?;
    if work.iter().any(|w| !w.removed && w.anchor.symbol == *mover) {
        return None;
    }
    let other = single_other(action, work, theta_anch)?;
    let target = bottom_centre(&work[other].anchor.bbox);
    let free = |i: &usize| !work[*i].anchor.attachment.as_ref().is_some_and(|a| a.hidden);
    let all: Vec<usize> = (0..work.len())
        .filter(|&i| !work[i].removed && work[i].anchor.object_type == *mover && i != other)
        .filter(free)
        .collect();
    let established: Vec<usize> =
        all.iter().copied().filter(|&i| work[i].anchor.confidence >= ESTABLISHED).collect();
    let pool = if established.is_empty() { all } else { established };
    pool.into_iter()
        .map(|i| {
            let p = bottom_centre(&work[i].anchor.bbox);
            ((p[0] - target[0]).powi(2) + (p[1] - target[1]).powi(2), i)
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, i)| work[i].anchor.symbol.clone())
}

/// For an action that names another, single object: the candidate nearest it.
fn near_other(
    action: &Action,
    binding: &Binding,
    work: &[Work],
    theta_anch: f64,
    taken: &[Symbol],
) -> Option<Symbol> {
    let other = action.args.iter().skip(1).find_map(|arg| {
        let single =
            work.iter().any(|w| !w.removed && w.anchor.symbol == *arg) || candidates(arg, work).len() == 1;
        if single { resolve(arg, work, theta_anch) } else { None }
    })?;
    let target = bottom_centre(&work[other].anchor.bbox);
    binding
        .candidates
        .iter()
        .filter(|c| !taken.contains(&c.symbol))
        .filter_map(|c| {
            let w = work.iter().find(|w| !w.removed && w.anchor.symbol == c.symbol)?;
            let p = bottom_centre(&w.anchor.bbox);
            Some(((p[0] - target[0]).powi(2) + (p[1] - target[1]).powi(2), c.symbol.clone()))
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, symbol)| symbol)
}

/// Drops bindings whose action should long be over (a missed `completed` event) and keeps at most
/// [`MAX_BINDINGS`].
fn forget_stale_bindings(bindings: &mut Vec<Binding>, time: Time, notes: &mut Vec<String>) {
    // A completed binding is kept only while an undecided action on its type is open.
    let undecided: Vec<Symbol> = bindings
        .iter()
        .filter(|b| b.bound.is_none())
        .filter_map(|b| b.action.args.first().cloned())
        .collect();
    bindings.retain(|b| !b.completed || b.action.args.first().is_some_and(|t| undecided.contains(t)));
    bindings.retain(|b| {
        let stale = b.action.expected_end.is_some_and(|end| time > end.saturating_add(1_000_000));
        if stale {
            notes.push(format!(
                "action `{}` started at {} never completed; forgotten",
                b.action.name, b.started
            ));
        }
        !stale
    });
    if bindings.len() > MAX_BINDINGS {
        let excess = bindings.len() - MAX_BINDINGS;
        notes.push(format!("{excess} unfinished actions forgotten (more than {MAX_BINDINGS} open)"));
        bindings.drain(..excess);
    }
}

/// An anchor named by an action argument: by symbol, else the best anchor of that type.
fn resolve(arg: &str, work: &[Work], theta_anch: f64) -> Option<usize> {
    if let Some(i) = work.iter().position(|w| !w.removed && &*w.anchor.symbol == arg) {
        return Some(i);
    }
    // Among the established anchors of the type when there are any: a false detection of the type
    // seen a moment ago is not the object that has been there all along (and is now hidden).
    candidates(arg, work).into_iter().max_by(|&a, &b| {
        let (a, b) = (&work[a].anchor, &work[b].anchor);
        (a.is_anchored(theta_anch), a.last_seen)
            .cmp(&(b.is_anchored(theta_anch), b.last_seen))
            .then(a.confidence.total_cmp(&b.confidence))
            .then(b.first_seen.cmp(&a.first_seen))
    })
}

/// [`ChildPlacement::Under`]: the parent `pa` has come down over the child `c`. If the child took a
/// percept of the parent's type this cycle, that was the parent arriving: the parent gets it and
/// the child its box from before. Otherwise a parent not seen this cycle (it moved hidden) is moved
/// so that its bottom centre is the child's (a guess: the attachment is provisional). Returns the
/// parent's box and whether it was guessed.
fn put_over(c: usize, pa: usize, work: &mut [Work], time: Time) -> (BBox, bool) {
    let parent_type = work[pa].anchor.object_type.clone();
    let child = &work[c];
    let took_parent = child.aligned
        && !work[pa].aligned
        && child.percept_type.as_ref().is_some_and(|t| *t == parent_type && *t != child.anchor.object_type);
    if took_parent {
        let seen = child.anchor.bbox;
        let before = child.box_before;
        work[c].anchor.bbox = before;
        work[c].aligned = false;
        let p = &mut work[pa];
        p.anchor.bbox = seen;
        p.anchor.status = AnchorStatus::Visible;
        p.anchor.last_seen = time;
        p.aligned = true;
    } else if !work[pa].aligned {
        let base = bottom_centre(&work[c].anchor.bbox);
        let p = &mut work[pa].anchor;
        p.bbox = from_bottom_centre(base, size(&p.bbox));
        return (p.bbox, true);
    }
    (work[pa].anchor.bbox, false)
}

/// Extension `infer_hidden`, for containers: a containing action completes over a single object,
/// but every anchor of the container's type is inside another (or there is none): the container is
/// an object not seen, now over that object. Its anchor is inferred there, the size of another
/// anchor of its type if there is one (else twice the object's), established (confidence 0.5).
fn infer_container(
    action: &Action,
    time: Time,
    work: &mut Vec<Work>,
    theta_anch: f64,
    notes: &mut Vec<String>,
) -> Option<Symbol> {
    let object_type = action.args.first()?.clone();
    let other = single_other(action, work, theta_anch)?;
    let child = work[other].anchor.bbox;
    let size = work
        .iter()
        .find(|w| !w.removed && w.anchor.object_type == object_type)
        .map_or([2.0 * child.width(), 2.0 * child.height()], |w| size(&w.anchor.bbox));
    let bbox = from_bottom_centre(bottom_centre(&child), size);
    let used: HashSet<Symbol> = work.iter().map(|w| w.anchor.symbol.clone()).collect();
    let symbol = fresh_symbol(&Percept::new("", &object_type, bbox), &used);
    notes.push(format!(
        "`{symbol}` ({object_type}) inferred over `{}`: no anchor of its type could have come over it",
        work[other].anchor.symbol
    ));
    // Established: the action says it is there, as surely as a few sightings would.
    let confidence = theta_anch.max(ESTABLISHED);
    work.push(Work {
        anchor: Anchor {
            confidence,
            ..Anchor::new(symbol.clone(), object_type, bbox, AnchorStatus::Occluded, time)
        },
        aligned: false,
        previous_centre: None,
        previous_confidence: confidence,
        removed: false,
        box_before: bbox,
        percept_type: None,
    });
    Some(symbol)
}

/// Extension `infer_hidden`: an anchor for an object a containing action names but that was never
/// perceived, inside its container `pa` (a square placed by `placement`, see
/// [`Extensions::infer_hidden_box`](crate::Extensions::infer_hidden_box)).
fn infer_hidden_child(
    object_type: &Symbol,
    pa: usize,
    placement: [f64; 2],
    time: Time,
    work: &mut Vec<Work>,
    theta_anch: f64,
    notes: &mut Vec<String>,
) -> usize {
    let parent_box = work[pa].anchor.bbox;
    let [w, c] = placement;
    let side = parent_box.width() * w;
    let [cx, cy] = [centre(&parent_box)[0], parent_box.y1 + parent_box.height() * c];
    let bbox = BBox::new(cx - side / 2.0, cy - side / 2.0, cx + side / 2.0, cy + side / 2.0);
    let used: HashSet<Symbol> = work.iter().map(|w| w.anchor.symbol.clone()).collect();
    let symbol = fresh_symbol(&Percept::new("", object_type, bbox), &used);
    notes.push(format!(
        "`{symbol}` ({object_type}) inferred inside `{}`: never perceived",
        work[pa].anchor.symbol
    ));
    work.push(Work {
        anchor: Anchor {
            confidence: theta_anch,
            ..Anchor::new(symbol, object_type.clone(), bbox, AnchorStatus::Attached, time)
        },
        aligned: false,
        previous_centre: None,
        previous_confidence: theta_anch,
        removed: false,
        box_before: bbox,
        percept_type: None,
    });
    work.len() - 1
}

fn apply_rule(
    rule: &ActionRule,
    action: &Action,
    time: Time,
    work: &mut Vec<Work>,
    params: &Params,
    notes: &mut Vec<String>,
) {
    let theta_anch = params.theta_anch;
    // Other arguments that name a type several anchors share are the one nearest the moving object
    // (argument 0): what a cone comes down over is where it ends.
    let lookup = |k: usize, work: &[Work], notes: &mut Vec<String>| -> Option<usize> {
        let arg = action.args.get(k)?;
        let near = if k == 0 { None } else { action.args.first().and_then(|a| resolve(a, work, theta_anch)) };
        let found = match near {
            Some(actor)
                if candidates(arg, work).len() > 1
                    && !work.iter().any(|w| !w.removed && w.anchor.symbol == *arg) =>
            {
                nearest(arg, actor, work)
            }
            _ => resolve(arg, work, theta_anch),
        };
        if found.is_none() {
            notes.push(format!("action `{}`: no anchor for `{arg}`", action.name));
        }
        found
    };
    for effect in &rule.effects {
        match effect {
            Effect::Attach { child, parent, relation, place_child, hides_child } => {
                let Some(pa) = lookup(*parent, work, notes) else { continue };
                let c = match lookup(*child, work, notes) {
                    Some(c) => c,
                    None if *hides_child && params.extensions.infer_hidden => {
                        let Some(arg) = action.args.get(*child) else { continue };
                        infer_hidden_child(
                            arg,
                            pa,
                            params.extensions.infer_hidden_box,
                            time,
                            work,
                            theta_anch,
                            notes,
                        )
                    }
                    None => continue,
                };
                let index = symbol_index(work);
                if c == pa || is_ancestor(c, pa, work, &index) {
                    notes.push(format!(
                        "action `{}`: attaching `{}` to `{}` would make a cycle; ignored",
                        action.name, work[c].anchor.symbol, work[pa].anchor.symbol
                    ));
                    continue;
                }
                let parent_box = work[pa].anchor.bbox;
                let parent_symbol = work[pa].anchor.symbol.clone();
                let rel = relation.as_ref().and_then(|r| {
                    let a = lookup(r.args[0], work, notes)?;
                    let b = lookup(r.args[1], work, notes)?;
                    Some(Relation {
                        name: r.name.as_str().into(),
                        args: [work[a].anchor.symbol.clone(), work[b].anchor.symbol.clone()],
                    })
                });
                let (parent_box, guessed) = if *place_child == ChildPlacement::Under {
                    put_over(c, pa, work, time)
                } else {
                    (parent_box, false)
                };
                let w = &mut work[c];
                if matches!(place_child, ChildPlacement::AtParentIfApart | ChildPlacement::Under)
                    && !w.aligned
                    && !intersects(&w.anchor.bbox, &parent_box)
                {
                    w.anchor.bbox = from_bottom_centre(bottom_centre(&parent_box), size(&w.anchor.bbox));
                }
                let mut attachment = geometry_of(&w.anchor.bbox, parent_symbol, &parent_box, rel);
                attachment.hidden = *hides_child;
                attachment.provisional = guessed;
                attachment.settling = *hides_child && params.extensions.average_still;
                w.anchor.attachment = Some(attachment);
            }
            Effect::Detach { child, parent } => {
                let Some(c) = lookup(*child, work, notes) else { continue };
                let parent_symbol = match parent {
                    Some(k) => match lookup(*k, work, notes) {
                        Some(pa) => Some(work[pa].anchor.symbol.clone()),
                        None => continue,
                    },
                    None => None,
                };
                let w = &mut work[c];
                if parent_symbol.is_none_or(|ps| w.anchor.attachment.as_ref().is_some_and(|a| a.parent == ps))
                {
                    w.anchor.attachment = None;
                }
            }
            Effect::DetachChildren { parent } => {
                if let Some(pa) = lookup(*parent, work, notes) {
                    let parent_symbol = work[pa].anchor.symbol.clone();
                    for w in work.iter_mut() {
                        if w.anchor.attachment.as_ref().is_some_and(|a| a.parent == parent_symbol) {
                            w.anchor.attachment = None;
                        }
                    }
                }
            }
            Effect::StartMoving { object } => {
                if let Some(o) = lookup(*object, work, notes) {
                    work[o].anchor.moving = true;
                    work[o].anchor.moving_until = action.expected_end;
                    work[o].anchor.moving_since = Some(time);
                    work[o].anchor.last_moved = Some(time);
                    // The boxes seen before the move are not where it will stand.
                    work[o].anchor.still = None;
                    let b = work[o].anchor.bbox;
                    let [x, y] = centre(&b);
                    work[o].anchor.move_track = vec![[time as f64, x, y, b.width(), b.height()]];
                }
            }
            Effect::StopMoving { object } => {
                if let Some(o) = lookup(*object, work, notes) {
                    stop_moving(&mut work[o].anchor);
                }
            }
            Effect::StartTurning { object } | Effect::StopTurning { object } => {
                if let Some(o) = lookup(*object, work, notes) {
                    let anchor = &mut work[o].anchor;
                    anchor.turning = matches!(effect, Effect::StartTurning { .. });
                    // The mean of the boxes before (or during) the turn is not the box after it.
                    anchor.still = None;
                }
            }
        }
    }
}

/// Extension: a detector boxes only the visible part of a partly hidden object. A percept is taken
/// as such a part when it overlaps another detection, is clearly smaller than the object's last
/// unoccluded size, one edge (not its opposite) lies inside an overlapping detection, and, compared
/// with the previous percept, that edge moved inwards while the opposite edge stayed put (an object
/// that changes depth or slides moves both). Then, and for as long as that stays so, the cut edge is
/// moved out to restore the remembered size. A percept overlapping nothing refreshes the size.
fn restore_partial_box(anchor: &mut Anchor, own: usize, percepts: &[Percept]) -> BBox {
    let b = percepts[own].bbox;
    let previous = anchor.last_percept_box.map(|[x1, y1, x2, y2]| BBox::new(x1, y1, x2, y2));
    anchor.last_percept_box = Some([b.x1, b.y1, b.x2, b.y2]);
    let was_partial = std::mem::take(&mut anchor.partial);
    let occluders: Vec<&BBox> = percepts
        .iter()
        .enumerate()
        .filter(|&(k, other)| k != own && intersects(&b, &other.bbox))
        .map(|(_, other)| &other.bbox)
        .collect();
    if occluders.is_empty() {
        anchor.full_size = Some(size(&b));
        return b;
    }
    let (Some([full_w, full_h]), Some(prev)) = (anchor.full_size, previous) else { return b };
    let [x1, x2] = restore_edges(|b| [b.x1, b.x2], &b, &prev, full_w, &occluders, was_partial);
    let [y1, y2] = restore_edges(|b| [b.y1, b.y2], &b, &prev, full_h, &occluders, was_partial);
    let restored = BBox::new(x1, y1, x2, y2);
    anchor.partial = restored != b;
    restored
}

/// One axis of [`restore_partial_box`]: the percept's `[low, high]` edges on the axis `edges`
/// picks, with the cut edge moved out to restore the remembered length `full` if the rules hold.
/// (Every occluder overlaps the percept on both axes, so only the edges on this axis matter.)
fn restore_edges(
    edges: impl Fn(&BBox) -> [f64; 2],
    b: &BBox,
    prev: &BBox,
    full: f64,
    occluders: &[&BBox],
    was_partial: bool,
) -> [f64; 2] {
    const SHRUNK: f64 = 0.85;
    const TOLERANCE: f64 = 2.0;
    let ([low, high], [prev_low, prev_high]) = (edges(b), edges(prev));
    let shrunk = high - low < SHRUNK * full;
    if !shrunk {
        return [low, high];
    }
    let within = |v: f64, [lo, hi]: [f64; 2]| lo - TOLERANCE <= v && v <= hi + TOLERANCE;
    let kept = |now: f64, then: f64| (now - then).abs() <= TOLERANCE;
    // The cut edge is shrinking now, or the part was already being restored.
    let cutting = |now: f64, then: f64, inwards: f64| was_partial || (now - then) * inwards > 0.5;
    let low_cut = occluders.iter().map(|d| edges(d)).any(|d| within(low, d) && d[0] < low);
    let high_cut = occluders.iter().map(|d| edges(d)).any(|d| within(high, d) && d[1] > high);
    match (low_cut, high_cut) {
        (true, false) if kept(high, prev_high) && cutting(low, prev_low, 1.0) => [high - full, high],
        (false, true) if kept(low, prev_low) && cutting(high, prev_high, -1.0) => [low, low + full],
        _ => [low, high],
    }
}

/// Counts one detection of `object_type` for the anchor and makes its type the most frequent one
/// (the current type wins ties).
fn vote_type(anchor: &mut Anchor, object_type: &Symbol) {
    if anchor.type_votes.is_empty() {
        anchor.type_votes.push((anchor.object_type.clone(), 1));
    }
    match anchor.type_votes.iter_mut().find(|(t, _)| t == object_type) {
        Some((_, n)) => *n = n.saturating_add(1),
        None => anchor.type_votes.push((object_type.clone(), 1)),
    }
    let current = anchor.type_votes.iter().find(|(t, _)| *t == anchor.object_type).map_or(0, |(_, n)| *n);
    if let Some((best, n)) = anchor.type_votes.iter().max_by_key(|(_, n)| *n)
        && *n > current
    {
        anchor.object_type = best.clone();
    }
}

/// A new anchor takes the detector's label if no anchor has it, else `<type><n>`.
fn fresh_symbol(percept: &Percept, used: &HashSet<Symbol>) -> Symbol {
    if !percept.label.is_empty() && !used.contains(&percept.label) {
        return percept.label.clone();
    }
    (0..)
        .map(|n| Symbol::from(format!("{}{n}", percept.object_type)))
        .find(|s| !used.contains(s))
        .unwrap_or_else(|| percept.label.clone())
}

/// Image-space spatial relations among anchors passed on for inference: `left_of(a, b)` when a's
/// box ends before b's begins; `behind(a, b)` when they overlap horizontally and a stands further
/// up the image (further from a camera looking down on a table) by more than a tenth of b's height.
fn spatial_relations(work: &[Work], relations: &mut Vec<Relation>) {
    let candidates: Vec<&Anchor> = work.iter().map(|w| &w.anchor).filter(|a| a.for_inference).collect();
    for a in &candidates {
        for b in &candidates {
            if a.symbol == b.symbol {
                continue;
            }
            let (ab, bb) = (&a.bbox, &b.bbox);
            if ab.x2 <= bb.x1 {
                relations
                    .push(Relation { name: "left_of".into(), args: [a.symbol.clone(), b.symbol.clone()] });
            }
            if ab.x1 < bb.x2 && bb.x1 < ab.x2 && ab.y2 < bb.y2 - 0.1 * bb.height() {
                relations
                    .push(Relation { name: "behind".into(), args: [a.symbol.clone(), b.symbol.clone()] });
            }
        }
    }
}
