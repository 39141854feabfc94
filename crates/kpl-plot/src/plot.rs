//! What a plot shows: series of tracks (one series per recorded stream), each track the points of
//! one object symbol over time, and interval events; built from a recording inside a time window.

use std::collections::BTreeMap;

use kpl_core::Time;
use kpl_score::{ObjectStream, Recording};

use crate::error::PlotError;
use crate::events::Event;

/// How a stream is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// The ground truth: a thin line per true object.
    Truth,
    /// Percepts (records that say nothing about being measured): a dot per point.
    Percepts,
    /// Objects of link processes or a world model: a square per point, hollow where predicted.
    Objects,
}

/// A track that comes back after more than this (microseconds) is labelled again.
pub const LABEL_GAP: Time = 1_000_000;

/// One position of an object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackPoint {
    pub time: Time,
    pub pos: [f64; 2],
    /// Derived from a percept at this time (records without `measured` count as measured).
    pub measured: bool,
    /// The object's first point, or its first after more than [`LABEL_GAP`] without one (a
    /// missed detection or two is no new segment). Labels go here.
    pub starts_segment: bool,
}

/// The points of one object symbol (or true object), in time order.
#[derive(Debug, Clone, PartialEq)]
pub struct Track {
    pub id: String,
    pub points: Vec<TrackPoint>,
}

/// One stream's tracks.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    pub stream: String,
    pub role: Role,
    /// Any SVG colour.
    pub color: String,
    pub tracks: Vec<Track>,
}

impl Series {
    /// A series in the default colour of its role.
    pub fn new(stream: &str, role: Role, tracks: Vec<Track>) -> Series {
        let color = match role {
            Role::Truth => "#444444",
            Role::Percepts => "#d62728",
            Role::Objects => "#1f5fbf",
        };
        Series { stream: stream.to_string(), role, color: color.to_string(), tracks }
    }

    /// Every point of every track.
    pub fn points(&self) -> impl Iterator<Item = &TrackPoint> {
        self.tracks.iter().flat_map(|t| &t.points)
    }
}

/// The valid times shown: `from` and `to` included; `None` is open.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Window {
    pub from: Option<Time>,
    pub to: Option<Time>,
}

impl Window {
    pub fn contains(&self, t: Time) -> bool {
        self.from.is_none_or(|f| t >= f) && self.to.is_none_or(|to| t <= to)
    }

    /// Whether `[from, to]` (an open `to`: still going on) overlaps the window.
    pub fn overlaps(&self, from: Time, to: Option<Time>) -> bool {
        self.to.is_none_or(|w| from <= w)
            && match (self.from, to) {
                (Some(w), Some(to)) => to >= w,
                _ => true,
            }
    }
}

/// What to take from a recording.
#[derive(Debug, Clone, Default)]
pub struct PlotOptions {
    /// The streams drawn (besides the ground truth); empty: every object stream.
    pub streams: Vec<String>,
    /// The ground-truth stream; `None`: the recording's own (`*.truth`), if it has one.
    pub truth: Option<String>,
    /// Leave the ground truth out.
    pub no_truth: bool,
    pub window: Window,
}

/// Everything a picture shows, before it is drawn.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Plot {
    /// Drawn in order: the truth first, then percepts, then objects.
    pub series: Vec<Series>,
    pub events: Vec<Event>,
    pub window: Window,
}

