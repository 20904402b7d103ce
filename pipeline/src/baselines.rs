//! The 2D baselines `degs eval` prints beside a run's figures: what the nearest train
//! frame, the linear blend of the two neighbouring train frames and the two-sided event
//! pseudo image score on the test frames. Taken from the deform stage's report
//! (`baselines`) when the run has one, else computed from the scene with
//! `deform::baselines` (with the scene's frame encoding and contrast threshold, where
//! the deform stage may have overridden them by its settings).
//!
//! They predict the recorded camera's image at a time; none can render a new
//! viewpoint, so the novel views have no baseline figures.

use anyhow::Result;
use deform::baselines::{BaselineScore, Recording};
use gaussians::stage::load_views;
use scene::manifest::Scene;
use serde::{Deserialize, Serialize};
use serde_json::Value;

/// Mean PSNR (dB) and SSIM of one baseline over the test frames.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Score {
    pub psnr_mean: f64,
    pub ssim_mean: f64,
}

/// The three baselines and where their figures come from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BaselineFigures {
    pub nearest: Score,
    pub blend: Score,
    /// The two-sided event pseudo image; None when the recording has no events.
    pub events: Option<Score>,
    /// [`FROM_REPORT`] or [`COMPUTED`].
    pub source: String,
}

/// `source` of figures read from the deform stage's report.
pub const FROM_REPORT: &str = "the deform report";
/// `source` of figures computed by `degs eval` itself.
pub const COMPUTED: &str = "computed from the scene";

impl BaselineFigures {
    /// The same with every PSNR at most `cap` (identical images score +∞).
    pub fn capped(mut self, cap: f64) -> Self {
        for s in [&mut self.nearest, &mut self.blend]
            .into_iter()
            .chain(self.events.as_mut())
        {
            s.psnr_mean = s.psnr_mean.min(cap);
        }
        self
    }
}

/// The `baselines` section of a deform stage's report; None when it has none or a
/// figure is missing.
pub fn from_report(report: &Value) -> Option<BaselineFigures> {
    let b = report.get("baselines")?;
    let score = |k: &str| {
        let s = b.get(k)?;
        Some(Score {
            psnr_mean: s.get("psnr_mean")?.as_f64()?,
            ssim_mean: s.get("ssim_mean")?.as_f64()?,
        })
    };
    Some(BaselineFigures {
        nearest: score("nearest")?,
        blend: score("blend")?,
        events: score("events"),
        source: FROM_REPORT.to_string(),
    })
}

/// Score the baselines on the scene's test frames; None when it has none. Errors name
/// the file that could not be read (an image, the event stream).
pub fn compute(scene: &Scene) -> Result<Option<BaselineFigures>> {
    if scene.test.frames.is_empty() {
        return Ok(None);
    }
    let train = load_views(scene, &scene.train)?;
    let test = load_views(scene, &scene.test)?;
    let times: Vec<f64> = scene.train.frames.iter().map(|f| f.timestamp).collect();
    let test_times: Vec<f64> = scene.test.frames.iter().map(|f| f.timestamp).collect();
    let events = match scene.events_path() {
        Some(_) => Some(scene.load_events()?),
        None => None,
    };
    let rec = Recording {
        train: &train,
        times: &times,
        events: events.as_ref(),
        contrast: scene.contrast_threshold(),
        srgb: scene.train.frame_encoding.is_none_or(|e| e.is_srgb()),
    };
    let b = deform::baselines::evaluate(&rec, &test, &test_times);
    let score = |s: &BaselineScore| Score {
        psnr_mean: s.psnr_mean,
        ssim_mean: s.ssim_mean,
    };
    Ok(Some(BaselineFigures {
        nearest: score(&b.nearest),
        blend: score(&b.blend),
        events: b.events.as_ref().map(score),
        source: COMPUTED.to_string(),
    }))
}

/// Mean PSNR/SSIM of a model's renders on one split.
pub type Figures = Option<(f64, f64)>;

