//! From pixels to the world (`kpl-camera` on the runtime):
//!
//! - `camera.georeference(percepts, poses, ...)`: a synchronized unit. Each state pairs a frame's
//!   image percepts (boxes or points in pixels, with their ids) with the camera's pose at that
//!   valid time (the runtime's state synchronisation: `use most recent` on the pose stream takes
//!   the latest pose for a frame without one), and turns every percept into a world percept on
//!   the ground plane: `pos`, `vel` (from the percept's pixel velocity, the ground point now and
//!   where its pixel was a moment ago under the previous pose), `size` (the box's longer side on
//!   the ground) and `pos_cov` (`[σ_xx, σ_xy, σ_yy]`, m², propagated from the pixel noise and the
//!   pose noise; `anchor.kalman` weighs the percept by it) and `border_px` (how far the box is
//!   from the image's nearest border, pixels: 0 or less when clipped there, as a vehicle's box is
//!   while it moves into the image; a spec declares it to use it). Its `camera` port gives, per state,
//!   the camera as a record (pose and intrinsics) for the camera functions.
//! - `camera.homography(percepts, ...)`: a fixed camera calibrated from point pairs (pixel and
//!   ground point, at least four): the homography is estimated when the unit is built, its
//!   residual reported in the run's results; each percept's ground point and covariance (the
//!   homography's Jacobian times the pixel noise, plus the fit's residual).
//! - `sim.uav_camera(...)`: the simulated tracker's camera mode (`kpl_sim::image`): boxes in
//!   pixels, the reported pose on port `pose`, the ground truth on `truth`.
//! - Functions for formulas over a camera record (the `camera` port): `pixel(camera, pos)`,
//!   `in_view(camera, pos)`, `footprint(camera)`.

use std::collections::HashMap;
use std::sync::Arc;

use kpl_camera::{
    Attitude, Camera, Distortion, Georeferencer, Gimbal, GroundEstimate, Homography, Intrinsics, PixelBox,
    Pose, PoseNoise,
};
use kpl_core::{Record, Time, Value, ValueType};
use kpl_runtime::context::SourceContext;
use kpl_runtime::process::{BoxFuture, Emitter, Input, ProcessError, Source, SyncUnit, Unit};
use kpl_runtime::registry::{BuildContext, BuildError};
use kpl_runtime::stats::{Malformed, ProcessStats};
use kpl_semantic::registry::{Entry, EntryKind, Param, ParamType, TypeReq};
use kpl_sim::image::CameraParams;
use kpl_sim::{Frame, PerceptSource, UavTrackerSim};

fn list(values: &[f64]) -> Value {
    Value::List(values.iter().map(|v| Value::Float(*v)).collect::<Vec<_>>().into())
}

fn record(id: Option<&str>, fields: Vec<(&str, Value)>) -> Value {
    Value::Record(Arc::new(Record {
        id: id.map(Arc::from),
        fields: fields.into_iter().map(|(n, v)| (Arc::from(n), v)).collect(),
    }))
}

/// A list of numbers from a value (`[1, 2.5]`).
fn numbers(value: &Value) -> Option<Vec<f64>> {
    match value {
        Value::List(items) => items.iter().map(Value::as_f64).collect(),
        _ => None,
    }
}

fn float_param(ctx: &BuildContext<'_>, name: &str, default: f64) -> f64 {
    ctx.param(name).and_then(Value::as_f64).unwrap_or(default)
}

fn list_param(ctx: &BuildContext<'_>, name: &str) -> Result<Vec<f64>, BuildError> {
    match ctx.param(name) {
        None => Ok(Vec::new()),
        Some(v) => numbers(v).ok_or_else(|| ctx.error(format!("`{name}` must be a list of numbers"))),
    }
}

// ---------------------------------------------------------------------------------------------
// The camera as the georeferencing unit is told it is.

/// Intrinsics and lens from a unit's parameters: `image_size`, `hfov_deg` or `focal_px`,
/// `principal_point`, `distortion`.
fn lens(ctx: &BuildContext<'_>) -> Result<(Intrinsics, Distortion), BuildError> {
    let size = list_param(ctx, "image_size")?;
    let [w, h] = size[..] else { return Err(ctx.error("`image_size` must be [width, height] in pixels")) };
    let focal = list_param(ctx, "focal_px")?;
    let principal = list_param(ctx, "principal_point")?;
    let k = match (focal.as_slice(), principal.as_slice()) {
        ([], []) => Intrinsics::from_fov(w, h, float_param(ctx, "hfov_deg", 70.0).to_radians()),
        ([fx, fy], []) => Intrinsics::new(*fx, *fy, w / 2.0, h / 2.0, w, h),
        ([fx, fy], [cx, cy]) => Intrinsics::new(*fx, *fy, *cx, *cy, w, h),
        _ => {
            return Err(
                ctx.error("`focal_px` is [fx, fy] and `principal_point` [cx, cy] (which needs `focal_px`)")
            );
        }
    }
    .map_err(|e| ctx.error(e.to_string()))?;
    let distortion =
        Distortion::from_opencv(&list_param(ctx, "distortion")?).map_err(|e| ctx.error(e.to_string()))?;
    Ok((k, distortion))
}

