//! `.evflow` and `.flo`: bit-exact round trips; truncated, wrong magic, NaN and hostile
//! headers give errors naming the file, never a panic or a huge allocation.

use evflow::flowfile::{EvFlow, HEADER_LEN, read_evflow, read_flo, write_evflow, write_flo};

fn sample(n: usize) -> EvFlow {
    EvFlow {
        width: 240,
        height: 180,
        t_a: 2.097134001,
        t_b: 2.1957,
        t_ref: 2.097134001,
        source_hash: std::array::from_fn(|i| i as u8 * 7),
        index: (0..n as u64).map(|i| 3 * i + 5).collect(),
        u: (0..n).map(|i| (i as f32 * 0.37).sin() * 123.456).collect(),
        v: (0..n)
            .map(|i| -(i as f32) * 1e-3 - f32::MIN_POSITIVE)
            .collect(),
    }
}

#[test]
fn evflow_round_trip_is_bit_exact() {
    let dir = tempfile::tempdir().unwrap();
    for n in [0, 1, 1000] {
        let p = dir.path().join(format!("{n}.evflow"));
        let f = sample(n);
        write_evflow(&p, &f).unwrap();
        assert_eq!(
            std::fs::metadata(&p).unwrap().len(),
            (HEADER_LEN + 16 * n) as u64
        );
        let g = read_evflow(&p).unwrap();
        assert_eq!(f, g);
        let bits = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&f.u), bits(&g.u));
        assert_eq!(bits(&f.v), bits(&g.v));
        assert_eq!(f.t_a.to_bits(), g.t_a.to_bits());
    }
}

#[test]
fn bad_evflow_files_give_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.evflow");
    write_evflow(&good, &sample(50)).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let mut cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty", vec![], "truncated"),
        ("short_header", bytes[..40].to_vec(), "truncated"),
        ("truncated", bytes[..bytes.len() - 3].to_vec(), "truncated"),
        (
            "trailing",
            [bytes.clone(), vec![0; 16]].concat(),
            "does not match",
        ),
    ];
    let mut magic = bytes.clone();
    magic[0] = b'X';
    cases.push(("magic", magic, "magic"));
    let mut version = bytes.clone();
    version[8] = 9;
    cases.push(("version", version, "version"));
    let mut huge = bytes.clone();
    huge[48..56].copy_from_slice(&(u64::MAX / 3).to_le_bytes());
    cases.push(("huge", huge, "does not match"));
    let mut nan = bytes.clone();
    let u0 = HEADER_LEN + 8 * 50;
    nan[u0..u0 + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    cases.push(("nan", nan, "not finite"));
    let mut order = bytes.clone();
    order[HEADER_LEN..HEADER_LEN + 8].copy_from_slice(&u64::MAX.to_le_bytes());
    cases.push(("order", order, "strictly increasing"));
    let mut window = bytes.clone();
    window[24..32].copy_from_slice(&f64::INFINITY.to_le_bytes());
    cases.push(("window", window, "not finite"));
    for (name, b, want) in cases {
        let p = dir.path().join(format!("{name}.evflow"));
        std::fs::write(&p, b).unwrap();
        let e = read_evflow(&p).unwrap_err().to_string();
        assert!(e.contains(&format!("{name}.evflow")), "{name}: {e}");
        assert!(e.contains(want), "{name}: {e}");
    }
    let e = read_evflow(&dir.path().join("missing.evflow"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing.evflow"), "{e}");
    // The writer refuses NaN and leaves nothing behind.
    let mut bad = sample(3);
    bad.v[1] = f32::NAN;
    let p = dir.path().join("refused.evflow");
    assert!(write_evflow(&p, &bad).is_err());
    assert!(!p.exists());
}

#[test]
fn flo_round_trip_and_errors() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (7u32, 5u32);
    let u: Vec<f32> = (0..35).map(|i| i as f32 * 0.25 - 3.0).collect();
    let v: Vec<f32> = (0..35).map(|i| 1.5 - i as f32 * 0.125).collect();
    let p = dir.path().join("a.flo");
    write_flo(&p, w, h, &u, &v).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    assert_eq!(&bytes[..4], &202021.25f32.to_le_bytes());
    assert_eq!(bytes.len(), 12 + 8 * 35);
    // Interleaved u, v of pixel 0 right after the header.
    assert_eq!(&bytes[12..16], &u[0].to_le_bytes());
    assert_eq!(&bytes[16..20], &v[0].to_le_bytes());
    assert_eq!(read_flo(&p).unwrap(), (w, h, u, v));
    let t = dir.path().join("t.flo");
    std::fs::write(&t, &bytes[..bytes.len() - 1]).unwrap();
    assert!(read_flo(&t).unwrap_err().to_string().contains("t.flo"));
    let m = dir.path().join("m.flo");
    std::fs::write(&m, [0u8; 20]).unwrap();
    assert!(read_flo(&m).unwrap_err().to_string().contains("magic"));
}

#[test]
fn colour_wheel_is_white_at_zero_and_saturated_at_max() {
    let c = evflow::flowfile::color_wheel(&[0.0, 2.0, 0.0], &[0.0, 0.0, -2.0], None);
    assert_eq!(&c[..3], &[1.0, 1.0, 1.0]);
    assert_eq!(&c[3..6], &[1.0, 0.0, 0.0]); // right = red
    assert!(c.iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x)));
}
