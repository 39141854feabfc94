//! The [`Context`] a formula is compiled against: which names exist (state fields, variables
//! such as `from` and `to`), which object types `forall`/`exists` may range over, which functions
//! may be called, and the time units of time stamps and of bare integer bounds.

use std::collections::HashMap;
use std::sync::Arc;

use kpl_core::TimeUnit;

use crate::term::{DomainId, FuncId, Function, SlotId, builtins};

/// Names, object types, functions and time units for compiling formulas.
///
/// ```
/// use kpl_core::TimeUnit;
/// use kpl_mtl::Context;
/// let mut ctx = Context::new(TimeUnit::Us, TimeUnit::Ms);
/// let from = ctx.declare_value("from");
/// assert_eq!(ctx.slot("from"), Some(from));
/// assert!(ctx.function("xydist").is_some());
/// ```
#[derive(Debug, Clone)]
pub struct Context {
    slots: Names,
    /// When set, an unknown name becomes a new slot instead of an error (the command line, whose
    /// states are JSON objects with whatever fields they have).
    open_names: bool,
    domains: Names,
    functions: Vec<Function>,
    time_unit: TimeUnit,
    tick_unit: TimeUnit,
}

impl Context {
    /// `time_unit`: the unit of the time stamps given to the progressors (microseconds in the
    /// runtime). `tick_unit`: the unit of a bare integer interval bound (`eventually[0, 500]`),
    /// milliseconds in a spec. Built-in functions are registered.
    pub fn new(time_unit: TimeUnit, tick_unit: TimeUnit) -> Context {
        Context {
            slots: Names::default(),
            open_names: false,
            domains: Names::default(),
            functions: builtins(),
            time_unit,
            tick_unit,
        }
    }

    /// A context where every unknown name becomes a new slot.
    pub fn open(time_unit: TimeUnit, tick_unit: TimeUnit) -> Context {
        Context { open_names: true, ..Context::new(time_unit, tick_unit) }
    }

    pub fn is_open(&self) -> bool {
        self.open_names
    }

    /// Declares a name of the state; declaring it again returns the same slot.
    pub fn declare_value(&mut self, name: &str) -> SlotId {
        self.slots.declare(name)
    }

    pub fn slot(&self, name: &str) -> Option<SlotId> {
        self.slots.get(name)
    }

    /// Declares an object type that quantifiers may range over.
    pub fn declare_object_type(&mut self, name: &str) -> DomainId {
        self.domains.declare(name)
    }

    pub fn domain(&self, name: &str) -> Option<DomainId> {
        self.domains.get(name)
    }

    /// Registers a host function (a predicate such as `on_road`); a later registration of the
    /// same name replaces the earlier one, built-ins included.
    pub fn register_function(&mut self, function: Function) -> FuncId {
        if let Some(i) = self.functions.iter().position(|f| f.name == function.name) {
            self.functions[i] = function;
            return i as FuncId;
        }
        self.functions.push(function);
        (self.functions.len() - 1) as FuncId
    }

    pub fn function(&self, name: &str) -> Option<FuncId> {
        self.functions.iter().position(|f| &*f.name == name).map(|i| i as FuncId)
    }

    pub fn functions(&self) -> &[Function] {
        &self.functions
    }

    pub fn function_names(&self) -> impl Iterator<Item = &str> {
        self.functions.iter().map(|f| &*f.name)
    }

    pub fn slot_names(&self) -> &[Arc<str>] {
        &self.slots.names
    }

    pub fn domain_names(&self) -> &[Arc<str>] {
        &self.domains.names
    }

    pub fn time_unit(&self) -> TimeUnit {
        self.time_unit
    }

    pub fn tick_unit(&self) -> TimeUnit {
        self.tick_unit
    }
}

/// Names numbered in the order they were first declared (slots, object types).
#[derive(Debug, Clone, Default)]
struct Names {
    names: Vec<Arc<str>>,
    index: HashMap<Arc<str>, u32>,
}

impl Names {
    /// The number of `name`, given the next free one if it is new.
    fn declare(&mut self, name: &str) -> u32 {
        if let Some(i) = self.index.get(name) {
            return *i;
        }
        let i = self.names.len() as u32;
        let name: Arc<str> = Arc::from(name);
        self.names.push(name.clone());
        self.index.insert(name, i);
        i
    }

    fn get(&self, name: &str) -> Option<u32> {
        self.index.get(name).copied()
    }
}
