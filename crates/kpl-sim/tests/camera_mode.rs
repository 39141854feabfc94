//! The tracker's camera mode: boxes where the camera sees the vehicles, nothing outside the
//! image, vehicles covered by nearer ones hidden, the noise of boxes and of the reported pose as
//! asked, ids kept and switched as an image tracker's, and the same frames for the same seed.
#![allow(clippy::unwrap_used, reason = "tests")]

use std::sync::Arc;

use kpl_camera::{Camera, Distortion};
use kpl_sim::{CameraParams, Frame, Params, PerceptSource, UavTrackerSim, Visibility};

fn recorded_grid() -> Params {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../../specs/traffic/sumo/grid");
    Params {
        network_file: Some(format!("{dir}/net.xml.gz")),
        traffic_file: Some(format!("{dir}/fcd.xml.gz")),
        seed: 3,
        dropout: 0.0,
        false_positive_rate: 0.0,
        ..Params::default()
    }
}

fn run(params: &Params, camera: &CameraParams, seconds: f64) -> Vec<Frame> {
    let network = Arc::new(params.load_network().unwrap());
    let mut sim = UavTrackerSim::with_camera(params, camera, network, 0, params.seed).unwrap();
    sim.frames_until((seconds * 1e6) as i64)
}

fn camera_of(params: &CameraParams, frame: &Frame) -> Camera {
    let (k, lens) = params.lens().unwrap();
    Camera::new(k, lens, frame.image.as_ref().unwrap().true_pose).unwrap()
}

#[test]
fn looking_straight_down_boxes_are_the_vehicles() {
    // No noise: each box's centre, taken back to the plane half a vehicle's height above the
    // ground, is the vehicle's centre (straight down the camera is a similarity, so the box of a
    // cuboid is centred on it, up to the perspective of its roof against its floor).
    let params = recorded_grid();
    let camera = CameraParams {
        centre: vec![200.0, 200.0],
        altitude_m: 150.0,
        pixel_noise_px: 0.0,
        gps_noise_m: 0.0,
        altitude_noise_m: 0.0,
        attitude_noise_deg: 0.0,
        ..CameraParams::default()
    };
    let frames = run(&params, &camera, 120.0);
    let (mut detected, mut out_of_view) = (0, 0);
    for frame in &frames {
        let image = frame.image.as_ref().unwrap();
        assert!(frame.percepts.is_empty(), "camera mode has no world percepts");
        assert_eq!(image.reported_pose, image.true_pose, "no pose noise");
        let cam = camera_of(&camera, frame);
        for p in &image.percepts {
            let PerceptSource::Car(id) = p.source else { panic!("no false positives asked") };
            let i = frame.cars.iter().position(|c| c.id == id).unwrap();
            let car = &frame.cars[i];
            let truth = image.boxes[i].unwrap();
            assert_eq!(p.bbox, truth, "no pixel noise");
            if truth.left <= 0.0 || truth.top <= 0.0 || truth.right() >= 1920.0 || truth.bottom() >= 1080.0 {
                continue; // clipped at the image's border
            }
            let half_height = kpl_sim::image::vehicle_height_m(car.length_m) / 2.0;
            let g = cam.ground_point(p.bbox.centre(), half_height).unwrap();
            assert!((g[0] - car.pos[0]).hypot(g[1] - car.pos[1]) < 0.05, "{g:?} vs {:?}", car.pos);
        }
        for ((car, seen), truth) in frame.cars.iter().zip(&frame.visibility).zip(&image.boxes) {
            match seen {
                Visibility::Detected => {
                    detected += 1;
                    assert!(truth.is_some());
                }
                Visibility::OutOfView => {
                    out_of_view += 1;
                    assert!(truth.is_none());
                    // Its centre is outside the image or near its border.
                    if let Some(p) = cam.pixel_of([car.pos[0], car.pos[1], 0.0]) {
                        let k = cam.intrinsics();
                        let margin = 40.0;
                        assert!(
                            p[0] < margin
                                || p[1] < margin
                                || p[0] > k.width - margin
                                || p[1] > k.height - margin,
                            "{p:?}"
                        );
                    }
                }
                _ => {}
            }
        }
    }
    assert!(detected > 1000 && out_of_view > 1000, "{detected} detected, {out_of_view} out of view");
}

