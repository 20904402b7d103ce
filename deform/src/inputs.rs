//! What the joint training reads: the scene (train and test views, the events, the
//! camera path), the warm-up model and its settings, the per-event flow of `evflow` and
//! the bindings of `assoc`. Every error names the file it is about.

use crate::camera_path::{CameraPath, Interp};
use crate::contrast::{ContrastEstimate, estimate_contrast};
use crate::event_counts::EventCounts;
use crate::event_image::srgb_to_linear;
use crate::rate_outliers::RateOutliers;
use crate::settings::{DeformSettings, FrameEncoding};
use gaussians::model::Model;
use gaussians::stage::load_views;
use gaussians::train::{TrainSettings, View};
use scene::error::{Error, Result};
use scene::events::EventStream;
use scene::manifest::Scene;
use std::path::Path;

/// Everything the joint training needs from the files, in memory.
pub struct Inputs {
    pub scene: Scene,
    /// Train views (camera, normalised time, planar RGB as stored).
    pub views: Vec<View>,
    /// Test views (held out).
    pub test: Vec<View>,
    /// Train frames as linear intensity (planar), for the event model.
    pub linear: Vec<Vec<f32>>,
    /// Their Rec. 709 luminance (one plane each), for `L_event` on luminance.
    pub luma: Vec<Vec<f32>>,
    /// Train frame times, seconds (the events' clock).
    pub times: Vec<f64>,
    pub events: EventStream,
    /// Hot pixels and burst bins of `events` (left out of `counts` and of `L_motion`).
    pub rate_outliers: RateOutliers,
    /// Per-interval counts of `events` without the rate outliers.
    pub counts: EventCounts,
    /// Per event of the stream: flow in px/s (NaN where `evflow` gave none, or a flow
    /// beyond the network's range).
    pub flow_u: Vec<f32>,
    pub flow_v: Vec<f32>,
    /// Events whose flow was beyond the network's range (`motion.flow_range_px`), set
    /// to NaN.
    pub flows_out_of_range: usize,
    /// The interpolated camera path through the train frames.
    pub path: CameraPath,
    /// The `C` the training starts from (given or estimated, as `settings.contrast` says).
    pub contrast: f64,
    /// `contrast_threshold`, or the manifest's when that is 0.
    pub contrast_given: f64,
    /// `C` estimated from the train frames and events, or why there is none.
    pub contrast_estimate: std::result::Result<ContrastEstimate, String>,
    /// Whether the stored frames are sRGB (else linear).
    pub srgb: bool,
    pub model: Model,
    pub warmup: TrainSettings,
    /// The warm-up's moving tracks (`gaussians::tracks::file`; empty without).
    pub tracks: gaussians::tracks::loss::Table,
    /// The warm-up's aligned depth priors per train view (`depth_prior.safetensors`;
    /// empty without).
    pub priors: Vec<Option<gaussians::tracks::depth::Aligned>>,
    /// Bindings per train frame, from `assoc.bin`.
    pub bindings: Vec<assoc::Bindings>,
    /// Half-width δt of the association window.
    pub assoc_delta_t: f64,
}

/// Per-event flow of every `flow/NNNN.evflow` in `flows` spread over the stream's
/// `n` events (NaN where no window covers an event, and where a flow moves an event by
/// more than `range_px` per component over its window: beyond the flow network's
/// range, see `MotionSettings::flow_range_px`; 0 checks nothing), and the number of
/// flows found out of range.
fn read_flows(flows: &Path, n: usize, range_px: f64) -> Result<(Vec<f32>, Vec<f32>, usize)> {
    let dir = flows.join("flow");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .map_err(|e| Error::io(&dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "evflow"))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(Error::invalid(
            &dir,
            "no .evflow files: is this an evflow output?",
        ));
    }
    let (mut u, mut v) = (vec![f32::NAN; n], vec![f32::NAN; n]);
    let mut out_of_range = 0;
    for p in files {
        let f = scene::formats::evflow::read_evflow(&p)?;
        // Largest |u|, |v| (px/s) the network can give over this window.
        let limit = range_px * (1.0 + 1e-3) / (f.t_b - f.t_a);
        for (k, &i) in f.index.iter().enumerate() {
            let i = usize::try_from(i).ok().filter(|&i| i < n).ok_or_else(|| {
                Error::invalid(
                    &p,
                    format!("event index {i} beyond the stream's {n} events"),
                )
            })?;
            let fast = |x: f32| f64::from(x).abs() > limit; // false for a NaN limit
            if range_px > 0.0 && (fast(f.u[k]) || fast(f.v[k])) {
                out_of_range += 1;
                (u[i], v[i]) = (f32::NAN, f32::NAN);
            } else {
                (u[i], v[i]) = (f.u[k], f.v[k]);
            }
        }
    }
    Ok((u, v, out_of_range))
}

