//! `degs import ecd`: a synthetic scene exported to the ECD layout and imported back is
//! the same scene; the real ECD sample's calibration and events import; poses are
//! interpolated and converted from OpenCV to OpenGL axes; bad files give errors naming
//! them.

mod common;
use common::*;
use glam::{DQuat, DVec3};
use import::ecd::{export_ecd, read_ecd};
use import::{ImportOptions, Layout, import};
use scene::image_io::{Image, write_png};
use scene::manifest::FrameEncoding;
use scene::{Pose, Scene};
use std::path::Path;

#[test]
fn synthetic_scene_round_trips_through_the_ecd_layout() {
    let dir = tempfile::tempdir().unwrap();
    let (orig, world) = tiny_scene(dir.path(), "synth");
    // Ground truth at 200 Hz as well as at the frame times, as ECD's motion capture.
    let extra: Vec<(f64, Pose)> = (0..=100)
        .map(|k| k as f64 * 0.005)
        .map(|t| (t, world.camera_at(t).cam_to_world))
        .collect();
    let ecd = dir.path().join("ecd");
    export_ecd(&orig, &extra, &ecd).unwrap();
    let gt_lines = std::fs::read_to_string(ecd.join("groundtruth.txt")).unwrap();
    assert_eq!(
        gt_lines.lines().count(),
        1 + 101 + 4,
        "header, 200 Hz, 4 test times"
    );

    let out = dir.path().join("back");
    let opts = ImportOptions {
        test_every: Some(2),
        frame_encoding: Some(FrameEncoding::Linear),
        ..Default::default()
    };
    let s = import(Layout::Ecd, &ecd, &opts, &out).unwrap();
    assert_eq!((s.frames, s.train_frames, s.test_frames), (9, 5, 4));
    assert_eq!((s.t_first, s.t_last), (0.0, 0.5));
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let back = Scene::open(&out).unwrap();
    assert_same_scene(&orig, &back, 1e-6);
    // The summary counts the events between consecutive frames.
    let c = s.events_per_interval.unwrap();
    assert!(c.min <= c.max && c.mean > 0.0);
    assert!(out.join("import.json").is_file());
}

#[test]
fn train_fps_thins_the_train_frames() {
    let dir = tempfile::tempdir().unwrap();
    let (orig, _) = tiny_scene(dir.path(), "synth");
    let ecd = dir.path().join("ecd");
    export_ecd(&orig, &[], &ecd).unwrap();
    let opts = ImportOptions {
        test_every: Some(2),
        train_fps: Some(4.0),
        ..Default::default()
    };
    let s = import(Layout::Ecd, &ecd, &opts, &dir.path().join("back")).unwrap();
    // Train candidates at 0, 1/8, …, 1/2 s; at 4 fps only 0, 1/4, 1/2 s remain.
    assert_eq!((s.train_frames, s.test_frames, s.dropped_frames), (3, 4, 2));
    let back = Scene::open(dir.path().join("back")).unwrap();
    let t: Vec<f64> = back.train.frames.iter().map(|f| f.timestamp).collect();
    assert_eq!(t, vec![0.0, 0.25, 0.5]);
    // The layout's default encoding (ECD frames are linear APS readouts).
    assert_eq!(back.train.frame_encoding, Some(FrameEncoding::Linear));
}

/// The real ECD sample (calib.txt, events.txt) plus frames and a ground truth made here:
/// the camera turning at the constant angular velocity of motion.txt.
fn real_sample_with_frames(dir: &Path) -> (std::path::PathBuf, DVec3) {
    let sample = testkit::testdata::shared_data("ecd_shapes_rotation");
    let src = dir.join("shapes");
    std::fs::create_dir_all(src.join("images")).unwrap();
    for f in ["calib.txt", "events.txt"] {
        std::fs::copy(sample.join(f), src.join(f)).unwrap();
    }
    let w: Vec<f64> = std::fs::read_to_string(sample.join("motion.txt"))
        .unwrap()
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    let omega = DVec3::new(w[0], w[1], w[2]);
    let mut images = String::new();
    // 2.25 s lies after the last event (2.1957 s): left out with a warning.
    for (k, t) in [2.1, 2.15, 2.19, 2.25].iter().enumerate() {
        let mut img = Image::new(240, 180, 1);
        img.data
            .iter_mut()
            .enumerate()
            .for_each(|(i, v)| *v = (i % 251) as f32 / 255.0);
        write_png(src.join(format!("images/frame_{k:08}.png")), &img).unwrap();
        images.push_str(&format!("{t} images/frame_{k:08}.png\n"));
    }
    std::fs::write(src.join("images.txt"), images).unwrap();
    // Two ground-truth samples: the rotation exp(ω·(t − 2.09)) about a fixed axis.
    let (t0, t1) = (2.09, 2.30);
    let q1 = DQuat::from_scaled_axis(omega * (t1 - t0));
    std::fs::write(
        src.join("groundtruth.txt"),
        format!(
            "# timestamp tx ty tz qx qy qz qw\n{t0} 0 0 0 0 0 0 1\n{t1} 0.21 0 0 {} {} {} {}\n",
            q1.x, q1.y, q1.z, q1.w
        ),
    )
    .unwrap();
    (src, omega)
}

