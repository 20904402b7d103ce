//! A window with millions of events (issue #4): `evflow finetune` on one 0.1 s window
//! of 2.4 M synthetic events at 64×48 warns that the CM loss subsamples, trains one
//! step on the subsample, and predicts a finite flow for every single event.

use std::process::Command;

const W: u32 = 64;
const H: u32 = 48;
const N: usize = 2_400_000;

/// A textured pattern translating by (+8, −4) px over 0.1 s: events at the pixels of
/// its moving edges, N in all, time-sorted.
fn big_stream() -> scene::events::EventStream {
    let mut ev = scene::events::EventStream::with_capacity(W, H, N);
    let span = 0.1;
    let mut k = 0u64;
    for i in 0..N {
        let t = span * i as f64 / N as f64;
        // A pseudo-random point on a grid of vertical and horizontal edges, shifted.
        k = k
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let r = (k >> 33) as u32;
        let (sx, sy) = (80.0 * t, -40.0 * t);
        let (x, y) = if r & 1 == 0 {
            ((r >> 1) % 6 * 11 + 3, (r >> 4) % H)
        } else {
            ((r >> 4) % W, (r >> 1) % 5 * 10 + 4)
        };
        let x = (x as f64 + sx).round().clamp(0.0, (W - 1) as f64) as u16;
        let y = (y as f64 + sy).round().rem_euclid(H as f64) as u16;
        ev.push(t, x, y, if r & 2 == 0 { 1 } else { -1 });
    }
    ev
}

#[test]
fn millions_of_events_in_one_window_give_finite_flow_for_every_event() {
    let tmp = tempfile::tempdir().unwrap();
    let events = tmp.path().join("big.evs");
    let stream = big_stream();
    assert_eq!(stream.len(), N);
    scene::formats::evs::write_evs(&events, &stream).unwrap();
    drop(stream);
    let out = tmp.path().join("out");
    let start = std::time::Instant::now();
    let run = Command::new(env!("CARGO_BIN_EXE_evflow"))
        .args(["finetune", "--events"])
        .arg(&events)
        .args(["--sensor", "64x48", "--epochs", "1", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    eprintln!(
        "finetune + predict of {N} events: {:.1} s",
        start.elapsed().as_secs_f64()
    );
    // A clear warning that the CM loss subsamples (every 12th event: 200 000 of 2.4 M).
    assert!(
        err.contains("warning: window 0 has 2400000 events") && err.contains("subsample of 200000"),
        "{err}"
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["events"], N);
    assert_eq!(
        report["finetune"]["cm_subsampled_windows"],
        serde_json::json!([0])
    );
    let curve = report["finetune"]["loss_curve"].as_array().unwrap();
    assert_eq!(curve.len(), 1, "one window, one epoch: one step");
    let loss = curve[0].as_f64().unwrap();
    assert!(loss.is_finite() && loss > 0.0, "{loss}");
    for key in ["cm_loss_before", "cm_loss_after"] {
        assert!(
            report["finetune"][key].as_f64().unwrap().is_finite(),
            "{key}"
        );
    }
    let gain = report["warp_gain"].as_f64().unwrap();
    assert!(gain.is_finite() && gain > 0.0, "{gain}");
    // Every event of the window has a finite flow, in stream order.
    let f = evflow::flowfile::read_evflow(&out.join("flow/0000.evflow")).unwrap();
    assert_eq!(f.len(), N);
    assert!(f.index.iter().enumerate().all(|(i, &j)| i as u64 == j));
    assert!(f.u.iter().chain(&f.v).all(|x| x.is_finite()));
    assert!(f.u.iter().any(|&x| x != 0.0), "a non-trivial flow");
    // The dense preview is finite too.
    let (w, h, u, v) = evflow::flowfile::read_flo(&out.join("previews/0000.flo")).unwrap();
    assert_eq!((w, h), (W, H));
    assert!(u.iter().chain(&v).all(|x| x.is_finite()));
}

#[test]
fn several_subsampled_windows_give_one_warning() {
    use evflow::settings::FlowSettings;
    use evflow::source::WindowSpec;
    use evflow::stage::{Event, Input};
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("small.evs");
    let mut ev = scene::events::EventStream::with_capacity(32, 24, 3000);
    for i in 0..3000u32 {
        let t = i as f64 * 1e-4;
        ev.push(t, ((i * 7) % 32) as u16, ((i * 5) % 24) as u16, 1);
    }
    scene::formats::evs::write_evs(&path, &ev).unwrap();
    let input = Input::Events {
        path,
        sensor: Some((32, 24)),
        calib: None,
        spec: WindowSpec {
            windows: vec![(0.0, 0.09995), (0.09995, 0.19995), (0.19995, 0.29995)],
            window_length: None,
        },
    };
    let s = FlowSettings {
        epochs: Some(1),
        max_cm_events: 500,
        previews: false,
        ..FlowSettings::default()
    };
    let mut warnings = Vec::new();
    let r = evflow::stage::run(
        &input,
        &tmp.path().join("out"),
        &s,
        true,
        None,
        false,
        |e| {
            if let Event::Warning(w) = e {
                warnings.push(w.to_string());
            }
        },
    )
    .unwrap();
    // Windows of 1000 events each (boundaries half-way between events).
    assert_eq!(r.windows, 3);
    assert_eq!(r.finetune.cm_subsampled_windows, vec![0, 1, 2]);
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert!(
        warnings[0].contains("3 windows have more than 500 events (up to 1000 in window 0)"),
        "{}",
        warnings[0]
    );
    // Below the limit: no warning, nothing subsampled.
    let s = FlowSettings {
        max_cm_events: 1000,
        ..s
    };
    warnings.clear();
    let r = evflow::stage::run(
        &input,
        &tmp.path().join("out2"),
        &s,
        true,
        None,
        false,
        |e| {
            if let Event::Warning(w) = e {
                warnings.push(w.to_string());
            }
        },
    )
    .unwrap();
    assert!(warnings.is_empty() && r.finetune.cm_subsampled_windows.is_empty());
}