/// The camera record of the `camera` port: pose (degrees) and intrinsics.
fn camera_record(camera: &Camera) -> Value {
    let p = camera.pose();
    let k = camera.intrinsics();
    let d = camera.distortion();
    record(
        None,
        vec![
            ("position", list(&p.position)),
            ("attitude", list(&[p.attitude.roll, p.attitude.pitch, p.attitude.yaw].map(f64::to_degrees))),
            ("gimbal", list(&[p.gimbal.pan, p.gimbal.tilt].map(f64::to_degrees))),
            ("image_size", list(&[k.width, k.height])),
            ("focal_px", list(&[k.fx, k.fy])),
            ("principal_point", list(&[k.cx, k.cy])),
            ("distortion", list(&[d.k1, d.k2, d.p1, d.p2, d.k3])),
        ],
    )
}

/// A camera from a camera record (the `camera` port), for the camera functions.
fn camera_from_record(value: &Value, func: &str) -> Result<Camera, String> {
    let r = value
        .as_record()
        .ok_or_else(|| format!("{func} needs a camera record (a `camera` port's sample)"))?;
    let get = |name: &str, n: usize| -> Result<Vec<f64>, String> {
        r.get(name)
            .and_then(numbers)
            .filter(|v| v.len() == n)
            .ok_or_else(|| format!("{func}: the camera record needs `{name}` ({n} numbers)"))
    };
    let size = get("image_size", 2)?;
    let focal = get("focal_px", 2)?;
    let principal = get("principal_point", 2)?;
    let k = Intrinsics::new(focal[0], focal[1], principal[0], principal[1], size[0], size[1])
        .map_err(|e| e.to_string())?;
    let distortion = match r.get("distortion").and_then(numbers) {
        Some(c) => Distortion::from_opencv(&c).map_err(|e| e.to_string())?,
        None => Distortion::default(),
    };
    let pose = pose_from_record(r).map_err(|e| format!("{func}: {e}"))?;
    Camera::new(k, distortion, pose).map_err(|e| e.to_string())
}

/// A pose from a pose record: `position` [x, y, z] (metres), `attitude` [roll, pitch, yaw]
/// and `gimbal` [pan, tilt] (degrees).
fn pose_from_record(r: &Record) -> Result<Pose, String> {
    let get = |name: &str, n: usize| -> Result<Vec<f64>, String> {
        r.get(name)
            .and_then(numbers)
            .filter(|v| v.len() == n && v.iter().all(|x| x.is_finite()))
            .ok_or_else(|| format!("a pose needs `{name}` ({n} finite numbers)"))
    };
    let position = get("position", 3)?;
    let attitude = get("attitude", 3)?;
    let gimbal = get("gimbal", 2)?;
    Ok(Pose::new(
        [position[0], position[1], position[2]],
        Attitude {
            roll: attitude[0].to_radians(),
            pitch: attitude[1].to_radians(),
            yaw: attitude[2].to_radians(),
        },
        Gimbal { pan: gimbal[0].to_radians(), tilt: gimbal[1].to_radians() },
    ))
}

/// A pose as the record `sim.uav_camera` reports it on its `pose` port.
pub(crate) fn pose_record(pose: &Pose) -> Value {
    record(
        None,
        vec![
            ("position", list(&pose.position)),
            (
                "attitude",
                list(&[pose.attitude.roll, pose.attitude.pitch, pose.attitude.yaw].map(f64::to_degrees)),
            ),
            ("gimbal", list(&[pose.gimbal.pan, pose.gimbal.tilt].map(f64::to_degrees))),
        ],
    )
}

/// A percept's pixel box (from `box` [left, top, width, height]) or point (from `pos`).
enum ImagePoint {
    Box(PixelBox),
    Point([f64; 2]),
}

fn image_point(r: &Record) -> Option<ImagePoint> {
    if let Some(b) = r.get("box").and_then(numbers).filter(|b| b.len() == 4) {
        let b = PixelBox::new(b[0], b[1], b[2], b[3]);
        return b.is_valid().then_some(ImagePoint::Box(b));
    }
    r.get("pos")
        .and_then(Value::as_vec2)
        .filter(|p| p[0].is_finite() && p[1].is_finite())
        .map(ImagePoint::Point)
}

