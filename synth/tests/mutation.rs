//! The synthetic scenes' ground-truth readers against thousands of damaged copies of a
//! file the writer made (`testkit::mutate`, docs/DESIGN.md "Inputs that cannot
//! hurt"): `gt/event_flow.bin`, the 16-bit object-id PNGs, and `timestamps.txt` of a
//! frame folder. (Depth and flow EXRs and the pose manifests are `scene` readers,
//! fuzzed in `scene/tests/mutation.rs`.) An error naming the file or a valid result,
//! never a panic, never an allocation beyond a bound tied to the file's size.

#[global_allocator]
static ALLOC: testkit::TrackingAlloc = testkit::TrackingAlloc;

use std::fs;
use synth::frames::read_timestamps;
use synth::gt::{
    EventFlowGt, NOISE_ID, read_event_flow_gt, read_object_png, write_event_flow_gt,
    write_object_png,
};
use testkit::{Plan, fuzz};

#[test]
fn event_flow_gt_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("event_flow.bin");
    let n = 150;
    let gt = EventFlowGt {
        width: 64,
        height: 48,
        index: (0..n as u64).map(|i| 2 * i + 1).collect(),
        u: (0..n).map(|i| i as f32 * 0.75 - 40.0).collect(),
        v: (0..n).map(|i| 12.5 - i as f32 * 0.25).collect(),
        object: (0..n).map(|i| [0, 1, 2, NOISE_ID][i % 4]).collect(),
    };
    write_event_flow_gt(&path, &gt).unwrap();
    let bytes = fs::read(&path).unwrap();
    assert_eq!(bytes.len(), 32 + 18 * n);
    // width, height, reserved, and the event count
    let mut plan = Plan::new(31);
    plan.length_fields = vec![(12, 4), (16, 4), (20, 4), (24, 8)];
    fuzz(&path, &bytes, &plan, |p| read_event_flow_gt(p)).assert_clean();
}

#[test]
fn object_png_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("object_0000.png");
    let (w, h) = (24u32, 16u32);
    let ids: Vec<u16> = (0..w * h)
        .map(|k| [0, 1, 2, 300, 65535][(k / 5 % 5) as usize])
        .collect();
    write_object_png(&path, w, h, &ids).unwrap();
    let bytes = fs::read(&path).unwrap();
    // IHDR width and height (big-endian in PNG; the hostile words still land there)
    let mut plan = Plan::new(32);
    plan.length_fields = vec![(16, 4), (20, 4)];
    fuzz(&path, &bytes, &plan, |p| read_object_png(p)).assert_clean();
}

#[test]
fn timestamps_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("timestamps.txt");
    let mut text = String::from("# frame times, seconds\n");
    for k in 0..60 {
        text += &format!("{:.6}\n", 0.125 + k as f64 * 0.0333);
        if k % 20 == 7 {
            text += "\n";
        }
    }
    fs::write(&path, &text).unwrap();
    assert_eq!(read_timestamps(&path).unwrap().len(), 60);
    fuzz(&path, text.as_bytes(), &Plan::new(33), |p| {
        read_timestamps(p)
    })
    .assert_clean();
}
