//! The tracker's camera mode: a UAV with a camera (`kpl-camera`) hovering over, or circling, the
//! traffic, and an image tracker that reports vehicles as boxes in pixels, with the pose the UAV
//! reports (GPS and attitude noise), as a real drone's detector and state estimation would.
//!
//! Per frame:
//! - **The pose.** The UAV is at `altitude_m` over its path: hovering at `centre` with its nose at
//!   `heading_deg`, or circling `centre` at `radius_m` counter-clockwise once per `period_s`, nose
//!   along the circle and camera panned 90° left (towards the centre). The gimbal adds `pan_deg`
//!   and tilts `tilt_deg` below the horizon. The reported pose is the true one plus noise: GPS
//!   (`gps_noise_m` per horizontal axis, `altitude_noise_m` up), attitude (`attitude_noise_deg`
//!   on roll, pitch and yaw), gimbal (`gimbal_noise_deg` on pan and tilt), each a first-order
//!   Gauss-Markov process with correlation time `pose_noise_time_s` (its standard deviation is the
//!   parameter's at every frame; 0 s is white noise), as a navigation filter's errors drift
//!   rather than jump.
//! - **Vehicles as boxes.** Each vehicle is a cuboid over its footprint on the ground (its length
//!   and width along its heading) of [`vehicle_height_m`] (1.5 m; 3 m for vehicles longer than
//!   7 m: trucks and buses), projected through the true camera (lens distortion included); its
//!   box is the bounding box of the eight corners, clipped to the image. A vehicle is **out of view** when a
//!   corner is behind the camera or beyond the lens model, when less than half its box is inside
//!   the image, or when the box is smaller than `min_box_px`; **occluded** when an occluder hides
//!   it (as in the world mode) or when nearer vehicles' boxes cover more than `covered_fraction`
//!   of its box (the nearer is the one whose centre is closer to the camera).
//! - **Detection.** A visible vehicle is missed with probability `dropout`; otherwise its box is
//!   reported with its centre moved by `pixel_noise_px` per axis and its width and height each by
//!   `pixel_noise_px` (so the centre's noise is exactly that).
//! - **Ids** as in the world mode (kept over up to `max_gap_frames` misses; a new id after being
//!   hidden), and **id switches**: two detected boxes that overlap (IoU above 0) exchange their
//!   ids with probability `id_switch_prob` per frame, as an image tracker confuses crossing
//!   objects.
//! - **Velocity**: the box centre's velocity in pixels per second, the track's smoothed
//!   difference of centres (a tracker's constant-velocity estimate; 0 at a track's first frame,
//!   the first difference at its second, then smoothed).
//! - **False positives**: as the world tracker's (`false_positive_rate` over the whole scene,
//!   `false_positive_on_road` of them on a road lane, the others off the roads anywhere in the
//!   network's bounds, only those the camera sees kept), each a car-sized cuboid (4.5 m x 1.8 m x
//!   1.5 m, at a random heading), living a geometric number of frames with mean
//!   `false_positive_duration_s`.

use std::collections::HashMap;

use kpl_camera::{Attitude, Camera, Distortion, Gimbal, Intrinsics, PixelBox, Pose};
use kpl_core::Time;
use kpl_roads::geom::Point;
use kpl_roads::{Occluders, RoadNetwork};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Geometric, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::error::ParamsError;
use crate::tracker::{PerceptId, PerceptSource, Visibility};
use crate::traffic::{CarId, CarState};

