//! Wall time of a fully cached `degs run` (goal: under a second).
//!
//! `cargo bench -p pipeline --bench cached_run` → a table on stdout and
//! `$CARGO_TARGET_DIR/bench-results/cached_run.json` (default `target/`).
//!
//! The experiment is the demo's: the `rigid` preset at 96×96 built by the real `degs
//! synth`, then stand-in stage binaries (shell scripts) that write as many files as the
//! real stages do (flow files and previews, PLY + field + renders + depth maps, bindings).
//! The first run builds everything; then `degs run` is timed again and again with every
//! stage cached: resolving keys (hashing binaries is remembered by size/mtime/inode),
//! checking every entry's files against its manifest (size + mtime), and writing the
//! run record. `--verify` re-hashes every cached file with blake3.

use std::fs;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Writes `$count` files of `$kib` KiB under `$out/$dir/` for each "DIR COUNT KIB" spec;
/// accepts any settings (`settings --check` prints no file, as the real stages' do but
/// evflow's).
const STAGE: &str = r#"#!/bin/sh
stage=$(basename "$0")
[ "$1" = settings ] && { cat > /dev/null; exit 0; }
case "$stage" in evflow|gaussians|deform) shift ;; esac
out=
while [ $# -gt 0 ]; do
  case "$1" in --out) out="$2"; shift 2 ;; *) shift 2 ;; esac
done
mkdir -p "$out"
spec() {
  mkdir -p "$out/$1"
  i=0
  while [ $i -lt $2 ]; do
    head -c $(($3 * 1024)) /dev/urandom > "$out/$1/$(printf %04d $i).bin"; i=$((i+1))
  done
}
case "$stage" in
  evflow) spec flow 8 64; spec previews 24 16 ;;
  gaussians) spec model 2 2048; spec renders 8 28; spec depth 8 37 ;;
  assoc) spec . 1 512; spec preview 9 8 ;;
  deform) spec model 2 2048; spec renders 8 28 ;;
esac
echo '{"stage": "'$stage'"}' > "$out/report.json"
"#;

struct Timing {
    name: &'static str,
    runs: Vec<f64>,
}

impl Timing {
    fn sorted(&self) -> Vec<f64> {
        let mut v = self.runs.clone();
        v.sort_by(f64::total_cmp);
        v
    }
    fn median(&self) -> f64 {
        let v = self.sorted();
        v[v.len() / 2]
    }
}

fn degs(args: &[&str], cache: &Path, stages: &Path) -> f64 {
    let t = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_degs"))
        .args(args)
        .arg("--cache")
        .arg(cache)
        .arg("--stages")
        .arg(stages)
        .output()
        .unwrap();
    let s = t.elapsed().as_secs_f64();
    assert!(
        out.status.success(),
        "degs {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    s
}

fn actions(cache: &Path) -> Vec<String> {
    let v: serde_json::Value =
        serde_json::from_slice(&fs::read(cache.join("runs/bench/run.json")).unwrap()).unwrap();
    v["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["action"].as_str().unwrap().to_string())
        .collect()
}

fn results_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../target"));
    target.join("bench-results")
}

fn main() {
    let reps: usize = std::env::var("DEGS_BENCH_REPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(10);
    let dir = tempfile::tempdir().unwrap();
    let stages = dir.path().join("bin");
    fs::create_dir_all(&stages).unwrap();
    for s in ["evflow", "gaussians", "assoc", "deform"] {
        let p = stages.join(s);
        fs::write(&p, STAGE).unwrap();
        fs::set_permissions(&p, fs::Permissions::from_mode(0o755)).unwrap();
    }
    // The scene is real: this build's `synth` writes it.
    let synth = Path::new(env!("CARGO_BIN_EXE_degs")).with_file_name("synth");
    assert!(
        synth.is_file(),
        "{}: build the workspace's binaries first",
        synth.display()
    );
    std::os::unix::fs::symlink(&synth, stages.join("synth")).unwrap();
    let exp = dir.path().join("bench.toml");
    fs::write(
        &exp,
        "name = \"bench\"\n[scene]\nsynth = \"rigid\"\n[scene.settings]\nwidth = 96\n\
         height = 96\n[evflow]\nepochs = 1\n[gaussians]\niterations = 1500\n",
    )
    .unwrap();
    let cache = dir.path().join("cache-root");
    let e = exp.to_str().unwrap();

    let first = degs(&["run", e, "--quiet"], &cache, &stages);
    assert!(actions(&cache).iter().skip(1).all(|a| a == "ran"));
    let (mut files, mut bytes) = (0usize, 0u64);
    for stage in ["synth", "evflow", "gaussians", "assoc", "deform"] {
        for entry in fs::read_dir(cache.join("cache").join(stage))
            .unwrap()
            .flatten()
        {
            let m = runner::cache::read_manifest(&entry.path()).unwrap();
            files += m.files.len();
            bytes += m.files.iter().map(|f| f.size).sum::<u64>();
        }
    }

    let mut timings = vec![
        Timing {
            name: "degs run (all cached)",
            runs: vec![],
        },
        Timing {
            name: "degs run --verify (re-hash all)",
            runs: vec![],
        },
        Timing {
            name: "degs status",
            runs: vec![],
        },
    ];
    for _ in 0..reps {
        timings[0]
            .runs
            .push(degs(&["run", e, "--quiet"], &cache, &stages));
        assert!(
            actions(&cache).iter().all(|a| a == "cached"),
            "a cached run ran a stage: {:?}",
            actions(&cache)
        );
        timings[1]
            .runs
            .push(degs(&["run", e, "--quiet", "--verify"], &cache, &stages));
        timings[2].runs.push(degs(&["status", e], &cache, &stages));
    }

    println!(
        "cached degs run: 5 stages, {files} cached files, {:.1} MiB; first (building) run {first:.2} s; {reps} repetitions\n",
        bytes as f64 / (1 << 20) as f64
    );
    println!(
        "| {:<32} | {:>9} | {:>9} | {:>9} |",
        "command", "min ms", "median ms", "max ms"
    );
    println!("|{:-<34}|{:->11}|{:->11}|{:->11}|", "", "", "", "");
    let mut json = Vec::new();
    for t in &timings {
        let v = t.sorted();
        println!(
            "| {:<32} | {:>9.1} | {:>9.1} | {:>9.1} |",
            t.name,
            v[0] * 1e3,
            t.median() * 1e3,
            v[v.len() - 1] * 1e3
        );
        json.push(serde_json::json!({
            "command": t.name,
            "min_s": v[0],
            "median_s": t.median(),
            "max_s": v[v.len() - 1],
            "runs_s": t.runs,
        }));
    }
    let goal_met = timings[0].median() < 1.0;
    println!(
        "\ngoal (< 1 s for a fully cached run): {}",
        if goal_met { "met" } else { "NOT met" }
    );
    let out = results_dir();
    fs::create_dir_all(&out).unwrap();
    let path = out.join("cached_run.json");
    let doc = serde_json::json!({
        "bench": "cached_run",
        "stages": 5,
        "cached_files": files,
        "cached_bytes": bytes,
        "first_run_s": first,
        "repetitions": reps,
        "timings": json,
        "goal_s": 1.0,
        "goal_met": goal_met,
    });
    fs::write(&path, serde_json::to_string_pretty(&doc).unwrap()).unwrap();
    println!("wrote {}", path.display());
}
