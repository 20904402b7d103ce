//! The tracks init ([`add_moving`]): the stereo Gaussians plus one per moving track, on
//! its trajectory; with `tracks.window`, one per moving track of each window of frames,
//! living over that window only.

use super::lift::Lifted;
use super::{
    Frame, Handover, LiftedTrack, RawTrack, TrackSettings, align_priors, depth,
    drop_where_prior_disagrees, events, lift_raw, lift_track, lk, loss, raw_tracks,
    raw_tracks_within,
};
use crate::splats::{ALWAYS, Gaussian, Splats};
use scene::Camera;
use std::collections::HashSet;

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
/// `s`), the priors as aligned (one per view; empty without priors), and the largest
/// share of a reference frame's track starts that lifted to moving Gaussians (how much
/// of the view moves). With `events` the tracks are chained through event images
/// between the frames.
pub(crate) fn add_moving(
    s: &mut Splats,
    views: &[Image],
    stride: usize,
    st: &TrackSettings,
    priors: Option<&scene::depth_prior::DepthPriors>,
    events: Option<&events::EventSource>,
) -> (loss::Table, Vec<Option<depth::Aligned>>, f64) {
    let Some(first) = views.first() else {
        return (Vec::new(), Vec::new(), 0.0);
    };
    let k = &first.camera.intrinsics;
    let (w, h) = (k.width as usize, k.height as usize);
    let levels = st.levels as usize;
    let grey: Vec<lk::Grey> = (views.iter())
        .map(|v| lk::Grey::from_planar(v.rgb, w, h))
        .collect();
    let mut between = match events {
        Some(src) => events::between(&grey, src),
        None => Vec::new(),
    };
    between.resize_with(views.len(), Vec::new);
    let frames: Vec<Frame> = (views.iter().zip(grey).zip(between))
        .map(|((v, g), b)| Frame {
            camera: v.camera,
            time: v.time,
            pyramid: lk::Pyramid::new(g, levels),
            between: b.into_iter().map(|g| lk::Pyramid::new(g, levels)).collect(),
        })
        .collect();
    let raws = raw_tracks(&frames, stride, 0, st);
    let mut lifted = lift_raw(&frames, &raws, st, &[]);
    let mut aligned = Vec::new();
    if let Some(p) = priors.filter(|_| st.depth_sigma > 0.0) {
        // The priors are aligned to still tracks from frames spread over the recording
        // as well (every fourth pixel of five): the middle frame's tracks do not reach
        // the ends when the frames are far apart.
        let spread = lift_raw(&frames, &raw_tracks(&frames, 4 * stride, 5, st), st, &[]);
        let still: Vec<&LiftedTrack> = (lifted.iter().chain(&spread))
            .filter(|l| matches!(l.point, Lifted::Still(_)))
            .collect();
        let mut depths = align_priors(&frames, &still, &s.means, p);
        // A frame whose prior the still scene does not confirm is not used.
        let mut set_aside = 0;
        for d in &mut depths {
            if d.as_ref()
                .is_some_and(|a| a.median_rel_error > st.depth_sigma)
            {
                (*d, set_aside) = (None, set_aside + 1);
            }
        }
        if set_aside > 0 {
            eprintln!(
                "depth prior: {set_aside} frames' maps set aside (median error over depth_sigma = {})",
                st.depth_sigma
            );
        }
        lifted = lift_raw(&frames, &raws, st, &depths);
        if st.prior_prunes {
            let dropped = drop_where_prior_disagrees(s, &frames, &depths, 3.0 * st.depth_sigma);
            eprintln!(
                "depth prior: {dropped} initial Gaussians dropped (off the prior's surface in most frames)"
            );
        }
        aligned = depths;
    }
    let moving: Vec<(LiftedTrack, [f32; 2])> = if st.window == 0 {
        let all = (lifted.into_iter()).filter(|l| matches!(l.point, Lifted::Moving { .. }));
        all.map(|l| (l, ALWAYS)).collect()
    } else {
        // A track that one quadratic holds over most of the recording keeps one
        // Gaussian for all of it (from the middle frame, as without windows); the
        // others are fitted window by window.
        let most = (3 * frames.len()).div_ceil(4);
        let whole: Vec<LiftedTrack> = (lifted.into_iter())
            .filter(|l| matches!(l.point, Lifted::Moving { .. }))
            .filter(|l| l.seen.iter().flatten().count() >= most)
            .collect();
        // The pixels each frame's whole-recording tracks pass through.
        let covered: HashSet<(usize, u32, u32)> = (whole.iter())
            .flat_map(|l| l.seen.iter().enumerate())
            .filter_map(|(k, q)| q.map(|q| (k, (q.x + 0.5) as u32, (q.y + 0.5) as u32)))
            .collect();
        let mut all: Vec<_> = whole.into_iter().map(|l| (l, ALWAYS)).collect();
        all.extend(windowed(&frames, stride, st, &aligned, &covered, raws));
        all
    };
    let mut per_reference = std::collections::HashMap::<usize, usize>::new();
    for (l, _) in &moving {
        *per_reference.entry(l.frame).or_default() += 1;
    }
    let starts = w.div_ceil(stride.max(1)) * h.div_ceil(stride.max(1));
    let share = per_reference
        .values()
        .max()
        .map_or(0.0, |&m| m as f64 / starts as f64);
    let t0 = crate::motion::T0 as f64;
    let before = s.len();
    s.motion.resize(before, [0.0; 6]);
    s.track.resize(before, loss::NONE);
    if st.window > 0 {
        s.life.resize(before, ALWAYS);
    }
    let mut table = Vec::new();
    for (l, life) in moving {
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
        if let Some(last) = s.life.last_mut() {
            *last = life;
        }
        table.push(l.seen);
    }
    if table.is_empty() {
        // No moving track: the stereo init as it is, without columns of still rows
        // (a model with none saves none, `Splats::track`).
        s.motion.clear();
        s.track.clear();
        s.life.clear();
    }
    (table, aligned, share)
}

