//! Degenerate inputs at the kernel level: a hot pixel, empty intervals, implausible
//! per-event flows (the stage-level runs are in `deform/tests/robust.rs`).

use crate::event_counts::{CountSettings, EventCounts, IntervalCounts};
use crate::event_image::{PseudoImage, PseudoInputs, PseudoMode, PseudoSettings};
use crate::event_image::{event_loss, pseudo_image};
use crate::fallbacks::{DroppedBindings, EventSkip, Fallbacks, interval_skip};
use crate::motion_loss::motion_loss;
use crate::motion_loss::{CsrBindings, MotionInputs, MotionLoss, MotionSettings, PerGaussian};
use scene::EventStream;

const W: usize = 6;
const H: usize = 5;

#[test]
fn a_hot_pixel_is_masked_on_both_sides_not_infinite() {
    // 40 000 events of one polarity in pixel (4, 2): exp(C·N) overflows f32 and f64,
    // exp(−C·N) underflows to 0. Every other pixel has no event.
    let hot = 2 * W + 4;
    for p in [1i8, -1] {
        let mut ev = EventStream::new(W as u32, H as u32);
        for i in 0..40_000 {
            ev.push(i as f64 / 40_000.0, 4, 2, p);
        }
        let sl = ev.as_slice();
        let k = IntervalCounts::build(&sl, 0.0, 1.0, 32);
        assert_eq!(k.events(), 40_000);
        let frame = vec![0.3f32; 3 * W * H];
        let inp = PseudoInputs {
            counts: &k,
            events: Some(&sl),
            left: &frame,
            right: &frame,
            channels: 3,
            contrast: 0.1f32,
        };
        let mut out = PseudoImage::default();
        for te in [0.3, 0.7] {
            let s = PseudoSettings::default();
            pseudo_image(&inp, te, PseudoMode::Nearest, &s, &mut out);
            for c in 0..3 {
                let v = c * W * H + hot;
                assert!(!out.valid[v], "p {p} t_e {te}: hot pixel valid");
                assert_eq!((out.data[v], out.n_eff[v]), (0.0, 0.0));
            }
            // the rest: no event, the frame itself
            assert_eq!(out.valid_count(), 3 * (W * H - 1), "p {p} t_e {te}");
            for v in (0..3 * W * H).filter(|v| v % (W * H) != hot) {
                assert!((out.data[v] - 0.3).abs() < 1e-6, "p {p} value {v}");
            }
            let render = vec![0.5f32; 3 * W * H];
            let mut g = vec![0.0f32; 3 * W * H];
            let l = event_loss(&render, &out, Some(&mut g));
            assert!((l.loss - 0.2).abs() < 1e-6 && l.d_contrast == 0.0, "{l:?}");
            assert!(g.iter().all(|x| x.is_finite()));
            assert_eq!(g[hot], 0.0);
        }
    }
}

#[test]
fn intervals_without_length_or_events_are_skipped_and_counted() {
    let mut ev = EventStream::new(W as u32, H as u32);
    for i in 0..10 {
        ev.push(0.05 + 0.01 * i as f64, 1, 1, 1); // all in [0, 0.5)
    }
    let times = [0.0, 0.5, 0.5, 1.0];
    let all = EventCounts::build(&ev.as_slice(), &times, &CountSettings::default()).unwrap();
    let k = all.intervals();
    assert_eq!(k.iter().map(|k| k.events()).collect::<Vec<_>>(), [10, 0, 0]);
    assert_eq!(interval_skip(&k[0]), None);
    assert_eq!(interval_skip(&k[1]), Some(EventSkip::EmptyInterval));
    assert_eq!(interval_skip(&k[2]), Some(EventSkip::NoEvents));
    let mut f = Fallbacks::default();
    f.skip_event(EventSkip::NoEvents);
    f.skip_event(EventSkip::NoEvents);
    f.skip_event(EventSkip::NoValidPixels);
    let dropped = |no_flow, outliers, disagreeing, rate_outliers| DroppedBindings {
        no_flow,
        outliers,
        disagreeing,
        rate_outliers,
    };
    f.drop_bindings(&dropped(3, 2, 4, 5));
    f.drop_bindings(&dropped(0, 1, 0, 2));
    assert_eq!(
        (
            f.event_steps_skipped,
            f.event_skipped_no_events,
            f.event_skipped_no_valid_pixels,
            f.event_skipped_empty_interval
        ),
        (3, 2, 1, 0)
    );
    assert_eq!(
        (
            f.bindings_dropped,
            f.bindings_dropped_no_flow,
            f.bindings_dropped_outliers,
            f.bindings_dropped_disagreeing,
            f.bindings_dropped_rate_outliers
        ),
        (17, 3, 3, 4, 7)
    );
}

/// `L_motion` of one Gaussian bound to events `0..n` with `weights`, flows `(u, v)`
/// px/s, over `dt` s, against `F_gs = (0.1, 0.05)` px (no `F_ego`).
fn one_gaussian(
    s: &MotionSettings,
    weights: &[f32],
    u: &[f64],
    v: &[f64],
    dt: f64,
) -> MotionLoss<f64> {
    let events: Vec<u64> = (0..weights.len() as u64).collect();
    let offsets = [0u32, weights.len() as u32];
    let inp = MotionInputs {
        dt,
        bindings: CsrBindings {
            offsets: &offsets,
            events: &events,
            weights,
        },
        flow_u: u,
        flow_v: v,
        flow_base: 0,
        ego: None,
        gs: PerGaussian {
            u: &[0.1],
            v: &[0.05],
            valid: None,
        },
    };
    motion_loss(s, &inp, None)
}

