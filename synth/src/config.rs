//! Settings of a synthetic scene: the types, their validation and the frame times.
//! Every field is defaulted in files (a missing key takes the `rigid` preset's value,
//! see the `presets` module); the keys and the flat simulator keys of older files are
//! handled in the `keys` module.

use crate::sim::SimConfig;
use glam::DVec3;
use serde::{Deserialize, Serialize};

/// Everything that defines a synthetic recording: sensor, timing, the event simulator,
/// the camera path and the objects.
///
/// Serialised with the simulator's settings as a nested table (`[events]`); reading also
/// accepts the flat keys of before (`contrast_threshold`, `threshold_sigma`, …), see
/// the `keys` module.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(remote = "Self", default, deny_unknown_fields)]
pub struct SynthConfig {
    /// Name of the preset this config started from (informative).
    pub preset: String,
    pub width: u32,
    pub height: u32,
    /// Horizontal field of view in degrees (square pixels, centred principal point).
    pub fov_x_deg: f64,
    /// Length of the recording in seconds; train frames at `k / train_fps` in `[0, duration]`.
    pub duration: f64,
    /// Rate of the sparse RGB (APS) training frames.
    pub train_fps: f64,
    /// Number of held-out test frames, at `(k + ½)·duration / test_frames`.
    pub test_frames: usize,
    /// The novel-view split (`transforms_novel.json`): one frame at each test time, seen
    /// from the recorded camera's centre rotated by this angle (degrees, about the
    /// vertical axis through `camera.target`), looking at `camera.target`. A view of
    /// the moving scene that no train or test frame saw; 0 writes no novel split.
    pub novel_angle_deg: f64,
    /// Internal render rate for the event simulator, Hz.
    pub render_rate_hz: f64,
    /// Sub-frames averaged into each training frame (1 = sharp).
    pub blur_subframes: usize,
    /// Exposure time of a blurred training frame, seconds (centred on the frame time).
    pub exposure_s: f64,
    /// `n×n` colour samples per pixel of the event simulator's internal renders
    /// (depth, flow and ids use the pixel centre).
    pub supersample: u32,
    /// `n×n` colour samples per pixel of the RGB train and test frames. A frame camera
    /// integrates light over the pixel; with too few samples the hard texture edges
    /// alias differently in every view, which no 3D model can reproduce.
    pub frame_supersample: u32,
    /// Seed of the event simulator (noise, threshold mismatch).
    pub seed: u64,
    /// Linear RGB of rays that hit nothing.
    pub background: [f64; 3],
    /// The event simulator: contrast thresholds, mismatch, refractory period, noise.
    pub events: SimConfig,
    pub camera: CameraPath,
    /// Objects; object id `k + 1` is `objects[k]` (0 is the background).
    pub objects: Vec<ObjectSpec>,
    /// A directional light: each surface's texture colour × `ambient + (1 − ambient)
    /// · max(0, n·l)`, so a turning surface changes its brightness as in real footage.
    /// None: unlit (every surface shows its texture as is).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub light: Option<Light>,
}

/// A directional light ([`SynthConfig::light`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Light {
    /// Direction towards the light, world axes (any length but zero).
    pub direction: DVec3,
    /// The fraction of a surface's colour it keeps facing away from the light.
    pub ambient: f64,
}

impl Default for Light {
    fn default() -> Self {
        Light {
            direction: DVec3::new(-0.4, 1.0, 0.6),
            ambient: 0.35,
        }
    }
}

/// A smooth camera path. Position `eye + sway ⊙ sin(2π·sway_hz·t + φ)` with phases
/// `φ = (0, π/2, π/4)`; orientation `R_y(ψ(t))·R_x(θ(t))·R₀` where `R₀` looks from
/// `eye` at `target`, `ψ = yaw·sin(2π·turn_hz·t)`, `θ = pitch·sin(2π·turn_hz·t + π/3)`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CameraPath {
    pub eye: DVec3,
    pub target: DVec3,
    pub sway: DVec3,
    pub sway_hz: f64,
    pub yaw_deg: f64,
    pub pitch_deg: f64,
    pub turn_hz: f64,
}

