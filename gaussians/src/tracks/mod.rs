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

pub mod bundle;
pub mod depth;
pub mod events;
pub mod file;
pub mod fill;
pub mod init;
pub mod lift;
pub mod lk;
pub mod loss;
pub mod part_motion;
pub mod parts;
pub mod prior_loss;
pub mod rigid;
mod settings;

use crate::splats::Splats;
use glam::{DVec2, DVec3, Vec2};
pub(crate) use init::{Image, add_moving};
use lift::{Lifted, Observation};
use rayon::prelude::*;
use scene::Camera;
pub use settings::{AUTO_STRIDE_PIXELS, Handover, TrackSettings};

/// How much nearer (relative) another point within a pixel may be before a stereo point
/// counts as hidden when the priors are aligned ([`depth::visible_points`]).
const VISIBLE_TOLERANCE: f64 = 0.05;

/// One frame for tracking: its camera, normalised time and pyramid, and the event
/// images between it and the next frame ([`events`]; empty: the frames alone).
pub struct Frame<'a> {
    pub camera: &'a Camera,
    pub time: f64,
    pub pyramid: lk::Pyramid,
    pub between: Vec<lk::Pyramid>,
}

/// The images a link from frame `k` to frame `k ± 1` passes through, `k`'s first.
fn chain<'f>(frames: &'f [Frame], k: usize, forward: bool) -> Vec<&'f lk::Pyramid> {
    let (near, far) = if forward { (k, k + 1) } else { (k - 1, k) };
    let mut c: Vec<&lk::Pyramid> = std::iter::once(&frames[near].pyramid)
        .chain(&frames[near].between)
        .chain(std::iter::once(&frames[far].pyramid))
        .collect();
    if !forward {
        c.reverse();
    }
    c
}

/// `p` carried through `chain` image by image (`None` where a window is lost). Matching
/// the chain's ends directly from where it lands loses most of what the event images
/// gained on `fast` (the window's appearance changes over a turn; 321 against 621 links
/// within 1.5 px, `tests/event_tracks.rs`' scene): the links are kept as chained.
fn follow(chain: &[&lk::Pyramid], p: Vec2, st: &TrackSettings) -> Option<Vec2> {
    let (r, e) = (st.radius as i32, st.min_texture);
    (chain.windows(2)).try_fold(p, |q, w| lk::track(w[0], w[1], q, r, e))
}

/// Where a window starting at `p` lands in each image of `chain` after the first
/// (`None` where it is lost on the way).
fn follow_each(chain: &[&lk::Pyramid], p: Vec2, st: &TrackSettings) -> Option<Vec<Vec2>> {
    let (r, e) = (st.radius as i32, st.min_texture);
    let mut out = Vec::with_capacity(chain.len().saturating_sub(1));
    let mut q = p;
    for w in chain.windows(2) {
        q = lk::track(w[0], w[1], q, r, e)?;
        out.push(q);
    }
    Some(out)
}

/// Where `track` passed through the event images between two consecutive frames that
/// both saw it: followed forward again from the earlier frame and kept when it lands
/// within `forward_backward` of the later one. Each as (camera between the two frames'
/// at the image's time, normalised time, camera pixel).
pub fn between_positions(
    frames: &[Frame],
    track: &[Option<Vec2>],
    st: &TrackSettings,
) -> Vec<(Camera, f64, DVec2)> {
    let mut out = Vec::new();
    for k in 0..frames.len().saturating_sub(1) {
        let (Some(a), Some(b)) = (track[k], track[k + 1]) else {
            continue;
        };
        let n = frames[k].between.len();
        if n == 0 {
            continue;
        }
        let Some(seen) = follow_each(&chain(frames, k, true), a, st) else {
            continue;
        };
        if seen[n].distance(b) > st.forward_backward {
            continue;
        }
        let (ca, cb) = (frames[k].camera, frames[k + 1].camera);
        for (j, q) in seen[..n].iter().enumerate() {
            let s = (j + 1) as f64 / (n + 1) as f64;
            let camera = Camera {
                intrinsics: ca.intrinsics,
                cam_to_world: scene::Pose::interpolate(&ca.cam_to_world, &cb.cam_to_world, s),
            };
            let time = frames[k].time + s * (frames[k + 1].time - frames[k].time);
            out.push((camera, time, camera_pixel(*q)));
        }
    }
    out
}

/// The track of pixel `p` of frame `r` through all frames (`None` where it was lost).
pub fn track_from(frames: &[Frame], r: usize, p: Vec2, st: &TrackSettings) -> Vec<Option<Vec2>> {
    track_within(frames, r, p, st, 0..frames.len())
}

