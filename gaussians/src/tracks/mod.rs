//! Point tracks through the train frames and the initial Gaussians they give, with
//! their trajectories (issue #30, `init = "tracks"`).
//!
//! The rendering loss does not move a textured moving object (BENCHMARKS.md, "What
//! moves them"): its motion has to come from correspondences. Here they come from the
//! RGB train frames: pyramidal Lucas–Kanade ([`lk`]) between consecutive frames, chained
//! forwards and backwards from a set of reference frames, each link kept only when
//! tracking back lands within `forward_backward` pixels of where it started (occlusion
//! and drift check, Kalal et al. 2010). Each track is then lifted ([`lift`]): a still
//! point where its rays meet within `still_pixels`, else a quadratic trajectory. Moving
//! tracks are taken from the reference frame nearest the middle of the recording only,
//! so that each moving object starts as one copy. The init ([`add_moving`]) keeps the
//! stereo init for the still scene (still tracks alone fail where the frames are too
//! far apart for Lucas–Kanade: −4.5 dB on `fast`, BENCHMARKS.md "Tracks lifted to
//! trajectories") and adds the moving tracks' Gaussians.

pub mod file;
pub mod lift;
pub mod lk;
pub mod loss;

use crate::splats::{Gaussian, Splats};
use glam::{DVec2, Vec2};
use lift::{Lifted, Observation};
use rayon::prelude::*;
use scene::Camera;

/// Settings of the tracks init (`[tracks]` in `settings.toml`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackSettings {
    /// Half-size of the Lucas–Kanade window, pixels (window `2r + 1`, at most 16).
    pub radius: u32,
    /// Pyramid levels (1 = no pyramid).
    pub levels: u32,
    /// Smallest eigenvalue of the window's structure tensor per pixel for a trackable
    /// window (grey levels² per pixel²).
    pub min_texture: f32,
    /// A link is kept when tracking it back lands within this many pixels.
    pub forward_backward: f32,
    /// A track is a still point when its rays meet within this RMS reprojection error.
    pub still_pixels: f64,
    /// A moving track is kept when its trajectory fits within this RMS error.
    pub moving_pixels: f64,
    /// Penalty on a trajectory's acceleration, relative to the angular residuals.
    pub ridge: f64,
    /// Weight of the track term `L_track` in the warm-up ([`loss`]): each moving track's
    /// Gaussian is pulled to where its track saw it in every train frame (0 = the tracks
    /// only start the trajectories).
    pub weight: f64,
    /// Residual (pixels) above which `L_track` grows linearly (Huber): a track that
    /// drifted pulls no harder than this.
    pub huber_px: f64,
    /// `L_track`'s gradient also trains the deformation field (else only the tracked
    /// Gaussians' own centres and trajectories).
    pub into_field: bool,
}

impl Default for TrackSettings {
    fn default() -> Self {
        TrackSettings {
            radius: 3,
            levels: 3,
            min_texture: 1e-5,
            forward_backward: 1.0,
            still_pixels: 1.0,
            moving_pixels: 2.0,
            ridge: 10.0,
            weight: 0.0,
            huber_px: 1.0,
            into_field: true,
        }
    }
}

impl TrackSettings {
    pub fn validate(&self) -> Result<(), String> {
        if !(1..=16).contains(&self.radius) || !(1..=8).contains(&self.levels) {
            return Err("tracks: radius must be 1..=16 and levels 1..=8".into());
        }
        let positive = [
            self.forward_backward as f64,
            self.still_pixels,
            self.moving_pixels,
        ];
        if positive.iter().any(|v| !(v.is_finite() && *v > 0.0))
            || !(self.ridge >= 0.0 && self.min_texture >= 0.0)
            || !(self.weight.is_finite() && self.weight >= 0.0)
            || !(self.huber_px.is_finite() && self.huber_px > 0.0)
        {
            return Err(
                "tracks: thresholds and huber_px must be positive, ridge, min_texture and \
                 weight finite and ≥ 0"
                    .into(),
            );
        }
        Ok(())
    }
}

