//! EPE against LoCM steps and time in one fine-tuning run: the flow is scored after
//! every step (scoring time not counted). The run always goes on to the stopping
//! rule's `max_steps` (the schedules depend only on `min_steps` and `max_steps`, not
//! on where training stops), and the rule of the settings is replayed on its pass
//! losses as it goes: the step where it stops is marked, so one curve shows what the
//! rule gives there and what more steps would have given.
//!
//! ```text
//! cargo run -p degs-evflow --example locm_budget -- ecd DIR [SETTINGS.toml] > curve.jsonl
//! cargo run -p degs-evflow --example locm_budget -- scene DIR [SETTINGS.toml] > curve.jsonl
//! degs chart curve.jsonl … --out DIR      # EPE ÷ zero-flow EPE against LoCM time
//! ```
//! `ecd DIR`: `events.txt`, `calib.txt`, `flow.npy` of a 240×180 ECD slice (one
//! window); `scene DIR`: a synthetic scene with `gt/`. Settings: `[evflow]` keys
//! (`stop.*`, `lr_*`, `mode`...); `epochs` is ignored (the rule decides). One JSON
//! line per step: `step`, `locm_s` (LoCM seconds so far), `loss` (CM loss of the
//! step), `epe_px` (mean EPE, px per window), `zero_px` (zero-flow EPE), `ratio`,
//! `stopped` (true on the step where the rule stops) and there `stop_reason`.

use burn::tensor::{DType, Device};
use evflow::finetune::{finetune_observed, for_inference};
use evflow::predict::{dense_flow, event_flow};
use evflow::settings::FlowSettings;
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
        Some(p) => stagekit::settings::parse(&std::fs::read_to_string(p)?, Path::new(p))?,
        None => FlowSettings::default(),
    };
    s.epochs = None;
    let (input, dense_gt) = match kind {
        "ecd" => (
            Input::Events {
                path: dir.join("events.txt"),
                sensor: Some((240, 180)),
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
        "{}",
        serde_json::json!({"step": 0, "locm_s": 0.0, "loss": null, "epe_px": e0,
            "zero_px": z0, "ratio": e0 / z0, "stopped": false})
    );
    // Run to max_steps (a window longer than any run never converges), replaying the
    // settings' own rule on the pass losses.
    let rule = s.budget();
    let steps_per_pass = src.windows.iter().filter(|w| !w.is_empty()).count();
    let plan = rule.schedule(steps_per_pass);
    let fine_from = evflow::finetune::first_fine_pass(&s, &plan);
    let mut run = s.clone();
    run.stop.window = usize::MAX;
    let (mut pass_loss, mut pass_sum) = (Vec::new(), 0.0);
    let mut stopped = None;
    let mut train_s = 0.0;
    let mut last = Instant::now();
    let mut step = 0;
    let mut failed = None;
    finetune_observed(&mut net, &src, &run, |st, net| {
        train_s += last.elapsed().as_secs_f64();
        step += 1;
        pass_sum += st.loss;
        let mut reason = None;
        if st.step + 1 == st.steps {
            pass_loss.push(pass_sum / st.steps as f64);
            pass_sum = 0.0;
            if stopped.is_none() {
                reason = rule.stop_after(&pass_loss, fine_from, step, steps_per_pass);
                stopped = reason.map(|r| (step, r));
            }
        }
        match score(net) {
            Ok((e, z)) => {
                let mut line = serde_json::json!({"step": step, "locm_s": train_s,
                    "loss": st.loss, "epe_px": e, "zero_px": z, "ratio": e / z,
                    "stopped": reason.is_some()});
                if let Some(r) = reason {
                    line["stop_reason"] = serde_json::to_value(r).unwrap_or_default();
                }
                println!("{line}");
            }
            Err(e) => failed = Some(e),
        }
        last = Instant::now();
    })?;
    if let Some(e) = failed {
        return Err(e);
    }
    match stopped {
        Some((n, r)) => eprintln!("ran {step} steps; the rule stops after {n} ({r:?})"),
        None => eprintln!("ran {step} steps; the rule did not stop"),
    }
    Ok(())
}
