//! `degs import aedat4`: the real DAVIS346 sample becomes a scene with its 4 APS frames
//! and its 6,676 events once the static camera is accepted; without it, a clear refusal.

use import::{ImportOptions, Layout, import};
use scene::Scene;
use scene::image_io::read_image;
use scene::manifest::FrameEncoding;

#[test]
fn the_sample_imports_with_its_frames_and_events() {
    let file = testkit::testdata::shared_data("aedat4_sample/sample.aedat4");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("scene");
    let e = import(Layout::Aedat4, &file, &ImportOptions::default(), &out)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("sample.aedat4") && e.contains("--static-camera") && e.contains("4 frames"),
        "{e}"
    );
    assert!(!out.exists());

    let opts = ImportOptions {
        static_camera: true,
        test_every: Some(4),
        ..Default::default()
    };
    let s = import(Layout::Aedat4, &file, &opts, &out).unwrap();
    assert_eq!(
        (s.frames, s.train_frames, s.test_frames, s.events),
        (4, 3, 1, 6_676)
    );
    assert_eq!((s.width, s.height), (346, 260));
    assert_eq!(s.warnings.len(), 2, "{:?}", s.warnings);
    assert!(s.warnings[0].contains("identity pose") && s.warnings[1].contains("--calib"));
    // 40 ms between frames; the events run 3.65 ms after the first frame to 0.17 s.
    assert!((s.t_last - s.t_first - 0.12).abs() < 1e-6);
    let scene = Scene::open(&out).unwrap();
    assert_eq!(scene.train.frame_encoding, Some(FrameEncoding::Linear));
    assert!(
        scene
            .train
            .frames
            .iter()
            .all(|f| f.cam_to_world == scene::Pose::default())
    );
    assert_eq!(scene.train.camera.fx, 346.0);
    assert_eq!(scene.load_events().unwrap().len(), 6_676);
    // The frames are the APS pixels exactly (grey, replicated to RGB by the reader).
    let aps = scene::formats::read_aedat4_frames(&file).unwrap();
    let img = read_image(scene.image_path(&scene.train.frames[1])).unwrap();
    let want: Vec<f32> = aps[1]
        .pixels
        .iter()
        .flat_map(|&p| [p as f32 / 255.0; 3])
        .collect();
    assert_eq!(img.data, want);
    assert_eq!(scene.test.frames[0].timestamp, aps[3].timestamp);
}
