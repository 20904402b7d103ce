//! What a user could do without a 3D model, scored on the same held-out frames: the
//! nearest train frame in time, the linear blend of the two neighbouring train frames,
//! and the two-sided event pseudo image of Eq. 11 (both neighbours carried to the test
//! time by the events between, blended in log space by the distance in time; pixels the
//! event model cannot predict — black or saturated — take the linear blend). A 3D model
//! that loses to these at in-between times is not yet worth its training time.

use crate::event_counts::{CountSettings, EventCounts};
use crate::event_image::{
    PseudoImage, PseudoInputs, PseudoMode, PseudoSettings, linear_to_srgb, pseudo_image,
    srgb_to_linear,
};
use gaussians::evaluation::{Lpips, lpips_planar};
use gaussians::stage::PSNR_CAP;
use gaussians::train::View;
use scene::events::EventStream;
use scene::metrics::{psnr_u8, ssim_u8};
use serde::Serialize;

/// PSNR (at most `gaussians::stage::PSNR_CAP`), SSIM and LPIPS of one baseline over the
/// test frames.
#[derive(Clone, Debug, Default, Serialize)]
pub struct BaselineScore {
    pub psnr_mean: f64,
    pub ssim_mean: f64,
    pub psnr: Vec<f64>,
    /// LPIPS (VGG16) as the model's (`gaussians::evaluation`); absent when the model's
    /// has none (its `lpips_note` says why) or a pair could not be scored.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lpips_mean: Option<f64>,
    /// The predictions themselves, one per test frame (planar RGB in the frames'
    /// stored encoding, like [`View::rgb`]), for a user to look at.
    #[serde(skip)]
    pub images: Vec<Vec<f32>>,
}

/// The three baselines (`events` is absent when the recording has no events).
#[derive(Clone, Debug, Default, Serialize)]
pub struct Baselines {
    pub nearest: BaselineScore,
    pub blend: BaselineScore,
    pub events: Option<BaselineScore>,
}

/// What the baselines see of a recording: the train views (planar, stored encoding)
/// with their times in seconds, the event stream, the contrast threshold and whether
/// the frames are sRGB.
pub struct Recording<'a> {
    pub train: &'a [View],
    pub times: &'a [f64],
    pub events: Option<&'a EventStream>,
    pub contrast: f64,
    pub srgb: bool,
}

/// Neighbouring train frames of time `t` and the blend weight of the right one.
fn neighbours(times: &[f64], t: f64) -> (usize, usize, f64) {
    let n = times.len();
    if n < 2 || t <= times[0] {
        return (0, 0, 0.0);
    }
    if t >= times[n - 1] {
        return (n - 1, n - 1, 0.0);
    }
    let j = times.partition_point(|&k| k <= t) - 1;
    let span = times[j + 1] - times[j];
    let s = if span > 0.0 {
        (t - times[j]) / span
    } else {
        0.0
    };
    (j, j + 1, s)
}

fn score(preds: Vec<Vec<f32>>, targets: &[&View], lpips: Option<&Lpips>) -> BaselineScore {
    let mut out = BaselineScore::default();
    let mut ssim = 0.0;
    for (p, v) in preds.iter().zip(targets) {
        let (w, h) = (
            v.camera.intrinsics.width as usize,
            v.camera.intrinsics.height as usize,
        );
        out.psnr.push(psnr_u8(p, &v.rgb).min(PSNR_CAP));
        ssim += ssim_u8(p, &v.rgb, w, h);
    }
    let n = preds.len().max(1) as f64;
    out.psnr_mean = out.psnr.iter().sum::<f64>() / n;
    out.ssim_mean = ssim / n;
    let size = |v: &View| {
        let k = &v.camera.intrinsics;
        (k.width as usize, k.height as usize)
    };
    let lpips: Option<Vec<f64>> = lpips.filter(|_| !preds.is_empty()).and_then(|m| {
        let pair = |(p, v): (&Vec<f32>, &&View)| {
            let (w, h) = size(v);
            lpips_planar(m, p, &v.rgb, w, h).ok()
        };
        preds.iter().zip(targets).map(pair).collect()
    });
    out.lpips_mean = lpips.map(|l| l.iter().sum::<f64>() / n);
    out.images = preds;
    out
}

