//! Prophesee / Metavision `.raw` files in the EVT 2.0 and EVT 3.0 encodings, after the
//! public format descriptions (docs.prophesee.ai, "Data Encoding Formats").
//!
//! A `.raw` file is an ASCII header of lines starting with `%` (ended by `% end` in
//! recent versions, else by the first line that does not start with `%`), then the
//! words of the encoding, little-endian. The header names the encoding (`% evt 2.0`,
//! `% evt 3.0`, or `% format EVT2` / `% format EVT3;height=H;width=W`) and the sensor
//! (`% geometry WxH`, or the `width`/`height` of the format line; older Metavision
//! files name only the HAL plugin, whose sensor is known: see `sensor_of_plugin`).
//! Checked once against two real Metavision recordings (an EVT 2.0 Gen3 file, 539 481
//! events, and an EVT 3.0 Gen4.1 file with vectors, 219 596 events; BENCHMARKS.md,
//! "Real .raw files"); they are not kept in the repository (their licence).
//!
//! **EVT 2.0**: 32-bit words, type in bits 31..28. `CD_OFF` (0x0) / `CD_ON` (0x1):
//! timestamp LSBs in 27..22, x in 21..11, y in 10..0; `EVT_TIME_HIGH` (0x8): the 28
//! timestamp MSBs in 27..0; the event time is `high << 6 | low` µs.
//! **EVT 3.0**: 16-bit words, type in bits 15..12, state carried between words:
//! `EVT_ADDR_Y` (0x0) y in 10..0; `EVT_ADDR_X` (0x2) one event, polarity bit 11, x in
//! 10..0; `VECT_BASE_X` (0x3) polarity and base x; `VECT_12` (0x4) / `VECT_8` (0x5) a
//! mask of 12 / 8 events at base x + bit index, then base x advances by 12 / 8;
//! `EVT_TIME_LOW` (0x6) / `EVT_TIME_HIGH` (0x8) the low / high 12 bits of a 24-bit µs
//! time.
//!
//! In both, triggers (0xA), `OTHERS` (0xE) and continuation words (0x7, 0xF) are
//! skipped; other types are reserved and an error. The time high part wraps around
//! (EVT 2.0 after 2³⁴ µs ≈ 4.8 h, EVT 3.0 after 2²⁴ µs ≈ 16.8 s): a time high smaller
//! than the previous one starts a new period. Timestamps become seconds `µs / 1e6`,
//! counted from the start of the first period (the file cannot say how many periods
//! passed before it started). Events must come out sorted (checked like every reader).
//!
//! [`write_raw`] writes either encoding (events only, no vectors in EVT 3.0), timestamps
//! rounded to whole microseconds: for tests and for handing streams to Metavision. The
//! periods before the first event and any gap of a whole period are written as explicit
//! wraps (time-high words that go down), so every stream our reader produces reads back.

use super::{ReadOptions, check, resolve_sensor};
use crate::atomic::write_atomic;
use crate::error::{Error, IoContext, Result};
use crate::events::EventStream;
use std::io::Write;
use std::path::Path;

/// The two encodings read and written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RawEncoding {
    Evt2,
    Evt3,
}

/// Largest header accepted (real headers are a few hundred bytes).
const MAX_HEADER: usize = 1 << 20;

/// What the header says, and where the data start.
#[derive(Debug, PartialEq)]
struct RawHeader {
    encoding: Option<RawEncoding>,
    sensor: Option<(u32, u32)>,
    data_start: usize,
}