crate::params::declare_params! {
    /// The camera mode's parameters (`sim.uav_camera`, besides the traffic's). Missing fields
    /// take their defaults.
    struct CameraParams, table CAMERA_PARAM_TABLE;
    /// Width and height of the image, pixels.
    image_size: Vec<f64>, "list<float>" = vec![1920.0, 1080.0];
    /// Horizontal field of view, degrees (square pixels, principal point at the image's centre).
    hfov_deg: f64, "float" = 70.0;
    /// Lens distortion, OpenCV's coefficients [k1, k2, p1, p2, k3] (fewer: the rest 0; empty: none).
    distortion: Vec<f64>, "list<float>" = Vec::new();
    /// The UAV's path: `hover` (over `centre`) or `circle` (around `centre` at `radius_m`).
    flight: String, "string" = "hover".to_string();
    /// The point [x, y] the UAV hovers over or circles; empty: the middle of the road network.
    centre: Vec<f64>, "list<float>" = Vec::new();
    /// Height of the camera above the ground, metres.
    altitude_m: f64, "float" = 100.0;
    /// Radius of the circle flown (`circle`), metres.
    radius_m: f64, "float" = 100.0;
    /// Time for one circle (`circle`), seconds.
    period_s: f64, "float" = 120.0;
    /// Hovering: the nose's heading (degrees counter-clockwise from east); circling: where on the circle the UAV starts (degrees from east).
    heading_deg: f64, "float" = 90.0;
    /// The gimbal's tilt below the horizon, degrees (90: straight down).
    tilt_deg: f64, "float" = 90.0;
    /// The gimbal's pan to the left of the nose, degrees (circling: added to the 90° that looks at the centre).
    pan_deg: f64, "float" = 0.0;
    /// Standard deviation of a box centre's position per axis (and of its width and height), pixels.
    pixel_noise_px: f64, "float" = 2.0;
    /// Standard deviation of the reported position per horizontal axis (GPS), metres.
    gps_noise_m: f64, "float" = 1.0;
    /// Standard deviation of the reported altitude, metres.
    altitude_noise_m: f64, "float" = 2.0;
    /// Standard deviation of the reported roll, pitch and yaw, each, degrees.
    attitude_noise_deg: f64, "float" = 0.5;
    /// Standard deviation of the reported gimbal pan and tilt, each, degrees.
    gimbal_noise_deg: f64, "float" = 0.0;
    /// Correlation time of the pose's noise (a first-order Gauss-Markov process), seconds; 0: independent every frame.
    pose_noise_time_s: f64, "float" = 5.0;
    /// Boxes with a side below this are not detected, pixels.
    min_box_px: f64, "float" = 4.0;
    /// A vehicle whose box nearer vehicles cover more than this fraction of is hidden.
    covered_fraction: f64, "float" = 0.5;
    /// Probability per frame that two overlapping detected boxes exchange their ids.
    id_switch_prob: f64, "float" = 0.0;
}

/// The height of a vehicle of this length, metres: 1.5, or 3 for one longer than 7 m.
pub fn vehicle_height_m(length_m: f64) -> f64 {
    if length_m > 7.0 { 3.0 } else { 1.5 }
}

/// The number of pose noise components: east, north, up, roll, pitch, yaw, pan, tilt.
const POSE_NOISE: usize = 8;

/// A car-sized false positive on the ground, metres.
const FALSE_POSITIVE_SIZE_M: [f64; 3] = [4.5, 1.8, 1.5];

/// Bounded tries to place a false positive where the camera sees it (the world tracker's count).
const FALSE_POSITIVE_TRIES: usize = 20;

/// Smoothing of a track's pixel velocity: the weight of the newest centre difference.
const VELOCITY_SMOOTHING: f64 = 0.5;

impl CameraParams {
    /// Reads the parameters from a JSON object and checks them.
    pub fn from_json(json: serde_json::Value) -> Result<CameraParams, ParamsError> {
        let params: CameraParams = serde_json::from_value(json)?;
        params.validate()?;
        Ok(params)
    }

