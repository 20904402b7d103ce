//! Event camera simulator (ESIM / v2e style): frames in, events out.
//!
//! Model, per pixel (Gallego et al.'s event generation model, as in ESIM):
//! - brightness is `L = log(ε + Y)`, `Y` the luminance of *linear* RGB (Rec. 709
//!   weights, [`luminance`]), `ε = 1e-3`;
//! - each pixel keeps a reference level `L_ref` (initialised from the first frame);
//!   whenever `L − L_ref ≥ C⁺` it emits `+1` and sets `L_ref += C⁺`, whenever
//!   `L_ref − L ≥ C⁻` it emits `−1` and sets `L_ref −= C⁻`;
//! - between two consecutive frames `L` is taken as linear in time, so the time of
//!   each crossing is interpolated exactly: `t = t₀ + (L_ref − L₀)/(L₁ − L₀)·(t₁ − t₀)`;
//! - thresholds vary per pixel: `C± = max(c_min, C±_nominal + σ·N(0,1))` (mismatch
//!   fixed at construction from the seed; `c_min = 0.01` as in ESIM);
//! - refractory period: a crossing less than `refractory_s` after the pixel's last
//!   emitted event is dropped (the reference still moves, i.e. the change is lost, as
//!   with a pixel held in reset);
//! - shot noise: Poisson events at `shot_noise_hz` per pixel, uniform in time, random
//!   polarity; hot pixels: a `hot_pixel_fraction` of pixels (chosen from the seed)
//!   firing `+1` at `hot_pixel_hz` (Poisson). Noise events bypass the reference level
//!   and the refractory filter.
//!
//! Everything is deterministic for a given seed (ChaCha8, one stream per frame), and
//! independent of the number of threads: rows are processed in parallel with rayon,
//! then the events of a frame interval are merged sorted by `(t, y, x, p)`.
//!
//! A directory of frames is simulated by the `frames` module, a synthetic world by
//! the `scene_dir` module.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Poisson, StandardNormal};
use rayon::prelude::*;
use scene::error::{Error, Result};
use scene::events::EventStream;
use serde::{Deserialize, Serialize};
use stagekit::Settings;

/// Rec. 709 luminance weights of linear RGB.
pub const LUMA: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// Settings of the simulator (serde, every field optional in files).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimConfig {
    /// Nominal positive contrast threshold C⁺ (log units).
    pub threshold_pos: f64,
    /// Nominal negative contrast threshold C⁻ (log units).
    pub threshold_neg: f64,
    /// Per-pixel threshold mismatch σ (std of the Gaussian added to C±).
    pub threshold_sigma: f64,
    /// Lower clamp of the per-pixel thresholds.
    pub min_threshold: f64,
    /// ε of `log(ε + Y)`.
    pub log_eps: f64,
    /// Refractory period in seconds (0 = none).
    pub refractory_s: f64,
    /// Shot-noise event rate per pixel, Hz.
    pub shot_noise_hz: f64,
    /// Fraction of hot pixels.
    pub hot_pixel_fraction: f64,
    /// Event rate of a hot pixel, Hz.
    pub hot_pixel_hz: f64,
}

/// Log-intensity slack of a threshold crossing: exact ties fire (see `push_frame_flagged`).
const TIE: f64 = 1e-9;

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            threshold_pos: 0.1,
            threshold_neg: 0.1,
            threshold_sigma: 0.02,
            min_threshold: 0.01,
            log_eps: 1e-3,
            refractory_s: 0.0,
            shot_noise_hz: 0.0,
            hot_pixel_fraction: 0.0,
            hot_pixel_hz: 0.0,
        }
    }
}

impl SimConfig {
    /// The single contrast threshold C of a scene manifest: the mean of the nominal
    /// C⁺ and C⁻ (exactly C when they are equal).
    pub(crate) fn nominal_threshold(&self) -> f64 {
        0.5 * (self.threshold_pos + self.threshold_neg)
    }
}

impl stagekit::Settings for SimConfig {
    /// `Err` with a sentence (starting with the key) when a setting is out of range.
    fn validate(&self) -> std::result::Result<(), String> {
        let checks = [
            ("threshold_pos", self.threshold_pos, 0.0),
            ("threshold_neg", self.threshold_neg, 0.0),
            ("min_threshold", self.min_threshold, 0.0),
            ("log_eps", self.log_eps, 0.0),
        ];
        for (name, v, min) in checks {
            if !(v.is_finite() && v > min) {
                return Err(format!("{name} = {v} must be finite and > {min}"));
            }
        }
        let non_negative = [
            ("threshold_sigma", self.threshold_sigma),
            ("refractory_s", self.refractory_s),
            ("shot_noise_hz", self.shot_noise_hz),
            ("hot_pixel_hz", self.hot_pixel_hz),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} = {v} must be finite and ≥ 0"));
            }
        }
        if !(0.0..=1.0).contains(&self.hot_pixel_fraction) {
            return Err(format!(
                "hot_pixel_fraction = {} must be in [0, 1]",
                self.hot_pixel_fraction
            ));
        }
        Ok(())
    }
}

