//! ECD / rpg text events: one event per line, `t x y p` separated by white space,
//! `t` in seconds, `x y` integer pixels, `p` ∈ {0, 1} (also accepted: −1, +1).
//! Lines starting with `#` and blank lines are skipped. The sensor size is not part of
//! the ECD layout; [`write_text`] adds a first line `# degs-events width=W height=H`
//! that [`read_text`] understands, otherwise [`ReadOptions::sensor`] must give it.
//!
//! Timestamps are written with Rust's shortest round-trip formatting, so
//! `read_text(write_text(s)) == s` bit for bit. Parsing runs in parallel over chunks of
//! lines (rayon).

use super::{ReadOptions, check, resolve_sensor};
use crate::atomic::write_atomic;
use crate::error::{Error, IoContext, Result};
use crate::events::EventStream;
use rayon::prelude::*;
use std::io::Write;
use std::path::Path;

/// First line written by [`write_text`].
const HEADER_TAG: &str = "degs-events";

/// Bytes per parallel parsing chunk.
const CHUNK: usize = 1 << 22;

/// Columns parsed from one chunk.
#[derive(Default)]
struct Columns {
    t: Vec<f64>,
    x: Vec<u16>,
    y: Vec<u16>,
    p: Vec<i8>,
}

/// Read a text event file.
pub fn read_text(path: impl AsRef<Path>, opts: &ReadOptions) -> Result<EventStream> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).at(path)?;
    if bytes.is_empty() {
        return Err(Error::invalid(path, "file is empty"));
    }
    let stored = header_sensor(path, &bytes)?;
    let (width, height) = resolve_sensor(path, stored, opts)?;

    // Chunk boundaries just after a newline, so every chunk holds whole lines.
    let mut bounds = vec![0usize];
    while *bounds.last().unwrap_or(&0) < bytes.len() {
        let start = *bounds.last().unwrap_or(&0) + CHUNK;
        if start >= bytes.len() {
            bounds.push(bytes.len());
            break;
        }
        let end = bytes[start..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |i| start + i + 1);
        bounds.push(end);
    }
    let parsed: Vec<std::result::Result<Columns, (usize, String)>> = bounds
        .par_windows(2)
        .map(|w| parse_chunk(&bytes[w[0]..w[1]], w[0]))
        .collect();
    let mut ev = EventStream::new(width, height);
    let total: usize = parsed
        .iter()
        .map(|c| c.as_ref().map_or(0, |c| c.t.len()))
        .sum();
    ev.t.reserve_exact(total);
    ev.x.reserve_exact(total);
    ev.y.reserve_exact(total);
    ev.p.reserve_exact(total);
    for chunk in parsed {
        let c = chunk.map_err(|(offset, msg)| {
            let line = 1 + bytes[..offset].iter().filter(|&&b| b == b'\n').count();
            Error::invalid(path, format!("line {line}: {msg}"))
        })?;
        ev.t.extend_from_slice(&c.t);
        ev.x.extend_from_slice(&c.x);
        ev.y.extend_from_slice(&c.y);
        ev.p.extend_from_slice(&c.p);
    }
    check(path, &ev)?;
    Ok(ev)
}

/// `width=W height=H` from the leading `#` lines, if present.
fn header_sensor(path: &Path, bytes: &[u8]) -> Result<Option<(u32, u32)>> {
    for line in bytes.split(|&b| b == b'\n').take(16) {
        let line = String::from_utf8_lossy(line);
        let Some(rest) = line.trim().strip_prefix('#') else {
            break;
        };
        if !rest.split_whitespace().any(|w| w == HEADER_TAG) {
            continue;
        }
        let mut w = None;
        let mut h = None;
        for kv in rest.split_whitespace() {
            if let Some(v) = kv.strip_prefix("width=") {
                w = v.parse::<u32>().ok();
            } else if let Some(v) = kv.strip_prefix("height=") {
                h = v.parse::<u32>().ok();
            }
        }
        return match (w, h) {
            (Some(w), Some(h)) => Ok(Some((w, h))),
            _ => Err(Error::invalid(
                path,
                format!("line 1: header {:?} lacks width=… height=…", line.trim()),
            )),
        };
    }
    Ok(None)
}

