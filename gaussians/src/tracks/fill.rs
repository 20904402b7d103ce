//! Tracks whose link failed, carried by their neighbours' motion (`tracks.fill`).
//!
//! Lucas–Kanade loses a window whose texture runs one way (stripes: the aperture
//! problem) or changes over a turn, and the forward–backward check then ends the track,
//! though the points around it were followed. Here the tracks of one reference frame
//! advance together, frame by frame; a track whose link failed moves by the affine motion
//! of the links that passed within `FILL_REACH` strides of it (RANSAC: the largest set
//! that one affine map carries within `INLIER_PX`, refitted by least squares), when at
//! least `MIN_INLIERS` of them agree. Measured on one link of `fast` at 96²
//! (`examples/track_ceiling.rs`, BENCHMARKS.md "What limits `fast`'s tracks"): the lost
//! links of the ball and the flag land mostly right, those of the spinning box mostly
//! not.

use super::{Frame, RawTrack, TrackSettings, chain, checked_link, grid};
use glam::Vec2;
use rayon::prelude::*;

/// Neighbours within this many strides (at least 6 px) carry a lost track.
const FILL_REACH: f32 = 6.0;
/// A neighbour agrees with an affine map that carries it within this many pixels.
const INLIER_PX: f32 = 0.75;
/// The fewest agreeing neighbours that carry a lost track.
const MIN_INLIERS: usize = 6;
/// RANSAC draws of three neighbours.
const DRAWS: usize = 60;

/// Least squares affine map taking the first point of each pair to the second, as
/// `[a, b, c, d, e, f]`: `x' = a x + b y + c`, `y' = d x + e y + f`.
pub fn fit_affine(pairs: &[(Vec2, Vec2)]) -> Option<[f64; 6]> {
    // The normal equations of the two rows share one 3×3 matrix.
    let mut m = glam::DMat3::ZERO;
    let (mut bx, mut by) = (glam::DVec3::ZERO, glam::DVec3::ZERO);
    for (p, q) in pairs {
        let r = glam::DVec3::new(p.x as f64, p.y as f64, 1.0);
        m += glam::DMat3::from_cols(r * r.x, r * r.y, r * r.z);
        bx += r * q.x as f64;
        by += r * q.y as f64;
    }
    if m.determinant().abs() < 1e-9 {
        return None;
    }
    let inv = m.inverse();
    let (sx, sy) = (inv * bx, inv * by);
    Some([sx.x, sx.y, sx.z, sy.x, sy.y, sy.z])
}

/// `p` carried by the affine map `a`.
pub fn apply(a: &[f64; 6], p: Vec2) -> Vec2 {
    let (x, y) = (p.x as f64, p.y as f64);
    Vec2::new(
        (a[0] * x + a[1] * y + a[2]) as f32,
        (a[3] * x + a[4] * y + a[5]) as f32,
    )
}

/// Where `p` goes by the motion of `links` (from, to) within `reach` pixels of it: the
/// affine map most of them agree with (at least [`MIN_INLIERS`]), `None` without one.
/// `seed` makes the draws repeatable.
pub fn carried(links: &[(Vec2, Vec2)], p: Vec2, reach: f32, seed: u64) -> Option<Vec2> {
    let near: Vec<(Vec2, Vec2)> = (links.iter())
        .filter(|(a, _)| a.distance_squared(p) <= reach * reach)
        .copied()
        .collect();
    if near.len() < MIN_INLIERS {
        return None;
    }
    let mut state = seed | 1;
    let mut draw = || {
        state =
            (state.wrapping_mul(6_364_136_223_846_793_005)).wrapping_add(1_442_695_040_888_963_407);
        ((state >> 33) as usize) % near.len()
    };
    let mut best: Vec<(Vec2, Vec2)> = Vec::new();
    for _ in 0..DRAWS {
        let Some(a) = fit_affine(&[near[draw()], near[draw()], near[draw()]]) else {
            continue;
        };
        let agree: Vec<(Vec2, Vec2)> = (near.iter())
            .filter(|(u, v)| apply(&a, *u).distance(*v) < INLIER_PX)
            .copied()
            .collect();
        if agree.len() > best.len() {
            best = agree;
        }
    }
    if best.len() < MIN_INLIERS {
        return None;
    }
    fit_affine(&best).map(|a| apply(&a, p))
}

