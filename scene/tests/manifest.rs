//! Scene manifest: round trip, accepted variants and every validation error.

use glam::{DMat4, DVec3};
use scene::camera::{Distortion, Intrinsics, Pose};
use scene::events::EventStream;
use scene::image_io::{Image, write_png};
use scene::manifest::{EventsRef, Frame, Manifest, Scene};
use std::path::Path;

fn camera() -> Intrinsics {
    Intrinsics {
        width: 8,
        height: 6,
        fx: 10.25,
        fy: 10.5,
        cx: 3.5,
        cy: 2.5,
        distortion: None,
    }
}

fn frames(n: usize) -> Vec<Frame> {
    (0..n)
        .map(|i| Frame {
            file_path: format!("images/{i:03}.png"),
            timestamp: 1.5 + 0.1 * i as f64,
            time: i as f64 / (n.max(2) - 1) as f64,
            cam_to_world: Pose::look_at(
                DVec3::new(i as f64 * 0.3, 0.2, 3.0),
                DVec3::ZERO,
                DVec3::Y,
            ),
        })
        .collect()
}

fn manifest(n: usize) -> Manifest {
    Manifest {
        camera: camera(),
        frames: frames(n),
        events: Some(EventsRef {
            path: "events.evs".into(),
            contrast_threshold: 0.17,
        }),
        frame_encoding: None,
    }
}

/// A complete scene directory with images of the camera's size and an event file.
fn write_scene(dir: &Path, n_train: usize) -> Manifest {
    let m = manifest(n_train);
    for f in &m.frames {
        let mut img = Image::new(8, 6, 3);
        img.data[0] = 1.0;
        write_png(dir.join(&f.file_path), &img).unwrap();
    }
    m.write(dir.join("transforms_train.json")).unwrap();
    let test = Manifest {
        frames: frames(1),
        events: None,
        ..m.clone()
    };
    test.write(dir.join("transforms_test.json")).unwrap();
    let mut ev = EventStream::new(8, 6);
    ev.push(1.5, 1, 2, 1);
    ev.push(1.6, 7, 5, -1);
    scene::formats::write_evs(dir.join("events.evs"), &ev).unwrap();
    m
}

fn assert_pose_close(a: &Pose, b: &Pose) {
    let d = (a.matrix() - b.matrix()).abs().to_cols_array();
    let max = d.iter().cloned().fold(0.0, f64::max);
    assert!(max < 1e-12, "poses differ by {max}");
}

fn err_text(r: scene::Result<impl std::fmt::Debug>) -> String {
    r.expect_err("expected an error").to_string()
}

#[test]
fn round_trip_keeps_every_field() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("transforms_train.json");
    let mut m = manifest(3);
    m.camera.distortion = Some(Distortion {
        k1: -0.1,
        k2: 0.01,
        p1: 1e-4,
        p2: -2e-4,
        k3: 0.0,
    });
    m.write(&path).unwrap();
    let r = Manifest::read(&path).unwrap();
    assert_eq!(r.camera, m.camera);
    assert_eq!(r.events, m.events);
    assert_eq!(r.frames.len(), 3);
    for (a, b) in r.frames.iter().zip(&m.frames) {
        assert_eq!(a.file_path, b.file_path);
        assert_eq!(a.timestamp.to_bits(), b.timestamp.to_bits());
        assert_eq!(a.time.to_bits(), b.time.to_bits());
        assert_pose_close(&a.cam_to_world, &b.cam_to_world);
    }
    // Writing what was read gives the same manifest again.
    let path2 = dir.path().join("again.json");
    r.write(&path2).unwrap();
    let r2 = Manifest::read(&path2).unwrap();
    assert_eq!(r2.camera, r.camera);
    for (a, b) in r2.frames.iter().zip(&r.frames) {
        assert_pose_close(&a.cam_to_world, &b.cam_to_world);
    }
    // The file is in the documented layout.
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert_eq!(v["camera"]["w"], 8);
    assert_eq!(v["camera"]["fl_y"], 10.5);
    assert_eq!(v["camera"]["k1"], -0.1);
    assert_eq!(v["events"]["contrast_threshold"], 0.17);
    let row0 = &v["frames"][1]["transform_matrix"][0];
    let m1 = m.frames[1].cam_to_world.matrix();
    assert!((row0[3].as_f64().unwrap() - m1.col(3).x).abs() < 1e-15);
    assert!((row0[0].as_f64().unwrap() - m1.col(0).x).abs() < 1e-15);
}

