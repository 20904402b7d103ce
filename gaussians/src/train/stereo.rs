//! Multi-view plane-sweep stereo over the train frames: a geometry-aware initial point
//! cloud for scenes that come without one (no SfM points).
//!
//! Random initial Gaussians cannot find the geometry of a scene seen by a few cameras
//! along a short path: the optimiser fits each train view with Gaussians at wrong depths
//! and novel views fall apart (docs/benchmarks/2026-11-23-warm-up.md). Plane sweep
//! (Collins 1996; multi-baseline SAD as Okutomi & Kanade 1993) gives the depth of
//! textured pixels from the frames alone:
//!
//! - for each reference view and each of `planes` fronto-parallel depths `d_k` (uniform in
//!   inverse depth between `near` and `far`), every reference pixel's ray point
//!   `X = d_k·r(p)` is mapped into each of the `neighbours` nearest train cameras and
//!   their colours compared (mean absolute RGB difference, bilinear sampling);
//! - the per-neighbour costs are summed over a `(2·window+1)²` box, the best half of the
//!   neighbours is averaged per pixel (robust to occlusion and to objects that move
//!   between frames), and the winning plane is refined by a parabola in inverse depth;
//! - a pixel is kept when its window has texture, its best cost is low and clearly below
//!   the best cost away from the winner (`ratio` test), so flat or ambiguous regions
//!   give no points.
//!
//! Cost: `planes × neighbours × pixels` bilinear samples per reference view (rayon over
//! planes), memory one `planes × pixels` f32 cost volume at a time (≈ 100 MB at 512²).

use rayon::prelude::*;
use scene::Camera;

/// Settings of the sweep (`[stereo]` in `settings.toml`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StereoSettings {
    /// Depth hypotheses per reference view (uniform in inverse depth).
    pub planes: usize,
    /// Nearest train cameras compared with each reference view.
    pub neighbours: usize,
    /// Half-size of the square cost-aggregation window, pixels.
    pub window: usize,
    /// Keep a pixel when best cost < `ratio` × the best cost at least `planes / 16`
    /// planes away from the winner.
    pub ratio: f32,
    /// Keep a pixel when its mean absolute colour difference is below this.
    pub max_cost: f32,
    /// Minimum standard deviation of the reference colours in the window.
    pub min_texture: f32,
    /// Relative depth tolerance of the cross-view consistency check.
    pub consistency: f32,
    /// Other views that must agree with a pixel's depth for it to be kept.
    pub min_consistent: usize,
    /// Reference views swept at most (evenly spaced over the train frames); every view
    /// can still serve as a neighbour. Bounds the cost on long recordings.
    pub max_reference_views: usize,
    /// Radius of the hole filling, × the image width (0 = no filling).
    pub fill_radius: f64,
    /// Fraction of the initial Gaussians that are random (frustum) points, for what
    /// stereo cannot see (flat regions, occlusions, moving objects).
    pub random_fraction: f64,
}

impl Default for StereoSettings {
    fn default() -> Self {
        StereoSettings {
            planes: 96,
            neighbours: 8,
            window: 2,
            ratio: 0.85,
            max_cost: 0.1,
            min_texture: 0.02,
            consistency: 0.03,
            min_consistent: 2,
            max_reference_views: 16,
            fill_radius: 0.08,
            random_fraction: 0.1,
        }
    }
}

impl StereoSettings {
    pub fn validate(&self) -> Result<(), String> {
        if !(2..=1024).contains(&self.planes)
            || self.neighbours == 0
            || self.window > 16
            || self.max_reference_views < 2
        {
            return Err(
                "stereo: 2 ≤ planes ≤ 1024, neighbours ≥ 1, window ≤ 16, max_reference_views ≥ 2"
                    .into(),
            );
        }
        let ok = self.ratio > 0.0
            && self.ratio <= 1.0
            && self.max_cost > 0.0
            && (0.0..=1.0).contains(&self.random_fraction)
            && !self.min_texture.is_nan()
            && self.consistency > 0.0
            && (0.0..=0.5).contains(&self.fill_radius);
        if !ok {
            return Err("stereo: 0 < ratio ≤ 1, max_cost > 0, random_fraction in [0, 1]".into());
        }
        Ok(())
    }
}

/// A reference view for the sweep: camera and planar RGB (`3 × H × W`).
pub struct StereoView<'a> {
    pub camera: &'a Camera,
    pub rgb: &'a [f32],
}

/// A reconstructed surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct StereoPoint {
    pub position: [f32; 3],
    pub colour: [f32; 3],
    /// Depth in the reference camera (for the footprint of the Gaussian).
    pub depth: f32,
    /// Focal length of the reference camera, pixels.
    pub focal: f32,
}

