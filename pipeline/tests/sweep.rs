//! `degs sweep`, `degs plan` on a sweep (shell, Snakemake, Slurm) and `degs chart`,
//! through the `degs` binary with fake stages.

mod common;
use common::{Fixture, stderr, stdout};
use serde_json::Value;
use std::collections::BTreeMap;
use std::fs;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// A sweep file over the fixture's scene directory.
fn sweep_file(f: &Fixture, name: &str, axes: &str) -> PathBuf {
    let p = f.dir.path().join(format!("{name}.toml"));
    let text = format!(
        "name = \"{name}\"\n[base]\n[base.scene]\ndir = \"{}\"\n[base.gaussians]\niterations = 10\n\
         [axes]\n{axes}",
        f.scene.display()
    );
    fs::write(&p, text).unwrap();
    p
}

fn sweep_record(f: &Fixture, name: &str) -> Value {
    let p = f.cache.join("runs").join(name).join("sweep.json");
    serde_json::from_slice(&fs::read(&p).unwrap()).unwrap()
}

/// How many times each stage was started.
fn starts(f: &Fixture) -> BTreeMap<String, usize> {
    let mut m = BTreeMap::new();
    for s in f.started() {
        *m.entry(s).or_default() += 1;
    }
    m
}

fn counts(pairs: &[(&str, usize)]) -> BTreeMap<String, usize> {
    pairs.iter().map(|(s, n)| (s.to_string(), *n)).collect()
}

