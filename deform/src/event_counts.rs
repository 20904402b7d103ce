//! Per-pixel signed event counts between the train frames, made cheap.
//!
//! For each interval `[t_j, t_{j+1})` between consecutive train frames,
//! [`IntervalCounts`] stores once the cumulative signed count `S_b(x) = Σ p` of the
//! events at pixel `x` with `t_j ≤ t < e_b`, at `B` bin edges `e_b = t_j + b·(t_{j+1} −
//! t_j)/B`, `b = 1..B` (`S_0 = 0`). The planes are edge-major (one contiguous `W·H`
//! plane per edge) in `i16` when every pixel's event count in the interval fits, else
//! `i32`. Building costs `O(events + B·pixels)`, memory `B·pixels·2` bytes per interval.
//!
//! The signed count over `[t_a, t_b)` inside an interval is `S(t_b) − S(t_a)`, where
//! `S(t)` at a time inside bin `b` is either
//! - **exact** ([`IntervalCounts::signed_counts`] with the event slice): `S_b` plus the
//!   events of the partial bin, a contiguous run of the time-sorted stream, scattered
//!   (cost: the events of two partial bins, about `2/B` of the interval's events); or
//! - **interpolated** (without the slice, and [`IntervalCounts::count_at`] for one
//!   pixel): `S_b + f·(S_{b+1} − S_b)`, `f` the fraction of the bin elapsed. Its error at
//!   a pixel is at most the number of that pixel's events in the (at most two) partial
//!   bins: zero for a pixel with no event there, and zero-mean when events are spread
//!   uniformly in time within a bin.
//!
//! Times follow `scene::events`: half-open windows `t_a ≤ t < t_b`, so an event exactly
//! at a frame time belongs to the interval that starts there. Query times are clamped
//! to the interval. Two frames at the same time make an empty interval (all counts 0).
//!
//! **Excluded events** ([`Exclusion`]: whole bins, whole pixels; the event-rate outliers
//! of `deform`) are not counted at all: an excluded bin adds nothing to the cumulative
//! counts (`S_{b+1} = S_b`), neither in the planes nor in the exact partial-bin scatter,
//! and an excluded pixel's count stays 0. [`IntervalCounts::events`] counts the events
//! kept.

use rayon::prelude::*;
use scene::EventSlice;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Settings of the count cube (serde, every field optional in files).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CountSettings {
    /// Time bins per interval between two train frames (at least 1).
    pub bins: usize,
}

impl Default for CountSettings {
    fn default() -> Self {
        CountSettings { bins: 32 }
    }
}

#[derive(Clone, Debug, PartialEq)]
enum Planes {
    I16(Vec<i16>),
    I32(Vec<i32>),
}

impl Planes {
    #[inline(always)]
    fn get(&self, i: usize) -> i32 {
        match self {
            Planes::I16(v) => v[i] as i32,
            Planes::I32(v) => v[i],
        }
    }
}

/// The `B + 1` bin edges of `[t0, t1)` with `bins` bins: `edges[0] = t0`,
/// `edges[B] = t1` exactly, `t0 + b·(t1 − t0)/B` between.
pub(crate) fn bin_edges(t0: f64, t1: f64, bins: usize) -> Vec<f64> {
    (0..=bins)
        .map(|b| match b {
            0 => t0,
            b if b == bins => t1,
            b => t0 + (t1 - t0) * (b as f64 / bins as f64),
        })
        .collect()
}

/// Events left out of the counts (module docs): nothing by default.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Exclusion {
    /// Per interval, per bin: left out (an interval's entry empty or missing: none).
    pub bins: Vec<Vec<bool>>,
    /// Per pixel, row-major: left out (`None`: none).
    pub pixels: Option<Arc<[bool]>>,
}

/// Cumulative signed counts of one interval between two frames (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct IntervalCounts {
    t0: f64,
    t1: f64,
    width: usize,
    height: usize,
    /// `B + 1` bin edges, `edges[0] = t0`, `edges[B] = t1`.
    edges: Vec<f64>,
    /// `B + 1` indices into the source slice: first event with `t ≥ edges[b]`.
    bin_start: Vec<usize>,
    /// `B` planes: plane `b − 1` holds `S_b`.
    planes: Planes,
    /// Where the source slice sat in its stream, and its length (checked by exact queries).
    source: (usize, usize),
    /// Per bin: its events left out (empty: none).
    excluded_bins: Vec<bool>,
    /// Per pixel: its events left out.
    excluded_pixels: Option<Arc<[bool]>>,
    /// Events counted (in the interval, outside the excluded bins and pixels).
    kept: usize,
}