#[test]
fn noise_of_boxes_and_pose_is_as_asked() {
    let params = recorded_grid();
    let camera =
        CameraParams { centre: vec![200.0, 200.0], pose_noise_time_s: 0.0, ..CameraParams::default() };
    let frames = run(&params, &camera, 120.0);
    let mut dx = Vec::new();
    let mut yaw = Vec::new();
    let mut east = Vec::new();
    for frame in &frames {
        let image = frame.image.as_ref().unwrap();
        yaw.push(image.reported_pose.attitude.yaw - image.true_pose.attitude.yaw);
        east.push(image.reported_pose.position[0] - image.true_pose.position[0]);
        for p in &image.percepts {
            let PerceptSource::Car(id) = p.source else { continue };
            let i = frame.cars.iter().position(|c| c.id == id).unwrap();
            let truth = image.boxes[i].unwrap();
            // Boxes at the image's border are clipped after the noise; leave them out.
            if truth.left > 10.0 && truth.right() < 1910.0 && truth.top > 10.0 && truth.bottom() < 1070.0 {
                dx.push(p.bbox.centre()[0] - truth.centre()[0]);
            }
        }
    }
    let sd = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    assert!(dx.len() > 800, "{}", dx.len());
    // About 1,000 boxes: the standard error of the standard deviation is 0.045 px.
    assert!((sd(&dx) - 2.0).abs() < 0.15, "box centre noise {}", sd(&dx));
    assert!(
        (sd(&yaw) - 0.5f64.to_radians()).abs() < 0.1 * 0.5f64.to_radians(),
        "yaw noise {}",
        sd(&yaw).to_degrees()
    );
    assert!((sd(&east) - 1.0).abs() < 0.1, "GPS noise {}", sd(&east));
    // Correlated noise: consecutive frames' yaw errors are close; white noise: not.
    let correlated = run(&params, &CameraParams { pose_noise_time_s: 5.0, ..camera.clone() }, 120.0);
    let lag = |frames: &[Frame]| {
        let e: Vec<f64> = frames
            .iter()
            .map(|f| f.image.as_ref().unwrap())
            .map(|i| i.reported_pose.attitude.yaw - i.true_pose.attitude.yaw)
            .collect();
        let num: f64 = e.windows(2).map(|w| w[0] * w[1]).sum();
        num / e.iter().map(|x| x * x).sum::<f64>()
    };
    assert!(lag(&correlated) > 0.9, "{}", lag(&correlated));
    assert!(lag(&frames).abs() < 0.15, "{}", lag(&frames));
}

#[test]
fn an_oblique_circling_camera_hides_covered_vehicles_and_is_deterministic() {
    let params = Params { false_positive_rate: 2.0, dropout: 0.05, ..recorded_grid() };
    let camera = CameraParams {
        flight: "circle".into(),
        centre: vec![260.0, 260.0],
        radius_m: 250.0,
        period_s: 60.0,
        altitude_m: 60.0,
        tilt_deg: 20.0,
        id_switch_prob: 0.3,
        distortion: vec![-0.1, 0.02],
        ..CameraParams::default()
    };
    let a = run(&params, &camera, 120.0);
    let b = run(&params, &camera, 120.0);
    assert_eq!(a, b);
    let count = |v: Visibility| a.iter().flat_map(|f| &f.visibility).filter(|s| **s == v).count();
    assert!(
        count(Visibility::Occluded) > 50,
        "covered vehicles in an oblique view: {}",
        count(Visibility::Occluded)
    );
    assert!(count(Visibility::Detected) > 1000);
    let false_positives = a
        .iter()
        .flat_map(|f| &f.image.as_ref().unwrap().percepts)
        .filter(|p| p.source == PerceptSource::FalsePositive)
        .count();
    assert!(false_positives > 100, "{false_positives}");
    // Every box is inside the image, the UAV moves on its circle.
    for frame in &a {
        let image = frame.image.as_ref().unwrap();
        for p in &image.percepts {
            assert!(p.bbox.left >= -10.0 && p.bbox.right() <= 1930.0, "{:?}", p.bbox);
        }
    }
    let (p0, p1) =
        (a[0].image.as_ref().unwrap().true_pose.position, a[300].image.as_ref().unwrap().true_pose.position);
    assert!(((p0[0] - p1[0]).hypot(p0[1] - p1[1]) - 2.0 * 250.0).abs() < 1e-6, "half a circle in 30 s");
    // Id switches: a vehicle's percept id changes while it stays detected.
    let mut switches = 0;
    let mut last = std::collections::HashMap::new();
    for frame in &a {
        for p in &frame.image.as_ref().unwrap().percepts {
            if let PerceptSource::Car(id) = p.source
                && let Some(old) = last.insert(id, p.id)
                && old != p.id
            {
                switches += 1;
            }
        }
    }
    assert!(switches > 10, "{switches}");
    let _ = Distortion::default();
}

#[test]
fn the_camera_parameter_table_in_the_docs_matches_the_code() {
    let docs =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/simulator.md")).unwrap();
    let section =
        docs.split("## Camera mode").nth(1).expect("docs/simulator.md has a section `## Camera mode`");
    let rows: Vec<&str> = section.lines().filter(|l| l.starts_with("| `")).collect();
    let described = CameraParams::describe();
    let expected: Vec<String> = described
        .iter()
        .map(|info| format!("| `{}` | {} | `{}` | {} |", info.name, info.ty, info.default, info.doc))
        .collect();
    for row in &expected {
        assert!(
            rows.contains(&row.as_str()),
            "docs/simulator.md's camera mode should have the rows\n{}",
            expected.join("\n")
        );
    }
}