impl Default for CameraPath {
    fn default() -> Self {
        CameraPath {
            eye: DVec3::new(0.0, 0.6, 3.2),
            target: DVec3::new(0.0, 0.1, 0.0),
            sway: DVec3::new(0.4, 0.1, 0.2),
            sway_hz: 0.5,
            yaw_deg: 4.0,
            pitch_deg: 2.0,
            turn_hz: 0.7,
        }
    }
}

/// The surface of an object in its material (local, undeformed) coordinates `q`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Shape {
    /// The plane `q.z = 0`, facing `+z`; a rectangle `|q.x| ≤ half_size[0]`,
    /// `|q.y| ≤ half_size[1]`, infinite where a half size is ≤ 0.
    Plane { half_size: [f64; 2] },
    /// An axis-aligned box `|q_i| ≤ half_size_i`.
    Cuboid { half_size: DVec3 },
    /// `Σ (q_i / radii_i)² = 1` (a sphere when the radii are equal).
    Ellipsoid { radii: DVec3 },
}

/// Procedural texture patterns; all have sharp edges between `colour_a` and `colour_b`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Pattern {
    /// 3-D checkerboard of cubes of side `cell`.
    Checker,
    /// Oblique stripes of width `cell` (so both flow components show).
    Stripes,
    /// Thresholded 3-D value noise with feature size `cell`.
    Blobs,
}

/// A solid texture evaluated at the material point, so it moves and deforms with the
/// surface.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Texture {
    pub pattern: Pattern,
    /// Feature size in scene units.
    pub cell: f64,
    pub colour_a: [f64; 3],
    pub colour_b: [f64; 3],
    /// Amplitude of a smooth multiplicative value-noise detail (0 = flat colours).
    pub detail: f64,
    pub seed: u32,
}

impl Default for Texture {
    fn default() -> Self {
        Texture {
            pattern: Pattern::Checker,
            cell: 0.2,
            colour_a: [0.8, 0.8, 0.75],
            colour_b: [0.1, 0.15, 0.3],
            detail: 0.2,
            seed: 1,
        }
    }
}

/// Rigid motion `X = c(t) + R(t)·(S(t)·q)`:
/// `c(t) = position + velocity·t + oscillation ⊙ sin(2π·oscillation_hz·t)`,
/// `R(t) = rot(spin_axis, spin_deg_per_s·t)·R₀`, `R₀` from `rotation_deg` (XYZ Euler).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Motion {
    pub position: DVec3,
    pub rotation_deg: DVec3,
    pub velocity: DVec3,
    pub oscillation: DVec3,
    pub oscillation_hz: f64,
    pub spin_axis: DVec3,
    pub spin_deg_per_s: f64,
}

impl Default for Motion {
    fn default() -> Self {
        Motion {
            position: DVec3::ZERO,
            rotation_deg: DVec3::ZERO,
            velocity: DVec3::ZERO,
            oscillation: DVec3::ZERO,
            oscillation_hz: 0.0,
            spin_axis: DVec3::Y,
            spin_deg_per_s: 0.0,
        }
    }
}

/// Non-rigid deformations (zero = rigid):
/// - non-uniform pulsing scale `S(t) = diag(1 + a_i·sin(2π·hz·t + 2πi/3))` applied in
///   material coordinates, so the surface and its texture stretch differently along
///   each axis (any shape);
/// - a travelling wave along the normal of a plane (a waving flag): the material point
///   `(x, y, 0)` moves to `(x, y, h)` with
///   `h(x, y, t) = wave_amplitude·sin(2π(x/wave_length − wave_hz·t))·cos(π·y/wave_length)`
///   (planes only).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Deform {
    pub scale_amplitude: DVec3,
    pub hz: f64,
    pub wave_amplitude: f64,
    pub wave_length: f64,
    pub wave_hz: f64,
}

