//! External weights without a JSON sidecar: the settings are inferred from the tensor
//! shapes (`--width` checks C, `--max-flow` sets the heads' scale), the result is the
//! same network as with the sidecar, and corrupt, truncated or mismatched files give
//! one-line errors that name the file, from the library and from the binary.

use burn::tensor::{DType, Device};
use evflow::net::io::{BareWeights, DEFAULT_MAX_FLOW, load};
use evflow::net::{FlowNet, NetConfig, tensor4, to_f64};
use std::path::{Path, PathBuf};
use std::process::Command;

fn evflow() -> Command {
    Command::new(env!("CARGO_BIN_EXE_evflow"))
}

/// A tiny network (C = 4, max_flow 16) saved with its sidecar, and a bare copy.
fn weights(dir: &Path) -> (PathBuf, PathBuf) {
    let cfg = NetConfig {
        base: 4,
        bins: 5,
        max_flow: 16.0,
    };
    let net = FlowNet::new(cfg, 3, &Device::flex(), DType::F32);
    let with = dir.join("with.safetensors");
    net.save(&with, "test").unwrap();
    let bare = dir.join("bare.safetensors");
    std::fs::copy(&with, &bare).unwrap();
    assert!(!evflow::net::io::sidecar(&bare).exists());
    (with, bare)
}

fn output(net: &FlowNet) -> Vec<f64> {
    let vox: Vec<f32> = (0..5 * 16 * 16)
        .map(|i| ((i * 37) % 11) as f32 - 5.0)
        .collect();
    let x = tensor4(vox, [1, 5, 16, 16], &net.device, net.dtype);
    to_f64(net.forward(x))
}

fn err_of(path: &Path, bare: BareWeights) -> String {
    load(path, &bare, &Device::flex(), DType::F32)
        .map(|_| ())
        .unwrap_err()
        .to_string()
}

#[test]
fn bare_weights_load_with_inferred_settings() {
    let tmp = tempfile::tempdir().unwrap();
    let (with, bare) = weights(tmp.path());
    let dev = Device::flex();
    let reference = load(&with, &BareWeights::default(), &dev, DType::F32).unwrap();
    assert!(!reference.inferred && reference.note(&with).is_none());
    // Inferred: C and B from enc1.weight, max_flow the default.
    let l = load(&bare, &BareWeights::default(), &dev, DType::F32).unwrap();
    assert!(l.inferred);
    assert_eq!(
        l.net.config,
        NetConfig {
            base: 4,
            bins: 5,
            max_flow: DEFAULT_MAX_FLOW
        }
    );
    let note = l.note(&bare).unwrap();
    assert!(
        note.contains("bare.safetensors") && note.contains("C = 4"),
        "{note}"
    );
    // With the right --max-flow (and a matching --width) the network is the saved one,
    // output for output.
    let spec = BareWeights {
        base: Some(4),
        max_flow: Some(16.0),
    };
    let l = load(&bare, &spec, &dev, DType::F32).unwrap();
    assert_eq!(l.net.config, reference.net.config);
    let (a, b) = (output(&l.net), output(&reference.net));
    assert_eq!(a.len(), 2 * 16 * 16);
    assert_eq!(a, b);
    assert!(a.iter().any(|v| v.abs() > 1e-6), "a non-trivial output");
    // The default max_flow (32) scales the tanh heads (and, through the coarse flows
    // fed to the next decoder level, changes the output beyond a factor): bounded by it.
    let d = output(
        &load(&bare, &BareWeights::default(), &dev, DType::F32)
            .unwrap()
            .net,
    );
    assert!(d.iter().all(|x| x.abs() <= DEFAULT_MAX_FLOW), "tanh bound");
    assert!(
        d.iter().zip(&b).any(|(x, y)| (x - y).abs() > 1e-3),
        "max_flow is used"
    );
    // A wrong --width is an error naming the file (bare) or the sidecar.
    let e = err_of(
        &bare,
        BareWeights {
            base: Some(8),
            ..Default::default()
        },
    );
    assert!(e.contains("bare.safetensors") && e.contains("C = 4"), "{e}");
    let e = err_of(
        &with,
        BareWeights {
            base: Some(8),
            ..Default::default()
        },
    );
    assert!(
        e.contains("with.safetensors.json") && e.contains("C = 4"),
        "{e}"
    );
    let e = err_of(
        &with,
        BareWeights {
            max_flow: Some(32.0),
            ..Default::default()
        },
    );
    assert!(
        e.contains("with.safetensors.json") && e.contains("max_flow = 16"),
        "{e}"
    );
    // The sidecar's own value (and no flags) is fine.
    let same = BareWeights {
        base: Some(4),
        max_flow: Some(16.0),
    };
    assert!(load(&with, &same, &dev, DType::F32).is_ok());
    let e = err_of(
        &bare,
        BareWeights {
            max_flow: Some(f64::INFINITY),
            ..Default::default()
        },
    );
    assert!(e.contains("max-flow"), "{e}");
}

