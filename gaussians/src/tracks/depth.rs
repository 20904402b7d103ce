//! Depth priors (`scene::depth_prior`) brought to the scene's units: each frame's map
//! aligned to the still points the tracks triangulated, then read at a track's pixels.
//!
//! A monocular network's depth is known up to a scale and a shift per frame (in depth or
//! in inverse depth). The still tracks seen in a frame give that frame's true depths at
//! their pixels (the point projected into the frame's camera), so the two numbers are a
//! least-squares line through those pairs, fitted twice: the second time without the pairs
//! more than three median deviations off the first line (a moving object's or a wrong
//! track's pixels).

use scene::depth_prior::DepthKind;

/// One frame's map in camera-space depth (`z`, the poses' units; 0 for holes).
#[derive(Clone, Debug)]
pub struct Aligned {
    pub width: usize,
    pub height: usize,
    pub z: Vec<f32>,
    /// Median relative error of the aligned map at the still points kept by the fit.
    pub median_rel_error: f64,
    /// Still points the fit used.
    pub points: usize,
}

impl Aligned {
    /// The depth at camera pixel `p` (pixel centres at integers), bilinear over the four
    /// neighbours; `None` outside or next to a hole.
    pub fn at(&self, p: glam::DVec2) -> Option<f64> {
        let (x0, y0) = (p.x.floor(), p.y.floor());
        if x0 < 0.0 || y0 < 0.0 {
            return None;
        }
        let (x, y) = (x0 as usize, y0 as usize);
        if x + 1 >= self.width || y + 1 >= self.height {
            return None;
        }
        let (fx, fy) = (p.x - x0, p.y - y0);
        let g = |x: usize, y: usize| self.z[y * self.width + x] as f64;
        let q = [g(x, y), g(x + 1, y), g(x, y + 1), g(x + 1, y + 1)];
        if q.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return None;
        }
        Some((q[0] * (1.0 - fx) + q[1] * fx) * (1.0 - fy) + (q[2] * (1.0 - fx) + q[3] * fx) * fy)
    }
}

/// The prior's value as a linear function of what is fitted: `z` (affine) or `1/z`.
fn feature(kind: DepthKind, z: f64) -> f64 {
    match kind {
        DepthKind::InverseAffine => 1.0 / z,
        DepthKind::Z | DepthKind::Affine => z,
    }
}

/// `prior ≈ a · feature(z) + b`, least squares.
fn line(pairs: &[(f64, f64)]) -> Option<(f64, f64)> {
    let n = pairs.len() as f64;
    let (sx, sy) = pairs
        .iter()
        .fold((0.0, 0.0), |(a, b), &(x, y)| (a + x, b + y));
    let (mx, my) = (sx / n, sy / n);
    let (mut sxx, mut sxy) = (0.0, 0.0);
    for &(x, y) in pairs {
        sxx += (x - mx) * (x - mx);
        sxy += (x - mx) * (y - my);
    }
    let a = sxy / sxx;
    (sxx > 0.0 && a.is_finite() && a > 0.0).then_some((a, my - a * mx))
}

/// A start for the refits that outliers do not pull: the median slope of the pairs
/// `(i, i + n/2)` in order of `x`, and the median intercept at that slope (a
/// Theil–Sen estimator on n/2 pairs).
fn robust_line(pairs: &[(f64, f64)]) -> Option<(f64, f64)> {
    let mut p = pairs.to_vec();
    p.sort_by(|a, b| a.0.total_cmp(&b.0));
    let h = p.len() / 2;
    let slopes: Vec<f64> = (0..h)
        .filter(|&i| p[i + h].0 > p[i].0)
        .map(|i| (p[i + h].1 - p[i].1) / (p[i + h].0 - p[i].0))
        .collect();
    let a = median(slopes);
    let b = median(p.iter().map(|&(x, y)| y - a * x).collect());
    (a.is_finite() && a > 0.0 && b.is_finite()).then_some((a, b))
}

/// The median of `v` (NaN when empty).
pub(super) fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let k = v.len() / 2;
    *v.select_nth_unstable_by(k, f64::total_cmp).1
}

/// Pairs of (camera pixel, depth) of the `points` (world, believed still: the stereo
/// init's) that `camera` sees: each point projected, and kept where no other point lies
/// more than `tolerance` (relative) nearer within a pixel of it, so that a surface
/// hidden in this frame does not count as seen (a point z-buffer over 3×3 pixels).
pub fn visible_points(
    points: &[[f32; 3]],
    camera: &scene::Camera,
    tolerance: f64,
) -> Vec<(glam::DVec2, f64)> {
    let k = &camera.intrinsics;
    let (w, h) = (k.width as usize, k.height as usize);
    let projected: Vec<(glam::DVec2, f64)> = (points.iter())
        .filter_map(|p| camera.project_world(glam::Vec3::from(*p).as_dvec3()))
        .filter(|(px, z)| {
            *z > 0.0
                && px.x >= -0.5
                && px.y >= -0.5
                && px.x < w as f64 - 0.5
                && px.y < h as f64 - 0.5
        })
        .collect();
    let cell =
        |p: glam::DVec2| (p.x.round() as usize).min(w - 1) + w * (p.y.round() as usize).min(h - 1);
    let mut nearest = vec![f64::INFINITY; w * h];
    for &(p, z) in &projected {
        let c = cell(p);
        nearest[c] = nearest[c].min(z);
    }
    (projected.into_iter())
        .filter(|&(p, z)| {
            let (x, y) = (cell(p) % w, cell(p) / w);
            let front = (y.saturating_sub(1)..(y + 2).min(h))
                .flat_map(|yy| (x.saturating_sub(1)..(x + 2).min(w)).map(move |xx| (xx, yy)))
                .map(|(xx, yy)| nearest[yy * w + xx])
                .fold(f64::INFINITY, f64::min);
            z <= front * (1.0 + tolerance)
        })
        .collect()
}

