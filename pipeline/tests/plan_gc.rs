//! `degs plan` (commands for a batch scheduler) and `degs gc` (drop unreferenced cache
//! entries), through the `degs` binary with fake stages.

mod common;
use common::{Fixture, stdout};
use std::fs;

#[test]
fn plan_prints_runnable_commands_that_degs_run_then_adopts() {
    let f = Fixture::new();
    let exp = f.experiment("a", "[gaussians]\niterations = 10\n");
    let out = f.degs(&["plan", exp.to_str().unwrap()]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    let script = stdout(&out);
    let commands: Vec<&str> = script
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("set "))
        .collect();
    // one command per external stage, in dependency order, each with its --out
    let order: Vec<&str> = commands
        .iter()
        .map(|l| {
            l.split_whitespace()
                .next()
                .unwrap()
                .rsplit('/')
                .next()
                .unwrap()
        })
        .collect();
    assert_eq!(
        order,
        ["evflow", "gaussians", "assoc", "deform"],
        "{script}"
    );
    assert!(commands.iter().all(|c| c.contains("--out ")), "{script}");
    assert!(f.started().is_empty(), "plan runs nothing");

    // a scheduler runs the script; degs run then finds every stage done
    let sh = f.dir.path().join("plan.sh");
    fs::write(&sh, &script).unwrap();
    let ran = std::process::Command::new("bash")
        .arg(&sh)
        .env("DEGS_FAKE_LOG", &f.log)
        .output()
        .unwrap();
    assert!(ran.status.success(), "{}", common::stderr(&ran));
    assert_eq!(f.started(), ["evflow", "gaussians", "assoc", "deform"]);
    f.run_ok(&exp, &[]);
    assert_eq!(f.started().len(), 4, "degs run started no stage again");
    assert!(
        f.actions("a")
            .iter()
            .all(|(_, a)| a != "ran" && a != "failed"),
        "{:?}",
        f.actions("a")
    );

    // after that, the plan shows every stage as cached
    let again = stdout(&f.degs(&["plan", exp.to_str().unwrap()]));
    let cached = again
        .lines()
        .filter(|l| l.starts_with("# cached: "))
        .count();
    assert_eq!(cached, 4, "{again}");
}

#[test]
fn gc_removes_exactly_the_entries_no_run_refers_to() {
    let f = Fixture::new();
    let exp = f.experiment("a", "[gaussians]\niterations = 10\n");
    f.run_ok(&exp, &[]);
    let old_gaussians = f.key("a", "gaussians");
    // the same experiment with another gaussians setting: its old gaussians, assoc and
    // deform entries are no longer referred to by any run record
    let exp = f.experiment("a", "[gaussians]\niterations = 20\n");
    f.run_ok(&exp, &[]);
    let entries = |stage: &str| {
        fs::read_dir(f.cache.join("cache").join(stage))
            .unwrap()
            .count()
    };
    assert_eq!(entries("gaussians"), 2);

    let dry = f.degs(&["gc", "--dry-run"]);
    assert!(dry.status.success());
    let text = stdout(&dry);
    let listed = |text: &str, verb: &str| {
        text.lines()
            .filter(|l| l.starts_with(verb) && l.contains('/'))
            .count()
    };
    assert_eq!(listed(&text, "would remove "), 3, "{text}");
    assert!(
        text.contains(&format!("gaussians/{old_gaussians}")),
        "{text}"
    );
    assert_eq!(entries("gaussians"), 2, "dry run removes nothing");

    let out = f.degs(&["gc"]);
    assert!(out.status.success());
    assert_eq!(listed(&stdout(&out), "removed "), 3, "{}", stdout(&out));
    for stage in ["evflow", "gaussians", "assoc", "deform"] {
        assert_eq!(entries(stage), 1, "{stage}");
    }
    assert!(
        !f.cache
            .join("cache/gaussians")
            .join(&old_gaussians)
            .exists()
    );
    // the surviving run is still fully cached
    f.run_ok(&exp, &[]);
    assert!(f.actions("a").iter().all(|(_, a)| a == "cached"));
}
