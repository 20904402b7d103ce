//! The scene directory's key and two runners on one cache: an edited scene file, or an
//! events file outside the scene directory that changes, rebuilds every stage; two
//! `degs run` processes on one cache both finish with the same, verified entries.

mod common;
use common::{Fixture, stderr};
use std::fs;

const STAGES: [&str; 4] = ["evflow", "gaussians", "assoc", "deform"];

fn assert_all(f: &Fixture, exp: &str, want: &str) {
    for s in STAGES {
        assert_eq!(f.action(exp, s), want, "{s}");
    }
}

/// Rewrite `path` with its own bytes: same content, a new modification time.
fn touch(path: &std::path::Path) {
    std::thread::sleep(std::time::Duration::from_millis(20));
    let bytes = fs::read(path).unwrap();
    fs::write(path, bytes).unwrap();
}

#[test]
fn an_edited_scene_file_rebuilds_every_stage() {
    let f = Fixture::new();
    let exp = f.experiment("a", "");
    f.run_ok(&exp, &[]);
    f.run_ok(&exp, &[]);
    assert_all(&f, "a", "cached");
    let before = f.key("a", "gaussians");
    touch(&f.scene.join("images/test_0000.png"));
    f.run_ok(&exp, &[]);
    assert_all(&f, "a", "ran");
    assert_ne!(f.key("a", "gaussians"), before);
}

#[test]
fn an_events_file_outside_the_scene_directory_is_part_of_its_key() {
    let f = Fixture::new();
    // The scene's events moved beside the scene directory, the manifest pointing there.
    let outside = f.dir.path().join("events.evs");
    fs::rename(f.scene.join("events.evs"), &outside).unwrap();
    let manifest = f.scene.join("transforms_train.json");
    let mut m: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(&manifest).unwrap()).unwrap();
    m["events"]["path"] = "../events.evs".into();
    fs::write(&manifest, serde_json::to_string_pretty(&m).unwrap()).unwrap();
    let exp = f.experiment("a", "");
    f.run_ok(&exp, &[]);
    f.run_ok(&exp, &[]);
    assert_all(&f, "a", "cached");
    touch(&outside);
    f.run_ok(&exp, &[]);
    assert_all(&f, "a", "ran");
}

#[test]
fn two_runners_on_one_cache_finish_with_the_same_verified_entries() {
    let f = Fixture::new();
    let exp = f.experiment("a", "");
    let spawn = || {
        f.command(&["run", exp.to_str().unwrap(), "--quiet"])
            .spawn()
            .unwrap()
    };
    let (mut one, mut two) = (spawn(), spawn());
    let (s1, s2) = (one.wait().unwrap(), two.wait().unwrap());
    assert!(s1.success() && s2.success(), "{s1:?} {s2:?}");
    // The entries the record names are complete and unchanged.
    let o = f.degs(&["status", exp.to_str().unwrap(), "--verify"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let status = String::from_utf8_lossy(&o.stdout).to_string();
    for s in STAGES {
        let line = status
            .lines()
            .find(|l| l.split_whitespace().next() == Some(s))
            .unwrap_or_else(|| panic!("no {s} in\n{status}"));
        assert!(line.contains("cached"), "{line}\n{status}");
    }
    assert!(f.temp_paths().is_empty(), "{:?}", f.temp_paths());
    // One entry per stage, and a third run builds nothing.
    for s in STAGES {
        let n = fs::read_dir(f.cache.join("cache").join(s)).unwrap().count();
        assert_eq!(n, 1, "{s}: {n} entries");
    }
    f.run_ok(&exp, &[]);
    assert_all(&f, "a", "cached");
}
