//! The after-the-fact transforms on a tiny synthetic scene, and the variant expansion.

use super::variants::{Recipe, StressFile, StressKind};
use runner::cache::{BinaryHashes, Cache};
use runner::context::Context;
use scene::manifest::Scene;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use synth::transform::{Corruption, SceneTransform, apply};

/// A 24×16 `rigid` scene, 0.25 s, train frames at 40 fps (11 of them), written once.
fn base_scene() -> &'static Path {
    static DIR: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    &DIR.get_or_init(|| {
        let d = tempfile::tempdir().unwrap();
        let overrides: toml::Table = "width = 24\nheight = 16\nduration = 0.25\n\
             render_rate_hz = 400\nsupersample = 1\nframe_supersample = 1\ntrain_fps = 40\n\
             novel_angle_deg = 0\n"
            .parse()
            .unwrap();
        let cfg = runner::experiment::synth_config("rigid", &overrides).unwrap();
        let out = d.path().join("base");
        synth::write_synthetic_scene(&cfg, &out).unwrap();
        (d, out)
    })
    .1
}

fn transformed(
    t: SceneTransform,
) -> (tempfile::TempDir, Scene, synth::transform::TransformSummary) {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("out");
    let s = apply(base_scene(), &out, &t).unwrap();
    let scene = Scene::open(&out).unwrap();
    (d, scene, s)
}

#[test]
fn dropping_train_frames_keeps_the_test_frames_and_the_events() {
    let base = Scene::open(base_scene()).unwrap();
    assert_eq!(base.train.frames.len(), 11);
    let base_events = base.load_events().unwrap().len();
    for (fps, want) in [(40.0, 11), (20.0, 6), (10.0, 3), (5.0, 2)] {
        let (_d, s, sum) = transformed(SceneTransform {
            train_fps: Some(fps),
            ..Default::default()
        });
        assert_eq!(s.train.frames.len(), want, "{fps} fps");
        assert_eq!(sum.train_frames, want);
        assert_eq!(s.test.frames, base.test.frames, "test frames fixed");
        assert_eq!(s.load_events().unwrap().len(), base_events);
        assert!(
            !s.root.join("gt/train").exists(),
            "gt/train is numbered by frame"
        );
    }
}

#[test]
fn a_gap_holds_no_event_and_a_burst_its_count_in_its_window() {
    let base = Scene::open(base_scene()).unwrap().load_events().unwrap();
    let (_d, s, sum) = transformed(SceneTransform {
        gap_fraction: 0.4,
        ..Default::default()
    });
    let [g0, g1] = sum.gap.unwrap();
    assert!(
        (g0 - 0.075).abs() < 1e-9 && (g1 - 0.175).abs() < 1e-9,
        "{g0} {g1}"
    );
    let ev = s.load_events().unwrap();
    assert_eq!(ev.window_range(g0, g1).len(), 0);
    let inside = base.window_range(g0, g1).len();
    assert!(inside > 100, "the base has events in the gap: {inside}");
    assert_eq!(ev.len(), base.len() - inside);
    assert_eq!(sum.gap_removed, inside);
    assert!(!s.root.join("gt/event_flow.bin").exists());

    let (_d, s, sum) = transformed(SceneTransform {
        burst_events: 5000,
        burst_s: 0.01,
        ..Default::default()
    });
    let [b0, b1] = sum.burst.unwrap();
    assert!((b0 - 0.25 / 3.0).abs() < 1e-9 && (b1 - b0 - 0.01).abs() < 1e-12);
    let ev = s.load_events().unwrap();
    assert_eq!(ev.len(), base.len() + 5000);
    let in_window = ev.window_range(b0, b1 + 1e-12).len();
    assert_eq!(in_window, 5000 + base.window_range(b0, b1 + 1e-12).len());
}

#[test]
fn added_noise_has_the_requested_rate_over_the_sensor() {
    let base = Scene::open(base_scene()).unwrap().load_events().unwrap();
    let (pixels, span) = (24.0 * 16.0, 0.25);
    for hz in [0.5, 5.0, 20.0] {
        let (_d, s, sum) = transformed(SceneTransform {
            noise_hz: hz,
            seed: 3,
            ..Default::default()
        });
        let added = s.load_events().unwrap().len() - base.len();
        assert_eq!(added, sum.noise_events);
        // the count is rounded: within half an event of the rate, and 2 % of it
        let rate = added as f64 / (pixels * span);
        assert!(
            (rate - hz).abs() <= (0.5 / (pixels * span)).max(0.02 * hz),
            "{hz}: {rate}"
        );
    }
    let (_d, s, sum) = transformed(SceneTransform {
        hot_pixel_fraction: 0.01,
        hot_pixel_hz: 100.0,
        ..Default::default()
    });
    assert_eq!((sum.hot_pixels, sum.hot_events), (4, 100));
    assert_eq!(s.load_events().unwrap().len(), base.len() + 100);
}

