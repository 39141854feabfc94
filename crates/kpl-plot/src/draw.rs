//! Drawing a [`Plot`] as SVG: the network (kpl-roads' drawing), extra occluders, situations
//! highlighted under the objects they name, the ground truth as lines, percepts as dots, objects as
//! squares (hollow: predicted), symbols as labels, a legend, and a timeline of the events.

use std::collections::BTreeMap;
use std::fmt::Write;

use kpl_core::Time;
use kpl_roads::svg::{View, draw_network, draw_occluder, escape};
use kpl_roads::{Occluder, RoadNetwork};

use crate::plot::{Plot, Role, Series};

/// How a plot is drawn.
#[derive(Debug, Clone, PartialEq)]
pub struct DrawOptions {
    /// Width of the map in pixels; its height follows the part of the world shown.
    pub width_px: f64,
    /// The part of the world drawn (`(lo, hi)`, metres); `None`: what the plot shows, with a margin.
    pub view: Option<([f64; 2], [f64; 2])>,
    /// Metres around the plot's points when `view` is `None`.
    pub margin_m: f64,
    /// Label each object where it appears (its first point and each return after a gap).
    pub labels: bool,
    pub legend: bool,
}

impl Default for DrawOptions {
    fn default() -> DrawOptions {
        DrawOptions { width_px: 1000.0, view: None, margin_m: 15.0, labels: true, legend: true }
    }
}

/// Colours of situations, by name in order of first appearance.
const EVENT_COLORS: [&str; 6] = ["#ff9900", "#e7298a", "#66a61e", "#7570b3", "#a6761d", "#1b9e77"];
/// Timeline rows drawn; more events are counted in a last line.
const MAX_TIMELINE_ROWS: usize = 40;
const FONT: &str = r#"font-family="sans-serif""#;

/// The picture: `network` (if any) under the plot, with `occluders` that are not the network's
/// own (a tracker's).
pub fn render(
    plot: &Plot,
    network: Option<&RoadNetwork>,
    occluders: &[Occluder],
    options: &DrawOptions,
) -> String {
    let view = fit_view(plot, network, options);
    let event_colors = event_colors(plot);
    let timeline_rows =
        plot.events.len().min(MAX_TIMELINE_ROWS) + usize::from(plot.events.len() > MAX_TIMELINE_ROWS);
    let timeline_px = if plot.events.is_empty() { 0.0 } else { 40.0 + 16.0 * timeline_rows as f64 };
    let (width_px, map_px) = (view.width_px(), view.height_px());
    let height_px = map_px + timeline_px;
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="{width_px:.0}" height="{height_px:.0}" viewBox="0 0 {width_px:.1} {height_px:.1}">"##
    );
    let _ = writeln!(svg, r##"<rect width="100%" height="100%" fill="#eef3e8"/>"##);
    if let Some(net) = network {
        draw_network(&mut svg, net, &view);
    }
    for occluder in occluders {
        draw_occluder(&mut svg, &view, occluder.kind, &occluder.area, &occluder.name);
    }
    draw_event_highlights(&mut svg, plot, &view, &event_colors);
    for series in &plot.series {
        draw_series(&mut svg, series, &view);
    }
    if options.labels {
        for series in plot.series.iter().filter(|s| s.role != Role::Truth) {
            draw_labels(&mut svg, series, &view);
        }
    }
    if options.legend {
        draw_legend(&mut svg, plot, &event_colors);
    }
    if !plot.events.is_empty() {
        draw_timeline(&mut svg, plot, &event_colors, map_px, width_px);
    }
    svg.push_str("</svg>\n");
    svg
}

/// The view asked for, else the plot's points with a margin, else the network, else 100 m.
fn fit_view(plot: &Plot, network: Option<&RoadNetwork>, options: &DrawOptions) -> View {
    let margin = if options.margin_m.is_finite() { options.margin_m.max(0.0) } else { 15.0 };
    let (lo, hi) = options
        .view
        .or_else(|| {
            plot.bounds().map(|(lo, hi)| ([lo[0] - margin, lo[1] - margin], [hi[0] + margin, hi[1] + margin]))
        })
        .or_else(|| network.map(RoadNetwork::bounds))
        .unwrap_or(([0.0, 0.0], [100.0, 100.0]));
    View::new(lo, hi, options.width_px)
}

fn event_colors(plot: &Plot) -> BTreeMap<&str, &'static str> {
    let mut colors = BTreeMap::new();
    for event in &plot.events {
        let next = EVENT_COLORS[colors.len() % EVENT_COLORS.len()];
        colors.entry(event.name.as_str()).or_insert(next);
    }
    colors
}

/// Sizes of marks in pixels: about a car's size, but visible at any scale.
fn dot_radius(view: &View) -> f64 {
    (0.5 * view.scale).clamp(1.5, 4.0)
}

fn square_half(view: &View) -> f64 {
    (0.9 * view.scale).clamp(2.5, 5.5)
}