#[test]
fn a_sweep_over_a_deform_setting_computes_every_shared_stage_once() {
    let f = Fixture::new();
    let p = f.dir.path().join("tiny.toml");
    fs::write(
        &p,
        "name = \"tiny\"\n[base.scene]\nsynth = \"rigid\"\n[base.scene.settings]\nwidth = 24\n\
         height = 16\nduration = 0.25\nrender_rate_hz = 200\nsupersample = 1\n\
         [axes]\n\"deform.iterations\" = [1, 2, 3]\n",
    )
    .unwrap();
    let out = f.degs(&["sweep", p.to_str().unwrap(), "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(
        starts(&f),
        counts(&[("assoc", 1), ("deform", 3), ("evflow", 1), ("gaussians", 1)])
    );
    let r = sweep_record(&f, "tiny");
    assert_eq!(r["status"], "ok");
    let names: Vec<&str> = r["experiments"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "tiny_iterations-1",
            "tiny_iterations-2",
            "tiny_iterations-3"
        ]
    );
    // synth, evflow, gaussians, assoc once; deform three times
    assert_eq!(r["stages_run"], 7);
    for e in r["entries"].as_array().unwrap() {
        let used = e["used_by"].as_array().unwrap().len();
        let want = if e["stage"] == "deform" { 1 } else { 3 };
        assert_eq!(used, want, "{e}");
        assert!(
            e["ran_in"].is_string(),
            "each entry was built by this sweep: {e}"
        );
    }
    // the run records say so: the later experiments found the shared stages cached
    assert_eq!(f.action("tiny_iterations-2", "synth"), "cached");
    assert_eq!(f.action("tiny_iterations-3", "evflow"), "cached");
    assert_eq!(f.action("tiny_iterations-3", "deform"), "ran");
    assert_eq!(
        f.key("tiny_iterations-1", "gaussians"),
        f.key("tiny_iterations-3", "gaussians")
    );
    // each experiment is a plain experiment file degs run takes
    let exp = f.cache.join("runs/tiny/tiny_iterations-2.toml");
    let text = fs::read_to_string(&exp).unwrap();
    assert!(text.contains("iterations = 2"), "{text}");
    f.run_ok(&exp, &[]);
    assert!(
        f.actions("tiny_iterations-2")
            .iter()
            .all(|(_, a)| a == "cached")
    );

    // running the finished sweep again runs nothing
    let out = f.degs(&["sweep", p.to_str().unwrap(), "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(sweep_record(&f, "tiny")["stages_run"], 0);
    assert_eq!(f.started().len(), 6);
    assert!(
        stdout(&out).contains("nothing (all cached)"),
        "{}",
        stdout(&out)
    );
}

#[test]
fn an_interrupted_sweep_resumes_where_it_stopped() {
    let f = Fixture::new();
    let p = sweep_file(&f, "resume", "\"deform.iterations\" = [1, 2]\n");
    let mut child = f
        .command(&["sweep", p.to_str().unwrap(), "--quiet"])
        .env("DEGS_FAKE_SLEEP", "deform")
        .spawn()
        .unwrap();
    let deform_dir = f.cache.join("cache/deform");
    let deadline = Instant::now() + Duration::from_secs(60);
    while !fs::read_dir(&deform_dir)
        .into_iter()
        .flatten()
        .flatten()
        .any(|e| e.path().join("partial.txt").exists())
    {
        assert!(Instant::now() < deadline, "deform never started");
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap(); // SIGKILL in the first experiment's deform
    child.wait().unwrap();
    assert_eq!(sweep_record(&f, "resume")["status"], "running");

    let out = f.degs(&["sweep", p.to_str().unwrap(), "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    // the shared stages ran once in all; deform once killed, then once per experiment
    assert_eq!(
        starts(&f),
        counts(&[("assoc", 1), ("deform", 3), ("evflow", 1), ("gaussians", 1)])
    );
    let r = sweep_record(&f, "resume");
    assert_eq!(r["status"], "ok");
    assert_eq!(r["stages_run"], 2);
    let evflow = r["entries"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["stage"] == "evflow")
        .unwrap();
    assert!(evflow["ran_in"].is_null(), "cached before the resumed run");
    assert!(evflow["built_wall_s"].as_f64().unwrap() > 0.0);
    assert!(f.temp_paths().is_empty(), "{:?}", f.temp_paths());
}

/// The rules of a Snakefile: name → (named inputs, output).
fn snake_rules(text: &str) -> BTreeMap<String, (BTreeMap<String, String>, String)> {
    let mut rules = BTreeMap::new();
    let mut lines = text.lines().peekable();
    let unquote =
        |s: &str| -> String { serde_json::from_str(s.trim().trim_end_matches(',')).unwrap() };
    while let Some(l) = lines.next() {
        let Some(name) = l.strip_prefix("rule ").and_then(|r| r.strip_suffix(':')) else {
            continue;
        };
        let (mut inputs, mut output, mut section) = (BTreeMap::new(), String::new(), "");
        while let Some(l) = lines.next_if(|l| l.starts_with(' ')) {
            let t = l.trim();
            if t.ends_with(':') && !t.contains('"') {
                section = if t == "input:" {
                    "input"
                } else if t == "output:" {
                    "output"
                } else {
                    ""
                };
            } else if section == "input" && !t.starts_with('#') {
                let (k, v) = t.split_once('=').unwrap_or(("", t));
                inputs.insert(k.to_string(), unquote(v));
            } else if section == "output" {
                let inner = t.trim_start_matches("directory(").trim_end_matches(')');
                output = unquote(inner);
            }
        }
        rules.insert(name.to_string(), (inputs, output));
    }
    rules
}

/// A fake `sbatch`: runs every task of the array at once, in order, logs
/// `level tasks dependency` and prints a job id.
const FAKE_SBATCH: &str = r#"#!/bin/bash
array=; dep=none; rest=()
for a in "$@"; do
  case "$a" in
    --array=*) array=${a#--array=} ;;
    --dependency=*) dep=${a#--dependency=} ;;
    --*) ;;
    *) rest+=("$a") ;;
  esac
done
n=${array#0-}
id=$((1000 + $(wc -l < "$SBATCH_LOG" 2>/dev/null || echo 0)))
echo "${rest[2]} $((n + 1)) $dep" >> "$SBATCH_LOG"
for i in $(seq 0 "$n"); do
  SLURM_ARRAY_TASK_ID=$i bash "${rest[@]}" >&2 || exit 1
done
echo "$id"
"#;

#[test]
fn the_plan_of_a_sweep_runs_each_stage_once_in_dependency_order() {
    let f = Fixture::new();
    let p = sweep_file(
        &f,
        "grid",
        "\"deform.iterations\" = [1, 2]\n\"assoc.k\" = [2, 3]\n",
    );
    let out = f.degs(&["plan", p.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(f.started().is_empty(), "plan runs nothing");
    let script = stdout(&out);
    let commands: Vec<&str> = script
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("set "))
        .collect();
    let stage_of = |c: &str| {
        c.split_whitespace()
            .next()
            .unwrap()
            .rsplit('/')
            .next()
            .unwrap()
            .to_string()
    };
    let order: Vec<String> = commands.iter().map(|c| stage_of(c)).collect();
    assert_eq!(
        order,
        [
            "evflow",
            "gaussians",
            "assoc",
            "assoc",
            "deform",
            "deform",
            "deform",
            "deform"
        ],
        "{script}"
    );

    // Snakemake: one rule per cache entry, its inputs the outputs of the rules it needs
    let run_dir = f.cache.join("runs/grid");
    let rules = snake_rules(&fs::read_to_string(run_dir.join("Snakefile")).unwrap());
    let all = rules.get("all").cloned();
    assert!(all.is_some());
    let rules: BTreeMap<_, _> = rules.into_iter().filter(|(k, _)| k != "all").collect();
    assert_eq!(rules.len(), 8);
    let outputs: BTreeMap<String, String> = rules
        .iter()
        .map(|(name, (_, out))| (out.clone(), name.split('_').next().unwrap().to_string()))
        .collect();
    assert_eq!(outputs.len(), 8, "every output once");
    let scene = f.scene.display().to_string();
    for (name, (inputs, out)) in &rules {
        let stage = name.split('_').next().unwrap();
        assert!(out.contains(&format!("/cache/{stage}/")), "{name}: {out}");
        let want: &[(&str, &str)] = match stage {
            "evflow" | "gaussians" => &[("scene", "scene")],
            "assoc" => &[("scene", "scene"), ("model", "gaussians")],
            "deform" => &[
                ("scene", "scene"),
                ("model", "gaussians"),
                ("flows", "evflow"),
                ("assoc", "assoc"),
            ],
            other => panic!("unexpected rule {other}"),
        };
        assert_eq!(inputs.len(), want.len(), "{name}: {inputs:?}");
        for (flag, from) in want {
            let dir = &inputs[*flag];
            if *from == "scene" {
                assert_eq!(dir, &scene);
            } else {
                assert_eq!(
                    outputs.get(dir).map(String::as_str),
                    Some(*from),
                    "{name} {flag}"
                );
            }
        }
    }

    // Slurm: one array job per level, each after the previous; every stage once
    let bin = f.dir.path().join("slurm-bin");
    fs::create_dir_all(&bin).unwrap();
    fs::write(bin.join("sbatch"), FAKE_SBATCH).unwrap();
    fs::set_permissions(bin.join("sbatch"), fs::Permissions::from_mode(0o755)).unwrap();
    let sbatch_log = f.dir.path().join("sbatch.log");
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap());
    let ran = std::process::Command::new("bash")
        .arg(run_dir.join("slurm.sh"))
        .env("PATH", path)
        .env("SBATCH_LOG", &sbatch_log)
        .env("DEGS_FAKE_LOG", &f.log)
        .output()
        .unwrap();
    assert!(ran.status.success(), "{}", stderr(&ran));
    assert_eq!(
        fs::read_to_string(&sbatch_log).unwrap(),
        "0 2 none\n1 2 afterok:1000\n2 4 afterok:1001\n"
    );
    assert_eq!(
        starts(&f),
        counts(&[("assoc", 2), ("deform", 4), ("evflow", 1), ("gaussians", 1)])
    );
    let started = f.started();
    assert!(started[..2].contains(&"evflow".to_string()) && started[2..4] == ["assoc", "assoc"]);

    // degs sweep then adopts every entry and runs nothing
    let out = f.degs(&["sweep", p.to_str().unwrap(), "-q"]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(sweep_record(&f, "grid")["stages_run"], 0);
    assert_eq!(f.started().len(), 8);
    // and the next plan has nothing left to run
    let again = f.degs(&["plan", p.to_str().unwrap()]);
    assert_eq!(
        stdout(&again)
            .lines()
            .filter(|l| l.starts_with("# cached: "))
            .count(),
        8
    );
    let slurm = fs::read_to_string(run_dir.join("slurm.sh")).unwrap();
    assert!(slurm.contains("nothing to run"), "{slurm}");
    assert_eq!(
        snake_rules(&fs::read_to_string(run_dir.join("Snakefile")).unwrap()).len(),
        1
    );
}

fn fake_reports(dir: &Path) -> PathBuf {
    let r = dir.join("reports");
    fs::create_dir_all(&r).unwrap();
    for (stage, json) in [
        (
            "gaussians",
            r#"{"test": {"psnr_mean": 24.5}, "gaussians": 900, "wall_seconds": 2.0}"#,
        ),
        (
            "evflow",
            r#"{"flow_epe_px_s": 8.5, "phases": [["finetune", 1.5]], "wall_s": 2.5}"#,
        ),
        (
            "deform",
            r#"{"test": {"psnr_mean": 26.0}, "gaussians": 950, "wall_seconds": 4.0,
                "settings": {"schedule": {"gamma1": 1.0, "gamma2_max": 1.0}},
                "baselines": {"nearest": {"psnr_mean": 21.0}, "blend": {"psnr_mean": 23.0},
                              "events": {"psnr_mean": 22.0}}}"#,
        ),
    ] {
        fs::write(r.join(format!("{stage}.json")), json).unwrap();
    }
    r
}

#[test]
fn chart_draws_a_sweep_from_its_name() {
    let f = Fixture::new();
    let p = sweep_file(&f, "ch", "\"deform.iterations\" = [1, 2]\n");
    let reports = fake_reports(f.dir.path());
    let out = f
        .command(&["sweep", p.to_str().unwrap(), "-q"])
        .env("DEGS_FAKE_REPORTS", &reports)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let charts = f.dir.path().join("charts");
    let out = f.degs(&["chart", "ch", "--out", charts.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert_eq!(stdout(&out).lines().count(), 10, "{}", stdout(&out));
    for name in [
        "scene-psnr-vs-time.png",
        "scene-epe-vs-locm.svg",
        "chart.csv",
    ] {
        assert!(
            fs::metadata(charts.join(name)).unwrap().len() > 300,
            "{name}"
        );
    }
    let json: Value =
        serde_json::from_slice(&fs::read(charts.join("chart.json")).unwrap()).unwrap();
    let models = json["models"].as_array().unwrap();
    assert_eq!(
        models.len(),
        3,
        "one shared warm-up and two joint trainings"
    );
    assert_eq!(models[0]["experiments"].as_array().unwrap().len(), 2);
    assert_eq!(json["baselines"].as_array().unwrap().len(), 3);
    assert_eq!(json["flows"][0]["locm_s"], 1.5);
    // a deform point costs what its four stages cost when built
    let rec = f.record("ch_iterations-2");
    let built: f64 = rec["stages"].as_array().unwrap()[1..]
        .iter()
        .map(|s| s["built_wall_s"].as_f64().unwrap())
        .sum();
    let d2 = models
        .iter()
        .find(|m| m["experiments"][0] == "ch_iterations-2")
        .unwrap();
    assert!((d2["total_s"].as_f64().unwrap() - built).abs() < 1e-9);
    // an unknown run is an error naming it, a corrupt sweep record one naming the file
    let bad = f.degs(&["chart", "no-such-run"]);
    assert!(!bad.status.success());
    assert!(stderr(&bad).contains("no-such-run"), "{}", stderr(&bad));
    let record = f.cache.join("runs/ch/sweep.json");
    let text = fs::read_to_string(&record).unwrap();
    fs::write(&record, &text[..text.len() / 2]).unwrap();
    let bad = f.degs(&["chart", "ch", "--out", charts.to_str().unwrap()]);
    assert!(!bad.status.success());
    let err = stderr(&bad);
    assert!(
        err.contains(&record.display().to_string()) && err.contains("not a degs sweep record"),
        "{err}"
    );
    // a sweep file that is not there, or truncated, is an error naming it
    let missing = f.dir.path().join("missing.toml");
    let bad = f.degs(&["sweep", missing.to_str().unwrap()]);
    assert!(stderr(&bad).contains("missing.toml"), "{}", stderr(&bad));
    let sweep_text = fs::read_to_string(&p).unwrap();
    fs::write(&p, &sweep_text[..sweep_text.len() - 8]).unwrap();
    let bad = f.degs(&["sweep", p.to_str().unwrap()]);
    assert!(!bad.status.success());
    assert!(
        stderr(&bad).contains(p.to_str().unwrap()),
        "{}",
        stderr(&bad)
    );
}
