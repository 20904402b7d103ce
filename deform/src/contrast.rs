//! The contrast threshold `C` from the recording itself (issue #18, item 2), and how the
//! joint training chooses the `C` it uses ([`ContrastMode`]).
//!
//! **Estimate.** Between two consecutive train frames a pixel's log brightness changes
//! by `ΔL = log(Y₁ + ε) − log(Y₀ + ε)` (`Y` the Rec. 709 luminance of the linear frame,
//! `ε` the pseudo image's `log_eps`) and it fires `n` events (signed count). The event
//! model says `n ≈ ΔL / C`: the count is `ΔL/C` rounded by where the pixel's reference
//! level sat at the first frame, an error in `(−1, 1)` of mean about 0. So `n` is the
//! noisy variable and `ΔL` the precise one, and the fit regresses `n` on `ΔL` through the
//! origin: `1/C = Σ ΔL·n / Σ ΔL²` (regressing `ΔL` on `n` instead would be biased by the
//! rounding). Pixels are chosen on `ΔL` only (never on `n`, which would bias the fit):
//! both frames' luminance in `[black_level, saturation)`, no channel clipped, and
//! `|ΔL| ≥ min_log_change`, and *steady*: the pixel's last event before the interval
//! has the sign of `ΔL` and none in the interval has the other sign. The event model
//! has hysteresis: after an event the level sits in `[r, r + C)` above the reference `r`
//! (or below it after a negative one), so a pixel that turned round before the frame
//! must cross a dead band of up to `2C` before it fires again, and its count falls
//! short by half an event on average (5 % at `C = 0.2` on the tests' oscillating
//! pixels); a pixel that has not fired yet sits exactly on its reference (the start of
//! the stream) and is biased the same way. Outliers (hot pixels, noise bursts, occlusions that the
//! counts and frames see differently) are dropped by iterating the fit with a cut at
//! `max(4·1.4826·MAD, 1.5)` events of residual `n − ΔL/C`. `C⁺` and `C⁻` are the same fit
//! over the pixels that brightened, and darkened. The spread is a seeded bootstrap over
//! the inlier pixels (standard deviation and 2.5–97.5 % interval of `C`).
//!
//! **Learn.** With [`ContrastMode::Learn`] the joint training also optimises `log C`
//! (Adam) by `∂L_event/∂C` ([`crate::event_image::event_loss`]'s `d_contrast`, checked
//! against finite differences in the tests), starting from the given or estimated `C`.

use rand::{RngExt, SeedableRng};
use scene::EventSlice;
use serde::{Deserialize, Serialize};
use stagekit::optim::Adam;

pub use crate::event_image::LUMA;

/// Which contrast threshold the joint training uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ContrastMode {
    /// The given `C`: `contrast_threshold`, or the manifest's when that is 0.
    Given,
    /// The estimate from the frames and events (the given `C` when there is too little
    /// signal to estimate).
    #[default]
    Estimate,
    /// The given `C` as initial value, then learned through `L_event`.
    Learn,
    /// The estimate as initial value, then learned through `L_event`.
    EstimateLearn,
}

impl ContrastMode {
    pub(crate) fn uses_estimate(self) -> bool {
        matches!(self, ContrastMode::Estimate | ContrastMode::EstimateLearn)
    }
    pub fn learns(self) -> bool {
        matches!(self, ContrastMode::Learn | ContrastMode::EstimateLearn)
    }
}

/// Settings of the estimate (serde, every field optional in files).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EstimateSettings {
    /// Smallest `|ΔL|` (log units) of a pixel used.
    pub min_log_change: f64,
    /// Luminance below this (linear) is too dark to trust its log.
    pub black_level: f64,
    /// Luminance, or any channel, at or above this (linear) is clipped.
    pub saturation: f64,
    /// Fewer inlier pixels than this: no estimate.
    pub min_pixels: usize,
    /// Bootstrap resamples of the spread.
    pub bootstrap: usize,
    pub seed: u64,
}

impl Default for EstimateSettings {
    fn default() -> Self {
        EstimateSettings {
            min_log_change: 0.2,
            black_level: 0.02,
            saturation: 0.99,
            min_pixels: 50,
            bootstrap: 200,
            seed: 0,
        }
    }
}

/// An estimate of `C` with its spread.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ContrastEstimate {
    /// `C` from every usable pixel.
    pub c: f64,
    /// Bootstrap standard deviation of `c` (`None`: fewer than 2 resamples).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub std: Option<f64>,
    /// Bootstrap 2.5 % and 97.5 % quantiles of `c`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ci95: Option<[f64; 2]>,
    /// `C⁺` from the pixels that brightened, `C⁻` from those that darkened (`None`:
    /// fewer than `min_pixels`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub c_pos: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub c_neg: Option<f64>,
    /// Pixel-intervals that passed the brightness checks, and those kept by the fit.
    pub pixels: usize,
    pub inliers: usize,
    /// Median absolute residual `|n − ΔL/C|` of the inliers, in events.
    pub residual_mad: f64,
}

