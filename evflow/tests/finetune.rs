//! LoCM fine-tuning and prediction end to end on a tiny synthetic scene with a tiny
//! network: the CM loss goes down, LoRA at init is the base network bit for bit, the
//! merged adapter matches the unmerged one, empty windows give zero flow, a single
//! train frame and corrupt weights give clear errors.

use burn::tensor::{DType, Device};
use evflow::finetune::for_inference;
use evflow::net::io::sidecar;
use evflow::net::{FlowNet, NetConfig, tensor4, to_f64};
use evflow::settings::{FlowSettings, Mode};
use evflow::source::{Source, WindowSpec};
use evflow::stage::{Event, Input};
use std::path::{Path, PathBuf};
use synth::SynthConfig;

fn tiny_scene(dir: &Path) -> PathBuf {
    let out = dir.join("scene");
    let cfg = SynthConfig {
        width: 48,
        height: 40,
        duration: 0.5,
        train_fps: 8.0,
        test_frames: 4, // at (k + ½)/8 s: between the train frames
        render_rate_hz: 300.0,
        ..SynthConfig::preset("rigid").unwrap()
    };
    synth::write_synthetic_scene(&cfg, &out).unwrap();
    out
}

fn tiny_weights(dir: &Path) -> PathBuf {
    let net = FlowNet::new(
        NetConfig {
            base: 4,
            bins: 5,
            max_flow: 16.0,
        },
        11,
        &Device::flex(),
        DType::F32,
    );
    let p = dir.join("tiny.safetensors");
    net.save(&p, "test").unwrap();
    p
}

fn settings(weights: &Path, mode: Mode) -> FlowSettings {
    FlowSettings {
        mode,
        epochs: Some(4),
        lr_start: 1e-2,
        lr_end: 2e-3,
        weights: Some(weights.to_path_buf()),
        // One window per interval (the tests below count and compare those windows).
        frame_window: 0.0,
        ..FlowSettings::default()
    }
}

#[test]
fn lora_finetune_lowers_the_cm_loss_and_writes_the_stage_outputs() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tiny_scene(tmp.path());
    let w = tiny_weights(tmp.path());
    let out = tmp.path().join("out");
    let mut steps = 0;
    let r = evflow::stage::run(
        &Input::Scene(scene.clone()),
        &out,
        &settings(&w, Mode::Lora),
        true,
        None,
        false,
        |e| {
            if let Event::Step(s) = e {
                assert!(s.loss.is_finite());
                steps += 1;
            }
        },
    )
    .unwrap();
    let ft = &r.finetune;
    assert_eq!(r.windows, 4);
    assert_eq!(steps, 4 * ft.trained_windows);
    assert_eq!(ft.loss_curve.len(), steps);
    assert_eq!(ft.epoch_s.len(), 4);
    assert_eq!((ft.epochs, ft.steps), (4, steps));
    assert_eq!(ft.stop_reason, evflow::budget::StopReason::Epochs);
    assert!(
        ft.cm_loss_after < ft.cm_loss_before,
        "CM loss {} -> {}",
        ft.cm_loss_before,
        ft.cm_loss_after
    );
    assert!(r.flow_epe_px_s.is_some_and(f64::is_finite));
    for f in [
        "adapter.safetensors",
        "adapter.safetensors.json",
        "settings.toml",
        "report.json",
        "flow/0000.evflow",
        "flow/0002.evflow",
        "previews/0001.flo",
        "previews/0001.exr",
        "previews/0001.png",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    // Every event of every window has a finite flow; indices point into the stream.
    let src = Source::from_scene(&scene, 0.0).unwrap();
    let mut total = 0;
    for win in &src.windows {
        let f = evflow::flowfile::read_evflow(&out.join(format!("flow/{:04}.evflow", win.index)))
            .unwrap();
        assert_eq!(f.len(), win.len());
        assert_eq!(f.source_hash, src.source_hash);
        assert_eq!(f.index.first().copied(), Some(win.range.start as u64));
        total += f.len();
    }
    assert_eq!(total, r.events);
    // `evflow eval` (evflow::eval metrics) agrees with the stage's own figures.
    let ev = evflow::stage::eval_flows(&Input::Scene(scene.clone()), &out, None, 0.0).unwrap();
    let (a, b) = (ev.mean_epe_px.unwrap(), r.flow_err_px.unwrap());
    assert!(
        (a - b).abs() < 1e-3 * b.max(1.0),
        "eval EPE {a} vs stage {b}"
    );
    assert!((ev.mean_flow_warp_ratio - r.warp_gain).abs() < 0.05);
    // Settings round-trip through settings.toml.
    let text = std::fs::read_to_string(out.join("settings.toml")).unwrap();
    let back: FlowSettings = toml::from_str(&text).unwrap();
    assert_eq!(back, settings(&w, Mode::Lora));
    // Predicting with the saved adapter reproduces the fine-tuned flow files.
    let out2 = tmp.path().join("out2");
    let mut s = settings(&w, Mode::None);
    s.previews = false;
    evflow::stage::run(
        &Input::Scene(scene),
        &out2,
        &s,
        false,
        Some(&out.join("adapter.safetensors")),
        false,
        |_| {},
    )
    .unwrap();
    let a = evflow::flowfile::read_evflow(&out.join("flow/0001.evflow")).unwrap();
    let b = evflow::flowfile::read_evflow(&out2.join("flow/0001.evflow")).unwrap();
    assert_eq!(a, b);
}

