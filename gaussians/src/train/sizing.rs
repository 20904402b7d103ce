//! Right-sizing the model once during the warm-up (issue #17: a model no bigger than
//! its scene needs): at one iteration (by default the end of densification) the train
//! views decide, in this order, whether the model keeps its deformation field, its SH
//! degree and each Gaussian. Every decision must keep the mean train-view PSNR within
//! `tolerance_db` of the model before sizing (one budget for all three, so the sized
//! model is at most `tolerance_db` below it; a still scene's field excepted); the
//! iterations after sizing fine-tune the smaller model.
//!
//! - **field**: the scene is *still* when the field moves at most one Gaussian in a
//!   thousand by more than `still_px` from where it puts it at the middle of the
//!   recording (a field trained on the views of a still scene fits each view on its
//!   own by fractions of a pixel, which the train views reward but no other view
//!   does); a still scene loses its field whatever that costs on the train views, and
//!   the rest of the budget counts from the frozen model below. Otherwise the model
//!   frozen at the middle of the recording (the field's
//!   deformation at that time baked into the Gaussians) is rendered at every train
//!   view; within tolerance, it replaces the canonical Gaussians and the field is
//!   dropped (a static scene ends with none). Frozen, not simply without the field: a
//!   trained field also holds a part that does not change with time (a shift the
//!   canonical Gaussians were trained beside), which the scene does need.
//! - **SH degree**: the lowest degree ≤ the one in use whose renders stay within
//!   tolerance becomes the model's degree for good, its coefficients refitted to the
//!   colours the train cameras see (`sh_refit.rs`; the higher ones zeroed; the degree
//!   no longer grows: a degree the sizing did not see is not taken).
//! - **Gaussians**: each Gaussian's blending weight `Σ α·T` summed over the train views
//!   ranks them; a binary search on the count finds the fewest most-contributing
//!   Gaussians whose renders stay within tolerance, and the rest are dropped.
//!
//! The field's width is not chosen here (the train views always prefer the widest
//! field); `field_probe.rs` can choose it at the field's switch from views held out of
//! training (opt-in, `field_probe`).

use super::judge::{Candidate, Judge, gather_deltas, middle_time, posed_deltas};
use super::sh_refit::refit_sh;
use super::static_split;
use crate::Rasterizer;
use crate::densify::GradStats;
use crate::motion::at_time;
use crate::optim::Adam;
use crate::raster::sh::num_coeffs;
use crate::splats::Splats;
use serde::{Deserialize, Serialize};

