//! Diagnostics for LoCM on a synthetic scene with per-event ground truth:
//!
//! ```text
//! cargo run --release -p evflow --example flow_floor -- SCENE_DIR [FLOWS_DIR …]
//! ```
//!
//! Per window and overall (event-weighted): the zero-flow EPE; the *floor* of any
//! predictor of one flow per pixel per window (each pixel predicts the mean
//! ground-truth displacement of its own events: no network can do better in the mean,
//! up to the mean/median gap); and the CM data term (λ_TV = 0, 3 scales, all events)
//! of that oracle flow, of zero flow and of each FLOWS_DIR's flow (dense flow rebuilt
//! at the event pixels from `flow/NNNN.evflow`, as `evflow eval` does). If a run's
//! flow has a lower CM loss than the oracle while its EPE is higher, the objective
//! itself prefers the wrong flow and more optimisation cannot close the gap.

use evflow::cm::{CmConfig, cm_loss};
use evflow::source::Source;
use std::path::PathBuf;

fn main() -> anyhow::Result<()> {
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    let Some((scene_dir, flows)) = args.split_first() else {
        anyhow::bail!("usage: flow_floor SCENE_DIR [FLOWS_DIR …]");
    };
    let src = Source::from_scene(scene_dir, 0.0)?;
    let gt = evflow::predict::scene_gt(scene_dir)?
        .ok_or_else(|| anyhow::anyhow!("{}: no gt/event_flow.bin", scene_dir.display()))?;
    let (wd, ht) = (src.width() as usize, src.height() as usize);
    let n = wd * ht;
    let cfg = CmConfig {
        scales: 3,
        lambda_tv: 0.0,
        first_level: 0,
    };
    let mut names = vec!["zero".to_string(), "oracle".to_string()];
    names.extend(flows.iter().map(|f| f.display().to_string()));
    // Sums over windows: EPE·count and CM loss, per flow.
    let mut epe_sum = vec![0.0; names.len()];
    let mut cm_sum = vec![0.0; names.len()];
    // Σ pred·gt, Σ |pred|, Σ |gt|: the least-squares gain and the magnitude ratio.
    let mut dot = vec![0.0; names.len()];
    let mut mag = vec![0.0; names.len()];
    let mut gt_sq = 0.0;
    let mut gt_mag = 0.0;
    let (mut count, mut windows) = (0usize, 0usize);
    for w in src.windows.iter().filter(|w| !w.is_empty()) {
        let span = w.duration();
        // Ground-truth displacement of each window event (NaN: no gt / noise).
        let gtd: Vec<(f64, f64)> = w
            .range
            .clone()
            .map(|i| match gt.index.binary_search(&(i as u64)) {
                Ok(j) if gt.object[j] != synth::gt::NOISE_ID => {
                    (gt.u[j] as f64 * span, gt.v[j] as f64 * span)
                }
                _ => (f64::NAN, f64::NAN),
            })
            .collect();
        let (mut su, mut sv, mut sn) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        for (k, i) in w.range.clone().enumerate() {
            let (u, v) = gtd[k];
            if u.is_finite() {
                let p = src.event_pixel(i);
                su[p] += u;
                sv[p] += v;
                sn[p] += 1.0;
            }
        }
        let mean = |s: &[f64]| -> Vec<f64> {
            s.iter()
                .zip(&sn)
                .map(|(a, c)| if *c > 0.0 { a / c } else { 0.0 })
                .collect()
        };
        let mut dense: Vec<(Vec<f64>, Vec<f64>)> =
            vec![(vec![0.0; n], vec![0.0; n]), (mean(&su), mean(&sv))];
        for f in flows {
            let path = f
                .join("flow")
                .join(evflow::predict::window_file(w.index, "evflow"));
            let ef = evflow::flowfile::read_evflow(&path)?;
            let (mut du, mut dv) = (vec![0.0; n], vec![0.0; n]);
            for (k, &i) in ef.index.iter().enumerate() {
                let p = src.event_pixel(i as usize);
                du[p] = ef.u[k] as f64 * span;
                dv[p] = ef.v[k] as f64 * span;
            }
            dense.push((du, dv));
        }
        let ev = src.cm_events(w, 0);
        let mut line = format!("window {} ({} events):", w.index, w.len());
        let mut scored = 0usize;
        for (m, (du, dv)) in dense.iter().enumerate() {
            let mut e = 0.0;
            scored = 0;
            for (k, i) in w.range.clone().enumerate() {
                let (u, v) = gtd[k];
                if u.is_finite() {
                    let p = src.event_pixel(i);
                    e += ((du[p] - u).powi(2) + (dv[p] - v).powi(2)).sqrt();
                    dot[m] += du[p] * u + dv[p] * v;
                    mag[m] += du[p].hypot(dv[p]);
                    if m == 0 {
                        gt_sq += u * u + v * v;
                        gt_mag += u.hypot(v);
                    }
                    scored += 1;
                }
            }
            let cm = cm_loss(&ev, du, dv, (wd, ht), (0.0, 1.0), &cfg).loss;
            epe_sum[m] += e;
            cm_sum[m] += cm;
            line.push_str(&format!(
                " {} EPE {:.3} CM {:.4};",
                names[m],
                e / scored.max(1) as f64,
                cm
            ));
        }
        count += scored;
        windows += 1;
        println!("{line}");
    }
    println!(
        "| flow | EPE px | CM data term (mean over windows) | gain Σp·g/Σg·g | mean |p| / mean |g| |"
    );
    println!("|---|---:|---:|---:|---:|");
    for (m, name) in names.iter().enumerate() {
        println!(
            "| {name} | {:.3} | {:.4} | {:.3} | {:.3} |",
            epe_sum[m] / count.max(1) as f64,
            cm_sum[m] / windows.max(1) as f64,
            dot[m] / gt_sq.max(1e-12),
            mag[m] / gt_mag.max(1e-12)
        );
    }
    Ok(())
}
