//! Training settings (`settings.toml`): schedules and learning rates after Deform-GS
//! (`docs/REFERENCES.md`), scaled to the 3500-iteration warm-up of DEGS.

pub use super::rigidity::RigiditySettings;
pub use super::sizing::SizeSettings;
pub use super::stereo::StereoSettings;
use crate::densify::DensifySettings;
use crate::field::FieldSettings;
use serde::{Deserialize, Serialize};

/// Initial Gaussians without a point cloud.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Init {
    /// `tracks`: on a scene without moving objects it is the stereo init. (Until the
    /// twelfth session `stereo` where the scene has no depth priors: the tracks cost the
    /// still background seen from elsewhere, a bug since fixed, `motion::has_trajectory`;
    /// BENCHMARKS.md, "Still Gaussians stay still".)
    #[default]
    Auto,
    /// Plane-sweep stereo over the train frames, plus a few random frustum points.
    Stereo,
    /// Random points in the train cameras' viewing frusta.
    Frustum,
    /// Random points in the box the cameras look at (Deform-GS synthetic init).
    Box,
    /// Lucas–Kanade tracks through the train frames, lifted to still points and to
    /// quadratic trajectories (`crate::tracks`): the moving objects start moving; with
    /// the scene's depth priors, at their distance.
    Tracks,
}

