//! The tracks init says when it placed moving objects without a depth prior (one moving
//! camera cannot tell their distance): on a scene whose objects move, `gaussians train`'s
//! report warns without `depth/`, does not with the scene's true depth there, and warns
//! again when the maps disagree with the still scene so that none is used.

use gaussians::stage::{self, TrainArgs};
use gaussians::train::TrainSettings;
use scene::depth_prior::{DepthKind, DepthPriors};
use stagekit::{StageArgs, TrainingArgs};
use std::path::Path;
use std::sync::atomic::AtomicBool;
use synth::{SynthConfig, SynthWorld};

/// `rigid` at 64², 8 fps over 1 s: the box and the ball move, the camera sways.
fn config() -> SynthConfig {
    let mut cfg = SynthConfig::preset("rigid").unwrap();
    (cfg.width, cfg.height) = (64, 64);
    cfg.test_frames = 8;
    cfg.supersample = 1;
    cfg.frame_supersample = 2;
    cfg
}

/// The init only: one iteration, no sizing.
fn settings(dir: &Path) -> std::path::PathBuf {
    let mut s = TrainSettings {
        iterations: 1,
        static_iterations: 0,
        ..TrainSettings::default()
    };
    s.size.tolerance_db = 0.0;
    let p = dir.join("settings.toml");
    std::fs::write(&p, stagekit::settings::to_toml(&s).unwrap()).unwrap();
    p
}

/// The report of the init on `scene` (its `report.json`, read back).
fn init_report(scene: &Path, out: &Path, config: &Path) -> serde_json::Value {
    let args = TrainArgs {
        stage: StageArgs::new(scene, out).with_config(config),
        training: TrainingArgs::default(),
        ..TrainArgs::default()
    };
    stage::train(&args, &AtomicBool::new(false), |_| {}).unwrap();
    serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap()
}

fn warnings(report: &serde_json::Value) -> Vec<String> {
    (report["warnings"].as_array().unwrap().iter())
        .map(|w| w.as_str().unwrap().to_string())
        .collect()
}

#[test]
fn moving_objects_without_a_usable_depth_prior_are_said_so() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = config();
    let scene = tmp.path().join("scene");
    synth::write_rgb_synthetic_scene(&cfg, &scene).unwrap();
    let config = settings(tmp.path());

    // No depth/: the moving objects' Gaussians are placed at a distance nothing gave.
    let r = init_report(&scene, &tmp.path().join("none"), &config);
    let moving = r["tracks_init"]["moving"].as_u64().unwrap();
    assert!(
        moving > 0,
        "the box and the ball move: {}",
        r["tracks_init"]
    );
    assert_eq!(r["tracks_init"]["prior_frames"], 0);
    let w = warnings(&r);
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].contains(&format!("{moving} Gaussians of moving objects ("))
            && w[0].contains("no depth priors")
            && w[0].contains("depth/"),
        "{}",
        w[0]
    );

    // The true depth of each train frame (the renderer's, kind `z`): every frame's map
    // agrees with the still scene, is used, and nothing is said.
    let world = SynthWorld::new(&cfg).unwrap();
    let times = cfg.train_times();
    let truth: Vec<Option<Vec<f32>>> = (times.iter())
        .map(|&t| Some(world.render_frame(t).depth))
        .collect();
    let train = scene::manifest::Scene::open(&scene).unwrap().train;
    let write = |maps| {
        let _ = std::fs::remove_dir_all(scene.join(scene::depth_prior::DIR));
        let p = DepthPriors {
            kind: DepthKind::Z,
            maps,
        };
        scene::depth_prior::write(&scene, &train, &p).unwrap();
    };
    write(truth);
    let r = init_report(&scene, &tmp.path().join("truth"), &config);
    assert_eq!(
        r["tracks_init"]["prior_frames"].as_u64(),
        Some(times.len() as u64),
        "{}",
        r["tracks_init"]
    );
    assert!(r["tracks_init"]["moving"].as_u64().unwrap() > 0);
    assert!(warnings(&r).is_empty(), "{:?}", warnings(&r));

    // Maps a hundred units deep everywhere: no frame agrees with the still scene, so
    // none is used, and the report says the priors were there but not used.
    write(times.iter().map(|_| Some(vec![100.0; 64 * 64])).collect());
    let r = init_report(&scene, &tmp.path().join("wrong"), &config);
    assert_eq!(r["tracks_init"]["prior_frames"], 0, "{}", r["tracks_init"]);
    let w = warnings(&r);
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].contains("were not used") && w[0].contains("depth.json's kind"),
        "{}",
        w[0]
    );
}

#[test]
fn a_still_scene_is_not_warned_about() {
    // `static`: nothing moves. A few tracks on the floor and wall drift and lift as
    // moving (0.4 % of the starts at 64²), but there is no moving object to misplace.
    let tmp = tempfile::tempdir().unwrap();
    let mut cfg = config();
    let still = SynthConfig::preset("static").unwrap();
    (cfg.objects, cfg.preset) = (still.objects, still.preset);
    let scene = tmp.path().join("scene");
    synth::write_rgb_synthetic_scene(&cfg, &scene).unwrap();
    let r = init_report(&scene, &tmp.path().join("out"), &settings(tmp.path()));
    let share = r["tracks_init"]["moving_share"].as_f64().unwrap();
    assert!(share < 0.01, "{}", r["tracks_init"]);
    assert!(warnings(&r).is_empty(), "{:?}", warnings(&r));
}
