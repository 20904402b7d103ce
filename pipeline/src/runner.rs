//! `degs run`: resolve keys, reuse cached entries, run the rest as processes (in
//! parallel where the graph allows), seal their outputs and record the run.

use crate::cache::{self, BinaryHashes, Verdict};
use crate::canon;
use crate::experiment::Experiment;
use crate::graph::{self, Context, Node, NodeKind};
use crate::process::{self, Outcome};
use crate::progress::Progress;
use crate::record::{Action, RunRecord, StageRecord, now_unix};
use anyhow::{Result, bail};
use std::fs;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
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
}

#[derive(Clone, Copy, PartialEq)]
enum State {
    Waiting,
    Running,
    Done(Action),
}

/// Write the settings file of every runnable node; return the resolved nodes.
pub fn prepare(exp: &Experiment, ctx: &Context) -> Result<Vec<Node>> {
    ctx.cache.remove_stale_temps()?;
    let mut hashes = BinaryHashes::load(&ctx.cache);
    let nodes = graph::resolve(exp, ctx, &mut hashes)?;
    hashes.save(&ctx.cache)?;
    for n in &nodes {
        if matches!(n.kind, NodeKind::SceneDir(_)) || n.binary.is_none() {
            continue;
        }
        let path = graph::settings_path(&ctx.cache, &exp.name, &n.stage);
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
    let started = Instant::now();
    let nodes = prepare(exp, ctx)?;
    let n = nodes.len();
    let included = match opts.until {
        Some(u) => graph::ancestors(&nodes, u),
        None => vec![true; n],
    };
    let mut forced = vec![false; n];
    for &f in &opts.force {
        for (i, d) in graph::descendants(&nodes, f).into_iter().enumerate() {
            forced[i] |= d;
        }
    }
    let mut record = RunRecord {
        experiment: exp.name.clone(),
        experiment_file: exp.file.clone(),
        cache_root: ctx.cache.root.clone(),
        status: "running".into(),
        started_unix: now_unix(),
        wall_s: 0.0,
        jobs: opts.jobs.max(1),
        stages: nodes
            .iter()
            .enumerate()
            .map(|(i, nd)| base_record(nd, i, &nodes, ctx))
            .collect(),
    };
    let record_path = ctx.cache.run_record(&exp.name);

    // What is already there.
    let mut state = vec![State::Waiting; n];
    let mut rebuild_reason: Vec<Option<String>> = vec![None; n];
    for i in 0..n {
        let nd = &nodes[i];
        let rec = &mut record.stages[i];
        if !included[i] {
            state[i] = State::Done(Action::NotRequested);
            continue;
        }
        if let Some(why) = &nd.unavailable {
            let action = if nd.binary.is_none() {
                Action::Unavailable
            } else {
                Action::Skipped
            };
            rec.error = Some(why.clone());
            state[i] = State::Done(action);
            progress.finish(&nd.stage, why);
            continue;
        }
        if let NodeKind::SceneDir(d) = &nd.kind {
            state[i] = State::Done(Action::Cached);
            progress.finish(&nd.stage, &format!("scene directory {}", d.display()));
            continue;
        }
        let entry = rec.entry.clone().unwrap_or_default();
        if !entry.is_dir() {
            continue;
        }
        match cache::verify(&entry, opts.verify_full) {
            Verdict::Ok if !forced[i] => state[i] = State::Done(Action::Cached),
            Verdict::Unsealed if !forced[i] => {
                // Written by a stage command from `degs plan`: adopt it.
                cache::seal(
                    &entry,
                    &nd.stage,
                    nd.key.as_deref().unwrap_or(""),
                    0.0,
                    None,
                )?;
                state[i] = State::Done(Action::Cached);
            }
            Verdict::Tampered(why) => rebuild_reason[i] = Some(why),
            _ => {}
        }
        if state[i] == State::Done(Action::Cached) {
            let m = cache::read_manifest(&entry);
            rec.built_wall_s = m.as_ref().map(|m| m.wall_s);
            rec.peak_rss_kib = m.and_then(|m| m.peak_rss_kib);
            progress.finish(&nd.stage, &format!("cached  {}", entry.display()));
        }
    }

    let jobs = opts.jobs.max(1);
    std::thread::scope(|s| -> Result<()> {
        let (tx, rx) = mpsc::channel::<(usize, Result<Outcome>)>();
        let mut running = 0usize;
        loop {
            let mut changed = true;
            while changed {
                changed = false;
                for i in 0..n {
                    if state[i] != State::Waiting {
                        continue;
                    }
                    let inputs = &nodes[i].inputs;
                    if let Some(bad) = inputs
                        .iter()
                        .find(|x| matches!(state[x.node], State::Done(a) if !a.has_output()))
                    {
                        let why = format!("input {} did not finish", nodes[bad.node].stage);
                        progress.finish(&nodes[i].stage, &format!("skipped: {why}"));
                        record.stages[i].error = Some(why);
                        state[i] = State::Done(Action::Skipped);
                        changed = true;
                        continue;
                    }
                    let ready = inputs
                        .iter()
                        .all(|x| matches!(state[x.node], State::Done(a) if a.has_output()));
                    if ready && running < jobs {
                        let args = start_stage(&nodes, i, ctx, &exp.name)?;
                        let msg = match &rebuild_reason[i] {
                            Some(why) => format!("rebuilding (cache entry tampered: {why})"),
                            None if forced[i] => "running (forced)".to_string(),
                            None => "running".to_string(),
                        };
                        progress.start(&nodes[i].stage, &msg);
                        let tx = tx.clone();
                        let stage = nodes[i].stage.clone();
                        s.spawn(move || {
                            let out = process::run(&args, &|line| progress.output(&stage, line));
                            let _ = tx.send((i, out));
                        });
                        state[i] = State::Running;
                        running += 1;
                        changed = true;
                    }
                }
            }
            record.wall_s = started.elapsed().as_secs_f64();
            record.write(&record_path)?;
            if running == 0 {
                break;
            }
            let Ok((i, outcome)) = rx.recv() else { break };
            running -= 1;
            let action = finish_stage(
                &nodes,
                i,
                ctx,
                &exp.name,
                outcome,
                &mut record.stages[i],
                rebuild_reason[i].is_some(),
            )?;
            let rec = &record.stages[i];
            let msg = match action {
                Action::Failed => format!(
                    "FAILED: {} (log: {})",
                    rec.error.as_deref().unwrap_or(""),
                    rec.log.as_deref().unwrap_or(Path::new("")).display()
                ),
                _ => format!(
                    "{} in {:.2} s, peak {}  {}",
                    action.as_str(),
                    rec.wall_s,
                    fmt_kib(rec.peak_rss_kib),
                    rec.entry.as_deref().unwrap_or(Path::new("")).display()
                ),
            };
            progress.finish(&nodes[i].stage, &msg);
            state[i] = State::Done(action);
        }
        Ok(())
    })?;

    for (i, st) in state.iter().enumerate() {
        if let State::Done(a) = st {
            record.stages[i].action = *a;
        }
    }
    let failed = record.stages.iter().any(|s| s.action == Action::Failed);
    record.status = if failed { "failed" } else { "ok" }.into();
    record.wall_s = started.elapsed().as_secs_f64();
    record.write(&record_path)?;
    Ok(record)
}

/// Clear the temp dir of node `i` and return its command line.
fn start_stage(nodes: &[Node], i: usize, ctx: &Context, exp: &str) -> Result<Vec<String>> {
    let nd = &nodes[i];
    let key = nd.key.as_deref().unwrap_or_default();
    let tmp = ctx.cache.temp_entry(&nd.stage, key);
    if tmp.exists() {
        fs::remove_dir_all(&tmp)?;
    }
    fs::create_dir_all(ctx.cache.stage_dir(&nd.stage))?;
    let config = graph::settings_path(&ctx.cache, exp, &nd.stage);
    Ok(graph::command(nodes, i, &ctx.cache, &tmp, &config))
}

/// Seal and move a finished stage into place (or record its failure); write its log.
fn finish_stage(
    nodes: &[Node],
    i: usize,
    ctx: &Context,
    exp: &str,
    outcome: Result<Outcome>,
    rec: &mut StageRecord,
    rebuilding: bool,
) -> Result<Action> {
    let nd = &nodes[i];
    let key = nd.key.as_deref().unwrap_or_default();
    let tmp = ctx.cache.temp_entry(&nd.stage, key);
    let entry = ctx.cache.entry(&nd.stage, key);
    let config = graph::settings_path(&ctx.cache, exp, &nd.stage);
    let args = graph::command(nodes, i, &ctx.cache, &tmp, &config);
    let log = ctx.cache.run_dir(exp).join(format!("{}.log", nd.stage));
    rec.log = Some(log.clone());
    let mut action = Action::Failed;
    let mut text = format!(
        "$ {}\n",
        args.iter()
            .map(|a| graph::shell_quote(a))
            .collect::<Vec<_>>()
            .join(" ")
    );
    match outcome {
        Err(e) => {
            rec.error = Some(format!("{e:#}"));
            text += &format!("could not start: {e:#}\n");
        }
        Ok(out) => {
            rec.wall_s = out.wall_s;
            rec.peak_rss_kib = out.peak_rss_kib;
            rec.exit_status = out.code;
            if out.success() && !tmp.is_dir() {
                rec.error = Some(format!(
                    "{} exited 0 but wrote nothing to {}",
                    nd.stage,
                    tmp.display()
                ));
            } else if out.success() {
                cache::seal(&tmp, &nd.stage, key, out.wall_s, out.peak_rss_kib)?;
                commit_entry(&tmp, &entry)?;
                rec.built_wall_s = Some(out.wall_s);
                action = if rebuilding {
                    Action::Rebuilt
                } else {
                    Action::Ran
                };
            } else {
                rec.error = Some(out.error_line());
            }
            text += &format!(
                "exit status: {}\nwall: {:.3} s\npeak memory: {}\n--- last {} lines of output ---\n",
                match (out.code, out.signal) {
                    (Some(c), _) => c.to_string(),
                    (None, Some(s)) => format!("killed by signal {s}"),
                    _ => "unknown".into(),
                },
                out.wall_s,
                fmt_kib(out.peak_rss_kib),
                out.tail.len()
            );
            for l in &out.tail {
                text += l;
                text.push('\n');
            }
        }
    }
    if action == Action::Failed {
        if tmp.exists() {
            let _ = fs::remove_dir_all(&tmp);
        }
        if let Some(e) = &rec.error {
            text += &format!("error: {e}\n");
        }
    }
    scene::atomic::write_bytes_atomic(&log, text.as_bytes())?;
    Ok(action)
}

/// Rename `tmp` to `entry`; an existing entry (forced or tampered) is moved aside first.
fn commit_entry(tmp: &Path, entry: &Path) -> Result<()> {
    if entry.exists() {
        let mut old = entry.as_os_str().to_os_string();
        old.push(format!(".old.tmp-{}", std::process::id()));
        let old = PathBuf::from(old);
        fs::rename(entry, &old)?;
        fs::rename(tmp, entry)?;
        let _ = fs::remove_dir_all(&old);
    } else if let Err(e) = fs::rename(tmp, entry) {
        if entry.is_dir() {
            // Another runner sealed the same key first: keep theirs.
            let _ = fs::remove_dir_all(tmp);
        } else {
            bail!(
                "{}: cannot move finished stage into place: {e}",
                entry.display()
            );
        }
    }
    Ok(())
}

/// "123 MiB" from KiB.
pub fn fmt_kib(kib: Option<u64>) -> String {
    match kib {
        None => "-".into(),
        Some(k) if k >= 1 << 20 => format!("{:.2} GiB", k as f64 / (1u64 << 20) as f64),
        Some(k) => format!("{:.1} MiB", k as f64 / 1024.0),
    }
}
