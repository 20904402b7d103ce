//! Frames with only a normalised time (blender `time`, nerfies `time_id`/`warp_id`)
//! beside an event file: finding that file, reading it for the frames' sensor, and
//! placing the frames on the events' clock (`timestamp = offset + time · duration`).

use scene::error::{Error, Result};
use scene::events::EventStream;
use scene::formats::{ReadOptions, read_events};
use std::path::{Path, PathBuf};

/// Layouts whose frames carry only a normalised time (blender, nerfies): where the
/// events are and how normalised times map to seconds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EventsAlignment {
    pub events: Option<PathBuf>,
    pub time_offset: Option<f64>,
    pub duration: Option<f64>,
}

/// Event file names looked for beside a layout's files, in this order.
pub(crate) const EVENT_NAMES: [&str; 6] = [
    "events.evs",
    "events.txt",
    "events.npz",
    "events.aedat4",
    "events.raw",
    "events.es",
];

/// The event file: `--events`, else the layout's own reference (relative to `src`), else
/// the first of [`EVENT_NAMES`] in `src`. `described_by` names the layout file in the
/// error when none is found.
pub fn event_file(
    src: &Path,
    o: &EventsAlignment,
    layout_ref: Option<&str>,
    described_by: &Path,
) -> Result<PathBuf> {
    if let Some(p) = &o.events {
        return Ok(p.clone());
    }
    if let Some(r) = layout_ref {
        return Ok(src.join(r));
    }
    EVENT_NAMES
        .iter()
        .map(|n| src.join(n))
        .find(|p| p.is_file())
        .ok_or_else(|| {
            Error::invalid(
                described_by,
                format!("no event file: none of {EVENT_NAMES:?} beside it; pass --events FILE"),
            )
        })
}

/// Read the events of a `width × height` sensor.
pub(crate) fn read_for_sensor(path: &Path, width: u32, height: u32) -> Result<EventStream> {
    read_events(
        path,
        &ReadOptions {
            sensor: Some((width, height)),
            coord_scale: None,
        },
    )
}

/// Maps normalised frame times in [0, 1] to seconds on the events' clock.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct TimeMap {
    pub offset: f64,
    pub duration: f64,
    /// Whether offset and duration were both given (else taken from the events' span).
    pub given: bool,
    /// Which of the two came from the events (for the warning).
    pub guessed: &'static str,
}

impl TimeMap {
    /// `--time-offset` / `--duration`, each defaulting to the events' first timestamp and
    /// their span.
    pub fn new(o: &EventsAlignment, events: &EventStream) -> Result<Self> {
        let (e0, e1) = span(events);
        let offset = o.time_offset.unwrap_or(e0);
        let duration = o.duration.unwrap_or(e1 - e0);
        if !(offset.is_finite() && duration.is_finite() && duration >= 0.0) {
            return Err(Error::Other(format!(
                "time offset {offset} / duration {duration}: must be finite, duration ≥ 0"
            )));
        }
        Ok(TimeMap {
            offset,
            duration,
            given: o.time_offset.is_some() && o.duration.is_some(),
            guessed: match (o.time_offset.is_some(), o.duration.is_some()) {
                (false, false) => "the events' first timestamp and span",
                (true, false) => "--time-offset, and the events' span as the duration",
                (false, true) => "the events' first timestamp as the offset, and --duration",
                (true, true) => "",
            },
        })
    }

    pub fn seconds(&self, normalised: f64) -> f64 {
        self.offset + normalised * self.duration
    }

    /// The warning to give when `n` frames were placed by a guessed map (none if given):
    /// where they went, and from what.
    pub fn warning(&self, n: usize) -> Option<String> {
        (n > 0 && !self.given).then(|| {
            format!(
                "{n} frames have only a normalised time: placed on {} … {} s from {} \
                 (pass --time-offset and --duration if the frames span another interval)",
                self.offset,
                self.seconds(1.0),
                self.guessed
            )
        })
    }
}

fn span(events: &EventStream) -> (f64, f64) {
    (
        events.t.first().copied().unwrap_or(0.0),
        events.t.last().copied().unwrap_or(0.0),
    )
}
