//! `degs plan`: the stages of one experiment or of every experiment of a sweep, each
//! cache entry once (a stage shared by several experiments is one job), as shell
//! commands in dependency order, as a Snakemake file and as a Slurm array script.
//!
//! Every command writes its output directory (the cache entry) atomically; `degs run`
//! or `degs sweep` afterwards adopts the entries the scheduler wrote. Entries already
//! in the cache are left out of the Snakemake and Slurm files (they appear as plain
//! inputs) and commented out of the shell commands, unless `all`.

use crate::cache::{self, Verdict};
use crate::command_line::{command, settings_path, shell_quote};
use crate::context::Context;
use crate::experiment::Experiment;
use crate::graph::{NodeKind, output_dir};
use anyhow::Result;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// One stage run (one cache entry) of the plan.
#[derive(Clone, Debug)]
pub struct Job {
    pub stage: String,
    pub key: String,
    /// Its output directory (the cache entry).
    pub out: PathBuf,
    pub command: Vec<String>,
    /// (flag without dashes, directory): the scene directory or other jobs' outputs.
    pub inputs: Vec<(String, PathBuf)>,
    /// 0 for jobs that read only the scene; else one more than its deepest input job.
    pub level: usize,
    /// Its entry is in the cache already (sealed and intact, or written unsealed).
    pub cached: bool,
    /// The experiments that use it.
    pub experiments: Vec<String>,
}

/// Every job of a set of experiments, in dependency order, with lines for the nodes
/// that cannot run (binary missing) and the scene directories.
#[derive(Clone, Debug, Default)]
pub struct Plan {
    pub name: String,
    pub cache_root: PathBuf,
    pub jobs: Vec<Job>,
    pub notes: Vec<String>,
}

impl Plan {
    /// Resolve every experiment (writing the settings files the commands read under
    /// `runs/<experiment>/`) and merge their stages by cache entry.
    pub fn build(name: &str, exps: &[Experiment], ctx: &Context) -> Result<Plan> {
        let mut plan = Plan {
            name: name.to_string(),
            cache_root: ctx.cache.root.clone(),
            ..Plan::default()
        };
        for exp in exps {
            let nodes = crate::run::prepare(exp, ctx)?;
            for (i, n) in nodes.iter().enumerate() {
                if let NodeKind::SceneDir(d) = &n.kind {
                    let note = format!("scene: {}", d.display());
                    if !plan.notes.contains(&note) {
                        plan.notes.push(note);
                    }
                    continue;
                }
                let key = match (&n.unavailable, &n.key) {
                    (None, Some(k)) => k.clone(),
                    (why, _) => {
                        let why = why.as_deref().unwrap_or("no key");
                        let note = format!("{}: {why}", n.stage);
                        if !plan.notes.contains(&note) {
                            plan.notes.push(note);
                        }
                        continue;
                    }
                };
                if let Some(j) = plan
                    .jobs
                    .iter_mut()
                    .find(|j| j.stage == n.stage && j.key == key)
                {
                    j.experiments.push(exp.name.clone());
                    continue;
                }
                let out = ctx.cache.entry(&n.stage, &key);
                let config = settings_path(&ctx.cache, &exp.name, &n.stage);
                let inputs: Vec<(String, PathBuf)> = n
                    .inputs
                    .iter()
                    .map(|x| {
                        let dir = output_dir(&nodes, x.node, &ctx.cache).unwrap_or_default();
                        (x.flag.trim_start_matches('-').to_string(), dir)
                    })
                    .collect();
                let level = inputs
                    .iter()
                    .filter_map(|(_, d)| plan.jobs.iter().find(|j| &j.out == d))
                    .map(|j| j.level + 1)
                    .max()
                    .unwrap_or(0);
                plan.jobs.push(Job {
                    stage: n.stage.clone(),
                    command: command(&nodes, i, &ctx.cache, &out, &config),
                    cached: out.is_dir()
                        && !matches!(cache::verify(&out, false), Verdict::Tampered(_)),
                    key,
                    out,
                    inputs,
                    level,
                    experiments: vec![exp.name.clone()],
                });
            }
        }
        // stable: within a level, the order the experiments met them
        plan.jobs.sort_by_key(|j| j.level);
        Ok(plan)
    }

    /// The jobs a scheduler has to run: those not cached, or every one with `all`.
    pub fn to_run(&self, all: bool) -> impl Iterator<Item = &Job> {
        self.jobs.iter().filter(move |j| all || !j.cached)
    }

    fn header(&self, what: &str) -> String {
        format!(
            "# degs plan: {what} for {} (cache {})\n\
             # Each stage appears once, even when several experiments share it; each command\n\
             # writes its output directory atomically. `degs run` / `degs sweep` then adopt them.\n",
            self.name,
            self.cache_root.display()
        )
    }

    /// The shell commands in dependency order (jobs of one level may run at the same
    /// time); cached ones commented out unless `all`.
    pub fn shell(&self, all: bool) -> String {
        let mut s = self.header("shell commands");
        s += "set -e\n";
        for n in &self.notes {
            let _ = writeln!(s, "# {n}");
        }
        for j in &self.jobs {
            let prefix = if j.cached && !all { "# cached: " } else { "" };
            let _ = writeln!(s, "{prefix}{}", quoted(&j.command));
        }
        s
    }

