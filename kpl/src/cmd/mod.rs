//! One module per subcommand; each has its clap `Args` (or `Command`) and a `run` returning the
//! process exit code: 0 success, 1 the input has errors, 2 usage or I/O errors.

pub mod bench;
pub mod cater;
pub mod check;
pub mod convert;
pub mod explain;
pub mod fmt;
pub mod graph;
pub mod keys;
pub mod launch;
pub mod list;
pub mod mtl;
pub mod plot;
pub mod run;
pub mod score;
pub mod situations;
