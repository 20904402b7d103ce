//! The `degs` command line (clap): every sub-command with its flags and help text.
//! What each does is in `commands.rs`.
// The doc comments below are the help text clap prints, written for a terminal.
#![allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]

use anyhow::{Result, anyhow};
use clap::{Args, Parser, Subcommand};
use runner::cache::Cache;
use runner::context::Context;
use runner::run::RunOptions;
use std::path::PathBuf;

/// Reconstruct a dynamic scene as 3D Gaussians from events + sparse RGB frames.
///
/// degs chains the stage binaries (synth → evflow, gaussians → assoc → deform) like
/// make: each stage's output is cached under a key made of its binary, its settings
/// and its inputs' keys, so re-running resumes where it stopped and experiments share
/// work. Start with `degs demo`.
#[derive(Parser)]
#[command(name = "degs", version, about, long_about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

/// The help of `degs synth --set`, with the default novel-view angle (from the
/// synthetic scene's settings type, so that it cannot drift).
fn synth_set_help() -> String {
    format!(
        "Override a setting, e.g. --set width=64 --set camera.sway_hz=0.5; \
         --set novel_angle_deg=0 writes no novel-view split [novel_angle_deg default: {}]",
        synth::SynthConfig::default().novel_angle_deg
    )
}

/// How `run`, `sweep` and `stress` run their stages.
#[derive(Args, Clone, Copy)]
pub struct RunFlags {
    /// Stages to run at the same time within an experiment (evflow and gaussians are
    /// independent)
    #[arg(short = 'j', long, default_value_t = 1)]
    pub jobs: usize,
    /// Experiments of a sweep or stress run to run at the same time, each with its -j
    /// stages; a stage they share is built once (the others wait on its cache entry's
    /// lock, as a second `degs` on the same cache does); the experiments share the cores
    /// evenly, each stage of one getting its whole share (RAYON_NUM_THREADS, unless set)
    #[arg(short = 'J', long = "experiments", default_value_t = 1)]
    pub experiments: usize,
    /// Re-hash every cached file (default: only files whose size or mtime changed)
    #[arg(long)]
    pub verify: bool,
    /// No progress lines
    #[arg(short, long)]
    pub quiet: bool,
}

impl RunFlags {
    /// The runner's options for these flags (nothing forced, no `--until`).
    pub fn options(&self) -> RunOptions {
        RunOptions {
            jobs: self.jobs,
            experiments: self.experiments,
            verify_full: self.verify,
            ..RunOptions::default()
        }
    }
}

#[derive(Args, Clone)]
pub struct Where {
    /// Cache root: holds cache/<stage>/<key>/ and runs/<name>/ [env: DEGS_CACHE]
    /// [default: ./degs-cache]
    #[arg(long, value_name = "DIR")]
    pub cache: Option<PathBuf>,
    /// Look for stage binaries only in DIR (default: next to degs, then PATH)
    /// [env: DEGS_STAGE_DIR]
    #[arg(long, value_name = "DIR")]
    pub stages: Option<PathBuf>,
}

