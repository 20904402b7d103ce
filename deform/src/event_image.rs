//! Pseudo images from the event generation model (Eq. 11) and the event loss `L_event`.
//!
//! Between frames `I(t0)` and `I(t2)` (linear intensity, planar `C × H × W` like the
//! rasterizer's renders), with `N(x; a, b)` the signed event count of pixel `x` over
//! `[a, b)` ([`crate::event_counts`]) and `C` the contrast threshold:
//!
//! - [`PseudoMode::Nearest`] (Eq. 11): for `t_e ≤ (t0 + t2)/2`,
//!   `P = (I(t0) + ε)·exp(C·N(t0, t_e)) − ε`; otherwise
//!   `P = (I(t2) + ε)/exp(C·N(t_e, t2)) − ε`. With `ε = 0` (the default,
//!   [`PseudoSettings::log_eps`]) this is the paper's formula; `ε > 0` inverts a sensor
//!   (or `evflow`'s simulator, `ε = 1e-3`) that fires on `log(ε + I)`.
//! - [`PseudoMode::TwoSided`] (the 2-D baseline of `degs eval`): both predictions,
//!   blended in log space by the distance in time, `log(P + ε) = (1 − s)·log(P_left +
//!   ε) + s·log(P_right + ε)`, `s = (t_e − t0)/(t2 − t0)`; where only one side is valid
//!   that side is used alone.
//!
//! Every channel is scaled by the same per-pixel factor (events see brightness, not
//! colour). A value is **valid** when its source frame value lies in
//! `[black_level, saturation)` ([`PseudoSettings`]; `I + ε > 0`: no log of zero) and
//! the predicted value lies in `[black_level, saturation]` and is finite; invalid values
//! are excluded from the loss (masked per channel). A source value at or above
//! `saturation` is clipped (its true brightness is unknown, so nothing can be predicted
//! from it); a prediction outside the range the frames are trusted in — `exp(C·N)`
//! overflowing to infinity, or underflowing towards 0, as a hot pixel's huge count does —
//! is masked rather than used. Pixels whose events the counts leave out (hot pixels,
//! `IntervalCounts::pixel_excluded`) are masked too: their count says nothing about
//! the scene. `PseudoImage::n_eff` holds `∂log(P + ε)/∂C` per value, so
//! `∂P/∂C = (P + ε)·n_eff`.
//!
//! [`event_loss`]: `L_event = mean over valid values of |R − P|` (L1, Eq. 11), with its
//! gradient w.r.t. the render (`sign(R − P)/M`, 0 where `R = P`) and w.r.t. `C`.
//!
//! sRGB helpers ([`srgb_to_linear`], [`linear_to_srgb`]: IEC 61966-2-1) and
//! [`planar_linear`] convert frames stored as 8-bit sRGB before the model is applied.

use crate::event_counts::IntervalCounts;
use rayon::prelude::*;
use scene::real::Real;
use scene::{EventSlice, Image};
use serde::{Deserialize, Serialize};

/// Rec. 709 luminance weights of linear RGB (what an event pixel integrates, as
/// `synth`'s simulator assumes).
pub const LUMA: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// Values per rayon task.
const CHUNK: usize = 8192;

/// Settings of the pseudo image (serde, every field optional in files).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PseudoSettings {
    /// `ε` of `log(I + ε)` (0: the paper's multiplicative form).
    pub log_eps: f64,
    /// Frame values, and predictions, below this (linear) carry no usable brightness:
    /// masked.
    pub black_level: f64,
    /// Predicted values above this (linear) are saturated, frame values at or above it
    /// are clipped: masked.
    pub saturation: f64,
    /// Half-width `b` of a dead zone around the pseudo image, in units of `C`: the render
    /// is penalised only outside `[(P + ε)·e^(−b·C) − ε, (P + ε)·e^(b·C) − ε]`. 0 is the
    /// paper's L1 (Eq. 11); 1 accepts the quantisation of the event model (a pixel's log
    /// change is known only to within about `C` of `C·N`).
    pub band: f64,
}

impl Default for PseudoSettings {
    fn default() -> Self {
        PseudoSettings {
            log_eps: 0.0,
            black_level: 0.01,
            saturation: 1.0,
            band: 0.0,
        }
    }
}

/// Which frame(s) the pseudo image is predicted from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PseudoMode {
    /// The nearer frame (Eq. 11).
    #[default]
    Nearest,
    /// Both frames, blended in log space.
    TwoSided,
}

