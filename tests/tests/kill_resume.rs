//! A run killed with SIGKILL at seeded points leaves the cache consistent, and the next
//! `degs run` resumes and ends with the same keys and the same output bytes as a run
//! that was never interrupted (docs/DESIGN.md "Inputs that cannot hurt").
//!
//! The scene is the tiny synthetic one of `degs_run.rs`, smaller still. A reference run
//! goes through uninterrupted in its own cache; then, in a second cache, runs are killed
//! seeded fractions of the reference's wall time after their first stage started, in
//! turn: the whole process
//! group (the runner and its stage at once, as a lost machine would), only the running
//! stage process (the runner records the failure), only the runner (its stage dies with
//! it). After each kill every sealed entry must verify; the last run goes to the end.

use degs_tests::{Workspace, entry, stage_record, stderr};
use pipeline::cache::{self, Cache, Verdict};
use std::collections::BTreeMap;
use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Child, Command};
use std::time::{Duration, Instant};

const EXPERIMENT: &str = r#"
name = "resume"

[scene]
synth = "rigid"

[scene.settings]
width = 24
height = 24
duration = 0.2
render_rate_hz = 200
test_frames = 2
supersample = 1

[evflow]
epochs = 1
previews = false

[gaussians]
iterations = 120
static_iterations = 60
init_points = 300
sh_degree = 0

[gaussians.field]
width = 8
depth = 2

[gaussians.densify]
from_iter = 40
interval = 40
until_iter = 100

[deform]
iterations = 20
rebind_every = 10
log_every = 5
"#;

const STAGES: [&str; 5] = ["synth", "evflow", "gaussians", "assoc", "deform"];

/// Files that record how long a run took (wall times, peak memory, dates), which no two
/// runs share; every other output file must be byte-identical.
fn records_timing(rel: &str) -> bool {
    rel == "report.json" || rel == cache::MANIFEST
}

/// blake3 of every output file of every stage of a finished run, by `stage/relative path`.
fn outputs(record: &serde_json::Value) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for stage in STAGES {
        let dir = entry(record, stage);
        for rel in cache::list_files(&dir).unwrap() {
            let rel_text = rel.to_string_lossy().to_string();
            if !records_timing(&rel_text) {
                let hash = cache::hash_file(&dir.join(&rel)).unwrap();
                out.insert(format!("{stage}/{rel_text}"), hash);
            }
        }
    }
    out
}

/// `degs run` in a process group of its own, so one signal reaches the runner and its
/// stage.
fn spawn_run(w: &Workspace, exp: &Path) -> Child {
    let mut cmd = Command::new(degs_tests::binary("degs"));
    cmd.args(["run", exp.to_str().unwrap(), "-j", "1", "--quiet"])
        .arg("--cache")
        .arg(&w.cache)
        .arg("--stages")
        .arg(degs_tests::bin_dir())
        .env_remove("DEGS_CACHE")
        .env_remove("DEGS_STAGE_DIR")
        .env_remove("EVFLOW_WEIGHTS")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .process_group(0);
    cmd.spawn().expect("start degs")
}

fn sigkill(target: &str) {
    let status = Command::new("kill")
        .args(["-KILL", "--", target])
        .status()
        .expect("run kill");
    // A process that already ended cannot be killed: not an error here.
    let _ = status;
}

/// Process ids of the children of `pid` (the stage the runner is running), over all
/// its threads (a stage is the child of the thread that started it).
fn children(pid: u32) -> Vec<String> {
    let tasks = std::fs::read_dir(format!("/proc/{pid}/task"))
        .into_iter()
        .flatten();
    tasks
        .flatten()
        .flat_map(|t| {
            std::fs::read_to_string(t.path().join("children"))
                .unwrap_or_default()
                .split_whitespace()
                .map(str::to_string)
                .collect::<Vec<_>>()
        })
        .collect()
}