fn parse_header(bytes: &[u8]) -> std::result::Result<RawHeader, String> {
    let mut h = RawHeader {
        encoding: None,
        sensor: None,
        data_start: 0,
    };
    let (mut w, mut ht) = (None, None);
    let mut plugin = None;
    let mut pos = 0;
    while pos < bytes.len() && bytes[pos] == b'%' {
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map(|i| pos + i + 1)
            .ok_or("header line without an end of line: truncated")?;
        if end > MAX_HEADER {
            return Err(format!("header longer than {MAX_HEADER} bytes"));
        }
        let line = String::from_utf8_lossy(&bytes[pos + 1..end]);
        let line = line.trim();
        pos = end;
        let (key, value) = line.split_once(' ').unwrap_or((line, ""));
        let value = value.trim();
        match key {
            "end" => break,
            "evt" => {
                h.encoding = Some(match value {
                    "2.0" => RawEncoding::Evt2,
                    "3.0" => RawEncoding::Evt3,
                    v => {
                        return Err(format!(
                            "encoding `evt {v}` is not supported (EVT 2.0, 3.0 are)"
                        ));
                    }
                })
            }
            "format" => {
                let mut parts = value.split(';');
                let name = parts.next().unwrap_or("").trim();
                h.encoding = Some(match name {
                    "EVT2" => RawEncoding::Evt2,
                    "EVT3" => RawEncoding::Evt3,
                    v => return Err(format!("format {v} is not supported (EVT2, EVT3 are)")),
                });
                for kv in parts {
                    match kv.trim().split_once('=') {
                        Some(("width", v)) => w = Some(dimension(v)?),
                        Some(("height", v)) => ht = Some(dimension(v)?),
                        _ => {}
                    }
                }
            }
            "plugin_name" => plugin = Some(value.to_string()),
            "geometry" => {
                let (a, b) = value
                    .split_once('x')
                    .ok_or_else(|| format!("geometry {value:?} is not WxH"))?;
                h.sensor = Some((dimension(a)?, dimension(b)?));
            }
            _ => {}
        }
    }
    if let (None, Some(w), Some(ht)) = (h.sensor, w, ht) {
        h.sensor = Some((w, ht));
    }
    if h.sensor.is_none() {
        h.sensor = plugin.as_deref().and_then(sensor_of_plugin);
    }
    h.data_start = pos;
    Ok(h)
}

/// The sensor of a Prophesee HAL plugin, for older files whose header names only the
/// plugin (`% plugin_name hal_plugin_gen41_evk3`): Gen3 / Gen3.1 are VGA (640×480),
/// Gen4 / Gen4.1 and the IMX636 are HD (1280×720). Unknown plugins give `None`.
fn sensor_of_plugin(name: &str) -> Option<(u32, u32)> {
    let chip = name.strip_prefix("hal_plugin_")?.split('_').next()?;
    match chip {
        "gen3" | "gen31" => Some((640, 480)),
        "gen4" | "gen41" | "imx636" => Some((1280, 720)),
        _ => None,
    }
}

fn dimension(v: &str) -> std::result::Result<u32, String> {
    v.trim()
        .parse::<u32>()
        .map_err(|_| format!("sensor dimension {v:?} is not a number"))
}

/// Read a Prophesee `.raw` file (EVT 2.0 or 3.0; format in the module doc).
pub fn read_raw(path: impl AsRef<Path>, opts: &ReadOptions) -> Result<EventStream> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).at(path)?;
    let bad = |msg: String| Error::invalid(path, msg);
    if bytes.is_empty() {
        return Err(bad("file is empty".into()));
    }
    let header = parse_header(&bytes).map_err(|m| bad(format!("header: {m}")))?;
    let encoding = header.encoding.ok_or_else(|| {
        bad("header names no event encoding (`% evt 3.0` or `% format EVT3`): not a Prophesee .raw file?".into())
    })?;
    let (width, height) = resolve_sensor(path, header.sensor, opts)?;
    let data = &bytes[header.data_start..];
    let mut ev = EventStream::new(width, height);
    let decoded = match encoding {
        RawEncoding::Evt2 => decode_evt2(data, &mut ev),
        RawEncoding::Evt3 => decode_evt3(data, &mut ev),
    };
    decoded.map_err(|(word, msg)| {
        let size = if encoding == RawEncoding::Evt2 { 4 } else { 2 };
        bad(format!(
            "word {word} (byte {}): {msg}",
            header.data_start + word * size
        ))
    })?;
    check(path, &ev)?;
    Ok(ev)
}

/// Errors carry the index of the offending word.
type Decoded = std::result::Result<(), (usize, String)>;

fn push_us(ev: &mut EventStream, us: u64, x: u16, y: u16, on: bool) {
    ev.push(us as f64 / 1e6, x, y, if on { 1 } else { -1 });
}

