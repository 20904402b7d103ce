//! `degs import hsergb`: a synthetic scene seen by a static camera, exported to the
//! HS-ERGB layout (events ×32 in one npz per frame interval) and imported back.

mod common;
use common::*;
use import::hsergb::export_hsergb;
use import::{ImportOptions, Layout, import};
use scene::Scene;
use scene::image_io::read_image;

#[test]
fn static_synthetic_scene_round_trips_through_the_hsergb_layout() {
    let dir = tempfile::tempdir().unwrap();
    let (orig, _) = write_scene(dir.path(), "synth", &tiny_static_config());
    let first = orig.train.frames[0].cam_to_world;
    assert!(
        orig.test
            .frames
            .iter()
            .all(|f| pose_diff(&f.cam_to_world, &first) == 0.0)
    );
    let src = dir.path().join("hsergb");
    export_hsergb(&orig, &src).unwrap();
    // 9 frames → 8 interval files.
    assert_eq!(
        std::fs::read_dir(src.join("events_aligned"))
            .unwrap()
            .count(),
        8
    );

    let out = dir.path().join("back");
    let opts = ImportOptions {
        test_every: Some(2),
        calib: Some(src.join("calib.txt")),
        ..Default::default()
    };
    let s = import(Layout::Hsergb, &src, &opts, &out).unwrap();
    assert_eq!((s.frames, s.train_frames, s.test_frames), (9, 5, 4));
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let back = Scene::open(&out).unwrap();
    assert_eq!(back.train.camera, orig.train.camera);
    // Same frames and times; the static camera becomes the identity pose (the layout
    // has no world frame), so every pose equals the first one as in the original.
    for (a, b) in [(&orig.train, &back.train), (&orig.test, &back.test)] {
        assert_eq!(a.frames.len(), b.frames.len());
        for (fa, fb) in a.frames.iter().zip(&b.frames) {
            assert_eq!(fa.timestamp, fb.timestamp);
            assert_eq!(fa.time, fb.time);
            assert_eq!(fb.cam_to_world, scene::Pose::default());
            let (ia, ib) = (
                read_image(orig.image_path(fa)).unwrap(),
                read_image(back.image_path(fb)).unwrap(),
            );
            assert_eq!(ia, ib);
        }
    }
    // Events: the same pixels and polarities; times rounded to the npz's whole µs.
    let (ea, eb) = (orig.load_events().unwrap(), back.load_events().unwrap());
    assert!(ea.len() > 100);
    assert_eq!((&ea.x, &ea.y, &ea.p), (&eb.x, &eb.y, &eb.p));
    let worst =
        ea.t.iter()
            .zip(&eb.t)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
    assert!(worst <= 0.5e-6 + 1e-12, "{worst}");
    // Without --calib the intrinsics are guessed, and the summary says so.
    let s = import(
        Layout::Hsergb,
        &src,
        &ImportOptions::default(),
        &dir.path().join("guess"),
    )
    .unwrap();
    assert!(s.warnings.iter().any(|w| w.contains("--calib")));
}

#[test]
fn bad_hsergb_folders_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let (orig, _) = write_scene(dir.path(), "synth", &tiny_static_config());
    let src = dir.path().join("hsergb");
    export_hsergb(&orig, &src).unwrap();
    let ts = src.join("images_corrected/timestamp.txt");
    let good = std::fs::read_to_string(&ts).unwrap();
    std::fs::write(&ts, "0\n0.1\n").unwrap();
    let e = import(
        Layout::Hsergb,
        &src,
        &ImportOptions::default(),
        &dir.path().join("x"),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("timestamp.txt") && e.contains("2 timestamps for 9 PNG frames"),
        "{e}"
    );
    std::fs::write(&ts, good).unwrap();
    // Event files out of order: the later file's events come first.
    let (a, b) = (
        src.join("events_aligned/000000.npz"),
        src.join("events_aligned/000005.npz"),
    );
    let tmp = src.join("tmp.bin");
    std::fs::rename(&a, &tmp).unwrap();
    std::fs::rename(&b, &a).unwrap();
    std::fs::rename(&tmp, &b).unwrap();
    let e = import(
        Layout::Hsergb,
        &src,
        &ImportOptions::default(),
        &dir.path().join("x"),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains(".npz") && e.contains("before the previous file's last event"),
        "{e}"
    );
    std::fs::remove_dir_all(src.join("events_aligned")).unwrap();
    let e = import(
        Layout::Hsergb,
        &src,
        &ImportOptions::default(),
        &dir.path().join("x"),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("events_aligned"), "{e}");
}

/// Loaders of HS-ERGB compare `timestamp.txt` with the npz `t` directly, so a
/// timestamp file in µs is read as µs (detected from the events' span, with a warning).
#[test]
fn timestamps_in_microseconds_are_detected() {
    let dir = tempfile::tempdir().unwrap();
    let (orig, _) = write_scene(dir.path(), "synth", &tiny_static_config());
    let src = dir.path().join("hsergb");
    export_hsergb(&orig, &src).unwrap();
    let ts = src.join("images_corrected/timestamp.txt");
    let us: String = std::fs::read_to_string(&ts)
        .unwrap()
        .lines()
        .map(|l| format!("{}\n", l.trim().parse::<f64>().unwrap() * 1e6))
        .collect();
    std::fs::write(&ts, us).unwrap();
    let opts = ImportOptions {
        test_every: Some(2),
        calib: Some(src.join("calib.txt")),
        ..Default::default()
    };
    let out = dir.path().join("back");
    let s = import(Layout::Hsergb, &src, &opts, &out).unwrap();
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(s.warnings[0].contains("microseconds"), "{:?}", s.warnings);
    let back = Scene::open(&out).unwrap();
    for (a, b) in [(&orig.train, &back.train), (&orig.test, &back.test)] {
        for (fa, fb) in a.frames.iter().zip(&b.frames) {
            assert!(
                (fa.timestamp - fb.timestamp).abs() < 1e-12,
                "{} vs {}",
                fa.timestamp,
                fb.timestamp
            );
        }
    }
}

