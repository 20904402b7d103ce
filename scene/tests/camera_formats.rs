//! Prophesee `.raw` (EVT 2.0 / 3.0) and Event Stream `.es`: bit-exact round trips of
//! microsecond streams, headers, sensor sizes, and truncated / corrupt / hostile input.

mod common;
use common::*;
use scene::events::EventStream;
use scene::formats::*;
use std::path::Path;

fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// A stream crossing several EVT 3.0 time-high wraps (2^24 µs ≈ 16.8 s): 12 s to 70 s.
fn long_stream() -> EventStream {
    let mut ev = EventStream::new(640, 480);
    let mut s = 7u64;
    let mut us = 12_000_000u64;
    for _ in 0..20_000 {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        us += (s >> 40) % 5_800; // up to 5.8 ms steps, ties included
        ev.push(
            us as f64 / 1e6,
            ((s >> 8) % 640) as u16,
            ((s >> 20) % 480) as u16,
            if s >> 63 == 1 { 1 } else { -1 },
        );
    }
    ev
}

#[test]
fn raw_and_es_round_trip_bit_exactly() {
    let dir = tempfile::tempdir().unwrap();
    for ev in [microsecond_stream(30_000), long_stream()] {
        assert!(ev.t[ev.len() - 1] < 100.0);
        for enc in [RawEncoding::Evt2, RawEncoding::Evt3] {
            let p = dir.path().join("ev.raw");
            write_raw(&p, &ev, enc).unwrap();
            // The header carries the sensor size; the encoding is auto-detected.
            assert_same(&read_events(&p, &ReadOptions::default()).unwrap(), &ev);
            assert_same(&read_raw(&p, &opts(ev.width, ev.height)).unwrap(), &ev);
        }
        let p = dir.path().join("ev.es");
        write_es(&p, &ev).unwrap();
        assert_same(&read_events(&p, &ReadOptions::default()).unwrap(), &ev);
    }
    // The long stream really wraps EVT 3.0's 24-bit time.
    assert!(long_stream().t.last().unwrap() * 1e6 > 3.0 * (1u64 << 24) as f64);
    // Empty streams are legal in both.
    let empty = EventStream::new(4, 3);
    let p = dir.path().join("e.raw");
    write_raw(&p, &empty, RawEncoding::Evt3).unwrap();
    assert_same(&read_raw(&p, &ReadOptions::default()).unwrap(), &empty);
    let p = dir.path().join("e.es");
    write_es(&p, &empty).unwrap();
    assert_same(&read_es(&p, &ReadOptions::default()).unwrap(), &empty);
    // Conversion picks the writers by extension.
    let s = convert(ecd(), dir.path().join("c.es"), &opts(240, 180)).unwrap();
    assert_eq!((s.output_format, s.events), ("es", 20_000));
    let s = convert(
        dir.path().join("c.es"),
        dir.path().join("c.raw"),
        &ReadOptions::default(),
    )
    .unwrap();
    assert_eq!(
        (s.input_format, s.output_format, s.events),
        ("es", "raw", 20_000)
    );
    // ECD timestamps are not whole microseconds: rounded like .npz (here ±0.5 µs).
    let a = read_events(ecd(), &opts(240, 180)).unwrap();
    let b = read_raw(dir.path().join("c.raw"), &ReadOptions::default()).unwrap();
    assert_eq!(
        (a.x.clone(), a.y.clone(), a.p.clone()),
        (b.x.clone(), b.y.clone(), b.p.clone())
    );
    let worst =
        a.t.iter()
            .zip(&b.t)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
    assert!(worst <= 0.5e-6 + 1e-12, "{worst}");
}

