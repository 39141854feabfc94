//! What every replay source shares (`file.jsonl`, `file.mcap`):
//! - [`replay_entry`] and [`ReplaySetup`]: the signature (a `path` relative to the spec and a
//!   `stream` to keep) and what a source is built from (the file, its filter, the type to decode,
//!   the clock), read off the build context the same way for every format.
//! - [`StreamFilter`]: a recording holds several streams and a source replays one of them. The
//!   filter is applied before a sample's value is decoded (the other streams' values need not fit
//!   the source's type), and a filter that kept nothing says so, naming the streams it saw.
//! - [`ReplayTimes`]: recorded samples must not go back in available time (such a sample is
//!   malformed); with the wall clock, recorded times are shifted so that the first sample happens
//!   when the run starts (a time the shift would move past the range of i64 is malformed).

use std::collections::BTreeMap;
use std::path::PathBuf;

use kpl_core::{Time, Value, ValueType};
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType};

use crate::clock::ClockKind;
use crate::context::SourceContext;
use crate::process::ProcessError;
use crate::registry::BuildContext;
use crate::sample::Sample;

/// The signature of a replay source named `name`: a required `path` (relative to the spec) and
/// an optional `stream` to keep (`stream_doc` says what names a stream in this format).
pub fn replay_entry(name: &str, summary: &str, stream_doc: &str) -> Entry {
    Entry::new(EntryKind::Source, name, summary)
        .param(Param::required("path", ParamType::Str, "file to read, relative to the spec"))
        .param(Param::optional("stream", ParamType::Str, Value::str(""), stream_doc))
}

/// What a replay source of [`replay_entry`]'s signature is built from.
#[derive(Debug)]
pub struct ReplaySetup {
    /// The file, relative to the spec's directory.
    pub path: PathBuf,
    pub filter: StreamFilter,
    /// The source's declared output type: what each value is decoded as.
    pub ty: ValueType,
    pub clock: ClockKind,
}

impl ReplaySetup {
    pub fn from_context(ctx: &BuildContext<'_>) -> ReplaySetup {
        ReplaySetup {
            path: ctx.input_path(ctx.param("path").and_then(Value::as_str).unwrap_or("")),
            filter: StreamFilter::new(ctx.param("stream").and_then(Value::as_str).unwrap_or("")),
            ty: ctx.process.output.clone().unwrap_or(ValueType::Any),
            clock: ctx.clock,
        }
    }
}

/// Which samples of a recording a replay keeps, and what it saw of the others (to say so when the
/// filter kept nothing: a misspelt stream name must not silently give an empty source).
#[derive(Debug, Default)]
pub struct StreamFilter {
    /// Keep only this stream (`None`: every stream).
    pub stream: Option<String>,
    kept: u64,
    /// The other streams' names (the first few) and how many samples they had.
    others: BTreeMap<String, u64>,
}

impl StreamFilter {
    /// How many other streams' names are kept for the warning.
    const NAMES: usize = 8;

    /// A filter for `stream` (empty: every stream).
    pub fn new(stream: &str) -> StreamFilter {
        StreamFilter { stream: (!stream.is_empty()).then(|| stream.to_string()), ..StreamFilter::default() }
    }

    /// Whether a sample of `stream` is kept (and counts it).
    pub fn keep(&mut self, stream: &str) -> bool {
        match &self.stream {
            Some(wanted) if wanted != stream => {
                if let Some(n) = self.others.get_mut(stream) {
                    *n += 1;
                } else if self.others.len() < Self::NAMES {
                    self.others.insert(stream.to_string(), 1);
                }
                false
            }
            _ => {
                self.kept += 1;
                true
            }
        }
    }

    /// The warning to give at the end of a replay of `what` (`data/x.jsonl`): the filter named a
    /// stream no sample had.
    pub fn warning(&self, what: &str) -> Option<String> {
        let wanted = self.stream.as_ref().filter(|_| self.kept == 0)?;
        let found = if self.others.is_empty() {
            "it has no samples".to_string()
        } else {
            let names: Vec<String> = self.others.iter().map(|(n, k)| format!("{n:?} ({k})")).collect();
            let candidates: Vec<&str> = self.others.keys().map(String::as_str).collect();
            let closest = kpl_semantic::closest(wanted, &candidates)
                .map(|n| format!("; did you mean {n:?}?"))
                .unwrap_or_default();
            format!("its streams are {}{closest}", names.join(", "))
        };
        Some(format!("no sample of {what} is of stream {wanted:?}, so this source is empty: {found}"))
    }
}

/// The times of replayed samples: order checked, shifted for the wall clock.
#[derive(Debug)]
pub struct ReplayTimes {
    clock: ClockKind,
    shift: Option<Time>,
    last_available: Option<Time>,
}

impl ReplayTimes {
    pub fn new(clock: ClockKind) -> ReplayTimes {
        ReplayTimes { clock, shift: None, last_available: None }
    }

    /// The sample as the run replays it, or `None` (counted as malformed at `location`) when its
    /// available time goes back.
    pub fn admit(
        &mut self,
        ctx: &SourceContext,
        location: &str,
        mut sample: Sample,
    ) -> Result<Option<Sample>, ProcessError> {
        if let Some(last) = self.last_available
            && sample.available < last
        {
            let error = format!("time stamp goes backwards: available {} after {last}", sample.available);
            ctx.malformed(location, error)?;
            return Ok(None);
        }
        let shift = *self.shift.get_or_insert_with(|| match self.clock {
            ClockKind::Sim => 0,
            ClockKind::Wall => ctx.clock.start().saturating_sub(sample.available),
        });
        let (Some(valid), Some(available)) =
            (sample.valid.checked_add(shift), sample.available.checked_add(shift))
        else {
            let error = format!(
                "valid {} / available {} cannot be moved to the wall clock (by {shift} us): past the range \
                 of 64-bit microseconds",
                sample.valid, sample.available
            );
            ctx.malformed(location, error)?;
            return Ok(None);
        };
        self.last_available = Some(sample.available);
        (sample.valid, sample.available) = (valid, available);
        Ok(Some(sample))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn an_empty_filter_keeps_everything_and_never_warns() {
        let mut filter = StreamFilter::new("");
        assert!(filter.keep("a") && filter.keep("b"));
        assert_eq!(filter.warning("f.jsonl"), None);
        assert_eq!(StreamFilter::new("").warning("f.jsonl"), None, "an empty recording is not a typo");
    }

    #[test]
    fn a_filter_that_kept_nothing_names_the_streams_and_the_closest() {
        let mut filter = StreamFilter::new("percept");
        for stream in ["percepts", "percepts", "truth"] {
            assert!(!filter.keep(stream));
        }
        assert_eq!(
            filter.warning("data/r.jsonl").unwrap(),
            "no sample of data/r.jsonl is of stream \"percept\", so this source is empty: its streams \
             are \"percepts\" (2), \"truth\" (1); did you mean \"percepts\"?"
        );
        let mut filter = StreamFilter::new("tmp");
        assert!(!filter.keep("speed"));
        assert!(!filter.warning("x").unwrap().contains("did you mean"));
        assert!(StreamFilter::new("tmp").warning("x").unwrap().ends_with("it has no samples"));
        let mut filter = StreamFilter::new("speed");
        assert!(filter.keep("speed") && !filter.keep("other"));
        assert_eq!(filter.warning("x"), None);
    }
}
