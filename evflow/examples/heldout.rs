//! Score any weights on the held-out pretraining windows of a settings file, so that
//! networks pretrained with different data settings compare on the same windows:
//!
//! ```text
//! cargo run --release -p evflow --example heldout -- SETTINGS.toml WEIGHTS…
//! ```
//!
//! The held-out scenes, windows and metrics are those of `evflow pretrain` with
//! SETTINGS.toml (`-` for the defaults); e.g. `evflow/weights/pretrain_c16_v1.toml` gives
//! the windows (0.125 s) of the width table's "held-out EPE". One line per weights file.

use burn::tensor::{DType, Device};
use evflow::net::FlowNet;
use evflow::pretrain::{PretrainSettings, evaluate, make_held_out};
use stagekit::settings::resolve;
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((cfg, weights)) = args.split_first() else {
        anyhow::bail!("usage: heldout SETTINGS.toml|- WEIGHTS…");
    };
    let s: PretrainSettings = resolve((cfg != "-").then_some(Path::new(cfg)), |_| {})?;
    let held = make_held_out(&s)?;
    for w in weights {
        let net = FlowNet::load(w.as_ref(), None, &Device::flex(), DType::F32)?;
        let h = evaluate(&net, &held, &s, 0)?;
        println!(
            "{w}: C={} held-out EPE {:.3} px ({:.1} % > 3 px), zero-flow EPE {:.3}, flow-warp {:.3}",
            net.config.base, h.metrics.epe, h.metrics.outliers_pct, h.zero.epe, h.flow_warp_ratio
        );
    }
    Ok(())
}
