//! The `.npz` event format (HS-ERGB layout): bit-exact round trips, coordinate scale,
//! big-endian and narrow types, and structural / truncated / hostile archives.

mod common;
use common::*;
use scene::formats::*;
use std::io::Write;
use std::path::Path;

#[test]
fn npz_round_trip_is_bit_exact_on_microsecond_timestamps() {
    let dir = tempfile::tempdir().unwrap();
    let ev = microsecond_stream(30_001);
    let p = dir.path().join("ev.npz");
    write_npz(&p, &ev).unwrap();
    let back = read_events(&p, &opts(346, 260)).unwrap();
    assert_same(&back, &ev);
    // Missing sensor size.
    assert!(err_text(read_npz(&p, &ReadOptions::default())).contains("sensor size"));
}

/// (member name, .npy bytes) of an archive.
type Members<'a> = Vec<(&'a str, Vec<u8>)>;

/// Write an .npz by hand from (name, npy bytes) members.
fn write_npz_members(path: &Path, members: &[(&str, Vec<u8>)]) {
    let mut zip = zip::ZipWriter::new(std::fs::File::create(path).unwrap());
    for (name, bytes) in members {
        let o = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated);
        zip.start_file(*name, o).unwrap();
        zip.write_all(bytes).unwrap();
    }
    zip.finish().unwrap();
}

fn npy<T: npyz::AutoSerialize>(data: &[T]) -> Vec<u8> {
    use npyz::WriterBuilder;
    let mut out = Vec::new();
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(&[data.len() as u64])
        .writer(&mut out)
        .begin_nd()
        .unwrap();
    w.extend(data).unwrap();
    w.finish().unwrap();
    out
}

#[test]
fn npz_hs_ergb_layout_with_coordinate_scale() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("hs.npz");
    // HS-ERGB-like: x, y ×32 (i32), `timestamp` f64 µs, `polarity` bool, deflated.
    let members = |x: i32| {
        vec![
            ("x.npy", npy(&[3 * 32 + 5i32, 10 * 32, x])),
            ("y.npy", npy(&[0i32, 7 * 32 + 15, 2 * 32])),
            (
                "timestamp.npy",
                npy(&[1_000_000.0f64, 1_000_000.5, 1_000_250.0]),
            ),
            ("polarity.npy", npy(&[true, false, true])),
        ]
    };
    write_npz_members(&p, &members(31 * 32 + 10));
    let o = ReadOptions {
        sensor: Some((32, 8)),
        coord_scale: Some(32.0),
    };
    let ev = read_events(&p, &o).unwrap();
    // 101/32 = 3.16 → 3, 320/32 = 10, 1002/32 = 31.3 → 31; 239/32 = 7.47 → 7.
    assert_eq!(ev.x, vec![3, 10, 31]);
    assert_eq!(ev.y, vec![0, 7, 2]);
    assert_eq!(ev.t, vec![1.0, 1.0000005, 1.00025]);
    assert_eq!(ev.p, vec![1, -1, 1]);
    // Without the scale the coordinates fall outside the sensor.
    let e = err_text(read_events(&p, &opts(32, 8)));
    assert!(
        e.contains("hs.npz") && e.contains("event 0") && e.contains("outside"),
        "{e}"
    );
    // 1012/32 = 31.6 rounds to 32: outside a 32-wide sensor.
    write_npz_members(&p, &members(31 * 32 + 20));
    let e = err_text(read_events(&p, &o));
    assert!(e.contains("event 2") && e.contains("outside"), "{e}");
    // coord_scale is refused for other formats.
    let e = err_text(read_events(ecd(), &o));
    assert!(
        e.contains("coordinate scale") && e.contains(".npz files only"),
        "{e}"
    );
}

/// `.npy` bytes of big-endian i64 (exercises npyz's general element reader).
fn npy_big_endian(data: &[i64]) -> Vec<u8> {
    use npyz::WriterBuilder;
    let mut out = Vec::new();
    let dtype = npyz::DType::Plain(">i8".parse().unwrap());
    let mut w = npyz::WriteOptions::new()
        .dtype(dtype)
        .shape(&[data.len() as u64])
        .writer(&mut out)
        .begin_nd()
        .unwrap();
    w.extend(data).unwrap();
    w.finish().unwrap();
    out
}

#[test]
fn npz_reads_big_endian_and_narrow_types() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("be.npz");
    let t = npy_big_endian(&[5, 6, 1_000_007]);
    assert!(String::from_utf8_lossy(&t).contains(">i8"));
    write_npz_members(
        &p,
        &[
            ("x.npy", npy(&[1u8, 2, 3])),
            ("y.npy", npy(&[4i16, 5, 6])),
            ("t.npy", t),
            ("p.npy", npy(&[-1i32, 1, -1])),
        ],
    );
    let ev = read_events(&p, &opts(8, 8)).unwrap();
    assert_eq!(ev.t, vec![5e-6, 6e-6, 1.000007]);
    assert_eq!(
        (ev.x, ev.y, ev.p),
        (vec![1, 2, 3], vec![4, 5, 6], vec![-1, 1, -1])
    );
}

