use super::{Rng, assert_close, fd};
use crate::event_counts::{CountSettings, EventCounts, IntervalCounts};
use crate::event_image::{
    EventChannels, PseudoImage, PseudoInputs, PseudoMode, PseudoSettings, event_loss,
    linear_to_srgb, planar_linear, planar_luminance, pseudo_image, render_event_loss,
    srgb_to_linear,
};
use scene::{EventStream, Image};

const W: usize = 9;
const H: usize = 7;

/// Random events over `[0, 1.2)` on a `W × H` sensor, sorted, with some exactly on
/// frame times and bin edges.
fn stream(rng: &mut Rng, n: usize) -> EventStream {
    let mut t: Vec<f64> = (0..n).map(|_| rng.uniform(0.0, 1.2)).collect();
    t.extend([0.0, 0.25, 0.5, 0.5, 1.0, 0.5 + 0.5 / 16.0]);
    t.sort_by(f64::total_cmp);
    let mut ev = EventStream::new(W as u32, H as u32);
    for &ti in &t {
        let x = (rng.next_u64() % W as u64) as u16;
        let y = (rng.next_u64() % H as u64) as u16;
        ev.push(
            ti,
            x,
            y,
            if rng.next_u64().is_multiple_of(3) {
                -1
            } else {
                1
            },
        );
    }
    ev
}

fn brute(ev: &EventStream, ta: f64, tb: f64) -> Vec<f32> {
    let mut out = vec![0.0f32; W * H];
    let (lo, hi, s) = if ta <= tb {
        (ta, tb, 1.0)
    } else {
        (tb, ta, -1.0)
    };
    for i in 0..ev.len() {
        if ev.t[i] >= lo && ev.t[i] < hi {
            out[ev.y[i] as usize * W + ev.x[i] as usize] += s * ev.p[i] as f32;
        }
    }
    out
}

#[test]
fn exact_counts_equal_brute_force_and_interpolation_error_is_bounded() {
    let mut rng = Rng::new(3);
    let ev = stream(&mut rng, 3000);
    let sl = ev.as_slice();
    let all = EventCounts::build(&sl, &[0.0, 0.5, 1.0], &CountSettings { bins: 16 }).unwrap();
    let k = &all.intervals()[1];
    assert_eq!(k.span(), (0.5, 1.0));
    assert!(k.is_compact());
    let mut out = vec![0.0f32; W * H];
    let edge = 0.5 + 0.5 * 3.0 / 16.0;
    let queries = [
        (0.5, 1.0),
        (0.5, 0.77),
        (0.61, 0.93),
        (edge, 0.9),
        (0.5, edge),
        (0.8, 0.6), // reversed: negated
        (0.3, 1.4), // clamped to the interval
        (0.7, 0.7),
    ];
    for &(ta, tb) in &queries {
        k.signed_counts(ta, tb, Some(&sl), &mut out);
        let want = brute(&ev, ta.clamp(0.5, 1.0), tb.clamp(0.5, 1.0));
        assert_eq!(out, want, "exact [{ta}, {tb})");
        // Interpolated: exact at bin edges, else off by at most the pixel's events in
        // the two partial bins.
        k.signed_counts(ta, tb, None, &mut out);
        for (i, (&a, &b)) in out.iter().zip(&want).enumerate() {
            let bin = |t: f64| {
                let t = t.clamp(0.5, 1.0);
                let b = (((t - 0.5) / 0.5 * 16.0).floor() as usize).min(15);
                let (lo, hi) = (0.5 + b as f64 / 32.0, 0.5 + (b + 1) as f64 / 32.0);
                (0..ev.len())
                    .filter(|&j| {
                        ev.t[j] >= lo
                            && ev.t[j] < hi
                            && ev.y[j] as usize * W + ev.x[j] as usize == i
                    })
                    .count() as f32
            };
            let bound = bin(ta) + bin(tb);
            assert!(
                (a - b).abs() <= bound + 1e-5,
                "interp [{ta}, {tb}) px {i}: {a} vs {b} (bound {bound})"
            );
        }
        let (x, y) = (4, 3);
        assert!((k.count_at(x, y, ta, tb) - out[y * W + x]).abs() < 1e-5);
    }
    k.signed_counts(0.5, edge, None, &mut out);
    assert_eq!(
        out,
        brute(&ev, 0.5, edge),
        "interpolated counts are exact on bin edges"
    );
    // The event exactly at t = 0.5 belongs to the second interval, not the first.
    let first = &all.intervals()[0];
    first.signed_counts(0.0, 0.5, Some(&sl), &mut out);
    assert_eq!(out, brute(&ev, 0.0, 0.5));
    assert_eq!(all.interval_of(0.5), Some(1));
    assert_eq!(all.interval_of(1.0), Some(1));
    assert_eq!(all.interval_of(0.0), Some(0));
    assert_eq!(all.interval_of(1.01), None);
    assert_eq!(all.interval_of(f64::NAN), None);
    assert!(all.memory_bytes() >= 2 * 16 * W * H * 2);
}