#[test]
fn a_wrong_contrast_is_claimed_in_the_manifest_only() {
    let base = Scene::open(base_scene()).unwrap();
    let c = base.contrast_threshold();
    for (ratio, claimed) in [(0.5, 2.0 * c), (2.0, 0.5 * c)] {
        let (_d, s, _) = transformed(SceneTransform {
            contrast_ratio: Some(ratio),
            ..Default::default()
        });
        assert!((s.contrast_threshold() - claimed).abs() < 1e-12);
        assert_eq!(s.load_events().unwrap(), base.load_events().unwrap());
    }
}

#[test]
fn each_corruption_is_an_error_naming_its_file() {
    let corrupt = |c| {
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("out");
        let s = apply(
            base_scene(),
            &out,
            &SceneTransform {
                corrupt: Some(c),
                ..Default::default()
            },
        )
        .unwrap();
        let err = Scene::open(&out)
            .and_then(|s| s.load_events().map(|_| ()))
            .unwrap_err()
            .to_string();
        (d, s.corrupted_file.unwrap(), err)
    };
    let (_d, file, err) = corrupt(Corruption::TruncatedEvents);
    assert_eq!(file, "events.evs");
    assert!(err.contains("events.evs"), "{err}");
    let (_d, file, err) = corrupt(Corruption::MissingFrame);
    assert_eq!(file, "images/train_0005.png");
    assert!(
        err.contains("train_0005.png") && err.contains("does not exist"),
        "{err}"
    );
    let (_d, file, err) = corrupt(Corruption::NanPose);
    assert_eq!(file, "transforms_train.json");
    assert!(err.contains("transforms_train.json"), "{err}");
    // the base scene is untouched (the copy's files are hard links)
    Scene::open(base_scene()).unwrap().load_events().unwrap();
}

fn stress_file(body: &str) -> StressFile {
    let d = tempfile::tempdir().unwrap().keep();
    let p = d.join("s.toml");
    std::fs::write(&p, body).unwrap();
    StressFile::load(&p).unwrap()
}

const SYNTH_BASE: &str = "name = \"st\"\n[base]\nname = \"b\"\n[base.scene]\nsynth = \"rigid\"\n\
                          [base.scene.settings]\nwidth = 24\nheight = 16\ntrain_fps = 20\n";

#[test]
fn variants_are_named_by_level_and_share_what_they_should() {
    let f = stress_file(&format!(
        "{SYNTH_BASE}[stresses]\nfps = [20, 5]\ngap_fraction = [0.25]\n\
         corrupt = [\"nan-pose\"]\nburst_events = [10000000]\n"
    ));
    let v = f.variants().unwrap();
    let names: Vec<&str> = v.iter().map(|v| v.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "clean",
            "fps-20",
            "fps-5",
            "gap-fraction-0.25",
            "burst-events-10000000",
            "corrupt-nan-pose"
        ]
    );
    assert_eq!(f.neutral_level(StressKind::Fps), Some(20.0));
    // 10 M on 1280×720 is as many per pixel as 4167 on 24×16
    assert_eq!(f.scaled_burst(1e7), 4167);
    let Recipe::Transform(t) = &v[4].recipe else {
        panic!("{:?}", v[4])
    };
    assert_eq!((t.burst_events, t.burst_s), (4167, 0.01));

    let dir = tempfile::tempdir().unwrap();
    let ctx = Context {
        cache: Cache::new(dir.path().join("c")),
        stage_dir: Some(build_dir()),
        degs: dir.path().join("degs"),
    };
    let scene_key = |e: &runner::experiment::Experiment| {
        let nodes = runner::graph::resolve(e, &ctx, &mut BinaryHashes::default()).unwrap();
        nodes[0].key.clone().unwrap()
    };
    let exps: Vec<Vec<_>> = v
        .iter()
        .map(|v| f.experiments(v, Path::new("/scenes/x")).unwrap())
        .collect();
    assert_eq!(exps[0][0].name, "st_clean_degs");
    assert_eq!(exps[0][1].name, "st_clean_rgb");
    // both methods read one scene; fps 20 is the clean scene itself; fps 5 another
    assert_eq!(scene_key(&exps[0][0]), scene_key(&exps[0][1]));
    assert_eq!(scene_key(&exps[1][0]), scene_key(&exps[0][0]));
    assert_ne!(scene_key(&exps[2][0]), scene_key(&exps[0][0]));
    let rgb = exps[0][1].settings("deform");
    assert_eq!(rgb["schedule"]["gamma1"].as_float(), Some(0.0));
    assert_eq!(rgb["schedule"]["gamma2_max"].as_float(), Some(0.0));
    assert!(exps[0][0].settings("deform").get("schedule").is_none());
    // a transformed variant reads the directory it is given
    assert_eq!(
        exps[3][0].scene,
        runner::experiment::SceneSource::Dir(PathBuf::from("/scenes/x"))
    );
}

