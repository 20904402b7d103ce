//! Event file formats: bit-exact round trips, the real ecd() sample, conversion, and
//! truncated / empty / corrupt / hostile input.

mod common;
use common::*;
use scene::events::EventStream;
use scene::formats::*;
use std::path::{Path, PathBuf};

fn only_file(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn text_round_trip_is_bit_exact() {
    let dir = tempfile::tempdir().unwrap();
    let ev = stream(50_000, 240, 180, 1);
    let p = dir.path().join("ev.txt");
    write_text(&p, &ev).unwrap();
    // The header carries the sensor size, so no option is needed.
    let back = read_events(&p, &ReadOptions::default()).unwrap();
    assert_same(&back, &ev);
    let first = std::fs::read_to_string(&p).unwrap();
    let mut lines = first.lines();
    assert!(lines.next().unwrap().contains("width=240 height=180"));
    // p is written as 0/1.
    let l = lines.next().unwrap();
    assert!(l.ends_with(" 0") || l.ends_with(" 1"), "{l}");
    // An empty stream round-trips too.
    let empty = EventStream::new(4, 3);
    write_text(&p, &empty).unwrap();
    assert_same(&read_text(&p, &ReadOptions::default()).unwrap(), &empty);
}

#[test]
fn reads_the_real_ecd_sample() {
    let ev = read_events(ecd(), &opts(240, 180)).unwrap();
    assert_eq!(ev.len(), 20_000);
    assert_eq!((ev.width, ev.height), (240, 180));
    // First and last lines of the file (checked with head/tail).
    assert_eq!(
        (ev.t[0], ev.x[0], ev.y[0], ev.p[0]),
        (2.097134001, 162, 27, -1)
    );
    assert_eq!((ev.t[1], ev.x[1], ev.y[1]), (2.09714, 77, 45));
    let n = ev.len() - 1;
    assert_eq!(
        (ev.t[n], ev.x[n], ev.y[n], ev.p[n]),
        (2.195729, 127, 147, 1)
    );
    assert_eq!(ev.t[n - 1], 2.1957200009999998);
    // 8,560 ON events (awk over the 4th column); max x 236, max y 179.
    assert_eq!(ev.p.iter().filter(|&&p| p == 1).count(), 8_560);
    assert_eq!(*ev.x.iter().max().unwrap(), 236);
    assert_eq!(*ev.y.iter().max().unwrap(), 179);
    // Without a sensor size the reader says what is missing.
    let e = err_text(read_events(ecd(), &ReadOptions::default()));
    assert!(e.contains("events.txt") && e.contains("sensor size"), "{e}");
    // A sensor too small for the data: the offending event is named.
    let e = err_text(read_events(ecd(), &opts(200, 180)));
    assert!(e.contains("outside the 200x180 sensor"), "{e}");
}

#[test]
fn evs_round_trip_is_bit_exact_and_mappable() {
    let dir = tempfile::tempdir().unwrap();
    let ev = stream(100_003, 346, 260, 2);
    let p = dir.path().join("ev.evs");
    write_evs(&p, &ev).unwrap();
    assert_eq!(
        std::fs::metadata(&p).unwrap().len(),
        64 + 13 * ev.len() as u64
    );
    assert_same(&read_events(&p, &ReadOptions::default()).unwrap(), &ev);
    assert_same(&read_evs(&p, &opts(346, 260)).unwrap(), &ev);
    let map = EvsMap::open(&p).unwrap();
    assert_eq!(map.len(), ev.len());
    assert_eq!(map.t(), &ev.t[..]);
    assert_eq!(map.x(), &ev.x[..]);
    assert_eq!(map.y(), &ev.y[..]);
    assert_eq!(map.p(), &ev.p[..]);
    assert_eq!(map.hash(), evs::content_hash(&ev));
    assert_eq!(
        map.hash(),
        *blake3::hash(&std::fs::read(&p).unwrap()[64..]).as_bytes()
    );
    // Header fields at their documented offsets.
    let bytes = std::fs::read(&p).unwrap();
    assert_eq!(&bytes[..8], b"DEGSEVS\0");
    assert_eq!(u32::from_le_bytes(bytes[12..16].try_into().unwrap()), 346);
    assert_eq!(
        u64::from_le_bytes(bytes[24..32].try_into().unwrap()),
        100_003
    );
    assert_eq!(
        f64::from_le_bytes(bytes[64..72].try_into().unwrap()),
        ev.t[0]
    );
    // The stored sensor must agree with the expected one.
    let e = err_text(read_evs(&p, &opts(240, 180)));
    assert!(e.contains("346x260") && e.contains("240x180"), "{e}");
    // Empty streams are legal .evs files.
    let empty = EventStream::new(8, 8);
    write_evs(&p, &empty).unwrap();
    assert_same(&read_evs(&p, &ReadOptions::default()).unwrap(), &empty);
}

#[test]
fn convert_between_formats() {
    let dir = tempfile::tempdir().unwrap();
    let evs = dir.path().join("ecd.evs");
    let s = convert(ecd(), &evs, &opts(240, 180)).unwrap();
    assert_eq!(s.events, 20_000);
    assert_eq!((s.width, s.height), (240, 180));
    assert_eq!((s.input_format, s.output_format), ("text", "evs"));
    assert_eq!((s.t_first, s.t_last), (2.097134001, 2.195729));
    let txt = dir.path().join("back.txt");
    let s2 = convert(&evs, &txt, &ReadOptions::default()).unwrap();
    assert_eq!(s2.events, 20_000);
    let a = read_events(ecd(), &opts(240, 180)).unwrap();
    let b = read_events(&txt, &ReadOptions::default()).unwrap();
    assert_same(&a, &b);
    let e = err_text(convert(
        &evs,
        dir.path().join("out.aedat4"),
        &ReadOptions::default(),
    ));
    assert!(
        e.contains("out.aedat4") && e.contains("not supported"),
        "{e}"
    );
    let e = err_text(convert(
        &evs,
        dir.path().join("out.csv"),
        &ReadOptions::default(),
    ));
    assert!(e.contains("unknown event file extension"), "{e}");
    assert_eq!(only_file(dir.path()), vec!["back.txt", "ecd.evs"]);
}

#[test]
fn hostile_text_files() {
    let dir = tempfile::tempdir().unwrap();
    let cases: &[(&str, &str)] = &[
        ("", "file is empty"),
        ("1.0 2 3 1\n1.5 2", "line 2"),
        ("1.0 2 3 1\n0.5 2 3 1\n", "not sorted"),
        ("1.0 2 3 1\nnan 2 3 1\n", "not finite"),
        ("1.0 2 3 1\ninf 2 3 1\n", "not finite"),
        ("1.0 2 300 1\n", "outside the 8x8 sensor"),
        ("1.0 -2 3 1\n", "x \"-2\""),
        ("1.0 2 3 2\n", "polarity"),
        ("1.0 2 3 1 5\n", "more than 4 fields"),
        ("abc 2 3 1\n", "timestamp \"abc\""),
        ("1.0 2 3 1\n\u{0}\u{1}\u{2}\n", "line 2"),
        ("# degs-events width=x height=3\n1.0 2 3 1\n", "lacks width"),
    ];
    for (i, (text, want)) in cases.iter().enumerate() {
        let p = dir.path().join(format!("case{i}.txt"));
        std::fs::write(&p, text).unwrap();
        let e = err_text(read_events(&p, &opts(8, 8)));
        assert!(
            e.contains(&format!("case{i}.txt")) && e.contains(want),
            "{text:?}: {e}"
        );
    }
    // Comments, CRLF line ends and blank lines are fine.
    let p = dir.path().join("ok.txt");
    std::fs::write(&p, "# t x y p\r\n1.0 2 3 1\r\n\r\n1.5 4 5 0\r\n").unwrap();
    let ev = read_events(&p, &opts(8, 8)).unwrap();
    assert_eq!((ev.len(), ev.x[1], ev.p[1]), (2, 4, -1));
    // The header's sensor size must agree with an expected one.
    let q = dir.path().join("hdr.txt");
    write_text(&q, &stream(10, 16, 16, 3)).unwrap();
    let e = err_text(read_events(&q, &opts(8, 8)));
    assert!(e.contains("16x16") && e.contains("8x8"), "{e}");
}

#[test]
fn hostile_evs_files() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.evs");
    let ev = stream(1000, 64, 48, 4);
    write_evs(&good, &ev).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let mut cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty.evs", vec![], "file is empty"),
        (
            "short.evs",
            bytes[..40].to_vec(),
            "shorter than the 64-byte header",
        ),
        ("trunc.evs", bytes[..bytes.len() - 1].to_vec(), "truncated"),
        ("long.evs", [&bytes[..], &[0u8]].concat(), "does not match"),
    ];
    let mut magic = bytes.clone();
    magic[0] = b'X';
    cases.push(("magic.evs", magic, "not an .evs file"));
    let mut version = bytes.clone();
    version[8] = 9;
    cases.push(("version.evs", version, "version 9"));
    let mut count = bytes.clone();
    count[24..32].copy_from_slice(&u64::MAX.to_le_bytes());
    cases.push(("count.evs", count, "does not match"));
    let mut flipped = bytes.clone();
    flipped[64 + 8 * 500] ^= 1; // one bit of an x coordinate
    cases.push(("flip.evs", flipped, "hash mismatch"));
    for (name, data, want) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, data).unwrap();
        let e = err_text(read_events(&p, &ReadOptions::default()));
        assert!(e.contains(name) && e.contains(want), "{name}: {e}");
    }
    // Contents that pass the hash but break the stream's rules: forge files whose hash
    // matches (what a buggy writer elsewhere could produce).
    let forge = |name: &str, f: &dyn Fn(&mut Vec<u8>)| -> PathBuf {
        let mut b = bytes.clone();
        f(&mut b);
        let h = blake3::hash(&b[64..]);
        b[32..64].copy_from_slice(h.as_bytes());
        let p = dir.path().join(name);
        std::fs::write(&p, b).unwrap();
        p
    };
    let n = ev.len();
    let cases: Vec<(PathBuf, &str)> = vec![
        (
            forge("nan.evs", &|b| {
                b[64 + 8 * 7..64 + 8 * 8].copy_from_slice(&f64::NAN.to_le_bytes())
            }),
            "event 7: timestamp NaN",
        ),
        (
            forge("unsorted.evs", &|b| {
                b[64 + 8 * 9..64 + 8 * 10].copy_from_slice(&0.0f64.to_le_bytes())
            }),
            "event 9: timestamps not sorted",
        ),
        (
            forge("outside.evs", &|b| {
                let o = 64 + 8 * n + 2 * 3;
                b[o..o + 2].copy_from_slice(&64u16.to_le_bytes())
            }),
            "event 3: pixel (64,",
        ),
        (
            forge("pol.evs", &|b| b[64 + 12 * n + 11] = 0),
            "event 11: polarity 0",
        ),
        (
            forge("zero.evs", &|b| {
                b[12..16].copy_from_slice(&0u32.to_le_bytes())
            }),
            "not usable",
        ),
    ];
    for (p, want) in cases {
        let e = err_text(read_events(&p, &ReadOptions::default()));
        assert!(
            e.contains(p.file_name().unwrap().to_str().unwrap()) && e.contains(want),
            "{e}"
        );
    }
}

