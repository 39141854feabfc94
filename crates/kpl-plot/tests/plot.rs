//! Plots of a small recording written here line by line: what is drawn, how many marks of each
//! kind, which labels, the time window, the situations, and the errors.
#![allow(clippy::unwrap_used, reason = "tests")]

use std::fmt::Write;
use std::path::Path;

use kpl_plot::events::EventReader;
use kpl_plot::{DrawOptions, Plot, PlotError, PlotOptions, Role, Window, render};
use kpl_roads::{RoadNetwork, scenarios};
use kpl_score::Recording;

/// 3 s at 10 Hz: car1 drives east at 10 m/s. The tracker sees it as vp1 until 1 s (missing at
/// 0.5 s), as vp2 from 2 s on; the on-road object oo1 is measured while a percept is there and
/// predicted between; a situation names oo1 from 1.5 s to 2.5 s.
fn recording() -> String {
    let mut text = String::new();
    for i in 0..=30 {
        let t = i * 100_000;
        let x = -50.0 + i as f64;
        let _ = writeln!(
            text,
            r#"{{"stream":"tracker.truth","valid":{t},"value":[{{"id":"car1","pos":[{x},-1.75]}}]}}"#
        );
        let seen = i != 5 && !(11..20).contains(&i);
        let percept = if i < 11 { "vp1" } else { "vp2" };
        let percepts = if seen { format!(r#"[{{"id":"{percept}","pos":[{x},-1.5]}}]"#) } else { "[]".into() };
        let _ = writeln!(text, r#"{{"stream":"tracker","valid":{t},"value":{percepts}}}"#);
        let _ = writeln!(
            text,
            r#"{{"stream":"world_onroad","valid":{t},"value":[{{"id":"oo1","pos":[{x},-1.75],"measured":{seen}}}]}}"#
        );
        if (15..=25).contains(&i) {
            let to = if i == 25 { "2500000" } else { "null" };
            let _ = writeln!(
                text,
                r#"{{"stream":"situations","valid":{t},"value":[{{"situation":"speeding","objects":["oo1"],"from":1500000,"to":{to}}}]}}"#
            );
        }
    }
    text
}

fn plot(options: &PlotOptions) -> Plot {
    let text = recording();
    let recording = Recording::read_from(Path::new("run.jsonl"), text.as_bytes()).unwrap();
    let mut plot = Plot::from_recording(&recording, options).unwrap();
    let mut events = EventReader::default();
    events.read(Path::new("run.jsonl"), text.as_bytes()).unwrap();
    plot.events = events.finish().events;
    plot
}

#[test]
fn percepts_are_dots_objects_squares_hollow_when_predicted() {
    let plot = plot(&PlotOptions::default());
    let roles: Vec<(&str, Role)> = plot.series.iter().map(|s| (s.stream.as_str(), s.role)).collect();
    assert_eq!(
        roles,
        [("tracker.truth", Role::Truth), ("tracker", Role::Percepts), ("world_onroad", Role::Objects)]
    );
    let net = RoadNetwork::build(&scenarios::crossing()).unwrap();
    let svg = render(&plot, Some(&net), &[], &DrawOptions::default());
    // 31 frames: 21 with a percept, 10 without (one missed detection, then nine frames).
    let circles = svg.lines().filter(|l| l.starts_with("<circle")).count();
    assert_eq!(circles, 21);
    let filled = svg.lines().filter(|l| l.starts_with("<rect x=") && l.contains("fill=\"#1f5fbf\"")).count();
    let hollow = svg
        .lines()
        .filter(|l| l.starts_with("<rect x=") && l.contains("fill=\"none\" stroke=\"#1f5fbf\""))
        .count();
    assert_eq!((filled, hollow), (21, 10));
    // The truth is one dashed line; labels where a track begins or comes back after over 1 s.
    assert_eq!(svg.matches("stroke-dasharray=\"4 2\"><title>car1</title>").count(), 1);
    for (label, count) in [(">vp1</text>", 1), (">vp2</text>", 1), (">oo1</text>", 1)] {
        assert_eq!(svg.matches(label).count(), count, "{label}");
    }
    // The legend names each stream and the hollow squares; the situation is in it too.
    for text in ["tracker (percepts)", "world_onroad (objects)", "hollow: predicted", "situation: speeding"] {
        assert!(svg.contains(text), "{text}");
    }
    // The network is under it: the crossing's four roads.
    assert_eq!(svg.matches("stroke=\"#8a8a8a\"").count(), 4);
}

#[test]
fn a_situation_is_one_event_highlighted_along_its_object_and_on_the_timeline() {
    let plot = plot(&PlotOptions::default());
    assert_eq!(plot.events.len(), 1, "eleven reports of one situation are one event");
    assert_eq!((plot.events[0].from, plot.events[0].to), (1_500_000, Some(2_500_000)));
    let svg = render(&plot, None, &[], &DrawOptions::default());
    // oo1's path from 1.5 s to 2.5 s: 11 points, as one wide band of the situation's colour.
    let band = svg.lines().find(|l| l.contains("stroke=\"#ff9900\" stroke-opacity=\"0.35\"")).unwrap();
    assert_eq!(band.matches(" L").count(), 10);
    assert!(svg.contains("<title>speeding oo1 from 1.5 s to 2.5 s</title>"));
}

#[test]
fn the_window_and_the_stream_choice_limit_what_is_drawn() {
    let options = PlotOptions {
        streams: vec!["tracker".into()],
        no_truth: true,
        window: Window { from: Some(2_000_000), to: Some(3_000_000) },
        ..PlotOptions::default()
    };
    let plot = plot(&options);
    assert_eq!(plot.series.len(), 1);
    let times: Vec<i64> = plot.series[0].points().map(|p| p.time).collect();
    assert_eq!(times.len(), 11);
    assert!(times.iter().all(|t| (2_000_000..=3_000_000).contains(t)));
    // The view fits what is drawn: x from -30 to -20 m, 15 m around.
    let svg = render(&plot, None, &[], &DrawOptions { width_px: 400.0, ..DrawOptions::default() });
    assert!(svg.starts_with(r#"<svg xmlns="http://www.w3.org/2000/svg" width="400" height="#));
}

#[test]
fn an_unknown_stream_is_an_error_with_a_suggestion() {
    let text = recording();
    let recording = Recording::read_from(Path::new("run.jsonl"), text.as_bytes()).unwrap();
    let options = PlotOptions { streams: vec!["world_onroads".into()], ..PlotOptions::default() };
    let err = Plot::from_recording(&recording, &options).unwrap_err();
    assert!(matches!(err, PlotError::UnknownStream { .. }));
    assert!(err.to_string().contains("did you mean `world_onroad`?"), "{err}");
}