#[test]
fn npz_structural_errors() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.npz");
    let t = npy(&[1i64, 2, 3]);
    let xy = npy(&[1u16, 2, 3]);
    let pol = npy(&[1i8, 0, 1]);
    let cases: Vec<(Members, &str)> = vec![
        (
            vec![
                ("x.npy", xy.clone()),
                ("y.npy", xy.clone()),
                ("p.npy", pol.clone()),
            ],
            "no array \"t\"",
        ),
        (
            vec![
                ("x.npy", npy(&[1u16, 2])),
                ("y.npy", xy.clone()),
                ("t.npy", t.clone()),
                ("p.npy", pol.clone()),
            ],
            "array lengths differ",
        ),
        (
            vec![
                ("x.npy", xy.clone()),
                ("y.npy", xy.clone()),
                ("t.npy", npy(&[3i64, 2, 1])),
                ("p.npy", pol.clone()),
            ],
            "not sorted",
        ),
        (
            vec![
                ("x.npy", xy.clone()),
                ("y.npy", xy.clone()),
                ("t.npy", npy(&[1.0f64, f64::NAN, 3.0])),
                ("p.npy", pol.clone()),
            ],
            "not finite",
        ),
        (
            vec![
                ("x.npy", xy.clone()),
                ("y.npy", xy.clone()),
                ("t.npy", t.clone()),
                ("p.npy", npy(&[1i8, 2, 0])),
            ],
            "polarity 2",
        ),
        (
            vec![
                ("x.npy", npy(&[1.5f32, 2.0, 3.0])),
                ("y.npy", xy.clone()),
                ("t.npy", t.clone()),
                ("p.npy", pol.clone()),
            ],
            "not a whole pixel",
        ),
        (
            vec![
                ("x.npy", xy.clone()),
                ("y.npy", xy.clone()),
                ("t.npy", t[..t.len() - 5].to_vec()),
                ("p.npy", pol.clone()),
            ],
            "t.npy",
        ),
        (
            vec![
                ("x.npy", b"\x93NUMPY garbage".to_vec()),
                ("y.npy", xy.clone()),
                ("t.npy", t.clone()),
                ("p.npy", pol.clone()),
            ],
            "not a valid .npy",
        ),
    ];
    for (members, want) in cases {
        write_npz_members(&p, &members);
        let e = err_text(read_npz(&p, &opts(8, 8)));
        assert!(
            e.contains("bad.npz") && e.contains(want),
            "want {want:?}: {e}"
        );
    }
    // A lying header (shape far larger than the data) is caught before allocating.
    let mut huge = npy(&[1i64, 2, 3]);
    let key = b"'shape': (3";
    let at = huge
        .windows(key.len())
        .position(|w| w == key)
        .expect("npy header")
        + key.len()
        - 1;
    huge[at] = b'9';
    write_npz_members(
        &p,
        &[
            ("x.npy", xy.clone()),
            ("y.npy", xy),
            ("t.npy", huge),
            ("p.npy", pol),
        ],
    );
    let e = err_text(read_npz(&p, &opts(8, 8)));
    assert!(e.contains("t.npy") && e.contains("truncated"), "{e}");
}

#[test]
fn npz_not_a_zip_cut_archive_and_empty_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.npz");
    write_npz(&good, &microsecond_stream(500)).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    assert_eq!(&bytes[..4], b"PK\x03\x04", "a zip archive");
    // A bare .npy saved as .npz (magic \x93NUMPY, not PK): no zip directory at all.
    let npy_file = npy(&[1i64, 2, 3]);
    // Broken local-header magic: the zip directory (at the end) is intact, so the
    // archive opens and the first member fails.
    let mut magic = bytes.clone();
    magic[..4].copy_from_slice(b"\x93NUM");
    let half = bytes[..bytes.len() / 2].to_vec();
    let zip = "not a valid .npz (zip)";
    let cases = [
        ("npy.npz", npy_file, zip),
        ("text.npz", b"t,x,y,p\n1,2,3,1\n".to_vec(), zip),
        ("magic.npz", magic, "x.npy: cannot open"),
        ("half.npz", half, zip),
        ("empty.npz", vec![], "file is empty"),
    ];
    // Every cut of the archive too: an error naming the file, never a panic or a stream.
    let cuts = (0..bytes.len())
        .step_by(97)
        .map(|n| ("cut.npz", bytes[..n].to_vec(), ""));
    for (name, data, want) in cases.into_iter().chain(cuts) {
        let p = dir.path().join(name);
        std::fs::write(&p, &data).unwrap();
        let r = std::panic::catch_unwind(|| read_events(&p, &opts(346, 260)));
        let e = err_text(r.unwrap_or_else(|_| panic!("{name} ({} B) panicked", data.len())));
        assert!(e.contains(name) && e.contains(want), "{name}: {e}");
    }
}