/// Which point of a box is taken to the ground.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum BoxPoint {
    Centre,
    Bottom,
}

// ---------------------------------------------------------------------------------------------
// camera.georeference

struct Georeference {
    intrinsics: Intrinsics,
    distortion: Distortion,
    noise: PoseNoise,
    pixel_sd: f64,
    point: BoxPoint,
    /// The height above the ground of the point taken (half a vehicle's height for box centres).
    point_height: f64,
    ground_z: f64,
    /// The last pose used, for velocities.
    previous: Option<(Time, Camera)>,
    stats: Arc<ProcessStats>,
    without_pose: u64,
    not_on_ground: u64,
    georeferenced: u64,
}

impl Georeference {
    fn malformed(&self, location: String, error: String) {
        self.stats.malformed(Malformed { location, error });
    }

    /// The pixel a percept stands for.
    fn pixel(&self, point: &ImagePoint) -> [f64; 2] {
        match (point, self.point) {
            (ImagePoint::Box(b), BoxPoint::Centre) => b.centre(),
            (ImagePoint::Box(b), BoxPoint::Bottom) => b.bottom_centre(),
            (ImagePoint::Point(p), _) => *p,
        }
    }

    /// How far a percept is from the image's nearest border, pixels (0 or less for a box the
    /// detector clipped at the border, as boxes of vehicles moving into the image are).
    fn border_px(&self, point: &ImagePoint) -> f64 {
        let b = match point {
            ImagePoint::Box(b) => *b,
            ImagePoint::Point(p) => PixelBox::new(p[0], p[1], 0.0, 0.0),
        };
        b.border_distance(self.intrinsics.width, self.intrinsics.height)
    }

    /// The world percept of one image percept.
    fn world(
        &self,
        geo: &Georeferencer<'_>,
        r: &Record,
        point: &ImagePoint,
        dt_s: Option<f64>,
    ) -> Option<Value> {
        let pixel = self.pixel(point);
        let estimate: GroundEstimate = geo.ground(pixel, self.pixel_sd).ok()?;
        let camera = geo.camera();
        let plane = self.ground_z + self.point_height;
        // The ground velocity: where the pixel was a moment ago, under the previous pose.
        let vel = match (r.get("vel").and_then(Value::as_vec2), dt_s, &self.previous) {
            (Some(v), Some(dt), Some((_, before))) if dt > 0.0 => {
                let earlier = [pixel[0] - v[0] * dt, pixel[1] - v[1] * dt];
                match before.ground_point(earlier, plane) {
                    Ok(g) => [(estimate.pos[0] - g[0]) / dt, (estimate.pos[1] - g[1]) / dt],
                    Err(_) => [0.0, 0.0],
                }
            }
            _ => [0.0, 0.0],
        };
        // The box's longer side on the ground.
        let size = match point {
            ImagePoint::Box(b) => {
                let c = b.centre();
                let side = |p: [f64; 2], q: [f64; 2]| match (
                    camera.ground_point(p, plane),
                    camera.ground_point(q, plane),
                ) {
                    (Ok(a), Ok(b)) => (a[0] - b[0]).hypot(a[1] - b[1]),
                    _ => 0.0,
                };
                side([b.left, c[1]], [b.right(), c[1]]).max(side([c[0], b.top], [c[0], b.bottom()]))
            }
            ImagePoint::Point(_) => 0.0,
        };
        let mut fields: Vec<(&str, Value)> = vec![
            ("pos", Value::Vec2(estimate.pos)),
            ("vel", Value::Vec2(vel)),
            ("size", Value::Float(size)),
            ("pos_cov", list(&estimate.cov_entries())),
            ("border_px", Value::Float(self.border_px(point))),
        ];
        if let Some(score) = r.get("score") {
            fields.push(("score", score.clone()));
        }
        Some(record(r.id.as_deref(), fields))
    }
}

