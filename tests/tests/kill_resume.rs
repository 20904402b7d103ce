//! A run killed with SIGKILL at seeded points leaves the cache consistent, and the next
//! `degs run` resumes and ends with the same keys and the same output bytes as a run
//! that was never interrupted (docs/DESIGN.md "Inputs that cannot hurt").
//!
//! The scene is the tiny synthetic one of `degs_run.rs`, smaller still. A reference run
//! goes through uninterrupted in its own cache; then, in a second cache, one killed run
//! per stage, in pipeline order: each waits until that stage's process runs and kills a
//! seeded fraction (under half) of the stage's reference wall time later, in turn: the
//! whole process group (the runner and its stage at once, as a lost machine would),
//! only the running stage process (the runner records the failure), only the runner
//! (its stage dies with it). After each kill the stage's entry must not be sealed (the
//! kill landed inside it) and every sealed entry must verify; the last run goes to the
//! end.

use degs_tests::{Workspace, entry, stage_record, stderr};
use runner::cache::{self, Cache, Verdict};
use std::collections::BTreeMap;
use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Child, Command};
use std::time::Duration;

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

/// Every sealed entry of the cache verifies against its manifest (full re-hash); the
/// run record, when there is one, is readable.
fn assert_consistent(w: &Workspace, when: &str) {
    for (stage, key, dir) in Cache::new(&w.cache).entries() {
        let v = cache::verify(&dir, true);
        assert_eq!(v, Verdict::Ok, "{when}: {stage}/{key}: {v:?}");
    }
    let record = w.cache.join("runs/resume/run.json");
    if record.exists() {
        runner::record::RunRecord::read(&record).unwrap_or_else(|e| panic!("{when}: {e:#}"));
    }
}

/// How each stage's run is killed: the process group, the runner only (its stage dies
/// with it), or the stage only. The stage-only kills come where the runner has nothing
/// left to run without the killed stage (after evflow it would go on with gaussians).
const MODES: [Kill; 5] = [
    Kill::Group,
    Kill::Runner,
    Kill::Stage,
    Kill::Group,
    Kill::Stage,
];

#[derive(Clone, Copy, Debug)]
enum Kill {
    Group,
    Runner,
    Stage,
}

/// The stage (binary, verb) a process runs, from its command line: `degs synth`, or
/// a stage binary.
fn stage_of(pid: &str) -> Option<String> {
    let cmd = std::fs::read(format!("/proc/{pid}/cmdline")).ok()?;
    let mut args = cmd
        .split(|&b| b == 0)
        .map(|a| String::from_utf8_lossy(a).to_string());
    let bin = Path::new(&args.next()?)
        .file_name()?
        .to_string_lossy()
        .to_string();
    match (bin.as_str(), args.next().as_deref()) {
        ("degs", Some("synth")) => Some("synth".into()),
        // The runner asking a stage binary about its settings is not the stage running.
        (_, Some("settings")) => None,
        (b, _) if STAGES.contains(&b) => Some(b.to_string()),
        _ => None,
    }
}

/// Wait until the runner runs `stage` (its process a child of the runner); false when
/// the runner ended first.
fn wait_for_stage(runner: &mut Child, stage: &str) -> Option<String> {
    while runner.try_wait().unwrap().is_none() {
        if let Some(p) = children(runner.id())
            .into_iter()
            .find(|p| stage_of(p).as_deref() == Some(stage))
        {
            return Some(p);
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    None
}

/// Stop process `pid` (SIGSTOP) and say whether it is stopped: alive, inside its work.
fn freeze(pid: &str) -> bool {
    let _ = Command::new("kill").args(["-STOP", pid]).status();
    for _ in 0..200 {
        let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
        match stat
            .rsplit(')')
            .next()
            .and_then(|r| r.trim_start().chars().next())
        {
            Some('T' | 't') => return true,
            Some('Z' | 'X') | None => return false,
            _ => std::thread::sleep(Duration::from_millis(1)),
        }
    }
    false
}

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
    for (i, (stage, f)) in STAGES.into_iter().zip(fractions(18, 5)).enumerate() {
        // A seeded point within the first 30 % of the stage's reference wall time.
        let wall = stage_record(&want, stage)["wall_s"].as_f64().unwrap();
        let mut child = spawn_run(&w, &exp);
        let pid = wait_for_stage(&mut child, stage).unwrap_or_else(|| {
            panic!(
                "kill {i}: the run ended before {stage} started: {}",
                std::fs::read_to_string(w.cache.join("runs/resume/run.json")).unwrap_or_default()
            )
        });
        // A stage of a few milliseconds (`assoc` here: 8.6 ms) may end within a point a
        // millisecond or two in, on a faster run than the reference (CI saw it): under
        // 10 ms it is stopped where it was found, inside it all the same.
        let delay = f * wall;
        if delay >= 0.01 {
            std::thread::sleep(Duration::from_secs_f64(delay));
        }
        // Stopped first, so the kill lands inside the stage, whatever the machine's speed.
        let when = format!(
            "kill {i} ({:?}) in {stage} at {:.1} of {:.1} ms",
            MODES[i],
            1e3 * f * wall,
            1e3 * wall
        );
        assert!(freeze(&pid), "{when}: {stage} had already ended");
        match MODES[i] {
            Kill::Group => sigkill(&format!("-{}", child.id())),
            Kill::Stage => sigkill(&pid),
            Kill::Runner => sigkill(&child.id().to_string()),
        }
        // The runner, when only its stage was killed, records the failure and stops.
        let status = child.wait().unwrap();
        let when = format!("{when} ({status})");
        assert_consistent(&w, &when);
        let key = stage_record(&want, stage)["key"]
            .as_str()
            .unwrap()
            .to_string();
        let sealed = w.cache.join("cache").join(stage).join(&key);
        assert!(
            cache::verify(&sealed, false) != Verdict::Ok,
            "{when}: {stage} was sealed: the kill did not land inside it"
        );
    }

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