#[test]
fn camera_angle_x_form_takes_the_size_from_the_image() {
    let dir = tempfile::tempdir().unwrap();
    write_png(dir.path().join("r_000.png"), &Image::new(20, 10, 3)).unwrap();
    let json = r#"{"camera_angle_x": 0.6911112070083618,
        "frames": [{"file_path": "./r_000", "time": 0.0,
                    "transform_matrix": [[1,0,0,0.5],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}]}"#;
    let path = dir.path().join("transforms_train.json");
    std::fs::write(&path, json).unwrap();
    let m = Manifest::read(&path).unwrap();
    let want = Intrinsics::from_fov_x(20, 10, 0.6911112070083618);
    assert_eq!(m.camera, want);
    assert_eq!((m.camera.width, m.camera.height), (20, 10));
    assert!((m.camera.fx - 10.0 / (0.6911112070083618f64 / 2.0).tan()).abs() < 1e-12);
    assert_eq!(m.camera.cx, 9.5);
    // No timestamp: the normalised time stands in for it.
    assert_eq!(m.frames[0].timestamp, 0.0);
    assert_eq!(
        m.frames[0].cam_to_world.translation,
        DVec3::new(0.5, 0.0, 4.0)
    );
    assert!(m.events.is_none());
    // Extension-less file_path resolves to .png, so the scene opens.
    let scene = Scene::open(dir.path()).unwrap();
    assert_eq!(
        scene.image_path(&scene.train.frames[0]),
        dir.path().join("./r_000.png")
    );
    assert!(scene.test.frames.is_empty());
    assert_eq!(scene.contrast_threshold(), 0.1);
}

#[test]
fn nerfstudio_top_level_camera_with_distortion() {
    let dir = tempfile::tempdir().unwrap();
    let json = r#"{"w": 240, "h": 180, "fl_x": 199.0923, "fl_y": 198.8288,
        "cx": 132.192, "cy": 110.7126, "k1": -0.368436, "k2": 0.150947,
        "p1": -0.000296, "p2": -0.000759, "k3": 0.0, "aabb_scale": 16,
        "frames": [], "events": {"path": "ev.txt"}}"#;
    let path = dir.path().join("t.json");
    std::fs::write(&path, json).unwrap();
    let m = Manifest::read(&path).unwrap();
    assert_eq!(m.camera.width, 240);
    assert_eq!(m.camera.fy, 198.8288);
    assert_eq!(m.camera.cx, 132.192);
    let d = m.camera.distortion.unwrap();
    assert_eq!(
        (d.k1, d.k2, d.p1, d.p2, d.k3),
        (-0.368436, 0.150947, -0.000296, -0.000759, 0.0)
    );
    assert_eq!(m.events.unwrap().contrast_threshold, 0.1);
}

#[test]
fn scene_opens_loads_events_and_interpolates_poses() {
    let dir = tempfile::tempdir().unwrap();
    let m = write_scene(dir.path(), 4);
    let scene = Scene::open(dir.path()).unwrap();
    assert_eq!(scene.train.frames.len(), 4);
    assert_eq!(scene.test.frames.len(), 1);
    assert_eq!(scene.contrast_threshold(), 0.17);
    let ev = scene.load_events().unwrap();
    assert_eq!(ev.len(), 2);
    assert_eq!((ev.x[1], ev.y[1], ev.p[1]), (7, 5, -1));
    let traj = scene.train_trajectory();
    assert_eq!(traj.times.len(), 4);
    for f in &m.frames {
        assert_pose_close(&traj.pose_at(f.timestamp), &f.cam_to_world);
    }
    // Halfway between frames 1 and 2 the centre is halfway between theirs.
    let mid = traj.pose_at(0.5 * (m.frames[1].timestamp + m.frames[2].timestamp));
    let want = 0.5 * (m.frames[1].cam_to_world.translation + m.frames[2].cam_to_world.translation);
    assert!((mid.translation - want).length() < 1e-12);
}

