//! Scheduling the waiting nodes of a run: each starts, on its own thread, once every
//! input has its output, at most `jobs` at a time; one whose input ended without
//! output is skipped. The run record is saved after every change.

use super::stage_process::{self, Started};
use super::state::{NodeState, State};
use crate::context::Context;
use crate::graph::Node;
use crate::lock::EntryLock;
use crate::progress::Progress;
use crate::record::{Action, RunRecord, StageRecord};
use crate::stage_progress::{RecentRate, StageProgress, parse};
use anyhow::Result;
use std::sync::mpsc;
use std::time::Instant;

/// What a node's thread tells the scheduler.
enum Message {
    /// A progress line of the running stage, read.
    Progress(StageProgress),
    /// The stage ended (or another runner built its entry); the entry's lock.
    Done(Result<(Started, EntryLock)>),
}

/// What the scheduler runs, and where.
pub struct Schedule<'a> {
    pub nodes: &'a [Node],
    pub ctx: &'a Context,
    /// The experiment's name (its settings files and logs are under `runs/<name>/`).
    pub experiment: &'a str,
    /// Stages run at the same time (at least 1).
    pub jobs: usize,
    pub progress: &'a Progress,
    /// Experiments of a sweep running at the same time as this one (`-J`; at least 1):
    /// progress lines name the experiment when several run, and the cores are shared.
    pub experiments_at_once: usize,
}

impl Schedule<'_> {
    /// How progress lines name node `i`: its stage, after the experiment when several
    /// experiments run at once.
    pub(crate) fn label(&self, i: usize) -> String {
        match self.experiments_at_once > 1 {
            true => format!("{}: {}", self.experiment, self.nodes[i].stage),
            false => self.nodes[i].stage.clone(),
        }
    }
}

/// Run every waiting node (or skip it), calling `save` on the record whenever
/// something changed; returns when nothing runs any more.
pub(crate) fn run_waiting(
    s: &Schedule,
    states: &mut [NodeState],
    record: &mut RunRecord,
    save: &mut dyn FnMut(&mut RunRecord) -> Result<()>,
) -> Result<()> {
    let jobs = s.jobs.max(1);
    std::thread::scope(|scope| -> Result<()> {
        let (tx, rx) = mpsc::channel::<(usize, Message)>();
        let mut saved = Instant::now();
        let mut running = 0usize;
        loop {
            skip_blocked(s, states, &mut record.stages);
            for i in ready(s.nodes, states).into_iter().take(jobs - running) {
                let args = stage_process::start(s.nodes, i, s.ctx, s.experiment)?;
                let label = s.label(i);
                s.progress.start(&label, &start_message(&states[i]));
                let reuse = !states[i].forced && states[i].rebuild_reason.is_none();
                let threads = crate::process::thread_share(s.experiments_at_once);
                let (tx, progress, nodes, ctx) = (tx.clone(), s.progress, s.nodes, s.ctx);
                scope.spawn(move || {
                    let rate = std::sync::Mutex::new(RecentRate::default());
                    let on_line = |line: &str| {
                        let read = parse(line)
                            .map(|p| rate.lock().unwrap_or_else(|e| e.into_inner()).update(p));
                        progress.output(&label, line, read.as_ref());
                        if let Some(p) = read {
                            let _ = tx.send((i, Message::Progress(p)));
                        }
                    };
                    let out = stage_process::lock_and_run(
                        nodes,
                        i,
                        ctx,
                        (&args, reuse, threads),
                        &on_line,
                    );
                    let _ = tx.send((i, Message::Done(out)));
                });
                states[i].state = State::Running;
                running += 1;
            }
            save(record)?;
            if running == 0 {
                break;
            }
            let Ok((i, message)) = rx.recv() else { break };
            let started = match message {
                Message::Progress(p) => {
                    // In the run record too, at most every two seconds.
                    record.stages[i].progress = Some(p);
                    if saved.elapsed().as_secs_f64() >= 2.0 {
                        save(record)?;
                        saved = Instant::now();
                    }
                    continue;
                }
                Message::Done(started) => started,
            };
            running -= 1;
            let (started, lock) = started?;
            let rec = &mut record.stages[i];
            let action = match started {
                Started::BuiltElsewhere => {
                    let entry = rec.entry.clone().unwrap_or_default();
                    let m = crate::cache::read_manifest(&entry);
                    rec.built_wall_s = m.as_ref().map(|m| m.wall_s);
                    rec.peak_rss_kib = m.and_then(|m| m.peak_rss_kib);
                    s.progress.finish(
                        &s.label(i),
                        &format!(
                            "cached (built meanwhile by another runner)  {}",
                            entry.display()
                        ),
                    );
                    Action::Cached
                }
                Started::Ran(outcome) => {
                    let rebuilding = states[i].rebuild_reason.is_some();
                    let action = stage_process::finish(
                        s.nodes,
                        i,
                        s.ctx,
                        s.experiment,
                        outcome,
                        rec,
                        rebuilding,
                    )?;
                    s.progress
                        .finish(&s.label(i), &stage_process::finish_message(action, rec));
                    action
                }
            };
            drop(lock);
            states[i].state = State::Done(action);
        }
        Ok(())
    })
}

/// Mark every waiting node with an input that ended without output as skipped (and
/// what needs it, in turn).
fn skip_blocked(s: &Schedule, states: &mut [NodeState], records: &mut [StageRecord]) {
    let mut changed = true;
    while changed {
        changed = false;
        for (i, node) in s.nodes.iter().enumerate() {
            if states[i].state != State::Waiting {
                continue;
            }
            let blocked = node
                .inputs
                .iter()
                .find(|x| matches!(states[x.node].state, State::Done(a) if !a.has_output()));
            if let Some(bad) = blocked {
                let why = format!("input {} did not finish", s.nodes[bad.node].stage);
                s.progress.finish(&s.label(i), &format!("skipped: {why}"));
                records[i].error = Some(why);
                states[i].state = State::Done(Action::Skipped);
                changed = true;
            }
        }
    }
}

/// The waiting nodes whose inputs all have their outputs, in run order.
fn ready(nodes: &[Node], states: &[NodeState]) -> Vec<usize> {
    (0..nodes.len())
        .filter(|&i| states[i].state == State::Waiting)
        .filter(|&i| {
            nodes[i]
                .inputs
                .iter()
                .all(|x| matches!(states[x.node].state, State::Done(a) if a.has_output()))
        })
        .collect()
}

fn start_message(st: &NodeState) -> String {
    match &st.rebuild_reason {
        Some(why) => format!("rebuilding (cache entry tampered: {why})"),
        None if st.forced => "running (forced)".to_string(),
        None => "running".to_string(),
    }
}
