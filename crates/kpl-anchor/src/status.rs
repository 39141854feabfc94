//! The status attributes of object records: besides its type's attributes, every object record
//! the engine emits says how its state is known, so that a link's output stream, the world model
//! and a condition (`from.measured`) all see it.
//!
//! - `measured` (bool): the state derives, through links, from a percept sample of this valid
//!   time;
//! - `predicted_since` (int, microseconds; only when `measured` is false): the valid time of the
//!   first state since the object was last measured (predicted by a model, or held at its last
//!   value);
//! - `likelihood` (float) on the objects of a structure predicted along several branches, and
//!   `branch_of` (string) on its branch objects ([`crate::branches`]).
//!
//! The names are [`kpl_core::OBJECT_STATUS`]: decoders (files, the wire) keep them on records of
//! any object type.

use std::sync::Arc;

use kpl_core::{Record, Time, Value};

pub const MEASURED: &str = "measured";
pub const PREDICTED_SINCE: &str = "predicted_since";
/// On the objects of a structure predicted along several branches: how likely its branch is.
pub const LIKELIHOOD: &str = "likelihood";
/// On a branch object: the symbol of the object whose prediction it branches from.
pub const BRANCH_OF: &str = "branch_of";

/// Whether `name` is one of the attributes the engine sets on object records.
pub fn is_status(name: &str) -> bool {
    matches!(name, MEASURED | PREDICTED_SINCE | LIKELIHOOD | BRANCH_OF)
}

/// `record` with the branch attributes set: its `likelihood`, and `branch_of` for a branch object.
pub fn with_branch(mut record: Record, likelihood: f64, branch_of: Option<&Arc<str>>) -> Record {
    record.fields.retain(|(name, _)| &**name != LIKELIHOOD && &**name != BRANCH_OF);
    record.fields.push((Arc::from(LIKELIHOOD), Value::Float(likelihood)));
    if let Some(owner) = branch_of {
        record.fields.push((Arc::from(BRANCH_OF), Value::Str(owner.clone())));
    }
    record
}

/// `record` without the branch attributes (a prediction's start state, a hypothesis).
pub fn without_branch(mut record: Record) -> Record {
    record.fields.retain(|(name, _)| &**name != LIKELIHOOD && &**name != BRANCH_OF);
    record
}

/// The status of one object's state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ObjectStatus {
    pub measured: bool,
    pub predicted_since: Option<Time>,
}

/// `record` with its status attributes set to `status` (replacing any it carried).
pub fn with_status(mut record: Record, status: ObjectStatus) -> Record {
    record.fields.retain(|(name, _)| &**name != MEASURED && &**name != PREDICTED_SINCE);
    push_status(&mut record.fields, status);
    record
}

/// Sets the status attributes of `record` to `status` in place: what [`with_status`] gives.
pub fn set_status(record: &mut Record, status: ObjectStatus) {
    record.fields.retain(|(name, _)| &**name != MEASURED && &**name != PREDICTED_SINCE);
    push_status(&mut record.fields, status);
}

/// A copy of `record` with its status attributes set to `status`: [`with_status`] of a clone,
/// made in one allocation (an object's state is copied so at every step).
pub fn with_status_of(record: &Record, status: ObjectStatus) -> Record {
    let mut fields = Vec::with_capacity(record.fields.len() + 2);
    fields.extend(
        record.fields.iter().filter(|(name, _)| &**name != MEASURED && &**name != PREDICTED_SINCE).cloned(),
    );
    push_status(&mut fields, status);
    Record { id: record.id.clone(), fields }
}

/// Sets `target` to [`with_status_of`]`(record, status)` in place, without allocating, when
/// nothing else holds `target` and it has that record's layout (the same attribute names in the
/// same order: an object's state from one step to the next); returns false, leaving `target` as
/// it was, otherwise. The record is equal to the one [`with_status_of`] makes.
pub fn write_status_of(target: &mut Arc<Record>, record: &Record, status: ObjectStatus) -> bool {
    let Some(target) = Arc::get_mut(target) else { return false };
    let with_since = status.predicted_since.is_some() && !status.measured;
    let n_status = 1 + usize::from(with_since);
    let Some(n_own) = target.fields.len().checked_sub(n_status) else { return false };
    let same_name = |a: &Arc<str>, b: &Arc<str>| Arc::ptr_eq(a, b) || **a == **b;
    let mut own = record.fields.iter().filter(|(name, _)| &**name != MEASURED && &**name != PREDICTED_SINCE);
    for (name, _) in &target.fields[..n_own] {
        match own.next() {
            Some((theirs, _)) if same_name(name, theirs) => {}
            _ => return false,
        }
    }
    if own.next().is_some()
        || &*target.fields[n_own].0 != MEASURED
        || (with_since && &*target.fields[n_own + 1].0 != PREDICTED_SINCE)
    {
        return false;
    }
    let own = record.fields.iter().filter(|(name, _)| &**name != MEASURED && &**name != PREDICTED_SINCE);
    for ((_, value), (_, new)) in target.fields.iter_mut().zip(own) {
        value.clone_from(new);
    }
    target.fields[n_own].1 = Value::Bool(status.measured);
    if let Some(since) = status.predicted_since.filter(|_| with_since) {
        target.fields[n_own + 1].1 = Value::Int(since);
    }
    if target.id != record.id {
        target.id.clone_from(&record.id);
    }
    true
}

