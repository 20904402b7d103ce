//! Grey images between the train frames from the events, for tracks to be chained
//! through where the frames alone are too far apart for Lucas–Kanade (issue #30: the
//! `fast` preset's half-turns between frames).
//!
//! At `steps` times evenly inside each frame interval `[t_a, t_b]` the image is the
//! two-sided event pseudo image in log intensity,
//! `L(t) = (1 − s)·(log I_a + C·N(t_a, t)) + s·(log I_b − C·N(t, t_b))`, `s` the fraction
//! of the interval, `N` a pixel's signed event count, `C` the contrast threshold. Two
//! consecutive images differ by `C` times the events between them plus the interval's
//! residual (what the frames and the events disagree on) spread evenly over time, so a
//! window's brightness change from one to the next is the events' own and its motion a
//! fraction of the interval's. The images are shown back in the frames' encoding (sRGB
//! unless the manifest says linear) so that Lucas–Kanade's texture threshold means the
//! same on them as on the frames.

use super::lk::Grey;
use scene::EventSlice;
use scene::image_io::{linear_to_srgb, srgb_to_linear};

/// Added to linear intensity before the logarithm, so that black pixels stay finite.
const LOG_EPS: f32 = 1e-3;

/// What the event images need besides the frames.
pub struct EventSource<'a> {
    pub events: EventSlice<'a>,
    /// The train frames' times, seconds on the events' clock.
    pub seconds: &'a [f64],
    /// Contrast threshold `C` (log intensity per event).
    pub contrast: f32,
    /// Whether the frames (and the images made here) are sRGB-encoded.
    pub srgb: bool,
    /// Images per frame interval.
    pub steps: usize,
}

/// For each frame interval `k` (between `grey[k]` and `grey[k + 1]`), the `src.steps`
/// event images inside it, earliest first; empty for the last frame.
pub fn between(grey: &[Grey], src: &EventSource) -> Vec<Vec<Grey>> {
    use rayon::prelude::*;
    assert_eq!(
        grey.len(),
        src.seconds.len(),
        "event images: one time per frame"
    );
    let logs: Vec<Vec<f32>> = grey.par_iter().map(|g| log_image(g, src.srgb)).collect();
    (0..grey.len())
        .into_par_iter()
        .map(|k| {
            if k + 1 >= grey.len() || src.steps == 0 {
                return Vec::new();
            }
            interval(&grey[k], &logs[k], &logs[k + 1], k, src)
        })
        .collect()
}

fn log_image(g: &Grey, srgb: bool) -> Vec<f32> {
    (g.data.iter())
        .map(|&v| {
            let lin = if srgb { srgb_to_linear(v) } else { v };
            (lin.max(0.0) + LOG_EPS).ln()
        })
        .collect()
}

/// The images of interval `k`: the signed counts are swept once through the interval's
/// events, an image made at each step's time.
fn interval(like: &Grey, la: &[f32], lb: &[f32], k: usize, src: &EventSource) -> Vec<Grey> {
    let (ta, tb) = (src.seconds[k], src.seconds[k + 1]);
    let ev = src.events.window(ta, tb);
    let w = like.width;
    let n = w * like.height;
    // The whole interval's counts first: the right side needs N(t, t_b) = N − N(t_a, t).
    let mut total = vec![0i32; n];
    let pixel = |i: usize| ev.y[i] as usize * w + ev.x[i] as usize;
    for i in 0..ev.len() {
        let p = pixel(i);
        if p < n {
            total[p] += ev.p[i].signum() as i32;
        }
    }
    let mut left = vec![0i32; n];
    let mut next = 0;
    let c = src.contrast;
    (1..=src.steps)
        .map(|j| {
            let s = j as f64 / (src.steps + 1) as f64;
            let t = ta + s * (tb - ta);
            while next < ev.len() && ev.t[next] < t {
                let p = pixel(next);
                if p < n {
                    left[p] += ev.p[next].signum() as i32;
                }
                next += 1;
            }
            let s = s as f32;
            let data = (0..n)
                .map(|p| {
                    let (nl, nr) = (left[p] as f32, (total[p] - left[p]) as f32);
                    let l = (1.0 - s) * (la[p] + c * nl) + s * (lb[p] - c * nr);
                    let lin = (l.exp() - LOG_EPS).clamp(0.0, 1.0);
                    if src.srgb { linear_to_srgb(lin) } else { lin }
                })
                .collect();
            Grey {
                width: w,
                height: like.height,
                data,
            }
        })
        .collect()
}
