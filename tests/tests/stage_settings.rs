//! Each stage binary is the authority on its settings: `degs` asks it (`STAGE settings
//! --defaults`, `STAGE settings --check`) for `degs config show`, the check of an
//! experiment's tables and the files outside the graph that enter a stage's key.

use degs_tests::{bin_dir, binary};
use runner::cache::Cache;
use runner::context::Context;
use runner::experiment::Experiment;
use runner::settings::defaults;
use std::path::Path;
use toml::Value;

fn ctx(dir: &Path) -> Context {
    Context {
        cache: Cache::new(dir.join("cache")),
        stage_dir: Some(bin_dir()),
        degs: binary("degs"),
    }
}

fn parse(text: &str) -> Experiment {
    Experiment::parse(text, Path::new("/exp/a.toml")).unwrap()
}

#[test]
fn every_known_stage_has_defaults() {
    let defaults = |s: &str| defaults(&binary(s)).unwrap();
    let g = defaults("gaussians");
    assert_eq!(g.get("iterations"), Some(&Value::Integer(3500)));
    assert!(g["field"].is_table());
    let e = defaults("evflow");
    assert_eq!(e.get("epochs"), None, "the stopping rule by default");
    assert_eq!(e["stop"].get("min_steps"), Some(&Value::Integer(10)));
    assert_eq!(defaults("assoc").get("k"), Some(&Value::Integer(3)));
    // 0: by the train frames' interval (`DeformSettings::iterations_for`)
    assert_eq!(
        defaults("deform").get("iterations"),
        Some(&Value::Integer(0))
    );
}

#[test]
fn unknown_stage_keys_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let ctx = ctx(dir.path());
    let e = parse("name = \"a\"\n[scene]\nsynth = \"rigid\"\n[gaussians]\niters = 10\n");
    let msg = e.check_stage_settings(&ctx).unwrap_err().to_string();
    assert!(
        msg.contains("iters") && msg.contains("[gaussians]") && msg.contains("/exp/a.toml"),
        "{msg}"
    );
    let e = parse("name = \"a\"\n[scene]\nsynth = \"rigid\"\n[assoc]\nk = \"three\"\n");
    assert!(e.check_stage_settings(&ctx).is_err());
    let e = parse(
        "name = \"a\"\n[scene]\nsynth = \"rigid\"\n[gaussians]\niterations = 10\n\
         [gaussians.field]\nwidth = 32\n[deform]\nanything = 1\n",
    );
    let err = e.check_stage_settings(&ctx).unwrap_err().to_string();
    assert!(
        err.contains("[deform]") && err.contains("anything"),
        "{err}"
    );
    // A value the stage's own rules refuse (not only an unknown key or a wrong type).
    let e = parse("name = \"a\"\n[scene]\nsynth = \"rigid\"\n[assoc]\nk = 0\n");
    let err = e.check_stage_settings(&ctx).unwrap_err().to_string();
    assert!(err.contains("[assoc]") && err.contains("k = 0"), "{err}");
}

#[test]
fn show_lists_every_default_and_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let ctx = ctx(dir.path());
    let e = parse(
        "name = \"a\"\n[scene]\nsynth = \"rigid\"\n[gaussians]\niterations = 10\n\
         [gaussians.field]\nwidth = 32\n[evflow]\nepochs = 1\n",
    );
    let text = runner::config_show::show(&e, &ctx).unwrap();
    for stage in ["evflow", "gaussians", "assoc"] {
        let defaults = defaults(&binary(stage)).unwrap();
        for (key, _) in runner::canon::flatten(&defaults) {
            let leaf = key.rsplit('.').next().unwrap();
            assert!(
                text.contains(&format!("#   {leaf} = ")),
                "{stage}.{key} missing"
            );
        }
    }
    assert!(text.contains("#   [gaussians.densify]"), "{text}");
    assert!(text.contains("[gaussians.field]\nwidth = 32"), "{text}");
    // the commented defaults do not change what the file means
    let again = Experiment::parse(&text, Path::new("/exp/a.toml")).unwrap();
    assert_eq!(again.stages, e.stages);
    assert_eq!(again.scene, e.scene);
}

#[test]
fn f32_defaults_print_as_their_shortest_decimal() {
    let dir = tempfile::tempdir().unwrap();
    let g = defaults(&binary("gaussians")).unwrap();
    let densify = g["densify"].as_table().unwrap();
    let grad = gaussians::train::TrainSettings::default()
        .densify
        .grad_threshold;
    assert_eq!(
        densify["grad_threshold"].as_float(),
        Some(grad.to_string().parse().unwrap())
    );
    let e = parse("name = \"a\"\n[scene]\nsynth = \"rigid\"\n");
    let text = runner::config_show::show(&e, &ctx(dir.path())).unwrap();
    assert!(text.contains("#   grad_threshold = 0.0002\n"), "{text}");
    assert!(!text.contains("0.000199999"), "{text}");
}

#[test]
fn bad_stage_axes_of_a_sweep_name_the_file_and_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let ctx = ctx(dir.path());
    let base = "name = \"b\"\n[scene]\nsynth = \"rigid\"\n[scene.settings]\nwidth = 32\n\
                [deform]\niterations = 10\n";
    for (body, want) in [
        ("[axes]\n\"deform.iteratons\" = [1]\n", "deform.iteratons"),
        ("[axes]\n\"assoc.k\" = [\"three\"]\n", "assoc.k"),
    ] {
        let text = format!(
            "name = \"s\"\n[base]\n{}\n{body}",
            base.replace("[", "[base.")
        );
        let sweep = studies::sweep::Sweep::parse(&text, Path::new("/sw/s.toml")).unwrap();
        let msg = format!("{:#}", sweep.check_stages(&ctx).unwrap_err());
        assert!(msg.contains("/sw/s.toml"), "{msg}");
        assert!(msg.contains(want), "{want}: {msg}");
    }
}

/// evflow's base weights are a file outside the graph: `evflow settings --check` names
/// the file it would read (explicit, else `$EVFLOW_WEIGHTS`, else the shipped one), so
/// that the runner keys the stage on its content.
#[test]
fn evflow_names_the_base_weights_it_would_read() {
    let dir = tempfile::tempdir().unwrap();
    let w = dir.path().join("w.safetensors");
    std::fs::write(&w, b"not read here").unwrap();
    let files = |table: &str, env: Option<&Path>| {
        let mut cmd = std::process::Command::new(binary("evflow"));
        cmd.args(["settings", "--check", "-"])
            .env_remove("EVFLOW_WEIGHTS")
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped());
        if let Some(e) = env {
            cmd.env("EVFLOW_WEIGHTS", e);
        }
        let mut child = cmd.spawn().unwrap();
        use std::io::Write;
        child
            .stdin
            .take()
            .unwrap()
            .write_all(table.as_bytes())
            .unwrap();
        let out = child.wait_with_output().unwrap();
        assert!(out.status.success());
        String::from_utf8(out.stdout).unwrap()
    };
    let explicit = files(&format!("weights = \"{}\"\n", w.display()), None);
    assert_eq!(explicit, format!("weights = \"{}\"\n", w.display()));
    assert_eq!(files("", Some(&w)), explicit);
    let shipped = files("", None);
    assert!(
        shipped.contains("evflow/weights/") && shipped.contains(".safetensors"),
        "{shipped}"
    );
    // A weights file that does not exist is the stage's error to report when it runs.
    assert_eq!(files("weights = \"/no/such/file\"\n", None), "");
}