/// One window of the moving tracks' trajectories ([`windows`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Window {
    /// The frames it holds.
    pub frames: std::ops::Range<usize>,
    /// The frame its tracks start from (the middle one).
    pub reference: usize,
    /// The frames its trajectories are fitted to: its own and one either side.
    pub context: std::ops::Range<usize>,
    /// The normalised time span its Gaussians live in, `[from, to)`, open at the
    /// recording's ends; the lives tile time (one copy of an object at any time). With
    /// [`Handover::Midway`] from midway to the previous window's last frame to midway to
    /// the next one's first; with [`Handover::Frame`] from its first frame to its last
    /// (which is the next window's first).
    pub life: [f32; 2],
}

/// The windows of `size` consecutive frames (the last may be shorter) over frames at
/// normalised `times`: one after another ([`Handover::Midway`]), or each starting at
/// the previous one's last frame ([`Handover::Frame`], `size` at least 2).
pub fn windows(times: &[f64], size: usize, handover: Handover) -> Vec<Window> {
    let n = times.len();
    let (size, step) = match handover {
        Handover::Midway => (size.max(1), size.max(1)),
        Handover::Frame => (size.max(2), size.max(2) - 1),
    };
    // Where the life of a window ending before frame `b` ends.
    let edge = |b: usize| match handover {
        Handover::Midway => (0.5 * (times[b - 1] + times[b])) as f32,
        Handover::Frame => times[b - 1] as f32,
    };
    let mut out = Vec::new();
    if n == 0 {
        return out;
    }
    let mut a = 0;
    loop {
        let b = (a + size).min(n);
        out.push(Window {
            frames: a..b,
            reference: (a + b).div_ceil(2) - 1,
            context: a.saturating_sub(1)..(b + 1).min(n),
            life: [
                out.last().map_or(ALWAYS[0], |w: &Window| w.life[1]),
                if b == n { ALWAYS[1] } else { edge(b) },
            ],
        });
        a += step;
        if b == n {
            break;
        }
    }
    out
}

/// The moving tracks of each window of `st.window` frames ([`windows`]), from its
/// reference frame, followed and lifted over the window's context only, with the
/// window's life; but none that starts at a pixel of `covered` (`(frame, x, y)`: where a
/// track with a Gaussian for the whole recording passes). A quadratic holds a turn or
/// an oscillation over a few frames where it cannot over the recording. `from_middle`:
/// the middle frame's tracks at `stride`, already followed (taken, not copied).
fn windowed(
    frames: &[Frame],
    stride: usize,
    st: &TrackSettings,
    depths: &[Option<depth::Aligned>],
    covered: &HashSet<(usize, u32, u32)>,
    from_middle: Vec<RawTrack>,
) -> Vec<(LiftedTrack, [f32; 2])> {
    let times: Vec<f64> = frames.iter().map(|f| f.time).collect();
    let middle = super::middle_frame(frames);
    let wins = windows(&times, st.window as usize, st.handover);
    let spans: Vec<_> = (wins.iter())
        .filter(|w| w.reference != middle)
        .map(|w| (w.reference, w.context.clone()))
        .collect();
    let mut raws = raw_tracks_within(frames, stride, &spans, st);
    if wins.iter().any(|w| w.reference == middle) {
        raws.extend(from_middle.into_iter().filter(|r| r.frame == middle));
    }
    raws.into_iter()
        .filter_map(|r| {
            let w = wins.iter().find(|w| w.reference == r.frame)?;
            // The surface point already has a Gaussian for the whole recording.
            let start = (r.frame, r.pixel.x as u32, r.pixel.y as u32);
            if covered.contains(&start) {
                return None;
            }
            let track: Vec<_> = (r.track.iter().enumerate())
                .map(|(k, p)| p.filter(|_| w.context.contains(&k)))
                .collect();
            let point = lift_track(frames, &track, st, depths)?;
            matches!(point, Lifted::Moving { .. }).then(|| {
                let seen = track.iter().map(|q| q.map(super::camera_pixel)).collect();
                let l = LiftedTrack {
                    frame: r.frame,
                    pixel: r.pixel,
                    point,
                    seen,
                };
                (l, w.life)
            })
        })
        .collect()
}
