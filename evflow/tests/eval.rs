//! Flow evaluation: metrics on hand-made cases, the real ECD slice (gt flow sharpens,
//! reversed flow blurs, zero flow scores its mean gt magnitude) and hostile inputs.

use evflow::cm::{CmConfig, CmEvents};
use evflow::eval::{EcdSlice, flow_metrics, flow_warp_loss, read_flow_npy, scale};
use std::path::PathBuf;

fn ecd_dir() -> PathBuf {
    testkit::testdata::shared_data("ecd_shapes_rotation")
}

#[test]
fn metrics_of_hand_made_flows() {
    let gt_u = [3.0, 0.0, 1.0, f64::NAN];
    let gt_v = [4.0, 0.0, 0.0, 0.0];
    let pu = [0.0, 0.0, 1.0, 9.0];
    let pv = [0.0, 3.5, 0.0, 9.0];
    let m = flow_metrics((&pu, &pv), (&gt_u, &gt_v), None).unwrap();
    // errors 5, 3.5, 0 (the NaN gt is not scored)
    assert_eq!(m.count, 3);
    assert!((m.epe - 8.5 / 3.0).abs() < 1e-12);
    assert!((m.outliers_pct - 200.0 / 3.0).abs() < 1e-9);
    assert!((m.gt_magnitude - 2.0).abs() < 1e-12);
    let masked =
        flow_metrics((&pu, &pv), (&gt_u, &gt_v), Some(&[false, true, true, true])).unwrap();
    assert_eq!(masked.count, 2);
    assert!((masked.epe - 1.75).abs() < 1e-12);
    assert!((masked.outliers_pct - 50.0).abs() < 1e-12);
    // A NaN prediction is an infinite error, not a dropped entry.
    let bad = flow_metrics((&[f64::NAN], &[0.0]), (&[1.0], &[0.0]), None).unwrap();
    assert!(bad.epe.is_infinite() && bad.outliers_pct == 100.0);
    // Nothing to score / size mismatch.
    let none = flow_metrics((&pu, &pv), (&gt_u, &gt_v), Some(&[false; 4])).unwrap();
    assert_eq!(none.count, 0);
    assert_eq!(none.epe, 0.0);
    assert!(flow_metrics((&pu[..2], &pv[..2]), (&gt_u, &gt_v), None).is_err());
    assert!(flow_metrics((&pu, &pv), (&gt_u, &gt_v), Some(&[true])).is_err());
}

#[test]
fn flow_warp_loss_of_a_moving_edge() {
    let (w, h) = (40, 16);
    let mut ev = CmEvents::default();
    for k in 0..1000 {
        let t = k as f64 / 1000.0;
        ev.x.push(5.0 + 20.0 * t);
        ev.y.push(2.0 + (k % 12) as f64);
        ev.t.push(t);
    }
    let f = |vx: f64| flow_warp_loss(&ev, &vec![vx; w * h], &vec![0.0; w * h], (w, h), 0.5);
    let (good, zero, bad) = (f(20.0), f(0.0), f(-20.0));
    assert!((zero.ratio - 1.0).abs() < 1e-12);
    assert!(good.ratio > 5.0, "good {good:?}");
    assert!(bad.ratio < 0.7, "bad {bad:?}");
    let empty = flow_warp_loss(&CmEvents::default(), &[0.0; 4], &[0.0; 4], (2, 2), 0.0);
    assert_eq!(empty.ratio, 0.0);
}

