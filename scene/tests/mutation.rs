//! Every reader of the data layer against thousands of damaged copies of a valid file
//! (`testkit::mutate`, docs/DESIGN.md "Inputs that cannot hurt"): an error that
//! names the file or a valid result, never a panic, never an allocation beyond a bound
//! tied to the file's size. The regression tests at the end hold the minimal inputs of
//! the faults the harness found.

#[global_allocator]
static ALLOC: testkit::TrackingAlloc = testkit::TrackingAlloc;

mod common;

use scene::formats::{self, ReadOptions, aedat4, read_evs, read_npz, read_text};
use scene::image_io::{self, Image};
use scene::manifest::{EventsRef, Frame, Manifest, Scene};
use scene::{Intrinsics, Pose};
use std::fs;
use std::path::Path;
use testkit::{Plan, fuzz};

fn sensor(w: u32, h: u32) -> ReadOptions {
    ReadOptions {
        sensor: Some((w, h)),
        coord_scale: None,
    }
}

#[test]
fn evs_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("events.evs");
    formats::write_evs(&path, &common::stream(300, 64, 48, 1)).unwrap();
    let bytes = fs::read(&path).unwrap();
    // The header's hash covers the columns: recompute it so damage reaches the checks
    // behind it.
    let rehash = |b: &mut [u8]| {
        if b.len() >= 64 {
            let h = blake3::hash(&b[64..]);
            b[32..64].copy_from_slice(h.as_bytes());
        }
    };
    let mut plan = Plan::new(1);
    plan.length_fields = vec![(8, 4), (12, 4), (16, 4), (24, 8)];
    plan.fixup = Some(&rehash);
    fuzz(&path, &bytes, &plan, |p| {
        read_evs(p, &ReadOptions::default())
    })
    .assert_clean();
}

/// The first 1500 lines of the real ECD recording (240×180, no header line).
#[test]
fn text_reader_on_real_ecd_events() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("events.txt");
    let text = fs::read_to_string(common::ecd()).unwrap();
    let head: String = text.lines().take(1500).flat_map(|l| [l, "\n"]).collect();
    let mut plan = Plan::new(2);
    plan.mutations = 1500;
    fuzz(&path, head.as_bytes(), &plan, |p| {
        read_text(p, &sensor(240, 180))
    })
    .assert_clean();
}

/// A file of [`formats::write_text`], whose header line gives the sensor.
#[test]
fn text_reader_with_header() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("events.txt");
    formats::write_text(&path, &common::stream(200, 64, 48, 3)).unwrap();
    let bytes = fs::read(&path).unwrap();
    let plan = Plan::new(3);
    fuzz(&path, &bytes, &plan, |p| {
        read_text(p, &ReadOptions::default())
    })
    .assert_clean();
}

#[test]
fn npz_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("events.npz");
    formats::write_npz(&path, &common::microsecond_stream(200)).unwrap();
    let bytes = fs::read(&path).unwrap();
    let plan = Plan::new(4);
    fuzz(&path, &bytes, &plan, |p| read_npz(p, &sensor(346, 260))).assert_clean();
}

/// The real DAVIS346 recording (429 kB: events, frames, IMU).
#[test]
fn aedat4_reader_on_real_recording() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sample.aedat4");
    let bytes = fs::read(testkit::testdata::shared_data(
        "aedat4_sample/sample.aedat4",
    ))
    .unwrap();
    let mut plan = Plan::new(5);
    plan.mutations = 1000;
    // the header length (after the 14-byte magic)
    plan.length_fields = vec![(14, 4)];
    fuzz(&path, &bytes, &plan, |p| {
        aedat4::read_aedat4(p, &ReadOptions::default())
    })
    .assert_clean();
}

fn pose(t: f64) -> Pose {
    let m = glam::DMat4::from_translation(glam::DVec3::new(t, 0.5 * t, 2.0));
    Pose::from_matrix(m).unwrap()
}

/// A tiny scene directory: three train frames (8×6 PNGs), `.evs` events.
fn write_scene(dir: &Path) {
    let camera = Intrinsics {
        width: 8,
        height: 6,
        fx: 10.0,
        fy: 10.0,
        cx: 3.5,
        cy: 2.5,
        distortion: None,
    };
    let frames: Vec<Frame> = (0..3)
        .map(|i| Frame {
            file_path: format!("images/train_{i:04}.png"),
            timestamp: 0.1 * i as f64,
            time: 0.5 * i as f64,
            cam_to_world: pose(i as f64),
        })
        .collect();
    for f in &frames {
        let mut img = Image::new(8, 6, 3);
        img.data
            .iter_mut()
            .enumerate()
            .for_each(|(k, v)| *v = (k % 7) as f32 / 7.0);
        image_io::write_png(dir.join(&f.file_path), &img).unwrap();
    }
    formats::write_evs(dir.join("events.evs"), &common::stream(100, 8, 6, 9)).unwrap();
    let m = Manifest {
        camera,
        frames,
        events: Some(EventsRef {
            path: "events.evs".into(),
            contrast_threshold: 0.2,
        }),
        frame_encoding: None,
    };
    m.write(dir.join(scene::manifest::TRAIN_FILE)).unwrap();
}

