//! The contrast estimate on events made by `synth`'s simulator with a known `C`.

use crate::contrast::{EstimateSettings, estimate_contrast};
use crate::event_counts::{CountSettings, EventCounts};
use scene::EventStream;
use synth::{SimConfig, Simulator};

const W: usize = 24;
const H: usize = 16;
/// Simulator rate and the train frames' spacing (s).
const SIM_HZ: f64 = 1000.0;
const FRAME_DT: f64 = 0.1;
const FRAMES: usize = 7;
const PRE_ROLL: f64 = 1.0;

/// Luminance of pixel `i` at `t`: a per-pixel log-brightness oscillation (random
/// amplitude, phase and rate), so intervals see changes of both signs and every size.
fn luminance(i: usize, t: f64) -> f32 {
    let h = |k: u64| {
        let mut z = (i as u64 * 0x9E37_79B9 + k).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z ^= z >> 29;
        (z % 10_000) as f64 / 10_000.0
    };
    let (amp, phase, hz) = (
        0.3 + 1.2 * h(1),
        std::f64::consts::TAU * h(2),
        0.5 + 2.5 * h(3),
    );
    (0.12 * (amp * (std::f64::consts::TAU * hz * t + phase).sin()).exp()) as f32
}

/// Events of the simulator over the recording and the train frames (planar RGB, grey).
fn record(cfg: &SimConfig, seed: u64) -> (EventStream, Vec<f64>, Vec<Vec<f32>>) {
    let mut sim = Simulator::new(W as u32, H as u32, cfg, seed);
    let mut events = EventStream::new(W as u32, H as u32);
    // The sensor runs for PRE_ROLL s before the first frame, so that the pixels'
    // reference levels are not the first frame itself.
    let steps = ((FRAMES - 1) as f64 * FRAME_DT * SIM_HZ).round() as i64;
    let pre = (PRE_ROLL * SIM_HZ).round() as i64;
    for s in -pre..=steps {
        let t = s as f64 / SIM_HZ;
        let y: Vec<f32> = (0..W * H).map(|i| luminance(i, t)).collect();
        sim.push_frame(t, &y, &mut events).unwrap();
    }
    let times: Vec<f64> = (0..FRAMES).map(|k| k as f64 * FRAME_DT).collect();
    let frames = times
        .iter()
        .map(|&t| {
            let y: Vec<f32> = (0..W * H).map(|i| luminance(i, t)).collect();
            y.repeat(3)
        })
        .collect();
    (events, times, frames)
}

fn sim_config(c_pos: f64, c_neg: f64) -> SimConfig {
    SimConfig {
        threshold_pos: c_pos,
        threshold_neg: c_neg,
        threshold_sigma: 0.0,
        log_eps: 1e-3,
        ..SimConfig::default()
    }
}

fn estimate(
    ev: &EventStream,
    times: &[f64],
    frames: &[Vec<f32>],
) -> Result<crate::contrast::ContrastEstimate, String> {
    estimate_contrast(
        frames,
        3,
        times,
        &ev.as_slice(),
        1e-3,
        &EstimateSettings::default(),
    )
}

#[test]
fn estimate_recovers_the_simulators_threshold_with_a_tight_spread() {
    for c in [0.05, 0.1, 0.2] {
        let (ev, times, frames) = record(&sim_config(c, c), 1);
        let e = estimate(&ev, &times, &frames).unwrap();
        let rel = (e.c - c).abs() / c;
        assert!(rel < 0.03, "C = {c}: estimate {e:?}");
        for side in [e.c_pos.unwrap(), e.c_neg.unwrap()] {
            assert!((side - c).abs() / c < 0.05, "C = {c}: {e:?}");
        }
        // The spread is real (not 0), small, and its interval holds the estimate.
        let (std, ci) = (e.std.unwrap(), e.ci95.unwrap());
        assert!(std > 0.0 && std < 0.02 * c, "C = {c}: {e:?}");
        assert!(ci[0] < e.c && e.c < ci[1], "{e:?}");
        assert!(ci[1] - ci[0] < 0.08 * c, "{e:?}");
        assert!(e.inliers > 500 && e.inliers <= e.pixels, "{e:?}");
        // Rounding of the count: the residuals are within an event.
        assert!(e.residual_mad < 0.6, "{e:?}");
    }
}

