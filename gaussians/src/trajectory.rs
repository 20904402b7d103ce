//! How well a model's Gaussians follow the true 3D motion of the moving objects of a
//! synthetic scene (`degs synth`: `synth.json` beside the manifests), issue #30. A model
//! right only along the recorded path can draw a moving object without moving its
//! Gaussians with it; this measures the motion itself.
//!
//! At the first train frame's time `t₀` every Gaussian (opacity ≥ 0.5) is projected into
//! that frame's camera. One whose pixel shows a moving object is *on* it when its depth
//! lies within 10 % of the surface's; it is then tied to that surface point's material
//! coordinates. At every test time `t` its model displacement `μ'(t) − μ'(t₀)` is
//! compared with the true displacement of its material point (the analytic world). The
//! figures: the mean error of the displacement, the mean true and model displacements
//! (all world units) and the error relative to the true motion (1 = no better than not
//! moving at all), and the fraction of the Gaussians seen on moving objects' pixels that
//! lie on the surface (the rest float in front or behind: a smear seen from elsewhere).
//! A Gaussian with a life (`Splats::life`) counts only at the test times it exists in.

use crate::model::Model;
use glam::DVec3;
use scene::manifest::Scene;
use serde::{Deserialize, Serialize};

/// The trajectory figures of a model (`report.json`: `trajectory`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrajectoryError {
    /// Gaussians on moving objects' surfaces at `t₀`, and test times compared.
    pub gaussians: usize,
    pub times: usize,
    /// Of the Gaussians projecting onto moving objects' pixels at `t₀`, the fraction
    /// within 10 % of the surface's depth.
    pub on_surface_fraction: f64,
    /// Mean `‖Δμ_model − Δμ_true‖`, `‖Δμ_true‖` and `‖Δμ_model‖` (world units).
    pub motion_error_mean: f64,
    pub true_motion_mean: f64,
    pub model_motion_mean: f64,
    /// Mean `‖Δμ_model‖` of every Gaussian on moving objects' pixels at `t₀`, on the
    /// surface or not (those off it may be what draws the objects along the path).
    pub seen_motion_mean: f64,
    /// `motion_error_mean / true_motion_mean`.
    pub relative_error: f64,
}

/// Depth tolerance (relative) for a Gaussian to count as on a surface.
const ON_SURFACE: f64 = 0.1;

/// The figures for `model` on `scene`; None when the scene is not synthetic (no
/// `synth.json`), has no train or test frames, or no Gaussian lies on a moving object.
pub fn trajectory_error(model: &Model, scene: &Scene) -> Option<TrajectoryError> {
    let text = std::fs::read_to_string(scene.root.join("synth.json")).ok()?;
    let cfg: synth::SynthConfig = serde_json::from_str(&text).ok()?;
    let world = synth::SynthWorld::new(&cfg).ok()?;
    let f0 = scene.train.frames.first()?;
    if scene.test.frames.is_empty() {
        return None;
    }
    let (t0, tau0) = (f0.timestamp, f0.time as f32);
    let cam = world.camera_at(t0);
    let (w, h) = (cam.intrinsics.width as f64, cam.intrinsics.height as f64);
    let at0 = model.at(tau0);
    let sigmoid = |x: f32| 1.0 / (1.0 + (-x).exp());
    // (Gaussian, object, material point, its world position at t₀)
    let mut tied = Vec::new();
    let mut seen = Vec::new();
    for (i, m) in at0.means.iter().enumerate() {
        if sigmoid(at0.opacity_logits[i]) < 0.5 {
            continue;
        }
        let p = DVec3::new(m[0] as f64, m[1] as f64, m[2] as f64);
        let Some((px, depth)) = cam.project_world(p) else {
            continue;
        };
        if !(px.x >= 0.0 && px.y >= 0.0 && px.x < w && px.y < h) {
            continue;
        }
        let Some(hit) = world.cast(t0, px) else {
            continue;
        };
        if !cfg.objects[hit.object].moves() {
            continue;
        }
        seen.push(i);
        if (depth - hit.depth).abs() <= ON_SURFACE * hit.depth {
            tied.push((i, hit.object, hit.local, hit.world));
        }
    }
    if tied.is_empty() {
        return None;
    }
    let (mut err, mut truth, mut moved, mut n) = (0.0, 0.0, 0.0, 0usize);
    let (mut seen_moved, mut seen_n) = (0.0, 0usize);
    let shift = |a: &[f32; 3], b: &[f32; 3]| {
        DVec3::from_array(std::array::from_fn(|k| (a[k] - b[k]) as f64))
    };
    // A Gaussian with a life (`tracks.window`) is compared only at the times it exists.
    let life = &model.splats.life;
    let alive = |i: usize, t: f32| life.get(i).is_none_or(|l| crate::motion::alive(*l, t));
    for f in &scene.test.frames {
        let t = f.time as f32;
        let at = model.at(t);
        for &i in seen.iter().filter(|&&i| alive(i, t)) {
            seen_moved += shift(&at.means[i], &at0.means[i]).length();
            seen_n += 1;
        }
        for &(i, object, local, start) in tied.iter().filter(|g| alive(g.0, t)) {
            let want = world.material_to_world(object, local, f.timestamp) - start;
            let got = shift(&at.means[i], &at0.means[i]);
            err += (got - want).length();
            truth += want.length();
            moved += got.length();
            n += 1;
        }
    }
    if n == 0 {
        return None;
    }
    let n = n as f64;
    Some(TrajectoryError {
        gaussians: tied.len(),
        times: scene.test.frames.len(),
        on_surface_fraction: tied.len() as f64 / seen.len() as f64,
        seen_motion_mean: seen_moved / seen_n.max(1) as f64,
        motion_error_mean: err / n,
        true_motion_mean: truth / n,
        model_motion_mean: moved / n,
        relative_error: if truth > 0.0 { err / truth } else { 0.0 },
    })
}
