//! Helpers shared by the event-format test files.
#![allow(dead_code)]

use scene::events::EventStream;
use scene::formats::ReadOptions;

pub mod aedat4_file;

/// The real ECD `shapes_rotation` slice shared by the tests.
pub fn ecd() -> std::path::PathBuf {
    testkit::testdata::shared_data("ecd_shapes_rotation/events.txt")
}

/// A sorted pseudo-random stream with awkward timestamps (full f64 mantissas, ties).
pub fn stream(n: usize, w: u32, h: u32, seed: u64) -> EventStream {
    let mut s = seed;
    let mut next = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        s >> 11
    };
    let mut ev = EventStream::new(w, h);
    let mut t = 12.345678901234567f64;
    for i in 0..n {
        if i % 7 != 3 {
            t += (next() % 1000) as f64 * 1.1e-7 + 1e-9;
        } // every 7th event shares its predecessor's timestamp
        let x = (next() % w as u64) as u16;
        let y = (next() % h as u64) as u16;
        let p = if next() % 2 == 0 { 1 } else { -1 };
        ev.push(t, x, y, p);
    }
    ev
}

/// The same stream with timestamps rounded to whole microseconds (what .npz holds).
pub fn microsecond_stream(n: usize) -> EventStream {
    let mut ev = stream(n, 346, 260, 5);
    ev.t.iter_mut().for_each(|t| *t = (*t * 1e6).round() / 1e6);
    ev
}

pub fn bits(ev: &EventStream) -> Vec<u64> {
    ev.t.iter().map(|t| t.to_bits()).collect()
}

pub fn assert_same(a: &EventStream, b: &EventStream) {
    assert_eq!((a.width, a.height, a.len()), (b.width, b.height, b.len()));
    assert_eq!(bits(a), bits(b), "timestamps differ in some bit");
    assert_eq!(a.x, b.x);
    assert_eq!(a.y, b.y);
    assert_eq!(a.p, b.p);
}

pub fn err_text<T: std::fmt::Debug>(r: scene::Result<T>) -> String {
    r.expect_err("expected an error").to_string()
}

pub fn opts(w: u32, h: u32) -> ReadOptions {
    ReadOptions {
        sensor: Some((w, h)),
        coord_scale: None,
    }
}
