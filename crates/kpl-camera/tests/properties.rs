//! Property tests of the camera geometry: a ground point projected into the image and back to
//! the ground is the same point within 1e-9 m, and a pixel taken to the ground and projected
//! back is the same pixel within 1e-9 px, for random cameras (intrinsics, lens distortion, UAV
//! position and attitude, gimbal) and points; a homography estimated from a camera's own pairs
//! maps every other point as the camera does.

#![allow(clippy::unwrap_used, reason = "tests")]

use kpl_camera::{Attitude, Camera, Distortion, Gimbal, Homography, Intrinsics, Pose};
use proptest::prelude::*;

fn camera() -> impl Strategy<Value = Camera> {
    (
        (320.0..4000.0f64, 0.7..1.4f64, 30.0..110.0f64),
        (-0.3..0.1f64, -0.05..0.05f64, -0.002..0.002f64, -0.002..0.002f64),
        (-500.0..500.0f64, -500.0..500.0f64, 5.0..400.0f64),
        (-0.15..0.15f64, -0.15..0.15f64, -3.2..3.2f64),
        (-1.0..1.0f64, 0.35..std::f64::consts::FRAC_PI_2),
    )
        .prop_map(
            |((width, aspect, hfov), (k1, k2, p1, p2), (x, y, z), (roll, pitch, yaw), (pan, tilt))| {
                let height = (width * aspect * 0.75).round();
                let k = Intrinsics::from_fov(width, height, hfov.to_radians()).unwrap();
                let lens = Distortion { k1, k2, p1, p2, k3: 0.0 };
                let pose = Pose::new([x, y, z], Attitude { roll, pitch, yaw }, Gimbal { pan, tilt });
                Camera::new(k, lens, pose).unwrap()
            },
        )
}

/// Whether a pixel's ray meets the ground steeply enough (at least 5° below the horizon) and
/// near enough for the 1e-9 round trip to be a fair demand of double precision.
fn well_conditioned(camera: &Camera, pixel: [f64; 2]) -> bool {
    let Ok(d) = camera.ray(pixel) else { return false };
    let horizontal = d[0].hypot(d[1]);
    let steep = -d[2] > horizontal * 5f64.to_radians().tan();
    let near = camera.ground_point(pixel, 0.0).is_ok_and(|g| {
        let c = camera.pose().position;
        (g[0] - c[0]).hypot(g[1] - c[1]) < 5000.0
    });
    // Where the lens is one-to-one: the distortion's Jacobian keeps its orientation.
    let k = camera.intrinsics();
    let lens_ok = camera
        .normalized(pixel)
        .is_ok_and(|n| camera.distortion().jacobian(n).determinant() > 0.2 && k.contains(pixel));
    steep && near && lens_ok
}