/// The block `degs eval` prints under its table: the model's test-frame figures beside
/// the baselines', then its novel-view figures (with no baselines). `model` names the
/// stage whose renders were scored; `baselines` is the figures or why there are none.
pub fn format_block(
    model: &str,
    test: Figures,
    novel: Figures,
    baselines: Result<&BaselineFigures, &str>,
) -> String {
    let row = |label: &str, f: Figures| match f {
        Some((p, s)) => format!("  {label:<32} {p:>8.2} {s:>7.4}\n"),
        None => format!("  {label:<32} {:>8} {:>7}\n", "-", "-"),
    };
    let of = |s: &Score| Some((s.psnr_mean, s.ssim_mean));
    let head = |title: &str| format!("{title:<34} {:>8} {:>7}\n", "PSNR dB", "SSIM");
    let model = format!("model ({model} renders)");
    let mut out = head("test frames");
    out += &row(&model, test);
    match baselines {
        Ok(b) => {
            out += &row("nearest train frame", of(&b.nearest));
            out += &row("linear blend", of(&b.blend));
            match &b.events {
                Some(e) => out += &row("event pseudo image (two-sided)", of(e)),
                None => out += "  event pseudo image (two-sided)   - (the scene has no events)\n",
            }
            out += &format!("  2D baselines: {}\n", b.source);
        }
        Err(why) => out += &format!("  2D baselines: not available ({why})\n"),
    }
    if let Some(f) = novel {
        out += &head("novel views");
        out += &row(&model, Some(f));
        out += "  2D baselines: none (they cannot render a new viewpoint)\n";
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_report_section_is_read_and_a_missing_figure_gives_none() {
        let r: Value = serde_json::from_str(
            r#"{"baselines": {"nearest": {"psnr_mean": 20.5, "ssim_mean": 0.6, "psnr": [20.5]},
                "blend": {"psnr_mean": 22.25, "ssim_mean": 0.7}, "events": null}}"#,
        )
        .unwrap();
        let b = from_report(&r).unwrap();
        assert_eq!(
            (b.nearest.psnr_mean, b.blend.ssim_mean, b.events),
            (20.5, 0.7, None)
        );
        assert_eq!(b.source, FROM_REPORT);
        let missing: Value =
            serde_json::from_str(r#"{"baselines": {"nearest": {"psnr_mean": 20.5}}}"#).unwrap();
        assert!(from_report(&missing).is_none());
        assert!(from_report(&serde_json::json!({"test": {}})).is_none());
    }

    #[test]
    fn the_block_lists_the_model_beside_each_baseline() {
        let b = BaselineFigures {
            nearest: Score {
                psnr_mean: 20.5,
                ssim_mean: 0.6,
            },
            blend: Score {
                psnr_mean: f64::INFINITY,
                ssim_mean: 1.0,
            },
            events: None,
            source: COMPUTED.into(),
        }
        .capped(100.0);
        let text = format_block("deform", Some((24.0, 0.8)), Some((19.5, 0.7)), Ok(&b));
        let lines: Vec<&str> = text.lines().collect();
        let cols = |l: &str| l.split_whitespace().map(str::to_string).collect::<Vec<_>>();
        assert_eq!(
            cols(lines[1]),
            ["model", "(deform", "renders)", "24.00", "0.8000"]
        );
        assert_eq!(cols(lines[2])[3..], ["20.50", "0.6000"]);
        assert_eq!(cols(lines[3])[2..], ["100.00", "1.0000"]);
        assert!(lines[4].contains("no events"), "{text}");
        assert_eq!(lines[5], "  2D baselines: computed from the scene");
        assert!(lines[6].starts_with("novel views"), "{text}");
        assert_eq!(cols(lines[7])[3..], ["19.50", "0.7000"]);
        assert!(lines[8].contains("cannot render a new viewpoint"), "{text}");
        let none = format_block("gaussians", None, None, Err("no test frames"));
        assert_eq!(
            none.lines().collect::<Vec<_>>()[1..],
            [
                "  model (gaussians renders)               -       -",
                "  2D baselines: not available (no test frames)"
            ]
        );
    }
}