impl Where {
    pub fn context(&self) -> Result<Context> {
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

    /// A run directory given as a path or as an experiment name.
    pub fn run_dir(&self, run: &str) -> Result<PathBuf> {
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
pub enum Command {
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
        #[command(flatten)]
        flags: RunFlags,
    },
    /// Experiment files.
    Config {
        #[command(subcommand)]
        command: ConfigCommand,
    },
    /// Write a synthetic scene directory with ground truth (depth, flow, per-event flow):
    /// train and test frames along the camera path, and novel views at the test times
    /// from a camera rotated about the scene's centre (`novel_angle_deg`).
    Synth {
        /// Preset: static, rigid, nonrigid, fast, moderate
        #[arg(long, default_value = "rigid")]
        preset: String,
        /// A full settings file instead of a preset (as written by `degs run`/`plan`)
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
        // Help: "Override a setting, e.g. … [novel_angle_deg default: …]".
        #[arg(long = "set", value_name = "KEY=VALUE", help = synth_set_help())]
        set: Vec<String>,
        /// Output scene directory: new, empty, or (with --force) an earlier `degs synth`
        /// output, replaced atomically; any other folder is refused
        #[arg(long)]
        out: PathBuf,
        /// Replace an earlier `degs synth` output at OUT
        #[arg(long)]
        force: bool,
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
    /// Run every experiment of a sweep (a base experiment and axes: their cartesian
    /// product) through the cache, -J at a time, so every stage they share is computed
    /// once. Writes each experiment to runs/<sweep>/<experiment>.toml and
    /// runs/<sweep>/sweep.json (the experiments, their run records, which experiment
    /// built each shared entry). Re-running resumes an interrupted sweep.
    Sweep {
        /// Sweep file (TOML: name, base = "experiment.toml" or [base], [axes] with
        /// "stage.key" = [values] or "scene.settings.key" = [values])
        sweep: PathBuf,
        #[command(flatten)]
        place: Where,
        #[command(flatten)]
        flags: RunFlags,
    },
    /// Test stability where methods fail: build stressed variants of a base experiment's
    /// scene (train frame rate, event noise, hot pixels, a wrong claimed contrast
    /// threshold, motion blur, a gap without events, a burst of events, corrupt files),
    /// run DEGS and RGB-only (deform with schedule.gamma1 = gamma2_max = 0) on each
    /// through the cache, and write runs/<name>/stress.json, report.md and a chart of
    /// test PSNR against each stress's level (stress-<stress>.png/.svg). A variant that
    /// fails is recorded with its error, not fatal. Re-running resumes.
    Stress {
        /// Stress file (TOML): name; base = "experiment.toml" or [base]; [stresses] with
        /// fps, noise_hz, hot_pixels, contrast_ratio, blur_subframes, gap_fraction,
        /// burst_events = [levels] and corrupt = ["truncated-events", "missing-frame",
        /// "nan-pose"] (absent: all, at their default levels); [settings] with
        /// hot_pixel_hz, burst_s, burst_reference_sensor, seed. See examples/stress/.
        stress: PathBuf,
        #[command(flatten)]
        place: Where,
        #[command(flatten)]
        flags: RunFlags,
    },
    /// Print the shell commands of the stages in order, each stage once; also write
    /// runs/<name>/Snakefile (Snakemake rules) and runs/<name>/slurm.sh (Slurm array
    /// jobs, one per level of the graph, in dependency order). Takes an experiment or a
    /// sweep file. Writes the settings files the commands read under runs/<experiment>/.
    Plan {
        /// Experiment file or sweep file
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
    /// Convert a recording in a public dataset's layout into a scene directory
    /// (transforms_train/test.json, images/, events.evs, import.json) and print what it
    /// found: frames, time span, events, events per frame interval, frame encoding.
    /// Layouts: ecd (calib.txt, images.txt + images/, events.txt, groundtruth.txt; poses
    /// converted from OpenCV to OpenGL camera axes and interpolated to the frame times),
    /// aedat4 (one DAVIS .aedat4 file: events + APS frames, no poses: needs
    /// --static-camera), hsergb (images_corrected/ + timestamp.txt, events_aligned/*.npz
    /// with coordinates ×32; a static camera: identity poses), blender (D-NeRF
    /// transforms_*.json + an event file; normalised times mapped to seconds), nerfies
    /// (nerfies / HyperNeRF / NeRF-DS: dataset.json, metadata.json, camera/*.json,
    /// rgb/Nx/ + an event file; time ids mapped to seconds, scene.json applied). See the
    /// README, "Bring your own recording".
    Import(ImportArgs),
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
        /// Synthetic preset: static, rigid, nonrigid, fast, moderate
        #[arg(long, default_value = "rigid")]
        preset: String,
        /// Override a scene setting, e.g. --set width=128 --set height=128
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Warm-up iterations of the gaussians stage
        #[arg(long, default_value_t = crate::demo::DEMO_GAUSSIANS_ITERATIONS)]
        iterations: u32,
        /// LoCM fine-tuning epochs of the evflow stage
        #[arg(long, default_value_t = crate::demo::DEMO_EVFLOW_EPOCHS)]
        epochs: usize,
        /// Joint iterations of the deform stage
        #[arg(long, default_value_t = crate::demo::DEMO_DEFORM_ITERATIONS)]
        deform_iterations: u32,
        /// Use every stage's default settings instead (each stage binary's own: `degs
        /// config show FILE` lists them)
        #[arg(long, conflicts_with_all = ["iterations", "epochs", "deform_iterations"])]
        full: bool,
        /// Stages to run at the same time
        #[arg(short = 'j', long, default_value_t = 2)]
        jobs: usize,
    },
    /// PSNR/SSIM of the final renders against the scene's test images and novel views
    /// (and the flow EPE the evflow stage reports where the scene has ground truth) →
    /// metrics.json; prints the 2D baselines (nearest frame, linear blend, event pseudo
    /// image) on the test frames beside them.
    Eval {
        /// A run directory (<cache>/runs/<name>) or an experiment name
        run: String,
        #[command(flatten)]
        place: Where,
    },
    /// The run's dynamic model (the joint training's, else the warm-up's) as a sequence
    /// of standard 3DGS PLY files, the Gaussians deformed to each time in world
    /// coordinates, in runs/<name>/export/: frame_0001.ply … (SuperSplat plays such a
    /// sequence on its timeline), sequence.zip (the same files; brush plays a zip of
    /// PLYs), times.json (each file's time in seconds and normalised). Times: every train
    /// and test frame's, or --fps N over the recording. Cached like a stage.
    Export {
        /// A run directory (<cache>/runs/<name>) or an experiment name
        run: String,
        /// Frames per second over the recording (default: the frames' times)
        #[arg(long)]
        fps: Option<f64>,
        #[command(flatten)]
        place: Where,
    },
    /// The run's dynamic model (the joint training's, else the warm-up's) rendered along
    /// a camera path over the recording, in runs/<name>/video/: frames/0001.png …,
    /// preview.gif, preview.mp4 (when ffmpeg is on the PATH; the output says when it is
    /// not), cameras.json (the rendered poses and times, a manifest usable as --path
    /// FILE). Cached like a stage.
    Render {
        /// A run directory (<cache>/runs/<name>) or an experiment name
        run: String,
        /// recorded (the camera's own path: slow motion), orbit (a swing of ±20° about
        /// the scene's centre while time runs), or a cameras file (a manifest in the
        /// scene's format: camera, each frame's transform_matrix and time)
        #[arg(long, default_value = "recorded")]
        path: String,
        /// Rendered frames per second of recording time [default: 4× the train frames']
        #[arg(long)]
        fps: Option<f64>,
        /// Frames per second of the preview animation [default: 10]
        #[arg(long)]
        playback_fps: Option<f64>,
        #[command(flatten)]
        place: Where,
    },
    /// Charts of accuracy against cost across runs, one per question and scene, PNG and
    /// SVG: test PSNR against total stage time (cached stages at their build cost),
    /// against model size on disk and against Gaussian count, test LPIPS against total
    /// stage time (where the stages had the LPIPS weights), flow EPE against LoCM
    /// time; Pareto front drawn, 2D baselines as horizontal lines, RGB-only and DEGS
    /// told apart. The numbers go to chart.json and chart.csv beside them.
    ///
    /// Files ending in .jsonl are LoCM budget curves (one JSON line per fine-tuning
    /// step, as `cargo run -p degs-evflow --example locm_budget -- ecd|scene DIR` prints):
    /// they are drawn together as flow EPE ÷ zero-flow EPE against LoCM time, one line
    /// per file, the step where the stopping rule stopped ringed, a dashed line at the
    /// zero-flow level; locm-curves.png/.svg/.json/.csv.
    Chart {
        /// Run directories, experiment names, sweep names, or LoCM curve files (.jsonl)
        #[arg(required = true)]
        runs: Vec<String>,
        #[command(flatten)]
        place: Where,
        /// Output directory [default: <cache>/charts]
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
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

/// The source layouts of `degs import`.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum ImportLayout {
    /// Event Camera Dataset folder
    Ecd,
    /// One AEDAT 4.0 file (DAVIS events + APS frames)
    Aedat4,
    /// HS-ERGB sequence folder (images_corrected/, events_aligned/*.npz)
    Hsergb,
    /// D-NeRF / Blender folder (transforms_*.json) with an event file beside it
    Blender,
    /// nerfies / HyperNeRF / NeRF-DS capture (dataset.json, metadata.json, camera/,
    /// rgb/Nx/) with an event file beside it
    Nerfies,
    /// COLMAP sparse model (sparse/0/ cameras, images, points3D; .bin or .txt) with its
    /// images/ and an event file; times from timestamps.txt or the image names
    Colmap,
}

impl ImportLayout {
    pub fn layout(self) -> import::Layout {
        match self {
            ImportLayout::Ecd => import::Layout::Ecd,
            ImportLayout::Aedat4 => import::Layout::Aedat4,
            ImportLayout::Hsergb => import::Layout::Hsergb,
            ImportLayout::Blender => import::Layout::Blender,
            ImportLayout::Nerfies => import::Layout::Nerfies,
            ImportLayout::Colmap => import::Layout::Colmap,
        }
    }
}

#[derive(Args)]
pub struct ImportArgs {
    /// Source layout
    #[arg(value_enum)]
    pub layout: ImportLayout,
    /// The recording: a folder (ecd) or a file (aedat4)
    pub src: PathBuf,
    /// Output scene directory: new, empty, or (with --force) an earlier `degs import`
    /// output, replaced atomically; a folder that holds the recording, or any other
    /// folder, is refused
    pub out: PathBuf,
    /// Replace an earlier `degs import` output at OUT
    #[arg(long)]
    pub force: bool,
    /// Hold out every N-th frame (the N-th, 2N-th, …) as a test frame
    #[arg(long, value_name = "N")]
    pub test_every: Option<usize>,
    /// Thin the train frames to at most F frames per second (the paper trains on 1/5
    /// of the frame rate)
    #[arg(long, value_name = "F")]
    pub train_fps: Option<f64>,
    /// Contrast threshold C of the event generation model, written to the manifest
    #[arg(long, default_value_t = scene::manifest::DEFAULT_CONTRAST_THRESHOLD)]
    pub contrast_threshold: f64,
    /// How the frames' 8-bit codes map to intensity (default: the layout's; APS frames
    /// of ecd/aedat4 are linear)
    #[arg(long, value_enum)]
    pub frame_encoding: Option<EncodingArg>,
    /// aedat4: the camera did not move; every frame gets the identity pose
    #[arg(long)]
    pub static_camera: bool,
    /// aedat4, hsergb: intrinsics from an ECD-style calib.txt (fx fy cx cy [k1 k2 p1 p2
    /// k3]); without it they are guessed (fx = fy = width) with a warning
    #[arg(long, value_name = "FILE")]
    pub calib: Option<PathBuf>,
    /// blender, nerfies, colmap: the event file (default: events.* beside the layout's
    /// files, or the blender manifest's events.path)
    #[arg(long, value_name = "FILE")]
    pub events: Option<PathBuf>,
    /// blender, nerfies: seconds on the events' clock of normalised time 0 (default: the first
    /// event's timestamp)
    #[arg(long, value_name = "S", allow_hyphen_values = true)]
    pub time_offset: Option<f64>,
    /// blender, nerfies: seconds spanned by normalised times 0…1 (default: the events'
    /// span)
    #[arg(long, value_name = "S")]
    pub duration: Option<f64>,
    /// nerfies: read the frames of rgb/Nx/ (intrinsics scaled by 1/N; default: rgb/1x/,
    /// else the smallest N there)
    #[arg(long, value_name = "N")]
    pub downscale: Option<u32>,
    /// colmap: the frames' times, `NAME SECONDS` per line (NAME as in images.bin/txt;
    /// default: SRC/timestamps.txt, else the last number in each image's name)
    #[arg(long, value_name = "FILE")]
    pub timestamps: Option<PathBuf>,
    /// colmap without a timestamps file: seconds per unit of the number in the image
    /// names (1e-6 for microsecond names, 1/fps for frame indices) [default: 1]
    #[arg(long, value_name = "S")]
    pub name_seconds: Option<f64>,
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum EncodingArg {
    Srgb,
    Linear,
}

#[derive(Subcommand)]
pub enum EventsCommand {
    /// Convert an event file between formats, chosen by extension: .txt (ECD `t x y p`),
    /// .npz (x, y, t in µs, p), .evs (degs columnar binary), .aedat4 (read only),
    /// .raw (Prophesee EVT 2.0/3.0; written as EVT 3.0), .es (Event Stream, DVS).
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
pub enum ConfigCommand {
    /// Print the resolved experiment: every synthetic-scene setting, each stage's own
    /// keys and, commented out under them, every default of that stage. Unknown stage
    /// keys are errors naming the key. The defaults come from the stage binaries
    /// (`STAGE settings --defaults`).
    Show {
        experiment: PathBuf,
        /// Look for stage binaries only in DIR (default: next to degs, then PATH)
        /// [env: DEGS_STAGE_DIR]
        #[arg(long, value_name = "DIR")]
        stages: Option<PathBuf>,
    },
}
