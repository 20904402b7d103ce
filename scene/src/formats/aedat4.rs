//! AEDAT 4.0 reader (iniVation DV: DAVIS, DVXplorer): polarity events here, the APS
//! frames in the sibling module `aedat4_frames`; IMU samples and triggers are skipped.
//!
//! File layout (little-endian throughout), as checked against a real DAVIS346 recording:
//!
//! 1. magic `#!AER-DAT4.0\r\n` (14 bytes);
//! 2. `i32` length, then that many bytes of an `IOHeader` FlatBuffer (file identifier
//!    `IOHE`, not size-prefixed) with fields 0 `compression: i32` (0 none, 1 LZ4,
//!    2 LZ4 high, 3 Zstd, 4 Zstd high; default 0), 1 `dataTablePosition: i64` (byte
//!    offset of the trailing packet index, −1 if absent) and 2 `infoNode: string`, an XML
//!    document describing the streams (`<node name="N">` with `typeIdentifier`
//!    `EVTS`/`FRME`/`IMUS`/`TRIG` and, for cameras, `sizeX`/`sizeY`);
//! 3. packets up to `dataTablePosition` (or the end of the file): `i32` stream id, `i32`
//!    byte size, then the body, compressed as the header says (LZ4 *frame* format or a
//!    Zstd frame). A decompressed body is a size-prefixed FlatBuffer whose file identifier
//!    names the type. Event packets (`EVTS`) hold one field 0: a vector of 16-byte structs
//!    `{t: i64 µs, x: i16, y: i16, on: bool, 3 bytes padding}`.
//!
//! Timestamps become seconds (`t / 1e6`, absolute: DV stores Unix-epoch microseconds, and
//! an f64 resolves them to 0.24 µs). `on` → +1, off → −1. The sensor size is the `sizeX`
//! × `sizeY` of the first `EVTS` stream in the XML, else [`ReadOptions::sensor`]. When
//! the file has several event streams, the one with the lowest id is read. Packets are
//! decompressed and decoded in parallel. FlatBuffers are parsed by hand with every
//! offset bounds-checked, so corrupt files produce errors, never panics.

use super::{ReadOptions, check, resolve_sensor};
use crate::error::{Error, IoContext, Result};
use crate::events::EventStream;
use rayon::prelude::*;
use std::io::Read;
use std::path::Path;

pub const MAGIC: &[u8; 14] = b"#!AER-DAT4.0\r\n";
/// Bytes per event struct in an `EVTS` packet.
const EVENT_STRIDE: usize = 16;
/// Largest decompressed packet accepted (a guard against decompression bombs).
const MAX_PACKET: u64 = 1 << 30;

/// A bounds-checked view of one FlatBuffer.
pub(super) struct Flat<'a> {
    pub buf: &'a [u8],
}

impl<'a> Flat<'a> {
    pub(super) fn bytes<const N: usize>(&self, at: usize) -> std::result::Result<[u8; N], String> {
        at.checked_add(N)
            .and_then(|end| self.buf.get(at..end))
            .map(|s| {
                let mut a = [0u8; N];
                a.copy_from_slice(s);
                a
            })
            .ok_or_else(|| {
                format!(
                    "FlatBuffer offset {at} outside its {} bytes",
                    self.buf.len()
                )
            })
    }
    pub(super) fn u16(&self, at: usize) -> std::result::Result<u16, String> {
        self.bytes::<2>(at).map(u16::from_le_bytes)
    }
    pub(super) fn u32(&self, at: usize) -> std::result::Result<u32, String> {
        self.bytes::<4>(at).map(u32::from_le_bytes)
    }
    pub(super) fn i32(&self, at: usize) -> std::result::Result<i32, String> {
        self.bytes::<4>(at).map(i32::from_le_bytes)
    }
    pub(super) fn i64(&self, at: usize) -> std::result::Result<i64, String> {
        self.bytes::<8>(at).map(i64::from_le_bytes)
    }

    /// Position of the root table.
    pub(super) fn root(&self) -> std::result::Result<usize, String> {
        Ok(self.u32(0)? as usize)
    }

