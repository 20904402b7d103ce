//! `degs import nerfies`: a synthetic scene written in the nerfies / HyperNeRF layout
//! (world → camera orientation in OpenCV axes, pixel centres at +½, scene.json
//! normalisation, integer time ids) and imported back.

mod common;
use common::*;
use import::nerfies::{NerfiesExport, export_nerfies};
use import::{EventsAlignment, ImportOptions, Layout, import};
use scene::Scene;
use std::path::Path;

const EXPORT: NerfiesExport = NerfiesExport {
    center: [0.5, -1.0, 2.0],
    scale: 0.25,
    offset: 0.0,
    ticks_per_second: 16.0,
};

/// Options placing time id 0 … 8 (the tiny scene's 0.5 s at 16 ticks/s) on 0 … 0.5 s.
fn aligned() -> ImportOptions {
    ImportOptions {
        alignment: EventsAlignment {
            events: None,
            time_offset: Some(0.0),
            duration: Some(0.5),
        },
        ..Default::default()
    }
}

fn edit_json(path: &Path, f: impl FnOnce(&mut serde_json::Value)) {
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    f(&mut v);
    std::fs::write(path, serde_json::to_string(&v).unwrap()).unwrap();
}

#[test]
fn synthetic_scene_round_trips_through_the_nerfies_layout() {
    let dir = tempfile::tempdir().unwrap();
    let (orig, _) = tiny_scene(dir.path(), "synth");
    let src = dir.path().join("nerfies");
    export_nerfies(&orig, &EXPORT, &src).unwrap();
    // The file really is in the layout's conventions: position = world / scale + center,
    // principal point half a pixel right/down of ours, rows of world → camera.
    let f0 = &orig.train.frames[0];
    let c0: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(src.join("camera/train_000.json")).unwrap())
            .unwrap();
    let pos = &c0["position"];
    let want = f0.cam_to_world.translation / 0.25 + glam::DVec3::new(0.5, -1.0, 2.0);
    for (i, w) in want.to_array().iter().enumerate() {
        assert!((pos[i].as_f64().unwrap() - w).abs() < 1e-12);
    }
    assert_eq!(
        c0["principal_point"][0].as_f64().unwrap(),
        orig.train.camera.cx + 0.5
    );
    // OpenCV +z (the third row of world → camera) is the OpenGL camera's −z, in world.
    let fwd = f0.cam_to_world.rotation * -glam::DVec3::Z;
    for i in 0..3 {
        assert!((c0["orientation"][2][i].as_f64().unwrap() - fwd[i]).abs() < 1e-12);
    }

    let out = dir.path().join("back");
    let s = import(Layout::Nerfies, &src, &aligned(), &out).unwrap();
    assert_eq!((s.frames, s.train_frames, s.test_frames), (9, 5, 4));
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let back = Scene::open(&out).unwrap();
    assert_same_scene(&orig, &back, 1e-6);

    // Without --time-offset/--duration the frames land on the events' span, with a warning.
    let s = import(
        Layout::Nerfies,
        &src,
        &ImportOptions::default(),
        &dir.path().join("guessed"),
    )
    .unwrap();
    assert!(
        s.warnings.iter().any(|w| w.contains("normalised time")),
        "{:?}",
        s.warnings
    );
}

#[test]
fn a_downscaled_folder_scales_the_intrinsics() {
    let dir = tempfile::tempdir().unwrap();
    let (orig, _) = tiny_scene(dir.path(), "synth");
    let src = dir.path().join("nerfies");
    export_nerfies(&orig, &EXPORT, &src).unwrap();
    // Declare full size twice the frames' size: rgb/2x holds the 32×24 frames.
    for e in std::fs::read_dir(src.join("camera")).unwrap() {
        edit_json(&e.unwrap().path(), |v| {
            let k = orig.train.camera;
            v["focal_length"] = (2.0 * k.fx).into();
            v["principal_point"] = serde_json::json!([2.0 * (k.cx + 0.5), 2.0 * (k.cy + 0.5)]);
            v["image_size"] = serde_json::json!([64, 48]);
        });
    }
    std::fs::rename(src.join("rgb/1x"), src.join("rgb/2x")).unwrap();
    let out = dir.path().join("back");
    let s = import(Layout::Nerfies, &src, &aligned(), &out).unwrap();
    assert_eq!((s.width, s.height), (32, 24));
    let back = Scene::open(&out).unwrap();
    let (a, b) = (orig.train.camera, back.train.camera);
    assert_eq!((a.fx, a.fy, a.cx, a.cy), (b.fx, b.fy, b.cx, b.cy));
    // --downscale names a folder that is not there.
    let o = ImportOptions {
        downscale: Some(4),
        ..aligned()
    };
    let e = import(Layout::Nerfies, &src, &o, &dir.path().join("x")).unwrap_err();
    assert!(e.to_string().contains("rgb/4x"), "{e}");
}

#[test]
fn malformed_captures_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let (orig, _) = tiny_scene(dir.path(), "synth");
    let src = dir.path().join("nerfies");
    export_nerfies(&orig, &EXPORT, &src).unwrap();
    let run = |name: &str| {
        import(Layout::Nerfies, &src, &aligned(), &dir.path().join(name))
            .unwrap_err()
            .to_string()
    };
    let cam = src.join("camera/test_001.json");
    let keep = std::fs::read(&cam).unwrap();
    type Edit = Box<dyn Fn(&mut serde_json::Value)>;
    let cases: [(&str, Edit, &str); 4] = [
        ("skew", Box::new(|v| v["skew"] = 0.5.into()), "skew"),
        (
            "focal",
            Box::new(|v| v["focal_length"] = 41.0.into()),
            "intrinsics differ from those of",
        ),
        (
            "rotation",
            Box::new(|v| v["orientation"][0][0] = 2.0.into()),
            "not a rotation",
        ),
        (
            "mirror",
            Box::new(|v| {
                for i in 0..3 {
                    let x = v["orientation"][0][i].as_f64().unwrap();
                    v["orientation"][0][i] = (-x).into();
                }
            }),
            "not a rotation",
        ),
    ];
    for (name, edit, want) in cases {
        edit_json(&cam, edit);
        let e = run(name);
        assert!(
            e.contains("test_001.json") && e.contains(want),
            "{name}: {e}"
        );
        std::fs::write(&cam, &keep).unwrap();
        assert!(
            !dir.path().join(name).exists(),
            "{name}: half-written output"
        );
    }
    edit_json(&src.join("metadata.json"), |v| {
        v.as_object_mut().unwrap().remove("train_002");
    });
    let e = run("meta");
    assert!(
        e.contains("metadata.json") && e.contains("train_002"),
        "{e}"
    );
}

#[test]
fn an_unknown_val_id_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (orig, _) = tiny_scene(dir.path(), "synth");
    let src = dir.path().join("nerfies");
    export_nerfies(&orig, &EXPORT, &src).unwrap();
    edit_json(&src.join("dataset.json"), |v| {
        v["val_ids"].as_array_mut().unwrap().push("nope_042".into());
    });
    let e = import(Layout::Nerfies, &src, &aligned(), &dir.path().join("o"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("dataset.json") && e.contains("nope_042"), "{e}");
}