#[test]
fn the_real_ecd_sample_imports_with_interpolated_converted_poses() {
    let dir = tempfile::tempdir().unwrap();
    let (src, omega) = real_sample_with_frames(dir.path());
    let rec = read_ecd(&src).unwrap();
    // calib.txt: fx fy cx cy k1 k2 p1 p2 k3, kept exactly.
    let k = rec.camera;
    assert_eq!((k.width, k.height), (240, 180));
    assert_eq!(
        (k.fx, k.fy, k.cx, k.cy),
        (199.092366542, 198.82882047, 132.192071378, 110.712660011)
    );
    let d = k.distortion.unwrap();
    assert_eq!(
        (d.k1, d.k2, d.p1, d.p2, d.k3),
        (
            -0.368436311798,
            0.150947243557,
            -0.000296130534385,
            -0.000759431726241,
            0.0
        )
    );
    assert_eq!(rec.events.len(), 20_000);
    assert_eq!(rec.frames.len(), 3);
    assert_eq!(rec.warnings.len(), 1);
    assert!(
        rec.warnings[0]
            .contains("1 of 4 frames lie more than half a frame interval outside the events"),
        "{:?}",
        rec.warnings
    );
    // Slerp between the two samples = constant angular velocity; translation lerps.
    let flip = DQuat::from_xyzw(1.0, 0.0, 0.0, 0.0);
    for f in &rec.frames {
        let s = f.timestamp - 2.09;
        let want = Pose::new(
            DQuat::from_scaled_axis(omega * s) * flip,
            DVec3::new(s, 0.0, 0.0),
        );
        let diff = pose_diff(&f.pose, &want);
        assert!(diff < 1e-9, "t={}: {diff:e}", f.timestamp);
        // OpenGL axes: the camera looks down −z, i.e. along OpenCV's +z.
        let fwd = f.pose.rotation * -DVec3::Z;
        let fwd_cv = DQuat::from_scaled_axis(omega * s) * DVec3::Z;
        assert!((fwd - fwd_cv).length() < 1e-9);
    }
    let out = dir.path().join("scene");
    let s = import::write_scene(&rec, &ImportOptions::default(), &out).unwrap();
    assert_eq!(
        (s.frames, s.train_frames, s.test_frames, s.events),
        (3, 3, 0, 20_000)
    );
    assert!(s.distortion);
    let scene = Scene::open(&out).unwrap();
    assert_eq!(scene.train.camera, k);
    assert_eq!(scene.load_events().unwrap(), rec.events);
    // The summary printed by `degs import`.
    let text = s.to_string();
    assert!(
        text.contains("240x180, with lens distortion") && text.contains("20000"),
        "{text}"
    );
}

#[test]
fn missing_and_bad_files_are_named() {
    let dir = tempfile::tempdir().unwrap();
    // The sample as shipped has no frames: the missing file is named.
    let sample = testkit::testdata::shared_data("ecd_shapes_rotation");
    let e = read_ecd(&sample).unwrap_err().to_string();
    assert!(e.contains("images.txt") && e.contains("missing"), "{e}");

    let (src, _) = real_sample_with_frames(dir.path());
    let gt = src.join("groundtruth.txt");
    let good = std::fs::read_to_string(&gt).unwrap();
    let cases: [(&str, &str, &str); 5] = [
        ("groundtruth.txt", "1 2 3\n", "line 1: 3 fields, expected 8"),
        (
            "groundtruth.txt",
            "2.0 0 0 0 0 0 0 0\n",
            "quaternion norm 0",
        ),
        (
            "groundtruth.txt",
            "2.0 0 0 0 0 0 0 1\n1.0 0 0 0 0 0 0 1\n",
            "line 2: timestamp 1 is not after",
        ),
        ("images.txt", "2.1 images/nope.png\n", "does not exist"),
        ("calib.txt", "0 1 2 3\n", "focal lengths"),
    ];
    for (file, text, want) in cases {
        let p = src.join(file);
        let before = std::fs::read(&p).unwrap();
        std::fs::write(&p, text).unwrap();
        let e = read_ecd(&src).unwrap_err().to_string();
        assert!(e.contains(file) && e.contains(want), "{file}: {e}");
        std::fs::write(&p, before).unwrap();
    }
    // Frames before the ground truth starts are left out, not extrapolated.
    std::fs::write(&gt, good.replace("2.09 0 0 0", "2.12 0 0 0")).unwrap();
    let rec = read_ecd(&src).unwrap();
    assert_eq!(rec.frames.len(), 2);
    assert!(
        rec.warnings
            .iter()
            .any(|w| w.contains("outside the ground truth"))
    );
    // A failed import leaves nothing behind.
    std::fs::write(src.join("events.txt"), "2.1 999 0 1\n").unwrap();
    let out = dir.path().join("never");
    let e = import(Layout::Ecd, &src, &ImportOptions::default(), &out)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("events.txt") && e.contains("outside the 240x180 sensor"),
        "{e}"
    );
    assert!(!out.exists());
}
