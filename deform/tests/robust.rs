//! `deform train` on degenerate recordings (issue #15, #18): every loss of every
//! iteration, the trained model (Gaussians, field, PoseNet) and every number of
//! `report.json` stay finite, the test PSNR is a number, and what the training left out
//! is counted in the report (`fallbacks`, docs/DESIGN.md §9).

mod fixture;

use deform::camera_path::{CameraPath, Interp};
use deform::event_counts::EventCounts;
use deform::inputs::Inputs;
use deform::settings::DeformSettings;
use deform::stage::TrainOutcome;
use deform::trainer::{JointStep, JointTrainer};
use fixture::{BURST, BURST_EVENTS, Fixture, HOT_PIXEL_EVENTS, HOT_PIXELS, SETTINGS};
use fixture::{TEST_TIME, Variant, build};
use gaussians::model::Model;
use gaussians::{Splats, TileRasterizer};
use serde_json::Value;
use std::path::Path;

const ITERATIONS: usize = 24;

fn finite(v: &[f32]) -> bool {
    v.iter().all(|x| x.is_finite())
}

#[track_caller]
fn assert_step_finite(s: &JointStep) {
    for (k, v) in [
        ("l_rgb", s.l_rgb),
        ("l_event", s.l_event),
        ("l_motion", s.l_motion),
        ("total", s.total),
        ("psnr", s.psnr),
    ] {
        assert!(v.is_finite() && v >= 0.0, "{k} = {v} at {s:?}");
    }
    if s.event_skipped {
        assert_eq!(s.l_event, 0.0, "{s:?}");
    }
}

#[track_caller]
fn assert_splats_finite(s: &Splats) {
    assert!(!s.is_empty());
    assert!(finite(s.means.as_flattened()), "means");
    assert!(finite(s.log_scales.as_flattened()), "scales");
    assert!(finite(s.rotations.as_flattened()), "rotations");
    assert!(finite(&s.opacity_logits), "opacities");
    assert!(finite(s.sh_dc.as_flattened()), "SH DC");
    assert!(finite(s.sh_rest.as_flattened()), "SH rest");
}

/// The saved model: Gaussians, field weights, PoseNet weights, all finite.
fn assert_model_finite(out: &Path) {
    let m = Model::load(out).unwrap();
    assert_splats_finite(&m.splats);
    let field = m.field.expect("the model keeps its field");
    assert!(!field.params.is_empty() && finite(&field.params), "field");
    let bytes = std::fs::read(out.join("posenet.safetensors")).unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let p: Vec<f32> = st
        .tensor("params")
        .unwrap()
        .data()
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let want = deform::posenet::PoseNetSettings::default().num_params();
    assert!(p.len() == want && finite(&p), "PoseNet: {} values", p.len());
}

/// Paths of every `null` (a non-finite float written by serde_json) and non-finite
/// number under `v`.
fn bad_numbers(v: &Value, path: &str, out: &mut Vec<String>) {
    match v {
        Value::Null => out.push(path.to_string()),
        Value::Number(n) if !n.as_f64().is_some_and(f64::is_finite) => out.push(path.to_string()),
        Value::Array(a) => a
            .iter()
            .enumerate()
            .for_each(|(i, x)| bad_numbers(x, &format!("{path}[{i}]"), out)),
        Value::Object(o) => o
            .iter()
            .for_each(|(k, x)| bad_numbers(x, &format!("{path}.{k}"), out)),
        _ => {}
    }
}

/// `report.json`: every number finite (only the optional peak memory may be absent),
/// a finite test PSNR, the curve of every iteration, the skip counts agreeing with the
/// iterations'.
fn check_report(o: &TrainOutcome, steps: &[JointStep]) -> Value {
    let text = std::fs::read_to_string(o.out.join("report.json")).unwrap();
    let r: Value = serde_json::from_str(&text).unwrap();
    let mut bad = Vec::new();
    bad_numbers(&r, "", &mut bad);
    bad.retain(|p| p != ".peak_memory_mib");
    assert!(bad.is_empty(), "not finite in report.json: {bad:?}");
    // Above predicting the test frame by its own mean colour (17.7 dB here).
    let psnr = r["test"]["psnr_mean"].as_f64().unwrap();
    let flat = r["test"]["mean_colour_psnr_mean"].as_f64().unwrap();
    assert!(
        psnr.is_finite() && psnr > flat + 1.0,
        "test PSNR {psnr}, mean colour {flat}"
    );
    assert!(r["baselines"]["events"]["psnr_mean"].as_f64().is_some());
    assert_eq!(r["curve"].as_array().unwrap().len(), ITERATIONS);
    let f = &r["fallbacks"];
    let skipped = steps.iter().filter(|s| s.event_skipped).count() as u64;
    assert_eq!(f["event_steps_skipped"], skipped, "{f}");
    let dropped: usize = steps.iter().map(|s| s.bindings_dropped).sum();
    assert_eq!(f["bindings_dropped"], dropped as u64, "{f}");
    r
}

