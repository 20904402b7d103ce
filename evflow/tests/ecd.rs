//! The shipped pretrained weights (`evflow/weights/default.safetensors`) load with their
//! sidecar and score zero-shot on the real ECD `shapes_rotation` slice (EPE against its
//! `flow.npy`, flow-warp loss). The figures are recorded in BENCHMARKS.md.

use burn::tensor::{DType, Device};
use evflow::eval::EcdSlice;
use evflow::net::FlowNet;
use std::path::Path;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn shipped_weights_score_zero_shot_on_the_ecd_slice() {
    // `EVFLOW_WEIGHTS` scores other weights (e.g. the other widths of the table).
    let weights = std::env::var_os("EVFLOW_WEIGHTS")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| root().join("weights/default.safetensors"));
    let net = FlowNet::load(&weights, None, &Device::flex(), DType::F32).unwrap();
    assert_eq!(net.config.bins, 5);
    assert!(net.param_count() < 4_000_000, "shipped weights stay small");
    let s = EcdSlice::read(&testkit::testdata::shared_data("ecd_shapes_rotation")).unwrap();
    let score = s.score_net(&net).unwrap();
    eprintln!(
        "ECD zero-shot (C={}): masked EPE {:.3} px, {:.1}% > 3 px (zero flow {:.3}); \
         per-event EPE {:.3}; flow-warp ratio {:.3} ; forward {:.0} ms",
        net.config.base,
        score.masked.epe,
        score.masked.outliers_pct,
        score.masked.gt_magnitude,
        score.per_event.epe,
        score.flow_warp.ratio,
        score.forward_s * 1e3
    );
    for m in [score.masked, score.dense, score.per_event] {
        assert!(m.epe.is_finite() && m.count > 0);
        assert!((0.0..=100.0).contains(&m.outliers_pct));
    }
    // Zero-shot, the pretrained net must beat zero flow clearly and sharpen the events
    // (shipped C=16: EPE 3.33 px vs 12.40 for zero flow, flow-warp ratio 2.43; the
    // previous weights 4.99 px, 1.86).
    assert!(
        score.masked.epe < 0.6 * score.masked.gt_magnitude,
        "EPE {} vs zero flow {}",
        score.masked.epe,
        score.masked.gt_magnitude
    );
    assert!(
        score.flow_warp.ratio > 1.3,
        "flow-warp {}",
        score.flow_warp.ratio
    );
    // Deterministic: the same weights give the same figures.
    let again = s.score_net(&net).unwrap();
    assert_eq!(score.masked, again.masked);
}