    /// Checks every range; the first parameter out of range is reported.
    pub fn validate(&self) -> Result<(), ParamsError> {
        let range = |name: &'static str, value: f64, lo: f64, hi: f64, expected: &'static str| {
            if value.is_finite() && (lo..=hi).contains(&value) {
                Ok(())
            } else {
                Err(ParamsError::OutOfRange { name, expected, found: value.to_string() })
            }
        };
        let out_of_range = |name: &'static str, expected: &'static str, found: String| {
            Err(ParamsError::OutOfRange { name, expected, found })
        };
        if self.image_size.len() != 2
            || !self.image_size.iter().all(|v| v.is_finite() && *v >= 16.0 && *v <= 20_000.0)
        {
            return out_of_range(
                "image_size",
                "[width, height] in pixels, each 16 to 20000",
                format!("{:?}", self.image_size),
            );
        }
        range("hfov_deg", self.hfov_deg, 1.0, 170.0, "between 1 and 170 degrees")?;
        if Distortion::from_opencv(&self.distortion).is_err() {
            return out_of_range(
                "distortion",
                "at most five finite numbers [k1, k2, p1, p2, k3]",
                format!("{:?}", self.distortion),
            );
        }
        if !["hover", "circle"].contains(&self.flight.as_str()) {
            return out_of_range("flight", "`hover` or `circle`", format!("{:?}", self.flight));
        }
        if !(self.centre.is_empty()
            || (self.centre.len() == 2 && self.centre.iter().all(|v| v.is_finite() && v.abs() < 1e7)))
        {
            return out_of_range("centre", "[x, y] in metres, or empty", format!("{:?}", self.centre));
        }
        range("altitude_m", self.altitude_m, 1.0, 10_000.0, "between 1 and 10000 metres")?;
        range("radius_m", self.radius_m, 0.0, 100_000.0, "between 0 and 100000 metres")?;
        range("period_s", self.period_s, 1.0, 1e6, "between 1 and 1000000 seconds")?;
        range("heading_deg", self.heading_deg, -3600.0, 3600.0, "between -3600 and 3600 degrees")?;
        range("tilt_deg", self.tilt_deg, -90.0, 90.0, "between -90 and 90 degrees")?;
        range("pan_deg", self.pan_deg, -3600.0, 3600.0, "between -3600 and 3600 degrees")?;
        range("pixel_noise_px", self.pixel_noise_px, 0.0, 1000.0, "between 0 and 1000 pixels")?;
        range("gps_noise_m", self.gps_noise_m, 0.0, 1000.0, "between 0 and 1000 metres")?;
        range("altitude_noise_m", self.altitude_noise_m, 0.0, 1000.0, "between 0 and 1000 metres")?;
        range("attitude_noise_deg", self.attitude_noise_deg, 0.0, 45.0, "between 0 and 45 degrees")?;
        range("gimbal_noise_deg", self.gimbal_noise_deg, 0.0, 45.0, "between 0 and 45 degrees")?;
        range("pose_noise_time_s", self.pose_noise_time_s, 0.0, 1e6, "between 0 and 1000000 seconds")?;
        range("min_box_px", self.min_box_px, 0.0, 10_000.0, "between 0 and 10000 pixels")?;
        range("covered_fraction", self.covered_fraction, 0.0, 1.0, "a fraction between 0 and 1")?;
        range("id_switch_prob", self.id_switch_prob, 0.0, 1.0, "a probability between 0 and 1")?;
        if self.flight == "hover" && self.radius_m != CameraParams::default().radius_m {
            return Err(ParamsError::NoEffect {
                name: "radius_m",
                reason: "the UAV hovers (`flight: \"circle\"` circles)",
            });
        }
        if self.flight == "hover" && self.period_s != CameraParams::default().period_s {
            return Err(ParamsError::NoEffect {
                name: "period_s",
                reason: "the UAV hovers (`flight: \"circle\"` circles)",
            });
        }
        Ok(())
    }

    /// The camera's intrinsics and lens.
    pub fn lens(&self) -> Result<(Intrinsics, Distortion), ParamsError> {
        let bad = |e: kpl_camera::CameraError| ParamsError::OutOfRange {
            name: "image_size",
            expected: "a usable camera",
            found: e.to_string(),
        };
        let k = Intrinsics::from_fov(self.image_size[0], self.image_size[1], self.hfov_deg.to_radians())
            .map_err(bad)?;
        let lens = Distortion::from_opencv(&self.distortion).map_err(|_| ParamsError::OutOfRange {
            name: "distortion",
            expected: "at most five finite numbers",
            found: format!("{:?}", self.distortion),
        })?;
        Ok((k, lens))
    }
}

/// The UAV's path.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Flight {
    Hover { centre: Point, heading: f64 },
    Circle { centre: Point, radius: f64, period_s: f64, start: f64 },
}

/// One image box of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImagePercept {
    pub id: PerceptId,
    pub bbox: PixelBox,
    /// The box centre's velocity, pixels per second.
    pub vel: [f64; 2],
    /// The detector's confidence.
    pub score: f64,
    /// Ground truth: not part of what the tracker reports.
    pub source: PerceptSource,
}

/// What the camera gave in one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageObservation {
    pub percepts: Vec<ImagePercept>,
    /// The pose as the UAV reports it (with GPS and attitude noise).
    pub reported_pose: Pose,
    /// The true pose.
    pub true_pose: Pose,
    /// Each vehicle's true box (clipped to the image) when it is in view, in the order of the
    /// frame's cars.
    pub boxes: Vec<Option<PixelBox>>,
}

