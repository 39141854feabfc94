//! The two perception modes a generated video is written with: perfect perception (the ground-truth
//! boxes of the objects that can be seen) and a simulated detector standing in for the paper's
//! Faster R-CNN. LA-CATER's detector was fine-tuned on the whole boxes of `<video>_bb.json`, so it
//! reports whole (amodal) boxes; this one does too, with edge errors that grow as more of the object
//! is hidden, misses that grow likewise, class confusions and short-lived false positives.
//!
//! The edge error is calibrated against the paper's detector row: with [`DetectorNoise::default`]
//! the OPNet heuristic, which outputs the snitch's detection whenever there is one, scores about the
//! paper's 88 % mean IoU on visible frames (docs/cater.md gives the measurement and the command).

use rand::Rng;
use rand::seq::IndexedRandom;
use rand_chacha::ChaCha8Rng;

use crate::classes::{COLORS, MATERIALS, SIZES};
use crate::formats::{Detection, HEIGHT, WIDTH};
use crate::render::{Rendered, VISIBLE_FRACTION};

/// The simulated detector's error rates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectorNoise {
    /// Detection probability of a fully visible object.
    pub detect_probability: f64,
    /// Visible fraction from which an object is detected at full probability (linear below, down
    /// to zero at [`VISIBLE_FRACTION`]).
    pub full_visibility: f64,
    /// Standard deviation of each box edge of a fully visible object: this many pixels plus
    /// `edge_sigma_relative` of the box's size.
    pub edge_sigma_px: f64,
    pub edge_sigma_relative: f64,
    /// How much the edge error grows for a hidden object: the sigma is multiplied by
    /// `1 + hidden_sigma_gain * hidden_fraction`.
    pub hidden_sigma_gain: f64,
    /// Probability that a detection's class is wrong in one attribute.
    pub confusion_probability: f64,
    /// Expected false positives starting per frame; each lasts 1 to 3 frames.
    pub ghost_rate: f64,
}

impl Default for DetectorNoise {
    fn default() -> DetectorNoise {
        DetectorNoise {
            detect_probability: 0.995,
            full_visibility: 0.25,
            edge_sigma_px: 0.3,
            edge_sigma_relative: 0.011,
            hidden_sigma_gain: 1.0,
            confusion_probability: 0.01,
            ghost_rate: 0.05,
        }
    }
}

/// Perfect perception of one frame: the ground-truth boxes (`[x, y, w, h]` -> `[x1, y1, x2, y2]`)
/// of the objects with at least [`VISIBLE_FRACTION`] of their silhouette seen.
pub fn perfect(frame: &[Rendered], object_class: &[u32]) -> Vec<Detection> {
    frame
        .iter()
        .enumerate()
        .filter(|(_, r)| r.visible_fraction >= VISIBLE_FRACTION)
        .map(|(i, r)| {
            let [x, y, w, h] = r.ground_truth;
            Detection {
                class: object_class[i],
                bbox: [f64::from(x), f64::from(y), f64::from(x + w), f64::from(y + h)],
            }
        })
        .collect()
}

