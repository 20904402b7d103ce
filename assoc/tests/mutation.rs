//! `assoc.bin` against thousands of damaged copies of a valid file
//! (`testkit::mutate`, docs/DESIGN.md "Inputs that cannot hurt"), with and
//! without its checksum recomputed (so the damage also reaches the parser behind it).

#[global_allocator]
static ALLOC: testkit::TrackingAlloc = testkit::TrackingAlloc;

use assoc::{Bindings, FrameBindings, read_assoc, read_assoc_for, write_assoc};
use std::fs;
use testkit::{Plan, fuzz};

/// Two frames of bindings for a model of 6 Gaussians.
fn frames() -> Vec<FrameBindings> {
    vec![
        FrameBindings {
            t0: 0.125,
            delta_t: 0.01,
            k: 3,
            bindings: Bindings {
                offsets: vec![0, 2, 2, 5, 5, 6, 6],
                events: vec![3, 8, 1, 2, 40_000_000_000, 7],
                weights: vec![0.25, 0.75, 0.2, 0.3, 0.5, 1.0],
            },
        },
        FrameBindings {
            t0: 0.5,
            delta_t: 0.02,
            k: 2,
            bindings: Bindings {
                offsets: vec![0, 0, 1, 1, 3, 3, 3],
                events: vec![11, 12, 13],
                weights: vec![1.0, 0.5, 0.5],
            },
        },
    ]
}

/// Recompute the trailing BLAKE3 checksum over everything before it.
fn rehash(b: &mut [u8]) {
    if b.len() >= 32 {
        let n = b.len() - 32;
        let h = blake3::hash(&b[..n]);
        b[n..].copy_from_slice(h.as_bytes());
    }
}

#[test]
fn assoc_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("assoc.bin");
    write_assoc(&path, &frames()).unwrap();
    let bytes = fs::read(&path).unwrap();
    let mut plan = Plan::new(41);
    // frame count; first frame's k, Gaussian and bound counts
    plan.length_fields = vec![(12, 4), (32, 4), (36, 4), (40, 4)];
    plan.fixup = Some(&rehash);
    fuzz(&path, &bytes, &plan, |p| read_assoc_for(p, 2, 6)).assert_clean();
}

/// Regression (found by reading the parser for the harness's hostile counts): without
/// the model's counts, a file of a few frame headers each claiming 2²⁵ Gaussians made
/// the reader allocate 128 MiB per frame. Now the total is bounded, and with the
/// model's counts a header that disagrees is refused before any allocation.
#[test]
fn frames_claiming_huge_models_are_refused() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("assoc.bin");
    let mut b = b"DEGSASC\0".to_vec();
    b.extend_from_slice(&1u32.to_le_bytes()); // version
    b.extend_from_slice(&3u32.to_le_bytes()); // frames
    for _ in 0..3 {
        b.extend_from_slice(&0.5f64.to_le_bytes()); // t0
        b.extend_from_slice(&0.01f64.to_le_bytes()); // delta_t
        b.extend_from_slice(&3u32.to_le_bytes()); // k
        b.extend_from_slice(&(1u32 << 25).to_le_bytes()); // Gaussians
        b.extend_from_slice(&0u32.to_le_bytes()); // bound
    }
    b.extend_from_slice(&[0; 32]);
    rehash(&mut b);
    fs::write(&path, &b).unwrap();
    let (r, peak) = testkit::alloc::peak_during(|| read_assoc(&path));
    let msg = r.unwrap_err().to_string();
    assert!(msg.contains(&path.display().to_string()), "{msg}");
    assert!(
        msg.contains("frame 1: more than 33554432 Gaussians"),
        "{msg}"
    );
    assert!(peak <= (4 << 25) + (1 << 20), "{peak} bytes");
    let (r, peak) = testkit::alloc::peak_during(|| read_assoc_for(&path, 3, 1000));
    let msg = r.unwrap_err().to_string();
    assert!(
        msg.contains("frame 0: bindings for 33554432 Gaussians but the model has 1000"),
        "{msg}"
    );
    assert!(peak < 1 << 20, "{peak} bytes");
    let msg = read_assoc_for(&path, 2, 1000).unwrap_err().to_string();
    assert!(
        msg.contains("3 frames of bindings for 2 train frames"),
        "{msg}"
    );
}
