//! Hot pixels and bursts on events made by `synth`'s simulator: none on the clean
//! presets, exactly the injected ones otherwise, and the counts without any trace of
//! the excluded events.

use crate::event_counts::{CountSettings, EventCounts, bin_edges};
use crate::event_image::{PseudoImage, PseudoInputs, PseudoMode, PseudoSettings, pseudo_image};
use crate::rate_outliers::{RateOutlierSettings, RateOutliers};
use crate::tests::Rng;
use scene::EventStream;
use synth::{SynthConfig, SynthWorld, simulate_scene};

const SIZE: u32 = 32;
const BINS: usize = 32;

/// The clean events of a preset at `SIZE`² (1 s, the simulator's 1 kHz).
fn preset_events(name: &str) -> EventStream {
    let mut cfg = SynthConfig::preset(name).unwrap();
    (cfg.width, cfg.height) = (SIZE, SIZE);
    simulate_scene(&SynthWorld::new(&cfg).unwrap()).unwrap().0
}

/// Train frame times over the preset's 1 s at `fps`.
fn frame_times(fps: f64) -> Vec<f64> {
    let n = fps.round() as usize;
    (0..=n).map(|k| k as f64 / fps).collect()
}

/// `ev` with `extra` (time, x, y, polarity) events merged in time order.
fn with_events(ev: &EventStream, extra: &[(f64, u16, u16, i8)]) -> EventStream {
    let mut list: Vec<(f64, u16, u16, i8)> = (0..ev.len())
        .map(|i| (ev.t[i], ev.x[i], ev.y[i], ev.p[i]))
        .chain(extra.iter().copied())
        .collect();
    list.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out = EventStream::with_capacity(ev.width, ev.height, list.len());
    for (t, x, y, p) in list {
        out.push(t, x, y, p);
    }
    out
}

#[test]
fn the_clean_presets_have_no_hot_pixel_and_no_burst() {
    for name in ["static", "rigid", "nonrigid", "fast"] {
        let ev = preset_events(name);
        assert!(ev.len() > 40_000, "{name}: {} events", ev.len());
        for fps in [5.0, 10.0, 40.0] {
            let times = frame_times(fps);
            let o = RateOutliers::detect(&ev.as_slice(), &times, BINS, &Default::default());
            assert_eq!(o.hot_pixels, Vec::<usize>::new(), "{name} at {fps} fps");
            assert_eq!(o.burst_bin_count(), 0, "{name} at {fps} fps");
            assert!(o.is_empty() && o.burst_events == 0 && o.hot_events == 0);
            // typical rates are those of the scene: tens of events per pixel and second
            let t = o.typical;
            let per_pixel = t.median_bin_rate_hz / (SIZE * SIZE) as f64;
            assert!((20.0..400.0).contains(&per_pixel), "{name}: {t:?}");
            assert!(t.median_active_pixel_count >= 20.0, "{name}: {t:?}");
        }
    }
}