proptest! {
    // Random poses and pixels: many draws are refused as ill-conditioned (grazing views, pixels
    // too close together), so the budget of refusals is generous.
    #![proptest_config(ProptestConfig { cases: 2000, max_global_rejects: 50_000, ..ProptestConfig::default() })]

    #[test]
    fn pixel_to_ground_and_back(camera in camera(), u in 0.0..1.0f64, v in 0.0..1.0f64) {
        let k = *camera.intrinsics();
        let pixel = [u * k.width, v * k.height];
        prop_assume!(well_conditioned(&camera, pixel));
        let g = camera.ground_point(pixel, 0.0).unwrap();
        let back = camera.pixel_of([g[0], g[1], 0.0]).unwrap();
        prop_assert!((back[0] - pixel[0]).abs() < 1e-9 && (back[1] - pixel[1]).abs() < 1e-9, "{pixel:?} -> {g:?} -> {back:?}");
    }

    #[test]
    fn ground_to_pixel_and_back(camera in camera(), u in 0.0..1.0f64, v in 0.0..1.0f64, ground_z in -20.0..3.0f64) {
        // A ground point the camera sees: the point under a random pixel.
        let k = *camera.intrinsics();
        let pixel = [u * k.width, v * k.height];
        prop_assume!(well_conditioned(&camera, pixel));
        let Ok(g) = camera.ground_point(pixel, ground_z) else { return Ok(()) };
        let p = camera.pixel_of([g[0], g[1], ground_z]).unwrap();
        let back = camera.ground_point(p, ground_z).unwrap();
        prop_assert!((back[0] - g[0]).abs() < 1e-9 && (back[1] - g[1]).abs() < 1e-9, "{g:?} -> {p:?} -> {back:?}");
    }

    #[test]
    fn the_footprint_holds_what_the_camera_sees(camera in camera(), u in 0.05..0.95f64, v in 0.05..0.95f64) {
        // Without distortion the footprint's edges are straight: every ground point seen inside
        // the image is inside the polygon.
        let camera = Camera::new(*camera.intrinsics(), Distortion::default(), *camera.pose()).unwrap();
        let k = *camera.intrinsics();
        let footprint = camera.footprint(0.0, 1e6);
        let Ok(g) = camera.ground_point([u * k.width, v * k.height], 0.0) else { return Ok(()) };
        let c = camera.pose().position;
        prop_assume!((g[0] - c[0]).hypot(g[1] - c[1]) < 0.9e6, "beyond the footprint's range");
        prop_assert!(footprint.len() >= 3);
        prop_assert!(inside(g, &footprint), "{g:?} not in {footprint:?}");
    }

    #[test]
    fn a_homography_from_four_pairs_maps_like_the_camera(camera in camera(), points in proptest::collection::vec((0.05..0.95f64, 0.05..0.95f64), 8)) {
        let camera = Camera::new(*camera.intrinsics(), Distortion::default(), *camera.pose()).unwrap();
        let k = *camera.intrinsics();
        let pairs: Vec<([f64; 2], [f64; 2])> = points
            .iter()
            .map(|(u, v)| [u * k.width, v * k.height])
            .filter(|p| well_conditioned(&camera, *p))
            .map(|p| (p, camera.ground_point(p, 0.0).unwrap()))
            .collect();
        prop_assume!(pairs.len() >= 5);
        // Four pixels that span the image (no three nearly on one line): a fair demand.
        let spread = (0..4).flat_map(|skip| {
            let three: Vec<[f64; 2]> = (0..4).filter(|&i| i != skip).map(|i| pairs[i].0).collect();
            let area = ((three[1][0] - three[0][0]) * (three[2][1] - three[0][1])
                - (three[1][1] - three[0][1]) * (three[2][0] - three[0][0])).abs() / 2.0;
            std::iter::once(area)
        }).fold(f64::INFINITY, f64::min);
        prop_assume!(spread > 0.02 * k.width * k.height);
        let Ok(fit) = Homography::estimate(&pairs[..4]) else { return Ok(()) };
        for (pixel, ground) in &pairs[4..] {
            let g = fit.homography.apply(*pixel).unwrap();
            let scale = 1.0 + ground[0].abs().max(ground[1].abs());
            prop_assert!((g[0] - ground[0]).abs() < 1e-6 * scale && (g[1] - ground[1]).abs() < 1e-6 * scale, "{g:?} vs {ground:?}");
        }
    }
}

fn inside(p: [f64; 2], polygon: &[[f64; 2]]) -> bool {
    // Convex polygon in either orientation: the point is on one side of every edge (with slack).
    let mut sign = 0.0;
    for i in 0..polygon.len() {
        let (a, b) = (polygon[i], polygon[(i + 1) % polygon.len()]);
        let cross = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
        let scale = (b[0] - a[0]).hypot(b[1] - a[1]) * 1e-9 * (1.0 + p[0].abs() + p[1].abs());
        if cross.abs() <= scale {
            continue;
        }
        if sign == 0.0 {
            sign = cross.signum();
        } else if cross.signum() != sign {
            return false;
        }
    }
    true
}