#[test]
fn corrupt_bare_weights_name_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, bare) = weights(tmp.path());
    let bytes = std::fs::read(&bare).unwrap();
    let write = |name: &str, b: &[u8]| {
        let p = tmp.path().join(name);
        std::fs::write(&p, b).unwrap();
        p
    };
    // Truncated in the data, in the header, and empty.
    for (name, len) in [
        ("half.safetensors", bytes.len() / 2),
        ("head.safetensors", 20),
        ("empty.safetensors", 0),
    ] {
        let e = err_of(&write(name, &bytes[..len]), BareWeights::default());
        assert!(
            e.contains(name) && e.contains("not a safetensors file"),
            "{name}: {e}"
        );
    }
    // A huge header length.
    let mut huge = bytes.clone();
    huge[..8].copy_from_slice(&u64::MAX.to_le_bytes());
    let e = err_of(&write("huge.safetensors", &huge), BareWeights::default());
    assert!(e.contains("huge.safetensors"), "{e}");
    // Valid safetensors, but not this network: no enc1, wrong enc1 shape, a missing
    // tensor, non-finite values.
    let t = |name: &str, shape: Vec<usize>, v: f32| {
        (
            name.to_string(),
            shape.clone(),
            vec![v; shape.iter().product()],
        )
    };
    let cases = [
        (
            "other.safetensors",
            vec![t("conv.weight", vec![4, 5, 3, 3], 0.1)],
            "enc1.weight",
        ),
        (
            "shape.safetensors",
            vec![t("enc1.weight", vec![4, 5, 1, 1], 0.1)],
            "[C, B, 3, 3]",
        ),
        (
            "partial.safetensors",
            vec![t("enc1.weight", vec![4, 5, 3, 3], 0.1)],
            "missing tensor enc1.bias",
        ),
        (
            "nan.safetensors",
            vec![t("enc1.weight", vec![4, 5, 3, 3], f32::NAN)],
            "non-finite",
        ),
    ];
    for (name, tensors, want) in cases {
        let p = tmp.path().join(name);
        evflow::net::io::write_safetensors(&p, &tensors).unwrap();
        let e = err_of(&p, BareWeights::default());
        assert!(e.contains(name) && e.contains(want), "{name}: {e}");
    }
    let e = err_of(
        &tmp.path().join("absent.safetensors"),
        BareWeights::default(),
    );
    assert!(
        e.contains("absent.safetensors") && e.contains("not found"),
        "{e}"
    );
}

/// `t x y p` lines: a bar moving right at 40 px/s over 0.2 s on a 32×24 sensor.
fn event_file(dir: &Path) -> PathBuf {
    let mut s = String::new();
    for k in 0..3000 {
        let t = k as f64 / 3000.0 * 0.2;
        let x = (4.0 + 40.0 * t) as u32 + (k % 3) as u32;
        s.push_str(&format!("{t:.6} {x} {} {}\n", 2 + k % 20, k % 2));
    }
    let p = dir.join("events.txt");
    std::fs::write(&p, s).unwrap();
    p
}

fn predict(events: &Path, weights: &Path, extra: &[&str], out: &Path) -> (Option<i32>, String) {
    let run = evflow()
        .args(["predict", "--events"])
        .arg(events)
        .args(["--sensor", "32x24", "--no-previews", "--weights"])
        .arg(weights)
        .args(extra)
        .arg("--out")
        .arg(out)
        .output()
        .unwrap();
    (
        run.status.code(),
        String::from_utf8_lossy(&run.stderr).into_owned(),
    )
}

#[test]
fn the_binary_loads_bare_weights_and_documents_the_names() {
    let help = evflow().arg("--help").output().unwrap();
    let text = String::from_utf8_lossy(&help.stdout);
    for name in [
        "enc1.weight [C,B,3,3]",
        "dec3.weight",
        "flow0..flow3",
        "NAME.bias",
        "lora_a",
        "--max-flow",
    ] {
        assert!(text.contains(name), "{name} missing from --help:\n{text}");
    }
    let tmp = tempfile::tempdir().unwrap();
    let (with, bare) = weights(tmp.path());
    let events = event_file(tmp.path());
    let (code, err) = predict(&events, &with, &[], &tmp.path().join("a"));
    assert_eq!(code, Some(0), "{err}");
    assert!(!err.contains("no JSON sidecar"), "{err}");
    let (code, err) = predict(
        &events,
        &bare,
        &["--width", "4", "--max-flow", "16"],
        &tmp.path().join("b"),
    );
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("warning") && err.contains("no JSON sidecar") && err.contains("max_flow = 16"),
        "{err}"
    );
    // Same network, same per-event flow.
    let fa = evflow::flowfile::read_evflow(&tmp.path().join("a/flow/0000.evflow")).unwrap();
    let fb = evflow::flowfile::read_evflow(&tmp.path().join("b/flow/0000.evflow")).unwrap();
    assert_eq!(fa.len(), 3000);
    assert_eq!((&fa.index, &fa.u, &fa.v), (&fb.index, &fb.u, &fb.v));
    assert!(fa.u.iter().chain(&fa.v).all(|x| x.is_finite()));
    // The resolved settings record the bare-weights flags.
    let settings = std::fs::read_to_string(tmp.path().join("b/settings.toml")).unwrap();
    assert!(
        settings.contains("weights_width = 4") && settings.contains("weights_max_flow = 16"),
        "{settings}"
    );
    // Errors: a wrong --width, a truncated file; one line naming the file, no output.
    let (code, err) = predict(&events, &bare, &["--width", "16"], &tmp.path().join("c"));
    assert_eq!(code, Some(1), "{err}");
    let last = err.lines().last().unwrap();
    assert!(
        last.contains("bare.safetensors") && last.contains("--width 16"),
        "{last}"
    );
    let cut = tmp.path().join("cut.safetensors");
    let bytes = std::fs::read(&bare).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() - 100]).unwrap();
    let (code, err) = predict(&events, &cut, &[], &tmp.path().join("d"));
    assert_eq!(code, Some(1), "{err}");
    let last = err.lines().last().unwrap();
    assert!(
        last.contains("cut.safetensors") && last.contains("not a safetensors file"),
        "{last}"
    );
    assert!(!tmp.path().join("c").exists() && !tmp.path().join("d").exists());
    // --width without --weights is a usage error.
    let run = evflow()
        .args(["predict", "--events"])
        .arg(&events)
        .args(["--sensor", "32x24", "--width", "4", "--out"])
        .arg(tmp.path().join("e"))
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(2));
}