/// HS-ERGB npz store coordinates ×32; a folder of npz in plain pixels (as other tools
/// write them) is read as pixels, with a warning, instead of every event landing in a
/// (W/32)×(H/32) corner.
#[test]
fn npz_in_plain_pixels_are_detected_from_their_range() {
    let (dir, orig, src) = exported();
    for e in std::fs::read_dir(src.join("events_aligned")).unwrap() {
        let p = e.unwrap().path();
        let opts = scene::ReadOptions {
            sensor: Some((32, 24)),
            coord_scale: Some(32.0),
        };
        let ev = scene::formats::read_npz(&p, &opts).unwrap();
        scene::formats::write_npz(&p, &ev).unwrap(); // now in plain pixels
    }
    let opts = with_calib(&src);
    let out = dir.path().join("back");
    let s = import(Layout::Hsergb, &src, &opts, &out).unwrap();
    assert!(
        s.warnings.iter().any(|w| w.contains("plain pixels")),
        "{:?}",
        s.warnings
    );
    let (ea, eb) = (
        orig.load_events().unwrap(),
        Scene::open(&out).unwrap().load_events().unwrap(),
    );
    assert!(ea.len() > 100);
    assert_eq!((&ea.x, &ea.y, &ea.p), (&eb.x, &eb.y, &eb.p));
    // The layout's own ×32 files still import without that warning.
    let src2 = dir.path().join("hsergb2");
    export_hsergb(&orig, &src2).unwrap();
    let opts = ImportOptions {
        calib: Some(src2.join("calib.txt")),
        ..opts
    };
    let s = import(Layout::Hsergb, &src2, &opts, &dir.path().join("back2")).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
}

/// A PNG cut short after an intact header is refused at import, naming the file.
#[test]
fn a_truncated_frame_is_refused_at_import() {
    let (dir, _, src) = exported();
    let mut pngs: Vec<_> = std::fs::read_dir(src.join("images_corrected"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    pngs.sort();
    let victim = &pngs[3];
    let bytes = std::fs::read(victim).unwrap();
    std::fs::write(victim, &bytes[..bytes.len() * 2 / 3]).unwrap();
    assert!(
        image::image_dimensions(victim).is_ok(),
        "the header is intact"
    );
    let opts = ImportOptions {
        calib: Some(src.join("calib.txt")),
        ..Default::default()
    };
    let out = dir.path().join("back");
    let e = import(Layout::Hsergb, &src, &opts, &out)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(victim.to_str().unwrap()) && e.contains("decode"),
        "{e}"
    );
    assert!(!out.exists());
}

/// Real HS-ERGB files hold a few small negative coordinates wrapped through 16 bits
/// (65 536 − 32·k; public converters subtract 65 536): those events lie off the sensor
/// and are dropped with a warning; the rest import as the layout's own ×32 files do.
#[test]
fn wrapped_negative_coordinates_are_dropped_and_said() {
    let (dir, orig, src) = exported();
    let mut files: Vec<_> = std::fs::read_dir(src.join("events_aligned"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    let raw = scene::ReadOptions {
        sensor: Some((1 << 16, 1 << 16)),
        coord_scale: None,
    };
    let first = &files[0];
    let ev = scene::formats::read_npz(first, &raw).unwrap();
    let mut with = scene::EventStream::new(1 << 16, 1 << 16);
    let t0 = ev.t[0];
    with.push(t0, (-32i16) as u16, 64, 1); // x = −1 px, wrapped
    with.push(t0, 96, (-64i16) as u16, -1); // y = −2 px
    for i in 0..ev.len() {
        with.push(ev.t[i], ev.x[i], ev.y[i], ev.p[i]);
    }
    scene::formats::write_npz(first, &with).unwrap();
    let opts = with_calib(&src);
    let out = dir.path().join("back");
    let s = import(Layout::Hsergb, &src, &opts, &out).unwrap();
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("2 events with negative coordinates")),
        "{:?}",
        s.warnings
    );
    let (ea, eb) = (
        orig.load_events().unwrap(),
        Scene::open(&out).unwrap().load_events().unwrap(),
    );
    assert_eq!((&ea.x, &ea.y, &ea.p), (&eb.x, &eb.y, &eb.p));
}

/// The tiny static scene exported to the HS-ERGB layout: the folder, the scene, the
/// layout's folder.
fn exported() -> (tempfile::TempDir, Scene, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let (orig, _) = write_scene(dir.path(), "synth", &tiny_static_config());
    let src = dir.path().join("hsergb");
    export_hsergb(&orig, &src).unwrap();
    (dir, orig, src)
}

/// Import options with the layout's calibration (and every other frame a test frame).
fn with_calib(src: &std::path::Path) -> ImportOptions {
    ImportOptions {
        test_every: Some(2),
        calib: Some(src.join("calib.txt")),
        ..Default::default()
    }
}