fn write_raw(dir: &Path, json: &str) -> std::path::PathBuf {
    let p = dir.join("transforms_train.json");
    std::fs::write(&p, json).unwrap();
    p
}

const CAM: &str = r#""camera": {"w": 8, "h": 6, "fl_x": 10, "fl_y": 10, "cx": 3.5, "cy": 2.5}"#;
const ID: &str = "[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]";

#[test]
fn unsorted_timestamps_name_the_frame() {
    let dir = tempfile::tempdir().unwrap();
    let p = write_raw(
        dir.path(),
        &format!(
            r#"{{{CAM}, "frames": [
            {{"file_path": "a.png", "timestamp": 1.0, "time": 0.0, "transform_matrix": {ID}}},
            {{"file_path": "b.png", "timestamp": 2.0, "time": 0.5, "transform_matrix": {ID}}},
            {{"file_path": "c.png", "timestamp": 2.0, "time": 1.0, "transform_matrix": {ID}}}]}}"#
        ),
    );
    let e = err_text(Manifest::read(&p));
    assert!(
        e.contains("transforms_train.json") && e.contains("frame 2"),
        "{e}"
    );
    assert!(
        e.contains("frame 2 (c.png) at 2 s is not after frame 1 (b.png) at 2 s"),
        "{e}"
    );
}

#[test]
fn non_rigid_pose_names_the_frame() {
    let dir = tempfile::tempdir().unwrap();
    let scaled = "[[1.001,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]";
    let p = write_raw(
        dir.path(),
        &format!(
            r#"{{{CAM}, "frames": [
            {{"file_path": "a.png", "timestamp": 1.0, "time": 0.0, "transform_matrix": {ID}}},
            {{"file_path": "b.png", "timestamp": 2.0, "time": 1.0, "transform_matrix": {scaled}}}]}}"#
        ),
    );
    let e = err_text(Manifest::read(&p));
    assert!(e.contains("frame 1") && e.contains("orthonormal"), "{e}");
    // A tiny deviation within 1e-4 is accepted.
    let p = write_raw(
        dir.path(),
        &format!(
            r#"{{{CAM}, "frames": [{{"file_path": "a.png", "timestamp": 1.0, "time": 0.0,
            "transform_matrix": [[1.00001,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}}]}}"#
        ),
    );
    assert!(Manifest::read(&p).is_ok());
    // A reflection is not a pose.
    let p = write_raw(
        dir.path(),
        &format!(
            r#"{{{CAM}, "frames": [{{"file_path": "a.png", "timestamp": 1.0, "time": 0.0,
            "transform_matrix": [[-1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}}]}}"#
        ),
    );
    let e = err_text(Manifest::read(&p));
    assert!(e.contains("frame 0") && e.contains("reflection"), "{e}");
}

#[test]
fn field_errors_are_reported() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        // time outside [0, 1]
        (
            format!(
                r#"{{{CAM}, "frames": [{{"file_path": "a.png", "timestamp": 1.0, "time": 1.5, "transform_matrix": {ID}}}]}}"#
            ),
            "outside [0, 1]",
        ),
        // no camera
        (r#"{"frames": []}"#.to_string(), "camera needs"),
        // zero focal length
        (
            r#"{"camera": {"w": 8, "h": 6, "fl_x": 0}, "frames": []}"#.to_string(),
            "focal",
        ),
        // empty sensor
        (
            r#"{"camera": {"w": 0, "h": 6, "fl_x": 5}, "frames": []}"#.to_string(),
            "empty",
        ),
        // bad contrast threshold
        (
            format!(
                r#"{{{CAM}, "frames": [], "events": {{"path": "e.txt", "contrast_threshold": -0.1}}}}"#
            ),
            "contrast_threshold",
        ),
        // not JSON at all / truncated
        (
            format!(r#"{{{CAM}, "frames": [{{"file_path": "#),
            "not a valid manifest",
        ),
        (String::new(), "not a valid manifest"),
        // a 3x4 matrix
        (
            format!(
                r#"{{{CAM}, "frames": [{{"file_path": "a.png", "time": 0.0, "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0]]}}]}}"#
            ),
            "not a valid manifest",
        ),
    ];
    for (json, want) in cases {
        let p = write_raw(dir.path(), &json);
        let e = err_text(Manifest::read(&p));
        assert!(
            e.contains("transforms_train.json") && e.contains(want),
            "{json}\n→ {e}"
        );
    }
    let e = err_text(Manifest::read(dir.path().join("missing.json")));
    assert!(e.contains("missing.json"), "{e}");

    // The writer refuses what JSON cannot hold, and writes nothing.
    let mut m = manifest(3);
    m.frames[2].timestamp = f64::NAN;
    let out = dir.path().join("nan.json");
    let e = err_text(m.write(&out));
    assert!(e.contains("nan.json") && e.contains("frame 2"), "{e}");
    let mut m = manifest(1);
    m.camera.fx = f64::INFINITY;
    assert!(err_text(m.write(&out)).contains("non-finite"));
    assert!(!out.exists());
}

