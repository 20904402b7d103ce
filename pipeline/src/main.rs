//! `degs`: run DEGS experiments stage by stage with a content-addressed cache.

use anyhow::{Result, anyhow};
use clap::{Args, Parser, Subcommand};
use pipeline::cache::Cache;
use pipeline::experiment::Experiment;
use pipeline::graph::{self, Context};
use pipeline::progress::Progress;
use pipeline::runner::{self, RunOptions};
use std::path::PathBuf;

/// Reconstruct a dynamic scene as 3D Gaussians from events + sparse RGB frames.
///
/// degs chains the stage binaries (synth → evflow, gaussians → assoc → deform) like
/// make: each stage's output is cached under a key made of its binary, its settings
/// and its inputs' keys, so re-running resumes where it stopped and experiments share
/// work. Start with `degs demo`.
#[derive(Parser)]
#[command(name = "degs", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Args, Clone)]
struct Where {
    /// Cache root: holds cache/<stage>/<key>/ and runs/<name>/ [env: DEGS_CACHE]
    /// [default: ./degs-cache]
    #[arg(long, value_name = "DIR")]
    cache: Option<PathBuf>,
    /// Look for stage binaries only in DIR (default: next to degs, then PATH)
    /// [env: DEGS_STAGE_DIR]
    #[arg(long, value_name = "DIR")]
    stages: Option<PathBuf>,
}

impl Where {
    fn context(&self) -> Result<Context> {
        let root = self
            .cache
            .clone()
            .or_else(|| std::env::var_os("DEGS_CACHE").map(PathBuf::from))
            .unwrap_or_else(|| PathBuf::from("degs-cache"));
        let stages = self
            .stages
            .clone()
            .or_else(|| std::env::var_os("DEGS_STAGE_DIR").map(PathBuf::from));
        Context::new(Cache::new(root), stages)
    }
}

#[derive(Subcommand)]
enum Command {
    /// Run an experiment: every stage not already cached, in dependency order.
    Run {
        /// Experiment file (TOML: name, [scene], [evflow], [gaussians], [assoc], [deform])
        experiment: PathBuf,
        #[command(flatten)]
        place: Where,
        /// Stop after this stage (runs only it and what it needs)
        #[arg(long, value_name = "STAGE")]
        until: Option<String>,
        /// Re-run this stage and everything after it even when cached (repeatable)
        #[arg(long, value_name = "STAGE")]
        force: Vec<String>,
        /// Stages to run at the same time (evflow and gaussians are independent)
        #[arg(short = 'j', long, default_value_t = 1)]
        jobs: usize,
        /// Re-hash every cached file (default: only files whose size or mtime changed)
        #[arg(long)]
        verify: bool,
        /// No progress lines
        #[arg(short, long)]
        quiet: bool,
    },
    /// Experiment files.
    Config {
        #[command(subcommand)]
        command: ConfigCommand,
    },
    /// Write a synthetic scene directory with ground truth (depth, flow, per-event flow).
    Synth {
        /// Preset: static, rigid, nonrigid, fast
        #[arg(long, default_value = "rigid")]
        preset: String,
        /// A full settings file instead of a preset (as written by `degs run`/`plan`)
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
        /// Override a setting, e.g. --set width=64 --set camera.sway_hz=0.5
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Output scene directory (replaced atomically)
        #[arg(long)]
        out: PathBuf,
    },
    /// Each stage of an experiment: cached / stale (and what changed) / missing /
    /// failed (with its error) / tampered / not available.
    Status {
        experiment: PathBuf,
        #[command(flatten)]
        place: Where,
        /// Re-hash every cached file
        #[arg(long)]
        verify: bool,
    },
    /// Print the shell commands of the stages in order (for Slurm, Snakemake, …).
    /// Writes the settings files they read under runs/<name>/.
    Plan {
        experiment: PathBuf,
        #[command(flatten)]
        place: Where,
        /// Also print cached stages uncommented
        #[arg(long)]
        all: bool,
    },
    /// Remove cache entries that no runs/*/run.json refers to.
    Gc {
        #[command(flatten)]
        place: Where,
        /// Only list what would be removed
        #[arg(long)]
        dry_run: bool,
    },
    /// Event files.
    Events {
        #[command(subcommand)]
        command: EventsCommand,
    },
    /// Synthesise the default scene (preset rigid at 96x96), write an experiment file
    /// for it (OUT/demo.toml: 1500 warm-up iterations and 1 LoCM epoch so it runs in
    /// minutes on two cores) and run every stage that is built; ends with a summary
    /// table (time, cached?, key figures), where the renders are, summary.json and
    /// events_preview.png. Running it again reuses every cached stage.
    Demo {
        /// Where everything goes (cache, runs, demo.toml, summary)
        #[arg(long, default_value = "degs-demo")]
        out: PathBuf,
        /// Look for stage binaries only in DIR [env: DEGS_STAGE_DIR]
        #[arg(long, value_name = "DIR")]
        stages: Option<PathBuf>,
        /// Synthetic preset: static, rigid, nonrigid, fast
        #[arg(long, default_value = "rigid")]
        preset: String,
        /// Override a scene setting, e.g. --set width=128 --set height=128
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Warm-up iterations of the gaussians stage
        #[arg(long, default_value_t = pipeline::demo::DEMO_GAUSSIANS_ITERATIONS)]
        iterations: u32,
        /// LoCM fine-tuning epochs of the evflow stage
        #[arg(long, default_value_t = pipeline::demo::DEMO_EVFLOW_EPOCHS)]
        epochs: usize,
        /// Use every stage's default settings (3500 iterations, 3 epochs) instead
        #[arg(long, conflicts_with_all = ["iterations", "epochs"])]
        full: bool,
        /// Stages to run at the same time
        #[arg(short = 'j', long, default_value_t = 2)]
        jobs: usize,
    },
    /// PSNR/SSIM of the final renders against the scene's test images (and the flow
    /// EPE the evflow stage reports where the scene has ground truth) → metrics.json.
    Eval {
        /// A run directory (<cache>/runs/<name>) or an experiment name
        run: String,
        #[command(flatten)]
        place: Where,
    },
    /// Evaluate several runs and print them side by side.
    Compare {
        /// Run directories or experiment names
        #[arg(required = true)]
        runs: Vec<String>,
        #[command(flatten)]
        place: Where,
    },
}