/// What `L_event` compares (Eq. 11): the event model predicts a per-pixel brightness
/// factor, which holds for the luminance an event pixel integrates but not for each
/// colour channel (an object of another colour passing over a pixel changes its chroma,
/// which no event count predicts).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EventChannels {
    /// Rec. 709 luminance of the linear render against the pseudo image of the frames'
    /// luminance.
    #[default]
    Luminance,
    /// Each colour channel scaled by the same factor (the paper's Eq. 11 on RGB frames).
    Rgb,
}

/// The inputs of a pseudo image: the interval's counts and its two frames.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PseudoInputs<'a, R> {
    pub counts: &'a IntervalCounts,
    /// The event slice the counts were built from (exact counts), or `None`
    /// (interpolated within the partial bins).
    pub events: Option<&'a EventSlice<'a>>,
    /// Frame at the interval's start, linear, planar `channels × H × W`.
    pub left: &'a [R],
    /// Frame at the interval's end, same layout.
    pub right: &'a [R],
    pub channels: usize,
    /// Contrast threshold `C` (log units per event).
    pub contrast: R,
}

/// A pseudo image, planar `channels × H × W`, with its mask and `∂log(P + ε)/∂C`.
/// Kept between calls, its buffers are reused.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PseudoImage<R> {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<R>,
    pub valid: Vec<bool>,
    pub n_eff: Vec<R>,
    pub log_eps: R,
    /// Dead-zone half-width `b` in units of `C` ([`PseudoSettings::band`]) and `b·C`.
    pub band_per_c: R,
    pub band: R,
    left_counts: Vec<f32>,
    right_counts: Vec<f32>,
}

impl<R: Real> PseudoImage<R> {
    /// Number of valid values.
    pub fn valid_count(&self) -> usize {
        self.valid.iter().filter(|&&v| v).count()
    }

    /// Empty this image (its buffers kept) to be filled as a `width × height` image of
    /// `like`'s channels and settings (a window or a coarser copy of `like`).
    pub(crate) fn begin_like(&mut self, like: &PseudoImage<R>, width: usize, height: usize) {
        let n = width * height * like.channels;
        for v in [&mut self.data, &mut self.n_eff] {
            v.clear();
            v.reserve(n);
        }
        self.valid.clear();
        self.valid.reserve(n);
        (self.width, self.height, self.channels) = (width, height, like.channels);
        (self.log_eps, self.band_per_c, self.band) = (like.log_eps, like.band_per_c, like.band);
    }
}

/// One side's prediction: `(log(P + ε), n)` or `None` where that side is not usable
/// (source black, clipped or not finite).
#[inline(always)]
fn side<R: Real>(i: R, n: R, c: R, eps: R, black: R, sat: R) -> Option<(R, R)> {
    let base = i + eps;
    if i >= black && i < sat && base > R::ZERO && i.is_finite() {
        Some((base.ln() + c * n, n))
    } else {
        None
    }
}

/// Eq. 11 (and its two-sided variant): the pseudo image at `t_e` (clamped to the
/// interval) into `out`.
pub(crate) fn pseudo_image<R: Real>(
    inp: &PseudoInputs<'_, R>,
    t_e: f64,
    mode: PseudoMode,
    s: &PseudoSettings,
    out: &mut PseudoImage<R>,
) {
    let k = inp.counts;
    let (w, h, ch) = (k.width(), k.height(), inp.channels);
    let n = w * h;
    assert!(
        inp.left.len() == ch * n && inp.right.len() == ch * n,
        "pseudo_image: frames must be {ch} × {h} × {w}"
    );
    let (t0, t2) = k.span();
    let t_e = if t_e.is_finite() {
        t_e.clamp(t0, t2)
    } else {
        t0
    };
    let frac = if t2 > t0 { (t_e - t0) / (t2 - t0) } else { 0.0 };
    let use_left = mode == PseudoMode::TwoSided || frac <= 0.5;
    let use_right = mode == PseudoMode::TwoSided || frac > 0.5;
    out.left_counts.resize(n, 0.0);
    out.right_counts.resize(n, 0.0);
    if use_left {
        k.signed_counts(t0, t_e, inp.events, &mut out.left_counts);
    }
    if use_right {
        k.signed_counts(t_e, t2, inp.events, &mut out.right_counts);
    }
    (out.width, out.height, out.channels) = (w, h, ch);
    out.data.resize(ch * n, R::ZERO);
    out.valid.resize(ch * n, false);
    out.n_eff.resize(ch * n, R::ZERO);
    out.log_eps = R::from_f64(s.log_eps);
    out.band_per_c = R::from_f64(s.band.max(0.0));
    out.band = out.band_per_c * inp.contrast;
    let (eps, black, sat) = (
        out.log_eps,
        R::from_f64(s.black_level),
        R::from_f64(s.saturation),
    );
    let (c, sf) = (inp.contrast, R::from_f64(frac));
    let (lc, rc) = (&out.left_counts, &out.right_counts);
    out.data
        .par_chunks_mut(CHUNK)
        .zip(out.valid.par_chunks_mut(CHUNK))
        .zip(out.n_eff.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(r, ((p, ok), ne))| {
            let start = r * CHUNK; // index into the planar image
            for j in 0..p.len() {
                let (vi, pi) = (start + j, (start + j) % n);
                if k.pixel_excluded(pi) {
                    (p[j], ok[j], ne[j]) = (R::ZERO, false, R::ZERO);
                    continue;
                }
                let a = use_left
                    .then(|| side(inp.left[vi], R::from_f64(lc[pi] as f64), c, eps, black, sat))
                    .flatten();
                let b = use_right
                    .then(|| {
                        side(
                            inp.right[vi],
                            -R::from_f64(rc[pi] as f64),
                            c,
                            eps,
                            black,
                            sat,
                        )
                    })
                    .flatten();
                let blended = match (a, b) {
                    (Some((la, na)), Some((lb, nb))) => {
                        Some(((R::ONE - sf) * la + sf * lb, (R::ONE - sf) * na + sf * nb))
                    }
                    (x, None) | (None, x) => x,
                };
                (p[j], ok[j], ne[j]) = match blended {
                    Some((l, nn)) => {
                        let v = l.exp() - eps;
                        if v.is_finite() && v >= black && v >= R::ZERO && v <= sat {
                            (v, true, nn)
                        } else {
                            (R::ZERO, false, R::ZERO)
                        }
                    }
                    None => (R::ZERO, false, R::ZERO),
                };
            }
        });
}