#[test]
fn ecd_slice_gt_flow_sharpens_and_zero_flow_scores_gt_magnitude() {
    let s = EcdSlice::read(&ecd_dir()).unwrap();
    assert_eq!((s.width, s.height), (240, 180));
    assert_eq!(s.cm.len(), 20_000);
    assert!((s.duration() - 0.098595).abs() < 1e-5, "{}", s.duration());
    let n = s.width * s.height;

    // Flow-warp loss: gt raises the IWE variance (README: about 1.7 → 4.4), reversed lowers.
    let zero = vec![0.0; n];
    let neg = |a: &[f64]| a.iter().map(|x| -x).collect::<Vec<_>>();
    let gt = s.score(&s.gt_u, &s.gt_v).unwrap();
    let rev = s.score(&neg(&s.gt_u), &neg(&s.gt_v)).unwrap();
    let z = s.score(&zero, &zero).unwrap();
    eprintln!(
        "ECD flow-warp: gt {:?} reversed {:?}",
        gt.flow_warp, rev.flow_warp
    );
    assert!(gt.flow_warp.ratio > 2.0, "gt ratio {}", gt.flow_warp.ratio);
    assert!(
        rev.flow_warp.ratio < 0.9,
        "reversed ratio {}",
        rev.flow_warp.ratio
    );
    assert!((z.flow_warp.ratio - 1.0).abs() < 1e-12);
    assert!(
        (1.2..2.5).contains(&z.flow_warp.var_unwarped),
        "{}",
        z.flow_warp.var_unwarped
    );
    assert_eq!(gt.masked.epe, 0.0);

    // The CM objective (lower loss = sharper) through the same API, px/s.
    let inv = 1.0 / s.duration();
    let (gu, gv) = (scale(&s.gt_u, inv), scale(&s.gt_v, inv));
    let cfg = CmConfig::default();
    let win = (s.t_a, s.t_b);
    let l_gt = evflow::eval::cm_objective(&s.cm, &gu, &gv, s.size(), win, &cfg);
    let l_zero = evflow::eval::cm_objective(&s.cm, &zero, &zero, s.size(), win, &cfg);
    let l_rev = evflow::eval::cm_objective(&s.cm, &neg(&gu), &neg(&gv), s.size(), win, &cfg);
    eprintln!("ECD CM loss: gt {l_gt:.4} zero {l_zero:.4} reversed {l_rev:.4}");
    assert!(l_gt < 0.8 * l_zero, "gt {l_gt} zero {l_zero}");
    assert!(l_rev > l_zero, "reversed {l_rev} zero {l_zero}");

    // Zero flow: EPE equals the mean gt magnitude (over the same entries).
    for m in [z.masked, z.dense, z.per_event] {
        assert!(m.count > 0);
        assert!((m.epe - m.gt_magnitude).abs() < 1e-9 * m.gt_magnitude.max(1.0));
    }
    let mean_mag: f64 = s
        .gt_u
        .iter()
        .zip(&s.gt_v)
        .map(|(u, v)| u.hypot(*v))
        .sum::<f64>()
        / n as f64;
    assert!((z.dense.epe - mean_mag).abs() < 1e-9);
    assert_eq!(z.dense.count, n);
    assert_eq!(z.per_event.count, 20_000);
    // Rotation at ~0.59 rad/s with f ≈ 199 px over 0.0986 s: displacements of ~5–15 px.
    assert!((3.0..20.0).contains(&z.masked.epe), "{}", z.masked.epe);
    eprintln!(
        "ECD zero flow: masked {:?} per event {:?}",
        z.masked, z.per_event
    );
}

#[test]
fn hostile_npy_and_calib_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("flow.npy");
    std::fs::write(&p, b"not numpy").unwrap();
    let e = read_flow_npy(&p).unwrap_err().to_string();
    assert!(e.contains("flow.npy") && e.contains("not a .npy"), "{e}");
    // Truncate the real file.
    let bytes = std::fs::read(ecd_dir().join("flow.npy")).unwrap();
    std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    let e = read_flow_npy(&p).unwrap_err().to_string();
    assert!(e.contains("flow.npy"), "{e}");
    // A full slice dir with a bad calibration.
    std::fs::write(&p, &bytes).unwrap();
    std::fs::copy(ecd_dir().join("events.txt"), dir.path().join("events.txt")).unwrap();
    std::fs::write(dir.path().join("calib.txt"), "199 198 132 110\n").unwrap();
    let e = EcdSlice::read(dir.path()).unwrap_err().to_string();
    assert!(
        e.contains("calib.txt") && e.contains("9 finite numbers"),
        "{e}"
    );
    std::fs::remove_file(dir.path().join("events.txt")).unwrap();
    std::fs::copy(ecd_dir().join("calib.txt"), dir.path().join("calib.txt")).unwrap();
    let e = EcdSlice::read(dir.path()).unwrap_err().to_string();
    assert!(e.contains("events.txt"), "{e}");
}
