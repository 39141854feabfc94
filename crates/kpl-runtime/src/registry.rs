//! The registry of implementations: every source, computational unit and sink the runtime can
//! run, by name, each with its signature (typed, documented parameters) for `kpl check` and
//! `kpl list`. Crates add their own (`kpl-std`, `kpl-anchor`, `kpl-zenoh`, a user's crate) with
//! [`Registry::add_source`], [`Registry::add_unit`], ...
//!
//! ```
//! use kpl_core::Value;
//! use kpl_runtime::process::{Emitter, Input, ProcessError, SyncUnit, Unit};
//! use kpl_runtime::registry::Registry;
//! use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};
//!
//! struct Scale(f64);
//! impl Unit for Scale {
//!     fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
//!         if let Some(x) = input.trigger_value().and_then(Value::as_f64) {
//!             out.emit(Value::Float(x * self.0));
//!         }
//!         Ok(())
//!     }
//! }
//!
//! let mut registry = Registry::with_builtins();
//! registry.add_unit(
//!     Entry::new(EntryKind::Compute, "demo.scale", "Multiplies a number by a factor.")
//!         .input("in", TypeReq::Any, "numbers")
//!         .param(Param::optional("factor", ParamType::Float, Value::Float(2.0), "the factor"))
//!         .output(TypeReq::Exact(kpl_core::ValueType::Float)),
//!     |ctx| {
//!         let factor = ctx.param("factor").and_then(Value::as_f64).unwrap_or(2.0);
//!         Ok(Box::new(SyncUnit(Scale(factor))))
//!     },
//! );
//! assert!(registry.signatures().entry(EntryKind::Compute, "demo.scale").is_some());
//! ```

use std::any::{Any, TypeId};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use kpl_core::Value;
use kpl_semantic::hir;
use kpl_semantic::registry::{Entry, EntryKind, Function};

use crate::clock::ClockKind;
use crate::process::{AsyncUnit, Source};

/// Why a process could not be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{process}: {message}")]
pub struct BuildError {
    pub process: String,
    pub message: String,
}

/// State shared between the processes of one run while they are built (for example the object
/// store all link processes of a spec share), by type.
#[derive(Default)]
pub struct Extensions {
    map: BTreeMap<TypeId, Box<dyn Any + Send>>,
}

impl std::fmt::Debug for Extensions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Extensions").field("len", &self.map.len()).finish()
    }
}

impl Extensions {
    pub fn get_or_insert_with<T: Any + Send>(&mut self, make: impl FnOnce() -> T) -> &mut T {
        let entry = self.map.entry(TypeId::of::<T>()).or_insert_with(|| Box::new(make()));
        match entry.downcast_mut::<T>() {
            Some(t) => t,
            None => unreachable!("entries are keyed by their own type"),
        }
    }

    pub fn get<T: Any + Send>(&self) -> Option<&T> {
        self.map.get(&TypeId::of::<T>())?.downcast_ref()
    }
}

/// What a factory builds a process from.
pub struct BuildContext<'a> {
    pub spec: &'a hir::Spec,
    pub process: &'a hir::Process,
    /// The spec file's directory: relative input paths are resolved against it.
    pub spec_dir: &'a Path,
    /// The run's output directory: relative output paths are resolved against it.
    pub out_dir: &'a Path,
    /// The run's seed; a process derives its own from it and its name ([`BuildContext::seed`]).
    pub run_seed: u64,
    pub clock: ClockKind,
    pub shared: &'a mut Extensions,
    /// The registry the process is built from: implementations that other processes run are kept
    /// there ([`Registry::extension`]).
    pub registry: &'a Registry,
    /// The process's counters (malformed input, errors, instances created at run time).
    pub stats: std::sync::Arc<crate::stats::ProcessStats>,
}

impl std::fmt::Debug for BuildContext<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BuildContext").field("process", &self.process.name).finish()
    }
}