#[test]
fn raw_files_written_by_hand_decode() {
    let dir = tempfile::tempdir().unwrap();
    // EVT 3.0 with a vector: y 5, base x 10 OFF, mask 0b101 → x 10 and 12 at t = 0x123456 µs.
    let words: [u16; 5] = [0x8123, 0x6456, 0x0005, 0x3000 | 10, 0x4000 | 0b101];
    let mut bytes = b"% evt 3.0\n% geometry 32x8\n% end\n".to_vec();
    bytes.extend(words.iter().flat_map(|w| w.to_le_bytes()));
    let ev = read_raw(write(dir.path(), "v.raw", &bytes), &ReadOptions::default()).unwrap();
    assert_eq!((ev.width, ev.height), (32, 8));
    assert_eq!(
        (ev.x.clone(), ev.y.clone(), ev.p.clone()),
        (vec![10, 12], vec![5, 5], vec![-1, -1])
    );
    assert_eq!(ev.t, vec![0x123456 as f64 / 1e6; 2]);
    // The same sensor from a `format` line only.
    let mut b2 = b"% format EVT3;height=8;width=32\n".to_vec();
    b2.extend(words.iter().flat_map(|w| w.to_le_bytes()));
    let ev2 = read_raw(write(dir.path(), "f.raw", &b2), &ReadOptions::default()).unwrap();
    assert_eq!(ev2, ev);
    // Without a stored size the options must give it.
    let mut b3 = b"% evt 3.0\n".to_vec();
    b3.extend(words.iter().flat_map(|w| w.to_le_bytes()));
    let p3 = write(dir.path(), "n.raw", &b3);
    let e = err_text(read_raw(&p3, &ReadOptions::default()));
    assert!(e.contains("n.raw") && e.contains("sensor size"), "{e}");
    assert_eq!(read_raw(&p3, &opts(32, 8)).unwrap(), ev);
}

#[test]
fn hostile_raw_files() {
    let dir = tempfile::tempdir().unwrap();
    let ev = microsecond_stream(2_000);
    let good = dir.path().join("g.raw");
    write_raw(&good, &ev, RawEncoding::Evt3).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty.raw", vec![], "file is empty"),
        (
            "nohdr.raw",
            vec![0x00, 0x80, 0x00, 0x20],
            "names no event encoding",
        ),
        ("evt21.raw", b"% evt 2.1\n".to_vec(), "not supported"),
        (
            "geom.raw",
            b"% evt 3.0\n% geometry 12\n".to_vec(),
            "not WxH",
        ),
        ("cut.raw", bytes[..bytes.len() - 1].to_vec(), "truncated"),
        (
            "big.raw",
            b"% evt 3.0\n% geometry 4x4\n% end\n\x20\x00\x0F\x20".to_vec(),
            "outside the 4x4 sensor",
        ),
        (
            "reserved.raw",
            b"% evt 3.0\n% geometry 4x4\n% end\n\x00\x90".to_vec(),
            "reserved EVT 3.0 word type 0x9",
        ),
        (
            "noy.raw",
            b"% evt 3.0\n% geometry 4x4\n% end\n\x01\x20".to_vec(),
            "before any EVT_ADDR_Y",
        ),
        // Time going back inside one period: unsorted.
        (
            "back.raw",
            b"% evt 3.0\n% geometry 4x4\n% end\n\x01\x00\x05\x60\x01\x20\x04\x60\x01\x20".to_vec(),
            "not sorted",
        ),
        (
            "huge.raw",
            [b"%".repeat(2 << 20), b"\n".to_vec()].concat(),
            "header longer",
        ),
    ];
    for (name, b, want) in cases {
        let p = write(dir.path(), name, &b);
        let e = err_text(read_raw(&p, &ReadOptions::default()));
        assert!(e.contains(name) && e.contains(want), "{name}: {e}");
    }
    // Every truncation of a small file fails cleanly or reads a prefix of the events.
    let small = &bytes[..bytes.len().min(400)];
    for n in 0..small.len() {
        let p = write(dir.path(), "t.raw", &small[..n]);
        if let Ok(got) = read_raw(&p, &ReadOptions::default()) {
            assert!(got.len() <= ev.len());
            assert_eq!(got.x[..], ev.x[..got.len()]);
        }
    }
    // Bit flips in the body: an error naming the file or a valid stream, never a panic.
    for k in 0..600 {
        let mut b = bytes.clone();
        let i = 40 + (k * 7919) % (b.len() - 40);
        b[i] ^= 1 << (k % 8);
        if let Err(e) = read_raw(write(dir.path(), "flip.raw", &b), &ReadOptions::default()) {
            assert!(e.to_string().contains("flip.raw"), "{e}");
        }
    }
    // Writers refuse what the format cannot hold, leaving nothing.
    let mut wide = EventStream::new(4096, 4);
    wide.push(0.0, 4000, 0, 1);
    let p = dir.path().join("w.raw");
    assert!(err_text(write_raw(&p, &wide, RawEncoding::Evt2)).contains("2048x2048"));
    assert!(!p.exists());
    // A stream that starts periods into the clock, and gaps of whole periods (EVT 3.0:
    // 2²⁴ µs ≈ 16.8 s; EVT 2.0: 2³⁴ µs ≈ 4.8 h), read back to the microsecond.
    let mut late = EventStream::new(4, 4);
    for (t, x) in [
        (20.0, 0),
        (20.5, 1),
        (60.25, 2),
        (60.25, 3),
        (61.0, 0),
        (40_000.0, 1),
    ] {
        late.push(t, x, 1, 1);
    }
    late.push(40_000.000_001, 2, 3, -1);
    for enc in [RawEncoding::Evt3, RawEncoding::Evt2] {
        write_raw(&p, &late, enc).unwrap();
        let back = read_raw(&p, &ReadOptions::default()).unwrap();
        assert_eq!(back, late, "{enc:?}");
    }
}

