//! `runs/<stress>/stress.json` and `report.md`: every variant × method with its
//! figures or its error, a table per stress, where DEGS falls below RGB-only, and any
//! NaN.

use super::variants::StressKind;
use serde::{Deserialize, Serialize};
use synth::transform::TransformSummary;

/// One variant run with one method.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct StressResult {
    pub variant: String,
    /// None for the clean variant.
    pub stress: Option<StressKind>,
    /// The level on the chart (the neutral level for the clean variant is the chart's,
    /// not stored here); None for a corruption.
    pub level: Option<f64>,
    pub label: String,
    /// `degs` or `rgb`.
    pub method: String,
    pub experiment: String,
    /// The run's status ("ok", "failed"); "not run" when its scene could not be made.
    pub status: String,
    pub psnr: Option<f64>,
    pub ssim: Option<f64>,
    /// Test LPIPS (VGG; None when the evaluation had no LPIPS: `lpips_note`).
    pub lpips: Option<f64>,
    pub novel_psnr: Option<f64>,
    /// The 2D baselines' test PSNR (nearest frame, linear blend, event pseudo image).
    pub nearest_psnr: Option<f64>,
    pub blend_psnr: Option<f64>,
    pub events_psnr: Option<f64>,
    /// Their test LPIPS.
    pub nearest_lpips: Option<f64>,
    pub blend_lpips: Option<f64>,
    pub events_lpips: Option<f64>,
    /// Why there is no LPIPS (`degs eval`'s note: off, or no weights).
    pub lpips_note: Option<String>,
    /// Wall time of every stage the run used, as built, seconds.
    pub total_s: Option<f64>,
    /// Wall time of its `deform` stage, seconds.
    pub deform_s: Option<f64>,
    pub train_frames: Option<usize>,
    /// The failed stage and its error line, or why the figures could not be had.
    pub error: Option<String>,
    /// Figures that came out NaN or infinite (they are stored as null).
    pub non_finite: Vec<String>,
}

/// A variant's scene.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct VariantScene {
    pub variant: String,
    /// The scene directory the runs read.
    pub scene: Option<std::path::PathBuf>,
    /// What the after-the-fact transform did (None for the clean and synth variants).
    pub transform: Option<TransformSummary>,
    /// Why the scene could not be made.
    pub error: Option<String>,
}

/// `runs/<stress>/stress.json`.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct StressRecord {
    pub stress: String,
    pub stress_file: std::path::PathBuf,
    /// "synthetic <preset>" or the scene directory.
    pub base: String,
    pub sensor: (u32, u32),
    /// Each stress's level on the clean scene (its charts' reference point).
    pub neutral_levels: Vec<(StressKind, f64)>,
    /// How a burst's count was scaled to this sensor.
    pub burst_note: Option<String>,
    pub scenes: Vec<VariantScene>,
    pub results: Vec<StressResult>,
}

impl StressRecord {
    /// The results of one stress (the clean variant's at its neutral level first).
    pub fn curve(&self, kind: StressKind, method: &str) -> Vec<(f64, &StressResult)> {
        let neutral = self
            .neutral_levels
            .iter()
            .find(|(k, _)| *k == kind)
            .map(|(_, l)| *l);
        let mut out: Vec<(f64, &StressResult)> = self
            .results
            .iter()
            .filter(|r| r.method == method)
            .filter_map(|r| match r.stress {
                None => neutral.map(|l| (l, r)),
                Some(k) if k == kind => r.level.map(|l| (l, r)),
                _ => None,
            })
            .collect();
        // a level equal to the clean scene's is the clean scene (one point)
        let stressed: Vec<f64> = out
            .iter()
            .filter(|(_, r)| r.stress.is_some())
            .map(|x| x.0)
            .collect();
        out.retain(|(l, r)| r.stress.is_some() || !stressed.contains(l));
        out.sort_by(|a, b| a.0.total_cmp(&b.0));
        out
    }

    /// Every stress that has a result.
    pub fn stresses(&self) -> Vec<StressKind> {
        let mut k: Vec<StressKind> = self.results.iter().filter_map(|r| r.stress).collect();
        k.sort();
        k.dedup();
        k
    }
}

fn num(v: Option<f64>, digits: usize) -> String {
    v.map_or("—".into(), |x| format!("{x:.digits$}"))
}