/// A neighbour view seen from a reference view: reference rays rotated into the
/// neighbour's frame and the reference centre in that frame.
struct NeighbourMap<'a> {
    rays: Vec<[f32; 3]>,
    t: [f32; 3],
    view: &'a StereoView<'a>,
}

/// Depth map of one reference view: depth per pixel, 0 where rejected.
pub fn depth_map(
    views: &[StereoView],
    reference: usize,
    near: f64,
    far: f64,
    s: &StereoSettings,
) -> Vec<f32> {
    let r = &views[reference];
    let k = &r.camera.intrinsics;
    let (w, h) = (k.width as usize, k.height as usize);
    let n = w * h;
    let nbrs = nearest_cameras(views, reference, s.neighbours);
    if nbrs.is_empty() || n == 0 || !(near > 0.0 && far > near) {
        return vec![0.0; n];
    }
    // Per neighbour: the rotated reference rays R·r(p) and the translation, so that the
    // point at depth d maps to d·(R·r) + t in the neighbour's camera frame.
    let ref_to_world = r.camera.cam_to_world;
    let maps: Vec<NeighbourMap> = nbrs
        .iter()
        .map(|&j| {
            let nb = &views[j];
            let rot = nb.camera.cam_to_world.rotation.inverse() * ref_to_world.rotation;
            let t = nb.camera.cam_to_world.to_camera(ref_to_world.translation);
            let rays = (0..n)
                .map(|p| {
                    let (u, v) = ((p % w) as f64, (p / w) as f64);
                    let ray = glam::DVec3::new((u - k.cx) / k.fx, -(v - k.cy) / k.fy, -1.0);
                    (rot * ray).as_vec3().to_array()
                })
                .collect();
            NeighbourMap {
                rays,
                t: t.as_vec3().to_array(),
                view: nb,
            }
        })
        .collect();
    // Inverse depth of (fractional) plane index `x`: uniform from 1/far to 1/near.
    let inv = |x: f32| {
        let a = x as f64 / (s.planes - 1) as f64;
        (1.0 / far + a * (1.0 / near - 1.0 / far)) as f32
    };
    let keep = nbrs.len().div_ceil(2);
    // Cost volume: planes × pixels (aggregated, best-half mean).
    let volume: Vec<Vec<f32>> = (0..s.planes)
        .into_par_iter()
        .map(|i| {
            let d = 1.0 / inv(i as f32);
            let per: Vec<Vec<f32>> = maps
                .iter()
                .map(|m| {
                    let raw = plane_cost(r.rgb, m.view, &m.rays, m.t, d, w, h);
                    box_sum(&raw, w, h, s.window)
                })
                .collect();
            let mut out = vec![0.0f32; n];
            let mut buf = Vec::with_capacity(per.len());
            for (p, o) in out.iter_mut().enumerate() {
                buf.clear();
                buf.extend(per.iter().map(|c| c[p]));
                buf.sort_unstable_by(f32::total_cmp);
                *o = buf[..keep].iter().sum::<f32>() / keep as f32;
            }
            out
        })
        .collect();
    let area = ((2 * s.window + 1) * (2 * s.window + 1)) as f32;
    let texture = window_std(r.rgb, w, h, s.window);
    let gap = (s.planes / 16).max(2);
    (0..n)
        .into_par_iter()
        .map(|p| {
            let (mut best, mut bi) = (f32::INFINITY, 0);
            for (i, c) in volume.iter().enumerate() {
                if c[p] < best {
                    (best, bi) = (c[p], i);
                }
            }
            let second = volume
                .iter()
                .enumerate()
                .filter(|(i, _)| i.abs_diff(bi) >= gap)
                .map(|(_, c)| c[p])
                .fold(f32::INFINITY, f32::min);
            let cost = best / area;
            if texture[p] < s.min_texture
                || cost > s.max_cost
                || best > s.ratio * second
                || bi == 0
                || bi == s.planes - 1
            {
                return 0.0;
            }
            // Parabola through the winner and its neighbours, in plane-index units.
            let (cm, c0, cp) = (volume[bi - 1][p], best, volume[bi + 1][p]);
            let den = cm - 2.0 * c0 + cp;
            let off = if den > 0.0 {
                (0.5 * (cm - cp) / den).clamp(-0.5, 0.5)
            } else {
                0.0
            };
            1.0 / inv(bi as f32 + off)
        })
        .collect()
}

