//! SVG pictures of a road network (roads with their lane markings, junction areas, occluders)
//! with tracks drawn over it (ground truth, percepts, anchored
//! objects: any list of point lists), so that a user can look at what was anchored.
//!
//! ```
//! use kpl_roads::{RoadNetwork, scenarios, svg};
//! let net = RoadNetwork::build(&scenarios::bridge()).unwrap();
//! let truth = svg::Layer::line("car1", "#1f77b4", vec![vec![[-100.0, -1.75], [100.0, -1.75]]]);
//! let picture = svg::render(&net, &[truth], &svg::SvgOptions::default());
//! assert!(picture.starts_with("<svg"));
//! ```

use std::fmt::Write;

use crate::format::OccluderKind;
use crate::geom::Point;
use crate::network::RoadNetwork;

/// How a layer's tracks are drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mark {
    /// A polyline through each track's points.
    Line,
    /// A dot at each point.
    Dots,
}

/// One legend entry: tracks in one colour.
#[derive(Debug, Clone, PartialEq)]
pub struct Layer {
    pub label: String,
    /// Any SVG colour (`#d62728`, `red`).
    pub color: String,
    pub mark: Mark,
    pub tracks: Vec<Vec<Point>>,
}

impl Layer {
    pub fn line(label: &str, color: &str, tracks: Vec<Vec<Point>>) -> Layer {
        Layer { label: label.to_string(), color: color.to_string(), mark: Mark::Line, tracks }
    }

    pub fn dots(label: &str, color: &str, tracks: Vec<Vec<Point>>) -> Layer {
        Layer { label: label.to_string(), color: color.to_string(), mark: Mark::Dots, tracks }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct SvgOptions {
    /// Width of the picture in pixels; the height follows the network's aspect ratio.
    pub width_px: f64,
    /// Draw only this part of the world (`(min, max)` in metres) instead of the whole network.
    pub view: Option<(Point, Point)>,
}

impl Default for SvgOptions {
    fn default() -> SvgOptions {
        SvgOptions { width_px: 1000.0, view: None }
    }
}

/// The mapping from world metres to picture pixels: `lo` is the bottom-left corner of the part of
/// the world drawn, `hi` the top-right; y grows upwards in the world and downwards in SVG.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    pub lo: Point,
    pub hi: Point,
    /// Pixels per metre.
    pub scale: f64,
}

impl View {
    /// A view of the world's rectangle `(lo, hi)` that is `width_px` wide (clamped to 50-20,000
    /// pixels; 1,000 when not finite).
    pub fn new(lo: Point, hi: Point, width_px: f64) -> View {
        let hi = [hi[0].max(lo[0] + 1.0), hi[1].max(lo[1] + 1.0)];
        let width_px = if width_px.is_finite() { width_px.clamp(50.0, 20_000.0) } else { 1000.0 };
        View { lo, hi, scale: width_px / (hi[0] - lo[0]) }
    }

    pub fn width_px(&self) -> f64 {
        (self.hi[0] - self.lo[0]) * self.scale
    }

    pub fn height_px(&self) -> f64 {
        (self.hi[1] - self.lo[1]) * self.scale
    }

    /// A world point in pixels.
    pub fn px(&self, p: Point) -> (f64, f64) {
        ((p[0] - self.lo[0]) * self.scale, (self.hi[1] - p[1]) * self.scale)
    }

