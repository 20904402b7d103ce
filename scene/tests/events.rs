//! `EventStream` time windows: `window_range(t0, t1)` is the **half-open** interval
//! `t0 ≤ t < t1` (an event exactly at `t0` is in, one exactly at `t1` is out), found by
//! binary search. Checked against a brute-force filter on ties, boundaries, empty
//! streams, empty / reversed / NaN windows and random data, and for nested slices.

use scene::events::{EventSlice, EventStream};
use std::ops::Range;

/// Deterministic pseudo-random numbers (64-bit LCG, high bits).
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 33
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// A stream with the given (sorted) timestamps; x encodes the event index.
fn stream_of(times: &[f64]) -> EventStream {
    let mut ev = EventStream::new(1024, 4);
    for (i, &t) in times.iter().enumerate() {
        ev.push(t, (i % 1024) as u16, (i / 1024 % 4) as u16, 1);
    }
    ev
}

/// The indices the definition selects: `t0 ≤ t < t1`.
fn brute(ev: &EventStream, t0: f64, t1: f64) -> Vec<usize> {
    (0..ev.len())
        .filter(|&i| t0 <= ev.t[i] && ev.t[i] < t1)
        .collect()
}

/// `window_range` as a list of indices, checking that `window` agrees with it.
fn fast(ev: &EventStream, t0: f64, t1: f64) -> Vec<usize> {
    let r = ev.window_range(t0, t1);
    assert!(r.start <= r.end && r.end <= ev.len(), "{r:?}");
    let w = ev.window(t0, t1);
    assert_eq!(w.offset, r.start);
    assert_eq!(w.len(), r.len());
    assert_eq!(w.t, &ev.t[r.clone()]);
    assert_eq!(w.x, &ev.x[r.clone()]);
    assert_eq!((w.width, w.height), (ev.width, ev.height));
    r.collect()
}

#[test]
fn window_is_half_open_on_ties_at_both_ends() {
    // Index:            0    1    2    3    4    5    6    7    8
    let ev = stream_of(&[0.5, 1.0, 1.0, 1.0, 1.5, 2.0, 2.0, 3.0, 3.0]);
    assert_eq!(ev.window_range(1.0, 2.0), 1..5); // all three ties at t0 in, t1 ties out
    assert_eq!(ev.window_range(1.0, 1.0), 1..1); // empty at the tie position
    assert_eq!(ev.window_range(2.0, 3.0), 5..7);
    assert_eq!(ev.window_range(2.0, 3.0000000000000004), 5..9); // next f64 above 3
    assert_eq!(ev.window_range(0.5, 0.5000000000000001), 0..1);
    assert_eq!(ev.window_range(f64::NEG_INFINITY, f64::INFINITY), 0..9);
    assert_eq!(ev.window_range(3.0, f64::INFINITY), 7..9);
    assert_eq!(ev.window_range(f64::NEG_INFINITY, 0.5), 0..0);
    // Outside the covered time: empty ranges at the ends.
    assert_eq!(ev.window_range(-5.0, -1.0), 0..0);
    assert_eq!(ev.window_range(3.5, 9.0), 9..9);
    // Adjacent windows partition the stream: every event in exactly one.
    let cuts = [0.0, 0.5, 1.0, 1.25, 2.0, 3.0, 4.0];
    let mut covered = Vec::new();
    for w in cuts.windows(2) {
        covered.extend(fast(&ev, w[0], w[1]));
    }
    assert_eq!(covered, (0..9).collect::<Vec<_>>());
    for w in cuts.windows(2) {
        assert_eq!(fast(&ev, w[0], w[1]), brute(&ev, w[0], w[1]));
    }
}