#[derive(Debug, Clone, Default)]
struct Track {
    percept: Option<PerceptId>,
    missed: u32,
    hidden: bool,
    last_centre: Option<[f64; 2]>,
    vel: [f64; 2],
    /// Whether `vel` is a difference of centres yet (not the 0 of a track's first frame).
    vel_known: bool,
}

#[derive(Debug, Clone)]
struct FalsePositive {
    id: PerceptId,
    bbox: PixelBox,
    frames_left: u64,
}

/// The settings of the world tracker the camera mode shares.
#[derive(Debug, Clone, PartialEq)]
pub struct SharedSettings {
    pub dropout: f64,
    pub max_gap_frames: u32,
    pub false_positive_rate: f64,
    pub false_positive_on_road: f64,
    pub false_positive_duration_s: f64,
}

/// The UAV, its camera and the image tracker's state between frames.
#[derive(Debug, Clone)]
pub struct ImageTracker {
    params: CameraParams,
    shared: SharedSettings,
    intrinsics: Intrinsics,
    distortion: Distortion,
    flight: Flight,
    rng: ChaCha8Rng,
    next_percept: u64,
    tracks: HashMap<CarId, Track>,
    false_positives: Vec<FalsePositive>,
    /// The pose noise's current value (metres, radians).
    noise: [f64; POSE_NOISE],
    noise_started: bool,
}

impl ImageTracker {
    pub fn new(
        params: CameraParams,
        shared: SharedSettings,
        network: &RoadNetwork,
        rng: ChaCha8Rng,
    ) -> Result<ImageTracker, ParamsError> {
        params.validate()?;
        let (intrinsics, distortion) = params.lens()?;
        let centre = match params.centre.as_slice() {
            [x, y] => [*x, *y],
            _ => {
                let (lo, hi) = network.bounds();
                [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0]
            }
        };
        let flight = match params.flight.as_str() {
            "circle" => Flight::Circle {
                centre,
                radius: params.radius_m,
                period_s: params.period_s,
                start: params.heading_deg.to_radians(),
            },
            _ => Flight::Hover { centre, heading: params.heading_deg.to_radians() },
        };
        Ok(ImageTracker {
            params,
            shared,
            intrinsics,
            distortion,
            flight,
            rng,
            next_percept: 1,
            tracks: HashMap::new(),
            false_positives: Vec::new(),
            noise: [0.0; POSE_NOISE],
            noise_started: false,
        })
    }

    pub fn params(&self) -> &CameraParams {
        &self.params
    }

    /// The camera's intrinsics.
    pub fn intrinsics(&self) -> &Intrinsics {
        &self.intrinsics
    }

    /// The true pose `elapsed` microseconds after the start.
    pub fn true_pose(&self, elapsed: Time) -> Pose {
        let t = elapsed as f64 / 1e6;
        let tilt = self.params.tilt_deg.to_radians();
        let pan = self.params.pan_deg.to_radians();
        let h = self.params.altitude_m;
        match self.flight {
            Flight::Hover { centre, heading } => {
                Pose::new([centre[0], centre[1], h], Attitude::level(heading), Gimbal { pan, tilt })
            }
            Flight::Circle { centre, radius, period_s, start } => {
                let angle = start + std::f64::consts::TAU * t / period_s;
                let position = [centre[0] + radius * angle.cos(), centre[1] + radius * angle.sin(), h];
                // Counter-clockwise: the nose along the tangent, the centre to the left.
                let yaw = angle + std::f64::consts::FRAC_PI_2;
                Pose::new(
                    position,
                    Attitude::level(yaw),
                    Gimbal { pan: std::f64::consts::FRAC_PI_2 + pan, tilt },
                )
            }
        }
    }

    fn gaussian(&mut self, sd: f64) -> f64 {
        if sd == 0.0 {
            return 0.0;
        }
        let z: f64 = self.rng.sample(StandardNormal);
        z * sd
    }

    fn new_percept_id(&mut self) -> PerceptId {
        let id = PerceptId(self.next_percept);
        self.next_percept += 1;
        id
    }

    /// The standard deviations of the pose noise: east, north, up (m), roll, pitch, yaw, pan,
    /// tilt (radians).
    fn noise_sd(&self) -> [f64; POSE_NOISE] {
        let p = &self.params;
        let (att, gim) = (p.attitude_noise_deg.to_radians(), p.gimbal_noise_deg.to_radians());
        [p.gps_noise_m, p.gps_noise_m, p.altitude_noise_m, att, att, att, gim, gim]
    }

