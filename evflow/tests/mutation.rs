//! The flow crate's readers against thousands of damaged copies of a valid file
//! (`testkit::mutate`, docs/DESIGN.md "Inputs that cannot hurt"): `.evflow`,
//! Middlebury `.flo`, network weights (safetensors) and their JSON sidecars, LoRA
//! adapters and theirs, and the ECD ground truth (`flow.npy`, `calib.txt`).

#[global_allocator]
static ALLOC: testkit::TrackingAlloc = testkit::TrackingAlloc;

use burn::tensor::{DType, Device};
use evflow::flowfile::{EvFlow, read_evflow, read_flo, write_evflow, write_flo};
use evflow::net::io::{BareWeights, load, load_adapters, save_adapters, sidecar};
use evflow::net::{FlowNet, NetConfig};
use std::fs;
use std::path::{Path, PathBuf};
use testkit::{Plan, fuzz};

#[test]
fn evflow_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("0000.evflow");
    let n = 120;
    let flow = EvFlow {
        width: 64,
        height: 48,
        t_a: 0.25,
        t_b: 0.5,
        t_ref: 0.25,
        source_hash: [7; 32],
        index: (0..n as u64).map(|i| 3 * i + 1).collect(),
        u: (0..n).map(|i| i as f32 - 60.0).collect(),
        v: (0..n).map(|i| 0.5 * i as f32).collect(),
    };
    write_evflow(&path, &flow).unwrap();
    let bytes = fs::read(&path).unwrap();
    let mut plan = Plan::new(21);
    plan.length_fields = vec![(8, 4), (12, 4), (16, 4), (48, 8)];
    fuzz(&path, &bytes, &plan, read_evflow).assert_clean();
}

#[test]
fn flo_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flow.flo");
    let u: Vec<f32> = (0..12 * 9).map(|k| k as f32 * 0.25).collect();
    let v: Vec<f32> = u.iter().map(|x| 1.0 - x).collect();
    write_flo(&path, 12, 9, &u, &v).unwrap();
    let bytes = fs::read(&path).unwrap();
    let mut plan = Plan::new(22);
    plan.length_fields = vec![(4, 4), (8, 4)];
    fuzz(&path, &bytes, &plan, read_flo).assert_clean();
}

/// A tiny network (C = 2) saved with its sidecar by the project's writer.
fn tiny_net(dir: &Path) -> (FlowNet, PathBuf) {
    let cfg = NetConfig {
        base: 2,
        bins: 5,
        max_flow: 16.0,
    };
    let net = FlowNet::new(cfg, 3, &Device::flex(), DType::F32);
    let path = dir.join("net.safetensors");
    net.save(&path, "mutation test").unwrap();
    (net, path)
}

fn load_weights(path: &Path) -> scene::Result<FlowNet> {
    load(path, &BareWeights::default(), &Device::flex(), DType::F32).map(|l| l.net)
}

#[test]
fn weights_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let (_, path) = tiny_net(dir.path());
    let bytes = fs::read(&path).unwrap();
    let mut plan = Plan::new(23);
    plan.mutations = 1000;
    // the safetensors header length
    plan.length_fields = vec![(0, 8)];
    fuzz(&path, &bytes, &plan, load_weights).assert_clean();
}

/// Bare weights (no sidecar): the settings come from the damaged tensors themselves.
#[test]
fn bare_weights_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let (_, path) = tiny_net(dir.path());
    fs::remove_file(sidecar(&path)).unwrap();
    let bytes = fs::read(&path).unwrap();
    let mut plan = Plan::new(24);
    plan.mutations = 1000;
    plan.length_fields = vec![(0, 8)];
    fuzz(&path, &bytes, &plan, load_weights).assert_clean();
}

#[test]
fn weights_sidecar_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let (_, path) = tiny_net(dir.path());
    let side = sidecar(&path);
    let bytes = fs::read(&side).unwrap();
    let mut plan = Plan::new(25);
    plan.mutations = 1000;
    fuzz(&side, &bytes, &plan, |_| load_weights(&path)).assert_clean();
}

#[test]
fn adapter_and_sidecar_readers() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let (mut net, _) = tiny_net(dir.path());
    net.attach_lora(2, 4.0, 5);
    let path = dir.path().join("adapter.safetensors");
    save_adapters(&net, &path).unwrap();
    let load_into = |_: &Path| {
        let mut fresh = net.clone();
        load_adapters(&mut fresh, &path)
    };
    let bytes = fs::read(&path).unwrap();
    let mut plan = Plan::new(26);
    plan.mutations = 1000;
    plan.length_fields = vec![(0, 8)];
    fuzz(&path, &bytes, &plan, load_into).assert_clean();
    let side = sidecar(&path);
    let bytes = fs::read(&side).unwrap();
    let mut plan = Plan::new(27);
    plan.mutations = 1000;
    fuzz(&side, &bytes, &plan, load_into).assert_clean();
}

/// The real ECD ground truth: `flow.npy` (1×2×180×240 float64) and `calib.txt`.
#[test]
fn ecd_ground_truth_readers() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let real = |f: &str| {
        fs::read(testkit::testdata::shared_data(&format!(
            "ecd_shapes_rotation/{f}"
        )))
    };
    let path = dir.path().join("flow.npy");
    let mut plan = Plan::new(28);
    plan.mutations = 600;
    fuzz(&path, &real("flow.npy").unwrap(), &plan, |p| {
        evflow::eval::read_flow_npy(p)
    })
    .assert_clean();
    let path = dir.path().join("calib.txt");
    fuzz(&path, &real("calib.txt").unwrap(), &Plan::new(29), |p| {
        evflow::source::read_calib(p, (240, 180))
    })
    .assert_clean();
}

/// Regressions (found by the harness): a sidecar that is not UTF-8 was taken as no
/// sidecar, and a sidecar's bad settings were reported against the safetensors file;
/// both now name the sidecar.
#[test]
fn sidecar_errors_name_the_sidecar() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let (net, path) = tiny_net(dir.path());
    let side = sidecar(&path);
    let text = fs::read_to_string(&side).unwrap();
    let side_name = side.display().to_string();
    for bad in [
        text.replace("\"bins\": 5", "\"bins\": 1000000000")
            .into_bytes(),
        text.replace("\"max_flow\": 16.0", "\"max_flow\": 0")
            .into_bytes(),
        [text.as_bytes(), &[0xFF; 4]].concat(),
    ] {
        assert_ne!(bad, text.as_bytes());
        fs::write(&side, &bad).unwrap();
        let msg = load_weights(&path).err().unwrap().to_string();
        assert!(msg.starts_with(&side_name), "{msg}");
    }
    fs::write(&side, &text).unwrap();
    let mut with = net.clone();
    with.attach_lora(2, 4.0, 5);
    let adapter = dir.path().join("adapter.safetensors");
    save_adapters(&with, &adapter).unwrap();
    let aside = sidecar(&adapter);
    let atext = fs::read_to_string(&aside).unwrap();
    fs::write(&aside, atext.replace("\"bins\": 5", "\"bins\": 55")).unwrap();
    let msg = load_adapters(&mut net.clone(), &adapter)
        .unwrap_err()
        .to_string();
    assert!(msg.starts_with(&aside.display().to_string()), "{msg}");
    assert!(msg.contains("adapter is for network"), "{msg}");
}
