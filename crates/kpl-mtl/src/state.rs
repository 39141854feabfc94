//! What a formula reads at one time stamp: the [`State`] trait, implemented by the host (the
//! runtime's synchronized state, a link process's pair of objects), and [`SlotState`], a plain
//! vector of values that tests and the command line use.

use kpl_core::Value;

use crate::term::{DomainId, SlotId};

/// One state of the stream, as seen by a compiled formula. Slots and domains are the indices a
/// [`crate::Context`] assigned to names and object types when the formula was compiled.
pub trait State {
    /// The value of a name in this state, or `None` when the state has none (see
    /// `docs/mtl.md`, "Missing values": the step then fails with [`crate::EvalError::Missing`]).
    fn value(&self, slot: SlotId) -> Option<&Value>;

    /// The objects of a type present in this state, each a [`Value::Record`] with an `id`.
    fn objects(&self, _domain: DomainId) -> &[Value] {
        &[]
    }

    /// The object of a type with this `id`, if present.
    fn object(&self, domain: DomainId, id: &str) -> Option<&Value> {
        self.objects(domain).iter().find(|o| matches!(o, Value::Record(r) if r.id.as_deref() == Some(id)))
    }
}

/// A state held as one optional value per slot and one list of objects per domain.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SlotState {
    pub values: Vec<Option<Value>>,
    pub objects: Vec<Vec<Value>>,
}

impl SlotState {
    pub fn new(values: Vec<Option<Value>>) -> SlotState {
        SlotState { values, objects: Vec::new() }
    }

    /// A state of boolean slots, in slot order.
    pub fn bools(values: &[bool]) -> SlotState {
        SlotState::new(values.iter().map(|b| Some(Value::Bool(*b))).collect())
    }
}

impl State for SlotState {
    fn value(&self, slot: SlotId) -> Option<&Value> {
        self.values.get(slot as usize).and_then(Option::as_ref)
    }

    fn objects(&self, domain: DomainId) -> &[Value] {
        self.objects.get(domain as usize).map_or(&[], Vec::as_slice)
    }
}
