//! One stage run as a process: before it, a clean temp dir and its command line;
//! after it, its output sealed and moved into the cache (or its failure recorded),
//! and its log written.

use crate::cache;
use crate::command_line::{command, settings_path, shell_quote};
use crate::context::Context;
use crate::graph::Node;
use crate::lock::EntryLock;
use crate::process::{Outcome, fmt_kib};
use crate::record::{Action, StageRecord};
use anyhow::{Result, bail};
use std::fs;
use std::path::{Path, PathBuf};

/// The command line of node `i` (its output goes to its temp dir).
pub fn start(nodes: &[Node], i: usize, ctx: &Context, exp: &str) -> Result<Vec<String>> {
    let nd = &nodes[i];
    let key = nd.key.as_deref().unwrap_or_default();
    let tmp = ctx.cache.temp_entry(&nd.stage, key);
    fs::create_dir_all(ctx.cache.stage_dir(&nd.stage))?;
    let config = settings_path(&ctx.cache, exp, &nd.stage);
    Ok(command(nodes, i, &ctx.cache, &tmp, &config))
}

/// What a node's thread found once it held the entry's lock.
pub enum Started {
    /// Another runner built the entry while this one waited: use it.
    BuiltElsewhere,
    /// The stage ran (or could not start).
    Ran(Result<Outcome>),
}

/// On node `i`'s own thread: take the entry's lock (waiting for a runner that builds
/// it), use the entry if that runner sealed it meanwhile, else clear the temp dir and
/// run `args`. `reuse`: an entry found then may be used (not when the node is forced or
/// rebuilds a tampered entry). The lock is returned, to be held until the output is in
/// place.
pub fn lock_and_run(
    nodes: &[Node],
    i: usize,
    ctx: &Context,
    (args, reuse, threads): (&[String], bool, Option<usize>),
    on_line: &(dyn Fn(&str) + Sync),
) -> Result<(Started, EntryLock)> {
    let nd = &nodes[i];
    let key = nd.key.as_deref().unwrap_or_default();
    let lock = match EntryLock::try_take(&ctx.cache, &nd.stage, key)? {
        Some(l) => l,
        None => {
            on_line("waiting: another runner is building this cache entry");
            EntryLock::take(&ctx.cache, &nd.stage, key)?
        }
    };
    let entry = ctx.cache.entry(&nd.stage, key);
    if reuse && cache::read_manifest(&entry).is_some() {
        return Ok((Started::BuiltElsewhere, lock));
    }
    let tmp = ctx.cache.temp_entry(&nd.stage, key);
    if tmp.exists() {
        fs::remove_dir_all(&tmp)?;
    }
    Ok((
        Started::Ran(crate::process::run(args, threads, on_line)),
        lock,
    ))
}

/// Seal and move a finished stage into place (or record its failure); write its log.
pub fn finish(
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
    let config = settings_path(&ctx.cache, exp, &nd.stage);
    let args = command(nodes, i, &ctx.cache, &tmp, &config);
    let log = ctx.cache.run_dir(exp).join(format!("{}.log", nd.stage));
    rec.log = Some(log.clone());
    let mut action = Action::Failed;
    let mut text = format!(
        "$ {}\n",
        args.iter()
            .map(|a| shell_quote(a))
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
            text += &log_summary(&out);
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

/// Exit status, wall time, peak memory and the output tail, for the stage's log.
fn log_summary(out: &Outcome) -> String {
    let mut text = format!(
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
    text
}

/// The progress line of a finished stage.
pub(crate) fn finish_message(action: Action, rec: &StageRecord) -> String {
    match action {
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
    }
}

/// Rename `tmp` to `entry`; an existing entry (forced or tampered) is moved aside first.
fn commit_entry(tmp: &Path, entry: &Path) -> Result<()> {
    if entry.exists() {
        let mut old = entry.as_os_str().to_os_string();
        old.push(".old");
        let old = scene::atomic::temp_path(&PathBuf::from(old));
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