#[test]
fn edge_cases_zero_events_one_pixel_equal_times() {
    // No events: all zero.
    let empty = EventStream::new(W as u32, H as u32);
    let k = IntervalCounts::build(&empty.as_slice(), 0.0, 1.0, 8);
    let mut out = vec![1.0f32; W * H];
    k.signed_counts(0.1, 0.9, Some(&empty.as_slice()), &mut out);
    assert!(out.iter().all(|&v| v == 0.0));
    // All events in one pixel, more than i16 holds: stored as i32, still exact.
    let mut ev = EventStream::new(W as u32, H as u32);
    for i in 0..40_000 {
        ev.push(i as f64 / 40_000.0, 2, 5, 1);
    }
    let k = IntervalCounts::build(&ev.as_slice(), 0.0, 1.0, 32);
    assert!(!k.is_compact());
    k.signed_counts(0.0, 1.0, Some(&ev.as_slice()), &mut out);
    assert_eq!(out[5 * W + 2], 40_000.0);
    assert_eq!(out.iter().filter(|&&v| v != 0.0).count(), 1);
    k.signed_counts(0.0, 0.3, None, &mut out);
    assert!((out[5 * W + 2] - 12_000.0).abs() <= 1.0);
    // Two frames at the same time: an empty interval, zero counts, no NaN.
    let mut rng = Rng::new(1);
    let ev = stream(&mut rng, 200);
    let all = EventCounts::build(
        &ev.as_slice(),
        &[0.0, 0.5, 0.5, 1.0],
        &CountSettings::default(),
    )
    .unwrap();
    let z = &all.intervals()[1];
    assert_eq!(z.span(), (0.5, 0.5));
    z.signed_counts(0.5, 0.5, Some(&ev.as_slice()), &mut out);
    assert!(out.iter().all(|&v| v == 0.0));
    z.signed_counts(0.2, 0.9, None, &mut out);
    assert!(out.iter().all(|&v| v == 0.0));
    assert_eq!(all.interval_of(0.5), Some(2));
    // A pseudo image on the empty interval is the left frame, in both modes.
    let (l, r) = (vec![0.3f64; 3 * W * H], vec![0.6f64; 3 * W * H]);
    let inp = PseudoInputs {
        counts: z,
        events: None,
        left: &l,
        right: &r,
        channels: 3,
        contrast: 0.2,
    };
    let mut p = PseudoImage::default();
    for mode in [PseudoMode::Nearest, PseudoMode::TwoSided] {
        pseudo_image(&inp, 0.5, mode, &PseudoSettings::default(), &mut p);
        assert_eq!(p.data, l);
        assert_eq!(p.valid_count(), 3 * W * H);
    }
    assert!(EventCounts::build(&ev.as_slice(), &[1.0, 0.0], &CountSettings::default()).is_err());
    assert!(EventCounts::build(&ev.as_slice(), &[0.0, 1.0], &CountSettings { bins: 0 }).is_err());
    let one = EventCounts::build(&ev.as_slice(), &[0.3], &CountSettings::default()).unwrap();
    assert!(one.intervals().is_empty() && one.interval_of(0.3).is_none());
}

/// Frames and events that agree: each pixel's log brightness changes by `C` per event.
struct Consistent {
    ev: EventStream,
    left: Vec<f64>,
    right: Vec<f64>,
}

