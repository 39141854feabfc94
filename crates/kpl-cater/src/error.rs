//! Errors of reading, writing and checking LA-CATER data. I/O problems and bad data are told apart
//! so the command can exit 2 for the one and 1 for the other.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum CaterError {
    #[error("{}: {source}", path.display())]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{}: not valid JSON for this file kind: {source}", path.display())]
    Json { path: PathBuf, source: serde_json::Error },
    #[error("{}: {reason}", path.display())]
    Invalid { path: PathBuf, reason: String },
    #[error("anchoring failed on {video} frame {frame}: {source}")]
    Aapa { video: String, frame: usize, source: kpl_aapa::AapaError },
}

impl CaterError {
    /// Bad input data (as opposed to an I/O failure).
    pub fn is_data_error(&self) -> bool {
        !matches!(self, CaterError::Io { .. })
    }

    pub(crate) fn invalid(path: &std::path::Path, reason: impl Into<String>) -> CaterError {
        CaterError::Invalid { path: path.to_owned(), reason: reason.into() }
    }
}
