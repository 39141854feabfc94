//! Branch objects: when a predicted structure's model gives several hypotheses (`along_roads` at a
//! crossing), each hypothesis is an object of its own, as the paper's on-road objects "split into
//! multiple objects at crossings": the object the model predicts (the owner, `oo1`) follows one
//! branch, and a new object of its type (`oo7`, `branch_of: "oo1"`) follows each other branch. They
//! are in the type's snapshot (a link's output) and in `forall` over the type, each with its
//! `likelihood`; they are not candidates of reestablish conditions (the structure is reacquired
//! through its root, at any hypothesis). When the structure is reacquired, or fed again, the branch
//! objects are removed (`removed`, cause `pruned`): the owner continues on the branch that was
//! reacquired, under its own symbol.
//!
//! **Likelihood.** Each branch i turns by θᵢ from the lane the object was on when prediction
//! began (the difference of the branch's heading and that lane's), and the object was moving at
//! δ from that lane's heading when it was last seen (a car that has started to turn, or drifts
//! towards a turning lane, has δ ≠ 0). The likelihood is a von Mises weight of the difference,
//! `exp(κ cos(θᵢ - δ))` with κ = [`TURN_CONCENTRATION`], normalised over the branches: with δ = 0
//! straight on is the most likely (e² : 1 : 1 against right angles), a car seen heading 30° to the
//! left makes the left branch likelier than with δ = 0. Branches are ordered most likely first.
//!
//! **Identity across steps.** The hypotheses are matched to the branch objects of the previous
//! step by state distance (position, and velocity: branches start at one place but head different
//! ways), the owner first, so each object keeps following its own route.

use kpl_core::{Record, Value};

use crate::records::velocity;
use crate::units::{MIN_HEADING_SPEED_MPS, heading_of_velocity};

/// κ of the von Mises weight of a branch's turn (see the module doc).
pub const TURN_CONCENTRATION: f64 = 2.0;

/// The likelihood of each hypothesis (summing to 1), from the state the prediction started from
/// and the heading of the lane it was on then (when it was snapped to one).
pub fn likelihoods(lane_heading: Option<f64>, start: &Record, hypotheses: &[Record]) -> Vec<f64> {
    let object_heading = heading_of_velocity(velocity(start), MIN_HEADING_SPEED_MPS);
    let base = lane_heading.or(object_heading);
    let drift = match (object_heading, lane_heading) {
        (Some(o), Some(l)) => wrap(o - l),
        _ => 0.0,
    };
    let weights: Vec<f64> = hypotheses
        .iter()
        .map(|h| {
            let turn = match (base, heading_of_velocity(velocity(h), MIN_HEADING_SPEED_MPS)) {
                (Some(b), Some(t)) => wrap(t - b),
                _ => 0.0,
            };
            (TURN_CONCENTRATION * (turn - drift).cos()).exp()
        })
        .collect();
    let total: f64 = weights.iter().sum();
    if total > 0.0 && total.is_finite() {
        weights.iter().map(|w| w / total).collect()
    } else {
        vec![1.0 / hypotheses.len().max(1) as f64; hypotheses.len()]
    }
}

/// An angle in (-π, π].
fn wrap(a: f64) -> f64 {
    let t = a.rem_euclid(std::f64::consts::TAU);
    if t > std::f64::consts::PI { t - std::f64::consts::TAU } else { t }
}

/// Assigns hypotheses to the objects that followed branches at the previous step (`previous`:
/// their last states, the owner first): for each object the index of its hypothesis, or `None`
/// when fewer hypotheses are left. The owner takes its closest hypothesis; the others then take the
/// closest free ones, closest pairs first.
pub fn assign(
    previous: &[&Value],
    hypotheses: &[Record],
    distance: impl Fn(&Value, &Record) -> f64,
) -> Vec<Option<usize>> {
    let mut taken = vec![false; hypotheses.len()];
    let mut out = vec![None; previous.len()];
    let Some((owner, others)) = previous.split_first() else { return out };
    if let Some(best) = (0..hypotheses.len())
        .min_by(|&a, &b| distance(owner, &hypotheses[a]).total_cmp(&distance(owner, &hypotheses[b])))
    {
        out[0] = Some(best);
        taken[best] = true;
    }
    let mut pairs: Vec<(f64, usize, usize)> = Vec::new();
    for (i, object) in others.iter().enumerate() {
        for (h, hypothesis) in hypotheses.iter().enumerate() {
            pairs.push((distance(object, hypothesis), i + 1, h));
        }
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    for (_, i, h) in pairs {
        if out[i].is_none() && !taken[h] {
            out[i] = Some(h);
            taken[h] = true;
        }
    }
    out
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;
    use std::sync::Arc;

    fn state(vel: [f64; 2]) -> Record {
        Record {
            id: None,
            fields: vec![("pos".into(), Value::vec2(0.0, 0.0)), ("vel".into(), Value::Vec2(vel))],
        }
    }

    #[test]
    fn straight_on_is_likeliest_unless_the_object_was_turning() {
        let branches = [state([0.0, 10.0]), state([10.0, 0.0]), state([0.0, -10.0])];
        let l = likelihoods(None, &state([10.0, 0.0]), &branches);
        assert!((l.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!(l[1] > l[0] && (l[0] - l[2]).abs() < 1e-12, "{l:?}");
        assert!((l[1] / l[0] - std::f64::consts::E.powi(2)).abs() < 1e-9);
        // Seen heading 30° left of its lane (east): left is likelier than right, and than before.
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let m = likelihoods(Some(0.0), &state([10.0 * c, 10.0 * s]), &branches);
        assert!(m[0] > m[2] && m[0] > l[0], "{m:?}");
        assert!((m.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn the_owner_keeps_its_closest_branch_and_others_follow_theirs() {
        let value = |x: f64| {
            Value::Record(Arc::new(Record { id: None, fields: vec![("x".into(), Value::Float(x))] }))
        };
        let distance = |v: &Value, h: &Record| {
            (v.as_record().unwrap().get("x").unwrap().as_f64().unwrap()
                - h.get("x").unwrap().as_f64().unwrap())
            .abs()
        };
        let hyp = |x: f64| Record { id: None, fields: vec![("x".into(), Value::Float(x))] };
        let (a, b, c) = (value(0.0), value(10.0), value(20.0));
        assert_eq!(
            assign(&[&b, &a, &c], &[hyp(1.0), hyp(11.0), hyp(19.0)], distance),
            vec![Some(1), Some(0), Some(2)]
        );
        // One branch fewer: the owner keeps its own, the farthest object loses.
        assert_eq!(assign(&[&c, &a, &b], &[hyp(1.0), hyp(21.0)], distance), vec![Some(1), Some(0), None]);
    }
}