impl IntervalCounts {
    /// Build the counts of `[t0, t1)` from a time-sorted slice (typically the whole
    /// stream; only its events in the interval are read). `t1 < t0` is treated as
    /// `t1 = t0`. Panics if `bins` is 0 or an event lies outside the sensor.
    pub fn build(events: &EventSlice<'_>, t0: f64, t1: f64, bins: usize) -> Self {
        Self::build_excluding(events, t0, t1, bins, &[], None)
    }

    /// [`IntervalCounts::build`] without the events of the bins flagged in
    /// `excluded_bins` (empty: none; else one flag per bin) and of the pixels flagged in
    /// `excluded_pixels` (module docs). Panics also if either has the wrong length.
    pub(crate) fn build_excluding(
        events: &EventSlice<'_>,
        t0: f64,
        t1: f64,
        bins: usize,
        excluded_bins: &[bool],
        excluded_pixels: Option<Arc<[bool]>>,
    ) -> Self {
        assert!(bins >= 1, "IntervalCounts: bins must be at least 1");
        let t1 = t1.max(t0);
        let (w, h) = (events.width as usize, events.height as usize);
        let n = w * h;
        assert!(
            excluded_bins.is_empty() || excluded_bins.len() == bins,
            "IntervalCounts: one excluded-bin flag per bin"
        );
        assert!(
            excluded_pixels.as_ref().is_none_or(|p| p.len() == n),
            "IntervalCounts: one excluded-pixel flag per pixel"
        );
        let edges = bin_edges(t0, t1, bins);
        let bin_start: Vec<usize> = edges
            .iter()
            .map(|&e| events.t.partition_point(|&t| t < e))
            .collect();
        let idx = |i: usize| events.y[i] as usize * w + events.x[i] as usize;
        let bin_kept = |b: usize| !excluded_bins.get(b).copied().unwrap_or(false);
        let pixel_kept = |k: usize| excluded_pixels.as_ref().is_none_or(|p| !p[k]);
        // Events per pixel bound every |S_b| and decide the storage width.
        let mut seen = vec![0u32; n];
        for b in (0..bins).filter(|&b| bin_kept(b)) {
            for i in bin_start[b]..bin_start[b + 1] {
                seen[idx(i)] += 1;
            }
        }
        if let Some(p) = &excluded_pixels {
            seen.iter_mut()
                .zip(p.iter())
                .for_each(|(c, &x)| *c *= u32::from(!x));
        }
        let kept = seen.iter().map(|&c| c as usize).sum();
        let wide = seen.iter().any(|&c| c > i16::MAX as u32);
        drop(seen);
        let mut run = vec![0i32; n];
        let mut fill = |store: &mut dyn FnMut(usize, &[i32])| {
            for b in 0..bins {
                if bin_kept(b) {
                    for i in bin_start[b]..bin_start[b + 1] {
                        let k = idx(i);
                        if pixel_kept(k) {
                            run[k] += events.p[i] as i32;
                        }
                    }
                }
                store(b, &run);
            }
        };
        let planes = if wide {
            let mut v = vec![0i32; bins * n];
            fill(&mut |b, r| v[b * n..(b + 1) * n].copy_from_slice(r));
            Planes::I32(v)
        } else {
            let mut v = vec![0i16; bins * n];
            fill(&mut |b, r| {
                for (d, &s) in v[b * n..(b + 1) * n].iter_mut().zip(r) {
                    *d = s as i16;
                }
            });
            Planes::I16(v)
        };
        IntervalCounts {
            t0,
            t1,
            width: w,
            height: h,
            edges,
            bin_start,
            planes,
            source: (events.offset, events.len()),
            // none flagged is none excluded (compares equal to a plain build)
            excluded_bins: if excluded_bins.contains(&true) {
                excluded_bins.to_vec()
            } else {
                Vec::new()
            },
            excluded_pixels,
            kept,
        }
    }

