//! The `kpl` binary: see the library (`kpl/src/lib.rs`).

fn main() -> std::process::ExitCode {
    kpl::main()
}
