//! Georeferencing speed (docs/performance.md, "Georeferencing"): one frame of 1,000 boxes from a
//! UAV at 100 m looking 45° down, each box's centre taken to the ground with its covariance
//! (pixel noise and pose noise), against the baseline of the same 1,000 bare ground
//! intersections (no covariance) in the same run. A new pose every frame, so the per-pose work
//! (rotation and its derivatives) is counted each time.
//!
//! `cargo bench -p kpl-camera --bench camera`

#![allow(clippy::unwrap_used, reason = "a benchmark on fixed, valid inputs")]

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use kpl_camera::{Attitude, Camera, Distortion, Georeferencer, Gimbal, Intrinsics, Pose, PoseNoise};

const BOXES: usize = 1000;

fn setup() -> (Camera, Vec<[f64; 2]>, PoseNoise) {
    let k = Intrinsics::from_fov(1920.0, 1080.0, 70f64.to_radians()).unwrap();
    let lens = Distortion { k1: -0.12, k2: 0.03, ..Distortion::default() };
    let pose =
        Pose::new([0.0, 0.0, 100.0], Attitude::level(0.3), Gimbal { pan: 0.1, tilt: 45f64.to_radians() });
    let camera = Camera::new(k, lens, pose).unwrap();
    // Box centres spread over the lower two thirds of the image (below the horizon).
    let pixels = (0..BOXES)
        .map(|i| {
            let u = (i % 40) as f64 / 40.0 * 1900.0 + 10.0;
            let v = 400.0 + (i / 40) as f64 / 25.0 * 660.0;
            [u, v]
        })
        .collect();
    let noise = PoseNoise {
        position_sd: [2.0, 2.0, 3.0],
        attitude_sd: [0.5f64.to_radians(); 3],
        gimbal_sd: [0.2f64.to_radians(); 2],
        ground_sd: 0.5,
    };
    (camera, pixels, noise)
}

fn bench(c: &mut Criterion) {
    let (camera, pixels, noise) = setup();
    let mut group = c.benchmark_group("georeference");
    group.throughput(Throughput::Elements(BOXES as u64));
    group.bench_with_input(BenchmarkId::new("with_covariance", BOXES), &pixels, |b, pixels| {
        let mut yaw = 0.0;
        b.iter(|| {
            yaw += 1e-4;
            let mut pose = *camera.pose();
            pose.attitude.yaw = yaw;
            let frame_camera = camera.with_pose(pose).unwrap();
            let geo = Georeferencer::new(&frame_camera, noise, 0.0);
            let mut sum = 0.0;
            for p in pixels {
                if let Ok(e) = geo.ground(*p, 2.0) {
                    sum += e.pos[0] + e.cov[(0, 0)];
                }
            }
            sum
        })
    });
    group.bench_with_input(BenchmarkId::new("baseline_ground_point", BOXES), &pixels, |b, pixels| {
        let mut yaw = 0.0;
        b.iter(|| {
            yaw += 1e-4;
            let mut pose = *camera.pose();
            pose.attitude.yaw = yaw;
            let frame_camera = camera.with_pose(pose).unwrap();
            let mut sum = 0.0;
            for p in pixels {
                if let Ok(g) = frame_camera.ground_point(*p, 0.0) {
                    sum += g[0];
                }
            }
            sum
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