fn consistent(rng: &mut Rng, c: f64, eps: f64) -> Consistent {
    let n = W * H;
    let left: Vec<f64> = (0..3 * n).map(|_| rng.uniform(0.05, 0.5)).collect();
    let mut ev = EventStream::new(W as u32, H as u32);
    let mut total = vec![0i32; n];
    let mut list = vec![];
    for (i, tot) in total.iter_mut().enumerate() {
        let k = (rng.next_u64() % 6) as i32 - 2;
        for _ in 0..k.abs() {
            list.push((rng.uniform(0.0, 1.0), i, k.signum() as i8));
        }
        *tot = k;
    }
    list.sort_by(|a, b| a.0.total_cmp(&b.0));
    for (t, i, p) in list {
        ev.push(t, (i % W) as u16, (i / W) as u16, p);
    }
    let right = (0..3 * n)
        .map(|v| (left[v] + eps) * (c * total[v % n] as f64).exp() - eps)
        .collect();
    Consistent { ev, left, right }
}

#[test]
fn pseudo_image_follows_eq_11_and_both_sides_agree_on_consistent_data() {
    let mut rng = Rng::new(8);
    let c = 0.2;
    for eps in [0.0, 1e-3] {
        let d = consistent(&mut rng, c, eps);
        let sl = d.ev.as_slice();
        let k = IntervalCounts::build(&sl, 0.0, 1.0, 32);
        let s = PseudoSettings {
            log_eps: eps,
            black_level: 0.0,
            saturation: 10.0,
            band: 0.0,
        };
        let inp = PseudoInputs {
            counts: &k,
            events: Some(&sl),
            left: &d.left,
            right: &d.right,
            channels: 3,
            contrast: c,
        };
        let mut out = PseudoImage::default();
        for &te in &[0.0, 0.2, 0.5, 0.63, 1.0] {
            pseudo_image(&inp, te, PseudoMode::Nearest, &s, &mut out);
            let n = W * H;
            let (from_left, cnt) = if te <= 0.5 {
                (true, brute(&d.ev, 0.0, te))
            } else {
                (false, brute(&d.ev, te, 1.0))
            };
            for v in 0..3 * n {
                let want = if from_left {
                    (d.left[v] + eps) * (c * cnt[v % n] as f64).exp() - eps
                } else {
                    (d.right[v] + eps) / (c * cnt[v % n] as f64).exp() - eps
                };
                assert!(
                    (out.data[v] - want).abs() < 1e-12 && out.valid[v],
                    "t_e {te} value {v}"
                );
            }
            let nearest = out.data.clone();
            // On consistent data the two-sided blend equals either side.
            pseudo_image(&inp, te, PseudoMode::TwoSided, &s, &mut out);
            assert_close(
                &format!("two-sided at {te}"),
                &out.data,
                &nearest,
                1e-10,
                1e-12,
            );
        }
        // At the frame times the pseudo image is the frame itself.
        pseudo_image(&inp, 0.0, PseudoMode::TwoSided, &s, &mut out);
        assert_close("t0", &out.data, &d.left, 1e-12, 1e-14);
        pseudo_image(&inp, 1.0, PseudoMode::TwoSided, &s, &mut out);
        assert_close("t2", &out.data, &d.right, 1e-12, 1e-14);
        // Outside the interval: clamped.
        pseudo_image(&inp, -3.0, PseudoMode::Nearest, &s, &mut out);
        assert_close("clamped", &out.data, &d.left, 1e-12, 1e-14);
    }
}

