//! `metrics.json`, the file the `evaluate` stage writes and `degs eval` completes and
//! reads: image quality of a model's renders on the held-out test frames and on the
//! novel views (whole image and masked), the 2D baselines beside them, the flow error
//! against ground truth. A file format between binaries, like the manifest: the
//! evaluation (`evaluate` crate) writes it, the runner (`degs`) reads it without linking
//! the evaluation.

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// PSNR of identical images is reported as this (dB), so means and JSON stay finite.
pub const PSNR_CAP: f64 = 100.0;

/// metrics.json of a run.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Metrics {
    /// The experiment (filled in by `degs eval`; empty in the stage's own output).
    #[serde(default)]
    pub experiment: String,
    /// The stage whose `renders/` were evaluated (filled in by `degs eval`).
    pub render_stage: Option<String>,
    pub frames: Vec<FrameMetrics>,
    pub psnr_mean: Option<f64>,
    pub ssim_mean: Option<f64>,
    /// The same stage's renders of the novel views (`<renders>/novel/`) against the
    /// scene's novel-view images; empty when either has none.
    #[serde(default)]
    pub novel_frames: Vec<FrameMetrics>,
    #[serde(default)]
    pub novel_psnr_mean: Option<f64>,
    #[serde(default)]
    pub novel_ssim_mean: Option<f64>,
    /// The novel views beside their renders and the difference (`novel_sheet.png`).
    #[serde(default)]
    pub novel_sheet: Option<PathBuf>,
    /// The novel views' PSNR over the pixels of moving objects and over the pixels some
    /// train view saw (means over the frames that have such pixels); None where the
    /// scene cannot say.
    #[serde(default)]
    pub novel_moving_psnr_mean: Option<f64>,
    #[serde(default)]
    pub novel_covisible_psnr_mean: Option<f64>,
    /// The same means of SSIM over those pixels, and of the relative depth error over
    /// the moving objects' pixels ([`MaskFigures`]).
    #[serde(default)]
    pub novel_moving_ssim_mean: Option<f64>,
    #[serde(default)]
    pub novel_covisible_ssim_mean: Option<f64>,
    #[serde(default)]
    pub novel_moving_depth_error_mean: Option<f64>,
    /// The means of the masked LPIPS ([`MaskFigures::moving_lpips`]).
    #[serde(default)]
    pub novel_moving_lpips_mean: Option<f64>,
    #[serde(default)]
    pub novel_covisible_lpips_mean: Option<f64>,
    /// PSNR and SSIM over the co-visible pixels no moving object covers: the still
    /// scene seen from elsewhere, apart from the objects ([`MaskFigures`]).
    #[serde(default)]
    pub novel_covisible_still_psnr_mean: Option<f64>,
    #[serde(default)]
    pub novel_covisible_still_ssim_mean: Option<f64>,
    /// The render stage's Gaussians against the moving objects' true 3D motion.
    #[serde(default)]
    pub trajectory: Option<Trajectory>,
    /// Mean LPIPS of the test frames and of the novel views (network `lpips_net`);
    /// None with the reason in `lpips_note` when the weights cannot be had.
    #[serde(default)]
    pub lpips_mean: Option<f64>,
    #[serde(default)]
    pub novel_lpips_mean: Option<f64>,
    /// The test frames' PSNR and LPIPS over the pixels a moving object covers
    /// (`gt/test/object_NNNN.png`), when the scene has those masks.
    #[serde(default)]
    pub moving_psnr_mean: Option<f64>,
    #[serde(default)]
    pub moving_lpips_mean: Option<f64>,
    /// The same over the pixels no moving object covers (the still scene).
    #[serde(default)]
    pub still_psnr_mean: Option<f64>,
    #[serde(default)]
    pub still_lpips_mean: Option<f64>,
    /// The test frames beside the model's renders and the 2D baselines
    /// (`test_sheet.png`), when written.
    #[serde(default)]
    pub test_sheet: Option<PathBuf>,
    /// Where the error stays over the test frames: the model's and the 2D baselines'
    /// mean absolute error per pixel (`test_error_map.png`), when written.
    #[serde(default)]
    pub test_error_map: Option<PathBuf>,
    #[serde(default)]
    pub lpips_net: Option<String>,
    #[serde(default)]
    pub lpips_note: Option<String>,
    /// The 2D baselines on the test frames (PSNR capped as the frames' are); None with
    /// the reason in `baselines_note` when they are not available.
    #[serde(default)]
    pub baselines: Option<BaselineFigures>,
    #[serde(default)]
    pub baselines_note: Option<String>,
    /// What the scene checks ([`crate::check`]) found: e.g. test frames that are train
    /// frames, whose scores are then not held-out scores.
    #[serde(default)]
    pub scene_findings: Vec<String>,
    /// Mean end-point error (px/s) of the per-event flow against the scene's ground
    /// truth (`gt/event_flow.bin`), over every non-noise event of every window; when
    /// the flow files cannot be read, the figure the evflow stage reported.
    pub flow_epe: Option<f64>,
    /// The same error in pixels over each event's window, and the fraction of events
    /// above 3 px.
    pub flow_err_px: Option<f64>,
    pub flow_outliers: Option<f64>,
    /// Events the flow figures are computed over.
    pub flow_events: usize,
    /// Where the flow figures come from: "gt/event_flow.bin" or "evflow report".
    pub flow_source: Option<String>,
    /// Total wall time of the stages that built this run's entries, seconds (filled in
    /// by `degs eval`).
    #[serde(default)]
    pub total_stage_s: f64,
    #[serde(default)]
    pub stage_s: Vec<(String, f64)>,
    /// What the run's stages say a user must know about these figures, `warning
    /// (STAGE): …` (filled in by `degs eval` from their reports' `warnings`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FrameMetrics {
    /// The held-out image (a test frame or a novel view).
    pub test_image: PathBuf,
    pub render: PathBuf,
    pub psnr: f64,
    pub ssim: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lpips: Option<f64>,
    /// Novel views: the scores on the moving objects' and the co-visible pixels.
    #[serde(flatten)]
    pub masks: MaskFigures,
}