/// One pixel over one interval: log change and signed event count.
#[derive(Clone, Copy, Debug)]
struct Sample {
    dl: f64,
    n: f64,
}

/// Luminance of pixel `i` of a planar frame (Rec. 709 of RGB; the value itself for one
/// channel) and its largest channel (for the clipping check).
fn luminance(frame: &[f32], plane: usize, i: usize, channels: usize) -> (f64, f64) {
    let (mut y, mut top) = (0.0, f64::NEG_INFINITY);
    for (k, w) in LUMA.iter().enumerate().take(channels) {
        let v = f64::from(frame[k * plane + i]);
        y += w * v;
        top = top.max(v);
    }
    if channels == 1 {
        y = f64::from(frame[i]);
    }
    (y, top)
}

/// Per pixel over one interval: signed count, and which polarities fired.
#[derive(Clone, Copy, Debug, Default)]
struct PixelEvents {
    n: i32,
    pos: bool,
    neg: bool,
}

/// The usable pixels of every interval (module docs). `events` time-sorted.
fn samples(
    linear: &[Vec<f32>],
    channels: usize,
    times: &[f64],
    events: &EventSlice<'_>,
    log_eps: f64,
    s: &EstimateSettings,
) -> Vec<Sample> {
    let plane = events.width as usize * events.height as usize;
    let pix = |k: usize| events.y[k] as usize * events.width as usize + events.x[k] as usize;
    // Polarity of each pixel's last event so far (0: none yet).
    let mut last = vec![0i8; plane];
    let mut px = vec![PixelEvents::default(); plane];
    let (mut out, mut k) = (Vec::new(), 0);
    for (j, w) in times.windows(2).enumerate() {
        let (t0, t1) = (w[0], w[1]);
        while k < events.t.len() && events.t[k] < t0 {
            last[pix(k)] = events.p[k];
            k += 1;
        }
        let before = last.clone();
        px.fill(PixelEvents::default());
        while k < events.t.len() && events.t[k] < t1 {
            let (i, p) = (pix(k), events.p[k]);
            px[i].n += i32::from(p);
            px[i].pos |= p > 0;
            px[i].neg |= p < 0;
            last[i] = p;
            k += 1;
        }
        let (Some(a), Some(b)) = (linear.get(j), linear.get(j + 1)) else {
            break;
        };
        if a.len() != channels * plane || b.len() != channels * plane {
            continue;
        }
        for i in 0..plane {
            let (y0, top0) = luminance(a, plane, i, channels);
            let (y1, top1) = luminance(b, plane, i, channels);
            let ok = |y: f64, top: f64| {
                y.is_finite() && y >= s.black_level && y < s.saturation && top < s.saturation
            };
            if !(ok(y0, top0) && ok(y1, top1)) {
                continue;
            }
            let dl = (y1 + log_eps).ln() - (y0 + log_eps).ln();
            // The pixel's level sits uniformly in its band only if its last event went
            // the way the change goes, and it turned no corner the events saw.
            let (up, e) = (dl > 0.0, px[i]);
            let steady = if up {
                before[i] > 0 && !e.neg
            } else {
                before[i] < 0 && !e.pos
            };
            if dl.abs() >= s.min_log_change && steady {
                out.push(Sample {
                    dl,
                    n: f64::from(e.n),
                });
            }
        }
    }
    out
}

/// `C = Σ ΔL² / Σ ΔL·n` (`None` when `Σ ΔL·n ≤ 0`: no positive threshold fits).
fn fit(samples: &[Sample]) -> Option<f64> {
    let (mut sxx, mut sxy) = (0.0, 0.0);
    for p in samples {
        sxx += p.dl * p.dl;
        sxy += p.dl * p.n;
    }
    (sxy > 0.0 && sxx > 0.0).then(|| sxx / sxy)
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let m = v.len() / 2;
    *v.select_nth_unstable_by(m, f64::total_cmp).1
}

