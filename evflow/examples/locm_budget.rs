//! EPE against LoCM steps and time in one fine-tuning run: the flow is scored after
//! every step (scoring time not counted), so one run with the stopping rule's
//! `max_steps` shows what the rule gives wherever it stops (the schedules depend only
//! on `min_steps` and `max_steps`, not on where training stops).
//!
//! ```text
//! cargo run -p degs-evflow --example locm_budget -- ecd DIR [SETTINGS.toml] > curve.jsonl
//! cargo run -p degs-evflow --example locm_budget -- scene DIR [SETTINGS.toml] > curve.jsonl
//! ```
//! `ecd DIR`: `events.txt`, `calib.txt`, `flow.npy` of a 240×180 ECD slice (one
//! window); `scene DIR`: a synthetic scene with `gt/`. Settings: `[evflow]` keys
//! (`stop.*`, `lr_*`, `mode`...); `epochs` is ignored (the rule decides). One JSON
//! line per step: step, LoCM seconds so far, CM loss, mean EPE (px per window),
//! zero-flow EPE, their ratio, and whether the rule stopped there.

use burn::tensor::{DType, Device};
use evflow::finetune::{FlowSettings, finetune_observed, for_inference};
use evflow::predict::{dense_flow, event_flow};
use evflow::source::{Source, WindowSpec};
use evflow::stage::{Input, score_window};
use std::path::{Path, PathBuf};
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (kind, dir) = match args.as_slice() {
        [k, d, ..] => (k.as_str(), PathBuf::from(d)),
        _ => anyhow::bail!("usage: locm_budget ecd|scene DIR [SETTINGS.toml]"),
    };
    let mut s: FlowSettings = match args.get(2) {
        Some(p) => scene::cli::settings::parse(&std::fs::read_to_string(p)?, Path::new(p))?,
        None => FlowSettings::default(),
    };
    s.epochs = None;
    let (input, dense_gt) = match kind {
        "ecd" => (
            Input::Events {
                path: dir.join("events.txt"),
                sensor: (240, 180),
                calib: Some(dir.join("calib.txt")),
                spec: WindowSpec::default(),
            },
            Some(evflow::eval::read_flow_npy(&dir.join("flow.npy"))?),
        ),
        "scene" => (Input::Scene(dir.clone()), None),
        _ => anyhow::bail!("the first argument is ecd or scene"),
    };
    let src: Source = input.open(s.frame_window)?;
    let gt = match kind {
        "scene" => evflow::predict::scene_gt(&dir)?,
        _ => None,
    };
    let weights = evflow::net::io::resolve_weights(s.weights.as_deref())?;
    let device = Device::flex().autodiff();
    let mut net = evflow::net::io::load(&weights, &s.bare_weights(), &device, DType::F32)?.net;
    let score = |net: &evflow::net::FlowNet| -> anyhow::Result<(f64, f64)> {
        let inf = for_inference(net);
        let (mut epe, mut zero, mut n) = (0.0, 0.0, 0.0);
        for w in src.windows.iter().filter(|w| !w.is_empty()) {
            let f = event_flow(&src, w, &dense_flow(&inf, &src, w));
            let r = score_window(&src, w, &f, gt.as_ref(), dense_gt.as_ref(), &dir)?;
            if let Some(m) = r.metrics.filter(|m| m.count > 0) {
                epe += m.epe;
                zero += m.gt_magnitude;
                n += 1.0;
            }
        }
        Ok((epe / n, zero / n))
    };
    let (e0, z0) = score(&net)?;
    println!(
        "{{\"step\":0,\"locm_s\":0.0,\"loss\":null,\"epe_px\":{e0:.4},\"zero_px\":{z0:.4},\"ratio\":{:.4}}}",
        e0 / z0
    );
    let mut train_s = 0.0;
    let mut last = Instant::now();
    let mut step = 0;
    let mut failed = None;
    let report = finetune_observed(&mut net, &src, &s, |st, net| {
        train_s += last.elapsed().as_secs_f64();
        step += 1;
        match score(net) {
            Ok((e, z)) => println!(
                "{{\"step\":{step},\"locm_s\":{train_s:.3},\"loss\":{:.6},\"epe_px\":{e:.4},\"zero_px\":{z:.4},\"ratio\":{:.4}}}",
                st.loss,
                e / z
            ),
            Err(e) => failed = Some(e),
        }
        last = Instant::now();
    })?;
    if let Some(e) = failed {
        return Err(e);
    }
    eprintln!(
        "stopped after {} steps ({:?}); {:.2} s per step",
        report.steps, report.stop_reason, report.step_s
    );
    Ok(())
}