/// Score the baselines on `test` views whose times (seconds) are `test_times`, LPIPS
/// with `lpips` when given.
pub fn evaluate(
    rec: &Recording<'_>,
    test: &[View],
    test_times: &[f64],
    lpips: Option<&Lpips>,
) -> Baselines {
    let targets: Vec<&View> = test.iter().collect();
    let mut nearest: Vec<Vec<f32>> = Vec::new();
    let mut blend: Vec<Vec<f32>> = Vec::new();
    for &t in test_times {
        let (a, b, s) = neighbours(rec.times, t);
        let near = if s <= 0.5 { a } else { b };
        nearest.push(rec.train[near].rgb.clone());
        let (fa, fb) = (&rec.train[a].rgb, &rec.train[b].rgb);
        let s = s as f32;
        blend.push(
            fa.iter()
                .zip(fb)
                .map(|(x, y)| (1.0 - s) * x + s * y)
                .collect(),
        );
    }
    let events = rec
        .events
        .filter(|e| !e.is_empty() && rec.times.len() >= 2)
        .map(|ev| {
            let to_linear = |v: &[f32]| -> Vec<f32> {
                if rec.srgb {
                    v.iter().map(|&c| srgb_to_linear(c)).collect()
                } else {
                    v.to_vec()
                }
            };
            let linear: Vec<Vec<f32>> = rec.train.iter().map(|v| to_linear(&v.rgb)).collect();
            let settings = CountSettings::default();
            let all = ev.as_slice();
            let counts = EventCounts::build(&all, rec.times, &settings).ok();
            let mut img = PseudoImage::<f32>::default();
            let preds = test_times
                .iter()
                .zip(&blend)
                .map(|(&t, fallback)| {
                    let (a, b, _) = neighbours(rec.times, t);
                    let Some(counts) = counts.as_ref().filter(|_| b == a + 1) else {
                        return fallback.clone();
                    };
                    let inp = PseudoInputs {
                        counts: &counts.intervals()[a],
                        events: Some(&all),
                        left: &linear[a],
                        right: &linear[b],
                        channels: 3,
                        contrast: rec.contrast as f32,
                    };
                    let s = PseudoSettings::default();
                    pseudo_image(&inp, t, PseudoMode::TwoSided, &s, &mut img);
                    img.data
                        .iter()
                        .zip(&img.valid)
                        .zip(fallback)
                        .map(|((&p, &ok), &f)| match (ok, rec.srgb) {
                            (false, _) => f,
                            (true, true) => linear_to_srgb(p),
                            (true, false) => p,
                        })
                        .collect()
                })
                .collect::<Vec<Vec<f32>>>();
            score(preds, &targets, lpips)
        });
    Baselines {
        nearest: score(nearest, &targets, lpips),
        blend: score(blend, &targets, lpips),
        events,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use scene::{Camera, Intrinsics, Pose};

    fn view(v: f32) -> View {
        let camera = Camera {
            intrinsics: Intrinsics::from_fov_x(4, 2, 1.0),
            cam_to_world: Pose::default(),
        };
        View {
            camera,
            time: 0.0,
            rgb: vec![v; 3 * 8],
        }
    }

    #[test]
    fn blend_is_exact_on_a_linear_ramp_and_nearest_is_not() {
        let train = [view(0.2), view(0.6)];
        let rec = Recording {
            train: &train,
            times: &[0.0, 1.0],
            events: None,
            contrast: 0.1,
            srgb: false,
        };
        let test = [view(0.3)];
        let b = evaluate(&rec, &test, &[0.25], None);
        assert_eq!(b.blend.psnr[0], PSNR_CAP);
        let want = scene::metrics::psnr_u8(&[0.2; 24], &[0.3; 24]);
        assert!((b.nearest.psnr[0] - want).abs() < 1e-12);
        assert!(b.events.is_none());
    }

    #[test]
    fn neighbours_clamp_outside_and_split_inside() {
        let t = [0.0, 1.0, 3.0];
        assert_eq!(neighbours(&t, -1.0), (0, 0, 0.0));
        assert_eq!(neighbours(&t, 5.0), (2, 2, 0.0));
        assert_eq!(neighbours(&t, 2.0), (1, 2, 0.5));
    }
}