/// `report.md`.
pub(crate) fn markdown(r: &StressRecord) -> String {
    let mut s = format!(
        "# Stress run `{}`\n\nBase: {} ({}×{}). Every variant is run with DEGS (the base's \
         settings) and RGB-only (`deform` with `schedule.gamma1 = gamma2_max = 0`). Test \
         PSNR/SSIM/LPIPS (VGG; lower is better) over the held-out test frames; 2D baselines \
         on the same frames. The \
         wrong-contrast stress keeps the events and changes the C the manifest claims to \
         C/ratio (ratio = true C / claimed C). `deform` estimates C from the recording by \
         default (`contrast = \"estimate\"`), so the claimed C matters only where the \
         estimate falls back to it.\n\n",
        r.stress, r.base, r.sensor.0, r.sensor.1
    );
    if let Some(note) = &r.burst_note {
        s += &format!("Burst: {note}\n\n");
    }
    let bad: Vec<String> = r
        .results
        .iter()
        .filter(|x| !x.non_finite.is_empty())
        .map(|x| format!("{} ({})", x.experiment, x.non_finite.join(", ")))
        .collect();
    s += &if bad.is_empty() {
        "**NaN check:** no figure is NaN or infinite.\n\n".to_string()
    } else {
        format!(
            "**NaN check: NON-FINITE figures in** {}\n\n",
            bad.join("; ")
        )
    };
    for kind in r.stresses() {
        s += &format!("## {} — {}\n\n", kind.key(), kind.axis_label());
        if kind == StressKind::Corrupt {
            s += &corrupt_table(r);
            continue;
        }
        s += "| level | DEGS PSNR | RGB-only PSNR | DEGS SSIM | RGB-only SSIM | DEGS LPIPS | \
              RGB-only LPIPS | DEGS novel | RGB novel | nearest | blend | events | \
              events LPIPS | train frames | DEGS s | RGB s | note |\n\
              |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
        let degs = r.curve(kind, "degs");
        let rgb = r.curve(kind, "rgb");
        let neutral = r
            .neutral_levels
            .iter()
            .find(|(k, _)| *k == kind)
            .map(|x| x.1);
        let mut below = Vec::new();
        for (level, d) in &degs {
            let g = rgb
                .iter()
                .find(|(_, g)| g.variant == d.variant)
                .map(|(_, g)| *g);
            let gp = g.and_then(|g| g.psnr);
            if let (Some(dp), Some(gp)) = (d.psnr, gp)
                && dp < gp
            {
                below.push(format!("{} ({dp:.2} < {gp:.2} dB)", d.label));
            }
            let mut note: Vec<String> = [Some(*d), g]
                .into_iter()
                .flatten()
                .filter_map(|x| x.error.as_ref().map(|e| format!("{}: {e}", x.method)))
                .collect();
            if d.stress.is_none() || Some(*level) == neutral {
                note.insert(0, "clean".into());
            }
            s += &format!(
                "| {level} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | \
                 {} | {} | {} |\n",
                num(d.psnr, 2),
                num(gp, 2),
                num(d.ssim, 3),
                num(g.and_then(|g| g.ssim), 3),
                num(d.lpips, 4),
                num(g.and_then(|g| g.lpips), 4),
                num(d.novel_psnr, 2),
                num(g.and_then(|g| g.novel_psnr), 2),
                num(d.nearest_psnr, 2),
                num(d.blend_psnr, 2),
                num(d.events_psnr, 2),
                num(d.events_lpips, 4),
                d.train_frames.map_or("—".into(), |n| n.to_string()),
                num(d.total_s, 0),
                num(g.and_then(|g| g.total_s), 0),
                note.join("; ").replace('|', "/"),
            );
        }
        s += &if below.is_empty() {
            "\nDEGS is not below RGB-only at any level.\n\n".to_string()
        } else {
            format!(
                "\n**DEGS falls below RGB-only at:** {}.\n\n",
                below.join(", ")
            )
        };
    }
    s
}

fn corrupt_table(r: &StressRecord) -> String {
    let mut s = "| corruption | damaged file | method | status | test PSNR | what happened |\n\
                 |---|---|---|---|---|---|\n"
        .to_string();
    for x in r
        .results
        .iter()
        .filter(|x| x.stress == Some(StressKind::Corrupt))
    {
        let file = r
            .scenes
            .iter()
            .find(|v| v.variant == x.variant)
            .and_then(|v| v.transform.as_ref())
            .and_then(|t| t.corrupted_file.clone())
            .unwrap_or_default();
        let what = match (&x.error, x.psnr) {
            (Some(e), _) => format!("error: {e}"),
            (None, Some(_)) => "ran to the end (graceful)".into(),
            (None, None) => "no figures".into(),
        };
        s += &format!(
            "| {} | {file} | {} | {} | {} | {} |\n",
            x.label,
            x.method,
            x.status,
            num(x.psnr, 2),
            what.replace('|', "/")
        );
    }
    s + "\n"
}
