//! The per-event flow's error against the scene's ground truth (`gt/event_flow.bin`),
//! else the end-point error the flow stage reported.

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};

/// Look for a number under a key containing "epe" in a stage report.
pub(crate) fn find_epe(v: &serde_json::Value) -> Option<f64> {
    match v {
        serde_json::Value::Object(m) => m
            .iter()
            .find_map(|(k, x)| {
                k.to_ascii_lowercase()
                    .contains("epe")
                    .then(|| x.as_f64())
                    .flatten()
            })
            .or_else(|| m.values().find_map(find_epe)),
        _ => None,
    }
}

/// Per-event flow error of a directory of `.evflow` files against ground truth.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct FlowError {
    /// Mean end-point error, px/s.
    pub epe_px_s: f64,
    /// Mean error in pixels over each event's window.
    pub err_px: Option<f64>,
    /// Fraction of events whose error over the window exceeds 3 px.
    pub outliers: Option<f64>,
    pub events: usize,
}

/// Compare every `flow_dir/*.evflow` with `gt_path` (`gt/event_flow.bin`), matching
/// events by their index into the scene's stream; noise events (ground-truth object
/// [`NOISE_ID`](synth::gt::NOISE_ID)) are left out. None when no event matches.
pub(crate) fn flow_error(flow_dir: &Path, gt_path: &Path) -> Result<Option<FlowError>> {
    let gt = synth::gt::read_event_flow_gt(gt_path)?;
    let mut files: Vec<PathBuf> = std::fs::read_dir(flow_dir)
        .with_context(|| format!("{}: cannot list", flow_dir.display()))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "evflow"))
        .collect();
    files.sort();
    let mut sums = evflow::predict::GtErrorSums::default();
    for f in &files {
        let flow = evflow::flowfile::read_evflow(f)?;
        if (flow.width, flow.height) != (gt.width, gt.height) {
            bail!(
                "{}: flow is {}x{} but the ground truth {} is {}x{}",
                f.display(),
                flow.width,
                flow.height,
                gt_path.display(),
                gt.width,
                gt.height
            );
        }
        sums.add(&flow, &gt, flow.t_b - flow.t_a);
    }
    Ok(sums.means().map(|(epe, px, out)| FlowError {
        epe_px_s: epe,
        err_px: Some(px),
        outliers: Some(out),
        events: sums.events,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epe_is_found_nested() {
        let v: serde_json::Value =
            serde_json::from_str(r#"{"metrics": {"flow": {"EPE_px_s": 3.5}}}"#).unwrap();
        assert_eq!(find_epe(&v), Some(3.5));
        assert_eq!(find_epe(&serde_json::json!({"x": 1})), None);
    }
}
