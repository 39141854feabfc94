//! Every parameter of AAPA in one serde-deserializable [`Params`], with the paper's values, and the
//! table of action rules that turns actions into attachments.
//!
//! Values from the paper (Kaur et al., section IV-B for LA-CATER, section V for the gearbox):
//!
//! | parameter | LA-CATER | gearbox | meaning |
//! |---|---|---|---|
//! | `theta` | 6500 | 6500 | reject an alignment whose cost (eq. 1) is not below this |
//! | `theta_anch` | 0.1 | 0.5 | confidence from which an anchor is kept by hypothesis reasoning |
//! | `theta_inf` | (= `theta_anch`) | 0.8 | confidence from which an anchor is passed on for inference |
//! | `conf_plus` | 0.1 | 0.05 | confidence gained per aligned cycle (capped at 1) |
//! | `conf_minus` | 0.1 | 0.1 | confidence lost per cycle while lost below `theta_anch` |
//!
//! The paper gives no value for the type mismatch constant of eq. (1), nor the distance: with
//! `theta = 6500` on pixel boxes only the squared Euclidean distance makes the threshold bite (about
//! 80 px of combined centre and size change), so `d` is the squared distance here, and the mismatch
//! constant is 10 (a misclassified detection still aligns when it is within about 25 px).

use serde::{Deserialize, Serialize};

use crate::types::ActionPhase;

/// All AAPA parameters. Deserialize from JSON; missing fields take the defaults of [`Params::default`]
/// (the paper's LA-CATER values with this implementation's extensions on).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// θ: maximum alignment cost (eq. 1), exclusive.
    pub theta: f64,
    /// The type mismatch constant of eq. (1): the cost factor when percept and anchor types differ
    /// (1 when they agree).
    pub type_mismatch: f64,
    /// θ_anch.
    pub theta_anch: f64,
    /// θ_inf (≥ θ_anch).
    pub theta_inf: f64,
    /// conf+.
    pub conf_plus: f64,
    /// conf-.
    pub conf_minus: f64,
    /// The image, for the out-of-view hypothesis. Without it nothing is ever out of view.
    pub image: Option<ImageSize>,
    /// The camera model, required to use camera poses (camera movement alignment).
    pub camera: Option<CameraModel>,
    /// Which actions have which effects.
    pub action_rules: Vec<ActionRule>,
    /// Infer spatial relations (`left_of`, `behind`) among anchors passed on for inference.
    pub spatial_relations: bool,
    pub extensions: Extensions,
}