    /// `(t0, t1)` of the interval.
    pub fn span(&self) -> (f64, f64) {
        (self.t0, self.t1)
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    pub fn bins(&self) -> usize {
        self.edges.len() - 1
    }

    /// Number of events counted: those in the interval outside the excluded bins and
    /// pixels (0 for an empty interval or a recording gap).
    pub fn events(&self) -> usize {
        self.kept
    }

    /// Number of events in the interval, excluded ones included.
    pub fn all_events(&self) -> usize {
        self.bin_start[self.bins()] - self.bin_start[0]
    }

    /// Whether the events of bin `b` are left out.
    pub(crate) fn bin_excluded(&self, b: usize) -> bool {
        self.excluded_bins.get(b).copied().unwrap_or(false)
    }

    /// Whether the events of pixel `i` (row-major) are left out.
    pub(crate) fn pixel_excluded(&self, i: usize) -> bool {
        self.excluded_pixels.as_ref().is_some_and(|p| p[i])
    }

    /// Whether the planes are stored as `i16` (else `i32`).
    pub fn is_compact(&self) -> bool {
        matches!(self.planes, Planes::I16(_))
    }

    /// Bytes held by the planes and tables.
    pub fn memory_bytes(&self) -> usize {
        let planes = match &self.planes {
            Planes::I16(v) => 2 * v.len(),
            Planes::I32(v) => 4 * v.len(),
        };
        planes + 16 * self.edges.len()
    }

    /// Bin `b` and fraction `f ∈ [0, 1]` of time `t` (clamped to the interval).
    #[inline]
    fn locate(&self, t: f64) -> (usize, f64) {
        let bins = self.bins();
        let dt = self.t1 - self.t0;
        let inside = dt > 0.0 && t > self.t0; // false for a NaN t
        if !inside {
            return (0, 0.0);
        }
        if t >= self.t1 {
            return (bins - 1, 1.0);
        }
        let x = (t - self.t0) / dt * bins as f64;
        let mut b = (x as usize).min(bins - 1);
        // Keep b consistent with the stored edges under rounding.
        while b > 0 && t < self.edges[b] {
            b -= 1;
        }
        while b + 1 < bins && t >= self.edges[b + 1] {
            b += 1;
        }
        let width = self.edges[b + 1] - self.edges[b];
        let f = if width > 0.0 {
            ((t - self.edges[b]) / width).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (b, f)
    }

    /// `S_b` at pixel `i` (`S_0 = 0`).
    #[inline(always)]
    fn s(&self, b: usize, i: usize) -> i32 {
        if b == 0 {
            0
        } else {
            self.planes.get((b - 1) * self.width * self.height + i)
        }
    }

    /// Interpolated `S(t)` at pixel `i`.
    #[inline(always)]
    fn s_interp(&self, (b, f): (usize, f64), i: usize) -> f32 {
        let a = self.s(b, i) as f32;
        if f > 0.0 {
            a + f as f32 * (self.s(b + 1, i) as f32 - a)
        } else {
            a
        }
    }

    /// Interpolated signed count of pixel `(x, y)` over `[ta, tb)` (negated when
    /// `tb < ta`).
    pub fn count_at(&self, x: usize, y: usize, ta: f64, tb: f64) -> f32 {
        let i = y * self.width + x;
        self.s_interp(self.locate(tb), i) - self.s_interp(self.locate(ta), i)
    }

    /// Signed count of every pixel over `[ta, tb)` into `out` (`W·H`, row-major),
    /// negated when `tb < ta`. With `events` (the slice the counts were built from) the
    /// counts are exact, else interpolated within the partial bins (module docs).
    /// Panics if `events` is not that slice (offset or length differ).
    pub(crate) fn signed_counts(
        &self,
        ta: f64,
        tb: f64,
        events: Option<&EventSlice<'_>>,
        out: &mut [f32],
    ) {
        let n = self.width * self.height;
        assert_eq!(out.len(), n, "signed_counts: output size");
        let (la, lb) = (self.locate(ta), self.locate(tb));
        match events {
            None => out
                .par_chunks_mut(self.width.max(1))
                .enumerate()
                .for_each(|(row, o)| {
                    let base = row * self.width;
                    for (j, v) in o.iter_mut().enumerate() {
                        *v = self.s_interp(lb, base + j) - self.s_interp(la, base + j);
                    }
                }),
            Some(ev) => {
                assert_eq!(
                    (ev.offset, ev.len()),
                    self.source,
                    "signed_counts: not the event slice the counts were built from"
                );
                let (ba, bb) = (la.0, lb.0);
                out.par_chunks_mut(self.width.max(1))
                    .enumerate()
                    .for_each(|(row, o)| {
                        let base = row * self.width;
                        for (j, v) in o.iter_mut().enumerate() {
                            *v = (self.s(bb, base + j) - self.s(ba, base + j)) as f32;
                        }
                    });
                let (ta, tb) = (ta.clamp(self.t0, self.t1), tb.clamp(self.t0, self.t1));
                self.scatter_partial(ev, bb, tb, 1.0, out);
                self.scatter_partial(ev, ba, ta, -1.0, out);
            }
        }
    }

    /// Add `sign·p` of the kept events in `[edges[b], t)` to `out`.
    fn scatter_partial(&self, ev: &EventSlice<'_>, b: usize, t: f64, sign: f32, out: &mut [f32]) {
        if self.bin_excluded(b) {
            return;
        }
        let (lo, hi) = (self.bin_start[b], self.bin_start[b + 1]);
        let end = lo + ev.t[lo..hi].partition_point(|&s| s < t);
        for i in lo..end {
            let k = ev.y[i] as usize * self.width + ev.x[i] as usize;
            if !self.pixel_excluded(k) {
                out[k] += sign * ev.p[i] as f32;
            }
        }
    }
}

/// The counts of every interval between consecutive train frames.
#[derive(Clone, Debug, PartialEq)]
pub struct EventCounts {
    times: Vec<f64>,
    intervals: Vec<IntervalCounts>,
}

impl EventCounts {
    /// Build all intervals (rayon over intervals). `frame_times` must be sorted
    /// (non-decreasing; equal times give empty intervals).
    pub fn build(
        events: &EventSlice<'_>,
        frame_times: &[f64],
        settings: &CountSettings,
    ) -> Result<Self, String> {
        Self::build_excluding(events, frame_times, settings, &Exclusion::default())
    }

    /// [`EventCounts::build`] without the events `excluded` names (module docs).
    pub(crate) fn build_excluding(
        events: &EventSlice<'_>,
        frame_times: &[f64],
        settings: &CountSettings,
        excluded: &Exclusion,
    ) -> Result<Self, String> {
        if settings.bins == 0 {
            return Err("event counts: bins must be at least 1".into());
        }
        if frame_times.iter().any(|t| !t.is_finite()) {
            return Err("event counts: a frame time is not finite".into());
        }
        if frame_times.windows(2).any(|w| w[1] < w[0]) {
            return Err("event counts: frame times are not sorted".into());
        }
        let n = events.width as usize * events.height as usize;
        if excluded.pixels.as_ref().is_some_and(|p| p.len() != n) {
            return Err("event counts: one excluded-pixel flag per pixel".into());
        }
        let bins_of = |j: usize| excluded.bins.get(j).map_or(&[][..], |b| b.as_slice());
        if (0..frame_times.len().saturating_sub(1))
            .any(|j| !bins_of(j).is_empty() && bins_of(j).len() != settings.bins)
        {
            return Err("event counts: one excluded-bin flag per bin".into());
        }
        let intervals = frame_times
            .par_windows(2)
            .enumerate()
            .map(|(j, w)| {
                let pixels = excluded.pixels.clone();
                IntervalCounts::build_excluding(
                    events,
                    w[0],
                    w[1],
                    settings.bins,
                    bins_of(j),
                    pixels,
                )
            })
            .collect();
        Ok(EventCounts {
            times: frame_times.to_vec(),
            intervals,
        })
    }

    pub fn frame_times(&self) -> &[f64] {
        &self.times
    }

    pub fn intervals(&self) -> &[IntervalCounts] {
        &self.intervals
    }

    /// The interval containing `t` (`t_j ≤ t < t_{j+1}`; the last interval also takes its
    /// end time), `None` outside the frames' time or when there is no interval.
    pub fn interval_of(&self, t: f64) -> Option<usize> {
        let n = self.times.len();
        if n < 2 || !(t >= self.times[0] && t <= self.times[n - 1]) {
            return None;
        }
        Some((self.times.partition_point(|&k| k <= t).max(1) - 1).min(n - 2))
    }

    /// Bytes held by all intervals.
    pub fn memory_bytes(&self) -> usize {
        self.intervals.iter().map(|i| i.memory_bytes()).sum()
    }
}
