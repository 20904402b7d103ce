//! The `evaluate` binary on a tiny synthetic scene: renders that are the held-out images
//! themselves score the PSNR cap and SSIM 1; one changed value scores the PSNR of its
//! closed form; its settings verb answers as the runner expects.

use scene::image_io::{read_image, write_png};
use scene::manifest::Scene;
use std::path::Path;
use std::process::Command;

fn evaluate(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_evaluate"))
        .args(args)
        .output()
        .unwrap()
}

fn tiny_scene(dir: &Path) -> Scene {
    let cfg = synth::SynthConfig {
        width: 32,
        height: 24,
        duration: 0.25,
        render_rate_hz: 200.0,
        test_frames: 2,
        supersample: 1,
        frame_supersample: 1,
        ..synth::SynthConfig::preset("rigid").unwrap()
    };
    synth::write_synthetic_scene(&cfg, &dir.join("scene")).unwrap();
    Scene::open(dir.join("scene")).unwrap()
}

#[test]
fn exact_and_one_level_off_renders_score_their_closed_forms() {
    let d = tempfile::tempdir().unwrap();
    let scene = tiny_scene(d.path());
    let renders = d.path().join("model/renders");
    std::fs::create_dir_all(&renders).unwrap();
    let mut changed = 0.0;
    for (i, f) in scene.test.frames.iter().enumerate() {
        let mut img = read_image(scene.image_path(f)).unwrap();
        if i == 1 {
            // one value of one pixel moved by 10 levels
            let v = (img.data[0] * 255.0).round();
            img.data[0] = (if v >= 10.0 { v - 10.0 } else { v + 10.0 }) / 255.0;
            let n = (img.width * img.height * img.channels) as f64;
            changed = 10.0 * (255.0f64.powi(2) * n / 100.0).log10();
        }
        write_png(renders.join(format!("{i:04}.png")), &img).unwrap();
    }
    let config = d.path().join("eval.toml");
    std::fs::write(&config, "lpips = \"off\"\n").unwrap();
    let out = d.path().join("out");
    let o = evaluate(&[
        "--scene",
        d.path().join("scene").to_str().unwrap(),
        "--model",
        d.path().join("model").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m: scene::evaluation::Metrics =
        serde_json::from_slice(&std::fs::read(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(m.frames.len(), 2);
    assert_eq!((m.frames[0].psnr, m.frames[0].ssim), (100.0, 1.0));
    assert!(
        (m.frames[1].psnr - changed).abs() < 1e-9,
        "{} vs {changed}",
        m.frames[1].psnr
    );
    assert!(m.frames[1].ssim < 1.0);
    assert_eq!(m.lpips_note.as_deref(), Some("LPIPS off (DEGS_LPIPS=off)"));
    // the baselines come from the scene when the model's report has none
    let b = m.baselines.expect("baselines");
    assert_eq!(b.source, scene::evaluation::COMPUTED);
    assert!(out.join("settings.toml").is_file());
    // the output is marked: a second run refuses it without --force
    let again = evaluate(&[
        "--scene",
        d.path().join("scene").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!again.status.success());
}

#[test]
fn the_settings_verb_answers_as_the_runner_expects() {
    let o = evaluate(&["settings", "--defaults"]);
    assert!(o.status.success());
    assert_eq!(String::from_utf8_lossy(&o.stdout), "lpips = \"fetch\"\n");
    let d = tempfile::tempdir().unwrap();
    let bad = d.path().join("bad.toml");
    std::fs::write(&bad, "lpips = \"sometimes\"\n").unwrap();
    let o = evaluate(&["settings", "--check", bad.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.starts_with("evaluate: error: ") && err.contains("bad.toml") && err.contains("lpips"),
        "{err}"
    );
}