/// One object of the scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectSpec {
    pub name: String,
    pub shape: Shape,
    #[serde(default)]
    pub texture: Texture,
    #[serde(default)]
    pub motion: Motion,
    #[serde(default)]
    pub deform: Deform,
}

impl ObjectSpec {
    /// Whether the object moves or deforms at all over time (a translation, an
    /// oscillation, a spin, a pulsing scale or a wave): the pixels it covers are the
    /// "moving object" pixels the novel-view scores single out.
    pub fn moves(&self) -> bool {
        let (m, d) = (&self.motion, &self.deform);
        m.velocity != DVec3::ZERO
            || (m.oscillation != DVec3::ZERO && m.oscillation_hz != 0.0)
            || (m.spin_deg_per_s != 0.0 && m.spin_axis != DVec3::ZERO)
            || (d.scale_amplitude != DVec3::ZERO && d.hz != 0.0)
            || (d.wave_amplitude != 0.0 && d.wave_hz != 0.0)
    }
}

impl stagekit::Settings for SynthConfig {
    /// `Err` with a sentence when a setting is out of range.
    fn validate(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 || self.width > 8192 || self.height > 8192 {
            return Err(format!(
                "image size {}x{} must be within 1..=8192",
                self.width, self.height
            ));
        }
        let positive = [
            ("fov_x_deg", self.fov_x_deg),
            ("duration", self.duration),
            ("train_fps", self.train_fps),
            ("render_rate_hz", self.render_rate_hz),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} = {v} must be finite and > 0"));
            }
        }
        if self.fov_x_deg >= 179.0 {
            return Err(format!("fov_x_deg = {} must be < 179", self.fov_x_deg));
        }
        if !(self.novel_angle_deg.is_finite() && self.novel_angle_deg.abs() <= 90.0) {
            return Err(format!(
                "novel_angle_deg = {} must be within -90..=90 (0: no novel split)",
                self.novel_angle_deg
            ));
        }
        if !(self.exposure_s.is_finite() && self.exposure_s >= 0.0) {
            return Err(format!(
                "exposure_s = {} must be finite and ≥ 0",
                self.exposure_s
            ));
        }
        // The simulator's messages start with the key; name its table too.
        self.events.validate().map_err(|e| format!("events.{e}"))?;
        let sampling_ok = |n: u32| (1..=8).contains(&n);
        if self.blur_subframes == 0
            || !sampling_ok(self.supersample)
            || !sampling_ok(self.frame_supersample)
        {
            return Err(
                "blur_subframes must be ≥ 1, supersample and frame_supersample in 1..=8".into(),
            );
        }
        if self.render_rate_hz * self.duration > 1e6 {
            return Err("render_rate_hz × duration exceeds 10⁶ internal frames".into());
        }
        if self.test_frames > 100_000 || self.duration * self.train_fps > 1e6 {
            return Err("test_frames ≤ 10⁵ and duration × train_fps ≤ 10⁶ required".into());
        }
        if let Some(msg) = self.test_on_train() {
            return Err(msg);
        }
        if self.objects.len() >= u16::MAX as usize {
            return Err("too many objects".into());
        }
        for o in &self.objects {
            let ok = match &o.shape {
                Shape::Plane { half_size } => half_size.iter().all(|h| h.is_finite()),
                Shape::Cuboid { half_size } => {
                    half_size.is_finite() && half_size.min_element() > 0.0
                }
                Shape::Ellipsoid { radii } => radii.is_finite() && radii.min_element() > 0.0,
            };
            if !ok {
                return Err(format!(
                    "object '{}': shape sizes must be finite and > 0",
                    o.name
                ));
            }
            if !(o.texture.cell.is_finite() && o.texture.cell > 0.0) {
                return Err(format!("object '{}': texture cell must be > 0", o.name));
            }
            let d = &o.deform;
            let wave_ok = d.wave_amplitude.is_finite()
                && d.wave_hz.is_finite()
                && (d.wave_amplitude == 0.0 || (d.wave_length.is_finite() && d.wave_length > 0.0));
            if !wave_ok {
                return Err(format!(
                    "object '{}': wave needs finite amplitude and hz and wave_length > 0",
                    o.name
                ));
            }
            if d.wave_amplitude != 0.0 && !matches!(o.shape, Shape::Plane { .. }) {
                return Err(format!("object '{}': a wave deforms planes only", o.name));
            }
            if o.deform.scale_amplitude.abs().max_element() >= 0.9 {
                return Err(format!(
                    "object '{}': deform scale_amplitude must be < 0.9 (scale stays positive)",
                    o.name
                ));
            }
            let m = &o.motion;
            let finite = m.position.is_finite()
                && m.rotation_deg.is_finite()
                && m.velocity.is_finite()
                && m.oscillation.is_finite()
                && m.oscillation_hz.is_finite()
                && m.spin_axis.is_finite()
                && m.spin_deg_per_s.is_finite()
                && o.deform.hz.is_finite();
            if !finite {
                return Err(format!("object '{}': motion has non-finite values", o.name));
            }
        }
        Ok(())
    }
}