impl Unit for Georeference {
    fn synchronized(&self) -> bool {
        true
    }

    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        let Some(percepts) = input.value(0) else { return Ok(()) };
        let Some(pose) = input.values.get(1).and_then(Option::as_ref) else {
            self.without_pose += 1;
            self.stats.result("frames without a pose (left out)", self.without_pose);
            return Ok(());
        };
        let location = || format!("{} at {} us", input.names.get(1).map_or("poses", |n| n), pose.valid);
        let parsed = pose.value.as_record().ok_or("not a record".to_string()).and_then(pose_from_record);
        let camera = match parsed
            .and_then(|p| Camera::new(self.intrinsics, self.distortion, p).map_err(|e| e.to_string()))
        {
            Ok(camera) => camera,
            Err(e) => {
                self.malformed(location(), e);
                return Ok(());
            }
        };
        let Value::List(items) = percepts else {
            self.malformed(
                format!("{} at {} us", input.names.first().map_or("percepts", |n| n), input.valid),
                "not a list of percepts".into(),
            );
            return Ok(());
        };
        let dt_s = self.previous.as_ref().map(|(t, _)| (input.valid - t) as f64 / 1e6);
        let plane = self.ground_z + self.point_height;
        let geo = Georeferencer::new(&camera, self.noise, plane);
        let mut world = Vec::with_capacity(items.len());
        for item in items.iter() {
            let Some(r) = item.as_record() else { continue };
            let Some(point) = image_point(r) else {
                self.malformed(
                    format!("{} at {} us", input.names.first().map_or("percepts", |n| n), input.valid),
                    format!(
                        "`{}` has no `box` [left, top, width, height] or `pos` in pixels",
                        r.id.as_deref().unwrap_or("?")
                    ),
                );
                continue;
            };
            match self.world(&geo, r, &point, dt_s) {
                Some(w) => {
                    world.push(w);
                    self.georeferenced += 1;
                }
                None => self.not_on_ground += 1,
            }
        }
        self.stats.result("percepts georeferenced", self.georeferenced);
        if self.not_on_ground > 0 {
            self.stats.result("percepts whose pixel sees no ground (left out)", self.not_on_ground);
        }
        out.emit(Value::List(world.into()));
        out.emit_port("camera", input.valid, camera_record(&camera));
        self.previous = Some((input.valid, camera));
        Ok(())
    }
}

fn noise_params(ctx: &BuildContext<'_>) -> Result<PoseNoise, BuildError> {
    let gps = float_param(ctx, "gps_noise_m", 1.0);
    let noise = PoseNoise {
        position_sd: [gps, gps, float_param(ctx, "altitude_noise_m", 2.0)],
        attitude_sd: [float_param(ctx, "attitude_noise_deg", 0.5).to_radians(); 3],
        gimbal_sd: [float_param(ctx, "gimbal_noise_deg", 0.0).to_radians(); 2],
        ground_sd: float_param(ctx, "ground_sd_m", 0.0),
    };
    if !noise.is_valid() {
        return Err(ctx.error("the noise parameters must be finite numbers at least 0"));
    }
    Ok(noise)
}

fn lens_params(entry: Entry) -> Entry {
    entry
        .param(Param::optional("image_size", ParamType::List(Box::new(ParamType::Float)), list(&[1920.0, 1080.0]), "width and height of the image, pixels"))
        .param(Param::optional("hfov_deg", ParamType::Float, Value::Float(70.0), "horizontal field of view, degrees (square pixels, principal point at the centre), unless `focal_px` is given"))
        .param(Param::optional("focal_px", ParamType::List(Box::new(ParamType::Float)), list(&[]), "focal lengths [fx, fy], pixels (instead of `hfov_deg`)"))
        .param(Param::optional("principal_point", ParamType::List(Box::new(ParamType::Float)), list(&[]), "principal point [cx, cy], pixels (default: the image's centre)"))
        .param(Param::optional("distortion", ParamType::List(Box::new(ParamType::Float)), list(&[]), "lens distortion, OpenCV's [k1, k2, p1, p2, k3]"))
}

fn georeference_entry() -> Entry {
    let entry = Entry::new(
        EntryKind::Compute,
        "camera.georeference",
        "Image percepts (boxes or points in pixels) and the camera's pose, synchronized, to world percepts on the ground with their covariance.",
    )
    .input("percepts", TypeReq::Any, "image percepts: records with `box` [left, top, width, height] or `pos` in pixels (and `vel` in pixels per second)")
    .input("poses", TypeReq::Any, "the camera's pose: records with `position` [x, y, z] (metres), `attitude` [roll, pitch, yaw] and `gimbal` [pan, tilt] (degrees)")
    .output(TypeReq::Objects(vec![
        ("pos".into(), ValueType::Vec2),
        ("vel".into(), ValueType::Vec2),
        ("size".into(), ValueType::Float),
        ("pos_cov".into(), ValueType::List(Box::new(ValueType::Float))),
    ]))
    .port("camera", TypeReq::Any, "the camera at each state: pose and intrinsics, for `pixel`, `in_view` and `footprint`");
    lens_params(entry)
        .param(Param::optional("pixel_noise_px", ParamType::Float, Value::Float(2.0), "standard deviation of a percept's pixel, per axis"))
        .param(Param::optional("gps_noise_m", ParamType::Float, Value::Float(1.0), "standard deviation of the pose's position per horizontal axis, metres"))
        .param(Param::optional("altitude_noise_m", ParamType::Float, Value::Float(2.0), "standard deviation of the pose's height, metres"))
        .param(Param::optional("attitude_noise_deg", ParamType::Float, Value::Float(0.5), "standard deviation of roll, pitch and yaw, each, degrees"))
        .param(Param::optional("gimbal_noise_deg", ParamType::Float, Value::Float(0.0), "standard deviation of the gimbal's pan and tilt, each, degrees"))
        .param(Param::optional("ground_sd_m", ParamType::Float, Value::Float(0.0), "standard deviation of the ground's height, metres"))
        .param(Param::optional("ground_z", ParamType::Float, Value::Float(0.0), "height of the ground plane, metres"))
        .param(Param::optional("point", ParamType::Choice(vec!["centre".into(), "bottom".into()]), Value::str("centre"), "the point of a box taken to the ground: its centre (seen from above) or the middle of its bottom side (a person or a car seen from the side)"))
        .param(Param::optional("point_height_m", ParamType::Float, Value::Float(0.0), "height of that point above the ground (half a vehicle's height for the centre of its box), metres"))
}

