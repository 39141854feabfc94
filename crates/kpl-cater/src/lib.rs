//! Snitch localisation on CATER-style videos, in LA-CATER's formats (Shamsian et al., used by the
//! AAPA paper's Table I).
//!
//! - [`formats`]: `<video>_bb.json` ground truth, CATER scene JSON, prediction files, perception.
//! - [`scene`], [`render`], [`detector`]: the generator (3D scenes under CATER's rules, a pinhole
//!   camera at 320x240 with depth-ordered occlusion, perfect perception and a noisy detector).
//! - [`dataset`]: the data directory layout; deterministic, parallel generation.
//! - [`models`]: OPNet's heuristic baseline and AAPA (with and without actions, and as published).
//! - [`score`]: OPNet-style IoU / L2 per category with ±SEM; [`eval`] runs a model over a directory.
//!
//! ```no_run
//! use kpl_cater::{dataset, eval, models::Model};
//! let dir = std::path::Path::new("/tmp/cater");
//! dataset::generate(dir, 10, 7, 2)?;
//! let report = eval::evaluate(&eval::EvalOptions {
//!     data: dir.to_owned(),
//!     model: Model::Aapa,
//!     perception: dataset::Perception::Perfect,
//!     params: None,
//!     threads: 2,
//!     predictions_dir: None,
//! })?;
//! println!("{:.2}", report.iou.overall.mean);
//! # Ok::<(), kpl_cater::CaterError>(())
//! ```

pub mod dataset;
pub mod detector;
mod error;
pub mod eval;
pub mod formats;
pub mod models;
pub mod render;
pub mod scene;
pub mod score;

pub use error::CaterError;
