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

    /// The memory as a `T` to change in place, when it holds one (copied first if it is
    /// shared, so a change never shows through another owner).
    pub fn get_mut<T: Any + Send + Sync + Clone>(&mut self) -> Option<&mut T> {
        let shared = self.0.as_mut()?;
        if Arc::get_mut(shared).is_none() {
            let copy = shared.downcast_ref::<T>()?.clone();
            *shared = Arc::new(copy);
        }
        Arc::get_mut(shared)?.downcast_mut::<T>()
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

#[cfg(test)]
#[allow(clippy::unwrap_used, reason = "tests")]
mod tests {
    use super::*;

    #[test]
    fn a_shared_memory_is_copied_before_it_changes() {
        let mut memory = UnitMemory::default();
        assert_eq!(memory.get_mut::<u32>(), None);
        memory.set(1_u32);
        let kept = memory.clone();
        *memory.get_mut::<u32>().unwrap() = 2;
        assert_eq!((memory.get::<u32>(), kept.get::<u32>()), (Some(&2), Some(&1)));
        // Not shared any more: changed in place.
        let before = Arc::as_ptr(memory.0.as_ref().unwrap()) as *const u8;
        *memory.get_mut::<u32>().unwrap() = 3;
        assert_eq!(Arc::as_ptr(memory.0.as_ref().unwrap()) as *const u8, before);
        assert_eq!(memory.get_mut::<i64>(), None, "another type");
    }
}