/// Depth maps of the reference views (at most `max_reference_views`, evenly spaced; the
/// other views' maps are empty) after the cross-view consistency check: a pixel survives
/// when its point, projected into at least `min_consistent` other reference views, lands
/// on a kept pixel whose depth agrees with the projected depth within `consistency`
/// (relative).
/// Outliers of single views rarely agree with another view, so the fused maps hold
/// few floaters.
pub fn fused_depth_maps(
    views: &[StereoView],
    near: f64,
    far: f64,
    s: &StereoSettings,
) -> Vec<Vec<f32>> {
    let refs = reference_views(views.len(), s.max_reference_views);
    let maps: Vec<Vec<f32>> = (0..views.len())
        .map(|i| {
            if refs.contains(&i) {
                depth_map(views, i, near, far, s)
            } else {
                Vec::new()
            }
        })
        .collect();
    (0..views.len())
        .map(|i| {
            let v = &views[i];
            let w = v.camera.intrinsics.width as usize;
            maps[i]
                .par_iter()
                .enumerate()
                .map(|(p, &d)| {
                    if d <= 0.0 {
                        return 0.0;
                    }
                    let px = glam::DVec2::new((p % w) as f64, (p / w) as f64);
                    let x = v.camera.unproject_world(px, d as f64);
                    let agree = (0..views.len())
                        .filter(|&j| j != i && !maps[j].is_empty())
                        .filter(|&j| {
                            let o = &views[j].camera;
                            let Some((q, dq)) = o.project_world(x) else {
                                return false;
                            };
                            let (ow, oh) = (o.intrinsics.width as f64, o.intrinsics.height as f64);
                            let (u, vv) = (q.x.round(), q.y.round());
                            if !(u >= 0.0 && vv >= 0.0 && u < ow && vv < oh) {
                                return false;
                            }
                            let od = maps[j][vv as usize * ow as usize + u as usize] as f64;
                            od > 0.0 && ((od - dq) / dq).abs() <= s.consistency as f64
                        })
                        .count();
                    if agree >= s.min_consistent { d } else { 0.0 }
                })
                .collect()
        })
        .collect()
}

/// `k` reference views evenly spaced over `n` (all of them when `n ≤ k`), so the sweep's
/// cost stays bounded on recordings with many frames.
fn reference_views(n: usize, k: usize) -> Vec<usize> {
    if n <= k {
        return (0..n).collect();
    }
    let mut v: Vec<usize> = (0..k).map(|i| i * (n - 1) / (k - 1).max(1)).collect();
    v.dedup();
    v
}

/// Fill the holes of a depth map (flat, untextured regions) from the kept pixels within
/// `radius`: the box mean of their inverse depth, where at least a tenth of the box is
/// kept and the kept inverse depths in the box agree (relative spread ≤ `consistency`,
/// so boxes across a depth edge stay empty).
pub fn fill_holes(depth: &[f32], w: usize, h: usize, radius: usize, consistency: f32) -> Vec<f32> {
    let inv: Vec<f32> = depth
        .iter()
        .map(|&d| if d > 0.0 { 1.0 / d } else { 0.0 })
        .collect();
    let cnt: Vec<f32> = depth.iter().map(|&d| (d > 0.0) as u8 as f32).collect();
    let sq: Vec<f32> = inv.iter().map(|v| v * v).collect();
    let (si, sc, ss) = (
        box_sum(&inv, w, h, radius),
        box_sum(&cnt, w, h, radius),
        box_sum(&sq, w, h, radius),
    );
    let area = ((2 * radius + 1) * (2 * radius + 1)) as f32;
    depth
        .iter()
        .enumerate()
        .map(|(p, &d)| {
            if d > 0.0 || sc[p] < 0.1 * area {
                return d;
            }
            let mean = si[p] / sc[p];
            let spread = (ss[p] / sc[p] - mean * mean).max(0.0).sqrt();
            if mean > 0.0 && spread <= consistency * mean {
                1.0 / mean
            } else {
                0.0
            }
        })
        .collect()
}

/// Surface points of every train view's fused depth map ([`fused_depth_maps`]), holes
/// filled ([`fill_holes`], radius `fill_radius` × the image width).
pub(crate) fn stereo_points(
    views: &[StereoView],
    near: f64,
    far: f64,
    s: &StereoSettings,
) -> Vec<StereoPoint> {
    let maps: Vec<Vec<f32>> = fused_depth_maps(views, near, far, s)
        .into_iter()
        .zip(views)
        .map(|(m, v)| {
            let (w, h) = (
                v.camera.intrinsics.width as usize,
                v.camera.intrinsics.height as usize,
            );
            let r = (s.fill_radius * w as f64).round() as usize;
            if r == 0 || m.is_empty() {
                m
            } else {
                fill_holes(&m, w, h, r, s.consistency)
            }
        })
        .collect();
    let mut out = Vec::new();
    for (v, depth) in views.iter().zip(&maps) {
        if depth.is_empty() {
            continue;
        }
        let k = &v.camera.intrinsics;
        let (w, n) = (k.width as usize, depth.len());
        for (p, &d) in depth.iter().enumerate() {
            if d > 0.0 {
                let px = glam::DVec2::new((p % w) as f64, (p / w) as f64);
                let x = v.camera.unproject_world(px, d as f64);
                out.push(StereoPoint {
                    position: x.as_vec3().to_array(),
                    colour: [v.rgb[p], v.rgb[n + p], v.rgb[2 * n + p]],
                    depth: d,
                    focal: k.fx as f32,
                });
            }
        }
    }
    out
}