impl Init {
    /// What `auto` means; the others as they are.
    pub fn resolve(self) -> Init {
        match self {
            Init::Auto => Init::Tracks,
            i => i,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainSettings {
    /// Total iterations (DEGS warm-up: 3500).
    pub iterations: u32,
    /// Iterations before the deformation field is switched on (Deform-GS: 3000 of 40k;
    /// here 1000 of 3500 so the field gets most of the warm-up once the canonical
    /// geometry has settled and the first densification rounds are done).
    pub static_iterations: u32,
    /// Coarse-to-fine: iterations before this one train on the views at half resolution
    /// (`View::half`; a quarter of the pixels), the rest at full (0 = never). It ends
    /// earlier where the run is short: at the latest four fifths of the way to the
    /// sizing, so the sizing judges a model that trained on the full views
    /// ([`Self::coarse_end`]).
    pub coarse_until: u32,
    /// Coarse-to-fine only for train frames of at least this many pixels (measured at
    /// 346 × 260; at 128² not measured, so not used there).
    pub coarse_min_pixels: usize,
    /// Use a deformation field at all (off: a static 3DGS model).
    pub deform: bool,
    /// Deform only Gaussians flagged `dynamic` (missing flags count as dynamic).
    pub dynamic_only: bool,
    /// Static/dynamic split: Gaussians the field moves by at most this many pixels in
    /// the train views over the whole recording are flagged static (they keep their
    /// canonical parameters) and `dynamic_only` is switched on (0 = no split). 1 px by
    /// default: sub-pixel motion is the field fitting each train view on its own, which
    /// unpins the camera at the times between them (DESIGN.md, "Static/dynamic split").
    pub static_tolerance_px: f32,
    /// When the split is made: this fraction of the way through the field phase.
    pub static_split_at: f32,
    pub field: FieldSettings,
    /// The isometry term on the field's motion (local rigidity; `rigidity.rs`).
    pub rigidity: RigiditySettings,
    /// Field learning rate, log-linear init → final over `iterations`. Deform-GS's
    /// 8e-4 → 1.6e-6 is spread over 40k iterations; squeezed into a 3500-iteration
    /// warm-up it left the field untrained (no better than a static model on the
    /// nonrigid preset; docs/benchmarks/2026-11-23-warm-up.md, "Stop 12").
    pub field_lr_init: f64,
    pub field_lr_final: f64,
    /// Position learning rate × scene extent, log-linear over `iterations`.
    pub position_lr_init: f64,
    pub position_lr_final: f64,
    pub feature_lr: f64,
    pub opacity_lr: f64,
    pub scaling_lr: f64,
    pub rotation_lr: f64,
    /// Weight λ of D-SSIM in `(1−λ)·L1 + λ·(1−SSIM)`.
    pub dssim_weight: f64,
    /// Highest SH degree; the degree grows by one every `sh_interval` iterations.
    pub sh_degree: u32,
    pub sh_interval: u32,
    pub densify: DensifySettings,
    /// Right-sizing once during the warm-up: field, SH degree and Gaussian count chosen
    /// by the train views within a PSNR tolerance (`tolerance_db = 0`: the fixed sizes
    /// of `field`, `sh_degree` and the cap below).
    pub size: SizeSettings,
    /// Cap on the Gaussians per pixel of a train frame, used when
    /// `densify.max_gaussians` is 0 (auto): a model needs no more Gaussians than its
    /// views have pixels to constrain them (measured: docs/benchmarks/2026-11-23-warm-up.md).
    pub max_gaussians_per_pixel: f64,
    /// Random initial Gaussians (when no point cloud is given).
    pub init_points: usize,
    /// Where the initial Gaussians come from when no point cloud is given.
    pub init: Init,
    /// Plane-sweep stereo settings (`init = "stereo"`).
    pub stereo: StereoSettings,
    /// Tracks settings (`init = "tracks"`).
    pub tracks: crate::tracks::TrackSettings,
    /// Depth range of the frustum points and of the stereo sweep, × each camera's
    /// distance to the point the cameras look at.
    pub init_near: f64,
    pub init_far: f64,
    /// Scene extent for learning rates and densification (0 = auto: the larger of the
    /// 3DGS camera extent and the half-size of the box the cameras look at).
    pub scene_extent: f32,
    pub background: [f32; 3],
    pub seed: u64,
}

impl Default for TrainSettings {
    fn default() -> Self {
        TrainSettings {
            iterations: 3500,
            static_iterations: 1000,
            coarse_until: 2000,
            coarse_min_pixels: 65_536,
            deform: true,
            dynamic_only: false,
            static_tolerance_px: 1.0,
            static_split_at: 0.75,
            field: FieldSettings::default(),
            rigidity: RigiditySettings::default(),
            field_lr_init: 3e-3,
            field_lr_final: 3e-4,
            position_lr_init: 1.6e-4 * 5.0,
            position_lr_final: 1.6e-6 * 5.0,
            feature_lr: 0.005,
            opacity_lr: 0.05,
            scaling_lr: 0.01,
            rotation_lr: 0.001,
            dssim_weight: 0.2,
            sh_degree: 3,
            sh_interval: 1000,
            densify: DensifySettings::default(),
            size: SizeSettings::default(),
            max_gaussians_per_pixel: 2.0,
            init_points: 20_000,
            init: Init::Auto,
            stereo: StereoSettings::default(),
            tracks: Default::default(),
            init_near: 0.3,
            init_far: 2.5,
            scene_extent: 0.0,
            background: [0.0; 3],
            seed: 0,
        }
    }
}

impl TrainSettings {
    /// The iteration coarse-to-fine ends at for train frames of `pixels` pixels (0: no
    /// coarse steps): `coarse_until`, for frames of at least `coarse_min_pixels`, but no
    /// later than four fifths of the way to the sizing (the sizing must judge a model
    /// trained on the full views: at the defaults 2000 of 2500; a sizing right at the
    /// switch, measured at 346 × 260, kept a third fewer Gaussians and ended 1 dB under).
    pub fn coarse_end(&self, pixels: usize) -> u32 {
        if pixels < self.coarse_min_pixels {
            return 0;
        }
        let sizing = super::sizing::iteration(&self.size, self.densify.until_iter, self.iterations);
        match sizing {
            Some(at) => self.coarse_until.min((u64::from(at) * 4 / 5) as u32),
            None => self.coarse_until,
        }
    }

    /// The Gaussian cap for train frames of `pixels` pixels: `densify.max_gaussians`,
    /// or when that is 0, `max_gaussians_per_pixel × pixels` (at least `init_points`).
    pub fn gaussian_cap(&self, pixels: usize) -> usize {
        match self.densify.max_gaussians {
            0 => ((self.max_gaussians_per_pixel * pixels as f64) as usize).max(self.init_points),
            n => n,
        }
    }
}

impl stagekit::Settings for TrainSettings {
    /// Reject settings that cannot train.
    fn validate(&self) -> Result<(), String> {
        if self.iterations == 0 {
            return Err("iterations must be positive".into());
        }
        if !(0.0..=1.0).contains(&self.dssim_weight) {
            return Err("dssim_weight must lie in [0, 1]".into());
        }
        if !(self.static_tolerance_px.is_finite() && self.static_tolerance_px >= 0.0) {
            return Err("static_tolerance_px must be finite and ≥ 0 (0: no split)".into());
        }
        if !(0.0..=1.0).contains(&self.static_split_at) {
            return Err("static_split_at must lie in [0, 1]".into());
        }
        if self.sh_degree > 3 {
            return Err(format!("sh_degree = {} must be ≤ 3", self.sh_degree));
        }
        let rates = [
            ("field_lr_init", self.field_lr_init),
            ("field_lr_final", self.field_lr_final),
            ("position_lr_init", self.position_lr_init),
            ("position_lr_final", self.position_lr_final),
            ("feature_lr", self.feature_lr),
            ("opacity_lr", self.opacity_lr),
            ("scaling_lr", self.scaling_lr),
            ("rotation_lr", self.rotation_lr),
        ];
        for (name, v) in rates {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} = {v} must be finite and ≥ 0"));
            }
        }
        self.densify.validate()?;
        self.rigidity.validate()?;
        if self.init_points == 0 {
            return Err("init_points must be positive".into());
        }
        if !(self.init_near > 0.0 && self.init_far > self.init_near) {
            return Err("0 < init_near < init_far required".into());
        }
        self.stereo.validate()?;
        self.tracks.validate()?;
        self.size.validate()?;
        if !(self.max_gaussians_per_pixel > 0.0 && self.max_gaussians_per_pixel.is_finite()) {
            return Err("max_gaussians_per_pixel must be positive".into());
        }
        if self.scene_extent.is_nan() || self.scene_extent < 0.0 {
            return Err("scene_extent must be ≥ 0".into());
        }
        if self.field.width == 0 || self.field.depth > 16 || self.field.width > 1024 {
            return Err("field depth ≤ 16 and 0 < width ≤ 1024 required".into());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use stagekit::Settings;
    use stagekit::settings::to_toml;

    /// Parse a `settings.toml`; unknown keys are errors.
    fn from_toml(text: &str) -> scene::Result<TrainSettings> {
        stagekit::settings::parse(text, std::path::Path::new("settings.toml"))
    }

    #[test]
    fn toml_round_trip_and_partial_files() {
        let s = TrainSettings::default();
        let back = from_toml(&to_toml(&s).unwrap()).unwrap();
        assert_eq!(back, s);
        let p = from_toml("iterations = 100\n[field]\nwidth = 32\n").unwrap();
        assert_eq!((p.iterations, p.field.width, p.field.depth), (100, 32, 4));
        // A partial table keeps the warm-up's values for the keys it does not name.
        let d = from_toml("[densify]\nuntil_iter = 5000\n").unwrap();
        assert_eq!(d.densify.until_iter, 5000);
        assert_eq!(
            (d.densify.opacity_reset_interval, d.densify.max_gaussians),
            (0, 0)
        );
        assert_eq!(d.densify.interval, s.densify.interval);
        assert!(from_toml("iteratons = 1").is_err());
        assert!(from_toml("iterations = -1").is_err());
        let bad = TrainSettings {
            dssim_weight: 2.0,
            ..Default::default()
        };
        assert!(bad.validate().is_err());
        assert!(s.validate().is_ok());
    }

    #[test]
    fn the_gaussian_cap_follows_the_image_unless_set() {
        let mut s = TrainSettings::default();
        assert_eq!(s.densify.max_gaussians, 0);
        assert_eq!(s.gaussian_cap(128 * 128), 32_768);
        // never below the initial count
        assert_eq!(s.gaussian_cap(64 * 64), 20_000);
        s.max_gaussians_per_pixel = 0.5;
        s.init_points = 1000;
        assert_eq!(s.gaussian_cap(100 * 100), 5_000);
        s.densify.max_gaussians = 777;
        assert_eq!(s.gaussian_cap(100 * 100), 777);
        s.max_gaussians_per_pixel = f64::NAN;
        assert!(s.validate().is_err());
        let bad = TrainSettings {
            stereo: StereoSettings {
                planes: 1,
                ..Default::default()
            },
            ..Default::default()
        };
        assert!(bad.validate().unwrap_err().contains("planes"));
    }

    /// Coarse-to-fine ends four fifths of the way to the sizing at the latest, and only
    /// on frames of at least `coarse_min_pixels`.
    #[test]
    fn coarse_end_by_frame_size_and_sizing() {
        let s = TrainSettings::default();
        assert_eq!(s.coarse_end(346 * 260), 2000);
        assert_eq!(s.coarse_end(128 * 128), 0);
        // Sizing at 2500 (the end of densification): 4/5 of it is 2000.
        let late = TrainSettings {
            coarse_until: 3000,
            ..Default::default()
        };
        assert_eq!(late.coarse_end(640 * 480), 2000);
        // A short run sizes at its last iteration: 400 → 320.
        let short = TrainSettings {
            iterations: 400,
            ..Default::default()
        };
        assert_eq!(short.coarse_end(640 * 480), 320);
        // No sizing: the setting as it stands.
        let mut fixed = TrainSettings::default();
        fixed.size.tolerance_db = 0.0;
        assert_eq!(fixed.coarse_end(640 * 480), 2000);
    }
}
