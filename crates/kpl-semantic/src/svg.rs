//! The process graph drawn as SVG (`kpl graph --format svg`), laid out here so that no Graphviz
//! is needed: processes in columns from left to right by the longest chain of streams that leads
//! to them, ordered within a column to keep streams short, each a box coloured by its kind (and
//! outlined by its host's colour in a deployed spec); streams are curves labelled with their name
//! and the policy parts that differ from the default. Feedback streams are dashed and loop below.

use std::fmt::Write as _;

use crate::hir::{self, ProcessId, Spec};

const FONT: f64 = 12.0;
/// Average advance of a character of the sans-serif font, in em (generous, so text fits).
const CHAR_EM: f64 = 0.62;
const NODE_HEIGHT: f64 = 42.0;
const NODE_PAD: f64 = 12.0;
const ROW_GAP: f64 = 34.0;
const MIN_COLUMN_GAP: f64 = 90.0;
const MARGIN: f64 = 24.0;
/// The height a stream's lane takes in a column it passes through.
const LANE_HEIGHT: f64 = 14.0;

/// A process's box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placed {
    pub x: f64,
    pub y: f64,
    pub width: f64,
    pub height: f64,
}

/// Where every process goes, how each stream runs, and the size of the picture.
#[derive(Debug, Clone)]
pub struct Layout {
    /// By [`ProcessId`].
    pub boxes: Vec<Placed>,
    pub width: f64,
    pub height: f64,
    /// The column of each process.
    pub column: Vec<usize>,
    /// For each stream (in [`streams`] order) that runs forward: the lanes it passes through in
    /// the columns between its producer and its consumer, as (left x, right x, y). A stream
    /// spanning several columns takes a lane of its own in each, so it never crosses a box.
    pub lanes: Vec<Vec<(f64, f64, f64)>>,
}

fn text_width(text: &str, size: f64) -> f64 {
    text.chars().count() as f64 * size * CHAR_EM
}

fn detail(p: &hir::Process) -> String {
    let what = match &p.kind {
        hir::ProcessKind::Source(c) | hir::ProcessKind::Compute(c) | hir::ProcessKind::Sink(c) => {
            c.entry.clone()
        }
        hir::ProcessKind::Link(l) => format!("{} -> {} via {}", l.from_type, l.to_type, l.via.entry),
        hir::ProcessKind::Monitor(_) => "formula".to_string(),
        hir::ProcessKind::Chronicle(_) => "events".to_string(),
    };
    format!("{} {what}", p.kind_name())
}

/// The streams of the graph: (producer, consumer, edge).
pub fn streams(spec: &Spec) -> Vec<(ProcessId, ProcessId, &hir::Edge)> {
    let graph = &spec.graph.graph;
    graph
        .edge_indices()
        .filter_map(|e| {
            let (a, b) = graph.edge_endpoints(e)?;
            Some((graph[a], graph[b], &graph[e]))
        })
        .collect()
}

fn edge_label(edge: &hir::Edge) -> (String, String) {
    (edge.stream.clone(), edge.policy.describe_changes())
}