fn decode_evt2(data: &[u8], ev: &mut EventStream) -> Decoded {
    let n = data.len() / 4;
    if !data.len().is_multiple_of(4) {
        return Err((n, format!("{} trailing bytes: truncated", data.len() % 4)));
    }
    let (mut high, mut epoch) = (0u64, 0u64);
    for (k, w) in data.chunks_exact(4).enumerate() {
        let w = u32::from_le_bytes([w[0], w[1], w[2], w[3]]);
        match w >> 28 {
            0x0 | 0x1 => {
                let low = ((w >> 22) & 0x3F) as u64;
                let us = ((epoch << 28 | high) << 6) | low;
                let (x, y) = (((w >> 11) & 0x7FF) as u16, (w & 0x7FF) as u16);
                push_us(ev, us, x, y, w >> 28 == 1);
            }
            0x8 => {
                let new = (w & 0x0FFF_FFFF) as u64;
                if new < high {
                    epoch += 1;
                }
                high = new;
            }
            0xA | 0xE | 0xF => {}
            t => return Err((k, format!("reserved EVT 2.0 word type {t:#x}"))),
        }
    }
    Ok(())
}

fn decode_evt3(data: &[u8], ev: &mut EventStream) -> Decoded {
    let n = data.len() / 2;
    if !data.len().is_multiple_of(2) {
        return Err((n, "1 trailing byte: truncated".into()));
    }
    let (mut high, mut low, mut epoch) = (0u64, 0u64, 0u64);
    let mut y: Option<u16> = None;
    let (mut base_x, mut on) = (0u32, false);
    for (k, w) in data.chunks_exact(2).enumerate() {
        let w = u16::from_le_bytes([w[0], w[1]]);
        let us = (epoch << 24) | (high << 12) | low;
        let row = |y: Option<u16>| y.ok_or((k, "an event before any EVT_ADDR_Y word".to_string()));
        match w >> 12 {
            0x0 => y = Some(w & 0x7FF),
            0x2 => {
                let y = row(y)?;
                push_us(ev, us, w & 0x7FF, y, w & 0x800 != 0);
            }
            0x3 => {
                base_x = (w & 0x7FF) as u32;
                on = w & 0x800 != 0;
            }
            t @ (0x4 | 0x5) => {
                let y = row(y)?;
                let (mask, len) = if t == 0x4 {
                    (w & 0xFFF, 12)
                } else {
                    (w & 0xFF, 8)
                };
                for i in 0..len {
                    if mask & (1 << i) != 0 {
                        let x = u16::try_from(base_x + i)
                            .map_err(|_| (k, format!("vector x {} out of range", base_x + i)))?;
                        push_us(ev, us, x, y, on);
                    }
                }
                base_x += len;
            }
            0x6 => low = (w & 0xFFF) as u64,
            0x8 => {
                let new = (w & 0xFFF) as u64;
                if new < high {
                    epoch += 1;
                }
                high = new;
            }
            0x7 | 0xA | 0xE | 0xF => {}
            t => return Err((k, format!("reserved EVT 3.0 word type {t:#x}"))),
        }
    }
    Ok(())
}

/// Whole microseconds of each event (rounded), checked to be representable.
fn microseconds(path: &Path, ev: &EventStream) -> Result<Vec<u64>> {
    ev.t.iter()
        .enumerate()
        .map(|(i, &t)| {
            let us = (t * 1e6).round();
            if (0.0..1.8e19).contains(&us) {
                Ok(us as u64)
            } else {
                Err(Error::invalid(
                    path,
                    format!("event {i}: timestamp {t} s cannot be stored"),
                ))
            }
        })
        .collect()
}

/// The time-high words that bring a reader (module doc: a smaller time high starts a
/// new period) from `state` = (period, high) to period `epoch` and high `h`: one
/// `1, 0` or `0` per period to pass (so a recording that starts hours into the clock,
/// or a gap of a full period, reads back), then `h` (always for the first event, as
/// Metavision writes one before any event). `emit(high)` writes one word.
fn time_high_words(state: &mut WriterTime, epoch: u64, h: u64, mut emit: impl FnMut(u64)) {
    while state.epoch < epoch {
        if state.high == 0 {
            emit(1);
        }
        emit(0);
        (state.epoch, state.high, state.any) = (state.epoch + 1, 0, true);
    }
    if state.high != h || !state.any {
        emit(h);
        (state.high, state.any) = (h, true);
    }
}