fn build_georeference(
    ctx: &mut BuildContext<'_>,
) -> Result<Box<dyn kpl_runtime::process::AsyncUnit>, BuildError> {
    let (intrinsics, distortion) = lens(ctx)?;
    let noise = noise_params(ctx)?;
    let pixel_sd = float_param(ctx, "pixel_noise_px", 2.0);
    let point_height = float_param(ctx, "point_height_m", 0.0);
    let ground_z = float_param(ctx, "ground_z", 0.0);
    if !(pixel_sd.is_finite() && pixel_sd >= 0.0 && point_height.is_finite() && ground_z.is_finite()) {
        return Err(ctx.error("`pixel_noise_px` must be at least 0; `point_height_m` and `ground_z` finite"));
    }
    let point = match ctx.param("point").and_then(Value::as_str) {
        Some("bottom") => BoxPoint::Bottom,
        _ => BoxPoint::Centre,
    };
    Ok(Box::new(SyncUnit(Georeference {
        intrinsics,
        distortion,
        noise,
        pixel_sd,
        point,
        point_height,
        ground_z,
        previous: None,
        stats: ctx.stats.clone(),
        without_pose: 0,
        not_on_ground: 0,
        georeferenced: 0,
    })))
}

// ---------------------------------------------------------------------------------------------
// camera.homography

struct FixedCamera {
    homography: Homography,
    rms: f64,
    pixel_sd: f64,
    point: BoxPoint,
    stats: Arc<ProcessStats>,
    previous: HashMap<Arc<str>, (Time, [f64; 2])>,
    georeferenced: u64,
}

impl Unit for FixedCamera {
    fn on_input(&mut self, input: &Input<'_>, out: &mut Emitter) -> Result<(), ProcessError> {
        let Some(Value::List(items)) = input.trigger_value() else { return Ok(()) };
        let mut world = Vec::with_capacity(items.len());
        let mut seen = HashMap::with_capacity(items.len());
        for item in items.iter() {
            let Some(r) = item.as_record() else { continue };
            let Some(point) = image_point(r) else {
                self.stats.malformed(Malformed {
                    location: format!(
                        "{} at {} us",
                        input.names.first().map_or("percepts", |n| n),
                        input.valid
                    ),
                    error: format!("`{}` has no `box` or `pos` in pixels", r.id.as_deref().unwrap_or("?")),
                });
                continue;
            };
            let pixel = match (point, self.point) {
                (ImagePoint::Box(b), BoxPoint::Centre) => b.centre(),
                (ImagePoint::Box(b), BoxPoint::Bottom) => b.bottom_centre(),
                (ImagePoint::Point(p), _) => p,
            };
            let (Some(pos), Some(j)) = (self.homography.apply(pixel), self.homography.jacobian(pixel)) else {
                continue;
            };
            let cov = j * j.transpose() * (self.pixel_sd * self.pixel_sd)
                + kpl_camera::Matrix2::identity() * (self.rms * self.rms);
            let id: Arc<str> = r.id.clone().unwrap_or_else(|| Arc::from(""));
            let vel = match self.previous.get(&id) {
                Some(&(t, p)) if input.valid > t => {
                    let dt = (input.valid - t) as f64 / 1e6;
                    [(pos[0] - p[0]) / dt, (pos[1] - p[1]) / dt]
                }
                _ => [0.0, 0.0],
            };
            seen.insert(id, (input.valid, pos));
            world.push(record(
                r.id.as_deref(),
                vec![
                    ("pos", Value::Vec2(pos)),
                    ("vel", Value::Vec2(vel)),
                    ("size", Value::Float(0.0)),
                    ("pos_cov", list(&[cov[(0, 0)], cov[(0, 1)], cov[(1, 1)]])),
                ],
            ));
            self.georeferenced += 1;
        }
        self.previous = seen;
        self.stats.result("percepts georeferenced", self.georeferenced);
        out.emit(Value::List(world.into()));
        Ok(())
    }
}

