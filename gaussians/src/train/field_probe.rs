//! The deformation field's width per scene (issue #17 item 1; DESIGN.md "Right-sizing"):
//! at the field's switch a short probe trains the model with each candidate width (the
//! configured one and its halvings) on the train views less a few held out, and keeps
//! the narrowest width whose held-out PSNR is within `size.tolerance_db` of the best; the
//! warm-up goes on from that candidate's probe, with every view again.
//!
//! The train views cannot choose the width: a wider field always fits them better, by
//! each Gaussian's own sub-pixel motion per view, whether or not the in-between times
//! gain from it (BENCHMARKS.md, "The field's width per scene"). Nor, measured, can a
//! short probe on held-out frames: after 200 iterations the two held-out frames of the
//! 9-frame presets scored 64 and 32 within 0.05 dB everywhere; after 600 they chose
//! against the test frames on one `nonrigid` seed of two (BENCHMARKS.md, "The field's
//! width chosen by held-out frames"); with 25 train frames (6 held out) it chose 32 on
//! every scene tried, where 64 tested 0.8–1.2 dB better ("The field's width probe with
//! 25 train frames"): early on the narrower field has learnt as much (it converges
//! faster), the wider one's lead comes later. So the probe is off by default
//! (`size.field_probe = 0`) and kept as an experiment's setting, not a recommendation.
//! It costs the losing candidates' iterations; a narrower field makes every later
//! iteration cheaper (the field's `gemm` is a third of a warm-up).

use super::View;
use super::settings::TrainSettings;
use serde::Serialize;

/// Hold out every this-many-th view (in time order) for the probe.
pub(crate) const HOLD_OUT_EVERY: usize = 4;
/// No probe with fewer train views than this (too few to spare any).
pub(crate) const MIN_VIEWS: usize = 8;
/// Narrowest field the probe tries.
pub(crate) const MIN_WIDTH: usize = 8;
/// No probe shorter than this many iterations (a field that has barely moved ranks
/// nothing).
pub(crate) const MIN_PROBE_ITERATIONS: u32 = 50;

/// What the probe measured and chose (for `report.json`).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FieldProbeSummary {
    /// Iteration of the field's switch, where the probe started.
    pub iteration: u32,
    /// Iterations each candidate trained.
    pub probe_iterations: u32,
    /// Indices of the held-out train views.
    pub held_out: Vec<usize>,
    /// Candidate widths, widest first, and the mean PSNR of each on the held-out views.
    pub widths: Vec<usize>,
    pub held_out_psnr: Vec<f64>,
    /// The width kept.
    pub width: usize,
    pub seconds: f64,
}

/// The views held out of the probe's training: in time order, positions 2, 2 + `every`,
/// 2 + 2·`every`, … short of the last (the first and last views in time stay in training,
/// so the probe judges in-between times, not extrapolation). Ascending indices; empty
/// when there are fewer than [`MIN_VIEWS`] views.
pub fn held_out_views(times: &[f32], every: usize) -> Vec<usize> {
    let n = times.len();
    if n < MIN_VIEWS || every < 2 {
        return Vec::new();
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| times[a].total_cmp(&times[b]).then(a.cmp(&b)));
    let mut out: Vec<usize> = (2..n - 1).step_by(every).map(|p| order[p]).collect();
    out.sort_unstable();
    out
}

/// Candidate widths: `width`, then halvings while at least [`MIN_WIDTH`], `halvings` of
/// them at most.
pub fn candidate_widths(width: usize, halvings: u32) -> Vec<usize> {
    let mut out = vec![width];
    let mut w = width;
    for _ in 0..halvings {
        w /= 2;
        if w < MIN_WIDTH {
            break;
        }
        out.push(w);
    }
    out
}

/// Index of the narrowest candidate whose score is within `tolerance_db` of the best
/// (`widths` widest first, as [`candidate_widths`]); NaN scores never win.
pub fn choose(widths: &[usize], psnr: &[f64], tolerance_db: f64) -> usize {
    let best = psnr
        .iter()
        .copied()
        .filter(|p| !p.is_nan())
        .fold(f64::NEG_INFINITY, f64::max);
    (0..widths.len())
        .filter(|&k| psnr[k] >= best - tolerance_db)
        .min_by_key(|&k| widths[k])
        .unwrap_or(0)
}

/// The probe's length from the field's switch in a run with settings `s`:
/// `size.field_probe`, cut short of the static/dynamic split (at `split`), the sizing (at
/// `sizing`) and the end of the run (`None`: no probe in this run).
pub fn iterations(s: &TrainSettings, split: Option<u32>, sizing: Option<u32>) -> Option<u32> {
    if !s.deform || s.size.tolerance_db <= 0.0 || s.size.field_probe == 0 {
        return None;
    }
    if candidate_widths(s.field.width, s.size.field_halvings).len() < 2 {
        return None;
    }
    let start = s.static_iterations;
    let limit = [split, sizing]
        .into_iter()
        .flatten()
        .fold(s.iterations, u32::min);
    let k = s.size.field_probe.min(limit.saturating_sub(start + 1));
    (k >= MIN_PROBE_ITERATIONS).then_some(k)
}

/// The probe (module docs) over `widths` (widest first, [`candidate_widths`]):
/// `train(width, train_views)` trains a copy of the model with a fresh field of that width
/// on the views less the held-out ones, `score(copy, held_out_views)` is its mean PSNR on
/// the others; the copy whose width [`choose`] keeps, and what the probe measured (its
/// `iteration` and `probe_iterations` left to the caller). `None`: too few views to hold
/// any out.
pub fn run<T>(
    views: &[View],
    widths: Vec<usize>,
    tolerance_db: f64,
    mut train: impl FnMut(usize, &[View]) -> T,
    mut score: impl FnMut(&T, &[View]) -> f64,
) -> Option<(T, FieldProbeSummary)> {
    let times: Vec<f32> = views.iter().map(|v| v.time).collect();
    let held_out = held_out_views(&times, HOLD_OUT_EVERY);
    if held_out.is_empty() {
        return None;
    }
    let start = std::time::Instant::now();
    let (train_views, held): (Vec<View>, Vec<View>) = {
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for (i, v) in views.iter().enumerate() {
            if held_out.binary_search(&i).is_ok() {
                b.push(v.clone());
            } else {
                a.push(v.clone());
            }
        }
        (a, b)
    };
    let mut scores = Vec::new();
    let mut probes = Vec::new();
    for &w in &widths {
        let p = train(w, &train_views);
        scores.push(score(&p, &held));
        probes.push(p);
    }
    let pick = choose(&widths, &scores, tolerance_db);
    let chosen = probes.swap_remove(pick);
    let summary = FieldProbeSummary {
        held_out,
        width: widths[pick],
        widths,
        held_out_psnr: scores,
        seconds: start.elapsed().as_secs_f64(),
        ..FieldProbeSummary::default()
    };
    Some((chosen, summary))
}