/// This build's binaries (`target/<profile>/`, above the test executable in `deps/`):
/// the real `synth` writes and transforms scenes (`cargo test --workspace` builds it).
fn build_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let deps = exe.parent().unwrap();
    let dir = if deps.ends_with("deps") {
        deps.parent().unwrap()
    } else {
        deps
    };
    assert!(
        dir.join("synth").is_file(),
        "{}: no `synth` binary: build the workspace's binaries (`cargo test --workspace`)",
        dir.display()
    );
    dir.to_path_buf()
}

#[test]
fn a_transformed_scene_is_a_cache_entry_keyed_by_its_settings() {
    let dir = tempfile::tempdir().unwrap();
    let ctx = Context {
        cache: Cache::new(dir.path()),
        stage_dir: Some(build_dir()),
        degs: dir.path().join("degs"),
    };
    let t = |g: f64| SceneTransform {
        gap_fraction: g,
        ..Default::default()
    };
    let (a, _) = super::transformed_scene(&ctx, (base_scene(), "k1"), &t(0.2), "s").unwrap();
    let stamp = std::fs::metadata(a.join("events.evs"))
        .unwrap()
        .modified()
        .unwrap();
    let (again, s) = super::transformed_scene(&ctx, (base_scene(), "k1"), &t(0.2), "s").unwrap();
    assert_eq!(a, again);
    assert_eq!(
        std::fs::metadata(a.join("events.evs"))
            .unwrap()
            .modified()
            .unwrap(),
        stamp
    );
    assert_eq!(s.settings, t(0.2));
    let (b, _) = super::transformed_scene(&ctx, (base_scene(), "k1"), &t(0.3), "s").unwrap();
    let (c, _) = super::transformed_scene(&ctx, (base_scene(), "k2"), &t(0.2), "s").unwrap();
    assert!(a != b && a != c && b != c);
    assert!(a.starts_with(dir.path().join("cache").join(super::STAGE)));
}

#[test]
fn bad_stress_files_name_the_file_and_the_key() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("bad.toml");
    for (body, want) in [
        (format!("{SYNTH_BASE}[stresses]\nfpz = [1]\n"), "fpz"),
        (format!("{SYNTH_BASE}[stresses]\nfps = []\n"), "fps"),
        (
            format!("{SYNTH_BASE}[stresses]\ncorrupt = [\"eaten\"]\n"),
            "eaten",
        ),
        (
            format!("{SYNTH_BASE}[stresses]\ngap_fraction = [1.5]\n"),
            "gap_fraction",
        ),
        (format!("{SYNTH_BASE}[settings]\nseeed = 1\n"), "seeed"),
        (format!("{SYNTH_BASE}extra = 1\n"), "extra"),
        (
            "name = \"x\"\n[base]\nname = \"b\"\n[base.scene]\ndir = \"nowhere\"\n".into(),
            "nowhere",
        ),
    ] {
        std::fs::write(&p, &body).unwrap();
        let msg = format!("{:#}", StressFile::load(&p).unwrap_err());
        assert!(
            msg.contains(&p.display().to_string()) && msg.contains(want),
            "{want}: {msg}"
        );
    }
}

#[test]
fn blur_needs_a_synthetic_base() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("s.toml");
    let body = format!(
        "name = \"s\"\n[base]\nname = \"b\"\n[base.scene]\ndir = \"{}\"\n\
         [stresses]\nfps = [10]\nblur_subframes = [8]\n",
        base_scene().display()
    );
    std::fs::write(&p, &body).unwrap();
    let msg = format!("{:#}", StressFile::load(&p).unwrap_err());
    assert!(msg.contains("blur") && msg.contains("synthetic"), "{msg}");
    std::fs::write(&p, body.replace("blur_subframes = [8]\n", "")).unwrap();
    let f = StressFile::load(&p).unwrap();
    assert!((f.base_fps - 40.0).abs() < 1e-6, "{}", f.base_fps);
    let v = f.variants().unwrap();
    let Recipe::Transform(t) = &v[1].recipe else {
        panic!("{:?}", v[1])
    };
    assert_eq!(t.train_fps, Some(10.0));
}

#[test]
fn the_example_stress_file_expands() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/stress/nonrigid.toml");
    let f = StressFile::load(&p).unwrap();
    assert_eq!((f.sensor, f.base_fps), ((64, 64), 10.0));
    let v = f.variants().unwrap();
    // clean + 4 + 3 + 2 + 2 + 3 + 1 + 1 + 3
    assert_eq!(v.len(), 20);
    assert_eq!(f.scaled_burst(1e7), 44_444);
    let synth_made = v
        .iter()
        .filter(|v| matches!(v.recipe, Recipe::Synth(_)))
        .count();
    assert_eq!(
        synth_made, 12,
        "fps, noise, hot pixels and blur are synth settings"
    );
}