    /// A Snakefile: one rule per job to run (inputs named by the stage's flags, the
    /// entry as a `directory()` output), and `all` asking for every entry.
    pub(crate) fn snakefile(&self, all: bool) -> String {
        let mut s = self.header("Snakemake rules");
        s += "# Run: snakemake -s Snakefile --cores N (or with a cluster profile).\n\n";
        s += "rule all:\n    input:\n";
        for j in &self.jobs {
            let _ = writeln!(s, "        {},", py_str(&j.out.display().to_string()));
        }
        for j in self.to_run(all) {
            let _ = write!(
                s,
                "\nrule {}:\n    # used by: {}\n    input:\n",
                rule_name(j),
                j.experiments.join(", ")
            );
            for (flag, dir) in &j.inputs {
                let _ = writeln!(s, "        {flag}={},", py_str(&dir.display().to_string()));
            }
            let _ = writeln!(
                s,
                "    output:\n        directory({})\n    shell:\n        {}",
                py_str(&j.out.display().to_string()),
                // Snakemake formats the shell string: literal braces are doubled
                py_str(&quoted(&j.command).replace('{', "{{").replace('}', "}}"))
            );
        }
        s
    }

    /// A Slurm script: run as `bash slurm.sh`, it submits one array job per level of
    /// the graph, each after the previous one succeeded (`afterok`); each array task
    /// (`slurm.sh task LEVEL`, `$SLURM_ARRAY_TASK_ID`) runs one job of that level.
    pub fn slurm(&self, all: bool, script: &Path) -> String {
        let mut levels: Vec<Vec<&Job>> = Vec::new();
        let mut last = None;
        for j in self.to_run(all) {
            if last != Some(j.level) {
                levels.push(Vec::new());
                last = Some(j.level);
            }
            levels.last_mut().expect("pushed").push(j);
        }
        let mut s = format!("#!/bin/bash\n{}", self.header("Slurm array jobs"));
        s += "# Submit with `bash slurm.sh`: one array job per level, each after the previous\n\
              # one succeeded; the tasks of a level are independent stages.\n\
              set -euo pipefail\n";
        let _ = writeln!(s, "SCRIPT={}", shell_quote(&script.display().to_string()));
        let logs = script.parent().unwrap_or(Path::new(".")).join("slurm-logs");
        let _ = writeln!(s, "LOGS={}", shell_quote(&logs.display().to_string()));
        s += "\ntask() {\n  case \"$1/$2\" in\n";
        for (l, jobs) in levels.iter().enumerate() {
            for (t, j) in jobs.iter().enumerate() {
                let _ = writeln!(s, "    {l}/{t}) # {} {}", j.stage, j.key);
                let _ = writeln!(s, "      {} ;;", quoted(&j.command));
            }
        }
        s += "    *) echo \"slurm.sh: no task $2 at level $1\" >&2; exit 2 ;;\n  esac\n}\n\n";
        s += "if [ \"${1:-}\" = task ]; then\n  \
              task \"$2\" \"${SLURM_ARRAY_TASK_ID:?not run as a Slurm array task}\"\n  exit\nfi\n\n";
        s += "mkdir -p \"$LOGS\"\nprev=\nsubmit() {\n  local dep=()\n  \
              if [ -n \"$prev\" ]; then dep=(--dependency=\"afterok:$prev\"); fi\n  \
              prev=$(sbatch --parsable --job-name=degs-plan --output=\"$LOGS/%A_%a.log\" \
              --array=0-$(($2 - 1)) ${dep[@]+\"${dep[@]}\"} \"$SCRIPT\" task \"$1\")\n  \
              prev=${prev%%;*}\n  echo \"level $1: $2 task(s), job $prev\"\n}\n";
        for (l, jobs) in levels.iter().enumerate() {
            let _ = writeln!(s, "submit {l} {}", jobs.len());
        }
        if levels.is_empty() {
            s += "echo \"nothing to run: every stage is cached\"\n";
        }
        s
    }
}

/// `stage_<first 12 of the key>`: unique (keys are) and a Python identifier.
pub(crate) fn rule_name(j: &Job) -> String {
    format!("{}_{}", j.stage, &j.key[..j.key.len().min(12)])
}

fn quoted(args: &[String]) -> String {
    args.iter()
        .map(|a| shell_quote(a))
        .collect::<Vec<_>>()
        .join(" ")
}

/// A Python string literal (a JSON string is one).
fn py_str(s: &str) -> String {
    serde_json::to_string(s).unwrap_or_default()
}

/// Write the plan's Snakefile and slurm.sh under `runs/<name>/`; their paths.
pub fn write_files(plan: &Plan, ctx: &Context, all: bool) -> Result<(PathBuf, PathBuf)> {
    let dir = ctx.cache.run_dir(&plan.name);
    let snake = dir.join("Snakefile");
    let slurm = dir.join("slurm.sh");
    scene::atomic::write_bytes_atomic(&snake, plan.snakefile(all).as_bytes())?;
    scene::atomic::write_bytes_atomic(&slurm, plan.slurm(all, &slurm).as_bytes())?;
    Ok((snake, slurm))
}
