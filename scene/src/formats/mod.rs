//! Event stream readers and writers (DESIGN §3), chosen by file extension:
//!
//! | extension | format | module |
//! |---|---|---|
//! | `.txt` | ECD / rpg text, one event `t x y p` per line (t in s, p ∈ {0,1}) | [`text`] |
//! | `.npz` | NumPy archive with arrays `x`, `y`, `t` (µs), `p` (HS-ERGB layout) | [`npz`] |
//! | `.evs` | this project's columnar binary, memory-mappable | [`evs`] |
//! | `.aedat4` | iniVation AEDAT 4.0 (DV software, DAVIS/DVXplorer cameras); APS frames: [`aedat4_frames`] | [`aedat4`] |
//! | `.raw` | Prophesee / Metavision EVT 2.0 or EVT 3.0 (encoding named in its header) | [`prophesee`] |
//! | `.es` | Event Stream 2.x, DVS or ATIS type (sepia, loris, ATIS cameras) | [`event_stream`] |
//!
//! Every reader returns a stream that passed [`EventStream::validate`] (finite, sorted
//! timestamps; pixels inside the sensor; polarity ±1) or an error naming the file and
//! the first bad event. Unsorted input is an error, not silently re-sorted. Every
//! writer refuses invalid streams and writes atomically.

pub mod aedat4;
pub mod aedat4_frames;
pub mod event_stream;
pub mod evflow;
pub mod evs;
pub mod npz;
pub mod prophesee;
pub mod text;

use crate::error::{Error, Result};
use crate::events::EventStream;
use std::path::Path;

pub use aedat4_frames::{ApsFrame, read_aedat4_frames};
pub use event_stream::{read_es, write_es};
pub use evs::{EvsMap, read_evs, write_evs};
pub use npz::{read_npz, write_npz};
pub use prophesee::{RawEncoding, read_raw, write_raw};
pub use text::{read_text, write_text};

/// What a reader cannot learn from some files.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ReadOptions {
    /// Sensor `(width, height)`. Needed for text and `.npz` files (they do not store it;
    /// a text file written by [`write_text`] carries it in its header line). For formats
    /// that store it (`.evs`, `.aedat4` with sensor info) a different value is an error.
    pub sensor: Option<(u32, u32)>,
    /// `.npz` only: the stored `x`, `y` are pixel coordinates multiplied by this factor
    /// (HS-ERGB stores them ×32); the reader divides and rounds to the nearest pixel.
    pub coord_scale: Option<f64>,
}

/// The event file formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Text,
    Npz,
    Evs,
    Aedat4,
    /// Prophesee `.raw` (EVT 2.0 / 3.0).
    Raw,
    /// Event Stream `.es`.
    Es,
}

impl Format {
    /// From a path's extension (case-insensitive).
    pub(crate) fn from_path(path: &Path) -> Result<Format> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "txt" => Ok(Format::Text),
            "npz" => Ok(Format::Npz),
            "evs" => Ok(Format::Evs),
            "aedat4" => Ok(Format::Aedat4),
            "raw" => Ok(Format::Raw),
            "es" => Ok(Format::Es),
            _ => Err(Error::invalid(
                path,
                format!(
                    "unknown event file extension {ext:?} (expected .txt, .npz, .evs, .aedat4, .raw or .es)"
                ),
            )),
        }
    }

    pub fn name(&self) -> &'static str {
        match self {
            Format::Text => "text",
            Format::Npz => "npz",
            Format::Evs => "evs",
            Format::Aedat4 => "aedat4",
            Format::Raw => "raw",
            Format::Es => "es",
        }
    }
}

/// Read an event stream, choosing the format by extension.
pub fn read_events(path: impl AsRef<Path>, opts: &ReadOptions) -> Result<EventStream> {
    let path = path.as_ref();
    if opts.coord_scale.is_some() && Format::from_path(path)? != Format::Npz {
        return Err(Error::invalid(
            path,
            "a coordinate scale (--coord-scale, --hsergb) applies to .npz files only",
        ));
    }
    match Format::from_path(path)? {
        Format::Text => read_text(path, opts),
        Format::Npz => read_npz(path, opts),
        Format::Evs => read_evs(path, opts),
        Format::Aedat4 => aedat4::read_aedat4(path, opts),
        Format::Raw => read_raw(path, opts),
        Format::Es => read_es(path, opts),
    }
}

