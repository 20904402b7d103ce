//! AEDAT4: the real DAVIS346 sample, synthetic files in every compression, and
//! truncated / corrupt / hostile input.

use common::aedat4_file::{XML, aedat4, event_packet};
use scene::events::EventStream;
use scene::formats::{ReadOptions, read_events};
use std::path::Path;

mod common;

fn sample() -> std::path::PathBuf {
    testkit::testdata::shared_data("aedat4_sample/sample.aedat4")
}

fn err_text<T: std::fmt::Debug>(r: scene::Result<T>) -> String {
    r.expect_err("expected an error").to_string()
}

#[test]
fn reads_the_real_davis346_sample() {
    let ev = read_events(sample(), &ReadOptions::default()).unwrap();
    // Figures from an independent Python decoder (LZ4 frame + FlatBuffers by hand):
    // 17 EVTS packets, 6,676 events, 3,563 ON, sensor 346x260.
    assert_eq!((ev.width, ev.height), (346, 260));
    assert_eq!(ev.len(), 6_676);
    assert_eq!(ev.p.iter().filter(|&&p| p == 1).count(), 3_563);
    assert_eq!(ev.t[0], 1589163147368868.0 / 1e6);
    assert_eq!((ev.x[0], ev.y[0], ev.p[0]), (215, 164, 1));
    let n = ev.len() - 1;
    assert_eq!(ev.t[n], 1589163147538809.0 / 1e6);
    assert_eq!((ev.x[n], ev.y[n], ev.p[n]), (96, 229, 1));
    assert_eq!(*ev.x.iter().max().unwrap(), 334);
    assert_eq!(*ev.y.iter().max().unwrap(), 245);
    assert_eq!(*ev.x.iter().min().unwrap(), 14);
    assert_eq!(*ev.y.iter().min().unwrap(), 8);
    assert!((ev.t[n] - ev.t[0] - 0.169941).abs() < 1e-6);
    // A conflicting expected sensor size is reported.
    let o = ReadOptions {
        sensor: Some((240, 180)),
        coord_scale: None,
    };
    let e = err_text(read_events(sample(), &o));
    assert!(e.contains("sample.aedat4") && e.contains("346x260"), "{e}");
}

fn events(n: usize, t0: i64, seed: u64) -> Vec<(i64, i16, i16, bool)> {
    let mut s = seed;
    let mut t = t0;
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            t += (s >> 60) as i64; // 0..15 µs steps, ties included
            (
                t,
                ((s >> 20) % 64) as i16,
                ((s >> 30) % 48) as i16,
                (s >> 40) & 1 == 1,
            )
        })
        .collect()
}

fn expected(evs: &[(i64, i16, i16, bool)], w: u32, h: u32) -> EventStream {
    let mut e = EventStream::new(w, h);
    for &(t, x, y, on) in evs {
        e.push(t as f64 / 1e6, x as u16, y as u16, if on { 1 } else { -1 });
    }
    e
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn synthetic_files_in_every_compression_read_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let a = events(500, 1_700_000_000_000_000, 1);
    let b = events(300, a.last().unwrap().0, 2);
    let c = events(1, b.last().unwrap().0 + 3, 3);
    let imu = event_packet(b"IMUS", &[(5, 1, 1, true)]);
    for compression in 0..=4 {
        let f = aedat4(
            compression,
            XML,
            &[
                (0, event_packet(b"EVTS", &a)),
                (1, imu.clone()),
                (0, event_packet(b"EVTS", &[])),
                (0, event_packet(b"EVTS", &b)),
                (0, event_packet(b"EVTS", &c)),
            ],
        );
        let p = write(dir.path(), &format!("c{compression}.aedat4"), &f);
        let ev = read_events(&p, &ReadOptions::default()).unwrap();
        let want = expected(&[a.clone(), b.clone(), c.clone()].concat(), 64, 48);
        assert_eq!(ev, want, "compression {compression}");
        assert_eq!(
            ev.t.iter().map(|t| t.to_bits()).collect::<Vec<_>>(),
            want.t.iter().map(|t| t.to_bits()).collect::<Vec<_>>()
        );
    }
}

#[test]
fn sensor_size_falls_back_to_the_options() {
    let dir = tempfile::tempdir().unwrap();
    let a = events(20, 1000, 4);
    let f = aedat4(1, "", &[(0, event_packet(b"EVTS", &a))]);
    let p = write(dir.path(), "noxml.aedat4", &f);
    let e = err_text(read_events(&p, &ReadOptions::default()));
    assert!(
        e.contains("noxml.aedat4") && e.contains("sensor size"),
        "{e}"
    );
    let o = ReadOptions {
        sensor: Some((64, 48)),
        coord_scale: None,
    };
    assert_eq!(read_events(&p, &o).unwrap(), expected(&a, 64, 48));
}