#[test]
fn masks_black_and_saturated_frames_without_nan() {
    let mut rng = Rng::new(4);
    let d = consistent(&mut rng, 0.3, 0.0);
    let sl = d.ev.as_slice();
    let k = IntervalCounts::build(&sl, 0.0, 1.0, 32);
    let n = W * H;
    let black = vec![0.0f64; 3 * n];
    let white = vec![1.0f64; 3 * n];
    let bright = vec![0.9f64; 3 * n];
    let mut out = PseudoImage::default();
    for mode in [PseudoMode::Nearest, PseudoMode::TwoSided] {
        let s = PseudoSettings::default();
        let inp = PseudoInputs {
            counts: &k,
            events: Some(&sl),
            left: &black,
            right: &black,
            channels: 3,
            contrast: 0.3,
        };
        pseudo_image(&inp, 0.3, mode, &s, &mut out);
        assert_eq!(out.valid_count(), 0);
        assert!(out.data.iter().chain(&out.n_eff).all(|v| v.is_finite()));
        let render = vec![0.5f64; 3 * n];
        let mut g = vec![1.0; 3 * n];
        let l = event_loss(&render, &out, Some(&mut g));
        assert_eq!((l.loss, l.d_contrast, l.valid), (0.0, 0.0, 0));
        assert!(g.iter().all(|&v| v == 0.0));
        // Saturated (clipped) frames: nothing can be predicted from them.
        let inp = PseudoInputs {
            left: &white,
            right: &white,
            ..inp
        };
        pseudo_image(&inp, 0.4, mode, &s, &mut out);
        assert_eq!(out.valid_count(), 0, "{mode:?}");
        assert!(out.data.iter().chain(&out.n_eff).all(|v| v.is_finite()));
        // Bright frames: exactly the pixels whose prediction exceeds 1 are masked.
        let inp = PseudoInputs {
            left: &bright,
            right: &bright,
            ..inp
        };
        pseudo_image(&inp, 0.4, mode, &s, &mut out);
        let cnt = brute(&d.ev, 0.0, 0.4);
        let cnt_r = brute(&d.ev, 0.4, 1.0);
        let mut masked = 0;
        for v in 0..3 * n {
            let x = match mode {
                PseudoMode::Nearest => cnt[v % n] as f64,
                // blend of +C·N_l and −C·N_r in log space
                PseudoMode::TwoSided => 0.6 * cnt[v % n] as f64 - 0.4 * cnt_r[v % n] as f64,
            };
            let up = 0.9 * (0.3 * x).exp() > 1.0;
            masked += usize::from(up);
            assert_eq!(out.valid[v], !up, "{mode:?} value {v}");
        }
        assert!(masked > 0 && masked < 3 * n, "{mode:?}: {masked} masked");
    }
    // Black on one side only: the two-sided image falls back to the other side.
    let s = PseudoSettings::default();
    let inp = PseudoInputs {
        counts: &k,
        events: Some(&sl),
        left: &black,
        right: &d.right,
        channels: 3,
        contrast: 0.3,
    };
    pseudo_image(&inp, 0.2, PseudoMode::TwoSided, &s, &mut out);
    let cnt = brute(&d.ev, 0.2, 1.0);
    for v in 0..3 * n {
        if d.right[v] >= 0.01 && out.valid[v] {
            let want = d.right[v] / (0.3 * cnt[v % n] as f64).exp();
            assert!((out.data[v] - want).abs() < 1e-12);
        }
    }
    assert!(out.valid_count() > 0);
}

#[test]
fn event_loss_gradients_match_finite_differences() {
    let mut rng = Rng::new(6);
    let d = consistent(&mut rng, 0.25, 0.0);
    let sl = d.ev.as_slice();
    let k = IntervalCounts::build(&sl, 0.0, 1.0, 32);
    let n = W * H;
    // A mismatched right frame so the two sides disagree.
    let right: Vec<f64> = d.right.iter().map(|&v| v * rng.uniform(0.8, 1.2)).collect();
    let render: Vec<f64> = (0..3 * n).map(|_| rng.uniform(0.0, 0.8)).collect();
    for (mode, te, eps, band) in [
        (PseudoMode::Nearest, 0.3, 0.0, 0.0),
        (PseudoMode::Nearest, 0.8, 1e-3, 0.0),
        (PseudoMode::TwoSided, 0.45, 0.0, 0.0),
        (PseudoMode::TwoSided, 0.7, 1e-3, 0.0),
        (PseudoMode::Nearest, 0.3, 0.0, 1.0),
        (PseudoMode::TwoSided, 0.7, 1e-3, 0.5),
    ] {
        let s = PseudoSettings {
            log_eps: eps,
            black_level: 0.01,
            saturation: 100.0,
            band,
        };
        let at = |c: f64, r: &[f64], g: Option<&mut [f64]>| {
            let inp = PseudoInputs {
                counts: &k,
                events: Some(&sl),
                left: &d.left,
                right: &right,
                channels: 3,
                contrast: c,
            };
            let mut out = PseudoImage::default();
            pseudo_image(&inp, te, mode, &s, &mut out);
            event_loss(r, &out, g)
        };
        let c = 0.25;
        let mut g = vec![0.0; 3 * n];
        let l = at(c, &render, Some(&mut g));
        assert_eq!(l.valid, 3 * n);
        let num_c = fd(&[c], 0, 1e-6, |x| at(x[0], &render, None).loss);
        assert_close(
            &format!("{mode:?} ∂L/∂C"),
            &[l.d_contrast],
            &[num_c],
            1e-6,
            1e-10,
        );
        for i in (0..3 * n).step_by(7) {
            let num = fd(&render, i, 1e-7, |x| at(c, x, None).loss);
            assert_close(
                &format!("{mode:?} ∂L/∂R[{i}]"),
                &[g[i]],
                &[num],
                1e-6,
                1e-10,
            );
        }
    }
}