    /// An SVG path through world points.
    pub fn path(&self, points: &[Point]) -> String {
        let mut d = String::new();
        for (i, &p) in points.iter().enumerate() {
            let (x, y) = self.px(p);
            let _ = write!(d, "{}{x:.1},{y:.1}", if i == 0 { "M" } else { " L" });
        }
        d
    }
}

/// Escapes text for SVG content and attribute values.
pub fn escape(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// Draws the network (roads by level with their lane markings, junction areas, occluders) into
/// `svg`, as SVG elements (no `<svg>` element around them).
pub fn draw_network(svg: &mut String, net: &RoadNetwork, view: &View) {
    let mut levels: Vec<i32> = net.roads().iter().map(|r| r.level).collect();
    levels.sort_unstable();
    levels.dedup();
    let ground = levels.first().copied().unwrap_or(0);
    for &level in &levels {
        for road in net.roads().iter().filter(|r| r.level == level) {
            let d = view.path(road.centerline.points());
            let w = road.width_m * view.scale;
            let _ = writeln!(svg, r##"<path d="{d}" fill="none" stroke="#8a8a8a" stroke-width="{w:.1}"/>"##);
            // A dashed line between neighbouring lanes.
            for pair in road.lanes.windows(2) {
                let boundary = pair[0].lateral_m - pair[0].width_m / 2.0;
                let Some(line) = road.centerline.offset(boundary) else { continue };
                let _ = writeln!(
                    svg,
                    r##"<path d="{}" fill="none" stroke="#ffffff" stroke-width="{:.1}" stroke-dasharray="{:.1}"/>"##,
                    view.path(line.points()),
                    (0.15 * view.scale).max(0.5),
                    3.0 * view.scale
                );
            }
        }
        if level == ground {
            for node in net.nodes().iter().filter(|n| n.area.len() >= 3) {
                let _ = writeln!(svg, r##"<path d="{} Z" fill="#8a8a8a"/>"##, view.path(&node.area));
            }
            for occluder in net.occluders().list() {
                draw_occluder(svg, view, occluder.kind, &occluder.area, &occluder.name);
            }
        }
    }
}

/// Draws one occluder's area, filled by its kind, with its name as a tooltip.
pub fn draw_occluder(svg: &mut String, view: &View, kind: OccluderKind, area: &[Point], name: &str) {
    let (fill, opacity) = match kind {
        OccluderKind::Bridge => ("#6b5a45", 0.8),
        OccluderKind::Tunnel => ("#3a3a3a", 0.9),
        OccluderKind::Trees => ("#3f7a3a", 0.8),
        OccluderKind::Building => ("#9a8f86", 0.9),
        OccluderKind::Other => ("#555555", 0.7),
    };
    let _ = writeln!(
        svg,
        r##"<path d="{} Z" fill="{fill}" fill-opacity="{opacity}"><title>{}</title></path>"##,
        view.path(area),
        escape(name)
    );
}

/// Draws the network (roads by level, crossings, bridges and tunnels) and the layers over it.
pub fn render(net: &RoadNetwork, layers: &[Layer], options: &SvgOptions) -> String {
    let (lo, hi) = options.view.unwrap_or_else(|| net.bounds());
    let view = View::new(lo, hi, options.width_px);
    let (width_px, height_px) = (view.width_px(), view.height_px());
    let mut svg = String::new();
    let _ = writeln!(
        svg,
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="{width_px:.0}" height="{height_px:.0}" viewBox="0 0 {width_px:.1} {height_px:.1}">"##
    );
    let _ = writeln!(svg, r##"<rect width="100%" height="100%" fill="#eef3e8"/>"##);
    draw_network(&mut svg, net, &view);

    let dot_radius = (0.8 * view.scale).clamp(1.0, 4.0);
    for layer in layers {
        let color = escape(&layer.color);
        for track in &layer.tracks {
            match layer.mark {
                Mark::Line if track.len() >= 2 => {
                    let _ = writeln!(
                        svg,
                        r##"<path d="{}" fill="none" stroke="{color}" stroke-width="1.5"/>"##,
                        view.path(track)
                    );
                }
                Mark::Line | Mark::Dots => {
                    for &p in track {
                        let (x, y) = view.px(p);
                        let _ = writeln!(
                            svg,
                            r##"<circle cx="{x:.1}" cy="{y:.1}" r="{dot_radius:.1}" fill="{color}"/>"##
                        );
                    }
                }
            }
        }
    }

    for (i, layer) in layers.iter().enumerate() {
        let y = 16.0 + 18.0 * i as f64;
        let _ = writeln!(
            svg,
            r##"<rect x="8" y="{:.0}" width="12" height="12" fill="{}"/><text x="26" y="{y:.0}" font-family="sans-serif" font-size="13" dominant-baseline="central">{}</text>"##,
            y - 6.0,
            escape(&layer.color),
            escape(&layer.label)
        );
    }
    svg.push_str("</svg>\n");
    svg
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, reason = "tests")]
    use super::*;
    use crate::scenarios;

    #[test]
    fn draws_roads_occluders_layers_and_an_escaped_legend() {
        let net = RoadNetwork::build(&scenarios::bridge()).unwrap();
        let layers = [
            Layer::line(
                "<cars & trucks>",
                "#1f77b4",
                vec![vec![[-100.0, -1.75], [100.0, -1.75]], vec![[0.0, 0.0]]],
            ),
            Layer::dots("percepts", "red", vec![vec![[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]]),
        ];
        let svg = render(&net, &layers, &SvgOptions { width_px: 400.0, view: None });
        assert!(svg.starts_with("<svg") && svg.ends_with("</svg>\n"));
        assert!(svg.contains("&lt;cars &amp; trucks&gt;") && !svg.contains("<cars"));
        assert!(svg.contains("<title>bridge</title>"));
        // Two roads, each a band and a dashed centre line.
        assert_eq!(svg.matches("stroke=\"#8a8a8a\"").count(), 2);
        // One line track, a one-point track drawn as a dot, three dots.
        assert_eq!(svg.matches("stroke=\"#1f77b4\"").count(), 1);
        assert_eq!(svg.matches("<circle").count(), 4);
        // The overpass (level 1) is drawn after the bridge, so it lies on top of it.
        let bridge_at = svg.find("<title>bridge</title>").unwrap();
        let last_road_at = svg.rfind("stroke=\"#8a8a8a\"").unwrap();
        assert!(last_road_at > bridge_at);
    }
}