/// Behaviour this implementation adds to the paper's algorithm, each aimed at a failure mode the
/// paper names. All off reproduces the paper's algorithm ([`Params::paper_cater`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Extensions {
    /// While an action moves an object (a `start_moving` effect) and the object is not seen, move
    /// its anchor with the velocity measured before it disappeared, until the action's expected
    /// end. Targets "objects that move while occluded" (the paper's H1 holds between actions).
    pub predict_motion: bool,
    /// When a new anchor is confirmed (reaches θ_anch) and an older anchored, unattached anchor of
    /// the same type is not seen this cycle, the old symbol takes the new percept instead of keeping
    /// two symbols for one object (re-acquisition, confirmed first so flickering ghosts cannot steal
    /// a symbol).
    pub reacquire: bool,
    /// A child following its parent scales its offset and size with the parent's box, so a carried
    /// object grows and shrinks with its carrier (the paper keeps the last size).
    pub scale_attached: bool,
    /// How a move that is not seen is assumed to proceed between its start and its expected end.
    pub motion_profile: MotionProfile,
    /// For detectors that box only the visible part of a partly hidden object (not for ground-truth
    /// boxes): a percept that overlaps other detections, is smaller than the object's remembered
    /// size and is being cut on one side is taken as its visible part, and the cut edge is moved out
    /// to restore the size (the paper names box size under partial occlusion as a failure). Off by
    /// default: it describes the sensor.
    pub restore_partial_boxes: bool,
    /// Alignment favours established anchors (confidence of at least 0.5): the cost of eq. (1) to a
    /// tentative anchor counts double, so a short-lived false detection kept as occluded does not
    /// take the object that has been there all along when it reappears.
    pub established_first: bool,
    /// An object that an attaching action hides (`_contain(cone, obj)`) but that has no anchor (it
    /// was never perceived: hidden behind another from the start) gets one, inferred from the
    /// action: inside its container, a square placed by `infer_hidden_box`, at θ_anch. The action
    /// says it exists and where it is; its size was never seen.
    pub infer_hidden: bool,
    /// Where an inferred hidden object's box is in its container's box: `[w, c]`, a square of
    /// width `w` times the container's box width, centred horizontally, its centre `c` of the
    /// container's box height down from its top. The default `[0.42, 0.6]` is the median of CATER's
    /// snitch under its cone (the generator's tuning seed, 148 contains).
    pub infer_hidden_box: [f64; 2],
    /// For detectors whose boxes are noisy (not for ground-truth boxes): an object that no action
    /// is moving stands still (H1), so its box is the mean of the boxes seen since it last moved,
    /// not the latest detection with its noise (a contained object follows that steadier box too).
    /// A box that strays from the mean starts it again. Off by default: it describes the sensor.
    pub average_still: bool,
    /// Objects do not move on their own (H1): an established anchor that no action is moving (not
    /// moving, not turning, not attached, not one of the objects an undecided action on identical
    /// objects may be moving) takes a percept that lies away from it (its centre further than 3 px
    /// plus a fifth of the box's smaller side) only at ten times the cost. So an object released
    /// where it stands does not take the percept of its identical twin that moves nearby. Off by
    /// default: it needs every move to be an action (CATER's scenes, not a hand moving freely).
    pub still_stays: bool,
    /// Two anchors of one type on the same spot (boxes overlapping at an IoU of 0.7 or more, of
    /// similar size), neither moving nor one inside the other (however deep), are one object
    /// anchored twice (a detector that reported it twice, or under another class for a few
    /// frames): the younger is merged into the older. Off by default: objects of one type can share a place (a casing top
    /// mounted on a casing base); in CATER they cannot.
    pub merge_duplicates: bool,
    /// Which of several anchors of a type an action names is decided by where things are: an
    /// action that puts its moving object over another, single object (`_contain(cone, snitch)`)
    /// by the anchor of the type nearest that object when it completes (among all of the type, not
    /// those inside another; if there is none, the container is inferred over the object with
    /// `infer_hidden`), and a moving object inside a container only with its container (a cone
    /// inside another is not what `_slide(cone)` moves unless its container moves too).
    pub identity_by_place: bool,
    /// Seconds for which an established anchor (confidence of at least 0.5) that disappears with
    /// no explanation (not occluded, out of view or attached) keeps its confidence where it was
    /// last seen (H1: objects do not move on their own), before `conf_minus` starts to take it
    /// away. `0` is the paper's rule: such a lost anchor decays at once. A perception that leaves out
    /// objects it should report (OPNet's perfect perception leaves out every object of a contained
    /// object's class, identical ones too) then does not make AAPA forget them.
    pub keep_lost: f64,
}

/// The speed profile of an action's move, for motion prediction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MotionProfile {
    /// Keep the last measured velocity until the expected end.
    ConstantVelocity,
    /// Start and stop smoothly (`3u² - 2u³` of the action's time fraction `u`, the shape of
    /// Blender's default keyframe easing and of typical arm trajectories): the velocity measured at
    /// fraction `u0` fixes the whole move, which decelerates to rest at the expected end.
    EaseInOut,
    /// The profile the move showed while it was seen: the positions seen since the move started are
    /// fitted (least squares) by each of smooth (`3u² - 2u³`), linear (`u`), ease-in (`u²`) and
    /// ease-out (`1 - (1 - u)²`) from where the move started, and the best fit continues the move
    /// to the expected end (smooth unless another fits clearly better). Without positions to fit,
    /// as [`MotionProfile::EaseInOut`].
    #[default]
    Fitted,
}

impl Default for Extensions {
    fn default() -> Extensions {
        Extensions {
            predict_motion: true,
            reacquire: true,
            scale_attached: true,
            motion_profile: MotionProfile::Fitted,
            restore_partial_boxes: false,
            established_first: true,
            infer_hidden: true,
            infer_hidden_box: [0.42, 0.6],
            average_still: false,
            still_stays: false,
            merge_duplicates: false,
            identity_by_place: true,
            keep_lost: 0.0,
        }
    }
}

/// Image size in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImageSize {
    pub width: f64,
    pub height: f64,
}

/// A pinhole camera that translates over a work surface (eye-in-hand). Poses are given in a frame
/// with the camera's axes; the surface is the plane `z = surface_z` of that frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraModel {
    /// Focal length in pixels.
    pub focal_px: f64,
    /// Principal point in pixels.
    pub principal: [f64; 2],
    /// Where the work surface is along the optical axis, metres.
    pub surface_z: f64,
}

/// What an action does to the world model, when an action event of this name and phase arrives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActionRule {
    pub action: String,
    #[serde(default)]
    pub phase: ActionPhase,
    pub effects: Vec<Effect>,
}