#[test]
fn a_wild_flow_among_three_events_is_dropped_and_the_loss_is_that_of_the_other_two() {
    let s = MotionSettings::default();
    assert_eq!((s.outlier_px, s.epsilon), (2.0, 1e-3));
    let w = [0.2f32, 0.3, 0.5];
    let (u, v) = ([40.0, 42.0, -300.0], [-10.0, -9.0, 250.0]);
    let out = one_gaussian(&s, &w, &u, &v, 0.01);
    // kept: weighted mean (41.2, −9.4) px/s · 0.01 s − (0.1, 0.05) = (0.312, −0.144) px
    let (rx, ry) = (0.312f64, -0.144f64);
    let want = (rx * rx + ry * ry + 1e-6).sqrt() - 1e-3;
    // (the weights are f32: 1e-7 px)
    assert!((out.loss - want).abs() < 1e-7, "{} vs {want}", out.loss);
    assert_eq!(
        (out.bound, out.dropped_outliers, out.dropped_non_finite),
        (1, 1, 0)
    );
    let two = one_gaussian(&s, &w[..2], &u[..2], &v[..2], 0.01);
    assert_eq!(two.dropped_outliers, 0);
    assert!((out.loss - two.loss).abs() < 1e-12);
    // The same event with a non-finite flow: dropped as such, same loss.
    for bad in [f64::NAN, f64::INFINITY] {
        let out = one_gaussian(&s, &w, &u, &[-10.0, -9.0, bad], 0.01);
        assert_eq!(
            (out.bound, out.dropped_outliers, out.dropped_non_finite),
            (1, 0, 1)
        );
        assert!((out.loss - two.loss).abs() < 1e-12);
    }
    // Rejection off: the wild flow counts (weighted mean (−129.4, 120.3) px/s).
    let off = MotionSettings {
        outlier_px: 0.0,
        ..s
    };
    let all = one_gaussian(&off, &w, &u, &v, 0.01);
    let (rx, ry) = (-1.294 - 0.1, 1.203 - 0.05);
    let want = (rx * rx + ry * ry + 1e-6f64).sqrt() - 1e-3;
    assert!((all.loss - want).abs() < 1e-7, "{all:?} vs {want}");
    assert_eq!(all.dropped_outliers, 0);
    // Spread flows are not outliers: devs (50, 0, 50) px/s, MAD 50 → threshold 222 px/s.
    let spread = one_gaussian(&s, &w, &[0.0, 50.0, 100.0], &[0.0; 3], 0.1);
    assert_eq!(spread.dropped_outliers, 0);
    // Below the pixel floor (1 px over 0.1 s is 10 px/s < 20 px/s): kept.
    let close = one_gaussian(&s, &w, &[40.0, 40.0, 50.0], &[0.0; 3], 0.1);
    assert_eq!(close.dropped_outliers, 0);
    // Two events cannot outvote each other.
    let pair = one_gaussian(&s, &w[..2], &[40.0, -300.0], &[0.0, 250.0], 0.01);
    assert_eq!((pair.bound, pair.dropped_outliers), (1, 0));
    // Every flow unusable: the Gaussian does not contribute, no NaN.
    let none = one_gaussian(&s, &w, &[f64::NAN; 3], &[0.0; 3], 0.01);
    assert_eq!(
        (none.bound, none.dropped_non_finite, none.loss),
        (0, 3, 0.0)
    );
}

#[test]
fn the_default_flow_range_is_the_shipped_networks() {
    let net = evflow::net::NetConfig::default();
    assert_eq!(MotionSettings::default().flow_range_px, net.max_flow);
}

#[test]
fn a_gaussian_whose_flow_disagrees_with_its_neighbours_is_dropped() {
    use crate::neighbours::{NeighbourSettings, disagreeing};
    // A 5 × 5 patch of Gaussians 1 px apart moving (3, −1) px over the span with ±0.2 px
    // of jitter; one in the middle reports (9, 4), one at the corner has no flow, one far
    // away is alone.
    let mut px = Vec::new();
    let mut flow = Vec::new();
    for k in 0..25 {
        let (x, y) = ((k % 5) as f32, (k / 5) as f32);
        px.push([10.0 + x, 20.0 + y]);
        let j = 0.2 * ((k * 7 % 5) as f32 - 2.0) / 2.0;
        flow.push(Some([3.0 + j, -1.0 - j]));
    }
    flow[12] = Some([9.0, 4.0]);
    flow[0] = None;
    px.push([50.0, 50.0]);
    flow.push(Some([-30.0, 0.0]));
    let s = NeighbourSettings::default();
    let out = disagreeing(&px, &flow, &s);
    let dropped: Vec<usize> = (0..out.len()).filter(|&i| out[i]).collect();
    assert_eq!(dropped, [12]);
    // Within the tolerance: kept.
    flow[12] = Some([4.5, -1.0]);
    assert!(!disagreeing(&px, &flow, &s).contains(&true));
    // A region whose flow genuinely varies (a spread of ±4 px) keeps an odd one of 5 px.
    let varied: Vec<Option<[f32; 2]>> = (0..26)
        .map(|k| Some([4.0 * ((k * 3 % 5) as f32 - 2.0) / 2.0, 0.0]))
        .collect();
    let mut v = varied.clone();
    v[12] = Some([5.0, 0.0]);
    assert!(!disagreeing(&px, &v, &s)[12]);
    // Radius 0 turns the check off; too few neighbours decide nothing.
    flow[12] = Some([9.0, 4.0]);
    let off = NeighbourSettings {
        radius_px: 0.0,
        ..s
    };
    assert!(!disagreeing(&px, &flow, &off).contains(&true));
    let few = NeighbourSettings {
        min_neighbours: 30,
        ..s
    };
    assert!(!disagreeing(&px, &flow, &few).contains(&true));
}
