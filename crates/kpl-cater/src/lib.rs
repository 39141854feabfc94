//! Snitch localisation on CATER videos, in LA-CATER's formats (Shamsian et al.'s OPNet, used by the
//! AAPA paper's Table I).
//!
//! - [`formats`]: `<video>_bb.json`, CATER scene JSON, OPNet's perception pickles and annotation
//!   files, this project's perception JSON, prediction files; [`classes`]: class names and OPNet's
//!   class indices; [`layout`]: where a data directory keeps them.
//! - [`sim`], [`render`], [`detector`], [`detector_b`]: the generator (CATER's own procedure for
//!   objects and movements, and hard scenes of this project's; CLEVR's camera at 320x240 with
//!   depth-ordered occlusion, perfect perception, a calibrated detector and a second, independent
//!   one); [`perfect_pickles`]: OPNet's perfect perception by its script's rule; [`dataset`]:
//!   deterministic, parallel generation of a directory in this project's layout or LA-CATER's.
//! - [`models`]: OPNet's heuristic baseline and AAPA (with and without actions, and as published).
//! - [`categories`]: OPNet's frame categories; [`score`]: its IoU scoring with ±SEM; [`eval`] runs a
//!   model over a directory and reports skipped videos with their reasons.
//!
//! ```no_run
//! use kpl_cater::{dataset, eval, layout::Perception, models::Model};
//! let dir = std::path::Path::new("/tmp/cater");
//! dataset::generate(dir, 10, 7, 2, &dataset::GeneratorConfig::default())?;
//! let report = eval::evaluate(&eval::EvalOptions::new(dir, Model::Aapa, Perception::Perfect))?;
//! println!("{:.2}", report.iou.overall.mean);
//! # Ok::<(), kpl_cater::CaterError>(())
//! ```

pub mod categories;
pub mod classes;
pub mod dataset;
pub mod detector;
pub mod detector_b;
mod error;
pub mod eval;
pub mod formats;
pub mod layout;
pub mod models;
pub mod perfect_pickles;
pub mod render;
pub mod score;
pub mod sim;

pub use error::CaterError;
