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
    let opts = over_half_a_second();
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

/// Frames placed off the events' clock (`--time-offset 5` for events over 0–0.5 s) are
/// refused, naming both spans; a partial overlap imports with a warning that says where
/// the frames were placed and from what (not "the events' span" when an offset was given).
#[test]
fn frames_placed_off_the_events_clock_are_refused_or_warned() {
    let dir = tempfile::tempdir().unwrap();
    let (orig, _) = tiny_scene(dir.path(), "synth");
    let src = dir.path().join("dnerf");
    export_blender(&orig, 0.0, 0.5, &src).unwrap();
    let at = |offset: f64| ImportOptions {
        alignment: EventsAlignment {
            events: None,
            time_offset: Some(offset),
            duration: None,
        },
        ..Default::default()
    };
    let out = dir.path().join("off");
    let e = import(Layout::Blender, &src, &at(5.0), &out)
        .unwrap_err()
        .to_string();
    assert!(e.contains("none of the") && e.contains("one clock"), "{e}");
    assert!(!out.exists());
    // Half the frames' span without events: imported, and said so.
    let ev = orig.load_events().unwrap();
    let span = ev.t[ev.len() - 1] - ev.t[0];
    let s = import(
        Layout::Blender,
        &src,
        &at(ev.t[0] + span / 2.0),
        &dir.path().join("half"),
    )
    .unwrap();
    let w = s.warnings.join("\n");
    assert!(
        w.contains("from --time-offset, and the events' span"),
        "{w}"
    );
    assert!(w.contains("cover 50 %"), "{w}");
}

/// D-NeRF's own split puts test cameras at the train times: accepted (other cameras, so
/// a fair test); two frames of one split at one time are refused, naming the split file
/// and both frames.
#[test]
fn test_views_at_train_times_are_accepted_and_equal_times_in_a_split_named() {
    let dir = tempfile::tempdir().unwrap();
    let (orig, _) = tiny_scene(dir.path(), "synth");
    let src = dir.path().join("dnerf");
    export_blender(&orig, 0.0, 0.5, &src).unwrap();
    let edit = |file: &str, f: &dyn Fn(&mut Vec<serde_json::Value>)| {
        let p = src.join(file);
        let mut j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&p).unwrap()).unwrap();
        f(j["frames"].as_array_mut().unwrap());
        std::fs::write(&p, serde_json::to_string(&j).unwrap()).unwrap();
    };
    let train: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(src.join("transforms_train.json")).unwrap())
            .unwrap();
    let train_times: Vec<f64> = train["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["time"].as_f64().unwrap())
        .collect();
    // Test views (their own cameras, half a frame later on the path) at train times.
    edit("transforms_test.json", &|frames| {
        for (f, t) in frames.iter_mut().zip(&train_times) {
            f["time"] = (*t).into();
        }
    });
    let opts = over_half_a_second();
    let s = import(Layout::Blender, &src, &opts, &dir.path().join("ok")).unwrap();
    assert_eq!((s.train_frames, s.test_frames), (5, 4));
    // Two train frames at one time.
    edit("transforms_train.json", &|frames| {
        let t = frames[1]["time"].clone();
        frames[2]["time"] = t;
    });
    let e = import(Layout::Blender, &src, &opts, &dir.path().join("bad"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("transforms_train.json") && e.contains("frame 2") && e.contains("frame 1"),
        "{e}"
    );
}

/// The exported frames' normalised times placed on 0–0.5 s, the events' clock.
fn over_half_a_second() -> ImportOptions {
    ImportOptions {
        alignment: EventsAlignment {
            events: None,
            time_offset: Some(0.0),
            duration: Some(0.5),
        },
        ..Default::default()
    }
}