thread_local! {
    /// The names of the status attributes, made once per thread: every state's record made on
    /// the thread shares them (and engines stepping on different threads, regions', do not share
    /// their reference counts).
    static STATUS_NAMES: (Arc<str>, Arc<str>) = (Arc::from(MEASURED), Arc::from(PREDICTED_SINCE));
}

fn push_status(fields: &mut Vec<(Arc<str>, Value)>, status: ObjectStatus) {
    STATUS_NAMES.with(|(measured, predicted_since)| {
        fields.reserve(2);
        fields.push((measured.clone(), Value::Bool(status.measured)));
        if let Some(since) = status.predicted_since.filter(|_| !status.measured) {
            fields.push((predicted_since.clone(), Value::Int(since)));
        }
    });
}

/// Whether an object value says it was measured (`measured: true`); a record without the
/// attribute (a percept as its source gives it) counts as measured.
pub fn is_measured(value: &Value) -> bool {
    match value.as_record().and_then(|r| r.get(MEASURED)) {
        Some(Value::Bool(b)) => *b,
        _ => true,
    }
}

/// `value` (an object record) marked as not measured at `time` (a sample held over from an
/// earlier time): `measured: false`, and `predicted_since` from `time` unless it says earlier.
pub fn held(value: &Value, time: Time) -> Value {
    let Some(record) = value.as_record() else { return value.clone() };
    let since = match record.get(PREDICTED_SINCE) {
        Some(Value::Int(t)) if *t <= time => *t,
        _ => time,
    };
    let status = ObjectStatus { measured: false, predicted_since: Some(since) };
    Value::Record(Arc::new(with_status_of(record, status)))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests
mod tests {
    use super::*;

    #[test]
    fn status_attributes_are_replaced_not_repeated() {
        let record = Record { id: Some("wo1".into()), fields: vec![("pos".into(), Value::vec2(1.0, 2.0))] };
        let predicted = with_status(record, ObjectStatus { measured: false, predicted_since: Some(7) });
        assert_eq!(predicted.get(MEASURED), Some(&Value::Bool(false)));
        assert_eq!(predicted.get(PREDICTED_SINCE), Some(&Value::Int(7)));
        let measured = with_status(predicted, ObjectStatus { measured: true, predicted_since: None });
        assert_eq!(measured.fields.len(), 2, "{measured:?}");
        assert_eq!(measured.get(MEASURED), Some(&Value::Bool(true)));
        assert_eq!(measured.get(PREDICTED_SINCE), None);
        assert!(is_measured(&Value::Record(Arc::new(measured.clone()))));
        let held = held(&Value::Record(Arc::new(measured)), 9);
        assert!(!is_measured(&held));
        assert_eq!(held.as_record().unwrap().get(PREDICTED_SINCE), Some(&Value::Int(9)));
    }

    fn arb_status() -> impl proptest::strategy::Strategy<Value = ObjectStatus> {
        use proptest::prelude::*;
        (any::<bool>(), proptest::option::of(0..1000i64))
            .prop_map(|(measured, predicted_since)| ObjectStatus { measured, predicted_since })
    }

    fn arb_record() -> impl proptest::strategy::Strategy<Value = Record> {
        use proptest::prelude::*;
        let names = prop_oneof![
            Just("pos"),
            Just("vel"),
            Just("size"),
            Just(MEASURED),
            Just(PREDICTED_SINCE),
            Just(LIKELIHOOD)
        ];
        (
            proptest::option::of(prop_oneof![Just("vp1"), Just("vp2")]),
            proptest::collection::vec((names, -5..5i64), 0..5),
        )
            .prop_map(|(id, fields)| Record {
                id: id.map(Arc::from),
                fields: fields.into_iter().map(|(n, v)| (Arc::from(n), Value::Int(v))).collect(),
            })
    }

    proptest::proptest! {
        /// Written in place or not, the state is the record `with_status_of` makes; in place
        /// exactly when the layouts agree and nothing else holds the target.
        #[test]
        fn writing_in_place_is_with_status_of(
            old in arb_record(),
            old_status in arb_status(),
            new in arb_record(),
            status in arb_status(),
            shared in proptest::prelude::any::<bool>(),
        ) {
            let mut target = Arc::new(with_status_of(&old, old_status));
            let keep = shared.then(|| target.clone());
            let before = (*target).clone();
            let expected = with_status_of(&new, status);
            let names = |r: &Record| r.fields.iter().map(|(n, _)| n.to_string()).collect::<Vec<_>>();
            let same_layout = names(&before) == names(&expected);
            let written = write_status_of(&mut target, &new, status);
            proptest::prop_assert_eq!(written, same_layout && !shared);
            if written {
                proptest::prop_assert_eq!(&*target, &expected);
            } else {
                proptest::prop_assert_eq!(&*target, &before);
            }
            drop(keep);
        }
    }
}
