//! Event-rate outliers (issue #18; docs/DESIGN.md §9, "Fallbacks"): **hot pixels** and
//! **bursts**, found from the recording's own rates and left out of the pseudo images of
//! `L_event` and of the events of `L_motion`.
//!
//! - A pixel is **hot** when its event count over the recording `n_x` exceeds
//!   `hot_pixel_ratio · max(m, m_x)`: `m` the median count of the *active* pixels (at
//!   least one event), `m_x` the median count of its (up to 8) neighbours. Ratios, not a
//!   median + k·MAD: counts scale with the recording's length and the scene's speed,
//!   their ratio to the median does not; and their distribution is skewed (textured
//!   edges fire several times the median), so a MAD of the bulk says little about the
//!   tail. The neighbours' median keeps a busy region (a moving object before a still
//!   camera, whose pixels all fire far above the sensor's median) from being taken
//!   for hot pixels; the sensor's median keeps a few events in an empty region from
//!   being taken for a hot pixel. Measured at 64² (`synth` presets `static`, `rigid`,
//!   `nonrigid`, `fast`, 1 s; also 32² and 128²): `n_x / max(m, m_x)` is at most 2.7
//!   (the busiest pixel is 5.7× `m`, but its neighbours are busy too), so the default
//!   5 never fires on them; 1 kHz hot pixels on `nonrigid` 64² are 7–23× (all 49 of a
//!   1 % stress found, no other pixel). A pixel firing at about the scene's own rate
//!   (the stress runs' 50 Hz hot pixels against `nonrigid`'s median 48 events per pixel
//!   per second: about 2×) is no outlier by rate and is not masked; its harm is
//!   bounded by the few events a pseudo image spans (at most half an interval's).
//! - A fine time bin of the counts (`counts.bins` per interval between train frames,
//!   [`crate::event_counts`]) is a **burst** when its event rate (events / its length,
//!   the hot pixels' events left out: a very hot pixel alone would lift every bin)
//!   exceeds `burst_ratio ·` the recording's typical rate (the median rate of all its
//!   bins, at least 4 events per bin); its neighbouring bins join while their rate
//!   exceeds `burst_edge_ratio ·` the typical rate (a burst's edges straddle bins and
//!   leave part of it in a bin below the main threshold). Measured on the same presets
//!   (5 to 40 fps, 32² to 128²): no bin above 2.4× the median rate (`fast`, whose
//!   scene moves 3× faster, has the same spread: the median rises with it), so the
//!   defaults 5 and 2.5 never fire on them; the stress runs' burst (10 M events per
//!   10 ms on 1280×720) fills bins at 20× the median of `nonrigid` 64² (6× on `fast`).
//!
//! The hot pixels and burst bins go to [`crate::event_counts::Exclusion`], so the
//! pseudo images neither count their events nor predict the hot pixels (masked), and
//! [`RateOutliers::excludes`] tells `L_motion` which bound events to leave out.

use crate::event_counts::{Exclusion, bin_edges};
use scene::{EventSlice, EventStream};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// The least typical count of a bin the burst test assumes: a Poisson count of mean 4
/// exceeds 5× that (the default ratio) with probability 10⁻⁶, so a sparse recording's
/// chance clusters of events are not taken for bursts.
const MIN_TYPICAL_BIN_EVENTS: f64 = 4.0;

/// Settings of the outlier tests (serde, every field optional in files; module docs).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RateOutlierSettings {
    /// A pixel whose event count exceeds this many times the larger of the median count
    /// of the active pixels and its neighbours' median is hot; 0: no pixel is.
    pub hot_pixel_ratio: f64,
    /// A time bin whose event rate exceeds this many times the recording's median bin
    /// rate is a burst; 0: no bin is.
    pub burst_ratio: f64,
    /// Bins next to a burst join it while their rate exceeds this many times the median
    /// (at most `burst_ratio`).
    pub burst_edge_ratio: f64,
}

impl Default for RateOutlierSettings {
    fn default() -> Self {
        RateOutlierSettings {
            hot_pixel_ratio: 5.0,
            burst_ratio: 5.0,
            burst_edge_ratio: 2.5,
        }
    }
}

impl RateOutlierSettings {
    /// Why the values cannot be used, if they cannot.
    pub fn validate(&self) -> Result<(), String> {
        let ratio = |name: &str, v: f64| {
            if v.is_finite() && (v == 0.0 || v >= 1.0) {
                Ok(())
            } else {
                Err(format!(
                    "rate_outliers.{name} must be 0 (off) or a finite ratio ≥ 1 (got {v})"
                ))
            }
        };
        ratio("hot_pixel_ratio", self.hot_pixel_ratio)?;
        ratio("burst_ratio", self.burst_ratio)?;
        ratio("burst_edge_ratio", self.burst_edge_ratio)?;
        if self.burst_ratio > 0.0 && self.burst_edge_ratio > self.burst_ratio {
            return Err(format!(
                "rate_outliers.burst_edge_ratio ({}) must not exceed burst_ratio ({})",
                self.burst_edge_ratio, self.burst_ratio
            ));
        }
        Ok(())
    }
}

