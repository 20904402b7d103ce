//! How the warm-up's sizing (`sizing.rs`) scores a candidate model: renders of it at
//! every train view against the frames.

use super::View;
use crate::Rasterizer;
use crate::field::{self, Deltas, Mlp};
use crate::motion::{at_time, with_trajectories};
use crate::splats::Splats;
use scene::metrics;
use std::borrow::Cow;

/// The model as the sizing renders it.
#[derive(Clone, Copy)]
pub struct Candidate<'a> {
    pub splats: &'a Splats,
    pub field: Option<&'a Mlp<f32>>,
    pub dynamic_only: bool,
    pub sh_degree: u32,
    /// The field's deltas of `splats` at each view, in view order, when already known
    /// (used instead of evaluating `field`): the field moves every Gaussian on its own,
    /// so candidates that differ only in SH degree or in which Gaussians they keep
    /// share one evaluation per view ([`posed_deltas`], [`gather_deltas`]).
    pub deltas: Option<&'a [Deltas]>,
}

/// The field's deltas of the candidate's Gaussians at every view (None without a
/// field).
pub fn posed_deltas(c: &Candidate, views: &[View]) -> Option<Vec<Deltas>> {
    let f = c.field?;
    Some(
        views
            .iter()
            .map(|v| field::splat_deltas(f, c.splats, v.time, c.dynamic_only).0)
            .collect(),
    )
}

/// The deltas of the Gaussians `keep` (indices) at every view.
pub fn gather_deltas(per_view: &[Deltas], keep: &[usize]) -> Vec<Deltas> {
    per_view
        .iter()
        .map(|d| {
            let mut out = Deltas::default();
            for &i in keep {
                out.push_one(d, i);
            }
            out
        })
        .collect()
}

/// Renders candidates at the train views.
pub struct Judge<'a, R> {
    pub r: &'a R,
    pub views: &'a [View],
    pub background: [f32; 3],
    /// Passes over the views so far.
    pub evaluations: usize,
}

impl<'a, R> Judge<'a, R> {
    /// A judge of renders by `r` on `background` at `views`, no pass made yet.
    pub fn new(r: &'a R, views: &'a [View], background: [f32; 3]) -> Self {
        Judge {
            r,
            views,
            background,
            evaluations: 0,
        }
    }
}

/// At most `n` of `views` spread evenly over them, first and last included (all of
/// them when `n` is 0 or no smaller than their count).
pub(crate) fn spread(views: &[View], n: usize) -> Cow<'_, [View]> {
    if n == 0 || n >= views.len() {
        return Cow::Borrowed(views);
    }
    let last = views.len() - 1;
    let pick = |k: usize| match n {
        1 => last / 2,
        _ => (k * last + (n - 1) / 2) / (n - 1),
    };
    Cow::Owned((0..n).map(|k| views[pick(k)].clone()).collect())
}

/// The middle of the views' time span (0 without views).
pub(crate) fn middle_time(views: &[View]) -> f32 {
    let lo = views.iter().map(|v| v.time).fold(f32::INFINITY, f32::min);
    let hi = views
        .iter()
        .map(|v| v.time)
        .fold(f32::NEG_INFINITY, f32::max);
    if lo <= hi { 0.5 * (lo + hi) } else { 0.0 }
}

/// PSNR above this (identical 8-bit images) counts as this, as the stage reports it.
const PSNR_CAP: f64 = 100.0;

/// The candidate's Gaussians at view `k` (at time `t`).
fn posed<'s>(c: &Candidate<'s>, k: usize, t: f32) -> Cow<'s, Splats> {
    match c.deltas {
        Some(d) => with_trajectories(
            c.splats,
            t,
            Cow::Owned(field::deform_splats(c.splats, &d[k])),
        ),
        None => at_time(c.splats, c.field, c.dynamic_only, t),
    }
}

impl<R: Rasterizer> Judge<'_, R> {
    /// Mean PSNR (8-bit, capped) of the candidate's renders against the train views.
    pub fn psnr(&mut self, c: &Candidate) -> f64 {
        self.evaluations += 1;
        let sum: f64 = self
            .views
            .iter()
            .enumerate()
            .map(|(k, v)| {
                let s = posed(c, k, v.time);
                let (img, _) = self.r.render(&s, &v.camera, c.sh_degree, self.background);
                metrics::psnr_u8(&img.rgb, &v.rgb).min(PSNR_CAP)
            })
            .sum();
        sum / self.views.len().max(1) as f64
    }

    /// Fraction of the views' pixels where `b` is visibly worse than `a`: its largest
    /// channel error exceeds `a`'s by more than `by`.
    pub(crate) fn worse_fraction(&mut self, a: &Candidate, b: &Candidate, by: f32) -> f64 {
        self.evaluations += 2;
        let (mut worse, mut pixels) = (0usize, 0usize);
        for (k, v) in self.views.iter().enumerate() {
            let render = |c: &Candidate| {
                let s = posed(c, k, v.time);
                self.r.render(&s, &v.camera, c.sh_degree, self.background).0
            };
            let (ia, ib) = (render(a), render(b));
            // planar 3×H×W, as rendered
            let n = v.rgb.len() / 3;
            let err = |img: &[f32], px: usize| {
                (0..3).fold(0f32, |m, k| {
                    m.max((img[k * n + px] - v.rgb[k * n + px]).abs())
                })
            };
            worse += (0..n)
                .filter(|&px| err(&ib.rgb, px) > err(&ia.rgb, px) + by)
                .count();
            pixels += n;
        }
        worse as f64 / pixels.max(1) as f64
    }

    /// Each Gaussian's blending weight summed over the views (None when the rasterizer
    /// cannot give them).
    pub fn contributions(&mut self, c: &Candidate) -> Option<Vec<f64>> {
        self.evaluations += 1;
        let mut acc = vec![0.0; c.splats.len()];
        for (k, v) in self.views.iter().enumerate() {
            let s = posed(c, k, v.time);
            if !self.r.add_contributions(&s, &v.camera, &mut acc) {
                return None;
            }
        }
        Some(acc)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use scene::Camera;
    use scene::camera::{Intrinsics, Pose};

    #[test]
    fn spread_picks_evenly_with_both_ends() {
        let camera = Camera {
            intrinsics: Intrinsics::from_fov_x(8, 8, 1.0),
            cam_to_world: Pose::default(),
        };
        for len in [1usize, 2, 9, 21, 61, 100] {
            let views: Vec<View> = (0..len)
                .map(|i| View {
                    camera,
                    time: i as f32,
                    rgb: Vec::new(),
                })
                .collect();
            for n in [1usize, 2, 3, 16, 61, 200] {
                let picked: Vec<usize> =
                    spread(&views, n).iter().map(|v| v.time as usize).collect();
                assert_eq!(picked.len(), n.min(len), "{n} of {len}");
                if n >= len {
                    continue;
                }
                let gaps: Vec<usize> = picked.windows(2).map(|w| w[1] - w[0]).collect();
                assert!(gaps.iter().all(|&g| g >= 1), "{picked:?}");
                if n >= 2 {
                    assert_eq!((picked[0], picked[n - 1]), (0, len - 1), "{picked:?}");
                    let (lo, hi) = (gaps.iter().min().unwrap(), gaps.iter().max().unwrap());
                    assert!(hi - lo <= 1, "uneven: {picked:?}");
                }
            }
            assert_eq!(spread(&views, 0).len(), len);
        }
    }
}
