//! `assoc.bin` round trip and corrupt inputs; lifting events through a depth map.

use assoc::{Bindings, FrameBindings, lift_events, read_assoc, write_assoc};
use glam::{DVec2, DVec3};
use scene::{Camera, EventStream, Intrinsics, Pose};

fn sample_frames() -> Vec<FrameBindings> {
    let b = Bindings {
        offsets: vec![0, 2, 2, 5, 5],
        events: vec![3, 8, 1, 2, 40_000_000_000],
        weights: vec![0.25, 0.75, 0.2, 0.3, 0.5],
    };
    vec![
        FrameBindings {
            t0: 0.125,
            delta_t: 0.01,
            k: 3,
            bindings: b,
        },
        FrameBindings {
            t0: 0.5,
            delta_t: 0.02,
            k: 4,
            bindings: Bindings {
                offsets: vec![0; 7],
                ..Default::default()
            },
        },
    ]
}

#[test]
fn assoc_bin_round_trips_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("assoc.bin");
    let frames = sample_frames();
    write_assoc(&path, &frames).unwrap();
    let back = read_assoc(&path).unwrap();
    assert_eq!(back, frames);
    // Writing what was read gives the same bytes.
    let p2 = dir.path().join("again.bin");
    write_assoc(&p2, &back).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), std::fs::read(&p2).unwrap());
}

#[test]
fn corrupt_truncated_and_foreign_files_are_named_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("assoc.bin");
    write_assoc(&path, &sample_frames()).unwrap();
    let good = std::fs::read(&path).unwrap();
    let bad = dir.path().join("bad.bin");
    let mut cases: Vec<Vec<u8>> = vec![
        Vec::new(),
        good[..good.len() / 2].to_vec(),
        b"PLY\nformat binary".to_vec(),
    ];
    let mut flipped = good.clone();
    flipped[30] ^= 0x40;
    cases.push(flipped);
    for bytes in cases {
        std::fs::write(&bad, &bytes).unwrap();
        let e = read_assoc(&bad).unwrap_err().to_string();
        assert!(e.contains("bad.bin"), "{e}");
    }
    // A well-formed checksum over a hostile header (huge counts) is still rejected.
    let mut hostile = good[..good.len() - 32].to_vec();
    hostile[8 + 4 + 4 + 16 + 4..8 + 4 + 4 + 16 + 8].copy_from_slice(&u32::MAX.to_le_bytes());
    let sum = blake3::hash(&hostile);
    hostile.extend_from_slice(sum.as_bytes());
    std::fs::write(&bad, &hostile).unwrap();
    let e = read_assoc(&bad).unwrap_err().to_string();
    assert!(e.contains("bad.bin"), "{e}");
    let missing = read_assoc(&dir.path().join("nope.bin"))
        .unwrap_err()
        .to_string();
    assert!(missing.contains("nope.bin"), "{missing}");
}

#[test]
fn writer_rejects_too_many_bindings() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.bin");
    let f = FrameBindings {
        t0: 0.0,
        delta_t: 0.01,
        k: 1,
        bindings: Bindings {
            offsets: vec![0, 2],
            events: vec![1, 2],
            weights: vec![0.5, 0.5],
        },
    };
    assert!(write_assoc(&path, &[f]).is_err());
    assert!(!path.exists(), "nothing half-written");
}

#[test]
fn lifted_events_lie_on_the_rendered_plane() {
    // Camera at (0,0,5) looking at the origin; a plane z = 0 fills the view.
    let k = Intrinsics::from_fov_x(64, 48, 1.0);
    let cam = Camera {
        intrinsics: k,
        cam_to_world: Pose::look_at(DVec3::new(0.3, -0.2, 5.0), DVec3::ZERO, DVec3::Y),
    };
    let (w, h) = (64usize, 48usize);
    let mut depth = vec![0f32; w * h];
    let mut alpha = vec![0f32; w * h];
    for v in 0..h {
        for u in 0..w {
            // Ray through the pixel centre hits z = 0 at camera depth d.
            let dir = cam.unproject_world(DVec2::new(u as f64, v as f64), 1.0)
                - cam.cam_to_world.centre();
            let s = -cam.cam_to_world.centre().z / dir.z;
            depth[v * w + u] = s as f32;
            alpha[v * w + u] = if u < 8 { 0.2 } else { 1.0 };
        }
    }
    let mut ev = EventStream::new(64, 48);
    for i in 0..200u16 {
        ev.push(i as f64 * 1e-4, (i * 7) % 64, (i * 5) % 48, 1);
    }
    let slice = ev.window(0.005, 1.0);
    let lifted = lift_events(&cam, &depth, &alpha, 0.5, &slice);
    assert_eq!(lifted.points.len() + lifted.dropped_no_depth, slice.len());
    assert!(lifted.dropped_no_depth > 0);
    for (p, &i) in lifted.points.iter().zip(&lifted.event_index) {
        assert!(p[2].abs() < 1e-4, "point {p:?} off the plane");
        assert!(i >= slice.offset as u64);
        let (px, _) = cam
            .project_world(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64))
            .unwrap();
        let j = i as usize;
        assert!((px.x - ev.x[j] as f64).abs() < 1e-3 && (px.y - ev.y[j] as f64).abs() < 1e-3);
    }
}