fn homography_entry() -> Entry {
    Entry::new(
        EntryKind::Compute,
        "camera.homography",
        "A fixed camera calibrated from point pairs (pixel and ground point, at least four): image percepts to world percepts with their covariance.",
    )
    .input("percepts", TypeReq::Any, "image percepts: records with `box` [left, top, width, height] or `pos` in pixels")
    .output(TypeReq::Objects(vec![
        ("pos".into(), ValueType::Vec2),
        ("vel".into(), ValueType::Vec2),
        ("pos_cov".into(), ValueType::List(Box::new(ValueType::Float))),
    ]))
    .param(Param::required("pairs", ParamType::List(Box::new(ParamType::List(Box::new(ParamType::Float)))), "point pairs [u, v, x, y]: a pixel and the ground point it shows (metres), at least four"))
    .param(Param::optional("pixel_noise_px", ParamType::Float, Value::Float(2.0), "standard deviation of a percept's pixel, per axis"))
    .param(Param::optional("point", ParamType::Choice(vec!["centre".into(), "bottom".into()]), Value::str("bottom"), "the point of a box taken to the ground: the middle of its bottom side (where a person or a car seen from the side meets the ground) or its centre"))
}

fn build_homography(
    ctx: &mut BuildContext<'_>,
) -> Result<Box<dyn kpl_runtime::process::AsyncUnit>, BuildError> {
    let pairs: Vec<([f64; 2], [f64; 2])> = match ctx.param("pairs") {
        Some(Value::List(items)) => items
            .iter()
            .map(|p| match numbers(p).as_deref() {
                Some([u, v, x, y]) => Ok(([*u, *v], [*x, *y])),
                _ => Err(ctx.error("every pair is [u, v, x, y]: a pixel and its ground point")),
            })
            .collect::<Result<_, _>>()?,
        _ => return Err(ctx.error("`pairs` must be a list of [u, v, x, y]")),
    };
    let fit = Homography::estimate(&pairs).map_err(|e| ctx.error(e.to_string()))?;
    // The residual, in millimetres, as the run's result.
    ctx.stats.result("calibration pairs", pairs.len() as u64);
    ctx.stats.result("calibration residual, RMS (mm)", (fit.rms * 1000.0).round() as u64);
    ctx.stats.result("calibration residual, largest (mm)", (fit.max * 1000.0).round() as u64);
    let point = match ctx.param("point").and_then(Value::as_str) {
        Some("centre") => BoxPoint::Centre,
        _ => BoxPoint::Bottom,
    };
    Ok(Box::new(SyncUnit(FixedCamera {
        homography: fit.homography,
        rms: fit.rms,
        pixel_sd: float_param(ctx, "pixel_noise_px", 2.0),
        point,
        stats: ctx.stats.clone(),
        previous: HashMap::new(),
        georeferenced: 0,
    })))
}

// ---------------------------------------------------------------------------------------------
// sim.uav_camera

struct UavCamera {
    params: kpl_sim::Params,
    camera: CameraParams,
    traffic_seed: u64,
    network: Arc<kpl_roads::RoadNetwork>,
}

/// The image percepts of a frame as records `{id, box, pos, vel, score, class}`.
fn image_percepts(frame: &Frame, prefix: &str) -> Value {
    let Some(image) = &frame.image else { return Value::List(Vec::new().into()) };
    let percepts: Vec<Value> = image
        .percepts
        .iter()
        .map(|p| {
            let id = format!("{prefix}{}", p.id.0);
            record(
                Some(&id),
                vec![
                    ("box", list(&p.bbox.to_array())),
                    ("pos", Value::Vec2(p.bbox.centre())),
                    ("vel", Value::Vec2(p.vel)),
                    ("score", Value::Float(p.score)),
                    ("class", Value::Int(-1)),
                ],
            )
        })
        .collect();
    Value::List(percepts.into())
}