/// Train on `v`: every step, the model and the report checked; the report returned.
/// A broken input costs at most `tolerance_db` of test PSNR against the normal
/// recording's run (what handling it should keep).
fn run_within(v: Variant, tolerance_db: f64) -> (Fixture, Value, Vec<JointStep>) {
    let fx = build(v);
    let (o, steps) = fx.train().unwrap_or_else(|e| panic!("{v:?}: {e}"));
    assert_eq!(steps.len(), ITERATIONS);
    steps.iter().for_each(assert_step_finite);
    assert_model_finite(&o.out);
    let r = check_report(&o, &steps);
    let psnr = r["test"]["psnr_mean"].as_f64().unwrap();
    let normal = normal_psnr();
    assert!(
        psnr >= normal - tolerance_db,
        "{v:?}: test PSNR {psnr} dB against the normal recording's {normal} dB"
    );
    (fx, r, steps)
}

/// [`run_within`] 0.6 dB of the normal recording (measured: every variant within
/// 0.45 dB but the black frame, 1.1 dB).
fn run(v: Variant) -> (Fixture, Value, Vec<JointStep>) {
    run_within(v, 0.6)
}

/// The normal recording's test PSNR after the same joint training (once per binary).
fn normal_psnr() -> f64 {
    static NORMAL: std::sync::OnceLock<f64> = std::sync::OnceLock::new();
    *NORMAL.get_or_init(|| {
        let (o, _) = build(Variant::Normal).train().unwrap();
        o.report.test.psnr_mean
    })
}

#[test]
fn a_normal_recording_skips_and_drops_nothing() {
    let (_, r, steps) = run(Variant::Normal);
    let f = &r["fallbacks"];
    for k in [
        "event_steps_skipped",
        "bindings_dropped",
        "flows_out_of_range",
        "events_without_flow",
        "hot_pixels",
        "hot_pixel_events",
        "burst_bins",
        "burst_events",
    ] {
        assert_eq!(f[k], 0, "{k}: {f}");
    }
    assert!(steps.iter().all(|s| s.l_event > 0.0));
    assert!(steps.iter().any(|s| s.l_motion > 0.0 && s.bound > 0));
    // The fixture is too small to estimate C: the default `estimate` falls back to the
    // given C and says why.
    let c = &r["contrast"];
    assert_eq!(
        (c["mode"].as_str(), c["given"].as_f64()),
        (Some("estimate"), Some(0.1))
    );
    assert!(c.get("estimate").is_none(), "{c}");
    let why = c["estimate_error"].as_str().unwrap();
    assert!(why.contains("too little signal"), "{why}");
    assert_eq!(
        (c["initial"].as_f64(), c["last"].as_f64()),
        (Some(0.1), Some(0.1))
    );
    assert!(steps.iter().all(|s| s.contrast == 0.1));
}

#[test]
fn an_interval_without_events_falls_back_to_rgb_only() {
    let (_, r, steps) = run(Variant::NoEventsInInterval1);
    let f = &r["fallbacks"];
    let n = f["event_skipped_no_events"].as_u64().unwrap();
    // only the draws of that interval (one of three; 15 of 24 with this seed)
    assert!(n > 0 && n < ITERATIONS as u64, "{f}");
    assert_eq!(f["event_steps_skipped"], n, "{f}");
    // the other intervals still supervise with events
    assert!(
        steps
            .iter()
            .filter(|s| !s.event_skipped)
            .all(|s| s.l_event > 0.0)
    );
}

#[test]
fn a_hot_pixel_is_masked_and_training_goes_on() {
    let (_, r, steps) = run(Variant::HotPixel);
    let f = &r["fallbacks"];
    assert_eq!(f["event_steps_skipped"], 0, "{f}");
    assert!(steps.iter().all(|s| s.l_event > 0.0));
    // Found by its rate (40 000 events against a median of 4): masked, its events
    // counted; its 0.1 s at 400 kHz is no burst (the bins' rates leave it out).
    let at_hot = count_at(Variant::HotPixel, &[fixture::HOT]);
    assert!(at_hot > fixture::HOT_EVENTS, "{at_hot}");
    assert_eq!(
        (f["hot_pixels"].as_u64(), f["burst_bins"].as_u64()),
        (Some(1), Some(0)),
        "{f}"
    );
    assert_eq!(f["hot_pixel_events"], at_hot as u64, "{f}");
}

/// Events of variant `v` at `pixels`.
fn count_at(v: Variant, pixels: &[(u16, u16)]) -> usize {
    let ev = fixture::events(v);
    (0..ev.len())
        .filter(|&i| pixels.contains(&(ev.x[i], ev.y[i])))
        .count()
}