/// A wide translucent band along each named object's path while the event lasts, and its name
/// where it begins.
fn draw_event_highlights(svg: &mut String, plot: &Plot, view: &View, colors: &BTreeMap<&str, &str>) {
    let width = (4.0 * view.scale).clamp(8.0, 16.0);
    for event in plot.events.iter().filter(|e| plot.window.overlaps(e.from, e.to)) {
        let color = colors.get(event.name.as_str()).copied().unwrap_or("#ff9900");
        let mut first = None;
        for id in &event.objects {
            for path in plot.points_of(id, event.from, event.to) {
                let Some(&start) = path.first() else { continue };
                first.get_or_insert(start);
                if path.len() == 1 {
                    let (x, y) = view.px(start);
                    let _ = writeln!(
                        svg,
                        r##"<circle cx="{x:.1}" cy="{y:.1}" r="{:.1}" fill="{color}" fill-opacity="0.35"/>"##,
                        width / 2.0
                    );
                } else {
                    let _ = writeln!(
                        svg,
                        r##"<path d="{}" fill="none" stroke="{color}" stroke-opacity="0.35" stroke-width="{width:.1}" stroke-linecap="round" stroke-linejoin="round"/>"##,
                        view.path(&path)
                    );
                }
            }
        }
        if let Some(start) = first {
            let (x, y) = view.px(start);
            let _ = writeln!(
                svg,
                r##"<text x="{:.1}" y="{:.1}" {FONT} font-size="11" font-style="italic" fill="{color}" stroke="#ffffff" stroke-width="3" paint-order="stroke">{}</text>"##,
                x + width,
                y - width,
                escape(&event.name)
            );
        }
    }
}

