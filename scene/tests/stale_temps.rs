//! Temp outputs of dead processes are removed; a killed process whose zombie nobody
//! reaps counts as dead (regression: found by `tests/tests/kill_resume.rs`, where the
//! killed runner's stage left `KEY.degs-tmp-RUNNER.degs-tmp-STAGE` behind for good because the
//! container's init did not reap it).

use scene::atomic::remove_stale_temps;
use std::fs;
use std::process::Command;

#[test]
fn temps_of_zombies_and_dead_processes_are_removed_and_live_ones_kept() {
    let dir = tempfile::tempdir().unwrap();
    // A child that exits and is not waited for: a zombie while this test runs.
    let mut zombie = Command::new("true").spawn().unwrap();
    let zpid = zombie.id();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
    loop {
        let stat = fs::read_to_string(format!("/proc/{zpid}/stat")).unwrap();
        let state = stat.rsplit(')').next().unwrap().trim_start().chars().next();
        if state == Some('Z') {
            break;
        }
        assert!(std::time::Instant::now() < deadline, "{stat}");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let mine = std::process::id();
    let zombie_temp = dir
        .path()
        .join(format!("key.degs-tmp-{mine}.degs-tmp-{zpid}"));
    let live_temp = dir.path().join("live.degs-tmp-1"); // init
    let dead_temp = dir.path().join("other.degs-tmp-4194304"); // above Linux's pid_max
    // A user's own file that merely looks like a temp name is not ours to remove.
    let users = dir.path().join("notes.tmp-4194304");
    for d in [&zombie_temp, &live_temp, &dead_temp, &users] {
        fs::create_dir_all(d).unwrap();
    }
    remove_stale_temps(dir.path()).unwrap();
    assert!(users.exists());
    assert!(!zombie_temp.exists());
    assert!(!dead_temp.exists());
    assert!(live_temp.exists());
    zombie.wait().unwrap();
}

#[test]
fn threads_writing_one_file_at_once_never_share_a_temp_file() {
    let dir = tempfile::tempdir().unwrap();
    let target = dir.path().join("record.json");
    std::thread::scope(|s| {
        for t in 0..4u8 {
            let target = &target;
            s.spawn(move || {
                for _ in 0..200 {
                    scene::atomic::write_bytes_atomic(target, &[t; 64]).unwrap();
                }
            });
        }
    });
    // One writer's whole content, and no temp file left.
    let bytes = fs::read(&target).unwrap();
    assert!(bytes.len() == 64 && bytes.iter().all(|&b| b == bytes[0]));
    assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    // A temp file of a dead process with a count is stale too; a live one's is kept.
    let dead = dir.path().join("x.degs-tmp-4194304.7");
    let live = dir
        .path()
        .join(format!("x.degs-tmp-{}.7", std::process::id()));
    let odd = dir.path().join("x.degs-tmp-4194304.notes");
    for p in [&dead, &live, &odd] {
        fs::write(p, "t").unwrap();
    }
    remove_stale_temps(dir.path()).unwrap();
    assert!(!dead.exists() && live.exists() && odd.exists());
}