#[test]
fn manifest_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    write_scene(dir.path());
    let path = dir.path().join(scene::manifest::TRAIN_FILE);
    let bytes = fs::read(&path).unwrap();
    fuzz(&path, &bytes, &Plan::new(6), |p| Manifest::read(p)).assert_clean();
}

/// The whole scene directory opened (images checked, events read) with a damaged
/// `transforms_train.json`.
#[test]
fn scene_directory_with_damaged_manifest() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    write_scene(dir.path());
    let path = dir.path().join(scene::manifest::TRAIN_FILE);
    let bytes = fs::read(&path).unwrap();
    let mut plan = Plan::new(7);
    plan.mutations = 1000;
    fuzz(&path, &bytes, &plan, |_| {
        Scene::open(dir.path()).and_then(|s| s.load_events())
    })
    .assert_clean();
}

#[test]
fn png_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frame.png");
    let mut img = Image::new(24, 16, 3);
    img.data
        .iter_mut()
        .enumerate()
        .for_each(|(k, v)| *v = ((k * 37) % 256) as f32 / 255.0);
    image_io::write_png(&path, &img).unwrap();
    let bytes = fs::read(&path).unwrap();
    // IHDR width and height (big-endian in PNG; the hostile words still land there)
    let mut plan = Plan::new(8);
    plan.length_fields = vec![(16, 4), (20, 4)];
    fuzz(&path, &bytes, &plan, |p| image_io::read_image(p)).assert_clean();
}

#[test]
fn exr_depth_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("depth.exr");
    let depth: Vec<f32> = (0..24 * 16).map(|k| 1.0 + k as f32 * 0.01).collect();
    image_io::write_exr_depth(&path, 24, 16, &depth).unwrap();
    let bytes = fs::read(&path).unwrap();
    fuzz(&path, &bytes, &Plan::new(9), |p| {
        image_io::read_exr_depth(p)
    })
    .assert_clean();
}

#[test]
fn exr_flow_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flow.exr");
    let u: Vec<f32> = (0..20 * 10).map(|k| k as f32 * 0.5 - 20.0).collect();
    let v: Vec<f32> = u.iter().map(|x| -x).collect();
    image_io::write_exr_flow(&path, 20, 10, &u, &v).unwrap();
    let bytes = fs::read(&path).unwrap();
    fuzz(&path, &bytes, &Plan::new(10), |p| {
        image_io::read_exr_flow(p)
    })
    .assert_clean();
}

// Regression tests: the faults the harness found, each with its minimal input.

/// An `.npz` whose zip directory claims a member of 4 GiB: the reader allocated what
/// the directory claimed (up to 1 GiB) before reading a byte.
#[test]
fn npz_member_claiming_a_huge_size_is_refused_without_allocating_it() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("events.npz");
    formats::write_npz(&path, &common::microsecond_stream(20)).unwrap();
    let mut bytes = fs::read(&path).unwrap();
    // the central directory record of the first member: uncompressed size at +24
    let cd = bytes.windows(4).position(|w| w == b"PK\x01\x02").unwrap();
    bytes[cd + 24..cd + 28].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    fs::write(&path, &bytes).unwrap();
    let (result, peak) = testkit::alloc::peak_during(|| read_npz(&path, &sensor(346, 260)));
    let msg = result.unwrap_err().to_string();
    assert!(msg.contains(&path.display().to_string()), "{msg}");
    assert!(
        msg.contains("x.npy") && msg.contains("declares 4294967280 bytes"),
        "{msg}"
    );
    assert!(peak < 1 << 20, "{peak} bytes allocated");
}

/// A 911-byte flow EXR with one header word set to 1 (found by the harness): the
/// decoder allocated 2.6 GB. Now its declared size is checked against the file first.
#[test]
fn exr_declaring_more_pixels_than_it_can_hold_is_refused_before_decoding() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flow.exr");
    let u: Vec<f32> = (0..20 * 10).map(|k| k as f32 * 0.5 - 20.0).collect();
    let v: Vec<f32> = u.iter().map(|x| -x).collect();
    image_io::write_exr_flow(&path, 20, 10, &u, &v).unwrap();
    let bytes = fs::read(&path).unwrap();
    assert_eq!(bytes.len(), 911);
    let damaged = testkit::Mutation::SetWord {
        at: 304,
        width: 4,
        value: 1,
    }
    .apply(&bytes);
    fs::write(&path, &damaged).unwrap();
    let (result, peak) = testkit::alloc::peak_during(|| image_io::read_exr_flow(&path));
    let msg = result.unwrap_err().to_string();
    assert!(msg.contains(&path.display().to_string()), "{msg}");
    assert!(msg.contains("more than its 911 bytes can hold"), "{msg}");
    assert!(peak < 1 << 20, "{peak} bytes allocated");
}
