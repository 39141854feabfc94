//! Generated tracking results for the differential and property tests: true trajectories that
//! cross, and hypotheses with noise (some beyond the gate), misses, gaps (fragmentations), new
//! ids, swapped ids (identity switches) and false positives, some lasting several frames.
#![allow(dead_code)]

use kpl_score::{Pos, Sequence};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// One frame: the true objects and the hypotheses, `(id, position)`.
pub type Objects = Vec<(String, Pos)>;

#[derive(Debug, Clone)]
pub struct Case {
    pub frames: Vec<(Objects, Objects)>,
    pub max_distance: f64,
}

impl Case {
    pub fn sequence(&self) -> Sequence {
        let mut s = Sequence::new();
        for (k, (truth, hyps)) in self.frames.iter().enumerate() {
            s.push_frame(
                k as i64 * 100_000,
                truth.iter().map(|(id, p)| (id.as_str(), *p)),
                hyps.iter().map(|(id, p)| (id.as_str(), *p)),
            )
            .unwrap();
        }
        s
    }
}

fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u: f64 = rng.random_range(f64::EPSILON..1.0);
    let v: f64 = rng.random();
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

struct Truth {
    start: usize,
    end: usize,
    pos: Pos,
    vel: Pos,
    wobble: f64,
    hypothesis: usize,
    gap: usize,
}

/// A random case from `seed`.
pub fn case(seed: u64) -> Case {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let max_distance = [1.0, 2.0, 3.0][rng.random_range(0..3)];
    let frames = rng.random_range(5..50);
    let area = rng.random_range(6.0..40.0);
    let p_miss = rng.random_range(0.0..0.3);
    let sigma = max_distance * rng.random_range(0.05..0.7);
    let p_new_id = rng.random_range(0.0..0.06);
    let p_swap = rng.random_range(0.0..0.08);
    let p_gap = rng.random_range(0.0..0.06);
    let fp_rate = rng.random_range(0.0..1.5);
    let mut next_hypothesis = 1;
    let mut truths: Vec<Truth> = (0..rng.random_range(0..9))
        .map(|_| {
            let start = rng.random_range(0..frames);
            let end = (start + rng.random_range(1..=frames)).min(frames);
            let speed = rng.random_range(0.0..1.5);
            let angle = rng.random_range(0.0..std::f64::consts::TAU);
            next_hypothesis += 1;
            Truth {
                start,
                end,
                pos: [rng.random_range(0.0..area), rng.random_range(0.0..area)],
                vel: [speed * angle.cos(), speed * angle.sin()],
                wobble: rng.random_range(0.0..0.5),
                hypothesis: next_hypothesis - 1,
                gap: 0,
            }
        })
        .collect();
    // False positives that stay for a while: (id, position, frames left).
    let mut ghosts: Vec<(usize, Pos, usize)> = Vec::new();
    let mut out = Vec::new();
    for f in 0..frames {
        let mut truth = Vec::new();
        let mut hyps = Vec::new();
        let alive: Vec<usize> =
            (0..truths.len()).filter(|&k| truths[k].start <= f && f < truths[k].end).collect();
        if alive.len() >= 2 && rng.random_bool(p_swap) {
            let a = alive[rng.random_range(0..alive.len())];
            let b = alive[rng.random_range(0..alive.len())];
            let (ha, hb) = (truths[a].hypothesis, truths[b].hypothesis);
            truths[a].hypothesis = hb;
            truths[b].hypothesis = ha;
        }
        for &k in &alive {
            let t = &mut truths[k];
            let dt = (f - t.start) as f64;
            let pos = [
                t.pos[0] + t.vel[0] * dt + t.wobble * (dt * 0.7).sin(),
                t.pos[1] + t.vel[1] * dt + t.wobble * (dt * 0.5).cos(),
            ];
            truth.push((format!("t{k}"), pos));
            if t.gap > 0 {
                t.gap -= 1;
                continue;
            }
            if rng.random_bool(p_gap) {
                t.gap = rng.random_range(1..6);
                continue;
            }
            if rng.random_bool(p_miss) {
                continue;
            }
            if rng.random_bool(p_new_id) {
                t.hypothesis = next_hypothesis;
                next_hypothesis += 1;
            }
            hyps.push((
                format!("h{}", t.hypothesis),
                [pos[0] + sigma * normal(&mut rng), pos[1] + sigma * normal(&mut rng)],
            ));
        }
        let new_ghosts = (fp_rate * rng.random::<f64>() * 2.0).floor() as usize;
        for _ in 0..new_ghosts {
            ghosts.push((
                next_hypothesis,
                [rng.random_range(0.0..area), rng.random_range(0.0..area)],
                rng.random_range(1..8),
            ));
            next_hypothesis += 1;
        }
        for g in &mut ghosts {
            hyps.push((
                format!("h{}", g.0),
                [g.1[0] + 0.2 * normal(&mut rng), g.1[1] + 0.2 * normal(&mut rng)],
            ));
            g.2 -= 1;
        }
        ghosts.retain(|g| g.2 > 0);
        hyps.shuffle(&mut rng);
        out.push((truth, hyps));
    }
    Case { frames: out, max_distance }
}
