//! `DEGS_SYNTH_CODE`: a fingerprint of the code that makes synthetic scenes (the `synth`
//! and `scene` crates' sources, the lock file, the compiler and the optimisation level).
//! The runner keys the synth stage by it instead of by the whole `degs` binary, so a
//! change to the runner or the charts does not make every synthetic scene (and every
//! stage after it) stale.

use std::path::{Path, PathBuf};

/// 64-bit FNV-1a, continued from `h`.
fn fnv(mut h: u64, bytes: &[u8]) -> u64 {
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    for e in rd.flatten() {
        let p = e.path();
        if p.is_dir() {
            files(&p, out);
        } else {
            out.push(p);
        }
    }
}

fn main() {
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap());
    let root = manifest.parent().unwrap().to_path_buf();
    let mut inputs = Vec::new();
    for dir in ["synth/src", "scene/src"] {
        println!("cargo:rerun-if-changed=../{dir}");
        files(&root.join(dir), &mut inputs);
    }
    for f in [
        "Cargo.lock",
        "Cargo.toml",
        "synth/Cargo.toml",
        "scene/Cargo.toml",
    ] {
        println!("cargo:rerun-if-changed=../{f}");
        inputs.push(root.join(f));
    }
    inputs.sort();
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let version = std::process::Command::new(rustc)
        .arg("-vV")
        .output()
        .map(|o| o.stdout)
        .unwrap_or_default();
    let mut h = [0xcbf2_9ce4_8422_2325u64, 0x8422_2325_cbf2_9ce4u64];
    let mut feed = |bytes: &[u8]| {
        h[0] = fnv(h[0], bytes);
        h[1] = fnv(h[1], bytes);
        h[1] = fnv(h[1], &h[0].to_le_bytes());
    };
    feed(&version);
    for v in ["OPT_LEVEL", "TARGET", "PROFILE"] {
        feed(std::env::var(v).unwrap_or_default().as_bytes());
    }
    for f in &inputs {
        let rel = f.strip_prefix(&root).unwrap_or(f);
        feed(rel.to_string_lossy().as_bytes());
        feed(&std::fs::read(f).unwrap_or_default());
    }
    println!("cargo:rustc-env=DEGS_SYNTH_CODE={:016x}{:016x}", h[0], h[1]);
}
