//! Fake stage binaries and a scratch cache for runner tests.
#![allow(dead_code)]

use std::fs;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A shell script that behaves like a stage: answers `settings --defaults` (one key)
/// and `settings --check -` (refuses a table with a key `bogus` or `iteratons`, the
/// misspelling the tests use, naming it; names the file of a
/// `weights = "…"` line as the file it would read), takes an optional verb
/// (`finetune`, `train`), checks its inputs, records its invocation in $DEGS_FAKE_LOG, writes
/// $DEGS_FAKE_REPORTS/<stage>.json as its report when that exists (as `gaussians`, copies
/// the scene's test images as its renders and its novel views as `renders/novel/`), fails when its settings say `seed = 666`,
/// sleeps 30 s when $DEGS_FAKE_SLEEP names it and 1 s when $DEGS_FAKE_PAUSE does,
/// prints ten progress lines as the stage kit does when $DEGS_FAKE_PROGRESS names it, meets the other stages named in
/// $DEGS_FAKE_MEET when it is one of them (see [`Fixture::meeting`]), and writes a few output
/// files.
pub const FAKE_STAGE: &str = r#"#!/bin/sh
stage=$(basename "$0")
all="$*"
if [ "$1" = settings ]; then
  case "$2" in
    --defaults) echo 'seed = 0' ;;
    --check)
      input=$(cat)
      bad=$(printf '%s\n' "$input" | sed -n 's/^\(bogus\|iteratons\) = .*/\1/p' | head -n 1)
      if [ -n "$bad" ]; then
        echo "$stage: error: key \`$bad\`: unknown field \`$bad\`" >&2; exit 1
      fi
      printf '%s\n' "$input" | grep '^weights = ' || true ;;
    *) echo "$stage: error: settings: give --defaults or --check FILE" >&2; exit 2 ;;
  esac
  exit 0
fi
scene=
verb=
case "$1" in --*|"") ;; *) verb="$1"; shift ;; esac
out=; config=
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out="$2"; shift 2 ;;
    --config) config="$2"; shift 2 ;;
    --scene|--model|--flows|--assoc)
      [ -d "$2" ] || { echo "error: $1 $2: not a directory" >&2; exit 2; }
      [ "$1" = "--scene" ] && scene="$2"
      shift 2 ;;
    *) echo "error: unknown argument $1" >&2; exit 2 ;;
  esac
done
[ -n "$out" ] && [ -f "$config" ] || { echo "error: need --out and --config" >&2; exit 2; }
echo "start $stage $all" >> "$DEGS_FAKE_LOG"
echo "$stage: reading $config" >&2
if grep -q '^seed = 666' "$config"; then
  echo "progress line before the failure" >&2
  echo "error: $config: seed = 666 asks for a failure" >&2
  exit 3
fi
mkdir -p "$out/renders"
case " $DEGS_FAKE_PAUSE " in *" $stage "*) sleep 1 ;; esac
case " $DEGS_FAKE_PROGRESS " in *" $stage "*)
  for k in 1 2 3 4 5 6 7 8 9 10; do echo "[    $k.0 s] iteration $k/10: loss 0.$k" >&2; done ;;
esac
if [ "$DEGS_FAKE_SLEEP" = "$stage" ]; then
  echo partial > "$out/partial.txt"
  sleep 30
fi
case " $DEGS_FAKE_MEET " in *" $stage "*)
  touch "$DEGS_FAKE_MEET_DIR/$stage"
  for other in $DEGS_FAKE_MEET; do
    waited=0
    while [ ! -e "$DEGS_FAKE_MEET_DIR/$other" ]; do
      if [ "$waited" -ge "$DEGS_FAKE_MEET_TRIES" ]; then
        echo "error: $stage waited in vain for $other to start: they did not run at the same time" >&2
        exit 4
      fi
      sleep 0.1; waited=$((waited+1))
    done
  done ;;
