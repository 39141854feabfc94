//! The transport for streams between hosts (`kpl run --host`).

/// The transport `kpl run --host` uses. Until `kpl-zenoh` is wired in there is none, and a run of
/// one host of a deployed spec is refused with a clear error.
pub fn factory() -> Option<Box<dyn kpl_runtime::run::TransportFactory>> {
    None
}