/// [`track_from`] followed only over the frames `span` (which holds `r`): `None` outside.
pub fn track_within(
    frames: &[Frame],
    r: usize,
    p: Vec2,
    st: &TrackSettings,
    span: std::ops::Range<usize>,
) -> Vec<Option<Vec2>> {
    let mut out = vec![None; frames.len()];
    out[r] = Some(p);
    for step in [1isize, -1] {
        let mut k = r as isize;
        while (span.start as isize..span.end as isize).contains(&(k + step)) {
            let Some(from) = out[k as usize] else { break };
            let Some(to) = checked_link(&chain(frames, k as usize, step > 0), from, st) else {
                break;
            };
            k += step;
            out[k as usize] = Some(to);
        }
    }
    out
}

/// `p` followed through `chain` (a link between two consecutive frames, [`chain`]):
/// where it lands, kept when it lands in the image and following it back lands within
/// `forward_backward` of `p` (`None` otherwise).
fn checked_link(chain: &[&lk::Pyramid], p: Vec2, st: &TrackSettings) -> Option<Vec2> {
    let g = &chain.last()?.0[0];
    let q = follow(chain, p, st)?;
    let inside = q.x >= 0.0 && q.y >= 0.0 && q.x < g.width as f32 && q.y < g.height as f32;
    let back: Vec<&lk::Pyramid> = chain.iter().rev().copied().collect();
    (inside && follow(&back, q, st)?.distance(p) <= st.forward_backward).then_some(q)
}

