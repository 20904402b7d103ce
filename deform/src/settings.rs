//! Settings of the joint training (`deform train --config settings.toml`; every key has
//! a default, unknown keys are errors).

use crate::contrast::{ContrastMode, EstimateSettings};
use crate::event_counts::CountSettings;
pub use crate::event_image::EventChannels;
use crate::event_image::{PseudoMode, PseudoSettings};
use crate::motion_loss::MotionSettings;
use crate::neighbours::NeighbourSettings;
use crate::posenet::PoseNetSettings;
use crate::rate_outliers::RateOutlierSettings;
use crate::schedule::LossSchedule;
use serde::{Deserialize, Serialize};

/// How `F_gs` (Eq. 10) projects the two deformed centres.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FlowForm {
    /// The paper's: both centres by the camera at `t0`, plus `F_ego·Δt` for the camera.
    #[default]
    Paper,
    /// `x(t1)` by the camera at `t1`, `x(t0)` by the camera at `t0` (ego-motion
    /// included, no `F_ego` term).
    Exact,
}

/// How the 8-bit frames are encoded (the event model works on linear intensity).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FrameEncoding {
    /// What the scene manifest says (`frame_encoding`), sRGB when it says nothing.
    #[default]
    Auto,
    Srgb,
    Linear,
}

