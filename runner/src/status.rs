//! `degs status` and `degs gc`.

use crate::cache::{self, BinaryHashes, Verdict};
use crate::canon;
use crate::context::Context;
use crate::experiment::Experiment;
use crate::graph::{self, Node, NodeKind};
use crate::record::{Action, RunRecord, StageRecord};
use anyhow::Result;
use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::fs;

/// State of one stage of an experiment.
#[derive(Clone, Debug, PartialEq)]
pub struct StageStatus {
    pub stage: String,
    /// cached, stale, missing, failed, tampered, unsealed, unavailable, blocked, scene
    pub state: &'static str,
    pub key: Option<String>,
    /// Why (stale: what changed; failed: the error line; tampered: which file).
    pub detail: String,
}

/// The status of every stage, compared with the experiment's last run record.
/// Reads only; `full` re-hashes every cached file.
pub fn status(exp: &Experiment, ctx: &Context, full: bool) -> Result<Vec<StageStatus>> {
    let mut hashes = BinaryHashes::load(&ctx.cache);
    let nodes = graph::resolve(exp, ctx, &mut hashes)?;
    let last = RunRecord::read(&ctx.cache.run_record(&exp.name)).ok();
    let mut out = Vec::new();
    for (i, n) in nodes.iter().enumerate() {
        let prev = last.as_ref().and_then(|r| r.stage(&n.stage));
        let (state, detail) = stage_state(&nodes, i, ctx, prev, full);
        out.push(StageStatus {
            stage: n.stage.clone(),
            state,
            key: n.key.clone(),
            detail,
        });
    }
    Ok(out)
}

fn stage_state(
    nodes: &[Node],
    i: usize,
    ctx: &Context,
    prev: Option<&StageRecord>,
    full: bool,
) -> (&'static str, String) {
    let n = &nodes[i];
    if let NodeKind::SceneDir(d) = &n.kind {
        return ("scene", d.display().to_string());
    }
    if let Some(why) = &n.unavailable {
        let state = if n.binary.is_none() {
            "unavailable"
        } else {
            "blocked"
        };
        return (state, why.clone());
    }
    let key = n.key.clone().unwrap_or_default();
    let entry = ctx.cache.entry(&n.stage, &key);
    if entry.is_dir() {
        return match cache::verify(&entry, full) {
            Verdict::Ok => ("cached", entry.display().to_string()),
            Verdict::Unsealed => (
                "unsealed",
                format!("{} has no manifest; `degs run` adopts it", entry.display()),
            ),
            Verdict::Tampered(why) => (
                "tampered",
                format!("{why}; `degs run` rebuilds {}", entry.display()),
            ),
        };
    }
    match prev {
        Some(p) if p.key.as_deref() == Some(key.as_str()) && p.action == Action::Failed => (
            "failed",
            format!(
                "{} (log: {})",
                p.error.as_deref().unwrap_or("?"),
                p.log
                    .as_deref()
                    .map(|l| l.display().to_string())
                    .unwrap_or_default()
            ),
        ),
        Some(p) if p.key.is_some() && p.key.as_deref() != Some(key.as_str()) => {
            ("stale", why_changed(nodes, i, p))
        }
        _ => ("missing", "never built with these settings".into()),
    }
}

/// What differs between node `i` now and its record in the last run.
fn why_changed(nodes: &[Node], i: usize, prev: &StageRecord) -> String {
    let n = &nodes[i];
    let mut why = Vec::new();
    if prev.binary_hash != n.binary_hash {
        why.push(format!("{} binary changed", n.stage));
    }
    let old = canon::flatten(&canon::from_json(&prev.settings));
    let new = canon::flatten(&n.settings);
    for (k, v) in &new {
        match old.get(k) {
            None => why.push(format!("setting {k} added ({v})")),
            Some(o) if o != v => why.push(format!("setting {k} changed {o} → {v}")),
            _ => {}
        }
    }
    for k in old.keys().filter(|k| !new.contains_key(*k)) {
        why.push(format!("setting {k} removed"));
    }
    for input in &n.inputs {
        let flag = input.flag.trim_start_matches('-');
        let now = nodes[input.node].key.as_deref().unwrap_or("");
        if prev.inputs.get(flag).map(String::as_str) != Some(now) {
            why.push(format!("input {} changed", nodes[input.node].stage));
        }
    }
    if why.is_empty() {
        why.push("key changed".into());
    }
    why.join("; ")
}

/// The status table as text.
pub fn format_status(rows: &[StageStatus]) -> String {
    let mut s = String::new();
    for r in rows {
        let key = r
            .key
            .as_deref()
            .map(|k| &k[..k.len().min(12)])
            .unwrap_or("-");
        let _ = writeln!(
            s,
            "{:<10} {:<11} {:<12} {}",
            r.stage, r.state, key, r.detail
        );
    }
    s
}

/// What `degs gc` did (or would do).
#[derive(Debug, Default)]
pub struct GcReport {
    pub removed: Vec<(String, String)>,
    pub kept: usize,
    pub bytes: u64,
}

/// Remove cache entries that no `runs/*/run.json` refers to (and stale temp dirs, and
/// the lock files no runner holds).
pub fn gc(cache: &cache::Cache, dry_run: bool) -> Result<GcReport> {
    if !dry_run {
        cache.remove_stale_temps()?;
        crate::lock::remove_free_locks(cache)?;
    }
    let mut used = BTreeSet::new();
    let mut used_dirs = BTreeSet::new();
    if let Ok(runs) = fs::read_dir(cache.root.join("runs")) {
        for r in runs.flatten() {
            let path = r.path().join("run.json");
            if !path.exists() {
                continue;
            }
            // An unreadable record keeps everything: better too much than a lost run.
            let record = RunRecord::read(&path)?;
            for s in record.stages {
                // a scene directory inside the cache (a `degs stress` scene) is used by path
                if let Some(entry) = &s.entry {
                    used_dirs.insert(entry.clone());
                }
                if let Some(k) = s.key {
                    used.insert((s.stage, k));
                }
            }
        }
    }
    let mut report = GcReport::default();
    for (stage, key, path) in cache.entries() {
        if used.contains(&(stage.clone(), key.clone())) || used_dirs.contains(&path) {
            report.kept += 1;
            continue;
        }
        report.bytes += cache::dir_size(&path);
        if !dry_run {
            fs::remove_dir_all(&path)?;
        }
        report.removed.push((stage, key));
    }
    Ok(report)
}