/// The value of `L_event`, its gradient w.r.t. `C`, and the number of valid values.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct EventLoss<R> {
    pub loss: R,
    pub d_contrast: R,
    pub valid: usize,
}

/// The band `[lo, hi]` around value `i` of the pseudo image (`lo = hi = P` at `b = 0`).
#[inline(always)]
fn band_edges<R: Real>(p: &PseudoImage<R>, i: usize) -> (R, R) {
    let base = p.data[i] + p.log_eps;
    if p.band > R::ZERO {
        let e = p.band.exp();
        (base / e - p.log_eps, base * e - p.log_eps)
    } else {
        (p.data[i], p.data[i])
    }
}

/// `sign` of the render's distance outside the band (0 inside it).
#[inline(always)]
fn band_sign<R: Real>(p: &PseudoImage<R>, i: usize, x: R) -> R {
    let (lo, hi) = band_edges(p, i);
    if x > hi {
        R::ONE
    } else if x < lo {
        -R::ONE
    } else {
        R::ZERO
    }
}

/// Distance of `x` outside the band of value `i` and its derivative w.r.t. `C`
/// (`∂hi/∂C = (hi + ε)·(n_eff + b)`, `∂lo/∂C = (lo + ε)·(n_eff − b)`).
#[inline(always)]
fn band_residual<R: Real>(p: &PseudoImage<R>, i: usize, x: R) -> (R, R) {
    let (lo, hi) = band_edges(p, i);
    let (eps, n, b) = (p.log_eps, p.n_eff[i], p.band_per_c);
    if x > hi {
        (x - hi, -(hi + eps) * (n + b))
    } else if x < lo {
        (lo - x, (lo + eps) * (n - b))
    } else {
        (R::ZERO, R::ZERO)
    }
}

/// Eq. 11: `L_event = (1/M)·Σ_valid |R − P|` for a render `R` (planar, same layout as
/// the pseudo image), or with a dead zone ([`PseudoSettings::band`]) the distance of `R`
/// outside `[lo, hi]`; with `grad_render`, writes `∂L/∂R` (0 on masked values and inside
/// the band). No valid value gives a zero loss and zero gradients.
pub(crate) fn event_loss<R: Real>(
    render: &[R],
    pseudo: &PseudoImage<R>,
    grad_render: Option<&mut [R]>,
) -> EventLoss<R> {
    let len = pseudo.data.len();
    assert_eq!(render.len(), len, "event_loss: render size");
    let chunk = CHUNK;
    let parts: Vec<(R, R, usize)> = render
        .par_chunks(chunk)
        .enumerate()
        .map(|(r, rr)| {
            let mut acc = (R::ZERO, R::ZERO, 0usize);
            for (j, &x) in rr.iter().enumerate() {
                let i = r * chunk + j;
                if pseudo.valid[i] {
                    let (e, dl) = band_residual(pseudo, i, x);
                    acc.0 += e;
                    acc.1 += dl;
                    acc.2 += 1;
                }
            }
            acc
        })
        .collect();
    let (mut sum, mut dc, mut m) = (R::ZERO, R::ZERO, 0usize);
    for p in parts {
        sum += p.0;
        dc += p.1;
        m += p.2;
    }
    let inv = if m > 0 {
        R::ONE / R::from_f64(m as f64)
    } else {
        R::ZERO
    };
    if let Some(g) = grad_render {
        assert_eq!(g.len(), len, "event_loss: gradient size");
        g.par_chunks_mut(chunk).enumerate().for_each(|(r, gg)| {
            for (j, v) in gg.iter_mut().enumerate() {
                let i = r * chunk + j;
                *v = if pseudo.valid[i] {
                    band_sign(pseudo, i, render[i]) * inv
                } else {
                    R::ZERO
                };
            }
        });
    }
    EventLoss {
        loss: sum * inv,
        d_contrast: dc * inv,
        valid: m,
    }
}