/// The joint training's settings. The Gaussians' learning rates, densification and field
/// come from the warm-up's `settings.toml` in the model directory.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DeformSettings {
    /// Joint iterations after the warm-up; 0 = by the train frames' interval
    /// ([`DeformSettings::iterations_for`]): 4000 at 20 fps and faster (2000 at sensor
    /// size), growing with the interval to 6000 at 10 fps and slower.
    pub iterations: u32,
    /// Seed of the sampling of views, event times and the PoseNet's first layer.
    pub seed: u64,
    /// γ1 and γ2(iter) of Eq. 13 (`gamma1 = 0`: w/o L_event; `gamma2_max = 0` or
    /// `motion = "off"`: w/o L_motion; `motion = "auto"`, the default, uses L_motion only
    /// below 9 fps: [`crate::schedule`]).
    pub schedule: LossSchedule,
    /// Use the PoseNet correction of the interpolated camera path (`false`: plain
    /// interpolation).
    pub posenet: bool,
    pub posenet_net: PoseNetSettings,
    /// Anchor the correction to zero at the train frames (whose poses are known):
    /// `ξ(t) − (1 − s)·ξ(ta) − s·ξ(tb)` between frames `ta`, `tb`; `false` is the paper's
    /// free correction (a jump at the frames, where the recorded poses are used).
    pub posenet_anchor: bool,
    /// First joint iterations in which `L_event` trains the PoseNet only (the scene is
    /// not moved to make up for a camera error between frames); 0 = from the start.
    pub posenet_warmup: u32,
    /// Adam learning rate of the PoseNet at the first joint iteration …
    pub posenet_lr: f64,
    /// … and at the last: log-linear decay between them (a constant rate leaves the
    /// PoseNet's last iterate a random draw around its optimum; > 0).
    pub posenet_lr_final: f64,
    /// The given contrast threshold C; 0 takes the manifest's.
    pub contrast_threshold: f64,
    /// Which C the training uses: `given` (the above), `estimate` (from the frames and
    /// events; the given C when there is too little signal), `learn` (the given C, then
    /// learned through `L_event`), `estimate_learn` ([`crate::contrast`]).
    pub contrast: ContrastMode,
    pub contrast_estimate: EstimateSettings,
    /// Adam learning rate of `log C` in the learning modes.
    pub contrast_lr: f64,
    pub frame_encoding: FrameEncoding,
    /// Fine time bins of the per-pixel event counts.
    pub counts: CountSettings,
    pub pseudo: PseudoSettings,
    /// Event-rate outliers left out of `L_event` and `L_motion`: hot pixels (a count far
    /// above the active pixels' median and the neighbours') and bursts (time bins far
    /// above the recording's median rate); `hot_pixel_ratio = 0`, `burst_ratio = 0`:
    /// off ([`crate::rate_outliers`]).
    pub rate_outliers: RateOutlierSettings,
    /// Which frame(s) predict the pseudo image of `L_event`: `nearest` (Eq. 11) or
    /// `two_sided` (both neighbours, blended in log space by the distance in time).
    pub pseudo_mode: PseudoMode,
    /// What `L_event` compares: `luminance` (what events measure) or `rgb`.
    pub event_channels: EventChannels,
    /// `L_event` on one of `k × k` equal tiles of the image, picked at random each step
    /// (`crate::crop`; 1 = the whole image): every pixel is compared as often as any
    /// other, and the event render costs `1/k²` of the pixels.
    pub event_tiles: u32,
    /// `L_event` at `1/k` of the resolution (`crate::coarse`; 1 = full): the pseudo image
    /// averaged over `k × k` blocks, the render at the blocks; applied before the tiles.
    pub event_downsample: u32,
    pub motion: MotionSettings,
    /// Bound Gaussians whose events' flow disagrees with their neighbours' are left
    /// out of `L_motion` (`radius_px = 0`: never).
    pub motion_neighbours: NeighbourSettings,
    pub flow_form: FlowForm,
    /// Span Δt of the motion loss in seconds (`t1 = t0 + Δt`); 0 takes the
    /// association window's half-width δt.
    pub motion_span: f64,
    /// Rebind events to Gaussians every this many iterations (§3.3); 0 never.
    pub rebind_every: u32,
    /// Association settings used when rebinding (those of the `assoc` stage by default).
    pub assoc: assoc::AssocSettings,
    /// Continue densification as in the warm-up (within its `until_iter`).
    pub densify: bool,
    /// Let that densification grow the model back up to the warm-up's cap before its
    /// sizing (the per-pixel cap `max_gaussians_per_pixel`, or an absolute
    /// `densify.max_gaussians` given to the warm-up; `model.json`'s
    /// `gaussian_cap_before_sizing`) instead of the count the sizing chose from the
    /// frames alone: the events need Gaussians the frames did not (`nonrigid` 64², warm-up
    /// 1500: +0.46 / +0.22 dB at 8 / 4 fps; BENCHMARKS.md). Only a warm-up that stops
    /// before the end of densification leaves the joint training any to do.
    pub regrow: bool,
    /// Give the warm-up's deformation field a colour head (`FieldSettings::color`,
    /// started at zero) for the joint training: each Gaussian's colour may then change
    /// with time as the frames and the events show (shading on a turning object, a
    /// shadow moving over a still floor; the static ones keep their geometry).
    /// Nothing when the warm-up's field already has one or the warm-up kept no field.
    pub field_color: bool,
    /// The rigid parts' poses' learning rates in the joint training
    /// (`gaussians.tracks.parts`, `gaussians::parts`), as a share of the warm-up's; 0
    /// (the default) keeps the warm-up's poses while the members' own parameters train.
    /// At the warm-up's rates the joint training lost what the parts gave the warm-up
    /// (`rigid` 4 fps: moving novel pixels 14.56 → 13.52 dB, test frames 29.21 → 29.02;
    /// held: 14.37 and 30.84; BENCHMARKS.md, "Rigid parts").
    pub part_pose_lr: f64,
    /// Record the losses every this many iterations in the report.
    pub log_every: u32,
}

impl Default for DeformSettings {
    fn default() -> Self {
        DeformSettings {
            iterations: 0,
            seed: 0,
            schedule: LossSchedule::default(),
            posenet: true,
            posenet_net: PoseNetSettings::default(),
            posenet_anchor: true,
            posenet_warmup: 300,
            posenet_lr: 1e-3,
            posenet_lr_final: 1e-4,
            contrast_threshold: 0.0,
            contrast: ContrastMode::default(),
            contrast_estimate: EstimateSettings::default(),
            contrast_lr: 0.01,
            frame_encoding: FrameEncoding::Auto,
            counts: CountSettings::default(),
            pseudo: PseudoSettings::default(),
            rate_outliers: RateOutlierSettings::default(),
            pseudo_mode: PseudoMode::Nearest,
            event_channels: EventChannels::Luminance,
            event_tiles: 1,
            event_downsample: 1,
            motion: MotionSettings::default(),
            motion_neighbours: NeighbourSettings::default(),
            flow_form: FlowForm::Paper,
            motion_span: 0.0,
            rebind_every: 500,
            assoc: assoc::AssocSettings::default(),
            densify: true,
            regrow: true,
            field_color: false,
            part_pose_lr: 0.0,
            log_every: 10,
        }
    }
}

