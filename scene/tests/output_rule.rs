//! What an output folder may replace ([`scene::atomic::OutputRule`]): checked at the
//! start, again at the commit, on the temp name too, and through symlinks.

use scene::atomic::{AtomicDir, OUTPUT_MARKER, OutputRule, temp_path};
use std::fs;

#[test]
fn a_user_folder_on_the_temp_name_is_kept() {
    let d = tempfile::tempdir().unwrap();
    let target = d.path().join("out");
    let tmp = temp_path(&target);
    fs::create_dir(&tmp).unwrap();
    fs::write(tmp.join("mine.txt"), "mine").unwrap();
    let e = AtomicDir::new(&target, &OutputRule::new("t"))
        .expect_err("refused")
        .to_string();
    assert!(e.contains("not a temp folder"), "{e}");
    assert_eq!(fs::read(tmp.join("mine.txt")).unwrap(), b"mine");
    assert!(!target.exists());
}

#[test]
fn a_folder_that_appeared_during_the_work_is_not_replaced_at_commit() {
    let d = tempfile::tempdir().unwrap();
    let target = d.path().join("out");
    let dir = AtomicDir::new(&target, &OutputRule::new("t").force(true)).unwrap();
    fs::write(dir.path().join("a"), "new").unwrap();
    fs::create_dir(&target).unwrap();
    fs::write(target.join("theirs.txt"), "theirs").unwrap();
    let e = dir.commit().expect_err("refused").to_string();
    assert!(e.contains("not an output of `t`"), "{e}");
    assert_eq!(fs::read(target.join("theirs.txt")).unwrap(), b"theirs");
    // The temp folder went with the refused commit.
    assert_eq!(fs::read_dir(d.path()).unwrap().count(), 1);
}

#[test]
fn an_earlier_output_is_replaced_when_forced_and_marked_with_its_command() {
    let d = tempfile::tempdir().unwrap();
    let target = d.path().join("out");
    for (i, force) in [false, true].into_iter().enumerate() {
        let dir = AtomicDir::new(&target, &OutputRule::new("cmd").force(force)).unwrap();
        fs::write(dir.path().join("n"), i.to_string()).unwrap();
        dir.commit().unwrap();
    }
    assert_eq!(fs::read_to_string(target.join("n")).unwrap(), "1");
    assert_eq!(
        fs::read_to_string(target.join(OUTPUT_MARKER)).unwrap(),
        "cmd\n"
    );
    // Another command's output is not this one's to replace.
    let e = AtomicDir::new(&target, &OutputRule::new("other").force(true))
        .expect_err("refused")
        .to_string();
    assert!(e.contains("not an output of `other`"), "{e}");
    // Nothing but the output is left beside it.
    assert_eq!(fs::read_dir(d.path()).unwrap().count(), 1);
}

#[test]
fn a_source_reached_through_a_symlink_is_seen() {
    let d = tempfile::tempdir().unwrap();
    let src = d.path().join("rec");
    fs::create_dir(&src).unwrap();
    fs::write(src.join("events.txt"), "0 1 2 1\n").unwrap();
    let link = d.path().join("link");
    std::os::unix::fs::symlink(&src, &link).unwrap();
    let rule = OutputRule::new("t").force(true).source(&link);
    assert!(rule.check(&src).is_err());
    let rule = OutputRule::new("t")
        .force(true)
        .source(src.join("events.txt"));
    let e = rule.check(&link).expect_err("refused").to_string();
    assert!(e.contains("holds the input"), "{e}");
    assert_eq!(fs::read(src.join("events.txt")).unwrap(), b"0 1 2 1\n");
}