/// Every `stride`-th pixel of a `w`×`h` frame (Lucas–Kanade coordinates, row by row):
/// where tracks start.
fn grid(w: usize, h: usize, stride: usize) -> impl Iterator<Item = Vec2> {
    let stride = stride.max(1);
    (0..h).step_by(stride).flat_map(move |y| {
        (0..w)
            .step_by(stride)
            .map(move |x| Vec2::new(x as f32 + 0.5, y as f32 + 0.5))
    })
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

/// Lift one track (Lucas–Kanade positions): still if its rays meet (and, with depth
/// priors, its depth agrees with theirs), else a trajectory when it was seen in at least
/// 5 frames (9 unknowns; 3 with prior depths) and it fits; `None` otherwise. `depths` holds each frame's
/// aligned prior (empty: none). Without prior depths the positions of a moving track in
/// the event images between the frames ([`between_positions`]) count as observations
/// too: a window of 3 frames (and one either side) then lifts without all 5 frames, and
/// the fit is checked between the frames as well.
pub fn lift_track(
    frames: &[Frame],
    track: &[Option<Vec2>],
    st: &TrackSettings,
    depths: &[Option<depth::Aligned>],
) -> Option<Lifted> {
    let t0 = crate::motion::T0 as f64;
    let between: Vec<(Camera, f64, DVec2)>;
    let mut obs: Vec<Observation> = (frames.iter().enumerate().zip(track))
        .filter_map(|((k, f), p)| {
            p.map(|p| {
                let pixel = camera_pixel(p);
                Observation {
                    camera: f.camera,
                    pixel,
                    tau: f.time - t0,
                    depth: depths.get(k).and_then(|d| d.as_ref()?.at(pixel)),
                }
            })
        })
        .collect();
    if obs.len() < 3 {
        return None;
    }
    let x = lift::still(&obs)?;
    let is_still = |x: DVec3| {
        lift::rms_pixels(&Lifted::Still(x), &obs) < st.still_pixels
            && agrees_with_prior(x, &obs, 3.0 * st.depth_sigma)
    };
    if is_still(x) {
        return Some(Lifted::Still(x));
    }
    let with_depth = obs.iter().filter(|o| o.depth.is_some()).count();
    // Over a short baseline the rays' meeting point is loose in depth: a still point at
    // the prior's depth that fits the rays as well is still (else three in five of a
    // window's trajectories on `rigid` 8 fps were still points: BENCHMARKS.md, "Still
    // points called moving").
    if st.depth_sigma > 0.0 && with_depth > 0 {
        let guess = prior_point(&obs).unwrap_or(x);
        if let Some(y) =
            lift::still_with_depth(&obs, guess, st.depth_sigma).filter(|&y| is_still(y))
        {
            return Some(Lifted::Still(y));
        }
    }
    if depths.iter().all(Option::is_none) {
        between = between_positions(frames, track, st);
        obs.extend(between.iter().map(|(camera, time, pixel)| Observation {
            camera,
            pixel: *pixel,
            tau: time - t0,
            depth: None,
        }));
    }
    // 9 unknowns: five positions of rays (two rows each), or three with prior depths
    // (three rows each: the distance is no longer free).
    if obs.len() < 5 && !(st.depth_sigma > 0.0 && with_depth >= 3) {
        return None;
    }
    // The guess weights the rays by distance: the prior's, where there is one.
    let (guess, ridge) = match prior_point(&obs) {
        Some(p) if st.depth_sigma > 0.0 => (p, st.depth_ridge),
        _ => (x, st.ridge),
    };
    let m = lift::moving(&obs, guess, ridge, st.depth_sigma)?;
    (lift::rms_pixels(&m, &obs) < st.moving_pixels).then_some(m)
}

/// Whether still point `x`'s depth in the observations' frames is within `tolerance`
/// (relative, median over the observations with a prior) of the prior; true without one.
fn agrees_with_prior(x: DVec3, obs: &[Observation], tolerance: f64) -> bool {
    let mut rel: Vec<f64> = obs
        .iter()
        .filter_map(|o| {
            let z = o.depth?;
            let (_, d) = o.camera.project_world(x)?;
            Some((d - z).abs() / z)
        })
        .collect();
    if rel.is_empty() || tolerance <= 0.0 {
        return true;
    }
    let k = rel.len() / 2;
    *rel.select_nth_unstable_by(k, f64::total_cmp).1 <= tolerance
}

/// The mean of the observations' points at their prior depths.
fn prior_point(obs: &[Observation]) -> Option<DVec3> {
    let pts: Vec<DVec3> = (obs.iter())
        .filter_map(|o| Some(o.camera.unproject_world(o.pixel, o.depth?)))
        .collect();
    (!pts.is_empty()).then(|| pts.iter().sum::<DVec3>() / pts.len() as f64)
}

/// A track before lifting: its start (frame, Lucas–Kanade pixel) and its positions.
pub struct RawTrack {
    pub frame: usize,
    pub pixel: Vec2,
    pub track: Vec<Option<Vec2>>,
}

/// The frame nearest the middle of the recording (`T0`).
pub(crate) fn middle_frame(frames: &[Frame]) -> usize {
    let t0 = crate::motion::T0 as f64;
    (0..frames.len())
        .min_by(|&i, &j| {
            (frames[i].time - t0)
                .abs()
                .total_cmp(&(frames[j].time - t0).abs())
        })
        .unwrap_or(0)
}

/// Tracks from every `stride`-th pixel of `references` frames evenly spaced over the
/// recording and of the one nearest `T0`.
pub fn raw_tracks(
    frames: &[Frame],
    stride: usize,
    references: usize,
    st: &TrackSettings,
) -> Vec<RawTrack> {
    let n = frames.len();
    if n < 3 {
        return Vec::new();
    }
    let count = references.min(n);
    let mut refs: Vec<usize> = (0..count)
        .map(|i| ((i as f64 + 0.5) * n as f64 / count as f64) as usize)
        .collect();
    refs.push(middle_frame(frames));
    refs.sort_unstable();
    refs.dedup();
    raw_tracks_at(frames, stride, &refs, st)
}

/// Tracks from every `stride`-th pixel of the frames `refs`.
pub fn raw_tracks_at(
    frames: &[Frame],
    stride: usize,
    refs: &[usize],
    st: &TrackSettings,
) -> Vec<RawTrack> {
    let spans: Vec<_> = refs.iter().map(|&r| (r, 0..frames.len())).collect();
    raw_tracks_within(frames, stride, &spans, st)
}

/// Tracks from every `stride`-th pixel of each frame `r` of `refs`, followed over its
/// own span of frames only (`(r, span)`): the cost grows with the spans, not with the
/// recording's length times the number of references.
pub(crate) fn raw_tracks_within(
    frames: &[Frame],
    stride: usize,
    refs: &[(usize, std::ops::Range<usize>)],
    st: &TrackSettings,
) -> Vec<RawTrack> {
    if st.fill > 0 {
        return fill::raw_tracks_filled(frames, stride, refs, st);
    }
    let g = &frames[0].pyramid.0[0];
    let (w, h) = (g.width, g.height);
    let starts: Vec<(usize, std::ops::Range<usize>, Vec2)> = refs
        .iter()
        .flat_map(|(r, span)| grid(w, h, stride).map(move |p| (*r, span.clone(), p)))
        .collect();
    starts
        .into_par_iter()
        .map(|(frame, span, pixel)| RawTrack {
            frame,
            pixel,
            track: track_within(frames, frame, pixel, st, span),
        })
        .collect()
}

/// `raws` lifted (with the frames' aligned priors, `depths`, empty for none). Still
/// points come from every reference frame, moving ones from the one nearest `T0` only.
pub fn lift_raw(
    frames: &[Frame],
    raws: &[RawTrack],
    st: &TrackSettings,
    depths: &[Option<depth::Aligned>],
) -> Vec<LiftedTrack> {
    let middle = middle_frame(frames);
    raws.par_iter()
        .filter_map(|r| {
            let point = lift_track(frames, &r.track, st, depths)?;
            let keep = matches!(point, Lifted::Still(_)) || r.frame == middle;
            keep.then(|| LiftedTrack {
                frame: r.frame,
                pixel: r.pixel,
                point,
                seen: r.track.iter().map(|q| q.map(camera_pixel)).collect(),
            })
        })
        .collect()
}

/// [`raw_tracks`] lifted without depth priors.
pub fn lift_frames(
    frames: &[Frame],
    stride: usize,
    references: usize,
    st: &TrackSettings,
) -> Vec<LiftedTrack> {
    lift_raw(frames, &raw_tracks(frames, stride, references, st), st, &[])
}

/// Each frame's prior aligned to the still points of `lifted` seen in it and to the
/// `points` (world, believed still: the stereo init's) it sees ([`depth::visible_points`];
/// `None` where a frame has no map or too few still points); with a line per frame on
/// stderr saying how well the prior agrees with the still scene.
pub fn align_priors(
    frames: &[Frame],
    lifted: &[&LiftedTrack],
    points: &[[f32; 3]],
    priors: &scene::depth_prior::DepthPriors,
) -> Vec<Option<depth::Aligned>> {
    let g = &frames[0].pyramid.0[0];
    let (w, h) = (g.width, g.height);
    let out: Vec<Option<depth::Aligned>> = (frames.iter().enumerate())
        .map(|(k, f)| {
            let map = priors.maps.get(k)?.as_ref()?;
            let mut refs: Vec<(DVec2, f64)> = (lifted.iter())
                .filter_map(|l| {
                    let Lifted::Still(x) = l.point else {
                        return None;
                    };
                    let seen = l.seen.get(k).copied().flatten()?;
                    Some((seen, f.camera.project_world(x)?.1))
                })
                .collect();
            refs.extend(depth::visible_points(points, f.camera, VISIBLE_TOLERANCE));
            depth::align(priors.kind, map, w, h, &refs)
        })
        .collect();
    let errs: Vec<String> = (out.iter())
        .map(|a| {
            a.as_ref()
                .map_or("-".into(), |a| format!("{:.1}", 100.0 * a.median_rel_error))
        })
        .collect();
    eprintln!(
        "depth prior: {} of {} train frames aligned to the still scene (tracks and stereo points); median error per frame, %: {}",
        out.iter().flatten().count(),
        frames.len(),
        errs.join(" ")
    );
    out
}

/// Drop the Gaussians of `s` whose depth disagrees with the aligned priors (relative
/// difference over `tolerance`) in more of the frames they project into than it agrees:
/// the stereo init's copies of moving objects, placed still at the distance where their
/// motion mimics parallax (BENCHMARKS.md, "What moves them"). A still point agrees
/// wherever nothing moves in front of it. A Gaussian seen against fewer than two priors
/// is kept. Returns how many were dropped.
pub fn drop_where_prior_disagrees(
    s: &mut Splats,
    frames: &[Frame],
    depths: &[Option<depth::Aligned>],
    tolerance: f64,
) -> usize {
    let keep: Vec<bool> = (0..s.len())
        .into_par_iter()
        .map(|i| {
            let x = glam::Vec3::from(s.means[i]).as_dvec3();
            let (mut agree, mut disagree) = (0u32, 0u32);
            for (f, d) in frames.iter().zip(depths) {
                let Some(d) = d else { continue };
                let Some((px, z)) = f.camera.project_world(x) else {
                    continue;
                };
                let Some(prior) = d.at(px) else { continue };
                if (z - prior).abs() <= tolerance * prior {
                    agree += 1;
                } else {
                    disagree += 1;
                }
            }
            // Judged only where at least two frames see it against a prior.
            agree + disagree < 2 || disagree <= agree
        })
        .collect();
    let dropped = keep.iter().filter(|k| !**k).count();
    if dropped > 0 {
        let mut kept = Splats::with_capacity(s.len() - dropped);
        for (i, _) in keep.iter().enumerate().filter(|(_, k)| **k) {
            kept.push(s.get(i));
        }
        *s = kept;
    }
    dropped
}
