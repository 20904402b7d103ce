//! How the joint training degrades on degenerate inputs instead of producing NaN or
//! pretend supervision (docs/DESIGN.md §9, "Fallbacks"), and the counts `report.json`
//! gives of it.
//!
//! - **`L_event` is skipped** for an iteration (the iteration is supervised by `L_rgb`
//!   and `L_motion` only) when the interval it drew has zero length (two train frames
//!   at the same time), has **no event at all** (a recording gap: an event camera
//!   watching a scene always emits some events, so an interval without any is missing
//!   data, and the pseudo image would be the nearer frame copied, a frozen-scene prior
//!   pretending to be supervision), or when no value of its pseudo image is valid
//!   (both usable sides black or clipped, or every prediction out of range).
//! - **Bound events are dropped from `L_motion`** when they have no flow (no `.evflow`
//!   window covers them, or their flow is beyond the flow network's range and was
//!   discarded when read) or are outliers among their Gaussian's events
//!   ([`crate::motion_loss`]), or belong to a Gaussian whose events' mean flow
//!   disagrees with its neighbours' in the image ([`crate::neighbours`]), or lie at a
//!   hot pixel or in a burst ([`crate::rate_outliers`]).
//! - **Event-rate outliers are left out** ([`crate::rate_outliers`]): hot pixels are
//!   masked out of every pseudo image and the events of burst bins are not counted in
//!   them.

use crate::event_counts::IntervalCounts;
use serde::Serialize;

/// Why an iteration's `L_event` was skipped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum EventSkip {
    /// The interval has zero length (frames at the same time).
    EmptyInterval,
    /// No event in the interval (a gap in the recording).
    NoEvents,
    /// No valid value in the pseudo image (black or clipped frames, predictions out of
    /// range).
    NoValidPixels,
}

/// Why the interval `k` cannot supervise `L_event`, if it cannot (before any pseudo
/// image is made).
pub(crate) fn interval_skip(k: &IntervalCounts) -> Option<EventSkip> {
    let (a, b) = k.span();
    if b <= a {
        Some(EventSkip::EmptyInterval)
    } else if k.events() == 0 {
        Some(EventSkip::NoEvents)
    } else {
        None
    }
}

/// What the training left out, over the whole run (`report.json`, `fallbacks`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Fallbacks {
    /// Iterations whose `L_event` was skipped (RGB-only supervision there), all reasons.
    pub event_steps_skipped: u64,
    pub event_skipped_empty_interval: u64,
    pub event_skipped_no_events: u64,
    pub event_skipped_no_valid_pixels: u64,
    /// Bound events left out of `L_motion`, summed over iterations, all reasons.
    pub bindings_dropped: u64,
    /// … because they had no (finite) flow.
    pub bindings_dropped_no_flow: u64,
    /// … as outliers among their Gaussian's events.
    pub bindings_dropped_outliers: u64,
    /// … because their Gaussian's mean flow disagreed with its neighbours'
    /// ([`crate::neighbours`]).
    pub bindings_dropped_disagreeing: u64,
    /// … because they are at a hot pixel or in a burst bin.
    pub bindings_dropped_rate_outliers: u64,
    /// Rebindings of a train frame that found no Gaussian alive there (every one outside
    /// its life): that frame's `L_motion` had no bindings until the next rebinding.
    pub rebind_frames_unbound: u64,
    /// Hot pixels: masked out of every pseudo image, their events out of `L_motion`.
    pub hot_pixels: usize,
    /// Events at the hot pixels.
    pub hot_pixel_events: usize,
    /// Time bins of the counts (`counts.bins` per interval) taken for a burst: their
    /// events are counted in no pseudo image and left out of `L_motion`.
    pub burst_bins: usize,
    /// Events in those bins (at hot pixels too).
    pub burst_events: usize,
    /// Events of the stream whose flow was beyond the flow network's range (discarded
    /// when read; included in `events_without_flow`).
    pub flows_out_of_range: usize,
    /// Events of the stream without a usable flow.
    pub events_without_flow: usize,
}

impl Fallbacks {
    /// Count one skipped `L_event`.
    pub(crate) fn skip_event(&mut self, why: EventSkip) {
        self.event_steps_skipped += 1;
        *match why {
            EventSkip::EmptyInterval => &mut self.event_skipped_empty_interval,
            EventSkip::NoEvents => &mut self.event_skipped_no_events,
            EventSkip::NoValidPixels => &mut self.event_skipped_no_valid_pixels,
        } += 1;
    }

    /// Count the bound events one `L_motion` left out.
    pub(crate) fn drop_bindings(&mut self, d: &DroppedBindings) {
        self.bindings_dropped_no_flow += d.no_flow as u64;
        self.bindings_dropped_outliers += d.outliers as u64;
        self.bindings_dropped_disagreeing += d.disagreeing as u64;
        self.bindings_dropped_rate_outliers += d.rate_outliers as u64;
        self.bindings_dropped += d.total() as u64;
    }
}

/// The bound events one `L_motion` left out, by reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct DroppedBindings {
    /// No (finite) flow.
    pub no_flow: usize,
    /// Outliers among their Gaussian's events.
    pub outliers: usize,
    /// Their Gaussian disagrees with its neighbours.
    pub disagreeing: usize,
    /// At a hot pixel or in a burst bin.
    pub rate_outliers: usize,
}

impl DroppedBindings {
    pub fn total(&self) -> usize {
        self.no_flow + self.outliers + self.disagreeing + self.rate_outliers
    }
}