esac
cp "$config" "$out/settings.toml"
echo "$stage output" > "$out/result.txt"
if [ -n "$DEGS_FAKE_REPORTS" ] && [ -f "$DEGS_FAKE_REPORTS/$stage.json" ]; then
  cp "$DEGS_FAKE_REPORTS/$stage.json" "$out/report.json"
else
  printf '{"stage": "%s"}\n' "$stage" > "$out/report.json"
fi
if [ "$stage" = gaussians ] && [ -d "$scene/images" ]; then
  i=0
  for f in "$scene"/images/test_*.png; do
    cp "$f" "$out/renders/$(printf %04d $i).png"; i=$((i+1))
  done
  i=0
  for f in "$scene"/images/novel_*.png; do
    [ -f "$f" ] || continue
    mkdir -p "$out/renders/novel"
    cp "$f" "$out/renders/novel/$(printf %04d $i).png"; i=$((i+1))
  done
fi
echo "end $stage" >> "$DEGS_FAKE_LOG"
"#;

/// The fixture's scene: 32×24, 0.25 s, train frames at k/8 s, two test frames between
/// them (a real scene, as `degs run` checks the scene before any stage starts).
pub fn tiny_scene_config() -> synth::SynthConfig {
    let set: toml::Table = "width = 32\nheight = 24\nduration = 0.25\nrender_rate_hz = 200\n\
                            test_frames = 2\nsupersample = 1\nframe_supersample = 1\n"
        .parse()
        .unwrap();
    runner::experiment::synth_config("rigid", &set).unwrap()
}

pub struct Fixture {
    pub dir: tempfile::TempDir,
    pub stages: PathBuf,
    pub cache: PathBuf,
    pub scene: PathBuf,
    pub log: PathBuf,
}

impl Fixture {
    /// Fake binaries for every external stage (the real `evaluate` and `synth`) and a
    /// scene directory.
    pub fn new() -> Fixture {
        let dir = tempfile::tempdir().unwrap();
        let stages = dir.path().join("bin");
        fs::create_dir_all(&stages).unwrap();
        for s in ["evflow", "gaussians", "assoc", "deform"] {
            let p = stages.join(s);
            fs::write(&p, FAKE_STAGE).unwrap();
            fs::set_permissions(&p, fs::Permissions::from_mode(0o755)).unwrap();
        }
        // The evaluation and the synthetic scenes are real: this build's `evaluate`
        // and `synth` (built beside `degs` by `cargo test --workspace`; without them,
        // `degs` says how to build them).
        for real in ["evaluate", "synth"] {
            let bin = Path::new(env!("CARGO_BIN_EXE_degs")).with_file_name(real);
            if bin.is_file() {
                std::os::unix::fs::symlink(&bin, stages.join(real)).unwrap();
            }
        }
        let scene = dir.path().join("scene");
        synth::write_synthetic_scene(&tiny_scene_config(), &scene).unwrap();
        Fixture {
            cache: dir.path().join("cache-root"),
            log: dir.path().join("invocations.log"),
            stages,
            scene,
            dir,
        }
    }

    /// Write an experiment on the fixture's scene; `body` holds the stage tables.
    pub fn experiment(&self, name: &str, body: &str) -> PathBuf {
        let p = self.dir.path().join(format!("{name}.toml"));
        let text = format!(
            "name = \"{name}\"\n[scene]\ndir = \"{}\"\n{body}",
            self.scene.display()
        );
        fs::write(&p, text).unwrap();
        p
    }

    pub fn command(&self, args: &[&str]) -> Command {
        let mut c = Command::new(env!("CARGO_BIN_EXE_degs"));
        c.args(args)
            .arg("--cache")
            .arg(&self.cache)
            .arg("--stages")
            .arg(&self.stages)
            .env("DEGS_FAKE_LOG", &self.log)
            .env_remove("DEGS_FAKE_SLEEP")
            .env_remove("DEGS_FAKE_PAUSE")
            .env_remove("DEGS_FAKE_PROGRESS")
            .env_remove("DEGS_FAKE_MEET");
        c
    }

