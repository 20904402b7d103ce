//! Outputs never destroy inputs (issue #29 §1): `degs import` and `degs synth` refuse an
//! output folder that is or holds the source, or that holds anything that is not an
//! earlier output of the same command; an earlier output is replaced only with
//! `--force`. Every case checks the bytes of what must survive, file by file.

mod common;
use common::{degs, stderr};
use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::Output;

/// Every file under `dir` with its bytes.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    fs::read(&p).unwrap(),
                );
            }
        }
    }
    out
}

/// A small ECD recording at `dir/name` (a tiny synthetic scene exported to the layout).
fn ecd_recording(dir: &Path, name: &str) -> PathBuf {
    let cfg = synth::SynthConfig {
        width: 24,
        height: 16,
        duration: 0.25,
        train_fps: 8.0,
        test_frames: 2,
        novel_angle_deg: 0.0,
        render_rate_hz: 200.0,
        frame_supersample: 1,
        supersample: 1,
        ..synth::SynthConfig::preset("rigid").unwrap()
    };
    let scene_dir = dir.join(format!("{name}-scene"));
    synth::write_synthetic_scene(&cfg, &scene_dir).unwrap();
    let scene = scene::Scene::open(&scene_dir).unwrap();
    let rec = dir.join(name);
    import::ecd::export_ecd(&scene, &[], &rec).unwrap();
    fs::remove_dir_all(&scene_dir).unwrap();
    // A file of the user's own beside the recording's.
    fs::write(rec.join("notes.txt"), "my notes").unwrap();
    rec
}

fn import(src: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "import",
        "ecd",
        src.to_str().unwrap(),
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    args.extend_from_slice(&["--test-every", "2"]);
    degs(&args)
}

#[test]
fn import_into_its_own_source_is_refused_and_the_source_kept() {
    let d = tempfile::tempdir().unwrap();
    let rec = ecd_recording(d.path(), "rec");
    let before = snapshot(&rec);
    for extra in [&[][..], &["--force"][..]] {
        let o = import(&rec, &rec, extra);
        assert!(!o.status.success());
        let e = stderr(&o);
        assert!(
            e.contains(rec.to_str().unwrap()) && e.contains("is the input"),
            "{e}"
        );
        assert_eq!(snapshot(&rec), before, "the source changed");
    }
}

#[test]
fn import_into_a_parent_of_the_source_is_refused_and_the_parent_kept() {
    let d = tempfile::tempdir().unwrap();
    let parent = d.path().join("parent");
    fs::create_dir(&parent).unwrap();
    let rec = ecd_recording(&parent, "rec");
    fs::write(parent.join("other.txt"), "other").unwrap();
    let before = snapshot(&parent);
    for extra in [&[][..], &["--force"][..]] {
        let o = import(&rec, &parent, extra);
        assert!(!o.status.success());
        let e = stderr(&o);
        assert!(e.contains("holds the input"), "{e}");
        assert_eq!(snapshot(&parent), before, "the parent changed");
    }
    // Also through a path that names the parent another way (`rec/..`).
    let o = import(&rec, &rec.join(".."), &["--force"]);
    assert!(!o.status.success(), "{}", stderr(&o));
    assert_eq!(snapshot(&parent), before);
}

#[test]
fn import_into_a_folder_of_other_files_is_refused_even_forced() {
    let d = tempfile::tempdir().unwrap();
    let rec = ecd_recording(d.path(), "rec");
    let out = d.path().join("mine");
    fs::create_dir(&out).unwrap();
    fs::write(out.join("notes.txt"), "keep me").unwrap();
    for extra in [&[][..], &["--force"][..]] {
        let o = import(&rec, &out, extra);
        assert!(!o.status.success());
        let e = stderr(&o);
        assert!(
            e.contains(out.to_str().unwrap()) && e.contains("not an output of `degs import`"),
            "{e}"
        );
        assert_eq!(fs::read(out.join("notes.txt")).unwrap(), b"keep me");
        assert_eq!(fs::read_dir(&out).unwrap().count(), 1);
    }
    // A file where the folder should be is refused too.
    let file = d.path().join("file");
    fs::write(&file, "a file").unwrap();
    let o = import(&rec, &file, &["--force"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("not a folder"), "{}", stderr(&o));
    assert_eq!(fs::read(&file).unwrap(), b"a file");
}

#[test]
fn an_earlier_import_is_replaced_only_with_force_and_an_empty_folder_is_fine() {
    let d = tempfile::tempdir().unwrap();
    let rec = ecd_recording(d.path(), "rec");
    let src_before = snapshot(&rec);
    let out = d.path().join("scene");
    fs::create_dir(&out).unwrap(); // empty: accepted
    let o = import(&rec, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let first = snapshot(&out);
    assert!(first.contains_key(Path::new("transforms_train.json")));
    let o = import(&rec, &out, &[]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--force"), "{}", stderr(&o));
    assert_eq!(snapshot(&out), first, "a refused import changed the output");
    // Forced: replaced by a different import (every frame a train frame now).
    let o = degs(&[
        "import",
        "ecd",
        rec.to_str().unwrap(),
        out.to_str().unwrap(),
        "--force",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let second = snapshot(&out);
    assert_ne!(second, first);
    assert!(!second.contains_key(Path::new("images/test_0000.png")));
    assert_eq!(snapshot(&rec), src_before, "the source changed");
    // No temp folder left beside the output.
    let names: Vec<String> = fs::read_dir(d.path())
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.contains(".degs-tmp-")), "{names:?}");
}

#[test]
fn synth_refuses_a_folder_of_other_files_and_replaces_its_own_only_forced() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("s");
    fs::create_dir(&out).unwrap();
    fs::write(out.join("notes.txt"), "keep me").unwrap();
    let args = |force: bool| {
        let mut a = vec![
            "synth",
            "--preset",
            "static",
            "--set",
            "width=16",
            "--set",
            "height=12",
            "--set",
            "duration=0.25",
            "--out",
            out.to_str().unwrap(),
        ];
        if force {
            a.push("--force");
        }
        a
    };
    for force in [false, true] {
        let o = degs(&args(force));
        assert!(!o.status.success());
        assert!(
            stderr(&o).contains("not an output of `degs synth`"),
            "{}",
            stderr(&o)
        );
        assert_eq!(fs::read(out.join("notes.txt")).unwrap(), b"keep me");
    }
    fs::remove_file(out.join("notes.txt")).unwrap();
    let o = degs(&args(false));
    assert!(o.status.success(), "{}", stderr(&o));
    let o = degs(&args(false));
    assert!(
        !o.status.success() && stderr(&o).contains("--force"),
        "{}",
        stderr(&o)
    );
    let o = degs(&args(true));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.join("transforms_train.json").is_file());
}
