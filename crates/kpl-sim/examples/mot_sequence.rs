//! Writes a traffic camera's sequence in MOTChallenge's files: the simulated camera mode on a mast
//! at a junction of the SUMO grid (specs/traffic/sumo/grid), 25 frames per second. `tracker.txt`
//! is what its image tracker reports (boxes with ids that fragment: a track missed for more than
//! two frames, or covered by a nearer vehicle, comes back under a new id), `gt.txt` the true boxes
//! of every vehicle in the image (covered ones too, with visibility 0; MOTChallenge's layout:
//! `frame, id, left, top, width, height, 1, class 3 (car), visibility`), and `seqinfo.ini` the
//! sequence's length and frame rate. specs/mot/ ships the output:
//!
//! `cargo run -p kpl-sim --example mot_sequence -- specs/mot`

#![allow(clippy::print_stderr, reason = "an example that says what it wrote")]

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::Arc;

use kpl_sim::{CameraParams, Params, PerceptSource, UavTrackerSim, Visibility};

/// The sequence: 20 s of the recording from 100 s on (when the grid is busy).
const FROM_S: f64 = 100.0;
const SECONDS: f64 = 20.0;
const FPS: f64 = 25.0;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = PathBuf::from(std::env::args().nth(1).ok_or("usage: mot_sequence OUT_DIR")?);
    let grid = concat!(env!("CARGO_MANIFEST_DIR"), "/../../specs/traffic/sumo/grid");
    let params = Params {
        network_file: Some(format!("{grid}/net.xml.gz")),
        traffic_file: Some(format!("{grid}/fcd.xml.gz")),
        seed: 11,
        rate_hz: FPS,
        dropout: 0.08,
        max_gap_frames: 2,
        false_positive_rate: 0.5,
        false_positive_duration_s: 0.3,
        ..Params::default()
    };
    // A camera 12 m up a mast south-west of junction B1, looking north-east at it.
    let camera = CameraParams {
        image_size: vec![1920.0, 1080.0],
        hfov_deg: 60.0,
        centre: vec![165.0, 170.0],
        altitude_m: 12.0,
        heading_deg: 40.0,
        tilt_deg: 20.0,
        pixel_noise_px: 2.0,
        gps_noise_m: 0.0,
        altitude_noise_m: 0.0,
        attitude_noise_deg: 0.0,
        min_box_px: 8.0,
        covered_fraction: 0.5,
        id_switch_prob: 0.002,
        ..CameraParams::default()
    };
    let network = Arc::new(params.load_network()?);
    let mut sim = UavTrackerSim::with_camera(&params, &camera, network, 0, params.seed)?;
    let all = sim.frames_until(((FROM_S + SECONDS - 1.0 / FPS) * 1e6).round() as i64);
    let skip = (FROM_S * FPS).round() as usize;
    let frames = &all[skip.min(all.len())..];
    let (mut tracker, mut gt) = (String::new(), String::new());
    for (k, frame) in frames.iter().enumerate() {
        let number = k + 1;
        let Some(image) = &frame.image else { continue };
        for p in &image.percepts {
            let b = p.bbox;
            writeln!(
                tracker,
                "{number},{},{:.2},{:.2},{:.2},{:.2},{:.3},-1,-1,-1",
                p.id.0, b.left, b.top, b.width, b.height, p.score
            )?;
        }
        for ((car, visibility), bbox) in frame.cars.iter().zip(&frame.visibility).zip(&image.boxes) {
            let Some(b) = bbox else { continue };
            let visible = if matches!(visibility, Visibility::Occluded) { 0.0 } else { 1.0 };
            writeln!(
                gt,
                "{number},{},{:.2},{:.2},{:.2},{:.2},1,3,{visible}",
                car.id.0 + 1,
                b.left,
                b.top,
                b.width,
                b.height
            )?;
        }
        let _ = PerceptSource::FalsePositive;
    }
    let info = format!(
        "[Sequence]\nname=kpl-grid-junction\nimDir=img1\nframeRate={FPS}\nseqLength={}\nimWidth=1920\nimHeight=1080\nimExt=.jpg\n",
        frames.len()
    );
    std::fs::create_dir_all(&out)?;
    std::fs::write(out.join("tracker.txt"), tracker)?;
    std::fs::write(out.join("gt.txt"), gt)?;
    std::fs::write(out.join("seqinfo.ini"), info)?;
    eprintln!("wrote {} frames to {}", frames.len(), out.display());
    Ok(())
}