/// One frame for tracking: its camera, normalised time and pyramid.
pub struct Frame<'a> {
    pub camera: &'a Camera,
    pub time: f64,
    pub pyramid: lk::Pyramid,
}

/// The track of pixel `p` of frame `r` through all frames (`None` where it was lost).
pub fn track_from(frames: &[Frame], r: usize, p: Vec2, st: &TrackSettings) -> Vec<Option<Vec2>> {
    let mut out = vec![None; frames.len()];
    out[r] = Some(p);
    let (w, h) = {
        let g = &frames[r].pyramid.0[0];
        (g.width as f32, g.height as f32)
    };
    let inside = |q: Vec2| q.x >= 0.0 && q.y >= 0.0 && q.x < w && q.y < h;
    let radius = st.radius as i32;
    for step in [1isize, -1] {
        let mut k = r as isize;
        while (0..frames.len() as isize).contains(&(k + step)) {
            let (a, b) = (
                &frames[k as usize].pyramid,
                &frames[(k + step) as usize].pyramid,
            );
            let Some(from) = out[k as usize] else { break };
            let Some(to) = lk::track(a, b, from, radius, st.min_texture) else {
                break;
            };
            let Some(back) = lk::track(b, a, to, radius, st.min_texture) else {
                break;
            };
            if !inside(to) || back.distance(from) > st.forward_backward {
                break;
            }
            k += step;
            out[k as usize] = Some(to);
        }
    }
    out
}

/// A lifted track: where it starts (frame, Lucas–Kanade pixel), what it lifted to, and
/// where it was seen in each frame (camera pixels, [`camera_pixel`]; `None` where lost).
pub struct LiftedTrack {
    pub frame: usize,
    pub pixel: Vec2,
    pub point: Lifted,
    pub seen: Vec<Option<DVec2>>,
}

/// A Lucas–Kanade position (pixel `x` covers `[x, x + 1)`, its centre at `x + ½`) in the
/// cameras' pixel coordinates (pixel `x` centred on `x`, as the rasterizer and
/// `Camera::project_world` have it).
pub fn camera_pixel(p: Vec2) -> DVec2 {
    DVec2::new(p.x as f64 - 0.5, p.y as f64 - 0.5)
}

/// Lift one track (Lucas–Kanade positions): still if its rays meet, else a trajectory
/// when it was seen in at least 5 frames (9 unknowns) and it fits; `None` otherwise.
pub fn lift_track(frames: &[Frame], track: &[Option<Vec2>], st: &TrackSettings) -> Option<Lifted> {
    let t0 = crate::motion::T0 as f64;
    let obs: Vec<Observation> = (frames.iter().zip(track))
        .filter_map(|(f, p)| {
            p.map(|p| Observation {
                camera: f.camera,
                pixel: camera_pixel(p),
                tau: f.time - t0,
            })
        })
        .collect();
    if obs.len() < 3 {
        return None;
    }
    let x = lift::still(&obs)?;
    let still = Lifted::Still(x);
    if lift::rms_pixels(&still, &obs) < st.still_pixels {
        return Some(still);
    }
    if obs.len() < 5 {
        return None;
    }
    let m = lift::moving(&obs, x, st.ridge)?;
    (lift::rms_pixels(&m, &obs) < st.moving_pixels).then_some(m)
}