/// Colours of object streams after the first (blue), in order.
const OBJECT_COLORS: [&str; 6] = ["#1f5fbf", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b"];
/// Colours of percept streams after the first (red).
const PERCEPT_COLORS: [&str; 3] = ["#d62728", "#e377c2", "#bcbd22"];

impl Plot {
    /// The recording's object streams as series: the ground truth (unless left out), then the
    /// streams that say nothing about measurement (percepts), then the others (link outputs).
    pub fn from_recording(recording: &Recording, options: &PlotOptions) -> Result<Plot, PlotError> {
        let truth_name = if options.no_truth {
            None
        } else {
            match &options.truth {
                Some(name) => Some(named(recording, name)?.name.clone()),
                None => recording.truth(None).ok().map(|s| s.name.clone()),
            }
        };
        let chosen: Vec<&ObjectStream> = if options.streams.is_empty() {
            recording.streams().filter(|s| Some(&s.name) != truth_name.as_ref()).collect()
        } else {
            options.streams.iter().map(|name| named(recording, name)).collect::<Result<_, _>>()?
        };
        let mut plot = Plot { window: options.window, ..Plot::default() };
        if let Some(name) = &truth_name
            && let Some(truth) = recording.stream(name)
        {
            plot.series.push(Series::new(&truth.name, Role::Truth, tracks(truth, options.window)));
        }
        let (percepts, objects): (Vec<&ObjectStream>, Vec<&ObjectStream>) =
            chosen.into_iter().partition(|s| !s.has_measured);
        for (i, stream) in percepts.iter().enumerate() {
            let mut series = Series::new(&stream.name, Role::Percepts, tracks(stream, options.window));
            series.color = PERCEPT_COLORS[i % PERCEPT_COLORS.len()].to_string();
            plot.series.push(series);
        }
        for (i, stream) in objects.iter().enumerate() {
            let mut series = Series::new(&stream.name, Role::Objects, tracks(stream, options.window));
            series.color = OBJECT_COLORS[i % OBJECT_COLORS.len()].to_string();
            plot.series.push(series);
        }
        Ok(plot)
    }

    /// The world rectangle `(lo, hi)` of every point and event object drawn, if there is any.
    pub fn bounds(&self) -> Option<([f64; 2], [f64; 2])> {
        let mut points = self.series.iter().flat_map(Series::points).map(|p| p.pos);
        let first = points.next()?;
        Some(points.fold((first, first), |(lo, hi), p| {
            ([lo[0].min(p[0]), lo[1].min(p[1])], [hi[0].max(p[0]), hi[1].max(p[1])])
        }))
    }

    /// The points of object `id` in any non-truth series between `from` and `to` (open: the end).
    pub fn points_of<'a>(
        &'a self,
        id: &'a str,
        from: Time,
        to: Option<Time>,
    ) -> impl Iterator<Item = Vec<[f64; 2]>> + 'a {
        self.series.iter().filter(|s| s.role != Role::Truth).flat_map(move |s| {
            s.tracks.iter().filter(move |t| t.id == id).map(move |t| {
                t.points
                    .iter()
                    .filter(|p| p.time >= from && to.is_none_or(|to| p.time <= to))
                    .map(|p| p.pos)
                    .collect()
            })
        })
    }

    /// The first and last valid time of any point.
    pub fn time_span(&self) -> Option<(Time, Time)> {
        let mut times = self.series.iter().flat_map(Series::points).map(|p| p.time);
        let first = times.next()?;
        Some(times.fold((first, first), |(lo, hi), t| (lo.min(t), hi.max(t))))
    }
}

fn named<'a>(recording: &'a Recording, name: &str) -> Result<&'a ObjectStream, PlotError> {
    recording.stream(name).ok_or_else(|| {
        let known: Vec<String> = recording.streams().map(|s| s.name.clone()).collect();
        let names: Vec<&str> = known.iter().map(String::as_str).collect();
        let suggestion = kpl_core::closest(name, &names).map(str::to_string);
        PlotError::UnknownStream { name: name.to_string(), suggestion, known }
    })
}

/// The stream's objects as tracks (by symbol, in order of first appearance) inside the window.
fn tracks(stream: &ObjectStream, window: Window) -> Vec<Track> {
    let mut order: Vec<String> = Vec::new();
    let mut by_id: BTreeMap<String, Vec<TrackPoint>> = BTreeMap::new();
    for snapshot in stream.snapshots.iter().filter(|s| window.contains(s.time)) {
        for object in &snapshot.objects {
            let points = by_id.entry(object.id.clone()).or_insert_with(|| {
                order.push(object.id.clone());
                Vec::new()
            });
            points.push(TrackPoint {
                time: snapshot.time,
                pos: object.pos,
                measured: object.measured.unwrap_or(true),
                starts_segment: points.last().is_none_or(|p| snapshot.time - p.time > LABEL_GAP),
            });
        }
    }
    order.into_iter().filter_map(|id| by_id.remove(&id).map(|points| Track { id, points })).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_contains_and_overlaps() {
        let w = Window { from: Some(10), to: Some(20) };
        assert!(w.contains(10) && w.contains(20) && !w.contains(9) && !w.contains(21));
        assert!(w.overlaps(0, Some(10)) && w.overlaps(20, None) && w.overlaps(0, None));
        assert!(!w.overlaps(0, Some(9)) && !w.overlaps(21, None));
        assert!(Window::default().contains(i64::MIN));
    }
}
