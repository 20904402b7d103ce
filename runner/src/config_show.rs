//! `degs config show`: the resolved experiment with every stage default visible (the
//! defaults come from the stage binaries themselves: `STAGE settings --defaults`).

use crate::context::Context;
use crate::experiment::Experiment;
use crate::settings::toml_section;
use crate::stages::STAGES;
use anyhow::Result;

/// The text of `degs config show`: the experiment as `degs run` reads it (the scene
/// with every synthetic-scene setting written out, each stage's own keys), and under
/// each stage, commented out, every default that applies to the keys not set.
/// Errors when a stage table has a key its stage does not know.
pub fn show(exp: &Experiment, ctx: &Context) -> Result<String> {
    exp.check_stage_settings(ctx)?;
    let mut out = exp.scene_toml();
    for stage in STAGES {
        let name = stage.name;
        out += &format!("\n# `{} --config <this table>`\n", stage.invocation());
        out += &toml_section(name, &exp.settings(name));
        match ctx.stage_binary(stage.binary) {
            Some(binary) => {
                let defaults = crate::settings::defaults(&binary)?;
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
                    "# `{name}`: {}; its defaults are its binary's own\n",
                    stage.not_built_message(ctx.stage_dir.as_deref())
                );
            }
        }
    }
    Ok(out)
}
