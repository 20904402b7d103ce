//! Every stage's default settings (from the stage libraries this `degs` was built
//! with) and `degs config show`: the resolved experiment with all defaults visible.

use crate::experiment::{Experiment, SETTINGS_STAGES, merge};
use anyhow::{Result, bail};
use toml::{Table, Value};

/// The default settings of `stage` as its binary reads them from `--config`, or None
/// for a stage whose library this build does not know (`deform`, not written yet).
pub fn stage_defaults(stage: &str) -> Option<Table> {
    match stage {
        "evflow" => settings_table(&evflow::finetune::FlowSettings::default()),
        "gaussians" => settings_table(&gaussians::train::TrainSettings::default()),
        "assoc" => settings_table(&assoc::AssocSettings::default()),
        _ => None,
    }
}

/// `settings` as a TOML table, through TOML text: the text writer prints an `f32`
/// field as the shortest decimal that reads back to the same `f32` (`0.0002`), which
/// then parses to the `f64` of that decimal. `toml::Value::try_from` would widen the
/// `f32` instead (`0.00019999999494757503`).
fn settings_table<T: serde::Serialize>(settings: &T) -> Option<Table> {
    toml::to_string(settings).ok()?.parse().ok()
}

/// Check `settings` against the stage's settings type: unknown keys and wrong types
/// are errors naming the key. Stages without a known type pass.
pub fn check_stage_settings(stage: &str, settings: &Table) -> std::result::Result<(), String> {
    let Some(mut full) = stage_defaults(stage) else {
        return Ok(());
    };
    merge(&mut full, settings);
    let text = toml::to_string(&full).map_err(|e| e.to_string())?;
    let msg = |e: toml::de::Error| e.message().trim().to_string();
    match stage {
        "evflow" => toml::from_str::<evflow::finetune::FlowSettings>(&text)
            .map(drop)
            .map_err(msg),
        "gaussians" => toml::from_str::<gaussians::train::TrainSettings>(&text)
            .map(drop)
            .map_err(msg),
        "assoc" => toml::from_str::<assoc::AssocSettings>(&text)
            .map(drop)
            .map_err(msg),
        _ => Ok(()),
    }
}

/// Check every stage table of `exp`; the error names the file, the stage and the key.
pub fn check_experiment(exp: &Experiment) -> Result<()> {
    for stage in SETTINGS_STAGES {
        if let Err(e) = check_stage_settings(stage, &exp.settings(stage)) {
            let file = exp
                .file
                .as_deref()
                .map(|f| format!("{}: ", f.display()))
                .unwrap_or_default();
            bail!("{file}[{stage}]: {e}");
        }
    }
    Ok(())
}

/// `[stage]` with `table` under it (nested tables as `[stage.sub]`).
pub fn stage_section(stage: &str, table: &Table) -> String {
    let scalars: Table = table
        .iter()
        .filter(|(_, v)| !v.is_table())
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    let mut out = format!("[{stage}]\n");
    out += &crate::canon::to_toml(&scalars);
    let mut subs: Vec<(&String, &Value)> = table.iter().filter(|(_, v)| v.is_table()).collect();
    subs.sort_by(|a, b| a.0.cmp(b.0));
    for (k, v) in subs {
        if let Value::Table(t) = v {
            out += "\n";
            out += &stage_section(&format!("{stage}.{k}"), t);
        }
    }
    out
}

/// The text of `degs config show`: the experiment as `degs run` reads it (the scene
/// with every synthetic-scene setting written out, each stage's own keys), and under
/// each stage, commented out, every default that applies to the keys not set.
/// Errors when a stage table has a key its stage does not know.
pub fn show(exp: &Experiment) -> Result<String> {
    check_experiment(exp)?;
    let mut out = exp.scene_toml();
    for stage in SETTINGS_STAGES {
        let table = exp.settings(stage);
        let cmd = crate::graph::stage_def(stage)
            .and_then(|d| d.verb)
            .map_or(stage.to_string(), |v| format!("{stage} {v}"));
        out += &format!("\n# `{cmd} --config <this table>`\n");
        out += &stage_section(stage, &table);
        match stage_defaults(stage) {
            Some(defaults) => {
                out += &format!("# defaults of `{stage}` (keys set above override them):\n");
                for line in stage_section(stage, &defaults).lines() {
                    if line.is_empty() {
                        out += "#\n";
                    } else {
                        out += &format!("#   {line}\n");
                    }
                }
            }
            None => {
                out += &format!(
                    "# `{stage}` is not part of this build: its defaults are its binary's own\n"
                );
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn parse(text: &str) -> Experiment {
        Experiment::parse(text, Path::new("/exp/a.toml")).unwrap()
    }

    #[test]
    fn every_known_stage_has_defaults() {
        let g = stage_defaults("gaussians").unwrap();
        assert_eq!(g.get("iterations"), Some(&Value::Integer(3500)));
        assert!(g["field"].is_table());
        assert_eq!(
            stage_defaults("evflow").unwrap().get("epochs"),
            Some(&Value::Integer(3))
        );
        assert_eq!(
            stage_defaults("assoc").unwrap().get("k"),
            Some(&Value::Integer(3))
        );
        assert!(stage_defaults("deform").is_none());
    }

    #[test]
    fn f32_defaults_print_as_their_shortest_decimal() {
        let g = stage_defaults("gaussians").unwrap();
        let densify = g["densify"].as_table().unwrap();
        let grad = gaussians::train::TrainSettings::default()
            .densify
            .grad_threshold;
        assert_eq!(
            densify["grad_threshold"].as_float(),
            Some(grad.to_string().parse().unwrap())
        );
        let e = parse("name = \"a\"\n[scene]\nsynth = \"rigid\"\n");
        let text = show(&e).unwrap();
        assert!(text.contains("#   grad_threshold = 0.0002\n"), "{text}");
        assert!(!text.contains("0.000199999"), "{text}");
    }

    #[test]
    fn unknown_stage_keys_are_named() {
        let e = parse("name = \"a\"\n[scene]\nsynth = \"rigid\"\n[gaussians]\niters = 10\n");
        let msg = check_experiment(&e).unwrap_err().to_string();
        assert!(
            msg.contains("iters") && msg.contains("[gaussians]") && msg.contains("/exp/a.toml"),
            "{msg}"
        );
        let e = parse("name = \"a\"\n[scene]\nsynth = \"rigid\"\n[assoc]\nk = \"three\"\n");
        assert!(check_experiment(&e).is_err());
        let e = parse(
            "name = \"a\"\n[scene]\nsynth = \"rigid\"\n[gaussians]\niterations = 10\n\
             [gaussians.field]\nwidth = 32\n[deform]\nanything = 1\n",
        );
        check_experiment(&e).unwrap();
    }

    #[test]
    fn show_lists_every_default_and_round_trips() {
        let e = parse(
            "name = \"a\"\n[scene]\nsynth = \"rigid\"\n[gaussians]\niterations = 10\n\
             [gaussians.field]\nwidth = 32\n[evflow]\nepochs = 1\n",
        );
        let text = show(&e).unwrap();
        for stage in ["evflow", "gaussians", "assoc"] {
            let defaults = crate::canon::flatten(&stage_defaults(stage).unwrap());
            for (key, _) in defaults {
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
}