#[test]
fn scene_open_checks_images_and_events() {
    // Missing image.
    let dir = tempfile::tempdir().unwrap();
    write_scene(dir.path(), 3);
    std::fs::remove_file(dir.path().join("images/002.png")).unwrap();
    let e = err_text(Scene::open(dir.path()));
    assert!(
        e.contains("transforms_train.json")
            && e.contains("frame 2")
            && e.contains("does not exist"),
        "{e}"
    );

    // Image of the wrong size.
    let dir = tempfile::tempdir().unwrap();
    write_scene(dir.path(), 3);
    write_png(dir.path().join("images/001.png"), &Image::new(9, 6, 3)).unwrap();
    let e = err_text(Scene::open(dir.path()));
    assert!(
        e.contains("frame 1") && e.contains("9x6") && e.contains("8x6"),
        "{e}"
    );

    // Not an image at all.
    std::fs::write(dir.path().join("images/001.png"), b"garbage").unwrap();
    let e = err_text(Scene::open(dir.path()));
    assert!(e.contains("frame 1") && e.contains("cannot read"), "{e}");

    // Missing events file.
    let dir = tempfile::tempdir().unwrap();
    write_scene(dir.path(), 2);
    std::fs::remove_file(dir.path().join("events.evs")).unwrap();
    let e = err_text(Scene::open(dir.path()));
    assert!(
        e.contains("events.evs") && e.contains("does not exist"),
        "{e}"
    );

    // Test camera of another size.
    let dir = tempfile::tempdir().unwrap();
    let m = write_scene(dir.path(), 2);
    let mut other = m.clone();
    other.camera.width = 16;
    other.frames.clear();
    other
        .write(dir.path().join("transforms_test.json"))
        .unwrap();
    let e = err_text(Scene::open(dir.path()));
    assert!(
        e.contains("transforms_test.json") && e.contains("16x6"),
        "{e}"
    );

    // No train frames; no directory.
    let dir = tempfile::tempdir().unwrap();
    Manifest {
        frames: vec![],
        ..manifest(0)
    }
    .write(dir.path().join("transforms_train.json"))
    .unwrap();
    assert!(err_text(Scene::open(dir.path())).contains("no frames"));
    assert!(err_text(Scene::open(dir.path().join("nope"))).contains("does not exist"));

    // Events whose sensor differs from the camera.
    let dir = tempfile::tempdir().unwrap();
    write_scene(dir.path(), 2);
    let mut ev = EventStream::new(16, 6);
    ev.push(1.5, 12, 2, 1);
    scene::formats::write_evs(dir.path().join("events.evs"), &ev).unwrap();
    let scene = Scene::open(dir.path()).unwrap();
    let e = err_text(scene.load_events());
    assert!(e.contains("events.evs") && e.contains("16x6"), "{e}");
}