#[test]
fn injected_hot_pixels_are_exactly_the_ones_masked() {
    let ev = preset_events("nonrigid");
    // six pixels at 1 kHz (about 20× the median pixel's rate), two of them side by side
    let hot: [(u16, u16); 6] = [(3, 4), (17, 9), (18, 9), (30, 30), (0, 31), (12, 22)];
    let mut rng = Rng::new(7);
    let mut extra = Vec::new();
    for &(x, y) in &hot {
        extra.extend((0..1000).map(|_| (rng.uniform(0.0, 1.0), x, y, 1i8)));
    }
    let stressed = with_events(&ev, &extra);
    let times = frame_times(10.0);
    let o = RateOutliers::detect(&stressed.as_slice(), &times, BINS, &Default::default());
    let mut want: Vec<usize> = hot
        .iter()
        .map(|&(x, y)| y as usize * SIZE as usize + x as usize)
        .collect();
    want.sort_unstable();
    assert_eq!(o.hot_pixels, want);
    let at_hot = |e: &EventStream| {
        (0..e.len())
            .filter(|&i| hot.contains(&(e.x[i], e.y[i])))
            .count()
    };
    assert_eq!(o.hot_events, 6000 + at_hot(&ev));
    assert_eq!(o.hot_events, at_hot(&stressed));
    // 6000 more events spread over the recording lift no bin
    assert_eq!(o.burst_bin_count(), 0);
    assert!(o.excludes(0.5, 17, 9) && !o.excludes(0.5, 16, 9));

    // The pseudo images mask exactly those pixels; the others are as without them.
    let settings = CountSettings { bins: BINS };
    let counts =
        EventCounts::build_excluding(&stressed.as_slice(), &times, &settings, &o.exclusion())
            .unwrap();
    let clean = EventCounts::build(&ev.as_slice(), &times, &settings).unwrap();
    let n = (SIZE * SIZE) as usize;
    let frame = vec![0.3f32; 3 * n];
    let mut a = PseudoImage::default();
    let mut b = PseudoImage::default();
    for (j, t_e) in [(2, 0.23), (7, 0.78)] {
        let inp = |k, e| PseudoInputs {
            counts: k,
            events: Some(e),
            left: &frame,
            right: &frame,
            channels: 3,
            contrast: 0.1f32,
        };
        let s = PseudoSettings::default();
        let (sl, cl) = (stressed.as_slice(), ev.as_slice());
        pseudo_image(
            &inp(&counts.intervals()[j], &sl),
            t_e,
            PseudoMode::Nearest,
            &s,
            &mut a,
        );
        pseudo_image(
            &inp(&clean.intervals()[j], &cl),
            t_e,
            PseudoMode::Nearest,
            &s,
            &mut b,
        );
        for v in 0..3 * n {
            if want.contains(&(v % n)) {
                assert!(!a.valid[v], "value {v} of a hot pixel is valid");
            } else {
                assert_eq!(
                    (a.valid[v], a.data[v]),
                    (b.valid[v], b.data[v]),
                    "value {v}"
                );
            }
        }
        let valid_at_hot = (0..3 * n).filter(|&v| want.contains(&(v % n)) && b.valid[v]);
        assert_eq!(a.valid_count(), b.valid_count() - valid_at_hot.count());
    }
}