/// One effect of an action. Numbers index the action's arguments.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "effect", rename_all = "snake_case", deny_unknown_fields)]
pub enum Effect {
    /// `attached(args[child], args[parent])`, replacing the child's previous parent (one parent per
    /// child), plus the optional relation (`holding(args[0], args[1])`).
    Attach {
        child: usize,
        parent: usize,
        #[serde(default)]
        relation: Option<RelationRule>,
        #[serde(default)]
        place_child: ChildPlacement,
        /// The child cannot be seen while attached (a cone over what it contains): its anchor is
        /// not aligned to percepts until it is detached, so no other detection can take it.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        hides_child: bool,
    },
    /// The child is no longer attached; with `parent`, only if that is its parent (a gripper that
    /// lets go of a part it has just inserted does not undo the insertion).
    Detach {
        child: usize,
        #[serde(default)]
        parent: Option<usize>,
    },
    /// All children of this object are released (a cone lifted off what it contained).
    DetachChildren { parent: usize },
    /// The object is being moved by this action (motion prediction while unseen).
    StartMoving { object: usize },
    /// The action that moved the object is over.
    StopMoving { object: usize },
    /// The object turns where it stands (CATER's `_rotate`): its box changes while it stays put,
    /// so boxes are not averaged over the turn and nothing moves it while it is unseen.
    StartTurning { object: usize },
    /// The turn is over.
    StopTurning { object: usize },
}

/// Where an attached child is believed to be at the moment of attachment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ChildPlacement {
    /// Where its anchor already is.
    #[default]
    Keep,
    /// If the child was not seen this cycle and its box does not even touch the parent's, it is
    /// placed on the parent's bottom centre: the action says it is inside (a cone put over it), so
    /// a stale position cannot be right.
    AtParentIfApart,
    /// The parent came down over the child (a cone put over it), so their bottom centres meet. A
    /// parent not seen this cycle (it moved hidden) is moved over the child; a child that took the
    /// parent's percept this cycle (the arriving cone, where the child was) gives it back to the
    /// parent and keeps its own box; otherwise as [`ChildPlacement::AtParentIfApart`].
    Under,
}

/// A relation produced by an attaching action, `name(args[a], args[b])`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RelationRule {
    pub name: String,
    pub args: [usize; 2],
}

impl Default for Params {
    fn default() -> Params {
        Params {
            theta: 6500.0,
            type_mismatch: 10.0,
            theta_anch: 0.1,
            theta_inf: 0.1,
            conf_plus: 0.1,
            conf_minus: 0.1,
            image: None,
            camera: None,
            action_rules: ActionRule::defaults(),
            spatial_relations: true,
            extensions: Extensions::default(),
        }
    }
}

impl Params {
    /// The paper's LA-CATER setting (IV-B) for a 320x240 video, with this implementation's
    /// extensions, `still_stays` (every move in CATER is an action), `merge_duplicates` (no two of
    /// its objects share a place) and `keep_lost` for the length of a CATER video (10 s), and without
    /// spatial relations (the benchmark reads only the snitch).
    pub fn cater() -> Params {
        Params {
            image: Some(ImageSize { width: 320.0, height: 240.0 }),
            spatial_relations: false,
            extensions: Extensions {
                keep_lost: 10.0,
                still_stays: true,
                merge_duplicates: true,
                ..Extensions::default()
            },
            ..Params::default()
        }
    }

    /// The paper's algorithm as published, for LA-CATER: no extensions, and attachments only from
    /// `_contain` (released when the cone is next picked up).
    pub fn paper_cater() -> Params {
        let action_rules = ActionRule::defaults()
            .into_iter()
            .filter(|r| r.action == "_contain" || r.action == "_pick_place")
            .map(|mut r| {
                r.effects.retain(|e| matches!(e, Effect::Attach { .. } | Effect::DetachChildren { .. }));
                for e in &mut r.effects {
                    if let Effect::Attach { place_child, hides_child, .. } = e {
                        *place_child = ChildPlacement::Keep;
                        *hides_child = false;
                    }
                }
                r
            })
            .filter(|r| !r.effects.is_empty())
            .collect();
        Params {
            action_rules,
            extensions: Extensions {
                predict_motion: false,
                reacquire: false,
                scale_attached: false,
                motion_profile: MotionProfile::ConstantVelocity,
                restore_partial_boxes: false,
                established_first: false,
                infer_hidden: false,
                infer_hidden_box: Extensions::default().infer_hidden_box,
                average_still: false,
                still_stays: false,
                merge_duplicates: false,
                identity_by_place: false,
                keep_lost: 0.0,
            },
            ..Params::cater()
        }
    }

