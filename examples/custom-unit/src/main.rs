//! The `kpl` command with this crate's units registered.

fn main() -> std::process::ExitCode {
    kpl::main_with(custom_unit::register)
}