    /// Moves the pose noise on by `dt_s` (a stationary Gauss-Markov process) and returns the
    /// reported pose.
    fn reported(&mut self, truth: Pose, dt_s: f64) -> Pose {
        let sd = self.noise_sd();
        let a = if self.params.pose_noise_time_s > 0.0 {
            (-dt_s / self.params.pose_noise_time_s).exp()
        } else {
            0.0
        };
        for (i, s) in sd.iter().enumerate() {
            let fresh = self.gaussian(*s);
            self.noise[i] =
                if self.noise_started { a * self.noise[i] + (1.0 - a * a).sqrt() * fresh } else { fresh };
        }
        self.noise_started = true;
        let n = self.noise;
        let mut pose = truth;
        for (axis, value) in pose.position.iter_mut().enumerate() {
            *value += n[axis];
        }
        pose.attitude.roll += n[3];
        pose.attitude.pitch += n[4];
        pose.attitude.yaw += n[5];
        pose.gimbal.pan += n[6];
        pose.gimbal.tilt += n[7];
        pose
    }

    /// The box of a cuboid standing on the ground (`size`: length, width, height) through
    /// `camera`: `None` when a corner is not in front of it (or beyond its lens model).
    fn footprint_box(camera: &Camera, centre: Point, heading: f64, size: [f64; 3]) -> Option<PixelBox> {
        let (s, c) = heading.sin_cos();
        let (hl, hw) = (size[0] / 2.0, size[1] / 2.0);
        let mut corners = [[0.0; 2]; 8];
        for (k, [a, b, z]) in [[hl, hw], [hl, -hw], [-hl, -hw], [-hl, hw]]
            .into_iter()
            .flat_map(|[a, b]| [[a, b, 0.0], [a, b, size[2]]])
            .enumerate()
        {
            corners[k] = camera.pixel_of([centre[0] + a * c - b * s, centre[1] + a * s + b * c, z])?;
        }
        PixelBox::around(corners)
    }

    /// One frame: the vehicles' boxes, what the tracker reports of them and the false positives,
    /// and the pose. `elapsed` is the time since the start, `dt_s` since the last frame.
    pub fn observe(
        &mut self,
        network: &RoadNetwork,
        cars: &[CarState],
        occluders: &Occluders,
        elapsed: Time,
        dt_s: f64,
    ) -> (ImageObservation, Vec<Visibility>) {
        let true_pose = self.true_pose(elapsed);
        let reported_pose = self.reported(true_pose, dt_s);
        let (w, h) = (self.intrinsics.width, self.intrinsics.height);
        let camera = match Camera::new(self.intrinsics, self.distortion, true_pose) {
            Ok(camera) => camera,
            // Validated parameters make a finite pose; nothing is seen otherwise.
            Err(_) => {
                let visibility = vec![Visibility::OutOfView; cars.len()];
                let observation = ImageObservation {
                    percepts: Vec::new(),
                    reported_pose,
                    true_pose,
                    boxes: vec![None; cars.len()],
                };
                return (observation, visibility);
            }
        };
        // The true boxes, clipped, of the vehicles in view (at least half of the box inside).
        let boxes: Vec<Option<PixelBox>> = cars
            .iter()
            .map(|car| {
                let size = [car.length_m, car.width_m, vehicle_height_m(car.length_m)];
                let full = Self::footprint_box(&camera, car.pos, car.heading, size)?;
                let clipped = full.clipped(w, h)?;
                let big_enough =
                    clipped.width >= self.params.min_box_px && clipped.height >= self.params.min_box_px;
                (clipped.area() >= 0.5 * full.area() && big_enough).then_some(clipped)
            })
            .collect();
        let centre = camera.pose().position;
        let depth = |car: &CarState| (car.pos[0] - centre[0]).hypot(car.pos[1] - centre[1]).hypot(centre[2]);
        // Covered by nearer vehicles: the sum of the nearer boxes' overlaps (capped at 1).
        let mut order: Vec<usize> = (0..cars.len()).filter(|&i| boxes[i].is_some()).collect();
        order.sort_by(|&a, &b| depth(&cars[a]).total_cmp(&depth(&cars[b])));
        let mut covered = vec![false; cars.len()];
        for (k, &i) in order.iter().enumerate() {
            let Some(b) = boxes[i] else { continue };
            let area = b.area();
            if area <= 0.0 {
                continue;
            }
            let overlap: f64 = order[..k].iter().filter_map(|&j| boxes[j]).map(|n| b.intersection(&n)).sum();
            covered[i] = (overlap / area).min(1.0) > self.params.covered_fraction;
        }
        let mut percepts = Vec::with_capacity(cars.len());
        let mut visibility = Vec::with_capacity(cars.len());
        for (i, car) in cars.iter().enumerate() {
            let seen = if boxes[i].is_none() {
                Visibility::OutOfView
            } else if covered[i] || occluders.hiding(car.pos, car.road()).is_some() {
                Visibility::Occluded
            } else {
                Visibility::Detected
            };
            let mut track = self.tracks.remove(&car.id).unwrap_or_default();
            let seen = if seen != Visibility::Detected {
                track.hidden = true;
                seen
            } else if self.shared.dropout > 0.0 && self.rng.random::<f64>() < self.shared.dropout {
                track.missed = track.missed.saturating_add(1);
                Visibility::Missed
            } else {
                let kept =
                    track.percept.is_some() && !track.hidden && track.missed <= self.shared.max_gap_frames;
                let id = match track.percept {
                    Some(id) if kept => id,
                    _ => self.new_percept_id(),
                };
                let bbox = self.noisy_box(boxes[i].unwrap_or_default());
                let vel = Self::velocity(&mut track, kept, bbox.centre(), dt_s);
                track.percept = Some(id);
                track.missed = 0;
                track.hidden = false;
                percepts.push(ImagePercept { id, bbox, vel, score: 1.0, source: PerceptSource::Car(car.id) });
                Visibility::Detected
            };
            visibility.push(seen);
            self.tracks.insert(car.id, track);
        }
        self.switch_ids(&mut percepts);
        self.false_positives_frame(network, &camera, dt_s, &mut percepts);
        (ImageObservation { percepts, reported_pose, true_pose, boxes }, visibility)
    }