#[test]
fn manifest_matrix_is_rows_of_camera_to_world() {
    // transform_matrix rows: the camera centre is the last column.
    let dir = tempfile::tempdir().unwrap();
    let p = write_raw(
        dir.path(),
        &format!(
            r#"{{{CAM}, "frames": [{{"file_path": "a.png", "timestamp": 0.25, "time": 0.0,
            "transform_matrix": [[0,-1,0,1],[1,0,0,2],[0,0,1,3],[0,0,0,1]]}}]}}"#
        ),
    );
    let m = Manifest::read(&p).unwrap();
    let pose = m.frames[0].cam_to_world;
    assert_eq!(pose.translation, DVec3::new(1.0, 2.0, 3.0));
    // Camera +X maps to world +Y (first column of the rotation).
    assert!((pose.to_world(DVec3::X) - DVec3::new(1.0, 3.0, 3.0)).length() < 1e-12);
    let want = DMat4::from_cols_array_2d(&[
        [0.0, 1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [1.0, 2.0, 3.0, 1.0],
    ]);
    assert!(
        (pose.matrix() - want)
            .abs()
            .to_cols_array()
            .iter()
            .all(|&d| d < 1e-12)
    );
}

#[test]
fn frame_encoding_round_trips_and_an_unknown_one_names_the_file() {
    use scene::manifest::FrameEncoding;
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("transforms_train.json");
    for enc in [None, Some(FrameEncoding::Srgb), Some(FrameEncoding::Linear)] {
        let m = Manifest {
            frame_encoding: enc,
            ..manifest(2)
        };
        m.write(&p).unwrap();
        assert_eq!(Manifest::read(&p).unwrap().frame_encoding, enc);
    }
    let text = std::fs::read_to_string(&p).unwrap();
    std::fs::write(&p, text.replace("\"linear\"", "\"gamma22\"")).unwrap();
    let e = Manifest::read(&p).unwrap_err().to_string();
    assert!(
        e.contains("transforms_train.json") && e.contains("gamma22"),
        "{e}"
    );
}

#[test]
fn the_novel_split_is_read_when_present_and_checked_like_the_test_split() {
    // Absent: empty, with the train camera and encoding.
    let dir = tempfile::tempdir().unwrap();
    let m = write_scene(dir.path(), 3);
    let scene = Scene::open(dir.path()).unwrap();
    assert!(scene.novel.frames.is_empty());
    assert_eq!(scene.novel.camera, m.camera);
    assert_eq!(scene.novel.frame_encoding, m.frame_encoding);

    // Present: two frames off the train path, their images checked.
    let mut novel = Manifest {
        frames: frames(2),
        events: None,
        ..m.clone()
    };
    for f in &mut novel.frames {
        f.cam_to_world.translation.x += 0.5;
    }
    novel
        .write(dir.path().join(scene::manifest::NOVEL_FILE))
        .unwrap();
    let scene = Scene::open(dir.path()).unwrap();
    assert_eq!(scene.novel.frames.len(), 2);
    for (a, b) in scene.novel.frames.iter().zip(&novel.frames) {
        assert_eq!(a.file_path, b.file_path);
        assert_pose_close(&a.cam_to_world, &b.cam_to_world);
    }
    assert_eq!(scene.novel.frames[1].timestamp, 1.6);
    assert_eq!(scene.test.frames.len(), 1);

    // A novel frame whose image is missing names the novel file and the frame.
    let mut missing = novel.clone();
    missing.frames[1].file_path = "images/novel_0001.png".into();
    missing
        .write(dir.path().join("transforms_novel.json"))
        .unwrap();
    let e = err_text(Scene::open(dir.path()));
    assert!(
        e.contains("transforms_novel.json")
            && e.contains("frame 1")
            && e.contains("novel_0001.png"),
        "{e}"
    );

    // A corrupt novel manifest is an error naming that file.
    std::fs::write(dir.path().join("transforms_novel.json"), "{\"frames\": [").unwrap();
    let e = err_text(Scene::open(dir.path()));
    assert!(
        e.contains("transforms_novel.json") && e.contains("not a valid manifest"),
        "{e}"
    );

    // A novel camera of another size.
    let mut other = novel.clone();
    other.camera.height = 7;
    other
        .write(dir.path().join("transforms_novel.json"))
        .unwrap();
    let e = err_text(Scene::open(dir.path()));
    assert!(
        e.contains("transforms_novel.json") && e.contains("8x7"),
        "{e}"
    );
}
