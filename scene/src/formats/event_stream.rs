//! Event Stream `.es` files (neuromorphic-paris/event_stream specification, version
//! 2.x; written by the sepia / command_line_tools / loris tools and the ATIS cameras).
//!
//! Layout: the 12 ASCII bytes `Event Stream`, the version (major, minor, patch bytes;
//! major 2 is read), the stream type byte (0 generic, 1 DVS, 2 ATIS, 3 display, 4
//! colour), for DVS and ATIS the sensor width and height (`u16` little-endian each), then
//! a byte-oriented state machine. Timestamps are deltas in microseconds from the
//! previous event (the first from 0):
//!
//! - **DVS**: byte `0xFF` = overflow (t += 127), `0xFE` = reset (ignored between events);
//!   otherwise byte 0 holds the delta in bits 7..1 and `is_increase` in bit 0, followed
//!   by x (`u16` LE) and y (`u16` LE).
//! - **ATIS**: byte `0b111111nn` with nn ≠ 0 = overflow (t += 63·nn), `0xFC` = reset;
//!   otherwise byte 0 holds the delta in bits 7..2, `polarity` in bit 1 and `is_tc` in
//!   bit 0, then x and y as for DVS. Only DVS events (`is_tc` = 0) are kept; threshold
//!   crossings (exposure measurements) are skipped and counted by no one.
//!
//! Generic, display and colour streams hold no camera events and are refused. Times
//! become seconds `µs / 1e6`. [`write_es`] writes DVS streams (timestamps rounded to
//! whole microseconds; the first must not be negative).

use super::{ReadOptions, check, resolve_sensor};
use crate::atomic::write_atomic;
use crate::error::{Error, IoContext, Result};
use crate::events::EventStream;
use std::io::Write;
use std::path::Path;

pub const MAGIC: &[u8; 12] = b"Event Stream";
/// Bytes before the events of a DVS or ATIS file.
const HEADER: usize = 20;

/// Read an Event Stream file (DVS or ATIS type; module doc).
pub fn read_es(path: impl AsRef<Path>, opts: &ReadOptions) -> Result<EventStream> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).at(path)?;
    let bad = |msg: String| Error::invalid(path, msg);
    if bytes.is_empty() {
        return Err(bad("file is empty".into()));
    }
    if bytes.len() < 16 || &bytes[..12] != MAGIC {
        return Err(bad(
            "not an Event Stream file (magic `Event Stream` missing)".into(),
        ));
    }
    let (major, minor, patch) = (bytes[12], bytes[13], bytes[14]);
    if major != 2 {
        return Err(bad(format!(
            "Event Stream version {major}.{minor}.{patch} is not supported (2.x is)"
        )));
    }
    let atis = match bytes[15] {
        1 => false,
        2 => true,
        t => {
            let kind = match t {
                0 => "generic",
                3 => "display",
                4 => "colour",
                _ => "unknown",
            };
            return Err(bad(format!(
                "stream type {t} ({kind} events) holds no camera events (DVS or ATIS needed)"
            )));
        }
    };
    let size = bytes
        .get(16..HEADER)
        .ok_or_else(|| bad("truncated in the sensor size".into()))?;
    let stored = (
        u16::from_le_bytes([size[0], size[1]]) as u32,
        u16::from_le_bytes([size[2], size[3]]) as u32,
    );
    let (width, height) = resolve_sensor(path, Some(stored), opts)?;
    let mut ev = EventStream::new(width, height);
    decode(&bytes[HEADER..], atis, &mut ev)
        .map_err(|(at, msg)| bad(format!("byte {}: {msg}", HEADER + at)))?;
    check(path, &ev)?;
    Ok(ev)
}

/// Decode the event bytes; an error carries the offset (in `data`) it is about.
fn decode(
    data: &[u8],
    atis: bool,
    ev: &mut EventStream,
) -> std::result::Result<(), (usize, String)> {
    let mut t: u64 = 0;
    let mut i = 0;
    while i < data.len() {
        let b = data[i];
        let (delta, on, keep) = if atis {
            if b & 0xFC == 0xFC {
                t += 63 * (b & 0x03) as u64; // 0xFC (nn = 0) is the reset byte
                i += 1;
                continue;
            }
            ((b >> 2) as u64, b & 0x02 != 0, b & 0x01 == 0)
        } else {
            if b >= 0xFE {
                if b == 0xFF {
                    t += 127; // overflow; 0xFE is the reset byte
                }
                i += 1;
                continue;
            }
            ((b >> 1) as u64, b & 0x01 != 0, true)
        };
        let xy = data.get(i + 1..i + 5).ok_or((
            i,
            format!("event truncated after {} of its 5 bytes", data.len() - i),
        ))?;
        t += delta;
        if keep {
            let x = u16::from_le_bytes([xy[0], xy[1]]);
            let y = u16::from_le_bytes([xy[2], xy[3]]);
            ev.push(t as f64 / 1e6, x, y, if on { 1 } else { -1 });
        }
        i += 5;
    }
    Ok(())
}