#[test]
fn empty_stream_and_empty_reversed_or_nan_windows() {
    let empty = EventStream::new(8, 8);
    for (t0, t1) in [(0.0, 1.0), (1.0, 0.0), (f64::NEG_INFINITY, f64::INFINITY)] {
        assert_eq!(empty.window_range(t0, t1), 0..0);
        let w = empty.window(t0, t1);
        assert!(w.is_empty() && w.offset == 0);
    }
    let ev = stream_of(&[1.0, 2.0, 2.0, 3.0, 4.0]);
    // Reversed windows are empty (no event has t0 ≤ t < t1), even across ties.
    for (t0, t1) in [(3.0, 2.0), (2.0, 1.0), (4.5, 0.0), (2.0, 2.0), (2.5, 2.5)] {
        let r = ev.window_range(t0, t1);
        assert!(r.is_empty(), "({t0}, {t1}) gave {r:?}");
        assert!(brute(&ev, t0, t1).is_empty());
    }
    // A NaN bound matches nothing (every comparison with NaN is false).
    for (t0, t1) in [(f64::NAN, 3.0), (1.0, f64::NAN), (f64::NAN, f64::NAN)] {
        assert!(brute(&ev, t0, t1).is_empty());
        let r = ev.window_range(t0, t1);
        assert!(r.is_empty(), "({t0}, {t1}) gave {r:?}");
        assert!(ev.window(t0, t1).is_empty());
    }
}

/// Sorted timestamps on a coarse grid (many ties), with runs of equal values.
fn random_times(rng: &mut Lcg, n: usize, grid: u64) -> Vec<f64> {
    let mut t: Vec<f64> = (0..n).map(|_| rng.below(grid) as f64 * 1e-3).collect();
    t.sort_by(f64::total_cmp);
    t
}

#[test]
fn window_matches_brute_force_on_random_streams() {
    let mut rng = Lcg(0x5eed);
    let mut nonempty = 0;
    for case in 0..40 {
        let n = [0, 1, 2, 17, 1000, 5000][case % 6];
        let grid = [3, 50, 1000, 100_000][case % 4];
        let ev = stream_of(&random_times(&mut rng, n, grid));
        ev.validate().unwrap();
        for _ in 0..200 {
            // Bounds on the grid (hit ties exactly), between grid points, or outside.
            let bound = |rng: &mut Lcg| match rng.below(3) {
                0 => rng.below(grid + 2) as f64 * 1e-3,
                1 => (rng.below(grid + 2) as f64 + 0.5) * 1e-3,
                _ => rng.below(grid * 2 + 4) as f64 * 1e-3 - 1e-3,
            };
            let (t0, t1) = (bound(&mut rng), bound(&mut rng));
            let want = brute(&ev, t0, t1);
            assert_eq!(fast(&ev, t0, t1), want, "n {n} grid {grid} [{t0}, {t1})");
            nonempty += usize::from(!want.is_empty());
        }
    }
    assert!(nonempty > 2000, "{nonempty} non-empty windows");
}

/// The events of `s` (a slice) as absolute stream indices.
fn absolute(s: &EventSlice, r: Range<usize>) -> Vec<usize> {
    r.map(|i| s.offset + i).collect()
}

#[test]
fn nested_windows_compose_and_keep_absolute_offsets() {
    let mut rng = Lcg(99);
    let ev = stream_of(&random_times(&mut rng, 3000, 400));
    for _ in 0..500 {
        let b: Vec<f64> = (0..4).map(|_| rng.below(420) as f64 * 1e-3).collect();
        let outer = ev.window(b[0], b[1]);
        // A window of a window is the intersection of the two intervals.
        let inner_range = outer.window_range(b[2], b[3]);
        let inner = outer.window(b[2], b[3]);
        assert_eq!(inner.offset, outer.offset + inner_range.start);
        let got = absolute(&outer, inner_range);
        let want = brute(&ev, b[0].max(b[2]), b[1].min(b[3]));
        assert_eq!(got, want, "{b:?}");
        // Offsets point back into the stream: same events there.
        for (k, &i) in got.iter().enumerate() {
            assert_eq!((inner.t[k], inner.x[k]), (ev.t[i], ev.x[i]));
        }
        // to_owned copies exactly the window.
        let owned = inner.to_owned();
        assert_eq!(owned.len(), got.len());
        assert_eq!(owned.t, got.iter().map(|&i| ev.t[i]).collect::<Vec<_>>());
    }
    // sub() keeps offsets relative to the root stream.
    let s = ev.as_slice().sub(100..200).sub(10..20);
    assert_eq!((s.offset, s.len(), s.t[0]), (110, 10, ev.t[110]));
}