/// The ground truth of a camera frame: every vehicle's record with `visible` (in the image and
/// not hidden), `in_view` (in the image, hidden or not), `seen_as` and, in view, its `box`.
fn camera_truth(frame: &Frame, prefix: &str) -> Value {
    let Some(image) = &frame.image else { return Value::List(Vec::new().into()) };
    let mut seen_as = std::collections::BTreeMap::new();
    for p in &image.percepts {
        if let PerceptSource::Car(car) = p.source {
            seen_as.insert(car, format!("{prefix}{}", p.id.0));
        }
    }
    let records: Vec<Value> = frame
        .cars
        .iter()
        .zip(&frame.visibility)
        .zip(&image.boxes)
        .map(|((car, visibility), bbox)| {
            let mut record = car.to_record();
            record.fields.push(("visible".into(), Value::Bool(visibility.in_view())));
            record.fields.push(("in_view".into(), Value::Bool(bbox.is_some())));
            let seen = seen_as.get(&car.id).cloned().unwrap_or_default();
            record.fields.push(("seen_as".into(), Value::str(&seen)));
            if let Some(b) = bbox {
                record.fields.push(("box".into(), list(&b.to_array())));
            }
            Value::Record(Arc::new(record))
        })
        .collect();
    Value::List(records.into())
}

impl Source for UavCamera {
    fn run<'a>(&'a mut self, ctx: &'a mut SourceContext) -> BoxFuture<'a, Result<(), ProcessError>> {
        Box::pin(async move {
            let mut sim = UavTrackerSim::with_camera(
                &self.params,
                &self.camera,
                self.network.clone(),
                ctx.now(),
                self.traffic_seed,
            )
            .map_err(|e| ProcessError::failed(e.to_string()))?;
            let prefix = self.params.percept_prefix.clone();
            // The occluders as `sim.uav_tracker`'s `view` gives them (the image's own footprint
            // is the `camera`'s, `in_view`): for `visible(view, this)` in forget conditions.
            let view = crate::tracker::view_value(None, &crate::tracker::occluders_value(sim.occluders()));
            while !sim.finished() {
                if !ctx.wait_until(sim.next_frame_time()).await {
                    break;
                }
                let frame = sim.next_frame();
                for problem in sim.take_problems() {
                    ctx.malformed(problem.location, problem.error)?;
                }
                ctx.emit(frame.time, image_percepts(&frame, &prefix)).await;
                if let Some(image) = &frame.image {
                    ctx.emit_port(1, frame.time, pose_record(&image.reported_pose)).await;
                }
                ctx.emit_port(2, frame.time, camera_truth(&frame, &prefix)).await;
                ctx.emit_port(3, frame.time, view.clone()).await;
                if ctx.unconsumed() {
                    break;
                }
            }
            Ok(())
        })
    }

    fn ends_by_itself(&self) -> bool {
        self.params.traffic_file.is_some()
    }
}

/// The world tracker's parameters the camera mode has no use for.
const WORLD_ONLY: [&str; 7] = [
    "noise_m",
    "vel_noise_mps",
    "size_noise_m",
    "footprint",
    "footprint_size_m",
    "camera_path",
    "false_positive_on_road",
];

fn uav_camera_entry() -> Entry {
    let mut entry = Entry::new(
        EntryKind::Source,
        "sim.uav_camera",
        "The simulated tracker's camera mode: a UAV camera over the traffic; boxes in pixels, the reported pose, the ground truth.",
    )
    .output(TypeReq::Objects(vec![("box".into(), ValueType::List(Box::new(ValueType::Float))), ("pos".into(), ValueType::Vec2)]))
    .port("pose", TypeReq::Any, "the pose the UAV reports at each frame (with GPS and attitude noise): `position` [x, y, z] metres, `attitude` [roll, pitch, yaw] and `gimbal` [pan, tilt] degrees")
    .port("truth", TypeReq::Any, "ground truth per frame: every vehicle (as `sim.uav_tracker`'s), `visible`, `in_view` (in the image), `seen_as` and, in view, its true `box`")
    .port("view", TypeReq::Any, "the occluders per frame (`footprint` empty: the image's is the camera's), as `sim.uav_tracker`'s `view`, for `visible(view, pos)`");
    for info in kpl_sim::Params::describe().into_iter().filter(|i| !WORLD_ONLY.contains(&i.name)) {
        entry = entry.param(crate::tracker::param_from_info(&info));
    }
    for info in CameraParams::describe() {
        entry = entry.param(crate::tracker::param_from_info(&info));
    }
    entry
}

fn build_uav_camera(ctx: &mut BuildContext<'_>) -> Result<Box<dyn Source>, BuildError> {
    let camera_names: Vec<&str> = CameraParams::describe().iter().map(|i| i.name).collect();
    let (params, traffic_seed) = crate::tracker::params_where(ctx, |name| !camera_names.contains(&name))?;
    let mut camera_json = serde_json::Map::new();
    if let Some(call) = ctx.call() {
        for (name, value) in &call.params {
            if camera_names.contains(&name.as_str()) {
                camera_json.insert(name.clone(), value.to_json());
            }
        }
    }
    let camera = CameraParams::from_json(serde_json::Value::Object(camera_json))
        .map_err(|e| ctx.error(e.to_string()))?;
    let network = Arc::new(params.load_network().map_err(|e| ctx.error(e.to_string()))?);
    UavTrackerSim::with_camera(&params, &camera, network.clone(), 0, traffic_seed)
        .map_err(|e| ctx.error(e.to_string()))?;
    Ok(Box::new(UavCamera { params, camera, traffic_seed, network }))
}