/// Settings of the sizing (`[size]` in the warm-up's settings).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SizeSettings {
    /// Train-view PSNR (dB) the sizing may give up, all decisions together (0 = no
    /// sizing: the fixed sizes of the other settings).
    pub tolerance_db: f64,
    /// Iteration of the sizing (0 = the end of densification, `densify.until_iter`, or
    /// the last iteration when the run ends before it). Sizing before the end of
    /// densification caps the count there at the sized count.
    pub at: u32,
    /// Drop the deformation field when the train views do not need it.
    pub drop_field: bool,
    /// A still scene: when the field moves at most one Gaussian in a thousand by more
    /// than this many pixels of the train views (centre, from where it puts it at the
    /// middle of the recording), the field goes whatever it is worth on the train views
    /// (0 = only the PSNR test).
    pub still_px: f32,
    /// …and when the model without its field is visibly worse on at most one train
    /// pixel in two thousand (`STILL_WORSE_FRACTION`): its largest channel error grows
    /// by more than this (display value, 0–1). Centre motion alone misses a field that
    /// hides and shows Gaussians (by their scale) instead of moving them, as an RGB-only
    /// warm-up does at a low frame rate (`fast` 64² at 4 fps: 99.9 % of the Gaussians
    /// moved less than 0.8 px, yet without the field 0.66 % of the train pixels were
    /// worse by more than 0.2; on `static` 128², 0.009 %: BENCHMARKS.md).
    pub still_visible: f32,
    /// Static/dynamic split of a scene that keeps its field: Gaussians the field moves
    /// by at most a tolerance (pixels, as `still_px`) are baked at the middle of the
    /// recording and skip the field; the largest of this, its half, quarter and eighth
    /// whose split stays within the budget is taken (0 = no split here).
    pub split_max_px: f32,
    /// Lower the SH degree to what the train views need.
    pub sh_degree: bool,
    /// Prune Gaussians by contribution.
    pub prune: bool,
    /// The field's width probe (`field_probe.rs`): iterations each candidate width trains
    /// from the field's switch on the train views less every fourth (0 = no probe: the
    /// width is `field.width`). Off by default, and not a recommendation: it favours the
    /// narrower field, which learns faster early; on the 9-frame presets it chose wrongly
    /// on one `nonrigid` seed in two (−0.4 dB), with 25 train frames on every scene tried
    /// (−0.8 to −1.2 dB; BENCHMARKS.md).
    pub field_probe: u32,
    /// Candidate widths: `field.width` and this many halvings of it (none below 8).
    pub field_halvings: u32,
    /// Train views the sizing renders each candidate at: this many, spread evenly over
    /// the recording (first and last included), or every view when there are no more
    /// (0 = every view). Its ~30 passes over 61 views of 346×260 took 183 s, a sixth of
    /// that warm-up; 16 views hold the figures of a scene whose frames are close in time
    /// (BENCHMARKS.md, "Sensor-size recordings").
    pub views: usize,
}

impl Default for SizeSettings {
    fn default() -> Self {
        SizeSettings {
            tolerance_db: 0.1,
            at: 0,
            drop_field: true,
            still_px: 1.0,
            still_visible: 0.2,
            split_max_px: 2.0,
            sh_degree: true,
            prune: true,
            field_probe: 0,
            field_halvings: 1,
            views: 16,
        }
    }
}

impl SizeSettings {
    pub fn validate(&self) -> Result<(), String> {
        if !(self.tolerance_db.is_finite() && self.tolerance_db >= 0.0) {
            return Err("size.tolerance_db must be finite and ≥ 0 (0: no sizing)".into());
        }
        if !(self.still_px.is_finite() && self.still_px >= 0.0) {
            return Err("size.still_px must be finite and ≥ 0 (0: no still test)".into());
        }
        if !(self.still_visible.is_finite() && self.still_visible >= 0.0) {
            return Err("size.still_visible must be finite and ≥ 0".into());
        }
        if !(self.split_max_px.is_finite() && self.split_max_px >= 0.0) {
            return Err("size.split_max_px must be finite and ≥ 0 (0: no split)".into());
        }
        Ok(())
    }
}

/// The largest fraction of train pixels the model without its field may render
/// visibly worse (`SizeSettings::still_visible`) for the scene to count as still.
pub const STILL_WORSE_FRACTION: f64 = 5e-4;

/// What the sizing decided (for `report.json`).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SizingSummary {
    pub iteration: u32,
    pub tolerance_db: f64,
    /// Mean train-view PSNR before sizing, and of the sized model.
    pub train_psnr_before: f64,
    pub train_psnr_after: f64,
    /// Mean train-view PSNR without the field (absent: the model had none, or the
    /// field was not tested).
    pub train_psnr_without_field: Option<f64>,
    pub field_dropped: bool,
    /// Quantiles 0.5, 0.99, 0.999 and 1 of the field's motion of each Gaussian (pixels;
    /// see `still_px`), and whether that made the scene still (absent: not measured).
    pub field_motion_px_quantiles: Option<[f32; 4]>,
    /// Fraction of the train pixels the model without its field renders visibly worse
    /// (see `still_visible`; absent: not measured).
    pub visibly_worse_without_field: Option<f64>,
    pub still: bool,
    /// The static/dynamic split made (absent: none).
    pub split: Option<SplitChoice>,
    pub sh_degree_before: u32,
    pub sh_degree: u32,
    /// Mean train-view PSNR at SH degree 0, 1, … (those tested; each refitted).
    pub train_psnr_by_sh_degree: Vec<f64>,
    pub gaussians_before: usize,
    pub gaussians: usize,
    /// The Gaussian cap of the settings before the sizing made `gaussians` the cap
    /// (the per-pixel cap resolved, or the absolute `densify.max_gaussians` given).
    pub gaussian_cap_before: usize,
    /// Gaussians with no weight in any train view (dropped at no cost).
    pub gaussians_without_weight: usize,
    /// Train views each pass rendered (`SizeSettings::views`), passes over them the
    /// sizing took, and its wall seconds.
    pub views: usize,
    pub evaluations: usize,
    pub seconds: f64,
}

