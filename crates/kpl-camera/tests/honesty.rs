//! Is the propagated uncertainty honest? Monte Carlo against the first-order propagation, for
//! the case: a UAV at 100 m, 2 px of pixel noise and 0.5° of attitude noise (roll,
//! pitch and yaw each), a 1920 x 1080 camera with a 70° field of view looking straight down and
//! 45° down. For each percept (a pixel on an 8 x 6 grid over the image, the ground point under
//! it as the truth), 10,000 draws: the image shows the truth at its pixel plus pixel noise, the
//! pose reported is the true pose plus attitude noise, and the estimate and its covariance are
//! computed from what is reported. Per percept:
//!
//! - the median ground error against the median the covariance predicts (within 20 %);
//! - the 95th percentile of the Mahalanobis distance against the 2-sigma ellipse: the ellipse
//!   that holds 95.45 % of a 2-D Gaussian (the probability of ±2σ in one dimension; Mahalanobis
//!   radius √(-2 ln 0.0455) = 2.486). (The ellipse of Mahalanobis radius 2 holds only 86.5 %, so
//!   an honest uncertainty's 95th percentile is outside it; both are printed.)
//!
//! `cargo test -p kpl-camera --test honesty -- --nocapture` prints the figures docs/camera.md
//! and docs/anchoring.md report.

#![allow(clippy::unwrap_used, reason = "tests")]

use kpl_camera::{
    Attitude, Camera, Distortion, Georeferencer, Gimbal, GroundEstimate, Intrinsics, Pose, PoseNoise,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const DRAWS: usize = 10_000;
const PIXEL_SD: f64 = 2.0;
const ATTITUDE_SD_DEG: f64 = 0.5;

/// The radius of the ellipse that holds 95.45 % of a 2-D Gaussian.
fn two_sigma_radius() -> f64 {
    (-2.0 * (1.0 - 0.954_499_736_103_641_6f64).ln()).sqrt()
}

struct PerceptResult {
    median_ratio: f64,
    p95_mahalanobis: f64,
    inside_two_sigma: f64,
}

fn quantile(values: &mut [f64], q: f64) -> f64 {
    values.sort_by(f64::total_cmp);
    values[((values.len() - 1) as f64 * q).round() as usize]
}

fn evaluate(tilt_deg: f64, seed: u64) -> Vec<PerceptResult> {
    let k = Intrinsics::from_fov(1920.0, 1080.0, 70f64.to_radians()).unwrap();
    let truth =
        Pose::new([0.0, 0.0, 100.0], Attitude::level(0.3), Gimbal { pan: 0.0, tilt: tilt_deg.to_radians() });
    let camera = Camera::new(k, Distortion::default(), truth).unwrap();
    let sd = ATTITUDE_SD_DEG.to_radians();
    let noise = PoseNoise { attitude_sd: [sd; 3], ..PoseNoise::default() };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let pixel_noise = Normal::new(0.0, PIXEL_SD).unwrap();
    let angle_noise = Normal::new(0.0, sd).unwrap();
    let mut results = Vec::new();
    for row in 0..6 {
        for col in 0..8 {
            let pixel = [(col as f64 + 0.5) * 1920.0 / 8.0, (row as f64 + 0.5) * 1080.0 / 6.0];
            let Ok(g0) = camera.ground_point(pixel, 0.0) else { continue };
            let nominal: GroundEstimate =
                Georeferencer::new(&camera, noise, 0.0).ground(pixel, PIXEL_SD).unwrap();
            let mut errors = Vec::with_capacity(DRAWS);
            let mut mahalanobis = Vec::with_capacity(DRAWS);
            for _ in 0..DRAWS {
                let mut reported = truth;
                reported.attitude.roll += angle_noise.sample(&mut rng);
                reported.attitude.pitch += angle_noise.sample(&mut rng);
                reported.attitude.yaw += angle_noise.sample(&mut rng);
                let seen = [pixel[0] + pixel_noise.sample(&mut rng), pixel[1] + pixel_noise.sample(&mut rng)];
                let reported_camera = camera.with_pose(reported).unwrap();
                let Ok(estimate) = Georeferencer::new(&reported_camera, noise, 0.0).ground(seen, PIXEL_SD)
                else {
                    continue;
                };
                errors.push((estimate.pos[0] - g0[0]).hypot(estimate.pos[1] - g0[1]));
                mahalanobis.push(estimate.mahalanobis2(g0).unwrap().sqrt());
            }
            let inside = mahalanobis.iter().filter(|d| **d <= two_sigma_radius()).count() as f64
                / mahalanobis.len() as f64;
            results.push(PerceptResult {
                median_ratio: quantile(&mut errors, 0.5) / nominal.error_quantile(0.5),
                p95_mahalanobis: quantile(&mut mahalanobis, 0.95),
                inside_two_sigma: inside,
            });
        }
    }
    results
}

#[test]
fn the_propagated_uncertainty_is_honest_from_100_m() {
    for (tilt, seed) in [(90.0, 1), (45.0, 2)] {
        let results = evaluate(tilt, seed);
        assert!(results.len() >= 40, "most of the grid sees the ground: {}", results.len());
        let n = results.len() as f64;
        let within_20 = results.iter().filter(|r| (0.8..=1.2).contains(&r.median_ratio)).count() as f64 / n;
        let p95_inside =
            results.iter().filter(|r| r.p95_mahalanobis <= two_sigma_radius()).count() as f64 / n;
        let p95_inside_radius_2 = results.iter().filter(|r| r.p95_mahalanobis <= 2.0).count() as f64 / n;
        let ratios: Vec<f64> = results.iter().map(|r| r.median_ratio).collect();
        let (lo, hi) = ratios.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), r| (lo.min(*r), hi.max(*r)));
        let mean_inside = results.iter().map(|r| r.inside_two_sigma).sum::<f64>() / n;
        println!(
            "tilt {tilt}°: {} percepts; median error / predicted median {lo:.3}-{hi:.3} ({:.0} % within 20 %); \
             95th percentile inside the 2-sigma ellipse (95.45 %) for {:.0} % of percepts (inside Mahalanobis 2: {:.0} %); \
             {:.1} % of all draws inside the 2-sigma ellipse",
            results.len(),
            within_20 * 100.0,
            p95_inside * 100.0,
            p95_inside_radius_2 * 100.0,
            mean_inside * 100.0
        );
        assert_eq!(within_20, 1.0, "every percept's median error within 20 % of the prediction: {ratios:?}");
        assert!(p95_inside >= 0.9, "95th percentile inside the 2-sigma ellipse for {p95_inside}");
    }
}