/// The joint iterations of `iterations = 0`: the fewest at train frames
/// [`AUTO_INTERVALS_S`]`.0` apart or closer, the most at `.1` apart or further.
pub const AUTO_ITERATIONS: (u32, u32) = (4000, 6000);

/// The fewest of [`AUTO_ITERATIONS`] for frames of [`SENSOR_PIXELS`] or more: a joint
/// step costs linearly in the pixels and Gaussians, and at DAVIS346 size (0.19 s a step)
/// 4000 would take the whole run from 14 to about 20 minutes.
pub const AUTO_FEWEST_SENSOR: u32 = 2000;

/// Frames of this many pixels or more (DAVIS346's 346 × 260 = 89 960; the 128² of the
/// scenes measured at 4000 is 16 384) take [`AUTO_FEWEST_SENSOR`].
pub const SENSOR_PIXELS: u64 = 65_536;

/// The frame intervals (seconds) between which `iterations = 0` grows linearly from the
/// fewest iterations to the most (20 fps and 10 fps).
pub const AUTO_INTERVALS_S: (f64, f64) = (0.05, 0.10);

impl DeformSettings {
    /// The joint iterations for train frames at `times` (seconds) of `pixels` each:
    /// `iterations`, or when that is 0, 4000 at Δt ≤ 50 ms (20 fps and faster; 2000 for
    /// frames of [`SENSOR_PIXELS`] or more), 6000 at Δt ≥ 100 ms (10 fps and slower),
    /// linear in Δt between, Δt the median interval. The longer the frames' interval,
    /// the more of the motion only the events show, and the longer the joint training
    /// keeps gaining on the frames between: measured −0.1 to +0.4 dB (LPIPS level or
    /// lower) at 4–10 fps from 6000 iterations against 4000; at 20 fps from 4000 against
    /// 2000 PSNR mixed (±0.4 dB, every row far above the event pseudo image) and LPIPS
    /// lower on the outside scenes, which only then come under the event pseudo image's
    /// on both seeds (BENCHMARKS.md, "The joint training's length", "6 000 joint
    /// iterations at 10 fps", "4 000 joint iterations at 20 fps").
    pub fn iterations_for(&self, times: &[f64], pixels: u64) -> u32 {
        if self.iterations > 0 {
            return self.iterations;
        }
        let ((fewest, most), (near, far)) = (AUTO_ITERATIONS, AUTO_INTERVALS_S);
        let fewest = if pixels >= SENSOR_PIXELS {
            AUTO_FEWEST_SENSOR
        } else {
            fewest
        };
        let dt = scene::manifest::median_interval(times);
        let s = ((dt - near) / (far - near)).clamp(0.0, 1.0);
        (f64::from(fewest) + s * f64::from(most - fewest)).round() as u32
    }