#[test]
fn estimate_separates_positive_and_negative_thresholds() {
    let (ev, times, frames) = record(&sim_config(0.2, 0.1), 2);
    let e = estimate(&ev, &times, &frames).unwrap();
    let (cp, cn) = (e.c_pos.unwrap(), e.c_neg.unwrap());
    assert!((cp - 0.2).abs() < 0.2 * 0.05, "{e:?}");
    assert!((cn - 0.1).abs() < 0.1 * 0.05, "{e:?}");
    assert!(e.c > cn && e.c < cp, "{e:?}");
}

#[test]
fn estimate_survives_hot_pixels_noise_and_threshold_mismatch() {
    let cfg = SimConfig {
        threshold_sigma: 0.01,
        shot_noise_hz: 2.0,
        hot_pixel_fraction: 0.03,
        hot_pixel_hz: 300.0,
        ..sim_config(0.1, 0.1)
    };
    let (ev, times, frames) = record(&cfg, 3);
    let e = estimate(&ev, &times, &frames).unwrap();
    // A per-pixel mismatch σ gives about the harmonic mean of the pixels' C (≈ C·(1 −
    // σ²/C²), 1 % here); hot pixels (tens of events) are cut as outliers.
    assert!((e.c - 0.1).abs() < 0.1 * 0.04, "{e:?}");
    assert!(e.inliers < e.pixels, "no outlier dropped: {e:?}");
}

#[test]
fn too_little_signal_is_an_error_not_a_guess() {
    // A static scene: no pixel changes by 0.2 in log.
    let (mut ev, times, mut frames) = record(&sim_config(0.1, 0.1), 4);
    let first = frames[0].clone();
    frames.iter_mut().for_each(|f| f.clone_from(&first));
    let err = estimate(&ev, &times, &frames).unwrap_err();
    assert!(
        err.contains("too little signal") && err.contains("0 pixel"),
        "{err}"
    );
    // All black or saturated frames: nothing passes the brightness checks.
    let (_, _, frames) = record(&sim_config(0.1, 0.1), 4);
    for v in [0.0f32, 1.0] {
        let flat: Vec<Vec<f32>> = frames.iter().map(|f| vec![v; f.len()]).collect();
        assert!(estimate(&ev, &times, &flat).is_err());
    }
    // Events of the opposite sign to every change: no positive C fits.
    ev.p.iter_mut().for_each(|p| *p = -*p);
    let (_, _, frames) = record(&sim_config(0.1, 0.1), 4);
    assert!(estimate(&ev, &times, &frames).is_err());
}

#[test]
fn learning_c_through_the_event_loss_finds_the_true_threshold() {
    use crate::contrast::LearnedContrast;
    use crate::event_image::{
        PseudoImage, PseudoInputs, PseudoMode, PseudoSettings, event_loss, pseudo_image,
    };
    let c_true = 0.1;
    let (ev, times, frames) = record(&sim_config(c_true, c_true), 5);
    let sl = ev.as_slice();
    let counts = EventCounts::build(&sl, &times, &CountSettings { bins: 8 }).unwrap();
    let s = PseudoSettings {
        log_eps: 1e-3,
        ..PseudoSettings::default()
    };
    for c0 in [0.5 * c_true, 2.0 * c_true] {
        let mut learned = LearnedContrast::new(c0, 0.02);
        let mut out = PseudoImage::<f64>::default();
        for step in 0..400 {
            // A perfect render at an in-between time of a rotating interval.
            let j = step % (FRAMES - 1);
            let t_e = times[j] + FRAME_DT * (0.15 + 0.7 * ((step * 7) % 10) as f64 / 10.0);
            let render: Vec<f64> = (0..W * H)
                .map(|i| f64::from(luminance(i, t_e)))
                .collect::<Vec<_>>()
                .repeat(3);
            let (left, right): (Vec<f64>, Vec<f64>) = (
                frames[j].iter().map(|&v| f64::from(v)).collect(),
                frames[j + 1].iter().map(|&v| f64::from(v)).collect(),
            );
            let inp = PseudoInputs {
                counts: &counts.intervals()[j],
                events: Some(&sl),
                left: &left,
                right: &right,
                channels: 3,
                contrast: learned.value(),
            };
            pseudo_image(&inp, t_e, PseudoMode::Nearest, &s, &mut out);
            let l = event_loss(&render, &out, None);
            learned.step(l.d_contrast);
        }
        let c = learned.value();
        assert!((c - c_true).abs() < 0.05 * c_true, "from {c0}: learned {c}");
    }
}
