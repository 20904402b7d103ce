//! LoCM budget curves: the JSON lines `evflow`'s `locm_budget` example writes, one per
//! fine-tuning step (`cargo run -p degs-evflow --example locm_budget -- ecd|scene DIR >
//! NAME.jsonl`). `degs chart` takes these files beside run names and draws every curve
//! as flow error ÷ zero-flow error against LoCM time (drawn by the `curve_draw` module).
//!
//! A line: `{"step": 3, "locm_s": 8.1, "loss": 0.19, "epe_px": 2.9, "zero_px": 12.6,
//! "ratio": 0.23, "stopped": false}`; the line where the stopping rule stops has
//! `"stopped": true` and `"stop_reason"`. The example trains on to `max_steps` either
//! way, so the lines after the stop show what more steps would have given. Step 0 is
//! the net before fine-tuning (`loss` null). Files written before `stopped` existed
//! read with no stop marked.

use anyhow::{Result, anyhow, bail};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// One step of a curve.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct CurveStep {
    pub step: u32,
    /// LoCM fine-tuning seconds up to and including this step (scoring not counted).
    pub locm_s: f64,
    /// The step's CM loss (null for step 0).
    pub loss: Option<f64>,
    /// Mean per-event EPE over the windows, px per window.
    pub epe_px: f64,
    /// The same for predicting no motion (mean ground-truth displacement).
    pub zero_px: f64,
    /// `epe_px ÷ zero_px`.
    pub ratio: f64,
    /// The stopping rule stopped after this step.
    #[serde(default)]
    pub stopped: bool,
    /// Why it stopped (`converged`, `max_steps`…), on the stopping line only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stop_reason: Option<String>,
}

/// One curve file.
#[derive(Clone, Debug, Serialize)]
pub(crate) struct Curve {
    /// The file's stem: the curve's name on the chart.
    pub name: String,
    pub path: PathBuf,
    pub steps: Vec<CurveStep>,
}

impl Curve {
    /// The step the stopping rule stopped at, when the file marks one.
    pub fn stop(&self) -> Option<&CurveStep> {
        self.steps.iter().find(|s| s.stopped)
    }
}

/// Whether a `degs chart` argument names a curve file rather than a run.
pub fn is_curve_file(arg: &str) -> bool {
    Path::new(arg)
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("jsonl"))
}

/// Read and check a curve file; errors name the file and the line.
pub(crate) fn read_curve(path: &Path) -> Result<Curve> {
    let bytes = std::fs::read(path).map_err(|e| anyhow!("{}: cannot read: {e}", path.display()))?;
    let text = std::str::from_utf8(&bytes)
        .map_err(|e| anyhow!("{}: not UTF-8 text: {e}", path.display()))?;
    let steps = parse_steps(text).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    let name = path
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_else(|| "curve".into());
    Ok(Curve {
        name,
        path: path.to_path_buf(),
        steps,
    })
}

/// The steps of a curve file's text; errors say which line and what is wrong with it.
pub(crate) fn parse_steps(text: &str) -> Result<Vec<CurveStep>> {
    let mut steps: Vec<CurveStep> = Vec::new();
    let ends_cut = !text.is_empty() && !text.ends_with('\n');
    let lines: Vec<&str> = text.lines().collect();
    for (i, line) in lines.iter().enumerate() {
        let n = i + 1;
        if line.trim().is_empty() {
            continue;
        }
        let s: CurveStep = serde_json::from_str(line).map_err(|e| {
            if ends_cut && n == lines.len() {
                anyhow!("line {n}: cut short (the file ends inside it): {e}")
            } else {
                anyhow!("line {n}: not a LoCM curve step: {e}")
            }
        })?;
        check_step(&s).map_err(|e| anyhow!("line {n}: {e}"))?;
        if s.stopped
            && let Some(first) = steps.iter().find(|p| p.stopped)
        {
            bail!(
                "line {n}: a second stop (step {}); the rule stopped at step {}",
                s.step,
                first.step
            );
        }
        if let Some(prev) = steps.last() {
            if s.step <= prev.step {
                bail!("line {n}: step {} after step {}", s.step, prev.step);
            }
            if s.locm_s < prev.locm_s {
                bail!(
                    "line {n}: LoCM time {} s is less than the previous step's {} s",
                    s.locm_s,
                    prev.locm_s
                );
            }
        }
        steps.push(s);
    }
    if steps.is_empty() {
        bail!("no steps (an empty curve file)");
    }
    Ok(steps)
}

/// The numbers of one step are what a run can produce.
fn check_step(s: &CurveStep) -> Result<()> {
    let finite_non_negative = |name: &str, v: f64| {
        if v.is_finite() && v >= 0.0 {
            Ok(())
        } else {
            Err(anyhow!("{name} = {v} is not a non-negative number"))
        }
    };
    finite_non_negative("locm_s", s.locm_s)?;
    finite_non_negative("epe_px", s.epe_px)?;
    finite_non_negative("ratio", s.ratio)?;
    if let Some(l) = s.loss {
        finite_non_negative("loss", l)?;
    }
    if !(s.zero_px.is_finite() && s.zero_px > 0.0) {
        bail!("zero_px = {} is not a positive number", s.zero_px);
    }
    // both are printed to 4 decimals, so the ratio matches to about 1e-4
    let expected = s.epe_px / s.zero_px;
    if (s.ratio - expected).abs() > 1e-3 * (1.0 + expected) {
        bail!("ratio {} is not epe_px ÷ zero_px = {expected:.4}", s.ratio);
    }
    if s.stop_reason.is_some() && !s.stopped {
        bail!("stop_reason on a step where the rule did not stop");
    }
    Ok(())
}

/// Every curve's steps as CSV, one row per step.
pub(crate) fn to_csv(curves: &[Curve]) -> String {
    let mut s = String::from("curve,step,locm_s,loss,epe_px,zero_px,ratio,stopped,stop_reason\n");
    for c in curves {
        for p in &c.steps {
            s += &format!(
                "{},{},{},{},{},{},{},{},{}\n",
                c.name,
                p.step,
                p.locm_s,
                p.loss.map_or(String::new(), |l| l.to_string()),
                p.epe_px,
                p.zero_px,
                p.ratio,
                p.stopped,
                p.stop_reason.as_deref().unwrap_or("")
            );
        }
    }
    s
}