    /// Why the values cannot be used, if they cannot.
    pub fn validate(&self) -> Result<(), String> {
        let finite_nonneg = |name: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(format!("{name} must be finite and ≥ 0 (got {v})"))
            }
        };
        finite_nonneg("schedule.gamma1", self.schedule.gamma1)?;
        finite_nonneg("schedule.gamma2_max", self.schedule.gamma2_max)?;
        finite_nonneg("posenet_lr", self.posenet_lr)?;
        finite_nonneg("part_pose_lr", self.part_pose_lr)?;
        if self.posenet_lr > 0.0
            && !(self.posenet_lr_final.is_finite() && self.posenet_lr_final > 0.0)
        {
            return Err(format!(
                "posenet_lr_final must be finite and > 0 (got {}): the rate decays log-linearly to it",
                self.posenet_lr_final
            ));
        }
        finite_nonneg("contrast_threshold", self.contrast_threshold)?;
        finite_nonneg("contrast_lr", self.contrast_lr)?;
        let e = &self.contrast_estimate;
        finite_nonneg("contrast_estimate.min_log_change", e.min_log_change)?;
        finite_nonneg("contrast_estimate.black_level", e.black_level)?;
        if !(e.saturation.is_finite() && e.saturation > e.black_level) {
            return Err(format!(
                "contrast_estimate.saturation must be finite and > black_level (got {})",
                e.saturation
            ));
        }
        finite_nonneg("motion_span", self.motion_span)?;
        finite_nonneg("pseudo.band", self.pseudo.band)?;
        self.rate_outliers.validate()?;
        if self.counts.bins == 0 {
            return Err("counts.bins must be at least 1".into());
        }
        if self.log_every == 0 {
            return Err("log_every must be at least 1".into());
        }
        if !(1..=16).contains(&self.event_tiles) {
            return Err(format!(
                "event_tiles must lie in 1..=16 (got {}; 1 = the whole image)",
                self.event_tiles
            ));
        }
        if !(1..=8).contains(&self.event_downsample) {
            return Err(format!(
                "event_downsample must lie in 1..=8 (got {}; 1 = full resolution)",
                self.event_downsample
            ));
        }
        stagekit::Settings::validate(&self.assoc).map_err(|e| format!("assoc: {e}"))
    }
}

impl stagekit::Settings for DeformSettings {
    fn validate(&self) -> Result<(), String> {
        DeformSettings::validate(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Train frames at `fps` over one second.
    fn frames(fps: f64) -> Vec<f64> {
        (0..=fps as usize).map(|k| k as f64 / fps).collect()
    }

    #[test]
    fn the_joint_iterations_grow_with_the_frames_interval() {
        let s = DeformSettings::default();
        assert_eq!(s.iterations, 0, "by the frame rate unless set");
        let small = 128 * 128;
        // 4000 at 50 ms, 6000 at 100 ms, linear between, by hand: 16 fps is 62.5 ms,
        // a quarter of the way (4500); 12.5 fps 80 ms, three fifths (5200)
        for (fps, want) in [(40.0, 4000), (20.0, 4000), (16.0, 4500), (12.5, 5200)] {
            assert_eq!(s.iterations_for(&frames(fps), small), want, "{fps} fps");
        }
        for fps in [10.0, 8.0, 4.0, 1.0] {
            assert_eq!(s.iterations_for(&frames(fps), small), 6000, "{fps} fps");
        }
        // at sensor size (DAVIS346: 346 × 260) from 2000: 16 fps a quarter of the way
        // to 6000 (3000), 12.5 fps three fifths (4400)
        let davis = 346 * 260;
        for (fps, want) in [(20.0, 2000), (16.0, 3000), (12.5, 4400), (10.0, 6000)] {
            assert_eq!(s.iterations_for(&frames(fps), davis), want, "{fps} fps");
        }
        assert_eq!(s.iterations_for(&frames(20.0), 65_535), 4000);
        assert_eq!(s.iterations_for(&frames(20.0), 65_536), 2000);
        // the median interval: one long gap among 20 fps frames changes nothing
        let mut t = frames(20.0);
        t.push(2.0);
        assert_eq!(s.iterations_for(&t, small), 4000);
        // one frame (no interval): the fewest
        assert_eq!(s.iterations_for(&[0.5], small), 4000);
        // a number set is kept
        let set = DeformSettings {
            iterations: 1234,
            ..DeformSettings::default()
        };
        assert_eq!(set.iterations_for(&frames(4.0), davis), 1234);
    }

    #[test]
    fn the_part_pose_rate_is_a_share_of_at_least_zero() {
        let ok = DeformSettings::default();
        assert_eq!(ok.part_pose_lr, 0.0, "held by default");
        assert_eq!(ok.validate(), Ok(()));
        for bad in [-0.1, f64::NAN, f64::INFINITY] {
            let s = DeformSettings {
                part_pose_lr: bad,
                ..DeformSettings::default()
            };
            let e = s.validate().unwrap_err();
            assert!(e.starts_with("part_pose_lr must be finite"), "{e}");
        }
    }
}