/// `L_event` on a stored (sRGB or linear) render, on luminance or per channel: the
/// gradient w.r.t. each stored value against central differences, and the luminance
/// mode's loss equal to `event_loss` on the render's Rec. 709 luminance.
#[test]
fn render_event_loss_gradients_match_finite_differences() {
    let mut rng = Rng::new(11);
    let d = consistent(&mut rng, 0.2, 0.0);
    let sl = d.ev.as_slice();
    let k = IntervalCounts::build(&sl, 0.0, 1.0, 32);
    let n = W * H;
    let s = PseudoSettings {
        black_level: 0.01,
        saturation: 100.0,
        ..PseudoSettings::default()
    };
    let (ly, ry) = (planar_luminance(&d.left, n), planar_luminance(&d.right, n));
    // Stored values away from the sRGB curve's knee (0.04045), where it has a kink.
    let stored: Vec<f64> = (0..3 * n).map(|_| rng.uniform(0.1, 0.9)).collect();
    for channels in [EventChannels::Luminance, EventChannels::Rgb] {
        let (left, right, planes) = match channels {
            EventChannels::Luminance => (&ly, &ry, 1),
            EventChannels::Rgb => (&d.left, &d.right, 3),
        };
        let inp = PseudoInputs {
            counts: &k,
            events: Some(&sl),
            left,
            right,
            channels: planes,
            contrast: 0.2,
        };
        let mut p = PseudoImage::default();
        pseudo_image(&inp, 0.35, PseudoMode::Nearest, &s, &mut p);
        assert_eq!(p.data.len(), planes * n);
        for srgb in [false, true] {
            let mut g = vec![0.0; 3 * n];
            let l = render_event_loss(&stored, srgb, channels, &p, &mut g);
            assert!(l.valid > n / 2, "{channels:?}: {} valid", l.valid);
            let lin: Vec<f64> = if srgb {
                stored.iter().map(|&c| srgb_to_linear(c)).collect()
            } else {
                stored.clone()
            };
            if channels == EventChannels::Luminance {
                let y = planar_luminance(&lin, n);
                assert_eq!(
                    y[3],
                    0.2126 * lin[3] + 0.7152 * lin[n + 3] + 0.0722 * lin[2 * n + 3]
                );
                assert_eq!(l.loss, event_loss(&y, &p, None).loss);
            }
            let mut scratch = vec![0.0; 3 * n];
            for i in (0..3 * n).step_by(5) {
                let num = fd(&stored, i, 1e-7, |x| {
                    render_event_loss(x, srgb, channels, &p, &mut scratch).loss
                });
                assert_close(
                    &format!("{channels:?} srgb {srgb} ∂L/∂stored[{i}]"),
                    &[g[i]],
                    &[num],
                    1e-5,
                    1e-10,
                );
            }
        }
    }
}

