//! Running one stage process: output tail, exit status, wall time and peak memory.

use anyhow::{Context, Result};
use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Read};
use std::os::unix::process::CommandExt;
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::time::Instant;

/// Lines of output kept for the log and the error message.
pub(crate) const TAIL_LINES: usize = 200;
const MAX_LINE: usize = 2000;

/// How a stage process ended.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// Exit code when it exited; None when killed by a signal.
    pub code: Option<i32>,
    pub signal: Option<i32>,
    pub wall_s: f64,
    /// Peak resident set size of the process (ru_maxrss from wait4), KiB.
    pub peak_rss_kib: Option<u64>,
    /// The last [`TAIL_LINES`] lines of stdout and stderr, interleaved as read.
    pub tail: Vec<String>,
}

impl Outcome {
    pub fn success(&self) -> bool {
        self.code == Some(0)
    }
    /// One line saying what went wrong: the last non-empty output line, else the status.
    pub fn error_line(&self) -> String {
        let status = match (self.code, self.signal) {
            (_, Some(s)) => format!("killed by signal {s}"),
            (Some(c), None) => format!("exit status {c}"),
            (None, None) => "unknown exit status".to_string(),
        };
        match self.tail.iter().rev().find(|l| !l.trim().is_empty()) {
            Some(l) => format!("{} ({status})", l.trim()),
            None => status,
        }
    }
}

/// Run `args[0]` with `args[1..]`, calling `on_line` for each output line. The child
/// is killed (SIGKILL) if this thread's process dies, so an interrupted runner leaves
/// no orphan writing into the cache. `threads`: the child's share of the cores
/// (`RAYON_NUM_THREADS`, unless the user set it), when several experiments run at once.
pub fn run(
    args: &[String],
    threads: Option<usize>,
    on_line: &(dyn Fn(&str) + Sync),
) -> Result<Outcome> {
    let mut cmd = Command::new(&args[0]);
    if let Some(n) = threads
        && std::env::var_os("RAYON_NUM_THREADS").is_none()
    {
        cmd.env("RAYON_NUM_THREADS", n.max(1).to_string());
    }
    cmd.args(&args[1..])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    // SAFETY: prctl is async-signal-safe; the closure allocates nothing.
    unsafe {
        cmd.pre_exec(|| {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL as libc::c_ulong);
            Ok(())
        });
    }
    let start = Instant::now();
    let mut child = cmd
        .spawn()
        .with_context(|| format!("{}: cannot start", args[0]))?;
    let pid = child.id() as libc::pid_t;
    let stdout = child.stdout.take();
    let stderr = child.stderr.take();
    let tail = Mutex::new(VecDeque::with_capacity(TAIL_LINES));
    let (status, rusage) = std::thread::scope(|s| {
        let tail = &tail;
        let read = move |r: Box<dyn Read + Send>| {
            for line in BufReader::new(r).split(b'\n').map_while(|l| l.ok()) {
                let mut line = String::from_utf8_lossy(&line).trim_end().to_string();
                line.truncate(line.floor_char_boundary(MAX_LINE));
                on_line(&line);
                let mut t = tail.lock().unwrap_or_else(|e| e.into_inner());
                if t.len() == TAIL_LINES {
                    t.pop_front();
                }
                t.push_back(line);
            }
        };
        if let Some(o) = stdout {
            s.spawn(move || read(Box::new(o)));
        }
        if let Some(e) = stderr {
            s.spawn(move || read(Box::new(e)));
        }
        wait4(pid)
    });
    drop(child);
    let (code, signal) = if libc::WIFEXITED(status) {
        (Some(libc::WEXITSTATUS(status)), None)
    } else if libc::WIFSIGNALED(status) {
        (None, Some(libc::WTERMSIG(status)))
    } else {
        (None, None)
    };
    Ok(Outcome {
        code,
        signal,
        wall_s: start.elapsed().as_secs_f64(),
        peak_rss_kib: rusage.map(|r| r.ru_maxrss.max(0) as u64),
        tail: tail.into_inner().unwrap_or_default().into(),
    })
}

/// Wait for `pid`, returning its wait status and resource usage (peak memory).
fn wait4(pid: libc::pid_t) -> (libc::c_int, Option<libc::rusage>) {
    let mut status: libc::c_int = 0;
    // SAFETY: rusage is plain old data; wait4 fills it.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    loop {
        // SAFETY: valid pointers to locals; pid is our own child.
        let r = unsafe { libc::wait4(pid, &mut status, 0, &mut ru) };
        if r == pid {
            return (status, Some(ru));
        }
        if r < 0 && std::io::Error::last_os_error().kind() == std::io::ErrorKind::Interrupted {
            continue;
        }
        return (status, None);
    }
}

/// "123 MiB" from KiB.
pub fn fmt_kib(kib: Option<u64>) -> String {
    match kib {
        None => "-".into(),
        Some(k) if k >= 1 << 20 => format!("{:.2} GiB", k as f64 / (1u64 << 20) as f64),
        Some(k) => format!("{:.1} MiB", k as f64 / 1024.0),
    }
}

/// A stage's share of the cores when `at_once` experiments run at the same time: None
/// for one (it has them all), else the cores divided evenly, at least one each. The
/// stages of one experiment (`-j`) each get the experiment's whole share: a stage's
/// thread pool is sized once at its start, and the stages beside it often end long
/// before it (LoCM beside the warm-up), so an even split left the warm-up on half the
/// cores for most of its run.
pub fn thread_share(at_once: usize) -> Option<usize> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    (at_once > 1).then(|| (cores / at_once).max(1))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sh(script: &str) -> Outcome {
        run(
            &["/bin/sh".into(), "-c".into(), script.into()],
            None,
            &|_| {},
        )
        .unwrap()
    }

    #[test]
    fn a_stage_gets_its_share_of_the_threads() {
        let args = [
            "/bin/sh".into(),
            "-c".into(),
            "echo t=$RAYON_NUM_THREADS".into(),
        ];
        let out = run(&args, Some(3), &|_| {}).unwrap();
        let expected = match std::env::var("RAYON_NUM_THREADS") {
            Ok(user) => format!("t={user}"),
            Err(_) => "t=3".to_string(),
        };
        assert_eq!(out.tail, vec![expected]);
        let cores = std::thread::available_parallelism().unwrap().get();
        assert_eq!(thread_share(1), None);
        assert_eq!(thread_share(2), Some((cores / 2).max(1)));
        assert_eq!(thread_share(10 * cores), Some(1));
    }

    #[test]
    fn exit_codes_signals_and_tail() {
        let ok = sh("echo one; echo two >&2");
        assert!(ok.success());
        assert_eq!(ok.tail.len(), 2);
        assert!(ok.peak_rss_kib.unwrap() > 0);
        let bad = sh("echo 'error: scene/x.json: bad magic' >&2; exit 3");
        assert_eq!(bad.code, Some(3));
        assert_eq!(
            bad.error_line(),
            "error: scene/x.json: bad magic (exit status 3)"
        );
        let killed = sh("kill -9 $$");
        assert_eq!(killed.signal, Some(9));
        assert_eq!(killed.error_line(), "killed by signal 9");
    }

    #[test]
    fn long_output_keeps_only_the_tail() {
        let o = sh("i=0; while [ $i -lt 500 ]; do echo line$i; i=$((i+1)); done");
        assert_eq!(o.tail.len(), TAIL_LINES);
        assert_eq!(o.tail.last().unwrap(), "line499");
    }

    #[test]
    fn missing_binary_is_an_error() {
        let e = run(&["/nonexistent/stage".into()], None, &|_| {}).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/stage"));
    }
}