#[test]
fn hot_pixels_and_a_burst_are_left_out_and_counted() {
    let (_, r, steps) = run(Variant::RateOutliers);
    let f = &r["fallbacks"];
    // exactly the three hot pixels; the burst [0.19, 0.2) s is bins 28–31 of the
    // interval [0.1, 0.2) (3.125 ms each; bin 28 holds 0.6 ms of it, 300 events)
    assert_eq!(f["hot_pixels"], HOT_PIXELS.len() as u64, "{f}");
    // theirs, the scene's and the burst's there
    let at_hot = count_at(Variant::RateOutliers, &HOT_PIXELS);
    let scene_at_hot = count_at(Variant::Normal, &HOT_PIXELS);
    assert!(at_hot > HOT_PIXELS.len() * HOT_PIXEL_EVENTS + scene_at_hot);
    assert_eq!(f["hot_pixel_events"], at_hot as u64, "{f}");
    assert_eq!(f["burst_bins"], 4, "{f}");
    let ev = fixture::events(Variant::RateOutliers);
    let in_bins = ev.window_range(0.1 + 28.0 * 0.1 / 32.0, BURST[1]).len();
    assert!(in_bins > BURST_EVENTS, "{in_bins}");
    assert_eq!(f["burst_events"], in_bins as u64, "{f}");
    // The stage's bindings hold burst and hot-pixel events until the first rebind
    // (iteration 8): dropped from L_motion and counted; none after it.
    let dropped = f["bindings_dropped_rate_outliers"].as_u64().unwrap();
    assert!(dropped > 0, "{f}");
    assert!(
        steps[8..].iter().all(|s| s.bindings_dropped == 0),
        "{steps:?}"
    );
    let before: usize = steps[..8].iter().map(|s| s.bindings_dropped).sum();
    assert_eq!(before as u64, dropped, "{f}");
    // every interval still supervises L_event with its other events
    assert_eq!(f["event_steps_skipped"], 0, "{f}");
    assert!(steps.iter().all(|s| s.l_event > 0.0));
    assert!(steps.iter().any(|s| s.l_motion > 0.0 && s.bound > 0));
    let typical = &r["rate_outliers"];
    let median = typical["median_active_pixel_count"].as_f64().unwrap();
    // 2 000 scene and 5 000 burst events over 576 pixels: about 12 each
    assert!((9.0..15.0).contains(&median), "{typical}");
}

#[test]
fn a_black_frame_gives_no_pseudo_image_from_it() {
    // The RGB loss trains on the black frame itself: it costs more.
    let (_, r, _) = run_within(Variant::BlackFrame, 1.5);
    let f = &r["fallbacks"];
    // t_e nearer the black frame 1 (in interval 0 or 1): nothing valid
    assert!(
        f["event_skipped_no_valid_pixels"].as_u64().unwrap() > 0,
        "{f}"
    );
    assert_eq!(f["event_skipped_no_events"], 0, "{f}");
}

#[test]
fn a_saturated_frame_gives_no_pseudo_image_from_it() {
    let (_, r, _) = run(Variant::SaturatedFrame);
    let f = &r["fallbacks"];
    assert!(
        f["event_skipped_no_valid_pixels"].as_u64().unwrap() > 0,
        "{f}"
    );
}

#[test]
fn implausible_flows_are_dropped_from_the_motion_loss_and_counted() {
    let (fx, r, steps) = run(Variant::WildFlows);
    let f = &r["fallbacks"];
    assert!(fx.out_of_range > 0 && fx.uncovered > 0);
    assert_eq!(f["flows_out_of_range"], fx.out_of_range as u64, "{f}");
    assert_eq!(
        f["events_without_flow"],
        (fx.out_of_range + fx.uncovered) as u64,
        "{f}"
    );
    assert!(f["bindings_dropped_no_flow"].as_u64().unwrap() > 0, "{f}");
    assert!(f["bindings_dropped_outliers"].as_u64().unwrap() > 0, "{f}");
    assert!(steps.iter().any(|s| s.l_motion > 0.0 && s.bound > 0));
    // The flows at 10⁵ px/s no longer dominate: L_motion stays near the clean run's
    // 0.37 (about 1 with the wild flows that are not outliers; 20–91 before the checks).
    let worst = steps.iter().map(|s| s.l_motion).fold(0.0, f64::max);
    assert!(worst < 3.0, "L_motion up to {worst}");
}