/// Parse whole lines; an error carries the byte offset (in the file) of its line.
fn parse_chunk(chunk: &[u8], base: usize) -> std::result::Result<Columns, (usize, String)> {
    let mut c = Columns::default();
    let guess = chunk.len() / 24 + 1;
    c.t.reserve(guess);
    c.x.reserve(guess);
    c.y.reserve(guess);
    c.p.reserve(guess);
    let mut offset = base;
    for line in chunk.split(|&b| b == b'\n') {
        let here = offset;
        offset += line.len() + 1;
        let line = line.strip_suffix(b"\r").unwrap_or(line);
        let mut fields = line
            .split(|b| b.is_ascii_whitespace())
            .filter(|f| !f.is_empty());
        let Some(first) = fields.next() else {
            continue; // blank line
        };
        if first[0] == b'#' {
            continue;
        }
        let err = |msg: String| (here, msg);
        let mut next = |name: &str| {
            fields
                .next()
                .ok_or_else(|| err(format!("expected `t x y p`, missing {name}")))
        };
        let (xs, ys, ps) = (next("x")?, next("y")?, next("p")?);
        if fields.next().is_some() {
            return Err(err("more than 4 fields (expected `t x y p`)".into()));
        }
        let t: f64 = field(first)
            .parse()
            .map_err(|_| err(format!("timestamp {:?} is not a number", field(first))))?;
        let x =
            parse_u16(xs).ok_or_else(|| err(format!("x {:?} is not a pixel index", field(xs))))?;
        let y =
            parse_u16(ys).ok_or_else(|| err(format!("y {:?} is not a pixel index", field(ys))))?;
        let p: i8 = match ps {
            b"1" | b"+1" => 1,
            b"0" | b"-1" => -1,
            _ => return Err(err(format!("polarity {:?} is not 0/1", field(ps)))),
        };
        c.t.push(t);
        c.x.push(x);
        c.y.push(y);
        c.p.push(p);
    }
    Ok(c)
}

/// Append the decimal digits of `v`.
fn push_u16(buf: &mut Vec<u8>, v: u16) {
    let mut digits = [0u8; 5];
    let mut n = v;
    let mut k = digits.len();
    loop {
        k -= 1;
        digits[k] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    buf.extend_from_slice(&digits[k..]);
}

/// A pixel index of at most 5 decimal digits (`None` otherwise).
fn parse_u16(b: &[u8]) -> Option<u16> {
    if b.is_empty() || b.len() > 5 {
        return None;
    }
    let mut v: u32 = 0;
    for &c in b {
        if !c.is_ascii_digit() {
            return None;
        }
        v = v * 10 + (c - b'0') as u32;
    }
    u16::try_from(v).ok()
}

fn field(b: &[u8]) -> &str {
    std::str::from_utf8(b).unwrap_or("<not UTF-8>")
}

/// Write `t x y p` lines (p as 0/1) after a `# degs-events width=W height=H` line. Atomic.
pub fn write_text(path: impl AsRef<Path>, ev: &EventStream) -> Result<()> {
    let path = path.as_ref();
    check(path, ev)?;
    const BATCH: usize = 1 << 18;
    write_atomic(path, |w| {
        writeln!(
            w,
            "# {HEADER_TAG} width={} height={} columns: t[s] x y p[0/1]",
            ev.width, ev.height
        )?;
        let n = ev.len();
        let starts: Vec<usize> = (0..n).step_by(BATCH).collect();
        // Format groups of batches in parallel, write them in order.
        for group in starts.chunks(rayon::current_num_threads().max(1) * 2) {
            let bufs: Vec<Vec<u8>> = group
                .par_iter()
                .map(|&s| {
                    let e = (s + BATCH).min(n);
                    let mut buf = Vec::with_capacity((e - s) * 28);
                    for i in s..e {
                        // Writing to a Vec cannot fail.
                        let _ = write!(buf, "{}", ev.t[i]);
                        buf.push(b' ');
                        push_u16(&mut buf, ev.x[i]);
                        buf.push(b' ');
                        push_u16(&mut buf, ev.y[i]);
                        buf.extend_from_slice(if ev.p[i] > 0 { b" 1\n" } else { b" 0\n" });
                    }
                    buf
                })
                .collect();
            for b in bufs {
                w.write_all(&b)?;
            }
        }
        Ok(())
    })
}
