//! Static/dynamic split: Gaussians that the deformation field barely moves over the
//! recording are flagged static, baked at the middle of the recording, and keep those
//! parameters from then on.
//!
//! A static Gaussian cannot be moved by the field, so the background cannot deform to
//! make up for an error of the camera (the joint training's PoseNet is pinned by it),
//! and the field runs on the dynamic Gaussians only (cheaper iterations).
//!
//! At the split's iteration [`decide`] makes it (the flags and the summary) and the
//! trainer takes the flags on.

use super::View;
use crate::field::{self, Mlp};
use crate::splats::Splats;
use scene::Camera;

/// Times at which the field is sampled between the first and last train time.
pub(crate) const SAMPLES: usize = 33;

/// How far the field moves each Gaussian, in pixels of the train views: over `times`,
/// the largest of `|δμ| + s_max·(θ + |Δs|/s)` (centre displacement plus the motion of
/// the Gaussian's outline from rotation by θ and relative scale change), divided by the
/// Gaussian's smallest depth over `cams` and multiplied by the focal length. A Gaussian
/// behind every camera scores 0 (no view sees it move). Measured from the canonical
/// Gaussian (`reference` None) or from where the field puts it at time `reference`
/// (a shift the field applies at every time alike is then no motion).
pub(crate) fn field_motion_px(
    mlp: &Mlp<f32>,
    splats: &Splats,
    cams: &[Camera],
    times: &[f32],
    reference: Option<f32>,
) -> Vec<f32> {
    let n = splats.len();
    let mut world = vec![0.0f32; n];
    let deformed = |t: f32| {
        let (d, _) = field::Deformation::forward(mlp, &splats.means, &[t]);
        field::apply_deltas(&splats.means, &splats.log_scales, &splats.rotations, &d)
    };
    let from = match reference {
        Some(t) => deformed(t),
        None => field::Deformed {
            means: splats.means.clone(),
            log_scales: splats.log_scales.clone(),
            rotations: splats.rotations.clone(),
        },
    };
    for &t in times {
        accumulate_motion(&from, &deformed(t), &mut world);
    }
    to_pixels(splats, cams, &world)
}

/// How far the field moves each Gaussian's centre away from where it puts it at time
/// `reference`, in pixels of the train views: over `times`, the largest
/// `|δμ(t) − δμ(reference)|`, divided by the Gaussian's smallest depth over `cams` and
/// multiplied by the focal length (0 behind every camera). Unlike [`field_motion_px`]
/// it ignores what the field does at every time alike (a constant shift), which is no
/// motion.
pub(crate) fn centre_motion_px(
    mlp: &Mlp<f32>,
    splats: &Splats,
    dynamic_only: bool,
    cams: &[Camera],
    times: &[f32],
    reference: f32,
) -> Vec<f32> {
    let n = splats.len();
    let (at_ref, _) = field::splat_deltas(mlp, splats, reference, dynamic_only);
    let mut world = vec![0.0f32; n];
    for &t in times {
        let (d, _) = field::splat_deltas(mlp, splats, t, dynamic_only);
        for (i, w) in world.iter_mut().enumerate() {
            let (a, b) = (d.dx[i], at_ref.dx[i]);
            let m = (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f32>().sqrt();
            *w = w.max(m);
        }
    }
    to_pixels(splats, cams, &world)
}

/// A colour change the split counts as none (two 8-bit steps).
pub(crate) const COLOR_STILL: f32 = 2.0 / 255.0;

/// With a colour field, `motion[i]` set to infinity for each Gaussian whose colour
/// changes over `times` by more than [`COLOR_STILL`] in some channel away from its colour at
/// `reference` (it cannot be baked at one time however little it moves); unchanged
/// without one.
pub(crate) fn keep_colour_changes_dynamic(
    mlp: &Mlp<f32>,
    splats: &Splats,
    dynamic_only: bool,
    times: &[f32],
    reference: f32,
    motion: &mut [f32],
) {
    if !mlp.settings.color {
        return;
    }
    let (at_ref, _) = field::splat_deltas(mlp, splats, reference, dynamic_only);
    for &t in times {
        let (d, _) = field::splat_deltas(mlp, splats, t, dynamic_only);
        for (i, m) in motion.iter_mut().enumerate() {
            let (a, b) = (d.dc[i], at_ref.dc[i]);
            let change = (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0f32, f32::max);
            if crate::raster::sh::C0 as f32 * change > COLOR_STILL {
                *m = f32::INFINITY;
            }
        }
    }
}

/// World distances `world[i]` at Gaussian i's centre, in pixels at its smallest depth
/// over `cams` (0 for a Gaussian behind every camera).
fn to_pixels(splats: &Splats, cams: &[Camera], world: &[f32]) -> Vec<f32> {
    let focal = cams
        .iter()
        .map(|c| c.intrinsics.fx.max(c.intrinsics.fy))
        .fold(0.0f64, f64::max);
    (0..splats.len())
        .map(|i| {
            let p = glam::DVec3::from(splats.means[i].map(f64::from));
            let z = cams
                .iter()
                .map(|c| -c.cam_to_world.to_camera(p).z)
                .filter(|&z| z > 1e-6)
                .fold(f64::INFINITY, f64::min);
            if z.is_finite() {
                (world[i] as f64 * focal / z) as f32
            } else {
                0.0
            }
        })
        .collect()
}

/// `out[i] = max(out[i], motion of Gaussian i from `from` to `to`)` in world units.
fn accumulate_motion(from: &field::Deformed, to: &field::Deformed, out: &mut [f32]) {
    for (i, out_i) in out.iter_mut().enumerate() {
        let (a, b) = (from.means[i], to.means[i]);
        let shift = (0..3).map(|k| (b[k] - a[k]).powi(2)).sum::<f32>().sqrt();
        let s0 = from.log_scales[i].map(f32::exp);
        let s1 = to.log_scales[i].map(f32::exp);
        let s_max = s0.iter().fold(0.0f32, |a, &b| a.max(b));
        let rel_scale = (0..3)
            .map(|k| (s1[k] - s0[k]).abs() / s0[k].max(1e-12))
            .fold(0.0f32, f32::max);
        let angle = quat_angle(from.rotations[i], to.rotations[i]);
        let m = shift + s_max * (angle + rel_scale);
        if m > *out_i {
            *out_i = m;
        }
    }
}

/// Angle (radians) of the rotation between two raw quaternions (normalised here).
fn quat_angle(a: [f32; 4], b: [f32; 4]) -> f32 {
    let na = a.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-12);
    let nb = b.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-12);
    let dot = (0..4).map(|k| a[k] * b[k]).sum::<f32>() / (na * nb);
    2.0 * dot.abs().min(1.0).acos()
}