#[test]
fn lora_at_init_is_exact_and_merged_matches_unmerged() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tiny_scene(tmp.path());
    let w = tiny_weights(tmp.path());
    let src = Source::from_scene(&scene, 0.0).unwrap();
    let win = &src.windows[1];
    let dev = Device::flex().autodiff();
    let mut net = evflow::net::io::load_base(&w, &dev).unwrap();
    let base = evflow::predict::dense_flow(&for_inference(&net), &src, win);
    net.attach_lora(16, 16.0, 3);
    // Unmerged forward on the autodiff net vs the base network.
    let (wd, ht) = (src.width() as usize, src.height() as usize);
    let (d, dt) = (net.device.clone(), net.dtype);
    let x = || tensor4(src.voxel(win, 5), [1, 5, ht, wd], &d, dt);
    let init = to_f64(net.forward(x()));
    let base_all: Vec<f64> = base.u.iter().chain(&base.v).map(|&v| v as f64).collect();
    assert_eq!(init, base_all, "LoRA at init must be the base network");
    // Train a little, then compare merged (inference copy) with unmerged.
    let s = FlowSettings {
        epochs: Some(1),
        lr_start: 5e-2,
        lr_end: 5e-2,
        ..FlowSettings::default()
    };
    let r = evflow::finetune::finetune(&mut net, &src, &s, |_| {}).unwrap();
    assert!(r.trainable_params > 0);
    let unmerged = to_f64(net.forward(x()));
    let merged = evflow::predict::dense_flow(&for_inference(&net), &src, win);
    let merged: Vec<f64> = merged
        .u
        .iter()
        .chain(&merged.v)
        .map(|&v| v as f64)
        .collect();
    let moved: f64 = unmerged
        .iter()
        .zip(&base_all)
        .map(|(a, b)| (a - b).abs())
        .sum();
    assert!(moved > 1e-3, "training did not change the flow");
    let worst = unmerged
        .iter()
        .zip(&merged)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-3, "merged vs unmerged differ by {worst} px");
}

#[test]
fn empty_window_gives_zero_flow_and_a_warning() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tiny_scene(tmp.path());
    let w = tiny_weights(tmp.path());
    let out = tmp.path().join("out");
    let input = Input::Events {
        path: scene.join("events.evs"),
        sensor: Some((48, 40)),
        calib: None,
        spec: WindowSpec {
            windows: vec![(0.1, 0.2), (50.0, 51.0)],
            window_length: None,
        },
    };
    let mut warnings = Vec::new();
    let r = evflow::stage::run(
        &input,
        &out,
        &settings(&w, Mode::Lora),
        true,
        None,
        false,
        |e| {
            if let Event::Warning(m) = e {
                warnings.push(m.to_string());
            }
        },
    )
    .unwrap();
    assert_eq!(r.predict.empty_windows, vec![1]);
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    let f = evflow::flowfile::read_evflow(&out.join("flow/0001.evflow")).unwrap();
    assert!(f.is_empty());
    let (_, _, u, v) = evflow::flowfile::read_flo(&out.join("previews/0001.flo")).unwrap();
    assert!(u.iter().chain(&v).all(|&x| x == 0.0));
    let f0 = evflow::flowfile::read_evflow(&out.join("flow/0000.evflow")).unwrap();
    assert!(!f0.is_empty() && f0.u.iter().chain(&f0.v).all(|x| x.is_finite()));
    assert!(r.finetune.cm_loss_after.is_finite());
}