/// The fit with outliers dropped: `(C, inliers, median |residual|)`.
fn robust_fit(all: &[Sample], min_pixels: usize) -> Option<(f64, Vec<Sample>, f64)> {
    let mut c = fit(all)?;
    let mut kept: Vec<Sample> = all.to_vec();
    let mut mad = 0.0;
    for _ in 0..8 {
        let mut res: Vec<f64> = all.iter().map(|p| (p.n - p.dl / c).abs()).collect();
        mad = median(&mut res);
        let cut = (4.0 * 1.4826 * mad).max(1.5);
        kept = all
            .iter()
            .copied()
            .filter(|p| (p.n - p.dl / c).abs() <= cut)
            .collect();
        if kept.len() < min_pixels.max(1) {
            return None;
        }
        let next = fit(&kept)?;
        let done = (next - c).abs() <= 1e-9 * c;
        c = next;
        if done {
            break;
        }
    }
    let mut res: Vec<f64> = kept.iter().map(|p| (p.n - p.dl / c).abs()).collect();
    if !res.is_empty() {
        mad = median(&mut res);
    }
    Some((c, kept, mad))
}

/// Estimate `C` from the train frames (`linear`: one planar `channels × H × W` linear
/// frame per time of `times`, increasing) and the events (time-sorted) between them
/// (module docs). `Err` says why there is no estimate (too few usable pixels, no
/// consistent sign).
pub fn estimate_contrast(
    linear: &[Vec<f32>],
    channels: usize,
    times: &[f64],
    events: &EventSlice<'_>,
    log_eps: f64,
    s: &EstimateSettings,
) -> Result<ContrastEstimate, String> {
    let all = samples(linear, channels, times, events, log_eps, s);
    let pixels = all.len();
    let short = || {
        format!(
            "too little signal to estimate C: {pixels} pixel-intervals with |ΔL| ≥ {} \
             (at least {} needed)",
            s.min_log_change, s.min_pixels
        )
    };
    if pixels < s.min_pixels.max(1) {
        return Err(short());
    }
    let (c, kept, residual_mad) = robust_fit(&all, s.min_pixels).ok_or_else(short)?;
    let side = |pos: bool| {
        let part: Vec<Sample> = all
            .iter()
            .copied()
            .filter(|p| (p.dl > 0.0) == pos)
            .collect();
        (part.len() >= s.min_pixels.max(1))
            .then(|| robust_fit(&part, s.min_pixels).map(|f| f.0))
            .flatten()
    };
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(s.seed);
    let mut boot: Vec<f64> = (0..s.bootstrap)
        .filter_map(|_| {
            let (mut sxx, mut sxy) = (0.0, 0.0);
            for _ in 0..kept.len() {
                let p = kept[rng.random_range(0..kept.len())];
                sxx += p.dl * p.dl;
                sxy += p.dl * p.n;
            }
            (sxy > 0.0).then(|| sxx / sxy)
        })
        .collect();
    boot.sort_by(f64::total_cmp);
    let (std, ci95) = if boot.len() >= 2 {
        let m = boot.iter().sum::<f64>() / boot.len() as f64;
        let var = boot.iter().map(|b| (b - m).powi(2)).sum::<f64>() / (boot.len() - 1) as f64;
        let q = |f: f64| boot[((f * (boot.len() - 1) as f64).round() as usize).min(boot.len() - 1)];
        (Some(var.sqrt()), Some([q(0.025), q(0.975)]))
    } else {
        (None, None)
    };
    Ok(ContrastEstimate {
        c,
        std,
        ci95,
        c_pos: side(true),
        c_neg: side(false),
        pixels,
        inliers: kept.len(),
        residual_mad,
    })
}

/// What `report.json` says about `C`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ContrastReport {
    pub mode: ContrastMode,
    /// `contrast_threshold` or the manifest's.
    pub given: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub estimate: Option<ContrastEstimate>,
    /// Why there is no estimate.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub estimate_error: Option<String>,
    /// The `C` the training started from.
    pub initial: f64,
    /// The `C` at the end (the learned one with a learning mode, else `initial`).
    pub last: f64,
}

/// `C` learned through `L_event`: Adam on `log C` (positive by construction; a step
/// moves `C` by a ratio, the same for any scale of `C`).
#[derive(Clone, Debug)]
pub(crate) struct LearnedContrast {
    log_c: [f32; 1],
    adam: Adam,
}

impl LearnedContrast {
    pub fn new(c: f64, lr: f64) -> Self {
        let mut adam = Adam::default();
        adam.add_group("log_contrast", lr, 1e-15, 1, 1);
        LearnedContrast {
            log_c: [c.ln() as f32],
            adam,
        }
    }

    pub fn value(&self) -> f64 {
        f64::from(self.log_c[0]).exp()
    }

    /// One step from `∂L/∂C` (`∂L/∂log C = C·∂L/∂C`). A non-finite gradient is skipped.
    pub fn step(&mut self, d_loss_dc: f64) {
        let g = self.value() * d_loss_dc;
        if g.is_finite() {
            self.adam.step(0, &mut self.log_c, &[g as f32]);
        }
    }
}