/// Luminance of interleaved linear RGB (3 channels), Rec. 709.
pub fn luminance(rgb: &[f32]) -> Vec<f32> {
    rgb.chunks_exact(3)
        .map(|c| LUMA[0] * c[0] + LUMA[1] * c[1] + LUMA[2] * c[2])
        .collect()
}

#[derive(Clone, Copy, Debug)]
struct Ev {
    t: f64,
    x: u16,
    y: u16,
    p: i8,
    noise: bool,
}

/// Per-pixel simulator state; feed frames in time order with [`Simulator::push_frame`].
pub struct Simulator {
    width: u32,
    height: u32,
    cfg: SimConfig,
    seed: u64,
    c_pos: Vec<f64>,
    c_neg: Vec<f64>,
    reference: Vec<f64>,
    prev_log: Vec<f64>,
    last_event: Vec<f64>,
    hot: Vec<u32>,
    prev_t: Option<f64>,
    frame_index: u64,
    scratch: Vec<Ev>,
}

impl Simulator {
    /// A simulator of a `width × height` sensor. Panics only on a zero-sized sensor or
    /// an invalid config (call [`SimConfig::validate`] first on user input).
    pub fn new(width: u32, height: u32, cfg: &SimConfig, seed: u64) -> Self {
        assert!(width > 0 && height > 0, "empty sensor");
        assert!(
            width <= u16::MAX as u32 + 1 && height <= u16::MAX as u32 + 1,
            "sensor too large"
        );
        if let Err(e) = cfg.validate() {
            panic!("invalid SimConfig: {e}");
        }
        let n = (width * height) as usize;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut draw = |nominal: f64| -> f64 {
            let z: f64 = StandardNormal.sample(&mut rng);
            (nominal + cfg.threshold_sigma * z).max(cfg.min_threshold)
        };
        let c_pos: Vec<f64> = (0..n).map(|_| draw(cfg.threshold_pos)).collect();
        let c_neg: Vec<f64> = (0..n).map(|_| draw(cfg.threshold_neg)).collect();
        let hot = if cfg.hot_pixel_fraction > 0.0 && cfg.hot_pixel_hz > 0.0 {
            (0..n as u32)
                .filter(|_| rng.random::<f64>() < cfg.hot_pixel_fraction)
                .collect()
        } else {
            Vec::new()
        };
        Simulator {
            width,
            height,
            cfg: cfg.clone(),
            seed,
            c_pos,
            c_neg,
            reference: vec![0.0; n],
            prev_log: vec![0.0; n],
            last_event: vec![f64::NEG_INFINITY; n],
            hot,
            prev_t: None,
            frame_index: 0,
            scratch: Vec::new(),
        }
    }

    /// Per-pixel positive thresholds (row-major).
    pub fn thresholds_pos(&self) -> &[f64] {
        &self.c_pos
    }

    /// Per-pixel negative thresholds (row-major).
    pub fn thresholds_neg(&self) -> &[f64] {
        &self.c_neg
    }

    /// Indices of the hot pixels.
    pub fn hot_pixels(&self) -> &[u32] {
        &self.hot
    }

    /// Feed the luminance frame at time `t` (row-major `width·height`, linear); the
    /// events since the previous frame are appended to `out`, sorted by time. The first
    /// frame only sets the reference levels. Returns the number of events appended.
    pub fn push_frame(
        &mut self,
        t: f64,
        luminance: &[f32],
        out: &mut EventStream,
    ) -> Result<usize> {
        self.push_frame_flagged(t, luminance, out, None)
    }

