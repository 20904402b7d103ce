//! Several runners at once: two `degs` processes on one cache build each shared entry
//! once (the cache entry's lock), and `degs sweep -J 2` runs two experiments at a time.

mod common;
use common::{Fixture, stderr};
use std::collections::BTreeMap;
use std::fs;

/// How many times each stage was started.
fn starts(f: &Fixture) -> BTreeMap<String, usize> {
    let mut m = BTreeMap::new();
    for s in f.started() {
        *m.entry(s).or_default() += 1;
    }
    m
}

/// Line numbers of the invocation log's lines that start with `prefix`.
fn positions(f: &Fixture, prefix: &str) -> Vec<usize> {
    fs::read_to_string(&f.log)
        .unwrap()
        .lines()
        .enumerate()
        .filter(|(_, l)| l.starts_with(prefix))
        .map(|(i, _)| i)
        .collect()
}

#[test]
fn two_runners_on_one_cache_build_each_shared_entry_once() {
    let f = Fixture::new();
    // The same scene, flow, warm-up and bindings; different joint trainings.
    let a = f.experiment("a", "[deform]\nseed = 1\n");
    let b = f.experiment("b", "[deform]\nseed = 2\n");
    // Every stage takes a second, so the second runner's cache check finds nothing
    // built: without the lock both would build the shared stages.
    let spawn = |exp: &std::path::Path| {
        f.command(&["run", exp.to_str().unwrap(), "-j", "2"])
            .env("DEGS_FAKE_PAUSE", "evflow gaussians assoc deform")
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (ra, rb) = (spawn(&a), spawn(&b));
    for (name, child) in [("a", ra), ("b", rb)] {
        let out = child.wait_with_output().unwrap();
        assert!(out.status.success(), "runner {name}: {}", stderr(&out));
    }
    let expected: BTreeMap<String, usize> =
        [("evflow", 1), ("gaussians", 1), ("assoc", 1), ("deform", 2)]
            .iter()
            .map(|(s, n)| (s.to_string(), *n))
            .collect();
    assert_eq!(
        starts(&f),
        expected,
        "log:\n{}",
        fs::read_to_string(&f.log).unwrap()
    );
    for stage in ["evflow", "gaussians", "assoc"] {
        let mut actions = [f.action("a", stage), f.action("b", stage)];
        actions.sort();
        assert_eq!(
            actions,
            ["cached", "ran"],
            "{stage}: one built it, one waited"
        );
        assert_eq!(f.key("a", stage), f.key("b", stage));
    }
    assert_eq!(
        (f.action("a", "deform"), f.action("b", "deform")),
        ("ran".into(), "ran".into())
    );
    // Nothing left behind but the entries and their (free) lock files, which gc removes.
    let out = f.degs(&["gc"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let leftover: Vec<_> = fs::read_dir(f.cache.join("cache/evflow"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().to_string())
        .filter(|n| n.ends_with(".lock") || n.contains(".degs-tmp-"))
        .collect();
    assert!(leftover.is_empty(), "{leftover:?}");
}

#[test]
fn sweep_j2_runs_two_experiments_at_a_time_and_j1_one() {
    for (j, overlap) in [("2", true), ("1", false)] {
        let f = Fixture::new();
        let p = f.dir.path().join("two.toml");
        fs::write(
            &p,
            format!(
                "name = \"two\"\n[base]\n[base.scene]\ndir = \"{}\"\n[axes]\n\"deform.seed\" = [1, 2]\n",
                f.scene.display()
            ),
        )
        .unwrap();
        let out = f
            .command(&["sweep", p.to_str().unwrap(), "-J", j])
            .env("DEGS_FAKE_PAUSE", "deform")
            .output()
            .unwrap();
        assert!(out.status.success(), "-J {j}: {}", stderr(&out));
        let c = starts(&f);
        assert_eq!(
            (c["evflow"], c["gaussians"], c["assoc"], c["deform"]),
            (1, 1, 1, 2)
        );
        let (starts_at, ends_at) = (positions(&f, "start deform "), positions(&f, "end deform"));
        assert_eq!((starts_at.len(), ends_at.len()), (2, 2));
        // Both joint trainings started before either ended (-J 2), or one after the
        // other (-J 1).
        assert_eq!(
            starts_at[1] < ends_at[0],
            overlap,
            "-J {j}: {starts_at:?} {ends_at:?}"
        );
        if overlap {
            let text = String::from_utf8_lossy(&out.stderr);
            assert!(
                text.contains(": deform"),
                "lines name the experiment: {text}"
            );
        }
    }
}

#[test]
fn a_running_stage_shows_its_phase_position_and_time_left() {
    // Not a terminal: a plain line per tenth of the work, and the last one in run.json.
    let f = Fixture::new();
    let exp = f.experiment("p", "");
    let out = f
        .command(&["run", exp.to_str().unwrap()])
        .env("DEGS_FAKE_PROGRESS", "gaussians")
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", stderr(&out));
    let text = stderr(&out);
    // Stage-clock 5.0 s for half of the work: 5 s left.
    assert!(
        text.contains("[degs] gaussians: iteration 5/10 (50 %), about 5 s left"),
        "{text}"
    );
    assert!(
        text.contains("[degs] gaussians: iteration 10/10 (100 %)\n"),
        "{text}"
    );
    let lines = text
        .lines()
        .filter(|l| l.contains("gaussians: iteration"))
        .count();
    assert_eq!(lines, 10, "one line per tenth: {text}");
    let rec = f.record("p");
    let g = rec["stages"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["stage"] == "gaussians")
        .unwrap();
    assert_eq!(g["progress"]["label"], "iteration");
    assert_eq!(
        (
            g["progress"]["done"].as_u64(),
            g["progress"]["total"].as_u64()
        ),
        (Some(10), Some(10))
    );
    let e = rec["stages"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["stage"] == "evflow")
        .unwrap();
    assert!(
        e.get("progress").is_none(),
        "a stage that said nothing has none: {e}"
    );
}