/// The column of each process: the longest chain of (non-feedback) streams leading to it. The
/// checker rules out cycles without a feedback stream; the sweep count bounds the work anyway.
fn columns(n: usize, edges: &[(ProcessId, ProcessId, &hir::Edge)]) -> Vec<usize> {
    let mut column = vec![0usize; n];
    for _ in 0..n {
        let mut changed = false;
        for &(from, to, edge) in edges {
            if !edge.policy.feedback && from != to && column[to] < column[from] + 1 && column[from] < n {
                column[to] = column[from] + 1;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    column
}

/// Columns by [`columns`]; a stream spanning several columns gets a lane (a virtual node) in each
/// column between; rows ordered by the mean row of what feeds them (a few sweeps); boxes sized
/// to their text; the gap after each column wide enough for the labels of the streams leaving it.
pub fn layout(spec: &Spec) -> Layout {
    let n = spec.processes.len();
    let edges = streams(spec);
    let column = columns(n, &edges);
    let forward = |k: usize| {
        let (from, to, edge) = edges[k];
        !edge.policy.feedback && column[to] > column[from]
    };
    // Items: processes 0..n, then one lane per stream and column it passes through.
    let mut item_column = column.clone();
    let mut chains: Vec<Vec<usize>> = Vec::with_capacity(edges.len());
    for (k, &(from, to, _)) in edges.iter().enumerate() {
        let mut chain = vec![from];
        if forward(k) {
            for c in column[from] + 1..column[to] {
                chain.push(item_column.len());
                item_column.push(c);
            }
        }
        chain.push(to);
        chains.push(chain);
    }
    let items = item_column.len();
    let mut feeds: Vec<Vec<usize>> = vec![Vec::new(); items];
    for (k, chain) in chains.iter().enumerate() {
        if forward(k) {
            for pair in chain.windows(2) {
                feeds[pair[1]].push(pair[0]);
            }
        }
    }
    let count = item_column.iter().max().map_or(0, |m| m + 1);
    let mut rows: Vec<Vec<usize>> = vec![Vec::new(); count];
    for (item, &c) in item_column.iter().enumerate() {
        rows[c].push(item);
    }
    for _ in 0..4 {
        let mut position = vec![0.0; items];
        for col in &rows {
            for (i, &item) in col.iter().enumerate() {
                position[item] = i as f64;
            }
        }
        for col in rows.iter_mut().skip(1) {
            let mut keyed: Vec<(f64, usize)> = col
                .iter()
                .map(|&item| {
                    let from = &feeds[item];
                    let key = if from.is_empty() {
                        position[item]
                    } else {
                        from.iter().map(|&f| position[f]).sum::<f64>() / from.len() as f64
                    };
                    (key, item)
                })
                .collect();
            keyed.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            *col = keyed.into_iter().map(|(_, item)| item).collect();
            for (i, &item) in col.iter().enumerate() {
                position[item] = i as f64;
            }
        }
    }
    let size = |item: usize| {
        if item >= n {
            return 0.0;
        }
        let p = &spec.processes[item];
        text_width(&p.name, FONT + 1.0).max(text_width(&detail(p), FONT - 1.0)) + 2.0 * NODE_PAD
    };
    let height = |item: usize| if item < n { NODE_HEIGHT } else { LANE_HEIGHT };
    let mut gaps = vec![MIN_COLUMN_GAP; count];
    for (k, &(from, _, edge)) in edges.iter().enumerate() {
        if forward(k) {
            let (name, policy) = edge_label(edge);
            let wanted = text_width(&name, FONT - 1.0).max(text_width(&policy, FONT - 2.0)) + 40.0;
            gaps[column[from]] = gaps[column[from]].max(wanted);
        }
    }
    let widths: Vec<f64> = rows.iter().map(|col| col.iter().map(|&i| size(i)).fold(0.0, f64::max)).collect();
    let column_height = |col: &[usize]| {
        col.iter().map(|&i| height(i)).sum::<f64>() + col.len().saturating_sub(1) as f64 * ROW_GAP
    };
    let inner_height = rows.iter().map(|c| column_height(c)).fold(0.0, f64::max);
    let mut boxes = vec![Placed { x: 0.0, y: 0.0, width: 0.0, height: NODE_HEIGHT }; n];
    let mut lane_at = vec![(0.0, 0.0, 0.0); items];
    let mut x = MARGIN;
    for (c, col) in rows.iter().enumerate() {
        let mut y = MARGIN + (inner_height - column_height(col)) / 2.0;
        for &item in col {
            if item < n {
                let width = size(item);
                boxes[item] = Placed { x: x + (widths[c] - width) / 2.0, y, width, height: NODE_HEIGHT };
            } else {
                lane_at[item] = (x, x + widths[c], y + LANE_HEIGHT / 2.0);
            }
            y += height(item) + ROW_GAP;
        }
        x += widths[c] + if c + 1 < count { gaps[c] } else { 0.0 };
    }
    let lanes = chains
        .iter()
        .map(|chain| chain[1..chain.len() - 1].iter().map(|&item| lane_at[item]).collect())
        .collect();
    let feedback_room = if edges.iter().any(|&(from, to, e)| e.policy.feedback || column[to] <= column[from])
    {
        70.0
    } else {
        0.0
    };
    let legend = 40.0;
    Layout {
        boxes,
        width: x + MARGIN,
        height: MARGIN * 2.0 + inner_height + feedback_room + legend,
        column,
        lanes,
    }
}

fn escape(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// Fill colour by kind of process.
fn fill(p: &hir::Process) -> &'static str {
    match p.kind {
        hir::ProcessKind::Source(_) => "#dbeafe",
        hir::ProcessKind::Compute(_) => "#ede9fe",
        hir::ProcessKind::Link(_) => "#dcfce7",
        hir::ProcessKind::Monitor(_) | hir::ProcessKind::Chronicle(_) => "#fef3c7",
        hir::ProcessKind::Sink(_) => "#f3f4f6",
    }
}

const HOST_COLOURS: [&str; 6] = ["#2563eb", "#dc2626", "#059669", "#d97706", "#7c3aed", "#db2777"];

/// The graph as an SVG document.
pub fn svg(spec: &Spec) -> String {
    let layout = layout(spec);
    let hosts: Vec<&str> =
        spec.deploy.as_ref().map(|d| d.hosts.iter().map(|h| h.name.as_str()).collect()).unwrap_or_default();
    let host_colour = |id: ProcessId| {
        spec.host_of(id)
            .and_then(|h| hosts.iter().position(|x| *x == h))
            .map(|i| HOST_COLOURS[i % HOST_COLOURS.len()])
    };
    let kinds = [
        ("source", "#dbeafe"),
        ("compute", "#ede9fe"),
        ("link", "#dcfce7"),
        ("monitor", "#fef3c7"),
        ("sink", "#f3f4f6"),
    ];
    let legend: Vec<(String, &str, bool)> = kinds
        .iter()
        .map(|(name, colour)| (name.to_string(), *colour, false))
        .chain(
            hosts
                .iter()
                .enumerate()
                .map(|(i, h)| (format!("host {h}"), HOST_COLOURS[i % HOST_COLOURS.len()], true)),
        )
        .collect();
    let legend_width: f64 = legend.iter().map(|(name, ..)| 28.0 + text_width(name, FONT - 1.0)).sum();
    let width = layout.width.max(legend_width + 2.0 * MARGIN);
    let mut out = String::new();
    let _ = writeln!(
        out,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w:.0}" height="{h:.0}" viewBox="0 0 {w:.0} {h:.0}" font-family="Helvetica, Arial, sans-serif" font-size="{FONT}">"#,
        w = width,
        h = layout.height
    );
    out.push_str(
        "<defs><marker id=\"arrow\" viewBox=\"0 0 10 10\" refX=\"10\" refY=\"5\" markerWidth=\"7\" markerHeight=\"7\" orient=\"auto-start-reverse\"><path d=\"M0,0 L10,5 L0,10 z\" fill=\"#374151\"/></marker></defs>\n",
    );
    let _ = writeln!(out, r##"<rect width="100%" height="100%" fill="#ffffff"/>"##);
    // Streams first, so that boxes and labels are drawn over them.
    let mut labels = String::new();
    let bottom = layout.boxes.iter().map(|b| b.y + b.height).fold(0.0, f64::max);
    let all = streams(spec);
    // Several streams between one pair of processes are spread apart: (index among them, count).
    let parallel = |k: usize| {
        let (from, to, _) = all[k];
        let same: Vec<usize> = (0..all.len()).filter(|&j| all[j].0 == from && all[j].1 == to).collect();
        let index = same.iter().position(|&j| j == k).unwrap_or(0);
        (index as f64 - (same.len() - 1) as f64 / 2.0, same.len())
    };
    // Label boxes placed so far: (centre x, centre y, width, height).
    let mut placed: Vec<(f64, f64, f64, f64)> = Vec::new();
    for (k, &(from, to, edge)) in all.iter().enumerate() {
        let (offset, _) = parallel(k);
        let (a, b) = (layout.boxes[from], layout.boxes[to]);
        let backwards = edge.policy.feedback || layout.column[to] <= layout.column[from];
        let (path, lx, ly) = if from == to {
            // A stream a process feeds back to itself: a loop under its box.
            let (cx, y) = (a.x + a.width / 2.0, a.y + a.height);
            let low = y + 36.0;
            (
                format!(
                    "M{:.1},{y:.1} C{:.1},{low:.1} {:.1},{low:.1} {:.1},{y:.1}",
                    cx + 18.0,
                    cx + 60.0,
                    cx - 60.0,
                    cx - 18.0
                ),
                cx,
                low + 6.0,
            )
        } else if backwards {
            // Down from the producer, along under every box, up into the consumer.
            let (x1, y1) = (a.x + a.width / 2.0, a.y + a.height);
            let (x2, y2) = (b.x + b.width / 2.0, b.y + b.height);
            let low = bottom + 30.0 + 12.0 * (k % 3) as f64;
            (
                format!("M{x1:.1},{y1:.1} C{x1:.1},{low:.1} {x2:.1},{low:.1} {x2:.1},{y2:.1}"),
                (x1 + x2) / 2.0,
                low - 4.0,
            )
        } else {
            let (x1, y1) = (a.x + a.width, a.y + a.height / 2.0 + offset * 8.0);
            let (x2, y2) = (b.x, b.y + b.height / 2.0 + offset * 8.0);
            // Curves between columns, straight through the lanes in between.
            let mut path = format!("M{x1:.1},{y1:.1}");
            let (mut px, mut py) = (x1, y1);
            let mut label = None;
            for &(left, right, y) in &layout.lanes[k] {
                let bend = (left - px) / 2.0;
                let _ = write!(
                    path,
                    " C{:.1},{py:.1} {:.1},{y:.1} {left:.1},{y:.1} L{right:.1},{y:.1}",
                    px + bend,
                    left - bend
                );
                label.get_or_insert(((px + left) / 2.0, (py + y) / 2.0));
                (px, py) = (right, y);
            }
            let bend = (x2 - px) / 2.0;
            let _ = write!(path, " C{:.1},{py:.1} {:.1},{y2:.1} {x2:.1},{y2:.1}", px + bend, x2 - bend);
            let (lx, ly) = label.unwrap_or(((px + x2) / 2.0, (py + y2) / 2.0));
            (path, lx, ly + offset * 8.0)
        };
        let dash = if edge.policy.feedback { r#" stroke-dasharray="6 4""# } else { "" };
        let _ = writeln!(
            out,
            r##"<path class="stream" data-from="{}" data-to="{}" d="{path}" fill="none" stroke="#374151" stroke-width="1.3"{dash} marker-end="url(#arrow)"/>"##,
            escape(&spec.processes[from].name),
            escape(&spec.processes[to].name)
        );
        let (name, policy) = edge_label(edge);
        let lines: Vec<(String, f64)> = std::iter::once((name, FONT - 1.0))
            .chain((!policy.is_empty()).then_some((policy, FONT - 2.0)))
            .collect();
        let w = lines.iter().map(|(t, s)| text_width(t, *s)).fold(0.0, f64::max) + 8.0;
        let h = lines.len() as f64 * FONT + 4.0;
        // Moved down past the labels already placed that it would cover.
        let mut ly = ly;
        for _ in 0..placed.len() {
            let covering = placed.iter().find(|(px, py, pw, ph): &&(f64, f64, f64, f64)| {
                (lx - px).abs() * 2.0 < w + pw && (ly - py).abs() * 2.0 < h + ph
            });
            match covering {
                Some(&(_, py, _, ph)) => ly = py + (ph + h) / 2.0 + 2.0,
                None => break,
            }
        }
        placed.push((lx, ly, w, h));
        let _ = writeln!(
            labels,
            r##"<rect x="{:.1}" y="{:.1}" width="{w:.1}" height="{h:.1}" rx="3" fill="#ffffff" fill-opacity="0.9"/>"##,
            lx - w / 2.0,
            ly - h / 2.0
        );
        for (i, (text, size)) in lines.iter().enumerate() {
            let weight = if i == 0 { r#" font-weight="bold""# } else { r##" fill="#4b5563""## };
            let _ = writeln!(
                labels,
                r#"<text x="{lx:.1}" y="{:.1}" font-size="{size}" text-anchor="middle"{weight}>{}</text>"#,
                ly - h / 2.0 + FONT * (i as f64 + 1.0) - 1.0,
                escape(text)
            );
        }
    }
    for p in &spec.processes {
        let b = layout.boxes[p.id];
        let (stroke, width) = host_colour(p.id).map_or(("#6b7280", 1.0), |c| (c, 2.5));
        let rx = match p.kind {
            hir::ProcessKind::Monitor(_) | hir::ProcessKind::Chronicle(_) | hir::ProcessKind::Link(_) => 14.0,
            _ => 4.0,
        };
        let _ = writeln!(
            out,
            r#"<g class="process" data-name="{}"><rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" rx="{rx}" fill="{}" stroke="{stroke}" stroke-width="{width}"/>"#,
            escape(&p.name),
            b.x,
            b.y,
            b.width,
            b.height,
            fill(p)
        );
        let cx = b.x + b.width / 2.0;
        let _ = writeln!(
            out,
            r#"<text x="{cx:.1}" y="{:.1}" font-size="{}" font-weight="bold" text-anchor="middle">{}</text>"#,
            b.y + 17.0,
            FONT + 1.0,
            escape(&p.name)
        );
        let _ = writeln!(
            out,
            r##"<text x="{cx:.1}" y="{:.1}" font-size="{}" fill="#374151" text-anchor="middle">{}</text></g>"##,
            b.y + 33.0,
            FONT - 1.0,
            escape(&detail(p))
        );
    }
    out.push_str(&labels);
    // Legend: kinds (fill), then hosts (outline).
    let mut x = MARGIN;
    let y = layout.height - MARGIN - 8.0;
    for (name, colour, host) in &legend {
        let (fill, stroke, stroke_width) =
            if *host { ("#ffffff", *colour, 2.5) } else { (*colour, "#6b7280", 1.0) };
        let _ = writeln!(
            out,
            r#"<rect x="{x:.1}" y="{:.1}" width="14" height="14" fill="{fill}" stroke="{stroke}" stroke-width="{stroke_width}"/><text x="{:.1}" y="{y:.1}" font-size="{}">{}</text>"#,
            y - 11.0,
            x + 18.0,
            FONT - 1.0,
            escape(name)
        );
        x += 28.0 + text_width(name, FONT - 1.0);
    }
    out.push_str("</svg>\n");
    out
}
