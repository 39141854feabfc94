//! Errors of building a plot.

/// Why a recording cannot be plotted as asked.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("no object stream `{name}` in the recording{}; object streams: {}", hint(.suggestion), .known.join(", "))]
    UnknownStream { name: String, suggestion: Option<String>, known: Vec<String> },
    #[error("the time window is empty: --from {from} s is not before --to {to} s")]
    EmptyWindow { from: f64, to: f64 },
    #[error("{path}: {source}")]
    Io { path: String, source: std::io::Error },
}

fn hint(suggestion: &Option<String>) -> String {
    suggestion.as_ref().map(|s| format!(" (did you mean `{s}`?)")).unwrap_or_default()
}