#[test]
fn writers_refuse_invalid_streams_and_leave_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let mut bad = stream(10, 8, 8, 6);
    bad.t[4] = bad.t[2] - 1.0;
    for name in ["a.evs", "a.txt", "a.npz"] {
        let e = err_text(write_events(dir.path().join(name), &bad));
        assert!(e.contains(name) && e.contains("not sorted"), "{e}");
    }
    let mut outside = stream(10, 8, 8, 6);
    outside.x[0] = 8;
    assert!(err_text(write_evs(dir.path().join("b.evs"), &outside)).contains("outside"));
    assert!(only_file(dir.path()).is_empty());

    // A write that fails at the end (the target is a directory, so the rename fails)
    // removes its temp file and leaves the directory alone.
    let target = dir.path().join("c.evs");
    std::fs::create_dir(&target).unwrap();
    assert!(write_evs(&target, &stream(10, 8, 8, 7)).is_err());
    assert!(write_text(dir.path().join("c.evs"), &stream(10, 8, 8, 7)).is_err());
    assert_eq!(only_file(dir.path()), vec!["c.evs"]);
    assert!(target.is_dir());

    // Overwriting a good file with a failing write keeps the old file intact.
    let keep = dir.path().join("keep.evs");
    let good = stream(100, 8, 8, 8);
    write_evs(&keep, &good).unwrap();
    assert!(write_evs(&keep, &bad).is_err());
    assert_same(&read_evs(&keep, &ReadOptions::default()).unwrap(), &good);
}

#[test]
fn unknown_extension_and_missing_file() {
    let e = err_text(read_events("/nonexistent/ev.dat", &ReadOptions::default()));
    assert!(
        e.contains("ev.dat") && e.contains("unknown event file extension"),
        "{e}"
    );
    let e = err_text(read_events("/nonexistent/ev.evs", &ReadOptions::default()));
    assert!(e.contains("/nonexistent/ev.evs"), "{e}");
}
