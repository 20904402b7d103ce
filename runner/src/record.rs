//! `runs/<name>/run.json`: what a run did, stage by stage.

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// What happened to a stage in a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Action {
    /// Its entry was already in the cache: nothing ran.
    Cached,
    /// It ran and its entry was sealed.
    Ran,
    /// Its entry failed verification (tampered) and it ran again.
    Rebuilt,
    /// It ran and failed.
    Failed,
    /// Not run because an input failed or is unavailable.
    Skipped,
    /// No binary for it.
    Unavailable,
    /// Excluded by `--until`.
    NotRequested,
    /// The run was interrupted before this stage finished.
    Pending,
}

impl Action {
    pub fn as_str(self) -> &'static str {
        match self {
            Action::Cached => "cached",
            Action::Ran => "ran",
            Action::Rebuilt => "rebuilt",
            Action::Failed => "failed",
            Action::Skipped => "skipped",
            Action::Unavailable => "unavailable",
            Action::NotRequested => "not-requested",
            Action::Pending => "pending",
        }
    }
    /// A requested stage that could not run: no binary, or an input not made.
    pub fn could_not_run(self) -> bool {
        matches!(self, Action::Unavailable | Action::Skipped)
    }
    /// The stage's output exists after the run.
    pub fn has_output(self) -> bool {
        matches!(self, Action::Cached | Action::Ran | Action::Rebuilt)
    }
}

/// One stage of a run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StageRecord {
    pub stage: String,
    pub action: Action,
    pub key: Option<String>,
    pub binary: Option<PathBuf>,
    pub binary_hash: Option<String>,
    /// Canonical settings the key was computed from.
    pub settings: serde_json::Value,
    /// Input flag → key of the input.
    pub inputs: BTreeMap<String, String>,
    /// The cache entry (or scene directory) holding its outputs.
    pub entry: Option<PathBuf>,
    /// Wall time of this run's execution (0 when cached).
    pub wall_s: f64,
    /// Wall time of the run that built the entry.
    pub built_wall_s: Option<f64>,
    /// Peak resident memory of the stage process (KiB).
    pub peak_rss_kib: Option<u64>,
    pub exit_status: Option<i32>,
    /// Last line of the stage's error output when it failed; why it was skipped.
    pub error: Option<String>,
    pub log: Option<PathBuf>,
    /// The stage's last progress line, read (phase, position, time left); kept after it
    /// ends. Absent for stages that said none (and in records of older runners).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub progress: Option<crate::stage_progress::StageProgress>,
    /// What its `report.json` says a user must know about its result (its `warnings`,
    /// [`report_warnings`]); `degs run` and `degs eval` print them.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

/// A whole run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RunRecord {
    pub experiment: String,
    pub experiment_file: Option<PathBuf>,
    pub cache_root: PathBuf,
    /// "running", "ok", "failed" or "incomplete" (a requested stage could not run).
    pub status: String,
    pub started_unix: u64,
    pub wall_s: f64,
    pub jobs: usize,
    pub stages: Vec<StageRecord>,
}

impl RunRecord {
    pub fn read(path: &Path) -> Result<RunRecord> {
        let bytes =
            std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
        serde_json::from_slice(&bytes)
            .with_context(|| format!("{}: not a degs run record", path.display()))
    }
    pub fn write(&self, path: &Path) -> Result<()> {
        scene::atomic::write_json_atomic(path, self)?;
        Ok(())
    }
    pub fn stage(&self, name: &str) -> Option<&StageRecord> {
        self.stages.iter().find(|s| s.stage == name)
    }
}

/// The `warnings` (an array of strings) of the `report.json` in a stage's output
/// directory `entry`; none when it has no report or the report says none.
pub fn report_warnings(entry: &Path) -> Vec<String> {
    let Ok(bytes) = std::fs::read(entry.join("report.json")) else {
        return Vec::new();
    };
    let Ok(v) = serde_json::from_slice::<serde_json::Value>(&bytes) else {
        return Vec::new();
    };
    (v.get("warnings")
        .and_then(|w| w.as_array())
        .into_iter()
        .flatten())
    .filter_map(|w| w.as_str().map(str::to_string))
    .collect()
}

/// The lines `degs run` and `degs eval` print for the stages' warnings, one per warning
/// (`warning (STAGE): …`).
pub fn warning_lines(stages: &[StageRecord]) -> Vec<String> {
    (stages.iter())
        .flat_map(|s| (s.warnings.iter()).map(move |w| format!("warning ({}): {w}", s.stage)))
        .collect()
}

pub(crate) fn now_unix() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0)
}