/// Uniform sample times over `[min, max]` of the views' times (one if they are equal).
pub(crate) fn sample_times(view_times: &[f32]) -> Vec<f32> {
    let lo = view_times.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = view_times.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    if !(lo.is_finite() && hi.is_finite()) {
        return Vec::new();
    }
    if hi <= lo {
        return vec![lo];
    }
    (0..SAMPLES)
        .map(|k| lo + (hi - lo) * k as f32 / (SAMPLES - 1) as f32)
        .collect()
}

/// Dynamic flags: a Gaussian is dynamic when the field moves it by more than
/// `tolerance_px` pixels.
pub fn dynamic_flags(motion_px: &[f32], tolerance_px: f32) -> Vec<bool> {
    motion_px.iter().map(|&m| m > tolerance_px).collect()
}

/// What the split found (for the report).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct SplitSummary {
    /// Iteration at which the split was made.
    pub iteration: u32,
    pub tolerance_px: f32,
    pub dynamic: usize,
    pub static_: usize,
    /// Quantiles 0.5, 0.9 and 0.99 of the Gaussians' motion in pixels.
    pub motion_px_quantiles: [f32; 3],
}

/// The split of `splats` by how far `field` moves each of them over the times of `views`
/// in their pixels, away from where it puts them at the views' middle time
/// ([`field_motion_px`]: centre and outline; a shift the field applies at every time
/// alike is no motion, and a Gaussian whose colour changes stays dynamic): the model with the Gaussians moved
/// by at most `tolerance_px` flagged static and baked at that middle time (the field's
/// deformation there applied to them once, as the sizing's split does), and the summary
/// of a split at `iteration`.
pub fn decide(
    field: &Mlp<f32>,
    splats: &Splats,
    views: &[View],
    tolerance_px: f32,
    iteration: u32,
) -> (Splats, SplitSummary) {
    let cams: Vec<Camera> = views.iter().map(|v| v.camera).collect();
    let times: Vec<f32> = views.iter().map(|v| v.time).collect();
    let times = sample_times(&times);
    let mid = super::judge::middle_time(views);
    let mut motion = field_motion_px(field, splats, &cams, &times, Some(mid));
    let motion_px_quantiles = quantiles(&motion, [0.5, 0.9, 0.99]);
    keep_colour_changes_dynamic(field, splats, false, &times, mid, &mut motion);
    let (d, _) = field::splat_deltas(field, splats, mid, false);
    let frozen = field::deform_splats(splats, &d);
    let model = split(splats, &frozen, &motion, tolerance_px);
    let dynamic = model.dynamic.iter().filter(|&&d| d).count();
    let summary = SplitSummary {
        iteration,
        tolerance_px,
        dynamic,
        static_: splats.len() - dynamic,
        motion_px_quantiles,
    };
    (model, summary)
}

/// `canonical` with the Gaussians that move by at most `tolerance_px` (`motion`) taken
/// from `frozen` and flagged static, the others flagged dynamic.
pub fn split(canonical: &Splats, frozen: &Splats, motion: &[f32], tolerance_px: f32) -> Splats {
    let mut out = canonical.clone();
    out.dynamic = motion.iter().map(|&m| m > tolerance_px).collect();
    for (i, &dynamic) in out.dynamic.iter().enumerate() {
        if !dynamic {
            out.means[i] = frozen.means[i];
            out.log_scales[i] = frozen.log_scales[i];
            out.rotations[i] = frozen.rotations[i];
            out.sh_dc[i] = frozen.sh_dc[i];
        }
    }
    out
}