    /// The paper's gearbox setting (V): θ_anch 0.5, θ_inf 0.8, conf+ 0.05, conf- 0.1.
    pub fn gearbox(image: ImageSize, camera: CameraModel) -> Params {
        Params {
            theta_anch: 0.5,
            theta_inf: 0.8,
            conf_plus: 0.05,
            conf_minus: 0.1,
            image: Some(image),
            camera: Some(camera),
            ..Params::default()
        }
    }
}

impl ActionRule {
    /// The built-in rules: the paper's robot actions and CATER's movements.
    ///
    /// | action | effect |
    /// |---|---|
    /// | `pick_up(hand, obj)` | `attached(obj, hand)`, `holding(hand, obj)` |
    /// | `put_down(hand, obj)`, `release(hand, obj)` | obj detached if hand is its parent |
    /// | `insert(obj, case)` | `attached(obj, case)`, `inserted(obj, case)` |
    /// | `screw(obj, base)` | `attached(obj, base)`, `screwed(obj, base)` |
    /// | `mount(obj, base)` | `attached(obj, base)`, `mounted(obj, base)` |
    /// | `move(agent, obj)` started / completed | obj moving / stopped |
    /// | `_contain(cone, obj)` completed | `attached(obj, cone)`, `contained(obj, cone)`, obj hidden |
    /// | `_slide(obj)`, `_pick_place(obj)`, `_contain(cone, ..)` started / completed | moving / stopped |
    /// | `_rotate(obj)` started / completed | turning in place / done |
    /// | `_pick_place(cone)` started | the cone's children released |
    pub fn defaults() -> Vec<ActionRule> {
        use ActionPhase::{Completed, Started};
        let attach = |child, parent, name: &str, args, place_child| Effect::Attach {
            child,
            parent,
            relation: Some(RelationRule { name: name.to_owned(), args }),
            place_child,
            hides_child: false,
        };
        let rule = |action: &str, phase, effects| ActionRule { action: action.to_owned(), phase, effects };
        vec![
            rule("pick_up", Completed, vec![attach(1, 0, "holding", [0, 1], ChildPlacement::Keep)]),
            rule("put_down", Completed, vec![Effect::Detach { child: 1, parent: Some(0) }]),
            rule("release", Completed, vec![Effect::Detach { child: 1, parent: Some(0) }]),
            rule("insert", Completed, vec![attach(0, 1, "inserted", [0, 1], ChildPlacement::Keep)]),
            rule("screw", Completed, vec![attach(0, 1, "screwed", [0, 1], ChildPlacement::Keep)]),
            rule("mount", Completed, vec![attach(0, 1, "mounted", [0, 1], ChildPlacement::Keep)]),
            rule("move", Started, vec![Effect::StartMoving { object: 1 }]),
            rule("move", Completed, vec![Effect::StopMoving { object: 1 }]),
            rule("_slide", Started, vec![Effect::StartMoving { object: 0 }]),
            rule("_slide", Completed, vec![Effect::StopMoving { object: 0 }]),
            rule(
                "_pick_place",
                Started,
                vec![Effect::DetachChildren { parent: 0 }, Effect::StartMoving { object: 0 }],
            ),
            rule("_pick_place", Completed, vec![Effect::StopMoving { object: 0 }]),
            rule("_rotate", Started, vec![Effect::StartTurning { object: 0 }]),
            rule("_rotate", Completed, vec![Effect::StopTurning { object: 0 }]),
            rule("_contain", Started, vec![Effect::StartMoving { object: 0 }]),
            rule(
                "_contain",
                Completed,
                vec![
                    Effect::StopMoving { object: 0 },
                    Effect::Attach {
                        child: 1,
                        parent: 0,
                        relation: Some(RelationRule { name: "contained".into(), args: [1, 0] }),
                        place_child: ChildPlacement::Under,
                        hides_child: true,
                    },
                ],
            ),
        ]
    }

    /// How many arguments this rule's effects need.
    pub fn arity(&self) -> usize {
        self.effects
            .iter()
            .map(|e| match e {
                Effect::Attach { child, parent, relation, .. } => {
                    let rel = relation.as_ref().map_or(0, |r| r.args[0].max(r.args[1]));
                    (*child).max(*parent).max(rel) + 1
                }
                Effect::Detach { child, parent } => (*child).max(parent.unwrap_or(0)) + 1,
                Effect::DetachChildren { parent } => parent + 1,
                Effect::StartMoving { object }
                | Effect::StopMoving { object }
                | Effect::StartTurning { object }
                | Effect::StopTurning { object } => object + 1,
            })
            .max()
            .unwrap_or(0)
    }
}
