//! A second simulated detector, written apart from [`crate::detector`] and unlike it in every kind
//! of error, so that AAPA is not tuned to one model of noise:
//!
//! - **detection** falls with the visible fraction along a logistic curve (half at 30 % visible),
//!   and misses come in bursts: each object's detector state is a two-state Markov chain (a good
//!   state, and a bad one entered with probability 1 % per frame and left with 30 %, in which
//!   the detection probability is a fifth);
//! - **box edges** err by 0.6 px plus 3 % of the box's size (standard deviation), correlated from
//!   frame to frame (each edge's error is an AR(1) process with coefficient 0.6), with a heavy tail
//!   (2 % of edges err four times as much) and a bias that grows boxes by 1 % of their size;
//! - **classes**: 2 % of detections get one wrong attribute, and the wrong class sticks to that
//!   object for 1 to 4 frames; the snitch is taken for a small yellow metal sphere in 4 % of its
//!   detections; 0.3 % of detections come out unclassified (OPNet's pickles get label `-1`, this
//!   project's JSON the class `unknown`);
//! - **duplicates**: 1 % of detections are reported twice (a failed non-maximum suppression), the
//!   second box shifted by a few pixels;
//! - **false positives**: 6 % of frames start one, near a real object (overlapping it, a part of
//!   it taken for an object) of a class that is a real object's with one attribute changed (one in
//!   ten of them the snitch's own class), lasting 1 to 4 frames and drifting.
//!
//! Like the other detector it reports whole (amodal) boxes: LA-CATER's detector was trained on
//! the whole boxes of `<video>_bb.json`.

use rand::Rng;
use rand::seq::IndexedRandom;
use rand_chacha::ChaCha8Rng;

use crate::classes::{COLORS, MATERIALS, SIZES, SNITCH_CLASS};
use crate::formats::{Detection, HEIGHT, WIDTH};
use crate::render::Rendered;

/// The class name unclassified detections get in this project's JSON.
pub const UNKNOWN_CLASS: &str = "unknown";
/// What the snitch is taken for.
pub const SNITCH_LOOKALIKE: &str = "small_yellow_sphere_metal";

/// The second detector's error rates (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectorBNoise {
    pub detect_probability: f64,
    /// Visible fraction at which the detection probability is half, and the logistic's width.
    pub half_visible: f64,
    pub visible_width: f64,
    /// Bursts of misses: entering and leaving the bad state per frame, and the detection
    /// probability's factor in it.
    pub burst_enter: f64,
    pub burst_leave: f64,
    pub burst_factor: f64,
    pub edge_sigma_px: f64,
    pub edge_sigma_relative: f64,
    /// AR(1) coefficient of each edge's error.
    pub edge_correlation: f64,
    pub outlier_probability: f64,
    pub outlier_scale: f64,
    /// Boxes grow by this share of their size on average.
    pub size_bias: f64,
    pub confusion_probability: f64,
    pub snitch_as_sphere: f64,
    pub unclassified: f64,
    pub duplicate_probability: f64,
    pub ghost_rate: f64,
}

impl Default for DetectorBNoise {
    fn default() -> DetectorBNoise {
        DetectorBNoise {
            detect_probability: 0.99,
            half_visible: 0.3,
            visible_width: 0.06,
            burst_enter: 0.01,
            burst_leave: 0.3,
            burst_factor: 0.2,
            edge_sigma_px: 0.6,
            edge_sigma_relative: 0.03,
            edge_correlation: 0.6,
            outlier_probability: 0.02,
            outlier_scale: 4.0,
            size_bias: 0.01,
            confusion_probability: 0.02,
            snitch_as_sphere: 0.04,
            unclassified: 0.003,
            duplicate_probability: 0.01,
            ghost_rate: 0.06,
        }
    }
}