/// The links of one step, bucketed by cells of `cell` pixels for the neighbour search.
struct Buckets {
    cell: f32,
    width: usize,
    cells: Vec<Vec<(Vec2, Vec2)>>,
}

impl Buckets {
    fn new(links: &[(Vec2, Vec2)], cell: f32, w: f32, h: f32) -> Buckets {
        let width = (w / cell).ceil().max(1.0) as usize;
        let height = (h / cell).ceil().max(1.0) as usize;
        let mut cells = vec![Vec::new(); width * height];
        for &(a, b) in links {
            let (cx, cy) = ((a.x / cell) as usize, (a.y / cell) as usize);
            cells[cy.min(height - 1) * width + cx.min(width - 1)].push((a, b));
        }
        Buckets { cell, width, cells }
    }

    /// The links in the 3×3 cells around `p`.
    fn around(&self, p: Vec2) -> Vec<(Vec2, Vec2)> {
        let height = self.cells.len() / self.width;
        let (cx, cy) = ((p.x / self.cell) as isize, (p.y / self.cell) as isize);
        let mut out = Vec::new();
        for y in (cy - 1).max(0)..=(cy + 1).min(height as isize - 1) {
            for x in (cx - 1).max(0)..=(cx + 1).min(self.width as isize - 1) {
                out.extend_from_slice(&self.cells[y as usize * self.width + x as usize]);
            }
        }
        out
    }
}

/// Tracks from every `stride`-th pixel of each reference frame `r` of `refs`, over its
/// span, advanced together frame by frame: a link that fails (lost, outside the image,
/// or back more than `forward_backward` from where it started) is carried by its
/// neighbours' links ([`carried`]) instead of ending the track, up to `tracks.fill`
/// links of a track each way from its reference frame.
pub(crate) fn raw_tracks_filled(
    frames: &[Frame],
    stride: usize,
    refs: &[(usize, std::ops::Range<usize>)],
    st: &TrackSettings,
) -> Vec<RawTrack> {
    let g = &frames[0].pyramid.0[0];
    let (w, h) = (g.width, g.height);
    let (wf, hf) = (w as f32, h as f32);
    let inside = |q: Vec2| q.x >= 0.0 && q.y >= 0.0 && q.x < wf && q.y < hf;
    let reach = (FILL_REACH * stride.max(1) as f32).max(6.0);
    let mut out = Vec::new();
    for (r, span) in refs {
        let r = *r;
        let starts: Vec<Vec2> = grid(w, h, stride).collect();
        // Links each track had carried so far (per direction).
        let mut carries = vec![0u32; starts.len()];
        let mut tracks: Vec<Vec<Option<Vec2>>> = (starts.iter())
            .map(|&p| {
                let mut t = vec![None; frames.len()];
                t[r] = Some(p);
                t
            })
            .collect();
        for step in [1isize, -1] {
            carries.iter_mut().for_each(|c| *c = 0);
            let mut k = r as isize;
            while k + step >= 0 && span.contains(&((k + step) as usize)) {
                let (from, to) = (k as usize, (k + step) as usize);
                let links = chain(frames, from, step > 0);
                let checked: Vec<Option<Vec2>> = (tracks.par_iter())
                    .map(|t| checked_link(&links, t[from]?, st))
                    .collect();
                let passed: Vec<(Vec2, Vec2)> = (tracks.iter().zip(&checked))
                    .filter_map(|(t, q)| Some((t[from]?, (*q)?)))
                    .collect();
                let buckets = Buckets::new(&passed, reach, wf, hf);
                let next: Vec<(Option<Vec2>, bool)> = (tracks.par_iter().zip(&checked))
                    .zip(&carries)
                    .enumerate()
                    .map(|(i, ((t, q), &c))| {
                        let Some(p) = t[from] else {
                            return (None, false);
                        };
                        if q.is_some() || c >= st.fill {
                            return (*q, false);
                        }
                        let seed = (i as u64) << 8 | to as u64;
                        let q = carried(&buckets.around(p), p, reach, seed).filter(|&q| inside(q));
                        (q, q.is_some())
                    })
                    .collect();
                for ((t, c), (q, was_carried)) in tracks.iter_mut().zip(&mut carries).zip(next) {
                    t[to] = q;
                    *c += was_carried as u32;
                }
                k += step;
            }
        }
        out.extend(
            (starts.into_iter().zip(tracks)).map(|(pixel, track)| RawTrack {
                frame: r,
                pixel,
                track,
            }),
        );
    }
    out
}
