//! Where each node of a run stands.

use crate::record::Action;

/// The state of a node during a run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum State {
    /// To run once its inputs have their outputs.
    Waiting,
    Running,
    Done(Action),
}

/// A node's state and why it runs.
#[derive(Clone, Debug)]
pub(crate) struct NodeState {
    pub state: State,
    /// Run even when cached (`--force` names it or a node it needs).
    pub forced: bool,
    /// Its cache entry failed verification and is rebuilt; what was wrong.
    pub rebuild_reason: Option<String>,
}
