//! The cache check at the start of a run: which nodes are excluded (`--until`), cannot
//! run (binary missing, an input unavailable), are the scene directory, or are cached
//! (a sealed entry that verifies; an unsealed one, written by a command from `degs
//! plan`, is adopted). Everything else waits to run; a tampered entry is rebuilt.

use super::state::{NodeState, State};
use crate::cache::{self, Verdict};
use crate::graph::{self, Node, NodeKind};
use crate::progress::Progress;
use crate::record::{Action, StageRecord};
use anyhow::Result;

/// What the run is asked for: `until` runs only that node and what it needs; `force`
/// re-runs those nodes and what needs them even when cached.
pub(crate) struct Request<'a> {
    pub until: Option<usize>,
    pub force: &'a [usize],
    /// Re-hash every cached file instead of trusting unchanged size + mtime.
    pub verify_full: bool,
}

/// The state of every node before anything runs; fills in the records of the nodes
/// that are done already (cached, unavailable, skipped) and reports them.
pub fn check(
    nodes: &[Node],
    request: &Request,
    records: &mut [StageRecord],
    (progress, label): (&Progress, &dyn Fn(usize) -> String),
) -> Result<Vec<NodeState>> {
    let n = nodes.len();
    let included = match request.until {
        Some(u) => graph::ancestors(nodes, u),
        None => vec![true; n],
    };
    let mut forced = vec![false; n];
    for &f in request.force {
        for (i, d) in graph::descendants(nodes, f).into_iter().enumerate() {
            forced[i] |= d;
        }
    }
    let mut states = Vec::with_capacity(n);
    for (i, nd) in nodes.iter().enumerate() {
        let mut st = NodeState {
            state: State::Waiting,
            forced: forced[i],
            rebuild_reason: None,
        };
        if included[i] {
            check_node(
                nd,
                &mut st,
                request.verify_full,
                &mut records[i],
                (progress, &label(i)),
            )?;
        } else {
            st.state = State::Done(Action::NotRequested);
        }
        states.push(st);
    }
    Ok(states)
}

fn check_node(
    nd: &Node,
    st: &mut NodeState,
    verify_full: bool,
    rec: &mut StageRecord,
    (progress, label): (&Progress, &str),
) -> Result<()> {
    if let Some(why) = &nd.unavailable {
        let action = if nd.binary.is_none() {
            Action::Unavailable
        } else {
            Action::Skipped
        };
        rec.error = Some(why.clone());
        st.state = State::Done(action);
        progress.finish(label, why);
        return Ok(());
    }
    if let NodeKind::Given(_) = &nd.kind {
        st.state = State::Done(Action::Cached);
        return Ok(());
    }
    if let NodeKind::SceneDir(d) = &nd.kind {
        st.state = State::Done(Action::Cached);
        progress.finish(label, &format!("scene directory {}", d.display()));
        return Ok(());
    }
    let entry = rec.entry.clone().unwrap_or_default();
    if !entry.is_dir() {
        return Ok(());
    }
    match cache::verify(&entry, verify_full) {
        Verdict::Ok if !st.forced => st.state = State::Done(Action::Cached),
        Verdict::Unsealed if !st.forced => {
            // Written by a stage command from `degs plan`: adopt it, at the wall time
            // its report gives (what it cost, for `degs chart`).
            cache::seal(
                &entry,
                &nd.stage,
                nd.key.as_deref().unwrap_or(""),
                cache::report_wall_s(&entry).unwrap_or(0.0),
                None,
            )?;
            st.state = State::Done(Action::Cached);
        }
        Verdict::Tampered(why) => st.rebuild_reason = Some(why),
        _ => {}
    }
    if st.state == State::Done(Action::Cached) {
        let m = cache::read_manifest(&entry);
        rec.built_wall_s = m.as_ref().map(|m| m.wall_s);
        rec.peak_rss_kib = m.and_then(|m| m.peak_rss_kib);
        progress.finish(label, &format!("cached  {}", entry.display()));
    }
    Ok(())
}