/// What a reader of the words written so far holds: its period and time high (both 0
/// at the start), and whether any time-high word was written.
#[derive(Clone, Copy, Default, PartialEq)]
struct WriterTime {
    epoch: u64,
    high: u64,
    any: bool,
}

/// Write `ev` as a `.raw` file in `encoding` (atomic; module doc).
pub fn write_raw(path: impl AsRef<Path>, ev: &EventStream, encoding: RawEncoding) -> Result<()> {
    let path = path.as_ref();
    check(path, ev)?;
    if ev.width > 2048 || ev.height > 2048 {
        return Err(Error::invalid(
            path,
            format!(
                "sensor {}x{} exceeds the 2048x2048 of EVT 2.0/3.0",
                ev.width, ev.height
            ),
        ));
    }
    let (name, evt) = match encoding {
        RawEncoding::Evt2 => ("EVT2", "2.0"),
        RawEncoding::Evt3 => ("EVT3", "3.0"),
    };
    let us = microseconds(path, ev)?;
    let mut body: Vec<u8> = Vec::with_capacity(ev.len() * 6);
    match encoding {
        RawEncoding::Evt2 => {
            let mut state = WriterTime::default();
            for (i, &us) in us.iter().enumerate() {
                let (epoch, h) = (us >> 34, (us >> 6) & 0x0FFF_FFFF);
                time_high_words(&mut state, epoch, h, |h| {
                    body.extend_from_slice(&((0x8u32 << 28) | h as u32).to_le_bytes())
                });
                let w = (u32::from(ev.p[i] > 0) << 28)
                    | (((us & 0x3F) as u32) << 22)
                    | ((ev.x[i] as u32) << 11)
                    | ev.y[i] as u32;
                body.extend_from_slice(&w.to_le_bytes());
            }
        }
        RawEncoding::Evt3 => {
            let (mut state, mut low, mut row) = (WriterTime::default(), None, None);
            let mut word = |w: u16| body.extend_from_slice(&w.to_le_bytes());
            for (i, &us) in us.iter().enumerate() {
                let (epoch, h, l) = (us >> 24, (us >> 12) & 0xFFF, us & 0xFFF);
                let before = state;
                time_high_words(&mut state, epoch, h, |h| word(0x8000 | h as u16));
                if state != before {
                    low = None;
                }
                if low != Some(l) {
                    word(0x6000 | l as u16);
                    low = Some(l);
                }
                if row != Some(ev.y[i]) {
                    word(ev.y[i]);
                    row = Some(ev.y[i]);
                }
                word(0x2000 | (u16::from(ev.p[i] > 0) << 11) | ev.x[i]);
            }
        }
    }
    write_atomic(path, |w| {
        write!(
            w,
            "% evt {evt}\n% format {name};height={};width={}\n% geometry {}x{}\n% end\n",
            ev.height, ev.width, ev.width, ev.height
        )?;
        w.write_all(&body)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_variants() {
        let h = parse_header(b"% camera IMX636\n% format EVT3;height=720;width=1280\n% end\nxx")
            .unwrap();
        assert_eq!(h.encoding, Some(RawEncoding::Evt3));
        assert_eq!(h.sensor, Some((1280, 720)));
        assert_eq!(h.data_start, 58);
        // Headers of real files that name only the plugin (Metavision 2020 recordings).
        let h = parse_header(
            b"% Date 2020-09-25 07:48:29\n% evt 3.0\n% firmware_version 3.2.3\n\
              % integrator_name Prophesee\n% plugin_name hal_plugin_gen41_evk3\n\x00\x80",
        )
        .unwrap();
        assert_eq!(
            (h.encoding, h.sensor),
            (Some(RawEncoding::Evt3), Some((1280, 720)))
        );
        let h = parse_header(b"% plugin_name hal_plugin_gen3_fx3\n% evt 2.0\n\x00").unwrap();
        assert_eq!(h.sensor, Some((640, 480)));
        let h = parse_header(b"% plugin_name hal_plugin_gen3_fx3\n% geometry 320x240\n\x00");
        assert_eq!(
            h.unwrap().sensor,
            Some((320, 240)),
            "the geometry line wins"
        );
        let h = parse_header(b"% plugin_name hal_plugin_sony_x\n% evt 2.0\n\x00").unwrap();
        assert_eq!(h.sensor, None);
        // Older files: `% evt` and `% geometry`, no `% end`.
        let h = parse_header(b"% evt 2.0\n% geometry 640x480\n\x01\x02").unwrap();
        assert_eq!(
            (h.encoding, h.sensor, h.data_start),
            (Some(RawEncoding::Evt2), Some((640, 480)), 29)
        );
        assert!(parse_header(b"% evt 2.1\n").unwrap_err().contains("2.1"));
        assert!(
            parse_header(b"% geometry 64\n")
                .unwrap_err()
                .contains("WxH")
        );
        assert!(
            parse_header(b"% evt 3.0")
                .unwrap_err()
                .contains("truncated")
        );
        let h = parse_header(b"\x00\x80").unwrap();
        assert_eq!((h.encoding, h.data_start), (None, 0));
    }

    #[test]
    fn evt3_vectors_and_time_wrap_decode() {
        let words: [u16; 9] = [
            0x8000 | 0xFFF,            // time high 0xFFF
            0x6000 | 0x005,            // time low 5 → t = 0xFFF005 µs
            7,                         // EVT_ADDR_Y (type 0): y = 7
            0x3000 | 0x800 | 100,      // base x 100, ON
            0x4000 | 0b1000_0000_0101, // x 100, 102, 111
            0x5000 | 0b1000_0001,      // x 112, 119
            0x8000 | 0x001,            // wrap: new period, high 1
            0x6000 | 0x002,            // t = 2^24 + 0x1002 µs
            0x2000 | 3,                // single OFF event at x 3
        ];
        let data: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        let mut ev = EventStream::new(2048, 2048);
        decode_evt3(&data, &mut ev).unwrap();
        assert_eq!(ev.x, vec![100, 102, 111, 112, 119, 3]);
        assert_eq!(ev.y, vec![7; 6]);
        assert_eq!(ev.p, vec![1, 1, 1, 1, 1, -1]);
        assert_eq!(ev.t[0], 0xFFF005 as f64 / 1e6);
        assert_eq!(ev.t[5], ((1u64 << 24) + 0x1002) as f64 / 1e6);
        // An event before any row address, a reserved type, an odd length.
        let e = decode_evt3(&0x2003u16.to_le_bytes(), &mut ev).unwrap_err();
        assert_eq!(e.0, 0);
        assert!(e.1.contains("EVT_ADDR_Y"));
        assert!(
            decode_evt3(&0x9000u16.to_le_bytes(), &mut ev)
                .unwrap_err()
                .1
                .contains("0x9")
        );
        assert!(
            decode_evt3(&[0], &mut ev)
                .unwrap_err()
                .1
                .contains("truncated")
        );
    }

    #[test]
    fn evt2_time_high_and_wrap_decode() {
        let words: [u32; 4] = [
            0x8000_0000 | 0x0FFF_FFFF,
            (1 << 28) | (63 << 22) | (5 << 11) | 9, // ON, t = (2^28 − 1)·64 + 63
            0x8000_0000 | 2,                        // wrap
            (12 << 22) | (2047 << 11) | 2047,       // OFF, t = (2^28 + 2)·64 + 12
        ];
        let data: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        let mut ev = EventStream::new(2048, 2048);
        decode_evt2(&data, &mut ev).unwrap();
        assert_eq!(
            (ev.x.clone(), ev.y.clone(), ev.p.clone()),
            (vec![5, 2047], vec![9, 2047], vec![1, -1])
        );
        assert_eq!(ev.t[0], (((1u64 << 28) - 1) * 64 + 63) as f64 / 1e6);
        assert_eq!(ev.t[1], (((1u64 << 28) + 2) * 64 + 12) as f64 / 1e6);
        assert!(
            decode_evt2(&0x3000_0000u32.to_le_bytes(), &mut ev)
                .unwrap_err()
                .1
                .contains("0x3")
        );
        assert!(
            decode_evt2(&[0, 0, 0], &mut ev)
                .unwrap_err()
                .1
                .contains("truncated")
        );
    }
}
