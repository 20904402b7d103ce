//! A minimal AEDAT 4.0 writer for tests (header, packets in any compression) and a
//! frame packet builder, shared by `aedat4.rs` and `mutation_formats.rs`.

use std::io::Write;

pub fn io_header(compression: i32, data_table: i64, xml: &str) -> Vec<u8> {
    // [root u32][IOHE][vtable: 10 bytes + 2 pad][table at 20: soffset, compression,
    //  data_table i64, string offset][string]
    let mut b = Vec::new();
    b.extend(20u32.to_le_bytes()); // root table at 20
    b.extend(b"IOHE");
    b.extend(10u16.to_le_bytes()); // vtable at 8
    b.extend(24u16.to_le_bytes());
    b.extend(4u16.to_le_bytes()); // compression at table+4
    b.extend(8u16.to_le_bytes()); // data table at table+8
    b.extend(16u16.to_le_bytes()); // string offset at table+16
    b.extend([0u8; 2]);
    assert_eq!(b.len(), 20);
    b.extend(12i32.to_le_bytes()); // table − vtable
    b.extend(compression.to_le_bytes());
    b.extend(data_table.to_le_bytes());
    b.extend(4u32.to_le_bytes()); // string right after this field (at 40)
    b.extend((xml.len() as u32).to_le_bytes());
    b.extend(xml.as_bytes());
    b.push(0);
    b
}

/// A size-prefixed packet FlatBuffer with identifier `id` and a vector of 16-byte
/// event structs.
pub fn event_packet(id: &[u8; 4], events: &[(i64, i16, i16, bool)]) -> Vec<u8> {
    let mut fb = Vec::new();
    fb.extend(16u32.to_le_bytes());
    fb.extend(id);
    fb.extend(6u16.to_le_bytes()); // vtable at 8
    fb.extend(8u16.to_le_bytes());
    fb.extend(4u16.to_le_bytes());
    fb.extend([0u8; 2]);
    fb.extend(8i32.to_le_bytes()); // table at 16
    fb.extend(8u32.to_le_bytes()); // vector at 28
    fb.extend([0u8; 4]);
    fb.extend((events.len() as u32).to_le_bytes());
    for &(t, x, y, on) in events {
        fb.extend(t.to_le_bytes());
        fb.extend(x.to_le_bytes());
        fb.extend(y.to_le_bytes());
        fb.push(on as u8);
        fb.extend([0u8; 3]);
    }
    let mut b = (fb.len() as u32).to_le_bytes().to_vec();
    b.extend(fb);
    b
}

pub fn compress(kind: i32, raw: &[u8]) -> Vec<u8> {
    match kind {
        0 => raw.to_vec(),
        1 | 2 => {
            let mut enc = lz4_flex::frame::FrameEncoder::new(Vec::new());
            enc.write_all(raw).unwrap();
            enc.finish().unwrap()
        }
        _ => ruzstd::encoding::compress_to_vec(raw, ruzstd::encoding::CompressionLevel::Fastest),
    }
}

pub const XML: &str = r#"<dv version="2.0"><node name="outInfo" path="/r/outInfo/">
<node name="0" path="/r/outInfo/0/"><attr key="typeIdentifier" type="string">EVTS</attr>
<node name="info" path="/r/outInfo/0/info/"><attr key="sizeX" type="int">64</attr>
<attr key="sizeY" type="int">48</attr></node></node>
<node name="1" path="/r/outInfo/1/"><attr key="typeIdentifier" type="string">IMUS</attr>
</node></node></dv>"#;

/// A file of `packets` (stream id, uncompressed body); with a trailing fake data table.
pub fn aedat4(compression: i32, xml: &str, packets: &[(i32, Vec<u8>)]) -> Vec<u8> {
    let mut body = Vec::new();
    for (id, raw) in packets {
        let c = compress(compression, raw);
        body.extend(id.to_le_bytes());
        body.extend((c.len() as i32).to_le_bytes());
        body.extend(c);
    }
    let probe = io_header(compression, 0, xml);
    let table_at = 14 + 4 + probe.len() + body.len();
    let header = io_header(compression, table_at as i64, xml);
    let mut f = b"#!AER-DAT4.0\r\n".to_vec();
    f.extend((header.len() as i32).to_le_bytes());
    f.extend(header);
    f.extend(body);
    f.extend(b"data table: not a packet");
    f
}

/// A size-prefixed `FRME` packet FlatBuffer (dv-processing's `Frame`): timestamp,
/// exposure start/end, `format` (0 grey, 16 BGR, 24 BGRA), size, position, pixels.
pub fn frame_packet(t: i64, format: i8, size: (i16, i16), pixels: &[u8]) -> Vec<u8> {
    // [root u32][FRME][vtable: 4 + 11 fields × 2 = 26 bytes + 2 pad]
    // [table at 36: soffset, ts, exposure start/end (i64), size x/y, position x/y
    //  (i16), format (i8) + pad, pixels offset (u32)][vector]
    let mut fb = Vec::new();
    fb.extend(36u32.to_le_bytes());
    fb.extend(b"FRME");
    let table_len = 4 + 4 + 24 + 8 + 4 + 4; // soffset, pad, i64×3, i16×4, i8+pad, offset
    fb.extend(26u16.to_le_bytes());
    fb.extend((table_len as u16).to_le_bytes());
    // field offsets in the table: 0 ts, 1–2 start/end of frame (absent), 3–4 exposure,
    // 5 format, 6–9 size and position, 10 pixels
    for off in [8u16, 0, 0, 16, 24, 40, 32, 34, 36, 38, 44] {
        fb.extend(off.to_le_bytes());
    }
    fb.extend([0u8; 2]);
    assert_eq!(fb.len(), 36);
    fb.extend(28i32.to_le_bytes()); // table − vtable
    fb.extend([0u8; 4]);
    fb.extend(t.to_le_bytes());
    fb.extend((t - 250).to_le_bytes());
    fb.extend((t + 250).to_le_bytes());
    for v in [size.0, size.1, 0, 0] {
        fb.extend(v.to_le_bytes());
    }
    fb.push(format as u8);
    fb.extend([0u8; 3]);
    fb.extend(4u32.to_le_bytes()); // the vector right after this field
    fb.extend((pixels.len() as u32).to_le_bytes());
    fb.extend(pixels);
    let mut b = (fb.len() as u32).to_le_bytes().to_vec();
    b.extend(fb);
    b
}
