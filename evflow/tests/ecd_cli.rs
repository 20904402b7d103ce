//! The bare-event-file path end to end on the real ECD `shapes_rotation` slice
//! (`shared/data/ecd_shapes_rotation/`, 240×180, 20 000 events, distorted sensor):
//! `evflow predict` / `evflow finetune --calib calib.txt` (events undistorted, flow on
//! the undistorted grid of the same K), then `evflow eval --gt-flow flow.npy`. The
//! per-event EPE must be finite and clearly below zero flow (the mean gt displacement,
//! ≈ 12.6 px at the events); the figures are recorded in BENCHMARKS.md.

use std::path::{Path, PathBuf};
use std::process::Command;

fn data() -> PathBuf {
    testkit::testdata::shared_data("ecd_shapes_rotation")
}

fn evflow(args: &[&str], paths: &[(&str, &Path)]) -> String {
    let mut c = Command::new(env!("CARGO_BIN_EXE_evflow"));
    c.args(args);
    for (flag, p) in paths {
        c.arg(flag).arg(p);
    }
    let d = data();
    c.arg("--events")
        .arg(d.join("events.txt"))
        .args(["--sensor", "240x180", "--calib"])
        .arg(d.join("calib.txt"));
    let run = c.output().unwrap();
    let err = String::from_utf8_lossy(&run.stderr).into_owned();
    assert!(run.status.success(), "evflow {args:?}: {err}");
    String::from_utf8_lossy(&run.stdout).into_owned()
}

/// `evflow eval` of a flow directory: (EPE, outliers %, gt magnitude, events, warp ratio).
fn eval(flows: &Path) -> (f64, f64, f64, u64, f64) {
    let gt = data().join("flow.npy");
    let text = evflow(
        &["eval"],
        &[("--flows", flows), ("--gt-flow", gt.as_path())],
    );
    let j: serde_json::Value = serde_json::from_str(&text).unwrap();
    let w = &j["windows"];
    assert_eq!(w.as_array().unwrap().len(), 1, "one window over the slice");
    let m = &w[0]["metrics"];
    let f = |v: &serde_json::Value| v.as_f64().unwrap();
    assert_eq!(f(&j["mean_epe_px"]), f(&m["epe"]));
    (
        f(&m["epe"]),
        f(&m["outliers_pct"]),
        f(&m["gt_magnitude"]),
        m["count"].as_u64().unwrap(),
        f(&j["mean_flow_warp_ratio"]),
    )
}

#[test]
fn calibrated_event_file_predict_finetune_and_eval_against_flow_npy() {
    let tmp = tempfile::tempdir().unwrap();
    let none = tmp.path().join("none");
    let lora = tmp.path().join("lora");
    evflow(&["predict", "--no-previews"], &[("--out", none.as_path())]);
    // One LoCM step (one window, one epoch) keeps the test short.
    evflow(
        &["finetune", "--mode", "lora", "--epochs", "1"],
        &[("--out", lora.as_path())],
    );
    let a = eval(&none);
    let b = eval(&lora);
    eprintln!("ECD via the CLI, none: {a:?}\nECD via the CLI, lora 1 step: {b:?}");
    for (epe, out, gt, count, ratio) in [a, b] {
        assert_eq!(count, 20_000, "every event scored");
        assert!((12.0..13.2).contains(&gt), "zero-flow EPE {gt}");
        assert!(epe.is_finite() && (0.0..=100.0).contains(&out));
        // Shipped C=16 weights: 3.69 px zero-shot, 3.38 after one LoCM step (measured;
        // previous weights 5.48 / 4.88), against 12.59 px for zero flow.
        assert!(epe < 0.47 * gt, "EPE {epe} vs zero flow {gt}");
        assert!(ratio > 1.5, "flow-warp ratio {ratio}");
    }
    // One LoCM step on the slice already lowers the EPE and sharpens the events more.
    // Measured: 3.69 -> 3.38 px (8.6 % lower); over LoRA seeds 0-7 (`--seed`) 3.36 to
    // 3.39 px, i.e. 8.2-9.0 % lower, a spread of 0.03 px. The bar is half the measured
    // gain, 4 % (0.15 px): five times the seed spread away from the measurement, so a
    // different platform's rounding does not flip it, while a LoCM step that stops
    // helping (or keeps less than half its effect) fails.
    assert!(
        b.0 < 0.96 * a.0,
        "lora {} vs none {}: {:.1} % lower, expected > 4 %",
        b.0,
        a.0,
        100.0 * (1.0 - b.0 / a.0)
    );
    assert!(b.1 < a.1, "outliers: lora {} vs none {}", b.1, a.1);
    assert!(b.4 > a.4, "flow-warp ratio: lora {} vs none {}", b.4, a.4);
    // The report records the undistortion grid and every event's flow.
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(lora.join("report.json")).unwrap()).unwrap();
    assert_eq!(r["events"], 20_000);
    assert_eq!(r["finetune"]["loss_curve"].as_array().unwrap().len(), 1);
    let f = evflow::flowfile::read_evflow(&lora.join("flow/0000.evflow")).unwrap();
    assert_eq!((f.width, f.height, f.len()), (240, 180, 20_000));
    // The dense preview is the displacement over the slice (Middlebury), like flow.npy.
    let (w, h, u, _) = evflow::flowfile::read_flo(&lora.join("previews/0000.flo")).unwrap();
    assert_eq!((w, h, u.len()), (240, 180, 240 * 180));
    assert!(!none.join("previews").exists(), "--no-previews");
}
