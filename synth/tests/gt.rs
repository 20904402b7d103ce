//! Ground-truth files of synthetic scenes: round trips and hostile input.

use synth::gt::{
    EventFlowGt, read_event_flow_gt, read_object_png, write_event_flow_gt, write_object_png,
};

fn sample() -> EventFlowGt {
    EventFlowGt {
        width: 64,
        height: 48,
        index: vec![0, 1, 5, 9],
        u: vec![1.5, -0.0, f32::MIN_POSITIVE, 1e30],
        v: vec![-3.25, 7.0, 0.1, -1e-30],
        object: vec![0, 3, 65535, 1],
    }
}

#[test]
fn event_flow_round_trips_bit_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("gt/event_flow.bin");
    let gt = sample();
    write_event_flow_gt(&p, &gt).unwrap();
    let back = read_event_flow_gt(&p).unwrap();
    assert_eq!(back, gt);
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&back.u), bits(&gt.u));
    assert_eq!(std::fs::metadata(&p).unwrap().len(), 32 + 4 * 18);
    // Empty is valid.
    let empty = EventFlowGt {
        width: 1,
        height: 1,
        ..Default::default()
    };
    write_event_flow_gt(&p, &empty).unwrap();
    assert_eq!(read_event_flow_gt(&p).unwrap(), empty);
}

#[test]
fn event_flow_rejects_bad_files_with_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("e.bin");
    write_event_flow_gt(&p, &sample()).unwrap();
    let good = std::fs::read(&p).unwrap();
    let check = |bytes: &[u8], what: &str| {
        std::fs::write(&p, bytes).unwrap();
        let e = read_event_flow_gt(&p).unwrap_err().to_string();
        assert!(e.contains("e.bin") && e.contains(what), "{e}");
    };
    check(&[], "header");
    check(&good[..20], "header");
    check(&good[..good.len() - 1], "truncated");
    let mut bad = good.clone();
    bad[0] = b'X';
    check(&bad, "magic");
    let mut bad = good.clone();
    bad[8] = 9;
    check(&bad, "version");
    // Hostile count: would overflow the size computation.
    let mut bad = good.clone();
    bad[24..32].copy_from_slice(&u64::MAX.to_le_bytes());
    check(&bad, "truncated");
    // NaN flow (first u value).
    let mut bad = good.clone();
    bad[64..68].copy_from_slice(&f32::NAN.to_le_bytes());
    check(&bad, "not finite");
    // Indices out of order.
    let mut bad = good.clone();
    bad[40..48].copy_from_slice(&7u64.to_le_bytes());
    check(&bad, "increasing");
    assert!(read_event_flow_gt(dir.path().join("missing.bin")).is_err());
}

#[test]
fn event_flow_writer_refuses_bad_columns_and_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("e.bin");
    let mut gt = sample();
    gt.v[2] = f32::INFINITY;
    assert!(write_event_flow_gt(&p, &gt).is_err());
    let mut gt = sample();
    gt.object.pop();
    assert!(write_event_flow_gt(&p, &gt).is_err());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn object_png_round_trips_16_bit_ids() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("object_0000.png");
    let ids: Vec<u16> = (0..12).map(|i| [0, 1, 2, 300, 65535, 7][i % 6]).collect();
    write_object_png(&p, 4, 3, &ids).unwrap();
    assert_eq!(read_object_png(&p).unwrap(), (4, 3, ids));
    assert!(write_object_png(&p, 5, 3, &[0; 12]).is_err());
    std::fs::write(&p, b"\x89PNG garbage").unwrap();
    let e = read_object_png(&p).unwrap_err().to_string();
    assert!(e.contains("object_0000.png"), "{e}");
}
