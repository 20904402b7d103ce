//! The `assoc` stage over files (issue: assoc, item 2 and "Must show"): a small
//! synthetic scene directory and a model directory whose depth maps are rendered by the
//! model itself go in; `assoc.bin` must hold, for every train frame, exactly what the
//! library computes for that frame, and mismatched inputs must fail naming the file
//! while leaving no output directory behind.

use assoc::{AssocSettings, associate_frame, read_assoc};
use gaussians::model::{Model, ModelInfo};
use gaussians::{Gaussian, Splats};
use glam::DVec2;
use scene::Scene;
use scene::image_io::{read_exr_depth, write_exr_depth};
use std::path::Path;
use synth::{SynthConfig, SynthWorld};

/// Gaussians on a 3-px grid of the surfaces seen at time 0 (a static model).
fn surface_model(cfg: &SynthConfig) -> Model {
    let world = SynthWorld::new(cfg).unwrap();
    let fx = world.intrinsics().fx;
    let mut s = Splats::default();
    for v in (0..cfg.height).step_by(3) {
        for u in (0..cfg.width).step_by(3) {
            let Some(hit) = world.cast(0.0, DVec2::new(u as f64, v as f64)) else {
                continue;
            };
            let p = hit.world;
            let mean = [p.x as f32, p.y as f32, p.z as f32];
            let log_scale = (1.5 * hit.depth / fx).ln() as f32;
            s.push(Gaussian {
                dynamic: true,
                ..Gaussian::isotropic(mean, log_scale, 3.0, [0.5; 3])
            });
        }
    }
    let info = ModelInfo {
        sh_degree: 0,
        gaussians: s.len(),
        ..Default::default()
    };
    Model {
        splats: s,
        field: None,
        info,
    }
}

/// Alpha-normalised depth (0 where alpha < 0.5), as the warm-up writes it.
fn write_depths(model: &Model, scene: &Scene, dir: &Path) {
    std::fs::create_dir_all(dir.join("depth")).unwrap();
    for (i, frame) in scene.train.frames.iter().enumerate() {
        let cam = scene.camera(frame);
        let f = model.render(&cam, frame.time as f32);
        let depth: Vec<f32> = f
            .depth
            .iter()
            .zip(&f.alpha)
            .map(|(&d, &a)| if a >= 0.5 { d / a } else { 0.0 })
            .collect();
        let path = assoc::stage::depth_path(dir, i);
        write_exr_depth(&path, f.width as u32, f.height as u32, &depth).unwrap();
    }
}

#[test]
fn stage_writes_the_library_bindings_for_every_frame_and_rejects_bad_depth() {
    let tmp = tempfile::tempdir().unwrap();
    let mut cfg = SynthConfig::preset("rigid").unwrap();
    cfg.width = 64;
    cfg.height = 64;
    cfg.duration = 0.5;
    cfg.render_rate_hz = 400.0;
    cfg.supersample = 1;
    let scene_dir = tmp.path().join("scene");
    synth::write_synthetic_scene(&cfg, &scene_dir).unwrap();
    let scene = Scene::open(&scene_dir).unwrap();
    assert!(scene.train.frames.len() >= 3);

    let model_dir = tmp.path().join("model");
    let model = surface_model(&cfg);
    assert!(model.splats.len() > 200);
    model.save(&model_dir).unwrap();
    write_depths(&model, &scene, &model_dir);

    let settings = AssocSettings::default();
    let out = tmp.path().join("assoc");
    let mut calls = 0;
    let report = assoc::stage::run(&scene_dir, &model_dir, &out, &settings, false, |_, _| {
        calls += 1
    })
    .unwrap();
    let n_frames = scene.train.frames.len();
    assert_eq!(calls, n_frames);
    assert_eq!(report.frames.len(), n_frames);
    assert_eq!(report.gaussians, model.splats.len());
    assert!(report.bound_fraction_mean > 0.05, "{report:?}");

    // assoc.bin holds, frame by frame, exactly the library's result.
    let sections = read_assoc(&out.join("assoc.bin")).unwrap();
    assert_eq!(sections.len(), n_frames);
    let events = scene.load_events().unwrap();
    for (i, (frame, sec)) in scene.train.frames.iter().zip(&sections).enumerate() {
        assert_eq!(sec.t0, frame.timestamp);
        assert_eq!((sec.delta_t, sec.k), (settings.delta_t, settings.k as u32));
        let (w, h, depth) = read_exr_depth(assoc::stage::depth_path(&model_dir, i)).unwrap();
        assert_eq!((w, h), (64, 64));
        let alpha: Vec<f32> = depth.iter().map(|&d| f32::from(d > 0.0)).collect();
        let window = events.window(
            frame.timestamp - settings.delta_t,
            (frame.timestamp + settings.delta_t).next_up(),
        );
        let (expected, stats) = associate_frame(
            &scene.camera(frame),
            &depth,
            &alpha,
            &window,
            &model.at(frame.time as f32).means,
            frame.timestamp,
            &settings,
        )
        .unwrap();
        assert_eq!(sec.bindings, expected, "frame {i}");
        assert_eq!(report.frames[i].gaussians_bound, stats.gaussians_bound);
        assert!(out.join("preview").join(format!("{i:04}.png")).is_file());
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(json["frames"].as_array().unwrap().len(), n_frames);
    assert!(out.join("settings.toml").is_file());

    // A depth map of another size names the file; nothing is left at the output path.
    let bad = assoc::stage::depth_path(&model_dir, 1);
    write_exr_depth(&bad, 32, 32, &[1.0; 32 * 32]).unwrap();
    let out2 = tmp.path().join("assoc2");
    let err = assoc::stage::run(&scene_dir, &model_dir, &out2, &settings, false, |_, _| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("0001.exr") && err.contains("32x32"), "{err}");
    assert!(!out2.exists());
    let leftovers: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.starts_with("assoc2"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");

    // A missing depth map names the file too.
    std::fs::remove_file(&bad).unwrap();
    let err = assoc::stage::run(&scene_dir, &model_dir, &out2, &settings, false, |_, _| {})
        .unwrap_err()
        .to_string();
    assert!(err.contains("0001.exr"), "{err}");

    // A model with zero Gaussians is refused by name.
    let empty_dir = tmp.path().join("empty");
    Model {
        splats: Splats::default(),
        field: None,
        info: ModelInfo::default(),
    }
    .save(&empty_dir)
    .unwrap();
    let err = assoc::stage::run(&scene_dir, &empty_dir, &out2, &settings, false, |_, _| {})
        .unwrap_err()
        .to_string();
    // The message itself, naming the model's PLY (the directory's name alone would not
    // do): `Model::load` refuses before the stage's own "no Gaussians" check.
    let ply = empty_dir.join(gaussians::model::PLY_FILE);
    assert_eq!(
        err,
        format!("{}: the PLY holds zero Gaussians", ply.display())
    );
    assert!(!out2.exists());
}