#[test]
fn single_frame_scene_and_corrupt_weights_give_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tiny_scene(tmp.path());
    let w = tiny_weights(tmp.path());
    // Corrupt weights: truncated safetensors.
    let bad = tmp.path().join("bad.safetensors");
    let bytes = std::fs::read(&w).unwrap();
    std::fs::write(&bad, &bytes[..bytes.len() / 3]).unwrap();
    std::fs::copy(sidecar(&w), sidecar(&bad)).unwrap();
    let out = tmp.path().join("out");
    let e = evflow::stage::run(
        &Input::Scene(scene.clone()),
        &out,
        &settings(&bad, Mode::Lora),
        true,
        None,
        false,
        |_| {},
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("bad.safetensors"), "{e}");
    assert!(!out.exists(), "nothing half-written");
    // Missing weights file.
    let e = evflow::stage::run(
        &Input::Scene(scene.clone()),
        &out,
        &settings(&tmp.path().join("nope.safetensors"), Mode::Lora),
        true,
        None,
        false,
        |_| {},
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("nope.safetensors"), "{e}");
    // A scene with one train frame.
    let train = scene.join("transforms_train.json");
    let mut j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&train).unwrap()).unwrap();
    j["frames"].as_array_mut().unwrap().truncate(1);
    std::fs::write(&train, j.to_string()).unwrap();
    let e = Source::from_scene(&scene, 0.0).unwrap_err().to_string();
    assert!(
        e.contains("transforms_train.json") && e.contains("single train frame"),
        "{e}"
    );
}

#[test]
fn the_stopping_rule_bounds_the_steps_and_says_why_it_stopped() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tiny_scene(tmp.path());
    let w = tiny_weights(tmp.path());
    let src = evflow::source::Source::from_scene(&scene, 0.0).unwrap();
    let run = |stop: evflow::budget::StopRule| {
        let mut s = settings(&w, Mode::Lora);
        s.epochs = None;
        s.stop = stop;
        let dev = burn::tensor::Device::flex().autodiff();
        let mut net = evflow::net::io::load(&w, &s.bare_weights(), &dev, burn::tensor::DType::F32)
            .unwrap()
            .net;
        evflow::finetune::finetune(&mut net, &src, &s, |_| {}).unwrap()
    };
    use evflow::budget::{StopReason, StopRule};
    // Tolerance 0: only a loss that rose or stayed put over a pass stops it early.
    let a = run(StopRule {
        min_steps: 1,
        max_steps: 12,
        window: 1,
        tolerance: 0.0,
    });
    let per_pass = a.trained_windows;
    assert!(per_pass > 0);
    assert_eq!(a.steps, a.epochs * per_pass);
    assert_eq!(a.loss_curve.len(), a.steps);
    assert!(a.steps <= 12, "{} steps", a.steps);
    assert!(matches!(
        a.stop_reason,
        StopReason::MaxSteps | StopReason::Converged
    ));
    // An impossible tolerance (100 % gain per pass) stops as soon as the minimum ran
    // and two passes at the finest level can be compared.
    let b = run(StopRule {
        min_steps: 2 * per_pass,
        max_steps: 100,
        window: 1,
        tolerance: 1.0,
    });
    // Coarse-to-fine puts pass 0 at a coarser level, so passes 1 and 2 are compared.
    assert_eq!((b.epochs, b.stop_reason), (3, StopReason::Converged));
}