impl BuildContext<'_> {
    /// The process's resolved call (source, compute, sink, or a link's unit).
    pub fn call(&self) -> Option<&hir::Call> {
        match &self.process.kind {
            hir::ProcessKind::Source(c) | hir::ProcessKind::Compute(c) | hir::ProcessKind::Sink(c) => Some(c),
            hir::ProcessKind::Link(l) => Some(&l.via),
            hir::ProcessKind::Monitor(_) | hir::ProcessKind::Chronicle(_) => None,
        }
    }

    /// A parameter's value (defaults are already filled in by the checker).
    pub fn param(&self, name: &str) -> Option<&Value> {
        self.call()?.params.get(name)
    }

    /// A seed for this process: derived from the run's seed and the process name, so processes
    /// differ and a run with a fixed `--seed` is reproducible.
    pub fn seed(&self) -> u64 {
        // FNV-1a over the name, mixed with the run seed (splitmix64 finish).
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for b in self.process.name.bytes() {
            h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
        let mut z = h ^ self.run_seed.wrapping_mul(0x9e37_79b9_7f4a_7c15);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// An input path relative to the spec's directory.
    pub fn input_path(&self, path: &str) -> PathBuf {
        self.spec_dir.join(path)
    }

    /// An output path relative to the run's output directory.
    pub fn output_path(&self, path: &str) -> PathBuf {
        self.out_dir.join(path)
    }

    pub fn error(&self, message: impl Into<String>) -> BuildError {
        BuildError { process: self.process.name.clone(), message: message.into() }
    }
}

pub type SourceFactory =
    Box<dyn Fn(&mut BuildContext<'_>) -> Result<Box<dyn Source>, BuildError> + Send + Sync>;
pub type UnitFactory =
    Box<dyn Fn(&mut BuildContext<'_>) -> Result<Box<dyn AsyncUnit>, BuildError> + Send + Sync>;

/// Everything a runtime can run, with the signatures `kpl check` checks specs against.
///
/// One assembly function fills it (`kpl_std::assemble`), for running or, in a registry made with
/// [`Registry::signatures_only`], for checking: then the implementations are dropped as they are
/// added, so a check builds nothing of the runtime.
#[derive(Default)]
pub struct Registry {
    signatures: kpl_semantic::registry::Registry,
    sources: BTreeMap<String, SourceFactory>,
    units: BTreeMap<(EntryKind, String), UnitFactory>,
    links: Option<UnitFactory>,
    chronicles: Option<UnitFactory>,
    functions: Vec<kpl_mtl::Function>,
    /// Implementations that live inside other processes, by type (the anchoring's link units and
    /// prediction models, which its link processes run).
    extensions: BTreeMap<TypeId, Box<dyn Any + Send + Sync>>,
    signatures_only: bool,
}

impl std::fmt::Debug for Registry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Registry").field("signatures", &self.signatures).finish()
    }
}

impl Registry {
    /// The runtime's own sources, units and sinks (`timer`, `file.jsonl`, `console`,
    /// `kpl.merge`) and the signatures of the formula functions.
    pub fn with_builtins() -> Registry {
        let mut registry = Registry::default();
        registry.add_builtins();
        registry
    }

    /// Adds the runtime's own sources, units, sinks and function signatures.
    pub fn add_builtins(&mut self) {
        crate::builtins::register(self);
    }

    /// An empty registry that keeps only the signatures of what is added to it: what `kpl check`
    /// and `kpl list` need. Its processes cannot be built.
    pub fn signatures_only() -> Registry {
        Registry { signatures_only: true, ..Registry::default() }
    }

    /// Whether this registry keeps only signatures ([`Registry::signatures_only`]).
    pub fn is_signatures_only(&self) -> bool {
        self.signatures_only
    }

    /// The implementations of type `T` kept by a crate whose processes run them (for example the
    /// link units and prediction models of the anchoring), made with `T::default()` on first use.
    pub fn extension_mut<T: Any + Send + Sync + Default>(&mut self) -> &mut T {
        let entry = self.extensions.entry(TypeId::of::<T>()).or_insert_with(|| Box::new(T::default()));
        match entry.downcast_mut::<T>() {
            Some(t) => t,
            None => unreachable!("extensions are keyed by their own type"),
        }
    }

    /// The implementations of type `T`, if a crate added them ([`Registry::extension_mut`]).
    pub fn extension<T: Any + Send + Sync>(&self) -> Option<&T> {
        self.extensions.get(&TypeId::of::<T>())?.downcast_ref()
    }

    pub fn add_source<F>(&mut self, entry: Entry, factory: F)
    where
        F: Fn(&mut BuildContext<'_>) -> Result<Box<dyn Source>, BuildError> + Send + Sync + 'static,
    {
        if !self.signatures_only {
            self.sources.insert(entry.name.clone(), Box::new(factory));
        }
        self.signatures.add(entry);
    }

    /// Adds a computational unit (`EntryKind::Compute`) or a sink (`EntryKind::Sink`).
    pub fn add_unit<F>(&mut self, entry: Entry, factory: F)
    where
        F: Fn(&mut BuildContext<'_>) -> Result<Box<dyn AsyncUnit>, BuildError> + Send + Sync + 'static,
    {
        if !self.signatures_only {
            self.units.insert((entry.kind, entry.name.clone()), Box::new(factory));
        }
        self.signatures.add(entry);
    }

    /// Adds a signature whose implementation lives inside another process: link units and
    /// prediction models, which the link processes run.
    pub fn add_signature(&mut self, entry: Entry) {
        self.signatures.add(entry);
    }

    /// Sets how chronicle recognisers are built (one factory for every `chronicle` of a spec;
    /// `kpl-std` sets it).
    pub fn set_chronicle_processes<F>(&mut self, factory: F)
    where
        F: Fn(&mut BuildContext<'_>) -> Result<Box<dyn AsyncUnit>, BuildError> + Send + Sync + 'static,
    {
        if !self.signatures_only {
            self.chronicles = Some(Box::new(factory));
        }
    }

    /// Sets how link processes are built (one factory for every `link` of a spec).
    pub fn set_link_processes<F>(&mut self, factory: F)
    where
        F: Fn(&mut BuildContext<'_>) -> Result<Box<dyn AsyncUnit>, BuildError> + Send + Sync + 'static,
    {
        if !self.signatures_only {
            self.links = Some(Box::new(factory));
        }
    }

    /// Adds a formula function: its signature (for checking) and its implementation (for
    /// monitors and link conditions).
    pub fn add_function(&mut self, signature: Function, implementation: kpl_mtl::Function) {
        self.signatures.add_function(signature);
        if !self.signatures_only {
            self.functions.retain(|f| *f.name != *implementation.name);
            self.functions.push(implementation);
        }
    }

    /// Adds a function signature whose implementation `kpl-mtl` already has built in.
    pub fn add_builtin_function(&mut self, signature: Function) {
        self.signatures.add_function(signature);
    }

    pub fn signatures(&self) -> &kpl_semantic::registry::Registry {
        &self.signatures
    }

    /// The signatures, for a caller that needs nothing else.
    pub fn into_signatures(self) -> kpl_semantic::registry::Registry {
        self.signatures
    }

    /// Sets the link protocols of the transport between hosts (`kpl-zenoh` does), which the
    /// checker accepts in a deploy section's endpoints.
    pub fn set_link_protocols(&mut self, protocols: &[&str]) {
        self.signatures.set_link_protocols(protocols);
    }

    /// Implementations of the functions that are not built into `kpl-mtl`.
    pub fn functions(&self) -> &[kpl_mtl::Function] {
        &self.functions
    }

    pub(crate) fn build_source(
        &self,
        ctx: &mut BuildContext<'_>,
        entry: &str,
    ) -> Result<Box<dyn Source>, BuildError> {
        let factory = self
            .sources
            .get(entry)
            .ok_or_else(|| ctx.error(format!("no implementation of source `{entry}`")))?;
        factory(ctx)
    }

    pub(crate) fn build_unit(
        &self,
        ctx: &mut BuildContext<'_>,
        kind: EntryKind,
        entry: &str,
    ) -> Result<Box<dyn AsyncUnit>, BuildError> {
        let factory = self
            .units
            .get(&(kind, entry.to_string()))
            .ok_or_else(|| ctx.error(format!("no implementation of {} `{entry}`", kind.noun())))?;
        factory(ctx)
    }

    pub(crate) fn build_link(&self, ctx: &mut BuildContext<'_>) -> Result<Box<dyn AsyncUnit>, BuildError> {
        let factory = self
            .links
            .as_ref()
            .ok_or_else(|| ctx.error("this runtime has no link processes (kpl-anchor is not registered)"))?;
        factory(ctx)
    }

    pub(crate) fn build_chronicle(
        &self,
        ctx: &mut BuildContext<'_>,
    ) -> Result<Box<dyn AsyncUnit>, BuildError> {
        let factory = self.chronicles.as_ref().ok_or_else(|| {
            ctx.error("this runtime has no chronicle recognisers (kpl-std is not registered)")
        })?;
        factory(ctx)
    }

    /// Names with a signature but no implementation here (and that are not run by link
    /// processes): what `kpl check` would accept but `kpl run` could not build.
    pub fn unimplemented(&self) -> Vec<(EntryKind, String)> {
        self.signatures
            .entries()
            .filter(|e| match e.kind {
                EntryKind::Source => !self.sources.contains_key(&e.name),
                EntryKind::Compute | EntryKind::Sink => !self.units.contains_key(&(e.kind, e.name.clone())),
                EntryKind::Link | EntryKind::Predict => self.links.is_none(),
            })
            .map(|e| (e.kind, e.name.clone()))
            .collect()
    }
}
