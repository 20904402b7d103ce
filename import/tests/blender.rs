//! `degs import blender`: a synthetic scene written as D-NeRF transforms (camera_angle_x,
//! frames with only a normalised time, no extension) plus events.evs, imported back.

mod common;
use common::*;
use import::EventsAlignment;
use import::blender::export_blender;
use import::{ImportOptions, Layout, import};
use scene::Scene;
use scene::image_io::read_image;

#[test]
fn synthetic_scene_round_trips_through_the_blender_layout() {
    let dir = tempfile::tempdir().unwrap();
    let (orig, _) = tiny_scene(dir.path(), "synth");
    let src = dir.path().join("dnerf");
    export_blender(&orig, 0.0, 0.5, &src).unwrap();
    let text = std::fs::read_to_string(src.join("transforms_train.json")).unwrap();
    assert!(text.contains("camera_angle_x") && !text.contains("timestamp"));

    let out = dir.path().join("back");
    let opts = ImportOptions {
        alignment: EventsAlignment {
            events: None,
            time_offset: Some(0.0),
            duration: Some(0.5),
        },
        ..Default::default()
    };
    let s = import(Layout::Blender, &src, &opts, &out).unwrap();
    // The layout's own split is kept.
    assert_eq!((s.frames, s.train_frames, s.test_frames), (9, 5, 4));
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let back = Scene::open(&out).unwrap();
    // camera_angle_x → fx: equal to rounding.
    let (a, b) = (orig.train.camera, back.train.camera);
    assert_eq!(
        (a.width, a.height, a.cx, a.cy),
        (b.width, b.height, b.cx, b.cy)
    );
    assert!((a.fx - b.fx).abs() < 1e-9 * a.fx && (a.fy - b.fy).abs() < 1e-9 * a.fy);
    for (ma, mb) in [(&orig.train, &back.train), (&orig.test, &back.test)] {
        assert_eq!(ma.frames.len(), mb.frames.len());
        for (fa, fb) in ma.frames.iter().zip(&mb.frames) {
            // k/8 s and (k + ½)/8 s survive t / 0.5 · 0.5 exactly.
            assert_eq!(fa.timestamp, fb.timestamp);
            assert!(pose_diff(&fa.cam_to_world, &fb.cam_to_world) <= 1e-6);
            let (ia, ib) = (
                read_image(orig.image_path(fa)).unwrap(),
                read_image(back.image_path(fb)).unwrap(),
            );
            assert_eq!(ia, ib);
        }
    }
    assert_eq!(orig.load_events().unwrap(), back.load_events().unwrap());
    // Without --time-offset/--duration the times land on the events' span, with a warning.
    let s = import(
        Layout::Blender,
        &src,
        &ImportOptions::default(),
        &dir.path().join("d"),
    )
    .unwrap();
    assert!(
        s.warnings[0].contains("normalised time"),
        "{:?}",
        s.warnings
    );
    let ev = orig.load_events().unwrap();
    assert_eq!((s.t_first, s.t_last), (ev.t[0], ev.t[ev.len() - 1]));
    // --test-every overrides the layout's split.
    let opts = ImportOptions {
        test_every: Some(3),
        ..opts
    };
    let s = import(Layout::Blender, &src, &opts, &dir.path().join("e")).unwrap();
    assert_eq!((s.train_frames, s.test_frames), (6, 3));
    // No event file: the error names the manifest and the flag.
    std::fs::remove_file(src.join("events.evs")).unwrap();
    let e = import(
        Layout::Blender,
        &src,
        &ImportOptions::default(),
        &dir.path().join("f"),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("transforms_train.json") && e.contains("--events"),
        "{e}"
    );
}
