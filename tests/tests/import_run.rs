//! `degs import LAYOUT` then `degs run` on the imported scene, for the layouts with real
//! recordings behind them (ECD, HS-ERGB, nerfies): a tiny synthetic scene (32×32 px) is
//! exported into the layout, imported by the `degs` binary, and every stage runs on it
//! end to end; the warm-up and the joint training beat the mean-colour baseline.

use degs_tests::{TINY_STAGES, Workspace, binary, entry, read_json, stage_record, stderr};
use import::nerfies::{NerfiesExport, export_nerfies};
use scene::Scene;
use std::path::Path;

const BUILT: [&str; 4] = ["evflow", "gaussians", "assoc", "deform"];

/// A 32×32, 0.25 s rigid scene (train frames at 8 fps, two test frames between them),
/// seen by a camera that does not move when `static_camera` (HS-ERGB has no poses).
fn tiny_scene(dir: &Path, static_camera: bool) -> Scene {
    let mut cfg = synth::SynthConfig {
        width: 32,
        height: 32,
        duration: 0.25,
        render_rate_hz: 200.0,
        test_frames: 2,
        novel_angle_deg: 0.0,
        supersample: 1,
        frame_supersample: 1,
        ..synth::SynthConfig::preset("rigid").unwrap()
    };
    if static_camera {
        cfg.camera.sway = glam::DVec3::ZERO;
        cfg.camera.yaw_deg = 0.0;
        cfg.camera.pitch_deg = 0.0;
    }
    let out = dir.join(if static_camera { "static" } else { "moving" });
    synth::write_synthetic_scene(&cfg, &out).unwrap();
    Scene::open(&out).unwrap()
}

/// `degs import` with `args`, then `degs run` on the result; checks every stage.
fn import_and_run(w: &Workspace, name: &str, args: &[&str]) {
    let out_dir = w.dir.path().join(format!("{name}-scene"));
    let out = std::process::Command::new(binary("degs"))
        .arg("import")
        .args(args)
        .arg(&out_dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "import {name}: {}", stderr(&out));
    let summary = read_json(&out_dir.join("import.json"));
    assert!(summary["test_frames"].as_u64().unwrap() >= 1, "{summary}");
    assert!(summary["events"].as_u64().unwrap() > 100, "{summary}");

    let text = format!(
        "name = \"{name}\"\n\n[scene]\ndir = \"{}\"\n{TINY_STAGES}",
        out_dir.display()
    );
    let exp = w.experiment(name, &text);
    let out = w.degs(&["run", exp.to_str().unwrap(), "-j", "2", "--quiet"]);
    assert!(out.status.success(), "run {name}: {}", stderr(&out));
    let record = w.run_record(name);
    assert_eq!(record["status"], "ok", "{record}");
    for stage in BUILT {
        assert_eq!(
            stage_record(&record, stage)["action"],
            "ran",
            "{name} {stage}"
        );
    }
    for stage in ["gaussians", "deform"] {
        let report = read_json(&entry(&record, stage).join("report.json"));
        let psnr = report["test"]["psnr_mean"].as_f64().unwrap();
        let baseline = report["test"]["mean_colour_psnr_mean"].as_f64().unwrap();
        assert!(
            psnr.is_finite() && psnr > baseline,
            "{name} {stage}: test PSNR {psnr} dB, mean colour {baseline} dB"
        );
    }
}

#[test]
fn imported_recordings_run_every_stage() {
    let w = Workspace::new();
    let moving = tiny_scene(w.dir.path(), false);
    let still = tiny_scene(w.dir.path(), true);

    let ecd = w.dir.path().join("ecd-src");
    import::ecd::export_ecd(&moving, &[], &ecd).unwrap();
    import_and_run(
        &w,
        "ecd",
        &["ecd", ecd.to_str().unwrap(), "--test-every", "2"],
    );

    let hs = w.dir.path().join("hsergb-src");
    import::hsergb::export_hsergb(&still, &hs).unwrap();
    let calib = hs.join("calib.txt");
    import_and_run(
        &w,
        "hsergb",
        &[
            "hsergb",
            hs.to_str().unwrap(),
            "--test-every",
            "2",
            "--calib",
            calib.to_str().unwrap(),
        ],
    );

    let nf = w.dir.path().join("nerfies-src");
    let x = NerfiesExport {
        center: [0.0; 3],
        scale: 1.0,
        offset: 0.0,
        ticks_per_second: 16.0,
    };
    export_nerfies(&moving, &x, &nf).unwrap();
    import_and_run(
        &w,
        "nerfies",
        &[
            "nerfies",
            nf.to_str().unwrap(),
            "--time-offset",
            "0",
            "--duration",
            "0.25",
        ],
    );
}
