//! The runner and its cache, driven through the `degs` binary with fake stages.

mod common;
use common::{Fixture, stderr, stdout};
use std::fs;
use std::time::{Duration, Instant};

const ALL_RAN: [(&str, &str); 5] = [
    ("scene", "cached"),
    ("evflow", "ran"),
    ("gaussians", "ran"),
    ("assoc", "ran"),
    ("deform", "ran"),
];

fn pairs(v: &[(&str, &str)]) -> Vec<(String, String)> {
    v.iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect()
}

#[test]
fn second_run_runs_no_stage() {
    let f = Fixture::new();
    let exp = f.experiment("a", "[gaussians]\niterations = 10\n");
    f.run_ok(&exp, &[]);
    assert_eq!(f.actions("a"), pairs(&ALL_RAN));
    assert_eq!(f.started(), ["evflow", "gaussians", "assoc", "deform"]);
    let first = f.record("a");

    f.run_ok(&exp, &[]);
    let all_cached: Vec<_> = ALL_RAN.iter().map(|(s, _)| (*s, "cached")).collect();
    assert_eq!(f.actions("a"), pairs(&all_cached));
    assert_eq!(
        f.started().len(),
        4,
        "no stage process started the second time"
    );
    let second = f.record("a");
    for i in 0..5 {
        assert_eq!(first["stages"][i]["key"], second["stages"][i]["key"]);
    }
    // the record carries what the entry cost when it was built
    let built = &second["stages"][2];
    assert_eq!(built["built_wall_s"], first["stages"][2]["wall_s"]);
    assert_eq!(built["wall_s"], 0.0, "nothing ran the second time");
    assert!(built["peak_rss_kib"].as_u64().unwrap() > 0);
    assert_eq!(built["peak_rss_kib"], first["stages"][2]["peak_rss_kib"]);
    // the stage got the canonical settings and wrote into its entry
    let entry = first["stages"][2]["entry"].as_str().unwrap();
    let settings = fs::read_to_string(format!("{entry}/settings.toml")).unwrap();
    assert_eq!(settings.trim(), "iterations = 10");
    assert!(fs::metadata(format!("{entry}/.degs-entry.json")).is_ok());
    assert!(f.temp_paths().is_empty());
}

#[test]
fn stages_get_their_verbs_inputs_and_settings_file() {
    let f = Fixture::new();
    let exp = f.experiment(
        "a",
        "[evflow]\nepochs = 1\n[gaussians]\niterations = 1500\n[assoc]\nk = 3\n",
    );
    f.run_ok(&exp, &[]);
    let log = fs::read_to_string(&f.log).unwrap();
    let args = |stage: &str| -> Vec<String> {
        let line = log
            .lines()
            .find(|l| l.starts_with(&format!("start {stage} ")))
            .unwrap();
        line.split(' ').skip(2).map(str::to_string).collect()
    };
    let rec = f.record("a");
    let entry = |i: usize| rec["stages"][i]["entry"].as_str().unwrap().to_string();
    let scene = f.scene.display().to_string();
    let settings = |s: &str| {
        f.cache
            .join(format!("runs/a/{s}.settings.toml"))
            .display()
            .to_string()
    };
    let ev = args("evflow");
    assert_eq!(ev[..3], ["finetune", "--scene", scene.as_str()]);
    assert_eq!(ev[5..], ["--config", settings("evflow").as_str()]);
    let gs = args("gaussians");
    assert_eq!(gs[..3], ["train", "--scene", scene.as_str()]);
    let asc = args("assoc");
    assert_eq!(
        asc[..4],
        ["--scene", scene.as_str(), "--model", entry(2).as_str()]
    );
    assert_eq!(asc[6..], ["--config", settings("assoc").as_str()]);
    assert_eq!(args("deform")[..2], ["train", "--scene"]);
    // each stage's settings file holds exactly its experiment table
    let read = |s: &str| fs::read_to_string(settings(s)).unwrap();
    assert_eq!(read("evflow").trim(), "epochs = 1");
    assert_eq!(read("gaussians").trim(), "iterations = 1500");
    assert_eq!(read("assoc").trim(), "k = 3");
    assert_eq!(read("deform").trim(), "");
}