#[test]
fn a_burst_flags_the_bins_it_covers_and_leaves_no_trace_in_the_counts() {
    let ev = preset_events("nonrigid");
    let times = frame_times(10.0);
    // Interval 3 [0.3, 0.4): 9 200 events in [e10 + 0.85·bin, e13 + 0.5·bin), 2.65
    // bins (1.1 M/s: the stress runs' 10 M per 10 ms on 1280×720, scaled to 32²; 20×
    // the scene's median rate): bin 10 holds 0.15 of a bin of it (about 4× the median
    // rate with the scene's own: an edge bin), bins 11 and 12 all of it, bin 13 half.
    let e = bin_edges(times[3], times[4], BINS);
    let bin = e[1] - e[0];
    let (a, z) = (e[10] + 0.85 * bin, e[13] + 0.5 * bin);
    let mut rng = Rng::new(3);
    let burst: Vec<(f64, u16, u16, i8)> = (0..9200)
        .map(|_| {
            let t = rng.uniform(a, z);
            let (x, y) = (rng.next_u64() % SIZE as u64, rng.next_u64() % SIZE as u64);
            (
                t,
                x as u16,
                y as u16,
                if rng.next_u64() & 1 == 0 { 1 } else { -1 },
            )
        })
        .collect();
    let stressed = with_events(&ev, &burst);
    let o = RateOutliers::detect(&stressed.as_slice(), &times, BINS, &Default::default());
    assert!(o.hot_pixels.is_empty());
    for (j, flags) in o.burst_bins.iter().enumerate() {
        let flagged: Vec<usize> = (0..BINS).filter(|&b| flags[b]).collect();
        let want = if j == 3 { vec![10, 11, 12, 13] } else { vec![] };
        assert_eq!(flagged, want, "interval {j}");
    }
    assert_eq!(o.burst_bin_count(), 4);
    assert_eq!(o.burst_windows, vec![[e[10], e[14]]]);
    let in_bins = |s: &EventStream| s.window_range(e[10], e[14]).len();
    assert_eq!(o.burst_events, in_bins(&stressed));
    assert_eq!(o.burst_events, 9200 + in_bins(&ev));
    assert!(o.excludes(e[10], 5, 5) && !o.excludes(e[14], 5, 5));
    // Without the burst bins the counts are those of the clean recording without the
    // same bins, to the event: the burst leaves no trace.
    let settings = CountSettings { bins: BINS };
    let ex = o.exclusion();
    let counts = EventCounts::build_excluding(&stressed.as_slice(), &times, &settings, &ex);
    let clean = EventCounts::build_excluding(&ev.as_slice(), &times, &settings, &ex);
    let (counts, clean) = (counts.unwrap(), clean.unwrap());
    let (k, kc) = (&counts.intervals()[3], &clean.intervals()[3]);
    assert_eq!(k.events(), kc.events());
    assert_eq!(k.all_events(), kc.all_events() + 9200);
    assert_eq!(k.events(), k.all_events() - o.burst_events);
    let n = (SIZE * SIZE) as usize;
    let (mut x, mut y) = (vec![0f32; n], vec![0f32; n]);
    for (ta, tb) in [(0.3, 0.4), (0.3, 0.335), (0.332, 0.3455), (0.341, 0.39)] {
        k.signed_counts(ta, tb, Some(&stressed.as_slice()), &mut x);
        kc.signed_counts(ta, tb, Some(&ev.as_slice()), &mut y);
        assert_eq!(x, y, "exact, [{ta}, {tb})");
        k.signed_counts(ta, tb, None, &mut x);
        kc.signed_counts(ta, tb, None, &mut y);
        assert_eq!(x, y, "interpolated, [{ta}, {tb})");
    }
    // the other intervals are untouched
    let raw = EventCounts::build(&stressed.as_slice(), &times, &settings).unwrap();
    assert_eq!(counts.intervals()[2], raw.intervals()[2]);

    // Off: nothing found.
    let off = RateOutlierSettings {
        hot_pixel_ratio: 0.0,
        burst_ratio: 0.0,
        ..Default::default()
    };
    assert!(RateOutliers::detect(&stressed.as_slice(), &times, BINS, &off).is_empty());
}

#[test]
fn kept_events_map_back_to_the_stream() {
    let mut ev = EventStream::new(4, 4);
    for i in 0..400 {
        ev.push(i as f64 / 400.0, (i % 4) as u16, ((i / 4) % 4) as u16, 1);
    }
    // pixel (1, 2) very hot: 600 more events
    let extra: Vec<_> = (0..600)
        .map(|i| (i as f64 / 600.0, 1u16, 2u16, -1i8))
        .collect();
    let ev = with_events(&ev, &extra);
    let o = RateOutliers::detect(&ev.as_slice(), &[0.0, 0.5, 1.0], 8, &Default::default());
    assert_eq!(o.hot_pixels, vec![2 * 4 + 1]);
    let window = ev.window(0.25, 0.5);
    let (kept, index) = o.kept_events(&window).unwrap();
    // 100 clean events (6 of them at (1, 2)) and 150 of the hot pixel's
    assert_eq!((window.len(), kept.len()), (250, 94));
    for (k, &i) in index.iter().enumerate() {
        let i = i as usize;
        assert_eq!(
            (kept.t[k], kept.x[k], kept.y[k]),
            (ev.t[i], ev.x[i], ev.y[i])
        );
        assert_ne!((ev.x[i], ev.y[i]), (1, 2));
    }
    assert!(RateOutliers::default().kept_events(&window).is_none());
}

#[test]
fn settings_are_validated() {
    let ok = RateOutlierSettings::default();
    assert_eq!(ok.validate(), Ok(()));
    for bad in [
        RateOutlierSettings {
            hot_pixel_ratio: 0.5,
            ..ok
        },
        RateOutlierSettings {
            burst_ratio: f64::NAN,
            ..ok
        },
        RateOutlierSettings {
            burst_edge_ratio: 6.0,
            ..ok
        },
        RateOutlierSettings {
            burst_edge_ratio: -1.0,
            ..ok
        },
    ] {
        let e = bad.validate().unwrap_err();
        assert!(e.starts_with("rate_outliers."), "{e}");
    }
}