/// The typical rates the tests compared with (`report.json`, `rate_outliers`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct TypicalRates {
    /// Median event count of the pixels with at least one event.
    pub median_active_pixel_count: f64,
    /// Median event rate of the time bins (events per second, whole sensor).
    pub median_bin_rate_hz: f64,
}

/// What [`RateOutliers::detect`] found.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RateOutliers {
    width: usize,
    /// Per pixel (row-major): hot.
    hot: Vec<bool>,
    /// Hot pixels, as row-major indices, ascending.
    pub hot_pixels: Vec<usize>,
    /// Events at hot pixels (the whole stream).
    pub hot_events: usize,
    /// Per interval between train frames, per bin: burst.
    pub burst_bins: Vec<Vec<bool>>,
    /// `[t_a, t_b)` of each run of burst bins, ascending and disjoint.
    pub burst_windows: Vec<[f64; 2]>,
    /// Events in burst bins (at hot pixels too).
    pub burst_events: usize,
    pub typical: TypicalRates,
}

/// Median of `v` (reordered); 0 for an empty slice.
fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_unstable_by(f64::total_cmp);
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

impl RateOutliers {
    /// Test every pixel and every bin of the intervals between `frame_times` (sorted)
    /// with `bins` bins each, as the counts cut them.
    pub(crate) fn detect(
        events: &EventSlice<'_>,
        frame_times: &[f64],
        bins: usize,
        s: &RateOutlierSettings,
    ) -> RateOutliers {
        let (w, h) = (events.width as usize, events.height as usize);
        let mut count = vec![0u32; w * h];
        for (&x, &y) in events.x.iter().zip(events.y) {
            count[y as usize * w + x as usize] += 1;
        }
        let (hot, median_active) = hot_pixels(&count, w, h, s.hot_pixel_ratio);
        let hot_pixels: Vec<usize> = (0..w * h).filter(|&i| hot[i]).collect();
        let hot_events = hot_pixels.iter().map(|&i| count[i] as usize).sum();
        // the bins' rates without the hot pixels' events (a very hot pixel alone would
        // lift every bin of its time)
        let hot_times: Vec<f64> = (0..events.len())
            .filter(|&i| hot[events.y[i] as usize * w + events.x[i] as usize])
            .map(|i| events.t[i])
            .collect();
        let (burst_bins, median_rate) = burst_bins(
            events,
            &hot_times,
            frame_times,
            bins.max(1),
            (s.burst_ratio, s.burst_edge_ratio),
        );
        let mut burst_windows: Vec<[f64; 2]> = Vec::new();
        let mut burst_events = 0;
        for (j, flags) in burst_bins.iter().enumerate() {
            let edges = bin_edges(frame_times[j], frame_times[j + 1], flags.len());
            for b in (0..flags.len()).filter(|&b| flags[b]) {
                let (a, z) = (edges[b], edges[b + 1]);
                burst_events +=
                    events.t.partition_point(|&t| t < z) - events.t.partition_point(|&t| t < a);
                match burst_windows.last_mut() {
                    Some(last) if last[1] == a => last[1] = z,
                    _ => burst_windows.push([a, z]),
                }
            }
        }
        RateOutliers {
            width: w,
            hot,
            hot_pixels,
            hot_events,
            burst_bins,
            burst_windows,
            burst_events,
            typical: TypicalRates {
                median_active_pixel_count: median_active,
                median_bin_rate_hz: median_rate,
            },
        }
    }

    /// Whether nothing was found.
    pub fn is_empty(&self) -> bool {
        self.hot_pixels.is_empty() && self.burst_windows.is_empty()
    }

    /// Number of burst bins over all intervals.
    pub(crate) fn burst_bin_count(&self) -> usize {
        self.burst_bins.iter().flatten().filter(|&&b| b).count()
    }

    /// The events the counts leave out: the burst bins and the hot pixels.
    pub(crate) fn exclusion(&self) -> Exclusion {
        Exclusion {
            bins: self.burst_bins.clone(),
            pixels: (!self.hot_pixels.is_empty()).then(|| Arc::from(self.hot.as_slice())),
        }
    }

