//! `degs plan` / `status` / `eval` check the scene before any stage starts (issue #29 §2):
//! test frames that are train frames and events off the frames' clock are errors naming
//! the experiment and the scene; a single train frame and no test frames are warnings.

mod common;
use common::{degs, stderr};
use serde_json::Value;
use std::fs;
use std::path::Path;
use std::process::Output;

/// A tiny synthetic scene at `dir`, its train manifest edited by `edit`, and an
/// experiment on it.
fn scene_with(dir: &Path, edit: impl Fn(&mut Value, &mut Value)) -> std::path::PathBuf {
    let scene = dir.join("scene");
    synth::write_synthetic_scene(&common::tiny_scene_config(), &scene).unwrap();
    let read = |f: &str| -> Value {
        serde_json::from_str(&fs::read_to_string(scene.join(f)).unwrap()).unwrap()
    };
    let (mut train, mut test) = (read("transforms_train.json"), read("transforms_test.json"));
    edit(&mut train, &mut test);
    fs::write(scene.join("transforms_train.json"), train.to_string()).unwrap();
    fs::write(scene.join("transforms_test.json"), test.to_string()).unwrap();
    let exp = dir.join("e.toml");
    fs::write(
        &exp,
        format!("name = \"e\"\n[scene]\ndir = \"{}\"\n", scene.display()),
    )
    .unwrap();
    exp
}

fn plan(dir: &Path, exp: &Path) -> Output {
    let cache = dir.join("cache");
    degs(&[
        "plan",
        exp.to_str().unwrap(),
        "--cache",
        cache.to_str().unwrap(),
    ])
}

#[test]
fn test_frames_on_train_frames_are_refused_before_any_stage() {
    let d = tempfile::tempdir().unwrap();
    let exp = scene_with(d.path(), |train, test| {
        // Test frame 0 becomes train frame 1: same time, same camera.
        test["frames"][0] = train["frames"][1].clone();
        test["frames"][0]["file_path"] = "images/test_0000.png".into();
        let a = test["frames"][0]["timestamp"].as_f64().unwrap();
        let b = test["frames"][1]["timestamp"].as_f64().unwrap();
        assert!(a < b);
    });
    for cmd in ["plan", "status"] {
        let cache = d.path().join("cache");
        let o = degs(&[
            cmd,
            exp.to_str().unwrap(),
            "--cache",
            cache.to_str().unwrap(),
        ]);
        assert!(!o.status.success(), "{cmd}");
        let e = stderr(&o);
        assert!(
            e.contains("e.toml") && e.contains("1 of 2 test frames are train frames"),
            "{cmd}: {e}"
        );
        assert!(!cache.join("runs").exists(), "{cmd}: wrote a run");
    }
}

#[test]
fn events_off_the_frames_clock_are_refused_before_any_stage() {
    let d = tempfile::tempdir().unwrap();
    // Frames 5 s later than the events (which cover 0–0.25 s).
    let exp = scene_with(d.path(), |train, test| {
        for m in [train, test] {
            for f in m["frames"].as_array_mut().unwrap() {
                let t = f["timestamp"].as_f64().unwrap();
                f["timestamp"] = (t + 5.0).into();
            }
        }
    });
    let o = plan(d.path(), &exp);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("none of the") && e.contains("one clock"), "{e}");
}

#[test]
fn one_train_frame_and_no_test_frames_are_warned_about() {
    let d = tempfile::tempdir().unwrap();
    let exp = scene_with(d.path(), |train, test| {
        train["frames"].as_array_mut().unwrap().truncate(1);
        test["frames"].as_array_mut().unwrap().clear();
    });
    let o = plan(d.path(), &exp);
    assert!(o.status.success(), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("warning:") && e.contains("1 train frame:"),
        "{e}"
    );
    assert!(e.contains("no test frames"), "{e}");
}