/// The static/dynamic split the sizing made.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct SplitChoice {
    pub tolerance_px: f32,
    pub dynamic: usize,
    pub static_: usize,
    /// Mean train-view PSNR of the split model.
    pub train_psnr: f64,
}

/// Tolerances tried for the split: `split_max_px`, its half, quarter, eighth.
const SPLIT_STEPS: u32 = 4;

/// The lowest SH degree below `current` whose PSNR reaches `target` (`current` when
/// none does), with the PSNR of each degree tested.
pub(crate) fn choose_sh_degree(
    mut psnr_at: impl FnMut(u32) -> f64,
    current: u32,
    target: f64,
) -> (u32, Vec<f64>) {
    let mut tried = Vec::new();
    for d in 0..current {
        let p = psnr_at(d);
        tried.push(p);
        if p >= target {
            return (d, tried);
        }
    }
    (current, tried)
}

/// Indices (ascending) of the `k` Gaussians of largest weight; ties keep the lower
/// index.
pub fn top_k(weights: &[f64], k: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..weights.len()).collect();
    order.sort_by(|&a, &b| weights[b].total_cmp(&weights[a]).then(a.cmp(&b)));
    order.truncate(k);
    order.sort_unstable();
    order
}

/// The smallest count `k` in `1..=n` for which `ok(k)` holds, by binary search between
/// 0 (taken as failing) and `hi` (taken as passing when `ok(hi)`; else `n` is returned
/// untested). Assumes `ok` monotone; where it is not, the result still passes `ok` or is
/// `n`.
pub(crate) fn smallest_count(n: usize, hi: usize, mut ok: impl FnMut(usize) -> bool) -> usize {
    let hi = hi.clamp(1, n.max(1));
    // At `hi = n` the model itself passes by definition.
    if hi < n && !ok(hi) {
        return n;
    }
    let (mut lo, mut hi) = (0, hi);
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if ok(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi
}

/// Gather the Gaussians `keep` (ascending indices) of `s`, flags included.
pub fn gather(s: &Splats, keep: &[usize]) -> Splats {
    let g = |i: &usize| *i;
    Splats {
        means: keep.iter().map(g).map(|i| s.means[i]).collect(),
        log_scales: keep.iter().map(g).map(|i| s.log_scales[i]).collect(),
        rotations: keep.iter().map(g).map(|i| s.rotations[i]).collect(),
        opacity_logits: keep.iter().map(g).map(|i| s.opacity_logits[i]).collect(),
        sh_dc: keep.iter().map(g).map(|i| s.sh_dc[i]).collect(),
        sh_rest: keep.iter().map(g).map(|i| s.sh_rest[i]).collect(),
        dynamic: if s.dynamic.len() == s.len() {
            keep.iter().map(|&i| s.dynamic[i]).collect()
        } else {
            Vec::new()
        },
        motion: if s.motion.len() == s.len() {
            keep.iter().map(|&i| s.motion[i]).collect()
        } else {
            Vec::new()
        },
        track: if s.track.len() == s.len() {
            keep.iter().map(|&i| s.track[i]).collect()
        } else {
            Vec::new()
        },
        life: if s.life.len() == s.len() {
            keep.iter().map(|&i| s.life[i]).collect()
        } else {
            Vec::new()
        },
        part: if s.part.len() == s.len() {
            keep.iter().map(|&i| s.part[i]).collect()
        } else {
            Vec::new()
        },
        parts: s.parts.clone(),
    }
}

/// Zero the SH coefficients above `degree` (in `sh_rest`, coefficient-major).
pub(crate) fn truncate_sh(sh_rest: &mut [[f32; 45]], degree: u32) {
    let keep = 3 * (num_coeffs(degree) - 1);
    for r in sh_rest {
        r[keep..].fill(0.0);
    }
}

/// The iteration of the sizing (`None`: no sizing in this run): `size.at`, or with 0 the
/// end of densification (`densify_until`) or of the run (`iterations`), the earlier.
pub fn iteration(size: &SizeSettings, densify_until: u32, iterations: u32) -> Option<u32> {
    if size.tolerance_db <= 0.0 {
        return None;
    }
    Some(match size.at {
        0 => densify_until.min(iterations),
        at => at,
    })
}

/// What the sizing decided ([`decide`]), made on the trainer's state by
/// [`Decision::apply`].
pub struct Decision {
    /// What was measured and decided; the trainer adds the iteration, the cap before and
    /// the sized model's figures.
    pub summary: SizingSummary,
    /// The SH degree from now on (`None`: the degree was not sized).
    pub sh_degree: Option<u32>,
    /// Canonical Gaussians in place of the model's: frozen (without the field) or split
    /// (the field on its dynamic ones).
    model: Option<Splats>,
    /// Whether the model keeps its field.
    field: bool,
    /// The colours refitted to `sh_degree` (indexed as the model before `keep`), when the
    /// degree was lowered.
    refit: Option<Splats>,
    /// The Gaussians kept (ascending indices; `None`: all).
    keep: Option<Vec<usize>>,
}

/// Size `model` (module docs): the trainer's model as it renders now (its field only
/// while on, no deltas), scored by `judge` at the train views; `field_trained`: the field
/// has trained since its switch (a field switched on this very iteration is still the
/// identity: nothing to learn from it).
pub fn decide<R: Rasterizer>(
    judge: &mut Judge<R>,
    model: Candidate,
    size: &SizeSettings,
    field_trained: bool,
) -> Decision {
    let views = judge.views;
    let Candidate {
        splats,
        field,
        dynamic_only,
        sh_degree: sh_before,
        ..
    } = model;
    let had_field = field.is_some();
    // The model frozen at the middle of the recording: the field's deformation at
    // that time baked into the Gaussians.
    let wanted = size.drop_field || size.split_max_px > 0.0;
    let frozen = (wanted && field.is_some() && field_trained)
        .then(|| at_time(splats, field, dynamic_only, middle_time(views)).into_owned());
    let mut c = Candidate {
        deltas: None,
        ..model
    };
    let before = judge.psnr(&c);
    let mut target = before - size.tolerance_db;
    let mut sum = SizingSummary {
        tolerance_db: size.tolerance_db,
        train_psnr_before: before,
        sh_degree_before: sh_before,
        sh_degree: sh_before,
        gaussians_before: splats.len(),
        ..SizingSummary::default()
    };
    let mut split_model = None;
    if let (Some(f), Some(mlp)) = (&frozen, field) {
        let frozen_c = Candidate {
            splats: f,
            field: None,
            ..c
        };
        let p = judge.psnr(&frozen_c);
        sum.train_psnr_without_field = Some(p);
        let cams: Vec<_> = views.iter().map(|v| v.camera).collect();
        let times: Vec<f32> = views.iter().map(|v| v.time).collect();
        let times = static_split::sample_times(&times);
        let mid = middle_time(views);
        let motion = static_split::centre_motion_px(mlp, splats, dynamic_only, &cams, &times, mid);
        sum.field_motion_px_quantiles =
            Some(static_split::quantiles(&motion, [0.5, 0.99, 0.999, 1.0]));
        let mut motion = motion;
        static_split::keep_colour_changes_dynamic(
            mlp,
            splats,
            dynamic_only,
            &times,
            mid,
            &mut motion,
        );
        if size.still_px > 0.0 {
            let moving = motion.iter().filter(|&&m| m > size.still_px).count();
            let worse = judge.worse_fraction(&c, &frozen_c, size.still_visible);
            sum.visibly_worse_without_field = Some(worse);
            sum.still = moving * 1000 <= motion.len() && worse <= STILL_WORSE_FRACTION;
        }
        if size.drop_field && (sum.still || p >= target) {
            c = frozen_c;
            sum.field_dropped = true;
            // The rest of the budget counts from the frozen model when a still
            // scene's field went below it.
            target = target.min(p - size.tolerance_db);
        } else if size.split_max_px > 0.0 {
            // The largest tolerance whose split stays within the budget.
            for k in 0..SPLIT_STEPS {
                let tolerance_px = size.split_max_px / (1 << k) as f32;
                let model = static_split::split(splats, f, &motion, tolerance_px);
                let p = judge.psnr(&Candidate {
                    splats: &model,
                    dynamic_only: true,
                    ..c
                });
                if p >= target {
                    let dynamic = model.dynamic.iter().filter(|&&d| d).count();
                    sum.split = Some(SplitChoice {
                        tolerance_px,
                        dynamic,
                        static_: model.len() - dynamic,
                        train_psnr: p,
                    });
                    split_model = Some(model);
                    break;
                }
            }
        }
    }
    if let Some(m) = &split_model {
        c = Candidate {
            splats: m,
            dynamic_only: true,
            ..c
        };
    }
    // From here on the candidates keep the field's motion of each Gaussian they
    // keep: evaluate the field once per view.
    let posed = posed_deltas(&c, views);
    let mut c = Candidate {
        deltas: posed.as_deref(),
        ..c
    };
    // A lower degree is scored (and kept) refitted to the colours the train cameras
    // see, not truncated (`sh_refit.rs`).
    let mut refit = None;
    if size.sh_degree {
        let eyes: Vec<[f64; 3]> = views
            .iter()
            .map(|v| v.camera.cam_to_world.translation.to_array())
            .collect();
        let (d, tried) = choose_sh_degree(
            |d| {
                let r = refit_sh(c.splats, sh_before, d, &eyes);
                let p = judge.psnr(&Candidate {
                    splats: &r,
                    sh_degree: d,
                    ..c
                });
                refit = Some(r);
                p
            },
            sh_before,
            target,
        );
        if d == sh_before {
            refit = None;
        }
        (sum.sh_degree, sum.train_psnr_by_sh_degree) = (d, tried);
    }
    if let Some(r) = &refit {
        c = Candidate {
            splats: r,
            sh_degree: sum.sh_degree,
            ..c
        };
    }
    let mut keep = None;
    let weights = if size.prune {
        judge.contributions(&c)
    } else {
        None
    };
    if let Some(w) = weights {
        let n = w.len();
        let weighed = w.iter().filter(|&&v| v > 0.0).count();
        sum.gaussians_without_weight = n - weighed;
        let k = smallest_count(n, weighed, |k| {
            let kept = top_k(&w, k);
            let sub = gather(c.splats, &kept);
            let deltas = c.deltas.map(|d| gather_deltas(d, &kept));
            judge.psnr(&Candidate {
                splats: &sub,
                deltas: deltas.as_deref(),
                ..c
            }) >= target
        });
        keep = (k < n).then(|| top_k(&w, k));
    }
    let sh = size.sh_degree.then_some(c.sh_degree);
    let field_kept = had_field && !sum.field_dropped;
    let canonical = match frozen.filter(|_| sum.field_dropped) {
        Some(f) => Some(f),
        None => split_model,
    };
    Decision {
        summary: sum,
        sh_degree: sh,
        model: canonical,
        field: field_kept,
        refit,
        keep,
    }
}

impl Decision {
    /// The Gaussian count when the sizing dropped some (the cap from then on: densification
    /// may still move Gaussians where they are needed, not add to them).
    pub fn kept(&self) -> Option<usize> {
        self.keep.as_ref().map(Vec::len)
    }

    /// Make the decisions on the trainer's Gaussians, their Adam moments (groups in the
    /// trainer's order: 5 is `sh_rest`) and densification statistics: the model in place
    /// of the canonical Gaussians, the SH degree (with the refitted colours), only the
    /// Gaussians kept. The settings that go with them (`deform`, `dynamic_only`,
    /// `sh_degree`, the cap) are the trainer's to change. Returns the summary.
    pub fn apply(
        self,
        splats: &mut Splats,
        adam: &mut Adam,
        stats: &mut GradStats,
    ) -> SizingSummary {
        if let Some(mut m) = self.model {
            if !self.field {
                m.dynamic.clear();
            }
            *splats = m;
        }
        if let Some(r) = self.refit {
            (splats.sh_dc, splats.sh_rest) = (r.sh_dc, r.sh_rest);
        }
        if let Some(sh) = self.sh_degree {
            truncate_sh(&mut splats.sh_rest, sh);
            // Adam's moments of the zeroed coefficients too (group 5: sh_rest).
            let g = &mut adam.groups[5];
            let from = 3 * (num_coeffs(sh) - 1);
            for item in 0..g.m.len() / g.width {
                let cols = item * g.width + from..(item + 1) * g.width;
                g.m[cols.clone()].fill(0.0);
                g.v[cols].fill(0.0);
            }
        }
        if let Some(keep) = &self.keep {
            *splats = gather(splats, keep);
            let src: Vec<Option<usize>> = keep.iter().map(|&i| Some(i)).collect();
            for k in 0..adam.groups.len() {
                adam.remap(k, &src);
            }
            *stats = GradStats::new(splats.len());
        }
        self.summary
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_search_finds_the_smallest_passing_count() {
        for need in 1..=40 {
            let mut calls = 0;
            let k = smallest_count(40, 30, |k| {
                calls += 1;
                k >= need
            });
            // Counts above `hi` are never needed when `hi` passes; else all are kept.
            assert_eq!(k, if need <= 30 { need } else { 40 }, "need {need}");
            assert!(calls <= 6, "{calls} evaluations");
        }
        assert_eq!(smallest_count(5, 5, |k| k >= 3), 3);
        assert_eq!(smallest_count(1, 0, |_| false), 1);
    }

    #[test]
    fn top_k_keeps_the_heaviest_in_file_order() {
        let w = [0.5, 3.0, 0.0, 3.0, 1.0];
        assert_eq!(top_k(&w, 2), vec![1, 3]);
        assert_eq!(top_k(&w, 3), vec![1, 3, 4]);
        assert_eq!(top_k(&w, 0), Vec::<usize>::new());
        let d = choose_sh_degree(|d| [30.0, 31.95, 32.0][d as usize], 3, 31.9);
        assert_eq!(d, (1, vec![30.0, 31.95]));
        assert_eq!(choose_sh_degree(|_| 0.0, 2, 1.0), (2, vec![0.0, 0.0]));
        let mut rest = [[1.0f32; 45]; 2];
        truncate_sh(&mut rest, 1);
        assert_eq!(rest[1][..9], [1.0; 9]);
        assert!(rest[1][9..].iter().all(|&v| v == 0.0));
    }
}