#[test]
fn band_loss_is_zero_inside_the_quantisation_band_and_l1_outside() {
    // P = 0.5 with C = 0.2, b = 1: band [0.5·e^−0.2, 0.5·e^0.2] = [0.40937, 0.61070].
    let mut p = PseudoImage::<f64>::default();
    p.data = vec![0.5; 4];
    p.valid = vec![true, true, true, false];
    p.n_eff = vec![2.0; 4];
    p.band_per_c = 1.0;
    p.band = 0.2;
    let (lo, hi) = (0.5 * (-0.2f64).exp(), 0.5 * 0.2f64.exp());
    let render = [0.45, 0.7, 0.3, 9.0];
    let mut g = vec![0.0; 4];
    let l = event_loss(&render, &p, Some(&mut g));
    assert_eq!(l.valid, 3);
    let want = ((0.7 - hi) + (lo - 0.3)) / 3.0;
    assert!((l.loss - want).abs() < 1e-12, "{} vs {want}", l.loss);
    assert_eq!(g, vec![0.0, 1.0 / 3.0, -1.0 / 3.0, 0.0]);
    // ∂L/∂C: −hi·(n + b) for the value above, lo·(n − b) for the one below.
    let want_c = (-hi * 3.0 + lo * 1.0) / 3.0;
    assert!((l.d_contrast - want_c).abs() < 1e-12);
    // b = 0 is the paper's L1.
    p.band = 0.0;
    p.band_per_c = 0.0;
    let l0 = event_loss(&render, &p, None);
    assert!((l0.loss - (0.05 + 0.2 + 0.2) / 3.0).abs() < 1e-12);
}

#[test]
fn f32_pseudo_image_agrees_with_f64() {
    let mut rng = Rng::new(9);
    let d = consistent(&mut rng, 0.2, 0.0);
    let sl = d.ev.as_slice();
    let k = IntervalCounts::build(&sl, 0.0, 1.0, 64);
    let s = PseudoSettings {
        saturation: 10.0,
        ..Default::default()
    };
    let (l32, r32): (Vec<f32>, Vec<f32>) = (
        d.left.iter().map(|&v| v as f32).collect(),
        d.right.iter().map(|&v| v as f32).collect(),
    );
    let mut a = PseudoImage::<f64>::default();
    let mut b = PseudoImage::<f32>::default();
    let inp64 = PseudoInputs {
        counts: &k,
        events: Some(&sl),
        left: &d.left,
        right: &d.right,
        channels: 3,
        contrast: 0.2,
    };
    let inp32 = PseudoInputs {
        counts: &k,
        events: Some(&sl),
        left: &l32,
        right: &r32,
        channels: 3,
        contrast: 0.2f32,
    };
    pseudo_image(&inp64, 0.37, PseudoMode::TwoSided, &s, &mut a);
    pseudo_image(&inp32, 0.37, PseudoMode::TwoSided, &s, &mut b);
    for i in 0..a.data.len() {
        assert_eq!(a.valid[i], b.valid[i]);
        assert!((a.data[i] - b.data[i] as f64).abs() < 1e-6 * (1.0 + a.data[i]));
    }
}

#[test]
fn srgb_conversion_is_iec_61966_2_1() {
    assert_eq!(srgb_to_linear(0.0f64), 0.0);
    assert!((srgb_to_linear(1.0f64) - 1.0).abs() < 1e-15);
    assert!((srgb_to_linear(0.5f64) - 0.214_041_140_482_232_5).abs() < 1e-12);
    assert!((srgb_to_linear(0.04045f64) - 0.04045 / 12.92).abs() < 1e-15);
    for i in 0..=255 {
        let c = i as f64 / 255.0;
        assert!(
            (linear_to_srgb(srgb_to_linear(c)) - c).abs() < 1e-12,
            "code {i}"
        );
        assert!((linear_to_srgb(srgb_to_linear(c as f32)) - c as f32).abs() < 1e-6);
    }
    // Continuous at the knee (the standard's constants meet within 1e-7).
    let k = 0.003_130_8f64;
    assert!((linear_to_srgb(k) - linear_to_srgb(k + 1e-12)).abs() < 1e-7);
    let img = Image {
        width: 2,
        height: 1,
        channels: 3,
        data: vec![0.5, 0.0, 1.0, 0.2, 0.4, 0.6],
    };
    let p = planar_linear(&img, false);
    assert_eq!(p, vec![0.5, 0.2, 0.0, 0.4, 1.0, 0.6]);
    let q = planar_linear(&img, true);
    assert!((q[0] - 0.214_041_14).abs() < 1e-6 && q[4] == 1.0);
}