/// A novel frame's figures in `metrics.json` (flattened into its frame record).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MaskFigures {
    /// The pixels moving objects cover in the ground truth, the PSNR and SSIM over them
    /// and the render's relative depth error there.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moving_pixels: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moving_psnr: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moving_ssim: Option<f64>,
    /// Mean relative depth error `|d − d_gt| / d_gt` of the render over the moving
    /// objects' pixels (a pixel the render leaves empty counts 1); None without the
    /// render's depth (`<renders>/novel_depth/NAME.exr`) or the scene's
    /// (`gt/novel/depth_NNNN.exr`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moving_depth_error: Option<f64>,
    /// The pixels some train view saw, and the PSNR and SSIM over them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covisible_pixels: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covisible_psnr: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covisible_ssim: Option<f64>,
    /// The co-visible pixels no moving object covers (both masks needed), and the PSNR
    /// and SSIM over them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covisible_still_pixels: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covisible_still_psnr: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covisible_still_ssim: Option<f64>,
    /// The pixels no moving object covers (the moving mask's complement), and the PSNR
    /// over them: the still scene, where a model that draws a moving object too wide or
    /// twice loses what its gain on the object hides in the whole image.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub still_pixels: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub still_psnr: Option<f64>,
    /// LPIPS over each mask: the mean of the spatial LPIPS map there
    /// (`lpips::Scored::masked_mean`); None without LPIPS or the mask.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moving_lpips: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covisible_lpips: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub still_lpips: Option<f64>,
}

/// The render stage's figures of its Gaussians' motion against the moving objects' true
/// 3D motion (`report.json`: `trajectory`, written by `gaussians::trajectory` for
/// synthetic scenes); read as the stage wrote them.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Trajectory {
    pub gaussians: usize,
    pub on_surface_fraction: f64,
    pub motion_error_mean: f64,
    pub true_motion_mean: f64,
    pub model_motion_mean: f64,
    /// Absent in reports of stages built before it was added.
    #[serde(default)]
    pub seen_motion_mean: Option<f64>,
    pub relative_error: f64,
}

/// Mean PSNR (dB) and SSIM of one baseline over the test frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Score {
    pub psnr_mean: f64,
    pub ssim_mean: f64,
    /// LPIPS (the evaluation's network), when it was computed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lpips_mean: Option<f64>,
    /// PSNR over the pixels a moving object covers (`gt/test/object_NNNN.png`), when
    /// the scene has those masks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moving_psnr_mean: Option<f64>,
    /// LPIPS over the same pixels.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moving_lpips_mean: Option<f64>,
    /// PSNR and LPIPS over the pixels no moving object covers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub still_psnr_mean: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub still_lpips_mean: Option<f64>,
}

/// The three 2D baselines (nearest train frame, linear blend, two-sided event pseudo
/// image) and where their figures come from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BaselineFigures {
    pub nearest: Score,
    pub blend: Score,
    /// The two-sided event pseudo image; None when the recording has no events.
    pub events: Option<Score>,
    /// [`COMPUTED`] ([`FROM_REPORT`] in evaluations made before the evaluation scored
    /// the baselines itself).
    pub source: String,
}

/// `source` of figures read from the deform stage's report.
pub const FROM_REPORT: &str = "the deform report";
/// `source` of figures computed by the evaluation itself.
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