fn normal(rng: &mut ChaCha8Rng) -> f64 {
    // Box-Muller.
    let u1: f64 = rng.random_range(f64::EPSILON..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A class that differs from `class` (`size_color_shape_material`) in one attribute.
fn confuse(rng: &mut ChaCha8Rng, class: &str) -> String {
    let parts: Vec<&str> = class.split('_').collect();
    let [size, color, shape, material] = parts[..] else { return class.to_owned() };
    let mut out = [size, color, shape, material];
    match rng.random_range(0..4) {
        0 => out[0] = SIZES.choose(rng).map_or(size, |s| s.0),
        1 => out[1] = COLORS.choose(rng).copied().unwrap_or(color),
        2 => out[3] = MATERIALS.choose(rng).copied().unwrap_or(material),
        _ => {
            out[2] = match shape {
                "sphere" => "spl",
                "spl" => "sphere",
                "cube" => "cylinder",
                "cylinder" => "cube",
                other => other,
            }
        }
    }
    out.join("_")
}

#[derive(Debug, Clone)]
struct Ghost {
    class: u32,
    bbox: [f64; 4],
    frames_left: usize,
}

/// Runs the simulated detector over a video. `classes` is the class list the detections index and
/// `object_class` each object's index in it (identical objects share one); classes produced by
/// confusions are appended to it.
pub fn detect_video(
    rng: &mut ChaCha8Rng,
    frames: &[Vec<Rendered>],
    classes: &mut Vec<String>,
    object_class: &[u32],
    noise: &DetectorNoise,
) -> Vec<Vec<Detection>> {
    let object_count = object_class.len();
    let class_index = |classes: &mut Vec<String>, name: String| -> u32 {
        match classes.iter().position(|c| *c == name) {
            Some(i) => i as u32,
            None => {
                classes.push(name);
                (classes.len() - 1) as u32
            }
        }
    };
    let mut ghosts: Vec<Ghost> = Vec::new();
    let mut out = Vec::with_capacity(frames.len());
    for frame in frames {
        let mut detections = Vec::new();
        for (i, r) in frame.iter().enumerate() {
            let Some(whole) = r.bbox else { continue };
            let ramp = ((r.visible_fraction - VISIBLE_FRACTION) / (noise.full_visibility - VISIBLE_FRACTION))
                .clamp(0.0, 1.0);
            if r.visible_fraction < VISIBLE_FRACTION
                || !rng.random_bool((noise.detect_probability * ramp).clamp(0.0, 1.0))
            {
                continue;
            }
            let gain = 1.0 + noise.hidden_sigma_gain * (1.0 - r.visible_fraction);
            let sigma_x = (noise.edge_sigma_px + noise.edge_sigma_relative * whole.width()) * gain;
            let sigma_y = (noise.edge_sigma_px + noise.edge_sigma_relative * whole.height()) * gain;
            let b = tidy([
                whole.x1 + sigma_x * normal(rng),
                whole.y1 + sigma_y * normal(rng),
                whole.x2 + sigma_x * normal(rng),
                whole.y2 + sigma_y * normal(rng),
            ]);
            let class = if rng.random_bool(noise.confusion_probability) {
                let confused = confuse(rng, &classes[object_class[i] as usize]);
                class_index(classes, confused)
            } else {
                object_class[i]
            };
            detections.push(Detection { class, bbox: b });
        }
        if rng.random_bool(noise.ghost_rate.clamp(0.0, 1.0)) && object_count > 0 {
            let base = rng.random_range(0..object_count);
            let class = class_index(classes, confuse(rng, &classes[object_class[base] as usize].clone()));
            let (w, h) = (rng.random_range(12.0..60.0), rng.random_range(12.0..60.0));
            let (x, y) = (rng.random_range(0.0..WIDTH - w), rng.random_range(0.0..HEIGHT - h));
            ghosts.push(Ghost { class, bbox: [x, y, x + w, y + h], frames_left: rng.random_range(1..=3) });
        }
        for ghost in &mut ghosts {
            let drift = [normal(rng), normal(rng)];
            let b = ghost.bbox;
            ghost.bbox = tidy([b[0] + drift[0], b[1] + drift[1], b[2] + drift[0], b[3] + drift[1]]);
            detections.push(Detection { class: ghost.class, bbox: ghost.bbox });
            ghost.frames_left -= 1;
        }
        ghosts.retain(|g| g.frames_left > 0);
        out.push(detections);
    }
    out
}

/// Clips to the image, orders the corners and rounds to a tenth of a pixel.
fn tidy(b: [f64; 4]) -> [f64; 4] {
    let (x1, x2) = (b[0].min(b[2]).clamp(0.0, WIDTH), b[0].max(b[2]).clamp(0.0, WIDTH));
    let (y1, y2) = (b[1].min(b[3]).clamp(0.0, HEIGHT), b[1].max(b[3]).clamp(0.0, HEIGHT));
    [x1, y1, x2, y2].map(|v| (v * 10.0).round() / 10.0)
}