/// Quantiles `qs` (in [0, 1]) of `v` (nearest rank; 0 for an empty `v`).
pub fn quantiles<const N: usize>(v: &[f32], qs: [f32; N]) -> [f32; N] {
    let mut s = v.to_vec();
    s.sort_by(f32::total_cmp);
    qs.map(|q| {
        if s.is_empty() {
            0.0
        } else {
            s[((q * (s.len() - 1) as f32).round() as usize).min(s.len() - 1)]
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::FieldSettings;
    use scene::camera::{Intrinsics, Pose};

    fn camera() -> Camera {
        Camera {
            intrinsics: Intrinsics::from_fov_x(64, 64, 60f64.to_radians()),
            cam_to_world: Pose::look_at(
                glam::DVec3::new(0.0, 0.0, 3.0),
                glam::DVec3::ZERO,
                glam::DVec3::Y,
            ),
        }
    }

    #[test]
    fn zero_field_moves_nothing_and_a_shift_scales_with_depth() {
        let s = FieldSettings {
            width: 8,
            depth: 2,
            ..FieldSettings::default()
        };
        let mut mlp = Mlp::<f32>::new(s, 1);
        mlp.zero_head();
        let mut splats = Splats::with_capacity(2);
        for z in [0.0f32, -3.0] {
            splats.push(crate::splats::Gaussian::isotropic(
                [0.0, 0.0, z],
                -3.0,
                0.0,
                [0.5; 3],
            ));
        }
        let cams = [camera()];
        let times = sample_times(&[0.0, 0.5, 1.0]);
        assert_eq!(times.len(), SAMPLES);
        let m = field_motion_px(&mlp, &splats, &cams, &times, None);
        assert_eq!(m, vec![0.0, 0.0]);

        // Head bias δμ = (0.01, 0, 0) with a zero head weight: a constant shift, seen
        // as 0.01·f/z pixels from the camera at distance z (3 and 6 here).
        let head = *mlp.layers.last().unwrap();
        mlp.params[head.bias] = 0.01;
        let m = field_motion_px(&mlp, &splats, &cams, &times, None);
        let f = cams[0].intrinsics.fx as f32;
        // A shift at every time alike is no motion from the middle of the recording.
        assert_eq!(
            centre_motion_px(&mlp, &splats, false, &cams, &times, 0.5),
            vec![0.0, 0.0]
        );
        assert_eq!(
            field_motion_px(&mlp, &splats, &cams, &times, Some(0.5)),
            vec![0.0, 0.0]
        );
        assert!((m[0] - 0.01 * f / 3.0).abs() < 1e-4, "{m:?}");
        assert!((m[1] - 0.01 * f / 6.0).abs() < 1e-4, "{m:?}");
        // A Gaussian behind the camera is not seen to move.
        splats.push(crate::splats::Gaussian::isotropic(
            [0.0, 0.0, 4.0],
            -3.0,
            0.0,
            [0.5; 3],
        ));
        assert_eq!(field_motion_px(&mlp, &splats, &cams, &times, None)[2], 0.0);
        assert_eq!(
            quantiles(&[3.0, 1.0, 2.0, 4.0, 5.0], [0.0, 0.5, 1.0]),
            [1.0, 3.0, 5.0]
        );
        assert_eq!(
            dynamic_flags(&[0.2, 0.6, 0.5], 0.5),
            vec![false, true, false]
        );
    }

    use crate::field::Deltas;

    /// The motion of the Gaussians of `splats` under deltas `d`, from canonical.
    fn motion_under(splats: &Splats, d: &Deltas) -> f32 {
        let canon = field::apply_deltas(
            &splats.means,
            &splats.log_scales,
            &splats.rotations,
            &Deltas::zeros(splats.len()),
        );
        let moved = field::apply_deltas(&splats.means, &splats.log_scales, &splats.rotations, d);
        let mut w = vec![0.0];
        accumulate_motion(&canon, &moved, &mut w);
        w[0]
    }

    #[test]
    fn rotation_and_scale_count_by_the_gaussians_size() {
        let mut splats = Splats::with_capacity(1);
        splats.push(crate::splats::Gaussian::isotropic(
            [0.0; 3],
            0.1f32.ln(),
            0.0,
            [0.5; 3],
        ));
        let mut d = Deltas::zeros(1);
        // δs = +0.01 on a scale of 0.1: 10 % larger → 0.1 · 0.1 = 0.01 world units.
        d.ds = vec![[0.01, 0.0, 0.0]];
        let w = motion_under(&splats, &d);
        assert!((w - 0.01).abs() < 1e-5, "{w}");
        // δq turning the identity by θ about z: q = (cos θ/2, 0, 0, sin θ/2).
        let th = 0.2f32;
        let mut d = Deltas::zeros(1);
        let q0 = splats.rotations[0];
        d.dq = vec![[(th / 2.0).cos() - q0[0], 0.0, 0.0, (th / 2.0).sin() - q0[3]]];
        let w = motion_under(&splats, &d);
        assert!((w - 0.1 * th).abs() < 1e-5, "{w}");
    }
}