/// SIGKILL the stage the runner is running (waiting for the next one to start when
/// the runner is between stages).
fn kill_stage(runner: &mut Child) {
    while runner.try_wait().unwrap().is_none() {
        let stages = children(runner.id());
        if !stages.is_empty() {
            stages.iter().for_each(|p| sigkill(p));
            return;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Every sealed entry of the cache verifies against its manifest (full re-hash); the
/// run record, when there is one, is readable.
fn assert_consistent(w: &Workspace, when: &str) {
    for (stage, key, dir) in Cache::new(&w.cache).entries() {
        let v = cache::verify(&dir, true);
        assert_eq!(v, Verdict::Ok, "{when}: {stage}/{key}: {v:?}");
    }
    let record = w.cache.join("runs/resume/run.json");
    if record.exists() {
        pipeline::record::RunRecord::read(&record).unwrap_or_else(|e| panic!("{when}: {e:#}"));
    }
}

/// Seeded fractions in [0, 0.3) (SplitMix64): each killed run is killed this share of
/// [`KILL_WINDOW`] after its first stage started, so the kill lands while that stage
/// (and every stage after it) is still to finish, whatever the machine's speed.
const KILL_WINDOW: Duration = Duration::from_millis(100);

fn fractions(seed: u64, n: usize) -> Vec<f64> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = s;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            0.3 * (z >> 11) as f64 / (1u64 << 53) as f64
        })
        .collect()
}

#[test]
fn runs_killed_at_seeded_points_resume_to_the_uninterrupted_result() {
    let reference = Workspace::new();
    let exp = reference.experiment("resume", EXPERIMENT);
    let out = reference.degs(&["run", exp.to_str().unwrap(), "-j", "1", "--quiet"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let want = reference.run_record("resume");
    let want_outputs = outputs(&want);
    assert!(want_outputs.keys().any(|k| k.starts_with("deform/")));

    let w = Workspace::new();
    let exp = w.experiment("resume", EXPERIMENT);
    let mut kills = 0;
    for (i, f) in fractions(18, 5).into_iter().enumerate() {
        let mut child = spawn_run(&w, &exp);
        // From the start of its first stage (hashing binaries and cache checks come
        // before), so the kill lands while work is left.
        while children(child.id()).is_empty() && child.try_wait().unwrap().is_none() {
            std::thread::sleep(Duration::from_millis(2));
        }
        let deadline = Instant::now() + KILL_WINDOW.mul_f64(f);
        while Instant::now() < deadline && child.try_wait().unwrap().is_none() {
            std::thread::sleep(Duration::from_millis(10));
        }
        if child.try_wait().unwrap().is_none() {
            kills += 1;
            match i % 3 {
                0 => sigkill(&format!("-{}", child.id())),
                1 => kill_stage(&mut child),
                // the stage dies with it (PR_SET_PDEATHSIG)
                _ => sigkill(&child.id().to_string()),
            }
        }
        // The runner, when only its stage was killed, records the failure and stops.
        let status = child.wait().unwrap();
        assert_consistent(
            &w,
            &format!("after kill {i} at {:.0}% ({status})", 100.0 * f),
        );
    }
    assert!(
        kills >= 3,
        "only {kills} of 5 runs were still running when killed"
    );

    let out = w.degs(&["run", exp.to_str().unwrap(), "-j", "1", "--quiet"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_consistent(&w, "after the last run");
    let got = w.run_record("resume");
    assert_eq!(got["status"], "ok", "{got}");
    for stage in STAGES {
        assert_eq!(
            stage_record(&got, stage)["key"],
            stage_record(&want, stage)["key"],
            "{stage}"
        );
    }
    let got_outputs = outputs(&got);
    assert_eq!(
        got_outputs.keys().collect::<Vec<_>>(),
        want_outputs.keys().collect::<Vec<_>>()
    );
    let differ: Vec<&String> = got_outputs
        .iter()
        .filter(|(k, h)| want_outputs[*k] != **h)
        .map(|(k, _)| k)
        .collect();
    assert!(
        differ.is_empty(),
        "outputs differ from the uninterrupted run: {differ:?}"
    );
    // nothing half-written is left behind
    let mut temps = Vec::new();
    for (stage, _, _) in Cache::new(&w.cache).entries() {
        for e in std::fs::read_dir(w.cache.join("cache").join(&stage))
            .unwrap()
            .flatten()
        {
            if e.file_name()
                .to_string_lossy()
                .contains(scene::atomic::TEMP_SUFFIX)
            {
                temps.push(e.path());
            }
        }
    }
    assert!(temps.is_empty(), "{temps:?}");
}