/// Write an event stream as `.evs`, `.txt`, `.npz`, `.raw` (EVT 3.0) or `.es` (DVS),
/// chosen by extension.
pub fn write_events(path: impl AsRef<Path>, ev: &EventStream) -> Result<()> {
    let path = path.as_ref();
    match Format::from_path(path)? {
        Format::Evs => write_evs(path, ev),
        Format::Text => write_text(path, ev),
        Format::Npz => write_npz(path, ev),
        Format::Aedat4 => Err(Error::invalid(path, "writing .aedat4 is not supported")),
        Format::Raw => write_raw(path, ev, RawEncoding::Evt3),
        Format::Es => write_es(path, ev),
    }
}

/// What [`convert`] did.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ConvertSummary {
    pub input_format: &'static str,
    pub output_format: &'static str,
    pub events: usize,
    pub width: u32,
    pub height: u32,
    /// First and last timestamp (s); 0 for an empty stream.
    pub t_first: f64,
    pub t_last: f64,
}

/// Read any supported file and write it as `.evs`, `.txt`, `.npz`, `.raw` or `.es` (by
/// the output's extension). Backs `degs events convert IN OUT`.
pub fn convert(
    input: impl AsRef<Path>,
    output: impl AsRef<Path>,
    opts: &ReadOptions,
) -> Result<ConvertSummary> {
    let (input, output) = (input.as_ref(), output.as_ref());
    let input_format = Format::from_path(input)?;
    let output_format = Format::from_path(output)?;
    let ev = read_events(input, opts)?;
    write_events(output, &ev)?;
    Ok(ConvertSummary {
        input_format: input_format.name(),
        output_format: output_format.name(),
        events: ev.len(),
        width: ev.width,
        height: ev.height,
        t_first: ev.t.first().copied().unwrap_or(0.0),
        t_last: ev.t.last().copied().unwrap_or(0.0),
    })
}

/// The sensor size a reader uses: the one stored in the file (`stored`), checked against
/// `opts.sensor`, else `opts.sensor`, else an error.
pub(crate) fn resolve_sensor(
    path: &Path,
    stored: Option<(u32, u32)>,
    opts: &ReadOptions,
) -> Result<(u32, u32)> {
    match (stored, opts.sensor) {
        (Some(s), Some(o)) if s != o => Err(Error::invalid(
            path,
            format!(
                "file says the sensor is {}x{} but {}x{} was expected",
                s.0, s.1, o.0, o.1
            ),
        )),
        (Some(s), _) | (None, Some(s)) => {
            if s.0 == 0 || s.1 == 0 || s.0 > 65536 || s.1 > 65536 {
                Err(Error::invalid(
                    path,
                    format!("sensor size {}x{} is not usable", s.0, s.1),
                ))
            } else {
                Ok(s)
            }
        }
        (None, None) => Err(Error::invalid(
            path,
            "the file does not store the sensor size: pass it with --sensor WxH",
        )),
    }
}

/// Check a stream a reader produced or a writer was given; errors name `path`.
/// The events are checked in parallel blocks; only when a block fails does the serial
/// [`EventStream::validate`] run, to word the error exactly.
pub(crate) fn check(path: &Path, ev: &EventStream) -> Result<()> {
    use rayon::prelude::*;
    const BLOCK: usize = 1 << 16;
    let n = ev.t.len();
    let lengths_ok = ev.x.len() == n && ev.y.len() == n && ev.p.len() == n;
    let ok = lengths_ok
        && ev.width > 0
        && ev.height > 0
        && (0..n.div_ceil(BLOCK)).into_par_iter().all(|b| {
            let (s, e) = (b * BLOCK, ((b + 1) * BLOCK).min(n));
            // Include the previous block's last timestamp in the order check.
            let t = &ev.t[s.saturating_sub(1)..e];
            t.iter().all(|v| v.is_finite())
                && t.windows(2).all(|w| w[0] <= w[1])
                && ev.x[s..e].iter().all(|&x| (x as u32) < ev.width)
                && ev.y[s..e].iter().all(|&y| (y as u32) < ev.height)
                && ev.p[s..e].iter().all(|&p| p == 1 || p == -1)
        });
    if ok {
        return Ok(());
    }
    ev.validate().map_err(|m| Error::invalid(path, m))
}