    /// Absolute position of field `i` of the table at `table`, `None` if absent.
    pub(super) fn field(
        &self,
        table: usize,
        i: usize,
    ) -> std::result::Result<Option<usize>, String> {
        let vtable = table as i64 - self.i32(table)? as i64;
        if vtable < 0 {
            return Err(format!("vtable offset of the table at {table} is negative"));
        }
        let vtable = vtable as usize;
        let vlen = self.u16(vtable)? as usize;
        let slot = 4 + 2 * i;
        if slot + 2 > vlen {
            return Ok(None);
        }
        match self.u16(vtable + slot)? {
            0 => Ok(None),
            off => Ok(Some(table + off as usize)),
        }
    }

    /// Follow the `u32` offset stored at `at` (strings, vectors, tables).
    pub(super) fn deref(&self, at: usize) -> std::result::Result<usize, String> {
        Ok(at + self.u32(at)? as usize)
    }

    /// A byte vector/string starting at `at` (u32 length, then the bytes).
    pub(super) fn vector(&self, at: usize, stride: usize) -> std::result::Result<&'a [u8], String> {
        let n = self.u32(at)? as usize;
        let start = at + 4;
        n.checked_mul(stride)
            .and_then(|len| start.checked_add(len))
            .and_then(|end| self.buf.get(start..end))
            .ok_or_else(|| {
                format!(
                    "vector of {n} items at {at} runs past the end of its {} bytes",
                    self.buf.len()
                )
            })
    }
}

/// What the `IOHeader` says.
struct Header {
    compression: i32,
    data_table: i64,
    info: String,
}

fn parse_header(buf: &[u8]) -> std::result::Result<Header, String> {
    let f = Flat { buf };
    if buf.get(4..8) != Some(b"IOHE") {
        return Err("IOHeader lacks its IOHE identifier".into());
    }
    let root = f.root()?;
    let compression = match f.field(root, 0)? {
        Some(p) => f.i32(p)?,
        None => 0,
    };
    let data_table = match f.field(root, 1)? {
        Some(p) => f.i64(p)?,
        None => -1,
    };
    let info = match f.field(root, 2)? {
        Some(p) => String::from_utf8_lossy(f.vector(f.deref(p)?, 1)?).into_owned(),
        None => String::new(),
    };
    Ok(Header {
        compression,
        data_table,
        info,
    })
}

/// One stream declared in the XML info node.
#[derive(Debug, Default, PartialEq)]
pub(super) struct StreamInfo {
    pub id: i32,
    pub type_id: String,
    pub size: Option<(u32, u32)>,
}

/// Streams of the `infoNode` XML: each `<node name="N" path=".../outInfo/N/">` block with
/// its `typeIdentifier`, `sizeX`, `sizeY` attributes.
fn parse_streams(xml: &str) -> Vec<StreamInfo> {
    let mut out = Vec::new();
    let starts: Vec<usize> = xml.match_indices("<node name=\"").map(|(i, _)| i).collect();
    for (k, &s) in starts.iter().enumerate() {
        let rest = &xml[s + 12..];
        let Some(name_end) = rest.find('"') else {
            continue;
        };
        let Ok(id) = rest[..name_end].parse::<i32>() else {
            continue;
        };
        let end = starts
            .iter()
            .skip(k + 1)
            .copied()
            .find(|&e| {
                xml[e + 12..]
                    .split('"')
                    .next()
                    .is_some_and(|n| n.parse::<i32>().is_ok())
            })
            .unwrap_or(xml.len());
        let block = &xml[s..end];
        let attr = |key: &str| -> Option<String> {
            let at = block.find(&format!("key=\"{key}\""))?;
            let after = &block[at..];
            let open = after.find('>')? + 1;
            let close = after[open..].find('<')? + open;
            Some(after[open..close].trim().to_string())
        };
        let Some(type_id) = attr("typeIdentifier") else {
            continue;
        };
        let size = match (
            attr("sizeX").and_then(|v| v.parse().ok()),
            attr("sizeY").and_then(|v| v.parse().ok()),
        ) {
            (Some(w), Some(h)) => Some((w, h)),
            _ => None,
        };
        out.push(StreamInfo { id, type_id, size });
    }
    out
}