/// Write `ev` as a DVS Event Stream 2.0.0 file (atomic; module doc).
pub fn write_es(path: impl AsRef<Path>, ev: &EventStream) -> Result<()> {
    let path = path.as_ref();
    check(path, ev)?;
    let (w, h) = match (u16::try_from(ev.width), u16::try_from(ev.height)) {
        (Ok(w), Ok(h)) => (w, h),
        _ => {
            return Err(Error::invalid(
                path,
                format!("sensor {}x{} does not fit 16 bits", ev.width, ev.height),
            ));
        }
    };
    let mut body = Vec::with_capacity(ev.len() * 5 + HEADER);
    body.extend_from_slice(MAGIC);
    body.extend_from_slice(&[2, 0, 0, 1]);
    body.extend_from_slice(&w.to_le_bytes());
    body.extend_from_slice(&h.to_le_bytes());
    let mut prev: u64 = 0;
    for i in 0..ev.len() {
        let us = (ev.t[i] * 1e6).round();
        if !(0.0..1.8e19).contains(&us) {
            return Err(Error::invalid(
                path,
                format!(
                    "event {i}: timestamp {} s cannot be stored (negative or too large)",
                    ev.t[i]
                ),
            ));
        }
        let us = us as u64;
        let mut delta = us - prev; // sorted (checked), so us ≥ prev
        prev = us;
        // Long gaps: 127 µs per overflow byte (bounded by the size check below).
        let overflows = delta / 127;
        if overflows > 1 << 32 {
            return Err(Error::invalid(
                path,
                format!("event {i}: a gap of {delta} µs would need {overflows} overflow bytes"),
            ));
        }
        body.resize(body.len() + overflows as usize, 0xFF);
        delta -= overflows * 127;
        body.push(((delta as u8) << 1) | u8::from(ev.p[i] > 0));
        body.extend_from_slice(&ev.x[i].to_le_bytes());
        body.extend_from_slice(&ev.y[i].to_le_bytes());
    }
    write_atomic(path, |f| f.write_all(&body))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dvs_bytes_decode_with_overflow_and_reset() {
        let data = [
            0xFF,
            0xFF, // +254 µs
            (3 << 1) | 1,
            10,
            0,
            20,
            1,    // +3 → 257 µs, ON, x 10, y 276
            0xFE, // reset: ignored
            0,
            0xFF,
            0xFF,
            0,
            0, // +0, OFF, x 65535, y 0
        ];
        let mut ev = EventStream::new(65535, 65535);
        decode(&data, false, &mut ev).unwrap();
        assert_eq!(ev.t, vec![257e-6, 257e-6]);
        assert_eq!(
            (ev.x.clone(), ev.y.clone(), ev.p.clone()),
            (vec![10, 65535], vec![276, 0], vec![1, -1])
        );
        let e = decode(&data[..5], false, &mut ev).unwrap_err();
        assert_eq!(e.0, 2);
        assert!(e.1.contains("truncated after 3 of its 5"), "{}", e.1);
    }

    #[test]
    fn atis_bytes_keep_dvs_events_and_skip_threshold_crossings() {
        let data = [
            0xFE, // overflow ×2: +126 µs
            0xFC, // reset
            (4 << 2) | 0b10,
            1,
            0,
            2,
            0, // +4 → 130 µs, DVS ON at (1, 2)
            (1 << 2) | 0b01,
            3,
            0,
            4,
            0, // +1 → 131 µs, threshold crossing: skipped
            (1 << 2),
            5,
            0,
            6,
            0, // +1 → 132 µs, DVS OFF at (5, 6)
        ];
        let mut ev = EventStream::new(8, 8);
        decode(&data, true, &mut ev).unwrap();
        assert_eq!(ev.t, vec![130e-6, 132e-6]);
        assert_eq!(
            (ev.x.clone(), ev.y.clone(), ev.p.clone()),
            (vec![1, 5], vec![2, 6], vec![1, -1])
        );
    }
}