#[test]
fn changing_a_gaussians_setting_reruns_it_and_its_dependents_only() {
    let f = Fixture::new();
    let exp = f.experiment("a", "[evflow]\nepochs = 5\n[gaussians]\niterations = 10\n");
    f.run_ok(&exp, &[]);
    let evflow_key = f.key("a", "evflow");
    let gaussians_key = f.key("a", "gaussians");

    let exp = f.experiment("a", "[evflow]\nepochs = 5\n[gaussians]\niterations = 20\n");
    let st = stdout(&f.degs(&["status", exp.to_str().unwrap()]));
    let line = |s: &str| st.lines().find(|l| l.starts_with(s)).unwrap().to_string();
    assert!(line("evflow").contains("cached"), "{st}");
    assert!(line("gaussians").contains("stale"), "{st}");
    assert!(
        line("gaussians").contains("setting iterations changed 10 → 20"),
        "{st}"
    );
    assert!(line("assoc").contains("input gaussians changed"), "{st}");
    assert!(line("deform").contains("stale"), "{st}");

    f.run_ok(&exp, &[]);
    assert_eq!(
        f.actions("a"),
        pairs(&[
            ("scene", "cached"),
            ("evflow", "cached"),
            ("gaussians", "ran"),
            ("assoc", "ran"),
            ("deform", "ran"),
        ])
    );
    assert_eq!(f.key("a", "evflow"), evflow_key);
    assert_ne!(f.key("a", "gaussians"), gaussians_key);
    // key order and number spelling do not matter
    let exp = f.experiment("a", "[gaussians]\niterations = 20\n[evflow]\nepochs = 5\n");
    f.run_ok(&exp, &[]);
    assert!(f.actions("a").iter().all(|(_, a)| a == "cached"));
}

#[test]
fn replacing_the_flow_weights_reruns_evflow_and_its_dependents() {
    let f = Fixture::new();
    let w = f.dir.path().join("w.safetensors");
    fs::write(&w, b"weights one").unwrap();
    let body = format!("[evflow]\nweights = \"{}\"\n", w.display());
    let exp = f.experiment("a", &body);
    f.run_ok(&exp, &[]);
    let before = f.key("a", "evflow");
    let gaussians = f.key("a", "gaussians");
    // same path, same size, new content
    fs::write(&w, b"weights two").unwrap();
    f.run_ok(&exp, &[]);
    assert_eq!(f.action("a", "evflow"), "ran");
    assert_eq!(f.action("a", "gaussians"), "cached");
    assert_ne!(f.key("a", "evflow"), before);
    assert_eq!(f.key("a", "gaussians"), gaussians);
}

#[test]
fn experiments_with_the_same_flow_settings_share_one_evflow_entry() {
    let f = Fixture::new();
    let a = f.experiment(
        "a",
        "[evflow]\nlr_end = 1e-4\n[gaussians]\niterations = 10\n",
    );
    let b = f.experiment(
        "b",
        "[evflow]\nlr_end = 0.0001\n[gaussians]\niterations = 99\n",
    );
    f.run_ok(&a, &[]);
    f.run_ok(&b, &[]);
    assert_eq!(f.action("b", "evflow"), "cached");
    assert_eq!(f.action("b", "gaussians"), "ran");
    assert_eq!(f.key("a", "evflow"), f.key("b", "evflow"));
    let evflow_entries = fs::read_dir(f.cache.join("cache/evflow")).unwrap().count();
    assert_eq!(evflow_entries, 1);
    assert_eq!(f.started().iter().filter(|s| *s == "evflow").count(), 1);
}

#[test]
fn sigkill_during_a_stage_then_rerun_resumes_cleanly() {
    let f = Fixture::new();
    let exp = f.experiment("a", "");
    let mut child = f
        .command(&["run", exp.to_str().unwrap(), "--quiet"])
        .env("DEGS_FAKE_SLEEP", "gaussians")
        .spawn()
        .unwrap();
    let tmp_dir = f.cache.join("cache/gaussians");
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        let partial = fs::read_dir(&tmp_dir)
            .into_iter()
            .flatten()
            .flatten()
            .any(|e| e.path().join("partial.txt").exists());
        if partial {
            break;
        }
        assert!(Instant::now() < deadline, "gaussians never started");
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    assert!(
        !f.temp_paths().is_empty(),
        "the interrupted stage left its temp dir"
    );
    assert_eq!(f.action("a", "gaussians"), "pending");

    f.run_ok(&exp, &[]);
    assert_eq!(
        f.actions("a"),
        pairs(&[
            ("scene", "cached"),
            ("evflow", "cached"),
            ("gaussians", "ran"),
            ("assoc", "ran"),
            ("deform", "ran"),
        ])
    );
    assert!(f.temp_paths().is_empty(), "{:?}", f.temp_paths());
    let entry = f.record("a")["stages"][2]["entry"]
        .as_str()
        .unwrap()
        .to_string();
    assert_eq!(
        fs::read_to_string(format!("{entry}/result.txt")).unwrap(),
        "gaussians output\n"
    );
}