/// Decompress one packet body as the header's compression says.
pub(super) fn decompress(compression: i32, body: &[u8]) -> std::result::Result<Vec<u8>, String> {
    let mut out = Vec::new();
    let result = match compression {
        0 => return Ok(body.to_vec()),
        1 | 2 => lz4_flex::frame::FrameDecoder::new(body)
            .take(MAX_PACKET + 1)
            .read_to_end(&mut out),
        3 | 4 => {
            let dec = ruzstd::decoding::StreamingDecoder::new(body)
                .map_err(|e| format!("bad Zstd frame: {e}"))?;
            dec.take(MAX_PACKET + 1).read_to_end(&mut out)
        }
        c => return Err(format!("unknown compression type {c}")),
    };
    result.map_err(|e| format!("cannot decompress: {e}"))?;
    if out.len() as u64 > MAX_PACKET {
        return Err(format!("decompresses to more than {MAX_PACKET} bytes"));
    }
    Ok(out)
}

/// Columns of one decoded event packet.
#[derive(Default)]
struct Packet {
    t: Vec<f64>,
    x: Vec<u16>,
    y: Vec<u16>,
    p: Vec<i8>,
}

/// Decode a decompressed body: `Ok(None)` when it is not an event packet.
fn decode_events(buf: &[u8]) -> std::result::Result<Option<Packet>, String> {
    // Size prefix, then the FlatBuffer proper.
    let f = Flat { buf };
    let size = f.u32(0)? as usize;
    let fb = buf
        .get(4..)
        .filter(|b| b.len() >= size && size >= 8)
        .ok_or_else(|| format!("size prefix {size} does not fit the {} bytes", buf.len()))?;
    if &fb[4..8] != b"EVTS" {
        return Ok(None);
    }
    let f = Flat { buf: &fb[..size] };
    let root = f.root()?;
    let Some(field) = f.field(root, 0)? else {
        return Ok(Some(Packet::default()));
    };
    let raw = f.vector(f.deref(field)?, EVENT_STRIDE)?;
    let n = raw.len() / EVENT_STRIDE;
    let mut p = Packet {
        t: Vec::with_capacity(n),
        x: Vec::with_capacity(n),
        y: Vec::with_capacity(n),
        p: Vec::with_capacity(n),
    };
    for (k, e) in raw.chunks_exact(EVENT_STRIDE).enumerate() {
        let t = i64::from_le_bytes(e[0..8].try_into().unwrap_or_default());
        let x = i16::from_le_bytes([e[8], e[9]]);
        let y = i16::from_le_bytes([e[10], e[11]]);
        if x < 0 || y < 0 {
            return Err(format!(
                "event {k} of the packet has negative pixel ({x}, {y})"
            ));
        }
        p.t.push(t as f64 / 1e6);
        p.x.push(x as u16);
        p.y.push(y as u16);
        p.p.push(if e[12] != 0 { 1 } else { -1 });
    }
    Ok(Some(p))
}

/// An opened AEDAT4 file: its bytes, header, declared streams and packet table.
pub(super) struct Container {
    pub data: Vec<u8>,
    pub compression: i32,
    pub streams: Vec<StreamInfo>,
    /// Per packet: (index, stream id, byte offset of its header, body range).
    pub packets: Vec<(usize, i32, usize, std::ops::Range<usize>)>,
}