    /// `command` with the stages named in `stages` meeting: each leaves a marker in
    /// a directory of the fixture when it starts and waits until the others' markers
    /// are there, at most `max_wait_tenths` × 0.1 s; then it fails saying whom it
    /// waited for. They all succeed only when they run at the same time.
    pub fn meeting(&self, args: &[&str], stages: &str, max_wait_tenths: u32) -> Command {
        let dir = self.dir.path().join("meet");
        fs::create_dir_all(&dir).unwrap();
        let mut c = self.command(args);
        c.env("DEGS_FAKE_MEET", stages)
            .env("DEGS_FAKE_MEET_DIR", dir)
            .env("DEGS_FAKE_MEET_TRIES", max_wait_tenths.to_string());
        c
    }

    pub fn degs(&self, args: &[&str]) -> Output {
        self.command(args).output().unwrap()
    }

    /// `degs run EXP`, asserting success.
    pub fn run_ok(&self, exp: &Path, extra: &[&str]) {
        let mut args = vec!["run", exp.to_str().unwrap()];
        args.extend_from_slice(extra);
        let out = self.degs(&args);
        assert!(
            out.status.success(),
            "degs run failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }

    pub fn record(&self, name: &str) -> serde_json::Value {
        let p = self.cache.join("runs").join(name).join("run.json");
        serde_json::from_slice(&fs::read(&p).unwrap()).unwrap()
    }

    /// (stage, action) of the last run of `name`.
    pub fn actions(&self, name: &str) -> Vec<(String, String)> {
        self.record(name)["stages"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| {
                (
                    s["stage"].as_str().unwrap().to_string(),
                    s["action"].as_str().unwrap().to_string(),
                )
            })
            .collect()
    }

    pub fn action(&self, name: &str, stage: &str) -> String {
        self.actions(name)
            .into_iter()
            .find(|(s, _)| s == stage)
            .map(|(_, a)| a)
            .unwrap()
    }

    pub fn key(&self, name: &str, stage: &str) -> String {
        let r = self.record(name);
        let s = r["stages"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["stage"] == stage)
            .unwrap();
        s["key"].as_str().unwrap().to_string()
    }

    /// Position of the first line of the invocation log that starts with `prefix`
    /// (`start evflow `, `end gaussians`): lines are appended as stages start and end.
    pub fn log_position(&self, prefix: &str) -> usize {
        fs::read_to_string(&self.log)
            .unwrap_or_default()
            .lines()
            .position(|l| l.starts_with(prefix))
            .unwrap_or_else(|| panic!("no line starting with {prefix:?} in the log"))
    }

    /// Stage names in the order they were started.
    pub fn started(&self) -> Vec<String> {
        fs::read_to_string(&self.log)
            .unwrap_or_default()
            .lines()
            .filter(|l| l.starts_with("start "))
            .map(|l| l.split(' ').nth(1).unwrap().to_string())
            .collect()
    }

    /// Every path under the cache root whose name contains `.degs-tmp-`.
    pub fn temp_paths(&self) -> Vec<PathBuf> {
        fn walk(d: &Path, out: &mut Vec<PathBuf>) {
            for e in fs::read_dir(d).into_iter().flatten().flatten() {
                let p = e.path();
                if e.file_name()
                    .to_string_lossy()
                    .contains(scene::atomic::TEMP_SUFFIX)
                {
                    out.push(p.clone());
                }
                if p.is_dir() {
                    walk(&p, out);
                }
            }
        }
        let mut out = Vec::new();
        walk(&self.cache, &mut out);
        out
    }
}

/// `degs ARGS` as a user runs it (no fixture cache or stages).
pub fn degs(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_degs"))
        .args(args)
        .output()
        .unwrap()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).to_string()
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).to_string()
}