    /// A box with noise on its centre and its sides, clipped to the image.
    fn noisy_box(&mut self, b: PixelBox) -> PixelBox {
        let sd = self.params.pixel_noise_px;
        if sd == 0.0 {
            return b;
        }
        let c = b.centre();
        let (cx, cy) = (c[0] + self.gaussian(sd), c[1] + self.gaussian(sd));
        let (bw, bh) = ((b.width + self.gaussian(sd)).max(1.0), (b.height + self.gaussian(sd)).max(1.0));
        PixelBox::new(cx - bw / 2.0, cy - bh / 2.0, bw, bh)
    }

    /// The smoothed velocity of a track's centre, pixels per second: 0 at its first frame (no
    /// difference yet), the first difference of centres at its second (not smoothed with that 0,
    /// which would halve it and take frames to catch up), then smoothed. `dt_s` is the time
    /// since the last frame; the last centre is older by the frames the track missed since.
    fn velocity(track: &mut Track, kept: bool, centre: [f64; 2], dt_s: f64) -> [f64; 2] {
        let since = dt_s * f64::from(track.missed.saturating_add(1));
        let (vel, known) = match (kept, track.last_centre) {
            (true, Some(last)) if since > 0.0 => {
                let raw = [(centre[0] - last[0]) / since, (centre[1] - last[1]) / since];
                let a = if track.vel_known { VELOCITY_SMOOTHING } else { 1.0 };
                ([a * raw[0] + (1.0 - a) * track.vel[0], a * raw[1] + (1.0 - a) * track.vel[1]], true)
            }
            _ => ([0.0, 0.0], false),
        };
        track.last_centre = Some(centre);
        track.vel = vel;
        track.vel_known = known;
        vel
    }

    /// Overlapping detected boxes exchange ids with probability `id_switch_prob`.
    fn switch_ids(&mut self, percepts: &mut [ImagePercept]) {
        if self.params.id_switch_prob <= 0.0 {
            return;
        }
        for i in 0..percepts.len() {
            for j in i + 1..percepts.len() {
                if percepts[i].bbox.iou(&percepts[j].bbox) > 0.0
                    && self.rng.random::<f64>() < self.params.id_switch_prob
                {
                    let (a, b) = (percepts[i].id, percepts[j].id);
                    percepts[i].id = b;
                    percepts[j].id = a;
                    // The tracks follow their new ids.
                    for track in self.tracks.values_mut() {
                        if track.percept == Some(a) {
                            track.percept = Some(b);
                        } else if track.percept == Some(b) {
                            track.percept = Some(a);
                        }
                    }
                }
            }
        }
    }

