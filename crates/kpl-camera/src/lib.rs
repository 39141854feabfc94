//! Camera geometry for KPL, the layer between pixels and the world: a pinhole camera with its
//! intrinsics and optional lens distortion (Brown-Conrady, as OpenCV defines it), its pose (a
//! UAV's position and attitude with a gimbal, or a fixed pan-tilt camera), a pixel's point on the
//! ground plane and a world point's pixel, the camera's footprint on the ground, a homography
//! estimated from point pairs for a fixed camera, and the ground point's covariance propagated
//! from the pixel's and the pose's noise; and readers for the files trackers write
//! ([`formats`]: MOTChallenge, VisDrone, UA-DETRAC XML, COCO-style JSON). See `docs/camera.md`.
//!
//! Pure library: no clock, no runtime; time, where it matters, is an argument (a pose is the
//! pose at one valid time), and the only I/O is the readers' (bytes a caller gives them).
//!
//! ```
//! use kpl_camera::{Attitude, Camera, Distortion, Georeferencer, Gimbal, Intrinsics, Pose, PoseNoise};
//! let k = Intrinsics::from_fov(1920.0, 1080.0, 70f64.to_radians()).unwrap();
//! let pose = Pose::new([100.0, 50.0, 100.0], Attitude::level(0.0), Gimbal::nadir());
//! let camera = Camera::new(k, Distortion::default(), pose).unwrap();
//! let pixel = camera.pixel_of([120.0, 40.0, 0.0]).unwrap();          // a car's centre
//! let geo = Georeferencer::new(&camera, PoseNoise { attitude_sd: [0.5f64.to_radians(); 3], ..PoseNoise::default() }, 0.0);
//! let estimate = geo.ground(pixel, 2.0).unwrap();                      // back on the ground
//! assert!((estimate.pos[0] - 120.0).abs() < 1e-9 && (estimate.pos[1] - 40.0).abs() < 1e-9);
//! assert!(estimate.cov[(0, 0)] > 0.5, "0.5° of attitude noise at 100 m is about a metre");
//! ```
//!
//! Modules: [`intrinsics`], [`distortion`], [`pose`], [`camera`] (projection, ground
//! intersection, footprint), [`uncertainty`] (georeferencing with covariance), [`homography`],
//! [`boxes`] (boxes in pixels: IoU and distances), [`formats`] (trackers' files), [`error`].

pub mod boxes;
pub mod camera;
pub mod distortion;
pub mod error;
pub mod formats;
pub mod homography;
pub mod intrinsics;
pub mod pose;
pub mod uncertainty;

pub use boxes::PixelBox;
pub use camera::Camera;
pub use distortion::Distortion;
pub use error::{CameraError, GroundError};
pub use homography::{Fit, Homography, HomographyError};
pub use intrinsics::Intrinsics;
pub use pose::{Attitude, Gimbal, Pose};
pub use uncertainty::{Georeferencer, GroundEstimate, PoseNoise};
/// The 2 x 2 matrix of covariances (nalgebra's).
pub type Matrix2 = nalgebra::Matrix2<f64>;