/// Two train frames at the same time: the scene reader refuses the manifest, naming
/// it; the trainer itself, given such inputs in memory, stays finite.
#[test]
fn duplicate_frame_times_are_refused_by_the_cli_and_survived_by_the_trainer() {
    let fx = build(Variant::Normal);
    let settings: DeformSettings = stagekit::settings::parse(SETTINGS, Path::new("x")).unwrap();
    let mut d = Inputs::load(&fx.scene, &fx.model, &fx.flows, &fx.assoc, &settings).unwrap();

    // In memory: frame 2 moved to frame 1's time (0.1 s).
    d.times[2] = d.times[1];
    d.views[2].time = d.views[1].time;
    d.counts = EventCounts::build(&d.events.as_slice(), &d.times, &settings.counts).unwrap();
    let poses: Vec<_> = d.views.iter().map(|v| v.camera.cam_to_world).collect();
    d.path = CameraPath::new(&d.times, &poses, Interp::Linear).unwrap();
    let mut tr = JointTrainer::new(&d, settings);
    let r = TileRasterizer;
    let steps: Vec<JointStep> = (0..ITERATIONS).map(|_| tr.step(&r, &d)).collect();
    steps.iter().for_each(assert_step_finite);
    assert!(
        tr.fallbacks.event_skipped_empty_interval > 0,
        "{:?}",
        tr.fallbacks
    );
    assert!(steps.iter().any(|s| s.l_motion > 0.0));
    assert_splats_finite(&tr.inner.splats);
    assert!(finite(&tr.inner.field.params));
    assert!(finite(tr.posenet.as_ref().unwrap().params()));
    let model = Model::from(&tr.inner);
    let test =
        gaussians::stage::evaluate(&model, &d.test, "test", None, &Err("off".into())).unwrap();
    assert!(
        test.psnr_mean.is_finite() && test.psnr_mean > 10.0,
        "{test:?}"
    );
    let rec = deform::baselines::Recording {
        train: &d.views,
        times: &d.times,
        events: Some(&d.events),
        contrast: d.contrast,
        srgb: d.srgb,
    };
    let b = deform::baselines::evaluate(&rec, &d.test, &[TEST_TIME], None);
    let all = [&b.nearest, &b.blend, b.events.as_ref().unwrap()];
    assert!(all.iter().all(|s| s.psnr_mean.is_finite()), "{b:?}");

    // On disk: the same manifest is an error naming the file, and nothing is written.
    let path = fx.scene.join(scene::manifest::TRAIN_FILE);
    let mut m: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    m["frames"][2]["timestamp"] = m["frames"][1]["timestamp"].clone();
    std::fs::write(&path, m.to_string()).unwrap();
    let out = fx.dir.path().join("out");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_deform"))
        .arg("train")
        .args(["--scene", fx.scene.to_str().unwrap()])
        .args(["--model", fx.model.to_str().unwrap()])
        .args(["--flows", fx.flows.to_str().unwrap()])
        .args(["--assoc", fx.assoc.to_str().unwrap()])
        .args(["--out", out.to_str().unwrap(), "--iterations", "2"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(1), "{err}");
    assert!(
        err.starts_with("deform: error: ")
            && err.contains("transforms_train.json")
            && err.contains("is not after frame"),
        "{err}"
    );
    assert!(!out.exists());
}

/// A warm-up sized before the end of densification leaves its count as the cap; the
/// joint training lifts it back to the cap before the sizing (`regrow`, the default):
/// the one `model.json` records (the per-pixel cap, or an absolute cap the warm-up was
/// given), the per-pixel cap for a model that does not say; or keeps the sized count.
#[test]
fn the_joint_training_may_regrow_a_sized_warm_up_to_its_cap_before_sizing() {
    let fx = build(Variant::Normal);
    let settings: DeformSettings = stagekit::settings::parse(SETTINGS, Path::new("x")).unwrap();
    assert!(settings.regrow, "regrow is the default");
    let mut d = Inputs::load(&fx.scene, &fx.model, &fx.flows, &fx.assoc, &settings).unwrap();
    let pixels = d.views[0].rgb.len() / 3;
    let mut per_pixel = d.warmup.clone();
    per_pixel.densify.max_gaussians = 0;
    let cap = per_pixel.gaussian_cap(pixels);
    let (sized, given) = (7, 123);
    assert!(cap > given && given > sized);
    d.warmup.densify.max_gaussians = sized;
    for (regrow, before_sizing, want) in [
        (true, None, cap),
        (true, Some(given), given),
        (false, Some(given), sized),
    ] {
        d.model.info.gaussian_cap_before_sizing = before_sizing;
        let s = DeformSettings {
            regrow,
            ..settings.clone()
        };
        let mut tr = JointTrainer::new(&d, s);
        tr.step(&TileRasterizer, &d);
        assert_eq!(
            tr.inner.settings.densify.max_gaussians, want,
            "regrow {regrow}, cap before sizing {before_sizing:?}"
        );
    }
}
