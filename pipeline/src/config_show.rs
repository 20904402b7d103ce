//! `degs config show`: the resolved experiment with every stage default visible (the
//! defaults come from the stage libraries this `degs` was built with).

use crate::experiment::Experiment;
use crate::settings::toml_section;
use crate::stages::STAGES;
use anyhow::Result;

/// The text of `degs config show`: the experiment as `degs run` reads it (the scene
/// with every synthetic-scene setting written out, each stage's own keys), and under
/// each stage, commented out, every default that applies to the keys not set.
/// Errors when a stage table has a key its stage does not know.
pub fn show(exp: &Experiment) -> Result<String> {
    exp.check_stage_settings()?;
    let mut out = exp.scene_toml();
    for stage in STAGES {
        let name = stage.name;
        out += &format!("\n# `{} --config <this table>`\n", stage.invocation());
        out += &toml_section(name, &exp.settings(name));
        match stage.defaults() {
            Some(defaults) => {
                out += &format!("# defaults of `{name}` (keys set above override them):\n");
                for line in toml_section(name, &defaults).lines() {
                    if line.is_empty() {
                        out += "#\n";
                    } else {
                        out += &format!("#   {line}\n");
                    }
                }
            }
            None => {
                out += &format!(
                    "# `{name}` is not part of this build: its defaults are its binary's own\n"
                );
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages;
    use std::path::Path;

    fn parse(text: &str) -> Experiment {
        Experiment::parse(text, Path::new("/exp/a.toml")).unwrap()
    }

    #[test]
    fn show_lists_every_default_and_round_trips() {
        let e = parse(
            "name = \"a\"\n[scene]\nsynth = \"rigid\"\n[gaussians]\niterations = 10\n\
             [gaussians.field]\nwidth = 32\n[evflow]\nepochs = 1\n",
        );
        let text = show(&e).unwrap();
        for stage in ["evflow", "gaussians", "assoc"] {
            let defaults = stages::find(stage).unwrap().defaults().unwrap();
            for (key, _) in crate::canon::flatten(&defaults) {
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
        let g = stages::find("gaussians").unwrap().defaults().unwrap();
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
}