impl Inputs {
    /// Read the scene, the warm-up model (`model`), flows (`flows`) and bindings
    /// (`assoc`).
    pub fn load(
        scene_dir: &Path,
        model_dir: &Path,
        flows: &Path,
        assoc_dir: &Path,
        s: &DeformSettings,
    ) -> Result<Inputs> {
        let scene = Scene::open(scene_dir)?;
        let views = load_views(&scene, &scene.train)?;
        let test = load_views(&scene, &scene.test)?;
        let srgb = match s.frame_encoding {
            FrameEncoding::Srgb => true,
            FrameEncoding::Linear => false,
            FrameEncoding::Auto => scene.train.frames_srgb(),
        };
        let linear: Vec<Vec<f32>> = views
            .iter()
            .map(|v| {
                if srgb {
                    v.rgb.iter().map(|&c| srgb_to_linear(c)).collect()
                } else {
                    v.rgb.clone()
                }
            })
            .collect();
        let luma: Vec<Vec<f32>> = linear
            .iter()
            .zip(&views)
            .map(|(l, v)| crate::event_image::planar_luminance(l, v.rgb.len() / 3))
            .collect();
        let times: Vec<f64> = scene.train.frames.iter().map(|f| f.timestamp).collect();
        let events = scene.load_events()?;
        let train_file = scene.root.join(scene::manifest::TRAIN_FILE);
        let rate_outliers =
            RateOutliers::detect(&events.as_slice(), &times, s.counts.bins, &s.rate_outliers);
        let counts = EventCounts::build_excluding(
            &events.as_slice(),
            &times,
            &s.counts,
            &rate_outliers.exclusion(),
        )
        .map_err(|e| Error::invalid(&train_file, e))?;
        let path = CameraPath::from_trajectory(&scene.train_trajectory(), Interp::Linear)
            .map_err(|e| Error::invalid(&train_file, e))?;
        let contrast_given = if s.contrast_threshold > 0.0 {
            s.contrast_threshold
        } else {
            scene.contrast_threshold()
        };
        let contrast_estimate = estimate_contrast(
            &linear,
            3,
            &times,
            &events.as_slice(),
            s.pseudo.log_eps,
            &s.contrast_estimate,
        );
        let contrast = match &contrast_estimate {
            Ok(e) if s.contrast.uses_estimate() => e.c,
            _ => contrast_given,
        };
        let (flow_u, flow_v, flows_out_of_range) =
            read_flows(flows, events.len(), s.motion.flow_range_px)?;
        let mut model = Model::load(model_dir)?;
        // The warm-up's moving tracks, when it trained with `L_track`.
        let tracks_file = model_dir.join(gaussians::tracks::file::TRACKS_FILE);
        let tracks = if tracks_file.exists() {
            let n = model.splats.len();
            let (ids, table) = gaussians::tracks::file::read(&tracks_file, n, views.len())?;
            model.splats.track = ids;
            table
        } else {
            Vec::new()
        };
        // The warm-up's aligned depth priors, when it trained with `L_depth`.
        let priors_file = model_dir.join(gaussians::tracks::file::PRIORS_FILE);
        let priors = if priors_file.exists() {
            let k = &views[0].camera.intrinsics;
            let (w, h) = (k.width as usize, k.height as usize);
            gaussians::tracks::file::read_priors(&priors_file, views.len(), w, h)?
        } else {
            Vec::new()
        };
        // The warm-up's resolved settings, validated like the warm-up's own input.
        let warmup: TrainSettings =
            stagekit::settings::read_file(&model_dir.join("settings.toml"))?;
        let assoc_file = assoc_dir.join("assoc.bin");
        // Counts checked against the model before the reader allocates for them.
        let frames = assoc::read_assoc_for(&assoc_file, views.len(), model.splats.len())?;
        let assoc_delta_t = frames.first().map_or(s.assoc.delta_t, |f| f.delta_t);
        Ok(Inputs {
            scene,
            views,
            priors,
            test,
            linear,
            luma,
            times,
            events,
            rate_outliers,
            counts,
            flow_u,
            flow_v,
            flows_out_of_range,
            path,
            contrast,
            contrast_given,
            contrast_estimate,
            srgb,
            model,
            tracks,
            warmup,
            bindings: frames.into_iter().map(|f| f.bindings).collect(),
            assoc_delta_t,
        })
    }
}
