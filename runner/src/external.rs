//! A stage the runner runs over outputs that exist already, beside an experiment's
//! graph: the evaluation over a finished run (`degs eval`), the export of its model
//! (`degs export`). One cached node (`cache/<stage>/<key>/`, its key from the binary's
//! hash, its settings and its inputs' keys and places) whose inputs are given folders,
//! run through [`crate::run::run_nodes`] like any stage: locked, logged, sealed.

use crate::context::Context;
use crate::graph::{Input, Node, NodeKind, key_of};
use crate::progress::Progress;
use crate::record::{Action, RunRecord, StageRecord};
use crate::run::{RunOptions, run_nodes};
use crate::stages;
use anyhow::{Context as _, Result, bail};
use std::path::PathBuf;
use toml::Table;

/// The stage: its node name (and cache folder), binary, cargo package, verb, settings.
pub struct External<'a> {
    /// What it is, in words (`the evaluation`): errors say it failed.
    pub what: &'a str,
    pub stage: &'a str,
    pub binary: &'a str,
    pub package: &'a str,
    pub verb: Option<&'static str>,
    pub settings: Table,
}

/// A folder the stage reads, passed as `flag`: an output of a run (`name`, its entry and
/// key).
pub struct Given {
    pub flag: &'static str,
    pub name: String,
    pub entry: PathBuf,
    pub key: String,
}

/// An output of `record` by stage name: `(entry, key)` when the stage left one.
pub fn output_of(record: &RunRecord, stage: &str) -> Option<(PathBuf, String)> {
    record
        .stage(stage)
        .filter(|s| s.action.has_output())
        .and_then(|s| Some((s.entry.clone()?, s.key.clone().unwrap_or_default())))
}

/// The run's scene: its first stage's output.
pub fn scene_of(record: &RunRecord) -> Option<(PathBuf, String)> {
    record
        .stages
        .first()
        .filter(|s| s.action.has_output())
        .and_then(|s| Some((s.entry.clone()?, s.key.clone().unwrap_or_default())))
}

/// Run `ext` over `given` for the experiment `experiment` (its settings file goes under
/// `runs/<experiment>/`) in the cache of `cache_root`; the stage's record, its entry
/// holding the output. A failed stage is an error naming its log.
pub fn run_external(
    ext: &External,
    given: Vec<Given>,
    (experiment, cache_root): (&str, PathBuf),
    ctx: &Context,
    progress: &Progress,
) -> Result<StageRecord> {
    let mut nodes = Vec::new();
    let mut inputs = Vec::new();
    for g in given {
        // An entry's key names its content; its place is in the key too, so that two
        // runs whose records give the same key to different folders stay apart.
        let key = blake3::hash(format!("{}\0{}", g.key, g.entry.display()).as_bytes()).to_hex()
            [..32]
            .to_string();
        inputs.push(Input {
            flag: g.flag,
            node: nodes.len(),
        });
        nodes.push(Node {
            stage: g.name,
            kind: NodeKind::Given(g.entry),
            verb: None,
            binary: None,
            binary_hash: None,
            settings: Table::new(),
            inputs: vec![],
            key: Some(key),
            unavailable: None,
        });
    }
    let ctx = Context {
        cache: crate::cache::Cache::new(cache_root),
        ..ctx.clone()
    };
    let binary = ctx.stage_binary(ext.binary).with_context(|| {
        format!(
            "cannot run {}: {}",
            ext.stage,
            stages::not_built(ext.binary, ext.package, ctx.stage_dir.as_deref())
        )
    })?;
    let mut hashes = crate::cache::BinaryHashes::load(&ctx.cache);
    let binary_hash = hashes.hash(&binary)?;
    hashes.save(&ctx.cache)?;
    let in_keys: Vec<(&str, &str)> = inputs
        .iter()
        .map(|i| (i.flag, nodes[i.node].key.as_deref().unwrap_or("")))
        .collect();
    let key = key_of(ext.stage, &binary_hash, &ext.settings, &in_keys);
    nodes.push(Node {
        stage: ext.stage.into(),
        kind: NodeKind::External,
        verb: ext.verb,
        binary: Some(binary),
        binary_hash: Some(binary_hash),
        settings: ext.settings.clone(),
        inputs,
        key: Some(key),
        unavailable: None,
    });
    let config = crate::command_line::settings_path(&ctx.cache, experiment, ext.stage);
    scene::atomic::write_bytes_atomic(&config, crate::canon::to_toml(&ext.settings).as_bytes())?;
    let opts = RunOptions {
        until: Some(nodes.len() - 1),
        jobs: 1,
        ..RunOptions::default()
    };
    let run = run_nodes(&nodes, (experiment, None), &ctx, &opts, progress, None)?;
    let done = run.stages.last().expect("the external node").clone();
    if done.action == Action::Failed {
        bail!(
            "{} failed: {} (log: {})",
            ext.what,
            done.error.as_deref().unwrap_or("?"),
            done.log
                .as_deref()
                .map(|p| p.display().to_string())
                .unwrap_or_default()
        );
    }
    Ok(done)
}
