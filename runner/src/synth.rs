//! `degs synth`: write a synthetic scene directory (the built-in first stage).

use crate::experiment::{merge, parse_set, synth_config};
use anyhow::{Context, Result, anyhow};
use std::path::Path;
use synth::SynthConfig;

/// The config of `degs synth`: a full config file (TOML, as written by `degs run` /
/// `degs plan`), or a preset, with `--set key=value` overrides either way.
pub fn load_config(
    config: Option<&Path>,
    preset: Option<&str>,
    set: &[String],
) -> Result<SynthConfig> {
    let overrides = parse_set(set).map_err(|e| anyhow!(e))?;
    match config {
        Some(path) => {
            let text = std::fs::read_to_string(path).with_context(|| {
                format!("{}: cannot read synthetic scene settings", path.display())
            })?;
            let mut table: toml::Table = text.parse().map_err(|e: toml::de::Error| {
                anyhow!("{}: {}", path.display(), e.message().trim())
            })?;
            merge(&mut table, &overrides);
            Ok(stagekit::settings::from_table(table, path)?)
        }
        None => {
            let preset = preset.unwrap_or("rigid");
            synth_config(preset, &overrides).map_err(|e| anyhow!(e))
        }
    }
}

/// Write the scene of `cfg` to `out` (atomically) under `rule`: what may be there.
pub fn write_scene(
    cfg: &SynthConfig,
    out: &Path,
    rule: &scene::atomic::OutputRule,
) -> Result<synth::Summary> {
    Ok(synth::write_synthetic_scene_with(cfg, out, rule)?)
}
