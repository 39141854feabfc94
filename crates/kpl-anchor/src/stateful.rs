//! Stateful link units: what a link unit sees besides the linked-from object ([`UnitCall`]: the
//! time, the unit's extra input streams at this state, and its memory of the linked-to object),
//! and the memory itself ([`UnitMemory`]). The paper's units compute B's state "possibly together
//! with information from other sources"; the Kalman units ([`crate::kalman`]) are built on this.
//!
//! A unit's memory belongs to the linked-to object, under the key the unit names
//! ([`crate::units::LinkUnit::memory_key`]): it outlives links (a world object reacquired after a
//! gap continues its filter), and every link into the object whose unit names the same key
//! shares it (two sensors' links into one world object update one filter: fusion).

use std::any::Any;
use std::fmt;
use std::sync::Arc;

use kpl_core::{Record, RecordType, Time, Value};

/// What a unit keeps about one object between computations (type-erased; the unit downcasts).
#[derive(Clone, Default)]
pub struct UnitMemory(pub Option<Arc<dyn Any + Send + Sync>>);

impl fmt::Debug for UnitMemory {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(if self.0.is_some() { "UnitMemory(..)" } else { "UnitMemory(empty)" })
    }
}

impl UnitMemory {
    /// The memory as a `T`, when it holds one.
    pub fn get<T: Any + Send + Sync>(&self) -> Option<&T> {
        self.0.as_deref().and_then(|m| m.downcast_ref::<T>())
    }

    pub fn set<T: Any + Send + Sync>(&mut self, value: T) {
        self.0 = Some(Arc::new(value));
    }
}

/// One computation of a linked-to object's state.
#[derive(Debug)]
pub struct UnitCall<'a> {
    /// The valid time of the state.
    pub time: Time,
    /// The linked-from object's state.
    pub from: &'a Record,
    /// The linked-to object's last state (absent for an object being created).
    pub previous: Option<&'a Record>,
    pub to: &'a RecordType,
    pub symbol: &'a Arc<str>,
    /// The unit's extra input streams at this state, in the order of its inputs (`None`: no
    /// sample at this time and no approximation).
    pub inputs: &'a [Option<Value>],
    /// The unit's memory of the linked-to object. A trial computation (an identification's
    /// candidate) gets a scratch memory that is dropped.
    pub memory: &'a mut UnitMemory,
}
