//! The `gaussians` binary's command line: `train --help` shows the defaults of the
//! settings its flags override (from `TrainSettings::default()`), and errors are one line
//! `gaussians: error: …` naming the file.

use gaussians::train::TrainSettings;
use stagekit::help::flag_help;
use std::process::Command;

fn gaussians() -> Command {
    Command::new(env!("CARGO_BIN_EXE_gaussians"))
}

#[test]
fn train_help_shows_the_settings_defaults() {
    let o = gaussians().args(["train", "--help"]).output().unwrap();
    assert!(o.status.success());
    let help = String::from_utf8_lossy(&o.stdout);
    let d = TrainSettings::default();
    for (flag, default) in [
        ("--iterations", d.iterations.to_string()),
        ("--seed", d.seed.to_string()),
        ("--field-width", d.field.width.to_string()),
        ("--field-depth", d.field.depth.to_string()),
    ] {
        let line = flag_help(&help, flag);
        assert!(line.contains(&format!("[default: {default}]")), "{line}");
    }
    assert!(flag_help(&help, "--init").contains("[default: auto]"));
}

#[test]
fn a_bad_config_is_one_error_line_naming_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = tmp.path().join("bad.toml");
    std::fs::write(&cfg, "iteratons = 3\n").unwrap();
    let o = gaussians()
        .args(["train", "--scene", "nowhere", "--out"])
        .arg(tmp.path().join("out"))
        .arg("--config")
        .arg(&cfg)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.starts_with(&format!("gaussians: error: {}: ", cfg.display()))
            && err.contains("iteratons"),
        "{err}"
    );
}