/// sRGB-encoded value in `[0, 1]` → linear (IEC 61966-2-1).
#[inline]
pub fn srgb_to_linear<R: Real>(c: R) -> R {
    if c <= R::from_f64(0.04045) {
        c / R::from_f64(12.92)
    } else {
        ((c + R::from_f64(0.055)) / R::from_f64(1.055)).powf(R::from_f64(2.4))
    }
}

/// Luminance (Rec. 709, [`LUMA`]) of a planar linear RGB image of `n` pixels (what an
/// event pixel integrates).
pub(crate) fn planar_luminance<R: Real>(rgb: &[R], n: usize) -> Vec<R> {
    assert_eq!(
        rgb.len(),
        3 * n,
        "planar_luminance: expected 3 planes of {n}"
    );
    let w = LUMA.map(R::from_f64);
    (0..n)
        .map(|i| w[0] * rgb[i] + w[1] * rgb[n + i] + w[2] * rgb[2 * n + i])
        .collect()
}

/// `d linear / d encoded` of the sRGB curve, the linear segment below 0.04045 extended
/// to negative values.
#[inline]
pub(crate) fn srgb_slope<R: Real>(c: R) -> R {
    if c <= R::from_f64(0.040_45) {
        R::ONE / R::from_f64(12.92)
    } else {
        R::from_f64(2.4 / 1.055)
            * ((c + R::from_f64(0.055)) / R::from_f64(1.055)).powf(R::from_f64(1.4))
    }
}

/// Eq. 11 on a render as stored (planar RGB, sRGB-encoded when `srgb`): linearised,
/// reduced to luminance for [`EventChannels::Luminance`] (the pseudo image then has one
/// plane), compared by [`event_loss`]; `grad` receives `∂L/∂(stored value)`.
pub(crate) fn render_event_loss<R: Real>(
    stored: &[R],
    srgb: bool,
    channels: EventChannels,
    pseudo: &PseudoImage<R>,
    grad: &mut [R],
) -> EventLoss<R> {
    let plane = stored.len() / 3;
    let linear: Vec<R> = if srgb {
        stored.iter().map(|&c| srgb_to_linear(c)).collect()
    } else {
        stored.to_vec()
    };
    let luma = channels == EventChannels::Luminance;
    let compared = if luma {
        planar_luminance(&linear, plane)
    } else {
        linear
    };
    let mut g = vec![R::ZERO; compared.len()];
    let el = event_loss(&compared, pseudo, Some(&mut g));
    let w = LUMA.map(R::from_f64);
    for (k, (gk, &c)) in grad.iter_mut().zip(stored).enumerate() {
        let dl = if luma {
            w[k / plane] * g[k % plane]
        } else {
            g[k]
        };
        *gk = dl * if srgb { srgb_slope(c) } else { R::ONE };
    }
    el
}

/// Linear value in `[0, 1]` → sRGB-encoded (IEC 61966-2-1).
#[inline]
pub(crate) fn linear_to_srgb<R: Real>(l: R) -> R {
    if l <= R::from_f64(0.003_130_8) {
        l * R::from_f64(12.92)
    } else {
        R::from_f64(1.055) * l.powf(R::from_f64(1.0 / 2.4)) - R::from_f64(0.055)
    }
}

/// A `scene::Image` (interleaved) as planar `C × H × W` values, linearised from sRGB
/// when `srgb` (frames stored as 8-bit sRGB), as is otherwise (`scene` reads PNGs as
/// linear `code/255`).
pub fn planar_linear(img: &Image, srgb: bool) -> Vec<f32> {
    let (n, c) = (img.pixels(), img.channels as usize);
    let mut out = vec![0.0f32; n * c];
    for (k, plane) in out.chunks_mut(n.max(1)).enumerate().take(c) {
        for (i, v) in plane.iter_mut().enumerate() {
            let x = img.data[i * c + k];
            *v = if srgb { srgb_to_linear(x) } else { x };
        }
    }
    out
}