// ---------------------------------------------------------------------------------------------
// Functions over a camera record

fn camera_functions() -> Vec<(kpl_semantic::registry::Function, kpl_mtl::Function)> {
    use ValueType::{Any, Bool, Vec2};
    let position = |v: &Value, func: &str| -> Result<[f64; 3], String> {
        match v {
            Value::Vec2(p) => Ok([p[0], p[1], 0.0]),
            Value::Record(r) => match r.get("pos") {
                Some(Value::Vec2(p)) => Ok([p[0], p[1], 0.0]),
                _ => Err(format!("{func} needs a position (vec2) or an object with `pos`")),
            },
            other => Err(format!("{func} needs a position (vec2), found {}", other.kind())),
        }
    };
    vec![
        (
            kpl_semantic::registry::Function::new(
                "pixel",
                vec![Any, Any],
                Vec2,
                "the pixel where a ground position appears in a camera (a `camera.georeference` `camera` sample)",
            ),
            kpl_mtl::Function::new("pixel", (2, Some(2)), move |a| {
                let camera = camera_from_record(&a[0], "pixel")?;
                let p = position(&a[1], "pixel")?;
                camera
                    .pixel_of(p)
                    .map(Value::Vec2)
                    .ok_or_else(|| "pixel: the position is behind the camera".to_string())
            }),
        ),
        (
            kpl_semantic::registry::Function::new(
                "in_view",
                vec![Any, Any],
                Bool,
                "whether a camera sees a ground position: in front of it and inside its image",
            ),
            kpl_mtl::Function::new("in_view", (2, Some(2)), move |a| {
                let camera = camera_from_record(&a[0], "in_view")?;
                Ok(Value::Bool(camera.sees(position(&a[1], "in_view")?)))
            }),
        ),
        (
            kpl_semantic::registry::Function::new(
                "footprint",
                vec![Any],
                Any,
                "the camera's footprint on the ground: a list of vec2 corners (within 5 km)",
            ),
            kpl_mtl::Function::new("footprint", (1, Some(1)), |a| {
                let camera = camera_from_record(&a[0], "footprint")?;
                let corners: Vec<Value> =
                    camera.footprint(0.0, FOOTPRINT_RANGE_M).into_iter().map(Value::Vec2).collect();
                Ok(Value::List(corners.into()))
            }),
        ),
    ]
}

/// How far from the camera the `footprint` function cuts an oblique view, metres.
const FOOTPRINT_RANGE_M: f64 = 5000.0;

pub(crate) fn register(registry: &mut kpl_runtime::Registry) {
    registry.add_unit(georeference_entry(), build_georeference);
    registry.add_unit(homography_entry(), build_homography);
    registry.add_source(uav_camera_entry(), build_uav_camera);
    for (signature, function) in camera_functions() {
        registry.add_function(signature, function);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_records_round_trip_and_functions_answer() {
        let k = Intrinsics::new(500.0, 500.0, 500.0, 400.0, 1000.0, 800.0).unwrap();
        let pose = Pose::new([10.0, 20.0, 100.0], Attitude::level(0.0), Gimbal::nadir());
        let camera = Camera::new(k, Distortion::default(), pose).unwrap();
        let value = camera_record(&camera);
        let back = camera_from_record(&value, "test").unwrap();
        assert!((back.pose().gimbal.tilt - pose.gimbal.tilt).abs() < 1e-12);
        assert_eq!(back.intrinsics(), camera.intrinsics());
        let functions = camera_functions();
        let call = |name: &str, args: &[Value]| {
            (functions.iter().find(|(s, _)| s.name == name).unwrap().1.body)(args)
        };
        assert_eq!(call("in_view", &[value.clone(), Value::vec2(10.0, 20.0)]), Ok(Value::Bool(true)));
        assert_eq!(call("in_view", &[value.clone(), Value::vec2(10.0, 200.0)]), Ok(Value::Bool(false)));
        let Ok(Value::Vec2(p)) = call("pixel", &[value.clone(), Value::vec2(30.0, 20.0)]) else { panic!() };
        assert!((p[0] - 500.0).abs() < 1e-9 && (p[1] - 300.0).abs() < 1e-9, "{p:?}");
        let Ok(Value::List(corners)) = call("footprint", &[value]) else { panic!() };
        assert_eq!(corners.len(), 4);
        assert!(call("in_view", &[Value::Int(1), Value::vec2(0.0, 0.0)]).is_err());
    }
}
