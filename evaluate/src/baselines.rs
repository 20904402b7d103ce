//! The 2D baselines beside a model's figures: what the nearest train frame, the linear
//! blend of the two neighbouring train frames and the two-sided event pseudo image
//! score on the test frames. Taken from the evaluated model's report (`baselines`,
//! which the deform stage writes) when it has them, else computed from the scene with
//! `deform::baselines` (with the scene's frame encoding and contrast threshold, where
//! the deform stage may have overridden them by its settings).
//!
//! They predict the recorded camera's image at a time; none can render a new
//! viewpoint, so the novel views have no baseline figures.

use anyhow::Result;
use deform::baselines::{BaselineScore, Recording};
use gaussians::stage::load_views;
use scene::evaluation::{BaselineFigures, COMPUTED, FROM_REPORT, Score};
use scene::manifest::Scene;
use serde_json::Value;

/// The `baselines` section of a deform stage's report; None when it has none or a
/// figure is missing.
pub(crate) fn from_report(report: &Value) -> Option<BaselineFigures> {
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
}