    /// Whether an event at `t` in pixel `(x, y)` is left out (at a hot pixel or in a
    /// burst bin).
    pub(crate) fn excludes(&self, t: f64, x: u16, y: u16) -> bool {
        let at_hot = self
            .hot
            .get(y as usize * self.width + x as usize)
            .copied()
            .unwrap_or(false);
        // the first window ending after t is the only one that can hold it
        let k = self.burst_windows.partition_point(|w| w[1] <= t);
        at_hot || self.burst_windows.get(k).is_some_and(|w| w[0] <= t)
    }
}

impl RateOutliers {
    /// The events of `window` that are not left out, as a stream of their own, with the
    /// index of each in the stream `window` was cut from; `None` when none is left out
    /// (use `window` itself).
    pub(crate) fn kept_events(&self, window: &EventSlice<'_>) -> Option<(EventStream, Vec<u64>)> {
        let out = |i: usize| self.excludes(window.t[i], window.x[i], window.y[i]);
        if self.is_empty() || !(0..window.len()).any(out) {
            return None;
        }
        let mut kept = EventStream::new(window.width, window.height);
        let mut index = Vec::new();
        for i in (0..window.len()).filter(|&i| !out(i)) {
            kept.push(window.t[i], window.x[i], window.y[i], window.p[i]);
            index.push((window.offset + i) as u64);
        }
        Some((kept, index))
    }
}

/// Hot flags per pixel and the median count of the active pixels (module docs).
fn hot_pixels(count: &[u32], w: usize, h: usize, ratio: f64) -> (Vec<bool>, f64) {
    let mut active: Vec<f64> = count
        .iter()
        .filter(|&&c| c > 0)
        .map(|&c| c as f64)
        .collect();
    let m = median(&mut active);
    let mut hot = vec![false; w * h];
    if ratio <= 0.0 {
        return (hot, m);
    }
    let mut around = Vec::with_capacity(8);
    for y in 0..h {
        for x in 0..w {
            let c = count[y * w + x] as f64;
            // cheap test first: most pixels are not above ratio·m
            if c <= ratio * m {
                continue;
            }
            around.clear();
            for (dx, dy) in (-1i64..=1).flat_map(|dy| (-1i64..=1).map(move |dx| (dx, dy))) {
                let (xx, yy) = (x as i64 + dx, y as i64 + dy);
                if (dx, dy) != (0, 0) && (0..w as i64).contains(&xx) && (0..h as i64).contains(&yy)
                {
                    around.push(count[yy as usize * w + xx as usize] as f64);
                }
            }
            hot[y * w + x] = c > ratio * median(&mut around).max(m);
        }
    }
    (hot, m)
}

/// Burst flags per interval and bin, and the median bin rate (events/s; module docs),
/// the events at `hot_times` (sorted) not counted; `(ratio, edge_ratio)` the settings'.
fn burst_bins(
    events: &EventSlice<'_>,
    hot_times: &[f64],
    frame_times: &[f64],
    bins: usize,
    (ratio, edge_ratio): (f64, f64),
) -> (Vec<Vec<bool>>, f64) {
    // (events, length) of every bin, the intervals' bins one after another in time
    let mut all: Vec<(f64, f64)> = Vec::new();
    for f in frame_times.windows(2) {
        let edges = bin_edges(f[0], f[1].max(f[0]), bins);
        let before =
            |e: f64| events.t.partition_point(|&t| t < e) - hot_times.partition_point(|&t| t < e);
        let at: Vec<usize> = edges.iter().map(|&e| before(e)).collect();
        all.extend((0..bins).map(|b| ((at[b + 1] - at[b]) as f64, edges[b + 1] - edges[b])));
    }
    let mut rates: Vec<f64> = all
        .iter()
        .filter(|(_, len)| *len > 0.0)
        .map(|(n, len)| n / len)
        .collect();
    let typical = median(&mut rates);
    // above `r` times the typical rate, the typical count taken as at least
    // MIN_TYPICAL_BIN_EVENTS (a few events in a bin of a sparse recording are no burst)
    let above = |b: usize, r: f64| {
        let (n, len) = all[b];
        r > 0.0 && len > 0.0 && n > r * (typical * len).max(MIN_TYPICAL_BIN_EVENTS)
    };
    let seeds: Vec<bool> = (0..all.len()).map(|b| above(b, ratio)).collect();
    let mut flags = seeds.clone();
    // each run of burst bins grows over its neighbours above the edge ratio (across
    // train frames too: a burst does not stop at one)
    for b in (0..all.len()).filter(|&b| seeds[b]) {
        let mut k = b;
        while k > 0 && !flags[k - 1] && above(k - 1, edge_ratio) {
            k -= 1;
            flags[k] = true;
        }
        let mut k = b;
        while k + 1 < all.len() && !seeds[k + 1] && above(k + 1, edge_ratio) {
            k += 1;
            flags[k] = true;
        }
    }
    let per_interval = flags.chunks(bins).map(<[bool]>::to_vec).collect();
    (per_interval, typical)
}