/// Align one frame's `map` (`width × height`, of `kind`) to `refs`, pairs of (camera
/// pixel, true depth) of still points seen in the frame. `None` with fewer than 8 usable
/// pairs or no line with a positive slope.
pub fn align(
    kind: DepthKind,
    map: &[f32],
    width: usize,
    height: usize,
    refs: &[(glam::DVec2, f64)],
) -> Option<Aligned> {
    let raw = Aligned {
        width,
        height,
        z: map.to_vec(),
        median_rel_error: 0.0,
        points: 0,
    };
    // (prior at the pixel, true depth)
    let samples: Vec<(f64, f64)> = refs
        .iter()
        .filter(|(_, z)| z.is_finite() && *z > 0.0)
        .filter_map(|&(p, z)| raw.at(p).map(|v| (v, z)))
        .collect();
    if samples.len() < 8 {
        return None;
    }
    let to_z = |v: f64, (a, b): (f64, f64)| -> f64 {
        match kind {
            DepthKind::Z => v,
            DepthKind::Affine => (v - b) / a,
            DepthKind::InverseAffine => a / (v - b),
        }
    };
    let fit = |keep: &dyn Fn(&(f64, f64)) -> bool| -> Option<(f64, f64)> {
        let pairs: Vec<(f64, f64)> = (samples.iter().filter(|s| keep(s)))
            .map(|&(v, z)| (feature(kind, z), v))
            .collect();
        match kind {
            DepthKind::Z => Some((1.0, 0.0)),
            _ if pairs.len() < 8 => None,
            _ => line(&pairs),
        }
    };
    let rel = |ab: (f64, f64), &(v, z): &(f64, f64)| (to_z(v, ab) - z).abs() / z;
    // Residuals in the prior's own units, where the model is a line (in depth a wrong
    // line's `a / (v − b)` can blow up and hide which pairs are wrong).
    let res = |(a, b): (f64, f64), &(v, z): &(f64, f64)| (v - (a * feature(kind, z) + b)).abs();
    // Refit without the pairs beyond three median deviations of the current line's
    // residuals until the line stops changing (the first one leans toward outliers).
    let mut ab = match kind {
        DepthKind::Z => (1.0, 0.0),
        _ => robust_line(
            &samples
                .iter()
                .map(|&(v, z)| (feature(kind, z), v))
                .collect::<Vec<_>>(),
        )?,
    };
    let mut cut = f64::INFINITY;
    for _ in 0..10 {
        let r: Vec<f64> = samples.iter().map(|s| res(ab, s)).collect();
        let m = median(r.clone());
        let mad = median(r.iter().map(|e| (e - m).abs()).collect());
        // A floor relative to the prior's spread: exact data has MAD 0.
        let spread = samples.iter().map(|s| s.0.abs()).fold(0.0, f64::max);
        cut = m + 3.0 * mad.max(1e-4 * spread);
        let next = fit(&|s| res(ab, s) <= cut)?;
        let same = (next.0 - ab.0).abs() <= 1e-12 * ab.0.abs()
            && (next.1 - ab.1).abs() <= 1e-12 * (1.0 + ab.1.abs());
        ab = next;
        if same {
            break;
        }
    }
    let second = ab;
    let kept: Vec<f64> = (samples.iter())
        .filter(|s| res(second, s) <= cut)
        .map(|s| rel(second, s))
        .collect();
    let z = map
        .iter()
        .map(|&v| {
            let z = to_z(v as f64, second);
            if v.is_finite() && z.is_finite() && z > 0.0 {
                z as f32
            } else {
                0.0
            }
        })
        .collect();
    Some(Aligned {
        width,
        height,
        z,
        points: kept.len(),
        median_rel_error: median(kept),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec2;

    /// A tilted plane's depth, as a prior of each kind, with a known affine per kind and
    /// a fifth of the reference pairs wrong (a moving object): the aligned map is the
    /// plane's depth to float precision.
    #[test]
    fn each_kind_is_aligned_back_to_the_true_depth_despite_outliers() {
        let (w, h) = (40usize, 30usize);
        let depth = |x: usize, y: usize| 2.0 + 0.05 * x as f64 + 0.03 * y as f64;
        let refs: Vec<(DVec2, f64)> = (0..200)
            .map(|i| {
                let (x, y) = (3 + (i * 7) % 33, 2 + (i * 11) % 25);
                let z = depth(x, y);
                // Every fifth pair says the point is 40 % nearer.
                (
                    DVec2::new(x as f64, y as f64),
                    if i % 5 == 0 { 0.6 * z } else { z },
                )
            })
            .collect();
        for (kind, (a, b)) in [
            (DepthKind::Z, (1.0, 0.0)),
            (DepthKind::Affine, (0.37, -0.5)),
            (DepthKind::InverseAffine, (12.0, 0.8)),
        ] {
            let map: Vec<f32> = (0..w * h)
                .map(|i| {
                    let z = depth(i % w, i / w);
                    (a * feature(kind, z) + b) as f32
                })
                .collect();
            let al = align(kind, &map, w, h, &refs).expect("aligned");
            assert_eq!(al.points, 160, "{kind:?}: the wrong fifth dropped");
            for (i, &z) in al.z.iter().enumerate() {
                let t = depth(i % w, i / w);
                assert!(
                    (z as f64 - t).abs() < 1e-4 * t,
                    "{kind:?} at {i}: {z} vs {t}"
                );
            }
            let p = DVec2::new(10.25, 7.5);
            let want = 2.0 + 0.05 * 10.25 + 0.03 * 7.5;
            assert!((al.at(p).unwrap() - want).abs() < 1e-4, "bilinear {kind:?}");
        }
    }

    /// A wall at depth 8 behind a board at depth 4 over the left half of the image,
    /// both sampled densely in the world: every board point is seen, the wall's only
    /// away from the board (a pixel of margin), and each kept pair is the projection.
    #[test]
    fn points_hidden_behind_a_nearer_surface_are_not_seen() {
        use glam::DVec3;
        let camera = scene::Camera {
            intrinsics: scene::Intrinsics {
                width: 32,
                height: 24,
                fx: 20.0,
                fy: 20.0,
                cx: 15.5,
                cy: 11.5,
                distortion: None,
            },
            cam_to_world: scene::Pose::look_at(DVec3::ZERO, -DVec3::Z, DVec3::Y),
        };
        // World x of image column u at depth z: (u − cx)·z/fx; columns 0..16 for the board.
        let plane = |z: f64, u0: f64, u1: f64| -> Vec<[f32; 3]> {
            let mut out = Vec::new();
            for i in 0..=4 * (u1 - u0) as usize {
                for j in 0..=4 * 24 {
                    let u = u0 + 0.25 * i as f64;
                    let v = -0.5 + 0.25 * j as f64;
                    let x = (u - 15.5) * z / 20.0;
                    let y = -(v - 11.5) * z / 20.0;
                    out.push([x as f32, y as f32, -z as f32]);
                }
            }
            out
        };
        let board = plane(4.0, -0.5, 15.5);
        let wall = plane(8.0, -0.5, 31.0);
        let points: Vec<[f32; 3]> = board.iter().chain(&wall).copied().collect();
        let seen = visible_points(&points, &camera, 0.05);
        let near: Vec<_> = seen
            .iter()
            .filter(|(_, z)| (*z - 4.0).abs() < 1e-4)
            .collect();
        let far: Vec<_> = seen
            .iter()
            .filter(|(_, z)| (*z - 8.0).abs() < 1e-4)
            .collect();
        let inside = |p: &DVec2| p.x > -0.5 && p.y > -0.5 && p.x < 31.5 && p.y < 23.5;
        let board_inside = board.iter().filter(|b| {
            let x = glam::Vec3::from(**b).as_dvec3();
            camera.project_world(x).is_some_and(|(p, _)| inside(&p))
        });
        assert_eq!(
            near.len(),
            board_inside.count(),
            "every board point is seen"
        );
        assert_eq!(near.len() + far.len(), seen.len());
        assert!(
            far.iter().all(|(p, _)| p.x > 15.5),
            "a wall point behind the board"
        );
        let open = (wall.iter())
            .filter_map(|w| camera.project_world(glam::Vec3::from(*w).as_dvec3()))
            .filter(|(p, _)| p.x > 17.5 && inside(p))
            .count();
        let far_open = far.iter().filter(|(p, _)| p.x > 17.5).count();
        assert_eq!(far_open, open, "the open wall is seen");
        assert!(open > 1000, "{open}");
    }

    #[test]
    fn too_few_pairs_or_holes_give_no_alignment() {
        let map = vec![1.0f32; 100];
        let refs = vec![(DVec2::new(3.0, 3.0), 2.0); 5];
        assert!(align(DepthKind::Affine, &map, 10, 10, &refs).is_none());
        let holes = vec![0.0f32; 100];
        let refs = vec![(DVec2::new(3.0, 3.0), 2.0); 50];
        assert!(align(DepthKind::Z, &holes, 10, 10, &refs).is_none());
    }
}