    fn false_positives_frame(
        &mut self,
        network: &RoadNetwork,
        camera: &Camera,
        dt_s: f64,
        percepts: &mut Vec<ImagePercept>,
    ) {
        self.false_positives.retain_mut(|fp| {
            fp.frames_left -= 1;
            fp.frames_left > 0
        });
        let n_new = crate::tracker::poisson_count(&mut self.rng, self.shared.false_positive_rate * dt_s);
        let mean_frames = (self.shared.false_positive_duration_s / dt_s).max(1.0);
        let (w, h) = (self.intrinsics.width, self.intrinsics.height);
        let (lo, hi) = network.bounds();
        for _ in 0..n_new {
            // As the world tracker places them: on a road lane or off the roads anywhere in the
            // scene, kept only where the camera sees them.
            let on_road = self.rng.random::<f64>() < self.shared.false_positive_on_road;
            let mut placed = None;
            for _ in 0..FALSE_POSITIVE_TRIES {
                let g = if on_road {
                    let u: f64 = self.rng.random();
                    match network.road_lane_position_at_fraction(u) {
                        Some(p) => p.point,
                        None => break,
                    }
                } else {
                    let p = [self.rng.random_range(lo[0]..=hi[0]), self.rng.random_range(lo[1]..=hi[1])];
                    if network.on_road(p) {
                        continue;
                    }
                    p
                };
                let heading = self.rng.random_range(0.0..std::f64::consts::TAU);
                if let Some(b) = Self::footprint_box(camera, g, heading, FALSE_POSITIVE_SIZE_M)
                    .and_then(|b| b.clipped(w, h))
                    && camera.sees([g[0], g[1], 0.0])
                {
                    placed = Some(b);
                    break;
                }
            }
            let Some(bbox) = placed else { continue };
            let extra = Geometric::new(1.0 / mean_frames).map_or(0, |g| self.rng.sample(g));
            let id = self.new_percept_id();
            self.false_positives.push(FalsePositive { id, bbox, frames_left: 1 + extra });
        }
        for i in 0..self.false_positives.len() {
            let fp = self.false_positives[i].clone();
            let bbox = self.noisy_box(fp.bbox);
            percepts.push(ImagePercept {
                id: fp.id,
                bbox,
                vel: [0.0, 0.0],
                score: 1.0,
                source: PerceptSource::FalsePositive,
            });
        }
    }

    /// Forgets the tracks of vehicles that left.
    pub fn forget(&mut self, cars: &[CarId]) {
        for car in cars {
            self.tracks.remove(car);
        }
    }

    /// Percept ids handed out so far.
    pub fn n_percept_ids(&self) -> u64 {
        self.next_percept - 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tracks_velocity_is_its_first_difference_at_its_second_frame_then_smoothed() {
        let mut track = Track::default();
        // 10 px per frame at 10 Hz: 100 px/s.
        assert_eq!(ImageTracker::velocity(&mut track, true, [0.0, 5.0], 0.1), [0.0, 0.0]);
        let second = ImageTracker::velocity(&mut track, true, [10.0, 5.0], 0.1);
        assert!((second[0] - 100.0).abs() < 1e-9 && second[1].abs() < 1e-9, "{second:?}");
        // Then smoothed: 20 px in a frame (200 px/s) moves it halfway.
        let third = ImageTracker::velocity(&mut track, true, [30.0, 5.0], 0.1);
        assert!((third[0] - 150.0).abs() < 1e-9, "{third:?}");
        // A new id (not kept) starts again from nothing.
        assert_eq!(ImageTracker::velocity(&mut track, false, [40.0, 5.0], 0.1), [0.0, 0.0]);
        let again = ImageTracker::velocity(&mut track, true, [45.0, 5.0], 0.1);
        assert!((again[0] - 50.0).abs() < 1e-9, "{again:?}");
    }

    #[test]
    fn a_missed_frame_does_not_double_the_velocity_after_it() {
        let mut track = Track::default();
        ImageTracker::velocity(&mut track, true, [0.0, 5.0], 0.1);
        // One frame missed (as `observe` counts it), then seen 20 px on: still 100 px/s.
        track.missed = 1;
        let after = ImageTracker::velocity(&mut track, true, [20.0, 5.0], 0.1);
        assert!((after[0] - 100.0).abs() < 1e-9 && after[1].abs() < 1e-9, "{after:?}");
    }
}
