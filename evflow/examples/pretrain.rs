//! Run [`evflow::pretrain::run`] without the CLI:
//! `cargo run -p evflow --example pretrain -- SETTINGS.toml OUT_DIR` (SETTINGS.toml may be
//! `-` for the defaults). Progress every 25 steps on stderr; the held-out figures at the end.

use evflow::pretrain::{PretrainSettings, run};
use stagekit::settings::resolve;
use std::path::Path;
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [cfg, out] = args.as_slice() else {
        anyhow::bail!("usage: pretrain SETTINGS.toml|- OUT_DIR");
    };
    let settings: PretrainSettings = resolve((cfg != "-").then_some(Path::new(cfg)), |_| {})?;
    let start = Instant::now();
    let mut avg = 0.0;
    let report = run(&settings, Path::new(out), false, &mut |k, n, loss| {
        avg += loss;
        if k % 25 == 0 || k == n {
            eprintln!(
                "step {k}/{n} loss {:.4} ({:.0} s)",
                avg / 25.0,
                start.elapsed().as_secs_f64()
            );
            avg = 0.0;
        }
    })?;
    eprintln!(
        "data {:.1} s, train {:.1} s ({:.3} s/step), {} params",
        report.data_s, report.train_s, report.step_s, report.params
    );
    for h in &report.held_out {
        eprintln!(
            "held-out @{}: EPE {:.3} px ({:.1}% > 3 px), zero-flow EPE {:.3}, flow-warp {:.3}, forward {:.1} ms",
            h.step,
            h.metrics.epe,
            h.metrics.outliers_pct,
            h.zero.epe,
            h.flow_warp_ratio,
            h.forward_s * 1e3
        );
    }
    Ok(())
}
