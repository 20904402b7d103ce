//! Helpers shared by the layout round-trip tests: a tiny synthetic scene and the
//! comparison of a scene with its re-import.
#![allow(dead_code)]

use scene::image_io::read_image;
use scene::{Pose, Scene};
use std::path::Path;
use synth::{SynthConfig, SynthWorld};

/// A 32×24, 0.5 s rigid scene: train frames at k/8 s (5), test frames halfway between
/// them (4), so the frames in time order alternate train, test, train, …
pub fn tiny_config() -> SynthConfig {
    SynthConfig {
        width: 32,
        height: 24,
        duration: 0.5,
        train_fps: 8.0,
        test_frames: 4,
        novel_angle_deg: 0.0,
        render_rate_hz: 400.0,
        frame_supersample: 1,
        supersample: 1,
        ..SynthConfig::preset("rigid").unwrap()
    }
}

/// The tiny scene seen from a camera that does not move (objects still move).
pub fn tiny_static_config() -> SynthConfig {
    let mut cfg = tiny_config();
    cfg.camera.sway = glam::DVec3::ZERO;
    cfg.camera.yaw_deg = 0.0;
    cfg.camera.pitch_deg = 0.0;
    cfg
}

/// Write the tiny scene under `dir/name`; returns it opened, and its world.
pub fn tiny_scene(dir: &Path, name: &str) -> (Scene, SynthWorld) {
    write_scene(dir, name, &tiny_config())
}

/// Write the scene of `cfg` under `dir/name`; returns it opened, and its world.
pub fn write_scene(dir: &Path, name: &str, cfg: &SynthConfig) -> (Scene, SynthWorld) {
    let cfg = cfg.clone();
    let out = dir.join(name);
    synth::write_synthetic_scene(&cfg, &out).unwrap();
    (Scene::open(&out).unwrap(), SynthWorld::new(&cfg).unwrap())
}

/// Largest absolute difference between two poses' 4×4 matrices.
pub fn pose_diff(a: &Pose, b: &Pose) -> f64 {
    (a.matrix() - b.matrix())
        .to_cols_array()
        .iter()
        .fold(0.0f64, |m, v| m.max(v.abs()))
}

/// `back` has the same camera (intrinsics exactly, poses to `tol`), the same frames
/// (timestamps and `time` bit for bit, pixels exactly) in each split, and the same events.
pub fn assert_same_scene(orig: &Scene, back: &Scene, tol: f64) {
    assert_eq!(orig.train.camera, back.train.camera);
    for (a, b) in [(&orig.train, &back.train), (&orig.test, &back.test)] {
        assert_eq!(a.frames.len(), b.frames.len());
        for (fa, fb) in a.frames.iter().zip(&b.frames) {
            assert_eq!(
                fa.timestamp.to_bits(),
                fb.timestamp.to_bits(),
                "{}",
                fa.file_path
            );
            assert_eq!(fa.time.to_bits(), fb.time.to_bits(), "{}", fa.file_path);
            let d = pose_diff(&fa.cam_to_world, &fb.cam_to_world);
            assert!(d <= tol, "{}: pose differs by {d:e}", fa.file_path);
            let (ia, ib) = (
                read_image(orig.image_path(fa)).unwrap(),
                read_image(back.image_path(fb)).unwrap(),
            );
            assert_eq!(ia, ib, "{} vs {}", fa.file_path, fb.file_path);
        }
    }
    let (ea, eb) = (orig.load_events().unwrap(), back.load_events().unwrap());
    assert!(ea.len() > 100, "the scene should have events");
    assert_eq!(ea, eb);
}