/// Read `path` and check its magic, header and packet table.
pub(super) fn open(path: &Path) -> Result<Container> {
    let data = std::fs::read(path).at(path)?;
    let bad = |msg: String| Error::invalid(path, msg);
    if data.is_empty() {
        return Err(bad("file is empty".into()));
    }
    if data.len() < MAGIC.len() || &data[..MAGIC.len()] != MAGIC {
        return Err(bad(
            "not an AEDAT 4.0 file (magic #!AER-DAT4.0 missing)".into()
        ));
    }
    let mut pos = MAGIC.len();
    let hlen = data
        .get(pos..pos + 4)
        .map(|b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .ok_or_else(|| bad("truncated before the header length".into()))?;
    pos += 4;
    let header_bytes = usize::try_from(hlen)
        .ok()
        .and_then(|l| data.get(pos..pos.checked_add(l)?))
        .ok_or_else(|| {
            bad(format!(
                "header length {hlen} runs past the end of the file"
            ))
        })?;
    let header = parse_header(header_bytes).map_err(|m| bad(format!("IOHeader: {m}")))?;
    pos += header_bytes.len();
    let streams = parse_streams(&header.info);

    let end = if header.data_table >= 0 {
        usize::try_from(header.data_table)
            .ok()
            .filter(|&e| e >= pos && e <= data.len())
            .ok_or_else(|| {
                bad(format!(
                    "dataTablePosition {} is outside the packet area {pos}..{}",
                    header.data_table,
                    data.len()
                ))
            })?
    } else {
        data.len()
    };
    let mut packets = Vec::new();
    while pos < end {
        let head = data
            .get(pos..pos + 8)
            .filter(|_| pos + 8 <= end)
            .ok_or_else(|| {
                bad(format!(
                    "packet {} at byte {pos}: truncated header",
                    packets.len()
                ))
            })?;
        let id = i32::from_le_bytes([head[0], head[1], head[2], head[3]]);
        let size = i32::from_le_bytes([head[4], head[5], head[6], head[7]]);
        let body = usize::try_from(size)
            .ok()
            .and_then(|s| pos.checked_add(8 + s))
            .filter(|&e| e <= end)
            .ok_or_else(|| {
                bad(format!(
                    "packet {} at byte {pos}: size {size} runs past the end ({end}): truncated",
                    packets.len()
                ))
            })?;
        packets.push((packets.len(), id, pos, pos + 8..body));
        pos = body;
    }
    Ok(Container {
        data,
        compression: header.compression,
        streams,
        packets,
    })
}

/// Read the polarity events of an AEDAT4 file.
pub fn read_aedat4(path: impl AsRef<Path>, opts: &ReadOptions) -> Result<EventStream> {
    let path = path.as_ref();
    let bad = |msg: String| Error::invalid(path, msg);
    let file = open(path)?;
    let event_stream = file
        .streams
        .iter()
        .filter(|s| s.type_id == "EVTS")
        .min_by_key(|s| s.id);
    let (width, height) = resolve_sensor(path, event_stream.and_then(|s| s.size), opts)?;
    let wanted = event_stream.map(|s| s.id);
    let decoded: Vec<Result<Option<Packet>>> = file
        .packets
        .par_iter()
        .filter(|(_, id, _, _)| wanted.is_none_or(|w| w == *id))
        .map(|(k, _, at, range)| {
            decompress(file.compression, &file.data[range.clone()])
                .and_then(|buf| decode_events(&buf))
                .map_err(|m| bad(format!("packet {k} at byte {at}: {m}")))
        })
        .collect();
    let mut ev = EventStream::new(width, height);
    for p in decoded {
        if let Some(p) = p? {
            ev.t.extend_from_slice(&p.t);
            ev.x.extend_from_slice(&p.x);
            ev.y.extend_from_slice(&p.y);
            ev.p.extend_from_slice(&p.p);
        }
    }
    check(path, &ev)?;
    Ok(ev)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn xml_streams_are_found() {
        let xml = r#"<dv version="2.0"><node name="outInfo" path="/a/outInfo/">
            <node name="0" path="/a/outInfo/0/"><attr key="typeIdentifier" type="string">EVTS</attr>
              <node name="info" path="/a/outInfo/0/info/"><attr key="sizeX" type="int">346</attr>
              <attr key="sizeY" type="int">260</attr></node></node>
            <node name="2" path="/a/outInfo/2/"><attr key="typeIdentifier" type="string">IMUS</attr>
            </node></node></dv>"#;
        let s = parse_streams(xml);
        assert_eq!(
            s,
            vec![
                StreamInfo {
                    id: 0,
                    type_id: "EVTS".into(),
                    size: Some((346, 260))
                },
                StreamInfo {
                    id: 2,
                    type_id: "IMUS".into(),
                    size: None
                },
            ]
        );
        assert!(parse_streams("").is_empty());
        assert!(parse_streams("<node name=\"").is_empty());
    }

    #[test]
    fn flatbuffer_reads_are_bounds_checked() {
        let f = Flat { buf: &[1, 0, 0, 0] };
        assert_eq!(f.u32(0), Ok(1));
        assert!(f.u32(1).is_err());
        assert!(f.i64(usize::MAX - 2).is_err());
        assert!(f.field(0, 0).is_err());
        assert!(f.vector(0, usize::MAX).is_err());
    }
}