/// What the detector remembers of one object.
#[derive(Debug, Clone, Default)]
struct Track {
    bad: bool,
    /// Each edge's correlated error, in units of its standard deviation.
    edge: [f64; 4],
    /// A wrong class that sticks, and for how many more frames.
    confused: Option<(u32, usize)>,
}

#[derive(Debug, Clone)]
struct Ghost {
    class: u32,
    bbox: [f64; 4],
    frames_left: usize,
}

fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    // Marsaglia's polar method (the other detector uses Box-Muller).
    loop {
        let u: f64 = rng.random_range(-1.0..1.0);
        let v: f64 = rng.random_range(-1.0..1.0);
        let s = u * u + v * v;
        if s > 0.0 && s < 1.0 {
            return u * (-2.0 * s.ln() / s).sqrt();
        }
    }
}

/// A class with one attribute changed (size, colour or material; shapes stay, but for the snitch).
fn other_class(rng: &mut ChaCha8Rng, class: &str) -> String {
    let parts: Vec<&str> = class.split('_').collect();
    let [size, color, shape, material] = parts[..] else { return class.to_owned() };
    if shape == "spl" {
        return SNITCH_LOOKALIKE.to_owned();
    }
    let pick = |rng: &mut ChaCha8Rng, options: &[&'static str], current: &str| -> String {
        let others: Vec<&&str> = options.iter().filter(|o| **o != current).collect();
        others.choose(rng).map_or(current.to_owned(), |o| (**o).to_owned())
    };
    let sizes: Vec<&'static str> = SIZES.iter().map(|s| s.0).collect();
    match rng.random_range(0..3) {
        0 => format!("{}_{color}_{shape}_{material}", pick(rng, &sizes, size)),
        1 => format!("{size}_{}_{shape}_{material}", pick(rng, &COLORS, color)),
        _ => format!("{size}_{color}_{shape}_{}", pick(rng, &MATERIALS, material)),
    }
}

