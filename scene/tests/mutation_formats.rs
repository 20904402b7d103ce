//! The readers added after `mutation.rs` against thousands of damaged copies of a valid
//! file (`testkit::mutate`, docs/DESIGN.md "Inputs that cannot hurt"):
//! Prophesee `.raw` (EVT 2.0, EVT 3.0 with vector words), Event Stream `.es` (DVS, and
//! a hand-made ATIS file) and the APS frames of the real AEDAT4 recording. An error
//! naming the file or a valid result, never a panic, never an allocation beyond a bound
//! tied to the file's size. Regression tests for the faults found are at the end.

#[global_allocator]
static ALLOC: testkit::TrackingAlloc = testkit::TrackingAlloc;

mod common;

use common::aedat4_file::{aedat4, frame_packet};
use scene::events::EventStream;
use scene::formats::{self, RawEncoding, ReadOptions, read_es, read_raw};
use std::fs;
use std::path::Path;
use testkit::{Plan, fuzz};

/// A stream whose microsecond times `write_raw` and `write_es` can store: the common
/// test stream, 64×48, moved to start 46 ms after 0 (an `.es` file spends a byte per
/// 127 µs before the first event) and rounded to whole microseconds.
fn stream(n: usize, seed: u64) -> EventStream {
    let mut ev = common::stream(n, 64, 48, seed);
    ev.t.iter_mut()
        .for_each(|t| *t = ((*t - 12.3) * 1e6).round() / 1e6);
    ev
}

/// Fuzz `bytes` written to `dir/name` with `read`; the counts are printed.
fn fuzz_file<T>(
    dir: &Path,
    name: &str,
    bytes: &[u8],
    plan: &Plan,
    read: impl Fn(&Path) -> scene::Result<T>,
) {
    let path = dir.join(name);
    fs::write(&path, bytes).unwrap();
    assert!(read(&path).is_ok(), "the valid file is read");
    fuzz(&path, bytes, plan, read).assert_clean();
}

#[test]
fn raw_evt2_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("events.raw");
    formats::write_raw(&path, &stream(300, 11), RawEncoding::Evt2).unwrap();
    let bytes = fs::read(&path).unwrap();
    let plan = Plan::new(21);
    fuzz_file(dir.path(), "evt2.raw", &bytes, &plan, |p| {
        read_raw(p, &ReadOptions::default())
    });
}

/// EVT 3.0 words after `write_raw`'s events: a row, a vector base, a 12-event and an
/// 8-event vector, a continuation and a trigger word (all at the last event's time,
/// so the stream stays sorted).
fn evt3_with_vectors(dir: &Path) -> Vec<u8> {
    let path = dir.join("events.raw");
    formats::write_raw(&path, &stream(300, 12), RawEncoding::Evt3).unwrap();
    let mut bytes = fs::read(&path).unwrap();
    let words: [u16; 6] = [
        5,                         // EVT_ADDR_Y: y 5
        0x3000 | 0x800 | 10,       // VECT_BASE_X: x 10, ON
        0x4000 | 0b1010_0000_0101, // VECT_12: x 10, 12, 19, 21
        0x5000 | 0xFF,             // VECT_8: x 22..29
        0x7000,                    // continuation (skipped)
        0xA000,                    // trigger (skipped)
    ];
    bytes.extend(words.iter().flat_map(|w| w.to_le_bytes()));
    bytes
}

#[test]
fn raw_evt3_reader_with_vectors() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let bytes = evt3_with_vectors(dir.path());
    let p = dir.path().join("check.raw");
    fs::write(&p, &bytes).unwrap();
    assert_eq!(
        read_raw(&p, &ReadOptions::default()).unwrap().len(),
        300 + 12
    );
    fuzz_file(dir.path(), "evt3.raw", &bytes, &Plan::new(22), |p| {
        read_raw(p, &ReadOptions::default())
    });
}

#[test]
fn es_dvs_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("events.es");
    formats::write_es(&path, &stream(300, 13)).unwrap();
    let bytes = fs::read(&path).unwrap();
    // the sensor width and height (u16 each) are the only length-like fields
    let mut plan = Plan::new(23);
    plan.length_fields = vec![(16, 4)];
    fuzz_file(dir.path(), "dvs.es", &bytes, &plan, |p| {
        read_es(p, &ReadOptions::default())
    });
}