#[test]
fn hostile_es_files() {
    let dir = tempfile::tempdir().unwrap();
    let ev = microsecond_stream(1_000);
    let good = dir.path().join("g.es");
    write_es(&good, &ev).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    assert_eq!(&bytes[..16], b"Event Stream\x02\x00\x00\x01");
    assert_eq!(u16::from_le_bytes([bytes[16], bytes[17]]), 346);
    let mut v1 = bytes.clone();
    v1[12] = 1;
    let mut colour = bytes.clone();
    colour[15] = 4;
    let mut oob = bytes[..20].to_vec();
    oob.extend([0, 0x5A, 0x01, 0, 0]); // x 346 on a 346-wide sensor
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty.es", vec![], "file is empty"),
        (
            "magic.es",
            b"Event Strean\x02\x00\x00\x01\x01\x00\x01\x00".to_vec(),
            "magic",
        ),
        ("v1.es", v1, "version 1.0.0 is not supported"),
        ("colour.es", colour, "colour events"),
        ("size.es", bytes[..18].to_vec(), "sensor size"),
        (
            "cut.es",
            bytes[..bytes.len() - 2].to_vec(),
            "truncated after 3 of its 5",
        ),
        ("oob.es", oob, "outside the 346x260 sensor"),
    ];
    for (name, b, want) in cases {
        let p = write(dir.path(), name, &b);
        let e = err_text(read_es(&p, &ReadOptions::default()));
        assert!(e.contains(name) && e.contains(want), "{name}: {e}");
    }
    let e = err_text(read_es(&good, &opts(240, 180)));
    assert!(e.contains("346x260") && e.contains("240x180"), "{e}");
    for k in 0..600 {
        let mut b = bytes.clone();
        let i = 16 + (k * 7919) % (b.len() - 16);
        b[i] ^= 1 << (k % 8);
        if let Err(e) = read_es(write(dir.path(), "flip.es", &b), &ReadOptions::default()) {
            assert!(e.to_string().contains("flip.es"), "{e}");
        }
    }
    let mut neg = EventStream::new(4, 4);
    neg.push(-1.0, 0, 0, 1);
    let p = dir.path().join("n.es");
    assert!(err_text(write_es(&p, &neg)).contains("negative"));
    assert!(!p.exists());
}