fn draw_series(svg: &mut String, series: &Series, view: &View) {
    let color = escape(&series.color);
    let _ =
        writeln!(svg, r#"<g class="{}"><title>{}</title>"#, role_class(series.role), escape(&series.stream));
    match series.role {
        Role::Truth => {
            for track in &series.tracks {
                let points: Vec<[f64; 2]> = track.points.iter().map(|p| p.pos).collect();
                if points.len() >= 2 {
                    let _ = writeln!(
                        svg,
                        r##"<path d="{}" fill="none" stroke="{color}" stroke-width="1" stroke-opacity="0.8" stroke-dasharray="4 2"><title>{}</title></path>"##,
                        view.path(&points),
                        escape(&track.id)
                    );
                }
            }
        }
        Role::Percepts => {
            let r = dot_radius(view);
            for p in series.points() {
                let (x, y) = view.px(p.pos);
                let _ = writeln!(
                    svg,
                    r##"<circle cx="{x:.1}" cy="{y:.1}" r="{r:.1}" fill="{color}" fill-opacity="0.85"/>"##
                );
            }
        }
        Role::Objects => {
            let h = square_half(view);
            for p in series.points() {
                let (x, y) = view.px(p.pos);
                let paint = if p.measured {
                    format!(r#"fill="{color}" fill-opacity="0.8""#)
                } else {
                    format!(r#"fill="none" stroke="{color}" stroke-width="1.2""#)
                };
                let _ = writeln!(
                    svg,
                    r#"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" {paint}/>"#,
                    x - h,
                    y - h,
                    2.0 * h,
                    2.0 * h
                );
            }
        }
    }
    svg.push_str("</g>\n");
}

fn role_class(role: Role) -> &'static str {
    match role {
        Role::Truth => "truth",
        Role::Percepts => "percepts",
        Role::Objects => "objects",
    }
}

/// Each symbol where its track begins or comes back: percepts above, objects below their mark.
fn draw_labels(svg: &mut String, series: &Series, view: &View) {
    let color = escape(&series.color);
    let (dx, dy) = match series.role {
        Role::Percepts => (4.0, -5.0),
        _ => (square_half(view) + 2.0, square_half(view) + 10.0),
    };
    for track in &series.tracks {
        for p in track.points.iter().filter(|p| p.starts_segment) {
            let (x, y) = view.px(p.pos);
            let _ = writeln!(
                svg,
                r##"<text x="{:.1}" y="{:.1}" {FONT} font-size="11" font-weight="bold" fill="{color}" stroke="#ffffff" stroke-width="3" paint-order="stroke">{}</text>"##,
                x + dx,
                y + dy,
                escape(&track.id)
            );
        }
    }
}

/// One line per series (its mark and stream), one for predicted states, one per situation.
fn draw_legend(svg: &mut String, plot: &Plot, event_colors: &BTreeMap<&str, &str>) {
    let mut entries: Vec<(String, String)> = Vec::new();
    for series in &plot.series {
        let color = escape(&series.color);
        let (glyph, what) = match series.role {
            Role::Truth => (
                format!(
                    r#"<path d="M0,6 L14,6" stroke="{color}" stroke-width="1.5" stroke-dasharray="4 2"/>"#
                ),
                "ground truth",
            ),
            Role::Percepts => (format!(r#"<circle cx="7" cy="6" r="3.5" fill="{color}"/>"#), "percepts"),
            Role::Objects => {
                (format!(r#"<rect x="2" y="1" width="10" height="10" fill="{color}"/>"#), "objects")
            }
        };
        entries.push((glyph, format!("{} ({what})", series.stream)));
    }
    if plot.series.iter().any(|s| s.role == Role::Objects && s.points().any(|p| !p.measured)) {
        entries.push((
            r##"<rect x="2" y="1" width="10" height="10" fill="none" stroke="#333333" stroke-width="1.2"/>"##
                .to_string(),
            "hollow: predicted, not measured".to_string(),
        ));
    }
    for (name, color) in event_colors {
        entries.push((
            format!(r#"<path d="M1,6 L13,6" stroke="{color}" stroke-opacity="0.5" stroke-width="8" stroke-linecap="round"/>"#),
            format!("situation: {name}"),
        ));
    }
    if let (Some(from), Some(to)) = (plot.window.from, plot.window.to) {
        entries.push((String::new(), format!("valid times {} to {}", seconds(from), seconds(to))));
    } else if let Some((from, to)) = plot.time_span() {
        entries.push((String::new(), format!("valid times {} to {}", seconds(from), seconds(to))));
    }
    let longest = entries.iter().map(|(_, text)| text.chars().count()).max().unwrap_or(0);
    let box_width = 34.0 + 6.5 * longest as f64;
    let box_height = 8.0 + 17.0 * entries.len() as f64;
    let _ = writeln!(
        svg,
        r##"<g class="legend"><rect x="6" y="6" width="{box_width:.0}" height="{box_height:.0}" fill="#ffffff" fill-opacity="0.85" stroke="#999999"/>"##
    );
    for (i, (glyph, text)) in entries.iter().enumerate() {
        let y = 12.0 + 17.0 * i as f64;
        let _ = writeln!(
            svg,
            r##"<g transform="translate(12,{y:.0})">{glyph}</g><text x="32" y="{:.0}" {FONT} font-size="12">{}</text>"##,
            y + 10.0,
            escape(text)
        );
    }
    svg.push_str("</g>\n");
}

/// Situations as bars over valid time, under the map.
fn draw_timeline(svg: &mut String, plot: &Plot, colors: &BTreeMap<&str, &str>, top: f64, width: f64) {
    let span = plot.time_span();
    let start = plot
        .window
        .from
        .or(span.map(|s| s.0))
        .into_iter()
        .chain(plot.events.iter().map(|e| e.from))
        .min()
        .unwrap_or(0);
    let end = plot
        .window
        .to
        .or(span.map(|s| s.1))
        .into_iter()
        .chain(plot.events.iter().filter_map(|e| e.to))
        .max()
        .unwrap_or(start)
        .max(start + 1);
    let (left, right) = (150.0, width - 20.0);
    let x_of = |t: Time| {
        left + (right - left).max(1.0) * (t.clamp(start, end) - start) as f64 / (end - start) as f64
    };
    let _ = writeln!(
        svg,
        r##"<g class="timeline"><rect x="0" y="{top:.1}" width="{width:.1}" height="100%" fill="#ffffff"/>"##
    );
    let _ = writeln!(
        svg,
        r##"<text x="8" y="{:.1}" {FONT} font-size="12" font-weight="bold">situations</text><text x="{left:.0}" y="{:.1}" {FONT} font-size="11">{}</text><text x="{right:.0}" y="{:.1}" {FONT} font-size="11" text-anchor="end">{}</text>"##,
        top + 16.0,
        top + 16.0,
        seconds(start),
        top + 16.0,
        seconds(end)
    );
    for (i, event) in plot.events.iter().take(MAX_TIMELINE_ROWS).enumerate() {
        let y = top + 26.0 + 16.0 * i as f64;
        let color = colors.get(event.name.as_str()).copied().unwrap_or("#ff9900");
        let (x0, x1) = (x_of(event.from), x_of(event.to.unwrap_or(end)));
        let label = format!("{} {}", event.name, event.objects.join(" "));
        let _ = writeln!(
            svg,
            r##"<text x="8" y="{:.1}" {FONT} font-size="11">{}</text><rect x="{x0:.1}" y="{:.1}" width="{:.1}" height="10" fill="{color}" fill-opacity="0.7"><title>{} from {} to {}</title></rect>"##,
            y + 9.0,
            escape(&shorten(&label, 22)),
            y,
            (x1 - x0).max(2.0),
            escape(&label),
            seconds(event.from),
            event.to.map_or("the end".to_string(), seconds)
        );
    }
    if plot.events.len() > MAX_TIMELINE_ROWS {
        let y = top + 26.0 + 16.0 * MAX_TIMELINE_ROWS as f64;
        let _ = writeln!(
            svg,
            r#"<text x="8" y="{:.1}" {FONT} font-size="11">and {} more</text>"#,
            y + 9.0,
            plot.events.len() - MAX_TIMELINE_ROWS
        );
    }
    svg.push_str("</g>\n");
}

fn shorten(text: &str, max: usize) -> String {
    if text.chars().count() <= max {
        text.to_string()
    } else {
        text.chars().take(max - 1).collect::<String>() + "…"
    }
}

fn seconds(t: Time) -> String {
    format!("{} s", t as f64 / 1e6)
}