/// An ATIS Event Stream by hand (the writer makes DVS only): 300 events, a third of
/// them threshold crossings (skipped by the reader), overflow and reset bytes between.
fn atis_file() -> (Vec<u8>, usize) {
    let mut b = b"Event Stream".to_vec();
    b.extend([2, 0, 0, 2]); // version 2.0.0, ATIS
    b.extend(64u16.to_le_bytes());
    b.extend(48u16.to_le_bytes());
    let mut dvs = 0;
    for k in 0..300u32 {
        match k % 17 {
            5 => b.push(0xFD),  // overflow: t += 63
            11 => b.push(0xFC), // reset
            _ => {}
        }
        let delta = (k * 7 % 63) as u8; // 63 would make the byte an overflow
        let is_tc = k % 3 == 0;
        dvs += usize::from(!is_tc);
        b.push(delta << 2 | ((k % 2) as u8) << 1 | u8::from(is_tc));
        b.extend(((k * 13 % 64) as u16).to_le_bytes());
        b.extend(((k * 5 % 48) as u16).to_le_bytes());
    }
    (b, dvs)
}

#[test]
fn es_atis_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let (bytes, dvs) = atis_file();
    let p = dir.path().join("check.es");
    fs::write(&p, &bytes).unwrap();
    assert_eq!(read_es(&p, &ReadOptions::default()).unwrap().len(), dvs);
    assert_eq!(dvs, 200);
    let mut plan = Plan::new(24);
    plan.length_fields = vec![(16, 4)];
    fuzz_file(dir.path(), "atis.es", &bytes, &plan, |p| {
        read_es(p, &ReadOptions::default())
    });
}

/// A hand-made uncompressed AEDAT4 file of three frames (8×6 grey, 6×4 BGR, 4×3
/// BGRA): the damage lands in the frame FlatBuffers themselves, which the real
/// recording (below) keeps LZ4-compressed.
#[test]
fn aedat4_frame_reader_on_uncompressed_frames() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let xml = r#"<node name="1" path="/o/1/"><attr key="typeIdentifier" type="string">FRME</attr></node>"#;
    let px = |n: usize| (0..n).map(|k| (k * 37 % 256) as u8).collect::<Vec<u8>>();
    let packets = [
        (1, frame_packet(1_000_000, 0, (8, 6), &px(8 * 6))),
        (1, frame_packet(1_040_000, 16, (6, 4), &px(6 * 4 * 3))),
        (1, frame_packet(1_080_000, 24, (4, 3), &px(4 * 3 * 4))),
    ];
    let bytes = aedat4(0, xml, &packets);
    let p = dir.path().join("check.aedat4");
    fs::write(&p, &bytes).unwrap();
    let frames = formats::read_aedat4_frames(&p).unwrap();
    let shapes: Vec<_> = frames
        .iter()
        .map(|f| (f.width, f.height, f.channels))
        .collect();
    assert_eq!(shapes, [(8, 6, 1), (6, 4, 3), (4, 3, 3)]);
    assert_eq!(frames[2].exposure, (1.07975, 1.08025));
    // BGR(A) → RGB: the first pixel's bytes 0, 37, 74 (BGR) become 74, 37, 0
    assert_eq!(frames[1].pixels[..3], [74, 37, 0]);
    let mut plan = Plan::new(26);
    plan.length_fields = vec![(14, 4)];
    fuzz_file(dir.path(), "frames.aedat4", &bytes, &plan, |p| {
        formats::read_aedat4_frames(p)
    });
}

/// The real DAVIS346 recording's four APS frames (LZ4-compressed packets).
#[test]
fn aedat4_frame_reader_on_real_recording() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let bytes = fs::read(testkit::testdata::shared_data(
        "aedat4_sample/sample.aedat4",
    ))
    .unwrap();
    let mut plan = Plan::new(25);
    plan.mutations = 1000;
    plan.length_fields = vec![(14, 4)];
    fuzz_file(dir.path(), "sample.aedat4", &bytes, &plan, |p| {
        formats::read_aedat4_frames(p)
    });
}
