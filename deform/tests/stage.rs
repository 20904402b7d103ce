//! The `deform` stage's command line and its errors on missing or wrong inputs (the
//! training itself runs end to end in `tests/tests/degs_run.rs`).

use std::process::Command;

fn deform() -> Command {
    Command::new(env!("CARGO_BIN_EXE_deform"))
}

#[test]
fn help_lists_the_inputs_and_the_ablation_switches() {
    let out = deform().args(["train", "--help"]).output().unwrap();
    assert!(out.status.success());
    let help = String::from_utf8_lossy(&out.stdout);
    for flag in [
        "--scene",
        "--model",
        "--flows",
        "--assoc",
        "--out",
        "--no-posenet",
        "--no-event-loss",
        "--no-motion-loss",
    ] {
        assert!(help.contains(flag), "{flag} missing from:\n{help}");
    }
}

#[test]
fn a_bad_settings_key_is_an_error_naming_the_file_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("bad.toml");
    std::fs::write(&cfg, "iteratons = 5\n").unwrap();
    let out_dir = dir.path().join("out");
    let d = dir.path().display().to_string();
    let out = deform()
        .args([
            "train", "--scene", &d, "--model", &d, "--flows", &d, "--assoc", &d,
        ])
        .args([
            "--out",
            out_dir.to_str().unwrap(),
            "--config",
            cfg.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.starts_with("deform: error: ") && err.contains("bad.toml") && err.contains("iteratons"),
        "{err}"
    );
    assert!(!out_dir.exists());
}

#[test]
fn a_missing_scene_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-scene");
    let d = dir.path().display().to_string();
    let out = deform()
        .args([
            "train",
            "--scene",
            missing.to_str().unwrap(),
            "--model",
            &d,
            "--flows",
            &d,
        ])
        .args([
            "--assoc",
            &d,
            "--out",
            dir.path().join("out").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no-such-scene"), "{err}");
}

/// The joint iterations `deform train` announces (its progress total) follow the
/// scene's train frames: 4 fps frames get 6000, 20 fps frames 4000 (4000 at 50 ms, 6000
/// at 100 ms and over, at this size), and `--iterations` wins over both; `L_motion` is
/// on at 4 fps and off at 20 fps.
use deform::schedule::MotionUse;

#[test]
fn the_joint_iterations_follow_the_frame_rate_unless_set() {
    let dir = tempfile::tempdir().unwrap();
    for (fps, want) in [(4.0, 6000), (20.0, 4000)] {
        let cfg = synth::config::SynthConfig {
            width: 32,
            height: 32,
            train_fps: fps,
            ..synth::config::SynthConfig::preset("rigid").unwrap()
        };
        let scene_dir = dir.path().join(format!("fps{fps}"));
        synth::scene_dir::write_synthetic_scene(&cfg, &scene_dir).unwrap();
        let mut a = deform::stage::TrainArgs::default();
        a.stage.scene = scene_dir;
        let got = deform::stage::joint_iterations(&a).unwrap();
        assert_eq!(got, want, "{fps} fps");
        // L_motion at 4 fps (250 ms apart: over 1/9 s), not at 20 fps (50 ms)
        let motion = deform::stage::run_settings(&a).unwrap().schedule.motion;
        let on = if fps < 9.0 {
            MotionUse::On
        } else {
            MotionUse::Off
        };
        assert_eq!(motion, on, "{fps} fps");
        a.training.iterations = Some(7);
        assert_eq!(deform::stage::joint_iterations(&a).unwrap(), 7);
    }
}