/// Tracks from every `stride`-th pixel of `references` frames evenly spaced over the
/// recording and of the one nearest `T0`, lifted. Still points come from every
/// reference frame, moving ones from the one nearest `T0` only.
pub fn lift_frames(
    frames: &[Frame],
    stride: usize,
    references: usize,
    st: &TrackSettings,
) -> Vec<LiftedTrack> {
    let n = frames.len();
    if n < 3 {
        return Vec::new();
    }
    let t0 = crate::motion::T0 as f64;
    let middle = (0..n)
        .min_by(|&i, &j| {
            (frames[i].time - t0)
                .abs()
                .total_cmp(&(frames[j].time - t0).abs())
        })
        .unwrap_or(0);
    let count = references.min(n);
    let mut refs: Vec<usize> = (0..count)
        .map(|i| ((i as f64 + 0.5) * n as f64 / count as f64) as usize)
        .collect();
    refs.push(middle);
    refs.sort_unstable();
    refs.dedup();
    let g = &frames[0].pyramid.0[0];
    let (w, h) = (g.width, g.height);
    let stride = stride.max(1);
    let starts: Vec<(usize, Vec2)> = refs
        .iter()
        .flat_map(|&r| {
            (0..h).step_by(stride).flat_map(move |y| {
                (0..w)
                    .step_by(stride)
                    .map(move |x| (r, Vec2::new(x as f32 + 0.5, y as f32 + 0.5)))
            })
        })
        .collect();
    starts
        .par_iter()
        .filter_map(|&(r, p)| {
            let tr = track_from(frames, r, p, st);
            let point = lift_track(frames, &tr, st)?;
            let keep = matches!(point, Lifted::Still(_)) || r == middle;
            keep.then(|| LiftedTrack {
                frame: r,
                pixel: p,
                point,
                seen: tr.iter().map(|q| q.map(camera_pixel)).collect(),
            })
        })
        .collect()
}

/// A train frame as the init sees it: planar RGB (all red, then green, then blue).
pub struct Image<'a> {
    pub camera: &'a Camera,
    /// Normalised time.
    pub time: f64,
    pub rgb: &'a [f32],
}

/// Appends a Gaussian for each moving track of the train frame nearest the middle of
/// the recording (every `stride`-th pixel) to `s`, with its trajectory; the Gaussians
/// already in `s` stay still. Colour of the start pixel, opacity ½, a footprint of
/// `stride` pixels at its depth. Returns the added Gaussians' tracks (camera pixels
/// per view), the table `s.track` indexes (`loss::NONE` for the Gaussians already in
/// `s`).
pub(crate) fn add_moving(
    s: &mut Splats,
    views: &[Image],
    stride: usize,
    st: &TrackSettings,
) -> loss::Table {
    let Some(first) = views.first() else {
        return Vec::new();
    };
    let k = &first.camera.intrinsics;
    let (w, h) = (k.width as usize, k.height as usize);
    let frames: Vec<Frame> = views
        .iter()
        .map(|v| Frame {
            camera: v.camera,
            time: v.time,
            pyramid: lk::Pyramid::new(lk::Grey::from_planar(v.rgb, w, h), st.levels as usize),
        })
        .collect();
    let lifted = lift_frames(&frames, stride, 0, st);
    let t0 = crate::motion::T0 as f64;
    let before = s.len();
    s.motion.resize(before, [0.0; 6]);
    s.track.resize(before, loss::NONE);
    let mut table = Vec::new();
    for l in lifted {
        let Lifted::Moving { mu, v, a } = l.point else {
            continue;
        };
        let f = &frames[l.frame];
        let Some((_, depth)) = f.camera.project_world(l.point.at(f.time - t0)) else {
            continue;
        };
        let (x, y) = (l.pixel.x as usize, l.pixel.y as usize);
        let (rgb, p) = (views[l.frame].rgb, y * w + x);
        let c0 = crate::raster::sh::C0 as f32;
        let sh = [rgb[p], rgb[w * h + p], rgb[2 * w * h + p]].map(|v| (v - 0.5) / c0);
        let scale = (0.5 * stride as f64 * depth / f.camera.intrinsics.fx) as f32;
        s.push(Gaussian {
            dynamic: true,
            ..Gaussian::isotropic(mu.as_vec3().to_array(), scale.max(1e-6).ln(), 0.0, sh)
        });
        *s.motion.last_mut().expect("just pushed") =
            [v.x, v.y, v.z, a.x, a.y, a.z].map(|c| c as f32);
        *s.track.last_mut().expect("just pushed") = table.len() as u32;
        table.push(l.seen);
    }
    table
}