impl Where {
    /// A run directory given as a path or as an experiment name.
    fn run_dir(&self, run: &str) -> Result<PathBuf> {
        let p = PathBuf::from(run);
        if p.join("run.json").exists() {
            return Ok(p);
        }
        let by_name = self.context()?.cache.run_dir(run);
        if by_name.join("run.json").exists() {
            Ok(by_name)
        } else {
            Err(anyhow!(
                "{run}: no run.json there nor at {}",
                by_name.display()
            ))
        }
    }
}

#[derive(Subcommand)]
enum EventsCommand {
    /// Convert an event file between formats, chosen by extension: .txt (ECD `t x y p`),
    /// .npz (x, y, t in µs, p), .evs (degs columnar binary), .aedat4 (read only).
    /// The output is written atomically; a bad input gives one line naming the file.
    Convert {
        input: PathBuf,
        output: PathBuf,
        /// Sensor size WxH for formats that do not store it (text, npz)
        #[arg(long, value_name = "WxH")]
        sensor: Option<String>,
        /// .npz input only: the stored x, y are pixel coordinates times this factor;
        /// they are divided by it and rounded to the nearest pixel
        #[arg(long, value_name = "FACTOR")]
        coord_scale: Option<f64>,
        /// .npz input from HS-ERGB, which stores x and y multiplied by 32: the same as
        /// --coord-scale 32
        #[arg(long, conflicts_with = "coord_scale")]
        hsergb: bool,
    },
}

#[derive(Subcommand)]
enum ConfigCommand {
    /// Print the resolved experiment: every synthetic-scene setting, each stage's own
    /// keys and, commented out under them, every default of that stage. Unknown stage
    /// keys are errors naming the key.
    Show { experiment: PathBuf },
}

fn main() {
    if let Err(e) = real_main() {
        eprintln!("degs: {e:#}");
        std::process::exit(1);
    }
}