    /// As [`Self::push_frame`], also appending to `noise` one flag per event (`true` for
    /// shot-noise and hot-pixel events).
    pub fn push_frame_flagged(
        &mut self,
        t: f64,
        luminance: &[f32],
        out: &mut EventStream,
        noise: Option<&mut Vec<bool>>,
    ) -> Result<usize> {
        let (w, h) = (self.width as usize, self.height as usize);
        if luminance.len() != w * h {
            return Err(Error::Other(format!(
                "simulator: frame has {} values, expected {}x{} = {}",
                luminance.len(),
                w,
                h,
                w * h
            )));
        }
        if !t.is_finite() {
            return Err(Error::Other(format!(
                "simulator: frame time {t} is not finite"
            )));
        }
        if let Some(bad) = luminance.iter().position(|v| !v.is_finite() || *v < 0.0) {
            return Err(Error::Other(format!(
                "simulator: frame at t = {t}: luminance {} at pixel {bad} is not finite and ≥ 0",
                luminance[bad]
            )));
        }
        let eps = self.cfg.log_eps;
        let Some(t0) = self.prev_t else {
            for (i, &y) in luminance.iter().enumerate() {
                let l = (eps + y as f64).ln();
                self.prev_log[i] = l;
                self.reference[i] = l;
            }
            self.prev_t = Some(t);
            self.frame_index += 1;
            return Ok(0);
        };
        if t <= t0 {
            return Err(Error::Other(format!(
                "simulator: frame times must increase ({t} after {t0})"
            )));
        }
        let refractory = self.cfg.refractory_s;
        let dt = t - t0;

        // Threshold crossings, row-parallel; each row collects its own events.
        let rows: Vec<Vec<Ev>> = self
            .reference
            .par_chunks_mut(w)
            .zip(self.prev_log.par_chunks_mut(w))
            .zip(self.last_event.par_chunks_mut(w))
            .zip(self.c_pos.par_chunks(w))
            .zip(self.c_neg.par_chunks(w))
            .zip(luminance.par_chunks(w))
            .enumerate()
            .map(|(y, (((((refs, prev), last), cp), cn), lum))| {
                let mut evs = Vec::new();
                for x in 0..w {
                    let l0 = prev[x];
                    let l1 = (eps + lum[x] as f64).ln();
                    prev[x] = l1;
                    let dl = l1 - l0;
                    let mut r = refs[x];
                    loop {
                        // A crossing that lands exactly on the level (a pixel back at
                        // an earlier value) fires: the reference, a sum of thresholds,
                        // misses it by rounding otherwise (TIE, far below any C).
                        let p = if l1 - r >= cp[x] - TIE {
                            r += cp[x];
                            1
                        } else if r - l1 >= cn[x] - TIE {
                            r -= cn[x];
                            -1
                        } else {
                            break;
                        };
                        // Linear interpolation of L between the frames (ESIM).
                        let frac = if dl != 0.0 {
                            ((r - l0) / dl).clamp(0.0, 1.0)
                        } else {
                            1.0
                        };
                        let te = t0 + frac * dt;
                        if te - last[x] >= refractory {
                            last[x] = te;
                            evs.push(Ev {
                                t: te,
                                x: x as u16,
                                y: y as u16,
                                p,
                                noise: false,
                            });
                        }
                    }
                    refs[x] = r;
                }
                evs
            })
            .collect();

        let mut evs = std::mem::take(&mut self.scratch);
        evs.clear();
        for row in rows {
            evs.extend_from_slice(&row);
        }
        self.add_noise(t0, t, &mut evs);
        evs.par_sort_unstable_by(|a, b| {
            a.t.total_cmp(&b.t)
                .then(a.y.cmp(&b.y))
                .then(a.x.cmp(&b.x))
                .then(a.p.cmp(&b.p))
                .then(a.noise.cmp(&b.noise))
        });
        out.t.reserve(evs.len());
        out.x.reserve(evs.len());
        out.y.reserve(evs.len());
        out.p.reserve(evs.len());
        for e in &evs {
            out.push(e.t, e.x, e.y, e.p);
        }
        if let Some(flags) = noise {
            flags.extend(evs.iter().map(|e| e.noise));
        }
        let n = evs.len();
        self.scratch = evs;
        self.prev_t = Some(t);
        self.frame_index += 1;
        Ok(n)
    }

    /// Shot noise and hot pixels in `(t0, t1]`, from the frame's own RNG stream.
    fn add_noise(&self, t0: f64, t1: f64, evs: &mut Vec<Ev>) {
        let dt = t1 - t0;
        let n_pix = self.width as u64 * self.height as u64;
        let shot_rate = self.cfg.shot_noise_hz * n_pix as f64 * dt;
        let hot_rate = self.cfg.hot_pixel_hz * dt;
        if shot_rate <= 0.0 && (self.hot.is_empty() || hot_rate <= 0.0) {
            return;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        rng.set_stream(self.frame_index);
        let time = |rng: &mut ChaCha8Rng| t1 - dt * rng.random::<f64>(); // in (t0, t1]
        if shot_rate > 0.0 {
            let count = poisson(&mut rng, shot_rate);
            for _ in 0..count {
                let pix = rng.random_range(0..n_pix);
                let te = time(&mut rng);
                let p = if rng.random::<bool>() { 1 } else { -1 };
                evs.push(Ev {
                    t: te,
                    x: (pix % self.width as u64) as u16,
                    y: (pix / self.width as u64) as u16,
                    p,
                    noise: true,
                });
            }
        }
        if hot_rate > 0.0 {
            for &pix in &self.hot {
                for _ in 0..poisson(&mut rng, hot_rate) {
                    let te = time(&mut rng);
                    evs.push(Ev {
                        t: te,
                        x: (pix % self.width) as u16,
                        y: (pix / self.width) as u16,
                        p: 1,
                        noise: true,
                    });
                }
            }
        }
    }
}

fn poisson(rng: &mut ChaCha8Rng, lambda: f64) -> u64 {
    match Poisson::new(lambda) {
        Ok(d) => d.sample(rng) as u64,
        Err(_) => 0,
    }
}