impl SynthConfig {
    /// Times of the training frames: `k / train_fps` for `k = 0 …` up to `duration`.
    pub fn train_times(&self) -> Vec<f64> {
        let n = (self.duration * self.train_fps + 1e-9).floor() as usize;
        (0..=n).map(|k| k as f64 / self.train_fps).collect()
    }

    /// Why the test split would hold train frames (a test time on a train time: the same
    /// camera and image, scored as if held out), with a `test_frames` that avoids it.
    fn test_on_train(&self) -> Option<String> {
        // Closed form (no lists: the settings may be hostile): test time t_k is train
        // time m / fps when t_k · fps is within 1 ns · fps of a whole m ≤ the last one.
        let last = (self.duration * self.train_fps + 1e-9).floor();
        let on_train = |n: usize| {
            (0..n)
                .filter(|&k| {
                    let t = (k as f64 + 0.5) * self.duration / n as f64;
                    let m = (t * self.train_fps).round();
                    m <= last && (m / self.train_fps - t).abs() < 1e-9
                })
                .count()
        };
        let k = on_train(self.test_frames);
        if k == 0 {
            return None;
        }
        let n = self.test_frames;
        let better = (1..=32)
            .flat_map(|d| [n + d, n.saturating_sub(d)])
            .find(|&m| m > 0 && on_train(m) == 0);
        Some(format!(
            "test_frames = {n}: {k} of the {n} test times (k + ½)·duration/test_frames fall \
             on train times (k / train_fps), so those test frames are train frames{}",
            better.map_or(String::new(), |m| format!(" (test_frames = {m} avoids it)"))
        ))
    }

    /// Times of the test frames: `(k + ½)·duration / test_frames`.
    pub fn test_times(&self) -> Vec<f64> {
        let n = self.test_frames;
        (0..n)
            .map(|k| (k as f64 + 0.5) * self.duration / n as f64)
            .collect()
    }

    /// Times of the novel-view frames: the test times, none when `novel_angle_deg` is 0.
    pub fn novel_times(&self) -> Vec<f64> {
        if self.novel_angle_deg == 0.0 {
            Vec::new()
        } else {
            self.test_times()
        }
    }

    /// Times of the internal renders fed to the event simulator: `k / render_rate_hz`
    /// up to `duration` (the last one exactly at `duration`).
    pub fn render_times(&self) -> Vec<f64> {
        let n = (self.duration * self.render_rate_hz - 1e-9).ceil().max(1.0) as usize;
        (0..=n)
            .map(|k| (k as f64 / self.render_rate_hz).min(self.duration))
            .collect()
    }
}