/// Runs the second detector over a video: `classes` is the class list the detections index and
/// `object_class` each object's index in it; classes it makes up are appended.
pub fn detect_video_b(
    rng: &mut ChaCha8Rng,
    frames: &[Vec<Rendered>],
    classes: &mut Vec<String>,
    object_class: &[u32],
    noise: &DetectorBNoise,
) -> Vec<Vec<Detection>> {
    let index_of = |classes: &mut Vec<String>, name: &str| -> u32 {
        let i = classes.iter().position(|c| c == name).unwrap_or_else(|| {
            classes.push(name.to_owned());
            classes.len() - 1
        });
        i as u32
    };
    let mut tracks = vec![Track::default(); object_class.len()];
    let mut ghosts: Vec<Ghost> = Vec::new();
    let rho = noise.edge_correlation.clamp(0.0, 0.99);
    let innovation = (1.0 - rho * rho).sqrt();
    let mut out = Vec::with_capacity(frames.len());
    for frame in frames {
        let mut detections = Vec::new();
        for (i, r) in frame.iter().enumerate() {
            let track = &mut tracks[i];
            // The state moves every frame, seen or not.
            track.bad = if track.bad {
                !rng.random_bool(noise.burst_leave)
            } else {
                rng.random_bool(noise.burst_enter)
            };
            for e in &mut track.edge {
                *e = rho * *e + innovation * gaussian(rng);
            }
            let Some(whole) = r.bbox else { continue };
            let logistic =
                1.0 / (1.0 + (-(r.visible_fraction - noise.half_visible) / noise.visible_width).exp());
            let mut p = noise.detect_probability * logistic;
            if track.bad {
                p *= noise.burst_factor;
            }
            if r.visible_fraction <= 0.0 || !rng.random_bool(p.clamp(0.0, 1.0)) {
                continue;
            }
            let (w, h) = (whole.width(), whole.height());
            let sigma = [w, h, w, h].map(|s| noise.edge_sigma_px + noise.edge_sigma_relative * s);
            let bias = [-w, -h, w, h].map(|s| s * noise.size_bias / 2.0);
            let base = [whole.x1, whole.y1, whole.x2, whole.y2];
            let bbox = tidy(std::array::from_fn(|k| {
                let tail = if rng.random_bool(noise.outlier_probability) { noise.outlier_scale } else { 1.0 };
                base[k] + bias[k] + sigma[k] * tail * track.edge[k]
            }));
            let own = object_class[i];
            let own_name = classes[own as usize].clone();
            let class = if let Some((c, left)) = track.confused.as_mut() {
                let c = *c;
                *left -= 1;
                if *left == 0 {
                    track.confused = None;
                }
                c
            } else if own_name == SNITCH_CLASS && rng.random_bool(noise.snitch_as_sphere) {
                index_of(classes, SNITCH_LOOKALIKE)
            } else if rng.random_bool(noise.confusion_probability) {
                let c = index_of(classes, &other_class(rng, &own_name));
                let frames = rng.random_range(1..=4);
                if frames > 1 {
                    track.confused = Some((c, frames - 1));
                }
                c
            } else {
                own
            };
            let class =
                if rng.random_bool(noise.unclassified) { index_of(classes, UNKNOWN_CLASS) } else { class };
            detections.push(Detection { class, bbox });
            if rng.random_bool(noise.duplicate_probability) {
                let shift = [gaussian(rng) * 3.0, gaussian(rng) * 3.0];
                let b = bbox;
                detections.push(Detection {
                    class,
                    bbox: tidy([b[0] + shift[0], b[1] + shift[1], b[2] + shift[0], b[3] + shift[1]]),
                });
            }
        }
        let real: Vec<(usize, &Rendered)> =
            frame.iter().enumerate().filter(|(_, r)| r.bbox.is_some()).collect();
        if rng.random_bool(noise.ghost_rate.clamp(0.0, 1.0))
            && let Some(&(i, near)) = real.choose(rng)
            && let Some(b) = near.bbox
        {
            let name = if rng.random_bool(0.1) {
                SNITCH_CLASS.to_owned()
            } else {
                other_class(rng, &classes[object_class[i] as usize].clone())
            };
            let class = index_of(classes, &name);
            let (w, h) = (b.width() * rng.random_range(0.3..0.9), b.height() * rng.random_range(0.3..0.9));
            let (cx, cy) = (rng.random_range(b.x1..=b.x2), rng.random_range(b.y1..=b.y2));
            let bbox = tidy([cx - w / 2.0, cy - h / 2.0, cx + w / 2.0, cy + h / 2.0]);
            ghosts.push(Ghost { class, bbox, frames_left: rng.random_range(1..=4) });
        }
        for ghost in &mut ghosts {
            let d = [gaussian(rng) * 1.5, gaussian(rng) * 1.5];
            let b = ghost.bbox;
            ghost.bbox = tidy([b[0] + d[0], b[1] + d[1], b[2] + d[0], b[3] + d[1]]);
            detections.push(Detection { class: ghost.class, bbox: ghost.bbox });
            ghost.frames_left -= 1;
        }
        ghosts.retain(|g| g.frames_left > 0);
        out.push(detections);
    }
    out
}

/// Orders the corners, clips to the image and rounds to whole pixels, as LA-CATER's pickles hold
/// boxes. (OPNet's detector script truncates, `astype(np.int)`, which moves every box up and left
/// by half a pixel on average: a bias no model can average away, costing some five points of IoU
/// on the snitch's small box. This detector's errors are meant to be noise, so it rounds.)
fn tidy(b: [f64; 4]) -> [f64; 4] {
    let (x1, x2) = (b[0].min(b[2]).clamp(0.0, WIDTH), b[0].max(b[2]).clamp(0.0, WIDTH));
    let (y1, y2) = (b[1].min(b[3]).clamp(0.0, HEIGHT), b[1].max(b[3]).clamp(0.0, HEIGHT));
    [x1, y1, x2, y2].map(f64::round)
}
