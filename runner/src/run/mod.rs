//! `degs run`: resolve keys, reuse cached entries, run the rest as processes (in
//! parallel where the graph allows), seal their outputs and record the run.
//!
//! [`run`] is [`prepare`] (keys, settings files), then the cache check (what is
//! already there: `cache_check`), then the scheduling of the rest (`schedule`; each
//! stage process: `stage_process`), then the final run record.

mod cache_check;
mod schedule;
mod stage_process;
mod state;

use crate::cache::BinaryHashes;
use crate::canon;
use crate::command_line::settings_path;
use crate::context::Context;
use crate::experiment::Experiment;
use crate::graph::{self, Node, NodeKind};
use crate::progress::Progress;
use crate::record::{Action, RunRecord, StageRecord, now_unix};
use anyhow::Result;
use cache_check::Request;
use schedule::Schedule;
use state::State;
use std::fs;
use std::time::Instant;

/// Options of `degs run`.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Run only this node and what it needs.
    pub until: Option<usize>,
    /// Run these nodes (and what depends on them) even when cached.
    pub force: Vec<usize>,
    /// Stages run at the same time (at least 1).
    pub jobs: usize,
    /// Re-hash every cached file instead of trusting unchanged size + mtime.
    pub verify_full: bool,
    /// Experiments run at the same time by sweeps and stress runs (`-J`; at least 1).
    pub experiments: usize,
}

/// Write the settings file of every runnable node; return the resolved nodes.
pub(crate) fn prepare(exp: &Experiment, ctx: &Context) -> Result<Vec<Node>> {
    ctx.cache.remove_stale_temps()?;
    let mut hashes = BinaryHashes::load(&ctx.cache);
    let nodes = graph::resolve(exp, ctx, &mut hashes)?;
    hashes.save(&ctx.cache)?;
    for n in &nodes {
        if matches!(n.kind, NodeKind::SceneDir(_) | NodeKind::Given(_)) || n.binary.is_none() {
            continue;
        }
        let path = settings_path(&ctx.cache, &exp.name, &n.stage);
        let text = canon::to_toml(&n.settings);
        if fs::read_to_string(&path).ok().as_deref() != Some(text.as_str()) {
            scene::atomic::write_bytes_atomic(&path, text.as_bytes())?;
        }
    }
    Ok(nodes)
}

fn base_record(n: &Node, i: usize, nodes: &[Node], ctx: &Context) -> StageRecord {
    StageRecord {
        stage: n.stage.clone(),
        action: Action::Pending,
        key: n.key.clone(),
        binary: n.binary.clone(),
        binary_hash: n.binary_hash.clone(),
        settings: canon::to_json(&n.settings),
        inputs: n
            .inputs
            .iter()
            .map(|x| {
                let key = nodes[x.node].key.clone().unwrap_or_default();
                (x.flag.trim_start_matches('-').to_string(), key)
            })
            .collect(),
        entry: graph::output_dir(nodes, i, &ctx.cache),
        wall_s: 0.0,
        built_wall_s: None,
        peak_rss_kib: None,
        exit_status: None,
        error: None,
        log: None,
        progress: None,
        warnings: Vec::new(),
    }
}

/// Run the experiment. Returns the run record (also written to `runs/<name>/run.json`);
/// a failed stage is recorded there, not returned as an error.
pub fn run(
    exp: &Experiment,
    ctx: &Context,
    opts: &RunOptions,
    progress: &Progress,
) -> Result<RunRecord> {
    let nodes = prepare(exp, ctx)?;
    let record_path = ctx.cache.run_record(&exp.name);
    run_nodes(
        &nodes,
        (&exp.name, exp.file.as_deref()),
        ctx,
        opts,
        progress,
        Some(&record_path),
    )
}

/// Run resolved `nodes` (their settings files written) for the experiment `name`
/// (read from `file`); the record is saved to `record_path` after every change when
/// given.
pub(crate) fn run_nodes(
    nodes: &[Node],
    (name, file): (&str, Option<&std::path::Path>),
    ctx: &Context,
    opts: &RunOptions,
    progress: &Progress,
    record_path: Option<&std::path::Path>,
) -> Result<RunRecord> {
    let started = Instant::now();
    let mut record = RunRecord {
        experiment: name.to_string(),
        experiment_file: file.map(|f| f.to_path_buf()),
        cache_root: ctx.cache.root.clone(),
        status: "running".into(),
        started_unix: now_unix(),
        wall_s: 0.0,
        jobs: opts.jobs.max(1),
        stages: nodes
            .iter()
            .enumerate()
            .map(|(i, nd)| base_record(nd, i, nodes, ctx))
            .collect(),
    };
    let mut save = |record: &mut RunRecord| -> Result<()> {
        record.wall_s = started.elapsed().as_secs_f64();
        match record_path {
            Some(p) => record.write(p),
            None => Ok(()),
        }
    };

    let request = Request {
        until: opts.until,
        force: &opts.force,
        verify_full: opts.verify_full,
    };
    let schedule = Schedule {
        nodes,
        ctx,
        experiment: name,
        jobs: opts.jobs,
        progress,
        experiments_at_once: opts.experiments.max(1),
    };
    let label = |i: usize| schedule.label(i);
    let mut states = cache_check::check(nodes, &request, &mut record.stages, (progress, &label))?;
    schedule::run_waiting(&schedule, &mut states, &mut record, &mut save)?;

    for (rec, st) in record.stages.iter_mut().zip(&states) {
        if let State::Done(a) = st.state {
            rec.action = a;
        }
        if let Some(entry) = rec.entry.as_deref().filter(|_| rec.action.has_output()) {
            rec.warnings = crate::record::report_warnings(entry);
        }
    }
    let failed = record.stages.iter().any(|s| s.action == Action::Failed);
    // A requested stage that could not run (no binary, or an input that could not be
    // made) leaves the run without its result: never "ok".
    let incomplete = record.stages.iter().any(|s| s.action.could_not_run());
    record.status = if failed {
        "failed"
    } else if incomplete {
        "incomplete"
    } else {
        "ok"
    }
    .into();
    save(&mut record)?;
    Ok(record)
}