#[test]
fn a_tampered_entry_is_detected_and_rebuilt() {
    let f = Fixture::new();
    let exp = f.experiment("a", "");
    f.run_ok(&exp, &[]);
    let entry = f.record("a")["stages"][2]["entry"]
        .as_str()
        .unwrap()
        .to_string();
    let file = format!("{entry}/result.txt");
    fs::write(&file, "gaussians outpuT\n").unwrap();

    let st = stdout(&f.degs(&["status", exp.to_str().unwrap()]));
    let line = st.lines().find(|l| l.starts_with("gaussians")).unwrap();
    assert!(
        line.contains("tampered") && line.contains("result.txt"),
        "{st}"
    );
    assert!(line.contains("blake3 mismatch"), "{st}");

    f.run_ok(&exp, &[]);
    assert_eq!(f.action("a", "gaussians"), "rebuilt");
    assert_eq!(f.action("a", "assoc"), "cached");
    assert_eq!(fs::read_to_string(&file).unwrap(), "gaussians output\n");
    let st = stdout(&f.degs(&["status", exp.to_str().unwrap()]));
    assert_eq!(
        st.lines().filter(|l| l.contains(" cached ")).count(),
        4,
        "{st}"
    );
    assert!(f.temp_paths().is_empty());
}

#[test]
fn a_failing_stage_leaves_its_error_in_the_log_and_in_status() {
    let f = Fixture::new();
    let exp = f.experiment("a", "[gaussians]\nseed = 666\n");
    let out = f.degs(&["run", exp.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = stderr(&out);
    let last = err.lines().last().unwrap();
    assert!(
        last.starts_with("degs: error: stage gaussians failed"),
        "{err}"
    );
    assert!(last.contains("seed = 666 asks for a failure"), "{err}");
    assert_eq!(
        f.actions("a"),
        pairs(&[
            ("scene", "cached"),
            ("evflow", "ran"),
            ("gaussians", "failed"),
            ("assoc", "skipped"),
            ("deform", "skipped"),
        ])
    );
    let rec = f.record("a");
    assert_eq!(rec["status"], "failed");
    assert_eq!(rec["stages"][2]["exit_status"], 3);
    let log = fs::read_to_string(f.cache.join("runs/a/gaussians.log")).unwrap();
    assert!(log.contains("exit status: 3"), "{log}");
    assert!(log.contains("progress line before the failure"), "{log}");
    assert!(log.contains("seed = 666 asks for a failure"), "{log}");
    let st = stdout(&f.degs(&["status", exp.to_str().unwrap()]));
    let line = st.lines().find(|l| l.starts_with("gaussians")).unwrap();
    assert!(
        line.contains("failed") && line.contains("seed = 666 asks for a failure"),
        "{st}"
    );
    assert!(line.contains("gaussians.log"), "{st}");
    assert!(f.temp_paths().is_empty());
    assert!(
        !f.cache
            .join("cache/gaussians")
            .read_dir()
            .unwrap()
            .any(|_| true)
    );
}

#[test]
fn unknown_experiment_key_is_an_error_naming_it() {
    let f = Fixture::new();
    let exp = f.experiment("a", "[gaussians]\niterations = 1\n[deform_typo]\nx = 1\n");
    let out = f.degs(&["run", exp.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = stderr(&out);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.contains("deform_typo") && err.contains("a.toml"),
        "{err}"
    );
    assert!(!f.cache.join("runs").exists());

    // a typo inside a stage table is caught before any stage starts
    let exp = f.experiment("b", "[evflow]\nepochs = 1\n[gaussians]\niteratons = 10\n");
    for verb in ["run", "status", "plan"] {
        let out = f.degs(&[verb, exp.to_str().unwrap()]);
        assert!(!out.status.success(), "{verb}");
        let err = stderr(&out);
        assert!(
            err.contains("[gaussians]") && err.contains("iteratons") && err.contains("b.toml"),
            "{verb}: {err}"
        );
    }
    assert!(f.started().is_empty(), "no stage ran");
}

#[test]
fn until_and_force_behave_like_make() {
    let f = Fixture::new();
    let exp = f.experiment("a", "");
    f.run_ok(&exp, &["--until", "gaussians"]);
    assert_eq!(
        f.actions("a"),
        pairs(&[
            ("scene", "cached"),
            ("evflow", "not-requested"),
            ("gaussians", "ran"),
            ("assoc", "not-requested"),
            ("deform", "not-requested"),
        ])
    );
    f.run_ok(&exp, &[]);
    assert_eq!(f.action("a", "gaussians"), "cached");
    f.run_ok(&exp, &["--force", "evflow"]);
    assert_eq!(
        f.actions("a"),
        pairs(&[
            ("scene", "cached"),
            ("evflow", "ran"),
            ("gaussians", "cached"),
            ("assoc", "cached"),
            ("deform", "ran"),
        ])
    );
    let out = f.degs(&["run", exp.to_str().unwrap(), "--until", "nosuch"]);
    assert!(stderr(&out).contains("unknown stage \"nosuch\""));
}

#[test]
fn independent_stages_run_in_parallel_with_j2() {
    // evflow and gaussians each wait (up to 60 s) until the other has started: the run
    // succeeds only when they run at the same time
    let f = Fixture::new();
    let exp = f.experiment("a", "");
    let out = f
        .meeting(
            &["run", exp.to_str().unwrap(), "-j", "2"],
            "evflow gaussians",
            600,
        )
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "evflow and gaussians did not run at the same time with -j 2: {}",
        stderr(&out)
    );
    // evflow and gaussians overlap; assoc starts after gaussians ended, deform after
    // evflow ended
    let at = |prefix: &str| f.log_position(prefix);
    assert!(at("start evflow ") < at("end gaussians"));
    assert!(at("start gaussians ") < at("end evflow"));
    assert!(at("start assoc ") > at("end gaussians"));
    assert!(at("start deform ") > at("end evflow"));

    // the same meeting with -j 1: the first of the two waits in vain and fails
    let f = Fixture::new();
    let exp = f.experiment("a", "");
    let out = f
        .meeting(
            &["run", exp.to_str().unwrap(), "-j", "1"],
            "evflow gaussians",
            5,
        )
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("evflow waited in vain for gaussians"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn missing_stage_binaries_build_the_rest_and_fail_the_run() {
    let f = Fixture::new();
    fs::remove_file(f.stages.join("assoc")).unwrap();
    let exp = f.experiment("a", "");
    // the stages that can run do, and the run still fails: its result is not there
    let out = f.degs(&["run", exp.to_str().unwrap()]);
    assert!(!out.status.success(), "a run without deform exited 0");
    let err = stderr(&out);
    assert!(
        err.contains("stage assoc could not run") && err.contains("not built yet"),
        "{err}"
    );
    assert_eq!(f.record("a")["status"], "incomplete");
    assert_eq!(
        f.actions("a"),
        pairs(&[
            ("scene", "cached"),
            ("evflow", "ran"),
            ("gaussians", "ran"),
            ("assoc", "unavailable"),
            ("deform", "skipped"),
        ])
    );
    let st = stdout(&f.degs(&["status", exp.to_str().unwrap()]));
    assert!(st.contains("not built yet"), "{st}");
    assert!(st.contains("cargo build --release -p degs-assoc"), "{st}");
    assert!(
        st.lines()
            .any(|l| l.starts_with("deform") && l.contains("needs assoc")),
        "{st}"
    );
}

#[test]
fn a_rebuilt_stage_binary_invalidates_exactly_its_stage_and_dependents() {
    let f = Fixture::new();
    let exp = f.experiment("a", "");
    f.run_ok(&exp, &[]);
    let p = f.stages.join("assoc");
    let mut script = fs::read_to_string(&p).unwrap();
    script.push_str("# v2\n");
    fs::write(&p, script).unwrap();
    let st = stdout(&f.degs(&["status", exp.to_str().unwrap()]));
    assert!(st.contains("assoc binary changed"), "{st}");
    f.run_ok(&exp, &[]);
    let ran: Vec<String> = f
        .actions("a")
        .into_iter()
        .filter(|(_, a)| a == "ran")
        .map(|(s, _)| s)
        .collect();
    assert_eq!(ran, ["assoc", "deform"]);
}