fn real_main() -> Result<()> {
    match Cli::parse().command {
        Command::Run {
            experiment,
            place,
            until,
            force,
            jobs,
            verify,
            quiet,
        } => {
            let exp = load_checked(&experiment)?;
            let ctx = place.context()?;
            let opts = RunOptions {
                until: until.as_deref().map(graph::parse_stage).transpose()?,
                force: force
                    .iter()
                    .map(|s| graph::parse_stage(s))
                    .collect::<Result<_>>()?,
                jobs,
                verify_full: verify,
            };
            let record = runner::run(&exp, &ctx, &opts, &Progress::new(quiet))?;
            if let Some(f) = record
                .stages
                .iter()
                .find(|s| s.action == pipeline::record::Action::Failed)
            {
                return Err(anyhow!(
                    "stage {} failed: {} (log: {})",
                    f.stage,
                    f.error.as_deref().unwrap_or("?"),
                    f.log
                        .as_deref()
                        .map(|p| p.display().to_string())
                        .unwrap_or_default()
                ));
            }
            Ok(())
        }
        Command::Config {
            command: ConfigCommand::Show { experiment },
        } => {
            print!(
                "{}",
                pipeline::defaults::show(&Experiment::load(&experiment)?)?
            );
            Ok(())
        }
        Command::Synth {
            preset,
            config,
            set,
            out,
        } => {
            let cfg = pipeline::synth::load_config(config.as_deref(), Some(&preset), &set)?;
            let s = pipeline::synth::write_scene(&cfg, &out)?;
            eprintln!(
                "[degs] synth: {} {}x{}, {} train + {} test frames, {} events in {:.2} s → {}",
                s.preset,
                s.width,
                s.height,
                s.train_frames,
                s.test_frames,
                s.events,
                s.total_s,
                out.display()
            );
            Ok(())
        }
        Command::Status {
            experiment,
            place,
            verify,
        } => {
            let exp = load_checked(&experiment)?;
            let rows = pipeline::status::status(&exp, &place.context()?, verify)?;
            print!("{}", pipeline::status::format_status(&rows));
            Ok(())
        }
        Command::Plan {
            experiment,
            place,
            all,
        } => {
            let exp = load_checked(&experiment)?;
            print!("{}", pipeline::status::plan(&exp, &place.context()?, all)?);
            Ok(())
        }
        Command::Gc { place, dry_run } => {
            let ctx = place.context()?;
            let r = pipeline::status::gc(&ctx.cache, dry_run)?;
            for (stage, key) in &r.removed {
                println!(
                    "{} {stage}/{key}",
                    if dry_run { "would remove" } else { "removed" }
                );
            }
            println!(
                "{} {} entries ({:.1} MiB), kept {}",
                if dry_run { "would remove" } else { "removed" },
                r.removed.len(),
                r.bytes as f64 / (1 << 20) as f64,
                r.kept
            );
            Ok(())
        }
        Command::Events {
            command:
                EventsCommand::Convert {
                    input,
                    output,
                    sensor,
                    coord_scale,
                    hsergb,
                },
        } => {
            let coord_scale = if hsergb { Some(32.0) } else { coord_scale };
            let sensor = sensor
                .map(|s| {
                    s.split_once(['x', 'X'])
                        .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
                        .ok_or_else(|| anyhow!("--sensor {s:?}: expected WxH, e.g. 346x260"))
                })
                .transpose()?;
            let opts = scene::formats::ReadOptions {
                sensor,
                coord_scale,
            };
            let s = scene::formats::convert(&input, &output, &opts)?;
            eprintln!(
                "[degs] converted {} events ({}x{}, t {:.6}..{:.6} s) {} → {}: {}",
                s.events,
                s.width,
                s.height,
                s.t_first,
                s.t_last,
                s.input_format,
                s.output_format,
                output.display()
            );
            Ok(())
        }
        Command::Demo {
            out,
            stages,
            preset,
            set,
            iterations,
            epochs,
            full,
            jobs,
        } => {
            let size = pipeline::demo::DEMO_SIZE;
            let mut all = vec![format!("width={size}"), format!("height={size}")];
            all.extend(set);
            let cfg = pipeline::synth::load_config(None, Some(&preset), &all)?;
            let opts = pipeline::demo::DemoOptions {
                scene: cfg,
                gaussians_iterations: (!full).then_some(iterations),
                evflow_epochs: (!full).then_some(epochs),
                jobs,
            };
            let place = Where {
                cache: Some(out),
                stages,
            };
            let ctx = place.context()?;
            let summary = pipeline::demo::demo(&opts, &ctx, &Progress::new(false))?;
            print!("{}", pipeline::demo::format_summary(&summary));
            Ok(())
        }
        Command::Eval { run, place } => {
            let dir = place.run_dir(&run)?;
            let m = pipeline::eval::eval_run(&dir)?;
            print!(
                "{}",
                pipeline::eval::compare_table(&[(m.experiment.clone(), m)])
            );
            eprintln!("[degs] wrote {}", dir.join("metrics.json").display());
            Ok(())
        }
        Command::Compare { runs, place } => {
            let mut rows = Vec::new();
            for r in &runs {
                let m = pipeline::eval::eval_run(&place.run_dir(r)?)?;
                rows.push((r.clone(), m));
            }
            print!("{}", pipeline::eval::compare_table(&rows));
            Ok(())
        }
    }
}

/// Load an experiment and check every stage table against its stage's settings, so a
/// typo in `[gaussians]` is an error naming the key before any stage runs.
fn load_checked(path: &std::path::Path) -> Result<Experiment> {
    let exp = Experiment::load(path)?;
    pipeline::defaults::check_experiment(&exp)?;
    Ok(exp)
}