/// Indices of the `k` train cameras nearest (by centre) to view `i`, itself excluded.
fn nearest_cameras(views: &[StereoView], i: usize, k: usize) -> Vec<usize> {
    let c = views[i].camera.cam_to_world.centre();
    let mut others: Vec<(f64, usize)> = (0..views.len())
        .filter(|&j| j != i)
        .map(|j| ((views[j].camera.cam_to_world.centre() - c).length(), j))
        .filter(|(d, _)| *d > 1e-9)
        .collect();
    others.sort_by(|a, b| a.0.total_cmp(&b.0));
    others.into_iter().take(k).map(|(_, j)| j).collect()
}

/// Mean absolute RGB difference between each reference pixel and the neighbour's colour
/// where the pixel's point at depth `d` projects (1 outside the neighbour's image or
/// behind it).
fn plane_cost(
    rgb: &[f32],
    nb: &StereoView,
    rays: &[[f32; 3]],
    t: [f32; 3],
    d: f32,
    w: usize,
    h: usize,
) -> Vec<f32> {
    let k = &nb.camera.intrinsics;
    let (nw, nh) = (k.width as usize, k.height as usize);
    let (fx, fy, cx, cy) = (k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32);
    let (n, nn) = (w * h, nw * nh);
    let mut out = vec![1.0f32; n];
    for (p, o) in out.iter_mut().enumerate() {
        let r = rays[p];
        let x = [d * r[0] + t[0], d * r[1] + t[1], d * r[2] + t[2]];
        let depth = -x[2];
        if depth <= 1e-6 {
            continue;
        }
        let u = cx + fx * x[0] / depth;
        let v = cy - fy * x[1] / depth;
        if !(u >= 0.0 && v >= 0.0 && u <= (nw - 1) as f32 && v <= (nh - 1) as f32) {
            continue;
        }
        let (u0, v0) = (
            (u as usize).min(nw.saturating_sub(2)),
            (v as usize).min(nh.saturating_sub(2)),
        );
        let (fu, fv) = (u - u0 as f32, v - v0 as f32);
        let q = v0 * nw + u0;
        let (q1, q2, q3) = (
            (q + 1).min(nn - 1),
            (q + nw).min(nn - 1),
            (q + nw + 1).min(nn - 1),
        );
        let mut c = 0.0;
        for ch in 0..3 {
            let b = &nb.rgb[ch * nn..(ch + 1) * nn];
            let top = b[q] + fu * (b[q1] - b[q]);
            let bot = b[q2] + fu * (b[q3] - b[q2]);
            c += (rgb[ch * n + p] - (top + fv * (bot - top))).abs();
        }
        *o = c / 3.0;
    }
    out
}

/// Sum over the `(2r+1)²` box around each pixel (clamped at the borders: border pixels
/// repeat), separable.
fn box_sum(a: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    let mut tmp = vec![0.0f32; a.len()];
    for y in 0..h {
        let row = &a[y * w..(y + 1) * w];
        for x in 0..w {
            let mut s = 0.0;
            for dx in 0..=2 * r {
                let xx = (x + dx).saturating_sub(r).min(w - 1);
                s += row[xx];
            }
            tmp[y * w + x] = s;
        }
    }
    let mut out = vec![0.0f32; a.len()];
    for y in 0..h {
        for dy in 0..=2 * r {
            let yy = (y + dy).saturating_sub(r).min(h - 1);
            for x in 0..w {
                out[y * w + x] += tmp[yy * w + x];
            }
        }
    }
    out
}

/// Standard deviation of the reference colours (all channels) in each pixel's box.
fn window_std(rgb: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    let n = w * h;
    let mut sum = vec![0.0f32; n];
    let mut sq = vec![0.0f32; n];
    for ch in 0..3 {
        let c = &rgb[ch * n..(ch + 1) * n];
        let s = box_sum(c, w, h, r);
        let q = box_sum(&c.iter().map(|v| v * v).collect::<Vec<_>>(), w, h, r);
        for p in 0..n {
            sum[p] += s[p];
            sq[p] += q[p];
        }
    }
    let m = (3 * (2 * r + 1) * (2 * r + 1)) as f32;
    sum.iter()
        .zip(&sq)
        .map(|(&s, &q)| ((q / m - (s / m).powi(2)).max(0.0)).sqrt())
        .collect()
}
