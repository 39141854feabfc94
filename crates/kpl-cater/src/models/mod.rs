//! The snitch localisation models: OPNet's programmed heuristic ([`heuristic`]), AAPA with CATER's
//! actions, AAPA without actions (the ablation) and AAPA exactly as published (`aapa-paper`, no
//! extensions, attachments from `_contain` only). Each turns a video's perception into one predicted
//! snitch box per frame (`[0, 0, 0, 0]` when AAPA has none, which the scoring counts as a miss, as
//! the paper does).

mod heuristic;

use std::collections::HashMap;

use kpl_aapa::{Aapa, Action, Params, WorldState};
use kpl_core::{BBox, Time};

pub use heuristic::heuristic;

use crate::error::CaterError;
use crate::formats::{IntBox, MovementKind, PerceptionFile, SNITCH_CLASS, Scene};

/// Microseconds per frame (30 fps).
pub const FRAME_US: Time = 33_333;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Model {
    Heuristic,
    Aapa,
    AapaNoActions,
    AapaPaper,
}

impl Model {
    pub const ALL: [Model; 4] = [Model::Heuristic, Model::Aapa, Model::AapaNoActions, Model::AapaPaper];

    pub fn name(self) -> &'static str {
        match self {
            Model::Heuristic => "heuristic",
            Model::Aapa => "aapa",
            Model::AapaNoActions => "aapa-no-actions",
            Model::AapaPaper => "aapa-paper",
        }
    }

    pub fn from_name(name: &str) -> Option<Model> {
        Model::ALL.into_iter().find(|m| m.name() == name)
    }

    /// The AAPA parameters this model uses unless overridden, for ground-truth boxes.
    pub fn default_params(self) -> Params {
        match self {
            Model::AapaPaper => Params::paper_cater(),
            _ => Params::cater(),
        }
    }

    /// The parameters for a perception whose boxes are noisy (a detector's) or not: the
    /// extended models then average the boxes of objects standing still (`average_still`, a
    /// property of the sensor); the published algorithm has no extensions.
    pub fn params_for(self, noisy_boxes: bool) -> Params {
        let mut params = self.default_params();
        if noisy_boxes && self != Model::AapaPaper {
            params.extensions.average_still = true;
        }
        params
    }
}

fn to_int(b: &BBox) -> IntBox {
    [b.x1.round() as i32, b.y1.round() as i32, b.x2.round() as i32, b.y2.round() as i32]
}

/// CATER's movements as AAPA action events, per frame: a `started` event at a move's first frame
/// (with its end time) and a `completed` one at its last. Arguments are object classes, which is
/// how AAPA's anchors (named by the detector) can be found from the annotations. `_no_op` records
/// (an object that stays put) and `_rotate`s (in place) are passed on too; AAPA's rules give them
/// no effect. Moves past the video's last frame complete at frame `frames` and are not delivered.
pub fn actions_per_frame(scene: &Scene, frames: usize) -> Vec<Vec<Action>> {
    let mut out = vec![Vec::new(); frames];
    let class_of: HashMap<&str, String> =
        scene.objects.iter().map(|o| (o.instance.as_str(), o.class())).collect();
    let mut events = Vec::new();
    for (instance, moves) in &scene.movements {
        let Some(actor) = class_of.get(instance.as_str()) else { continue };
        for m in moves {
            if m.kind() == Some(MovementKind::NoOp) {
                continue;
            }
            let mut args: Vec<&str> = vec![actor.as_str()];
            if let Some(other) = m.other.as_deref().and_then(|o| class_of.get(o)) {
                args.push(other.as_str());
            }
            events.push((m.start, 0, Action::started(&m.action, &args, Some(m.end * FRAME_US))));
            events.push((m.end, 1, Action::completed(&m.action, &args)));
        }
    }
    // Within a frame, completions after starts, in a fixed order.
    events.sort_by_key(|e| (e.0, e.1));
    for (frame, _, action) in events {
        if let Some(slot) = usize::try_from(frame).ok().and_then(|f| out.get_mut(f)) {
            slot.push(action);
        }
    }
    out
}

/// Runs a model over one video.
pub fn predict(
    model: Model,
    params: &Params,
    scene: &Scene,
    perception: &PerceptionFile,
) -> Result<Vec<IntBox>, CaterError> {
    predict_traced(model, params, scene, perception, |_, _| {})
}

/// [`predict`], handing each frame's world state to `trace` (AAPA models).
pub fn predict_traced(
    model: Model,
    params: &Params,
    scene: &Scene,
    perception: &PerceptionFile,
    mut trace: impl FnMut(usize, &WorldState),
) -> Result<Vec<IntBox>, CaterError> {
    let frames = perception.frames.len();
    match model {
        Model::Heuristic => Ok(heuristic(perception)),
        Model::Aapa | Model::AapaPaper | Model::AapaNoActions => {
            let aapa = Aapa::new(params.clone()).map_err(|source| CaterError::Aapa {
                video: scene.video.clone(),
                frame: 0,
                source,
            })?;
            let actions = if model == Model::AapaNoActions {
                vec![Vec::new(); frames]
            } else {
                actions_per_frame(scene, frames)
            };
            let mut world = WorldState::default();
            let mut out = Vec::with_capacity(frames);
            for (frame, frame_actions) in actions.iter().enumerate() {
                let percepts = perception.percepts(frame);
                world = aapa
                    .step_from(frame as Time * FRAME_US, &percepts, frame_actions, None, world)
                    .map_err(|source| CaterError::Aapa { video: scene.video.clone(), frame, source })?;
                trace(frame, &world);
                out.push(
                    world
                        .best_of_type(SNITCH_CLASS, params.theta_anch)
                        .map_or([0, 0, 0, 0], |a| to_int(&a.bbox)),
                );
            }
            Ok(out)
        }
    }
}
