//! The runner's readers against thousands of damaged copies of a valid file
//! (`testkit::mutate`, docs/DESIGN.md "Inputs that cannot hurt"): experiment
//! files (a synthetic scene with overrides, and a scene directory), run records, cache
//! entry manifests and the remembered binary hashes.

#[global_allocator]
static ALLOC: testkit::TrackingAlloc = testkit::TrackingAlloc;

use runner::cache::{self, BinaryHashes, Cache, Verdict};
use runner::context::Context;
use runner::experiment::Experiment;
use runner::record::{Action, RunRecord, StageRecord};
use std::collections::BTreeMap;
use std::convert::Infallible;
use std::fs;
use std::path::{Path, PathBuf};
use testkit::{Plan, fuzz};

const SYNTHETIC: &str = r#"name = "tiny"

[scene]
synth = "rigid"

[scene.settings]
width = 32
height = 32
duration = 0.25
test_frames = 2
camera.sway_hz = 0.5

[evflow]
epochs = 1

[gaussians]
iterations = 200
sh_degree = 0

[gaussians.field]
width = 16
depth = 2

[deform]
iterations = 30
rebind_every = 10
"#;

/// A context whose stage directory holds no binaries: the reader is fuzzed in this
/// process; the stage tables are each stage binary's to check (`STAGE settings
/// --check`, fuzzed by the stage crates' own readers).
fn no_stage_binaries(dir: &Path) -> Context {
    Context {
        cache: Cache::new(dir.join("cache")),
        stage_dir: Some(dir.join("no-binaries")),
        degs: dir.join("degs"),
    }
}

#[test]
fn experiment_reader_synthetic_scene() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tiny.toml");
    let mut plan = Plan::new(51);
    plan.mutations = 1500;
    let ctx = no_stage_binaries(dir.path());
    fuzz(&path, SYNTHETIC.as_bytes(), &plan, |p| {
        Experiment::load_checked(p, &ctx)
    })
    .assert_clean();
}

#[test]
fn experiment_reader_scene_directory() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    // A real scene (loading the experiment checks it), small enough to read thousands
    // of times.
    let cfg: toml::Table = "width = 8\nheight = 6\nduration = 0.25\nrender_rate_hz = 40\n\
                            test_frames = 2\nsupersample = 1\nframe_supersample = 1\n"
        .parse()
        .unwrap();
    let cfg = runner::experiment::synth_config("static", &cfg).unwrap();
    synth::write_synthetic_scene(&cfg, &dir.path().join("scene")).unwrap();
    let path = dir.path().join("real.toml");
    let text = "name = \"real-1\"\n[scene]\ndir = \"scene\"\n[assoc]\nk = 3\n[deform]\nseed = 4\n";
    let ctx = no_stage_binaries(dir.path());
    fuzz(&path, text.as_bytes(), &Plan::new(52), |p| {
        Experiment::load_checked(p, &ctx)
    })
    .assert_clean();
}

fn stage(name: &str, action: Action) -> StageRecord {
    StageRecord {
        stage: name.into(),
        action,
        key: Some(format!("{name}-0123456789abcdef")),
        binary: Some(PathBuf::from(format!("/opt/degs/{name}"))),
        binary_hash: Some("ab".repeat(32)),
        settings: serde_json::json!({"iterations": 200, "field": {"width": 16}}),
        inputs: BTreeMap::from([("scene".to_string(), "synth-42".to_string())]),
        entry: Some(PathBuf::from(format!("/cache/{name}/key"))),
        wall_s: 1.25,
        built_wall_s: Some(1.25),
        peak_rss_kib: Some(20480),
        exit_status: Some(0),
        error: None,
        log: Some(PathBuf::from(format!("/cache/runs/tiny/{name}.log"))),
        progress: None,
        warnings: Vec::new(),
    }
}

#[test]
fn run_record_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.json");
    RunRecord {
        experiment: "tiny".into(),
        experiment_file: Some(PathBuf::from("/exp/tiny.toml")),
        cache_root: PathBuf::from("/cache"),
        status: "ok".into(),
        started_unix: 1_700_000_000,
        wall_s: 3.5,
        jobs: 2,
        stages: vec![
            stage("gaussians", Action::Ran),
            stage("assoc", Action::Cached),
        ],
    }
    .write(&path)
    .unwrap();
    let bytes = fs::read(&path).unwrap();
    fuzz(&path, &bytes, &Plan::new(53), RunRecord::read).assert_clean();
}

/// The verdict on an entry whose `.degs-entry.json` is damaged: never an error (a
/// damaged manifest reads as unsealed or tampered), so only panics and allocation are
/// checked here.
#[test]
fn cache_entry_manifest_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let entry = dir.path().join("entry");
    fs::create_dir_all(entry.join("renders")).unwrap();
    fs::write(entry.join("report.json"), b"{\"stage\": \"gaussians\"}").unwrap();
    fs::write(entry.join("renders/0000.png"), [7u8; 300]).unwrap();
    cache::seal(&entry, "gaussians", "key", 2.5, Some(1024)).unwrap();
    let path = entry.join(cache::MANIFEST);
    let bytes = fs::read(&path).unwrap();
    let verdict = |_: &Path| -> Result<Verdict, Infallible> { Ok(cache::verify(&entry, true)) };
    fuzz(&path, &bytes, &Plan::new(54), verdict).assert_clean();
}

#[test]
fn binary_hashes_reader() {
    let _alone = testkit::alloc::exclusive();
    let dir = tempfile::tempdir().unwrap();
    let c = Cache::new(dir.path());
    let bin = dir.path().join("gaussians");
    fs::write(&bin, b"a stage binary").unwrap();
    let mut hashes = BinaryHashes::load(&c);
    let want = hashes.hash(&bin).unwrap();
    hashes.save(&c).unwrap();
    let path = dir.path().join("cache/.binary-hashes.json");
    let bytes = fs::read(&path).unwrap();
    // A damaged file that is no longer JSON is forgotten (the binary is hashed again);
    // only panics and allocation are checked.
    let read = |_: &Path| -> Result<bool, Infallible> {
        Ok(BinaryHashes::load(&c).hash(&bin).is_ok_and(|h| h == want))
    };
    fuzz(&path, &bytes, &Plan::new(55), read).assert_clean();
}
