//! Scheduling the waiting nodes of a run: each starts, on its own thread, once every
//! input has its output, at most `jobs` at a time; one whose input ended without
//! output is skipped. The run record is saved after every change.

use super::stage_process;
use super::state::{NodeState, State};
use crate::context::Context;
use crate::graph::Node;
use crate::process::{self, Outcome};
use crate::progress::Progress;
use crate::record::{Action, RunRecord, StageRecord};
use anyhow::Result;
use std::sync::mpsc;

/// What the scheduler runs, and where.
pub struct Schedule<'a> {
    pub nodes: &'a [Node],
    pub ctx: &'a Context,
    /// The experiment's name (its settings files and logs are under `runs/<name>/`).
    pub experiment: &'a str,
    /// Stages run at the same time (at least 1).
    pub jobs: usize,
    pub progress: &'a Progress,
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
        let (tx, rx) = mpsc::channel::<(usize, Result<Outcome>)>();
        let mut running = 0usize;
        loop {
            skip_blocked(s, states, &mut record.stages);
            for i in ready(s.nodes, states).into_iter().take(jobs - running) {
                let args = stage_process::start(s.nodes, i, s.ctx, s.experiment)?;
                s.progress
                    .start(&s.nodes[i].stage, &start_message(&states[i]));
                let (tx, progress) = (tx.clone(), s.progress);
                let stage = s.nodes[i].stage.clone();
                scope.spawn(move || {
                    let out = process::run(&args, &|line| progress.output(&stage, line));
                    let _ = tx.send((i, out));
                });
                states[i].state = State::Running;
                running += 1;
            }
            save(record)?;
            if running == 0 {
                break;
            }
            let Ok((i, outcome)) = rx.recv() else { break };
            running -= 1;
            let rec = &mut record.stages[i];
            let rebuilding = states[i].rebuild_reason.is_some();
            let action =
                stage_process::finish(s.nodes, i, s.ctx, s.experiment, outcome, rec, rebuilding)?;
            s.progress.finish(
                &s.nodes[i].stage,
                &stage_process::finish_message(action, rec),
            );
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
                s.progress.finish(&node.stage, &format!("skipped: {why}"));
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