#[test]
fn hostile_and_corrupt_files() {
    let dir = tempfile::tempdir().unwrap();
    let a = events(50, 1000, 5);
    let good = aedat4(1, XML, &[(0, event_packet(b"EVTS", &a))]);
    let mut unsorted = a.clone();
    unsorted.swap(10, 30);
    let mut outside = a.clone();
    outside[7].1 = 64;
    let mut negative = a.clone();
    negative[3].2 = -1;
    let mut bad_lz4 = good.clone();
    let hl = i32::from_le_bytes(good[14..18].try_into().unwrap()) as usize;
    bad_lz4[18 + hl + 8] ^= 0xff; // the LZ4 frame magic of packet 0
    let mut bad_hlen = good.clone();
    bad_hlen[14..18].copy_from_slice(&i32::MAX.to_le_bytes());
    let mut neg_size = aedat4(0, XML, &[(0, event_packet(b"EVTS", &a))]);
    neg_size[18 + hl + 4..18 + hl + 8].copy_from_slice(&(-5i32).to_le_bytes());
    let mut short_prefix = event_packet(b"EVTS", &a);
    short_prefix[0..4].copy_from_slice(&100_000u32.to_le_bytes());
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty.aedat4", vec![], "file is empty"),
        (
            "magic.aedat4",
            b"#!AER-DAT3.1\r\nxxxxxxxx".to_vec(),
            "not an AEDAT 4.0",
        ),
        ("hdr.aedat4", good[..16].to_vec(), "header length"),
        ("hlen.aedat4", bad_hlen, "runs past the end"),
        (
            "cut.aedat4",
            good[..good.len() - 60].to_vec(),
            "dataTablePosition",
        ),
        ("neg.aedat4", neg_size, "size -5"),
        ("lz4.aedat4", bad_lz4, "packet 0"),
        (
            "comp.aedat4",
            aedat4(0, XML, &[(0, event_packet(b"EVTS", &a))])
                .iter()
                .enumerate()
                .map(|(i, &b)| if i == 18 + 24 { 7 } else { b })
                .collect(),
            "unknown compression type 7",
        ),
        (
            "unsorted.aedat4",
            aedat4(3, XML, &[(0, event_packet(b"EVTS", &unsorted))]),
            "not sorted",
        ),
        (
            "outside.aedat4",
            aedat4(0, XML, &[(0, event_packet(b"EVTS", &outside))]),
            "event 7: pixel (64,",
        ),
        (
            "negative.aedat4",
            aedat4(0, XML, &[(0, event_packet(b"EVTS", &negative))]),
            "negative pixel",
        ),
        (
            "prefix.aedat4",
            aedat4(0, XML, &[(0, short_prefix)]),
            "size prefix",
        ),
    ];
    for (name, bytes, want) in cases {
        let p = write(dir.path(), name, &bytes);
        let e = err_text(read_events(&p, &ReadOptions::default()));
        assert!(e.contains(name) && e.contains(want), "{name}: {e}");
    }
    // Without a data table position, a file cut inside a packet is truncated.
    let mut no_table = aedat4(0, XML, &[(0, event_packet(b"EVTS", &a))]);
    no_table[18 + 28..18 + 36].copy_from_slice(&(-1i64).to_le_bytes());
    let len = no_table.len() - "data table: not a packet".len();
    let p = write(dir.path(), "cut2.aedat4", &no_table[..len - 10]);
    let e = err_text(read_events(&p, &ReadOptions::default()));
    assert!(e.contains("cut2.aedat4") && e.contains("truncated"), "{e}");
    let p = write(dir.path(), "whole.aedat4", &no_table[..len]);
    assert_eq!(read_events(&p, &ReadOptions::default()).unwrap().len(), 50);
}

#[test]
fn every_truncation_and_many_bit_flips_of_the_sample_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(sample()).unwrap();
    let p = dir.path().join("mangled.aedat4");
    for cut in (0..bytes.len()).step_by(1999) {
        std::fs::write(&p, &bytes[..cut]).unwrap();
        let e = err_text(read_events(&p, &ReadOptions::default()));
        assert!(e.contains("mangled.aedat4"), "cut {cut}: {e}");
    }
    // Flipped bytes: either a clean error or a valid stream, never a panic.
    let mut s = 99u64;
    let mut errors = 0;
    for _ in 0..300 {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut b = bytes.clone();
        let at = (s >> 16) as usize % b.len();
        b[at] ^= 1 << ((s >> 8) % 8);
        std::fs::write(&p, &b).unwrap();
        match read_events(&p, &ReadOptions::default()) {
            Ok(ev) => assert!(ev.validate().is_ok()),
            Err(e) => {
                errors += 1;
                assert!(e.to_string().contains("mangled.aedat4"), "{e}")
            }
        }
    }
    assert!(errors > 0);
}

#[test]
fn reads_the_four_aps_frames_of_the_sample() {
    let frames = scene::formats::read_aedat4_frames(sample()).unwrap();
    assert_eq!(frames.len(), 4);
    // Figures from this reader, cross-checked for plausibility: frames every 40 ms with
    // 500 µs exposures, the first 3.65 ms before the first event; grey levels ~77.
    let sums = [6_949_660u64, 6_883_041, 6_961_512, 6_941_188];
    for (k, f) in frames.iter().enumerate() {
        assert_eq!(
            (f.width, f.height, f.channels, f.position),
            (346, 260, 1, (0, 0))
        );
        assert_eq!(f.pixels.len(), 346 * 260);
        let t = 1_589_163_147_365_215 + 40_000 * k as i64;
        assert_eq!(f.timestamp, t as f64 / 1e6);
        assert_eq!(f.exposure, ((t - 250) as f64 / 1e6, (t + 250) as f64 / 1e6));
        assert_eq!(f.pixels.iter().map(|&p| p as u64).sum::<u64>(), sums[k]);
    }
    // A file without a frame stream has no frames; a corrupt frame packet is named.
    let xml = r#"<node name="0" path="/o/0/"><attr key="typeIdentifier" type="string">EVTS</attr></node>"#;
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "noframes.aedat4", &aedat4(0, xml, &[]));
    assert!(scene::formats::read_aedat4_frames(&p).unwrap().is_empty());
    let xml = r#"<node name="1" path="/o/1/"><attr key="typeIdentifier" type="string">FRME</attr></node>"#;
    let p = write(
        dir.path(),
        "badframe.aedat4",
        &aedat4(0, xml, &[(1, vec![1, 2, 3])]),
    );
    let e = err_text(scene::formats::read_aedat4_frames(&p));
    assert!(
        e.contains("badframe.aedat4") && e.contains("packet 0"),
        "{e}"
    );
}
