//! `evflow`: per-event optical flow from events (thin CLI over the `evflow` library).

use clap::{Args, Parser, Subcommand};
use evflow::finetune::{FlowSettings, Mode};
use evflow::source::{WindowSpec, parse_sensor, parse_window};
use evflow::stage::{Event, Input};
use std::io::IsTerminal;
use std::path::PathBuf;

/// Event-based optical flow for degs: EV-FlowNet adapted to one recording by LoCM
/// (LoRA + contrast maximisation). Outputs per-event flow files (`flow/NNNN.evflow`,
/// px/s) that `assoc` and `deform` read, dense previews and report.json.
#[derive(Parser, Debug)]
#[command(name = "evflow", version, after_help = evflow::weights::TENSOR_NAMES_HELP)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Simulate events from a directory of frames (images sorted by name +
    /// timestamps.txt, one time in seconds per line) and write them as .evs.
    Simulate {
        /// Directory with the frames and timestamps.txt.
        #[arg(long)]
        frames: PathBuf,
        /// Output event file (.evs).
        #[arg(long)]
        out: PathBuf,
        /// Simulator settings (TOML, keys of synth::sim::SimConfig).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Random seed (threshold mismatch, noise).
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
    /// LoCM: fine-tune the pretrained flow network on the recording with the
    /// contrast-maximisation loss (no ground truth), then predict the flow of every
    /// event. Writes OUT/adapter.safetensors (lora) or OUT/weights.safetensors (full),
    /// OUT/flow/NNNN.evflow, OUT/previews/, OUT/settings.toml, OUT/report.json.
    /// This is the pipeline's `evflow` stage.
    Finetune {
        #[command(flatten)]
        input: InputArgs,
        #[command(flatten)]
        common: CommonArgs,
        /// What to train: lora (adapters r=16, default), full (all weights), none.
        #[arg(long)]
        mode: Option<Mode>,
        /// Passes over the windows [default 3].
        #[arg(long)]
        epochs: Option<usize>,
        /// Adam learning rate at the first step [default 5e-4].
        #[arg(long)]
        lr_start: Option<f64>,
        /// Learning rate at the last step, exponential decay in between [default 1e-4].
        #[arg(long)]
        lr_end: Option<f64>,
        /// LoRA rank [default 16].
        #[arg(long)]
        rank: Option<usize>,
        /// Seed of the LoRA initialisation [default 0].
        #[arg(long)]
        seed: Option<u64>,
    },
    /// Predict per-event flow with the pretrained network (plus an optional adapter from
    /// `evflow finetune`), no training. Same outputs as finetune, without the adapter.
    Predict {
        #[command(flatten)]
        input: InputArgs,
        #[command(flatten)]
        common: CommonArgs,
        /// LoRA adapter (adapter.safetensors written by `evflow finetune`).
        #[arg(long)]
        adapter: Option<PathBuf>,
    },
    /// Score existing flow files (FLOWS/flow/NNNN.evflow): end-point error and outliers
    /// (> 3 px) against the scene's ground truth where it has one, flow-warp gain (IWE
    /// variance with the flow ÷ without) always. Prints JSON; writes it to --out FILE.
    Eval {
        #[command(flatten)]
        input: InputArgs,
        /// Directory written by `evflow finetune`/`predict`.
        #[arg(long)]
        flows: PathBuf,
        /// Dense ground truth `.npy` (1x2xHxW, px of displacement over the window, e.g.
        /// the ECD slice's flow.npy) for bare event files.
        #[arg(long)]
        gt_flow: Option<PathBuf>,
        /// Write the figures to this JSON file too.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Pretrain the flow network on synthetic scenes with ground-truth flow (supervised
    /// and/or CM loss). Writes OUT/weights.safetensors (+ .json sidecar), report.json
    /// (loss curve, held-out EPE) and settings.toml. The shipped default weights were made
    /// with `evflow pretrain --config evflow/weights/pretrain_c16.toml --out DIR`.
    Pretrain {
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
        /// Settings (TOML, keys of evflow::pretrain::PretrainSettings).
        #[arg(long)]
        config: Option<PathBuf>,
        /// Base width C of the network (overrides the config).
        #[arg(long)]
        base: Option<usize>,
        /// Training iterations (overrides the config).
        #[arg(long)]
        iterations: Option<usize>,
    },
}

/// Where the events come from: a scene directory, or a bare event file.
#[derive(Args, Debug)]
struct InputArgs {
    /// Scene directory (transforms_train.json with an events entry); one window per
    /// interval between consecutive train frames.
    #[arg(long, conflicts_with = "events", required_unless_present = "events")]
    scene: Option<PathBuf>,
    /// Bare event file (.txt t x y p, .npz, .evs, .aedat4) instead of a scene.
    #[arg(long, requires = "sensor")]
    events: Option<PathBuf>,
    /// Sensor size WxH of the event file, e.g. 240x180.
    #[arg(long)]
    sensor: Option<String>,
    /// Calibration `fx fy cx cy k1 k2 p1 p2 k3` (ECD calib.txt): events are undistorted
    /// and the flow lives on the undistorted grid of the same K.
    #[arg(long, requires = "events")]
    calib: Option<PathBuf>,
    /// A window T0,T1 in seconds (repeatable). Default: consecutive windows of
    /// --window-length, else one window over the whole stream.
    #[arg(long = "window", requires = "events")]
    windows: Vec<String>,
    /// Length of consecutive windows in seconds.
    #[arg(long, requires = "events")]
    window_length: Option<f64>,
}

#[derive(Args, Debug)]
struct CommonArgs {
    /// Output directory (appears complete or not at all).
    #[arg(long)]
    out: PathBuf,
    /// Settings file (TOML, keys of FlowSettings); flags override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Base network weights: safetensors with a .json sidecar, or bare (tensor names in
    /// `evflow --help`). Default: $EVFLOW_WEIGHTS, else the weights shipped in
    /// evflow/weights/.
    #[arg(long)]
    weights: Option<PathBuf>,
    /// Base width C of bare --weights (no sidecar); checked against enc1.weight, which
    /// gives it when omitted.
    #[arg(long, requires = "weights")]
    width: Option<usize>,
    /// Largest flow of bare --weights' tanh heads, px per window [default 32].
    #[arg(long, requires = "weights")]
    max_flow: Option<f64>,
    /// Skip the dense previews (.flo, EXR, PNG).
    #[arg(long)]
    no_previews: bool,
}

fn input_of(a: &InputArgs) -> anyhow::Result<Input> {
    if let Some(dir) = &a.scene {
        return Ok(Input::Scene(dir.clone()));
    }
    let path = a
        .events
        .clone()
        .ok_or_else(|| anyhow::anyhow!("give --scene or --events"))?;
    let sensor =
        parse_sensor(a.sensor.as_deref().unwrap_or_default()).map_err(anyhow::Error::msg)?;
    let windows = a
        .windows
        .iter()
        .map(|w| parse_window(w))
        .collect::<Result<Vec<_>, _>>()
        .map_err(anyhow::Error::msg)?;
    Ok(Input::Events {
        path,
        sensor,
        calib: a.calib.clone(),
        spec: WindowSpec {
            windows,
            window_length: a.window_length,
        },
    })
}

fn settings_of(c: &CommonArgs) -> anyhow::Result<FlowSettings> {
    let mut s = match &c.config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", path.display()))?;
            toml::from_str::<FlowSettings>(&text)
                .map_err(|e| anyhow::anyhow!("{}: {}", path.display(), e.message()))?
        }
        None => FlowSettings::default(),
    };
    if let Some(w) = &c.weights {
        s.weights = Some(w.clone());
    }
    if c.width.is_some() {
        s.weights_width = c.width;
    }
    if c.max_flow.is_some() {
        s.weights_max_flow = c.max_flow;
    }
    if c.no_previews {
        s.previews = false;
    }
    Ok(s)
}

/// Run the stage with a progress bar on a terminal, plain lines otherwise.
fn run_stage(
    input: &Input,
    out: &std::path::Path,
    s: &FlowSettings,
    train: bool,
    adapter: Option<&std::path::Path>,
) -> anyhow::Result<()> {
    let terminal = std::io::stderr().is_terminal();
    let bar = indicatif::ProgressBar::new(0);
    if !terminal {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    bar.set_style(
        indicatif::ProgressStyle::with_template("{prefix:>9} [{bar:30}] {pos}/{len} {msg}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    let report = evflow::stage::run(input, out, s, train, adapter, |e| match e {
        Event::Phase(p) => {
            bar.set_prefix(p.to_string());
            bar.set_position(0);
            if !terminal {
                eprintln!("evflow: {p}");
            }
        }
        Event::Step(st) => {
            bar.set_length((st.epochs * st.steps) as u64);
            bar.set_position((st.epoch * st.steps + st.step + 1) as u64);
            bar.set_message(format!("epoch {} loss {:.4}", st.epoch + 1, st.loss));
            if !terminal {
                eprintln!(
                    "evflow: epoch {}/{} window {} ({}/{}) loss {:.5} lr {:.2e}",
                    st.epoch + 1,
                    st.epochs,
                    st.window,
                    st.step + 1,
                    st.steps,
                    st.loss,
                    st.lr
                );
            }
        }
        Event::Predicted(d, t) => {
            bar.set_length(t as u64);
            bar.set_position(d as u64);
            if !terminal {
                eprintln!("evflow: predicted window {d}/{t}");
            }
        }
        Event::Warning(w) => bar.suspend(|| eprintln!("evflow: warning: {w}")),
    })?;
    bar.finish_and_clear();
    let ft = &report.finetune;
    eprintln!(
        "evflow: {} windows, {} events, CM loss {:.4} -> {:.4}, warp gain {:.3}{}, {:.1} s -> {}",
        report.windows,
        report.events,
        ft.cm_loss_before,
        ft.cm_loss_after,
        report.warp_gain,
        report
            .flow_epe_px_s
            .map_or(String::new(), |e| format!(", EPE {e:.3} px/s")),
        report.wall_s,
        out.display()
    );
    Ok(())
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.cmd {
        Cmd::Simulate {
            frames,
            out,
            config,
            seed,
        } => {
            let cfg = match &config {
                Some(p) => {
                    let text = std::fs::read_to_string(p)
                        .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", p.display()))?;
                    toml::from_str(&text)
                        .map_err(|e| anyhow::anyhow!("{}: {}", p.display(), e.message()))?
                }
                None => synth::sim::SimConfig::default(),
            };
            let s = synth::frames::simulate_frames(&frames, &out, &cfg, seed)?;
            eprintln!(
                "evflow: {} frames -> {} events ({}x{}) in {:.2} s -> {}",
                s.frames,
                s.events,
                s.width,
                s.height,
                s.seconds,
                out.display()
            );
        }
        Cmd::Finetune {
            input,
            common,
            mode,
            epochs,
            lr_start,
            lr_end,
            rank,
            seed,
        } => {
            let mut s = settings_of(&common)?;
            if let Some(v) = mode {
                s.mode = v;
            }
            if let Some(v) = epochs {
                s.epochs = v;
            }
            if let Some(v) = lr_start {
                s.lr_start = v;
            }
            if let Some(v) = lr_end {
                s.lr_end = v;
            }
            if let Some(v) = rank {
                s.rank = v;
            }
            if let Some(v) = seed {
                s.seed = v;
            }
            run_stage(&input_of(&input)?, &common.out, &s, true, None)?;
        }
        Cmd::Predict {
            input,
            common,
            adapter,
        } => {
            let mut s = settings_of(&common)?;
            s.mode = Mode::None;
            run_stage(
                &input_of(&input)?,
                &common.out,
                &s,
                false,
                adapter.as_deref(),
            )?;
        }
        Cmd::Eval {
            input,
            flows,
            gt_flow,
            out,
        } => {
            let e = evflow::stage::eval_flows(&input_of(&input)?, &flows, gt_flow.as_deref())?;
            let text = serde_json::to_string_pretty(&e)?;
            if let Some(p) = out {
                scene::atomic::write_bytes_atomic(&p, text.as_bytes())?;
            }
            println!("{text}");
        }
        Cmd::Pretrain {
            out,
            config,
            base,
            iterations,
        } => pretrain(&out, config.as_deref(), base, iterations)?,
    }
    Ok(())
}

fn pretrain(
    out: &std::path::Path,
    config: Option<&std::path::Path>,
    base: Option<usize>,
    iterations: Option<usize>,
) -> anyhow::Result<()> {
    use evflow::pretrain::PretrainSettings;
    let mut s = match config {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", p.display()))?;
            toml::from_str::<PretrainSettings>(&text)
                .map_err(|e| anyhow::anyhow!("{}: {}", p.display(), e.message()))?
        }
        None => PretrainSettings::default(),
    };
    if let Some(b) = base {
        s.base = b;
    }
    if let Some(i) = iterations {
        s.iterations = i;
    }
    let terminal = std::io::stderr().is_terminal();
    let bar = indicatif::ProgressBar::new(0);
    if !terminal {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let r = evflow::pretrain::run(&s, out, &mut |k, n, loss| {
        bar.set_length(n as u64);
        bar.set_position(k as u64);
        bar.set_message(format!("loss {loss:.4}"));
        if !terminal && (k % 25 == 0 || k == n) {
            eprintln!("evflow: pretrain step {k}/{n} loss {loss:.4}");
        }
    })?;
    bar.finish_and_clear();
    let text = toml::to_string(&s)?;
    scene::atomic::write_bytes_atomic(&out.join("settings.toml"), text.as_bytes())?;
    eprintln!(
        "evflow: pretrained {} params in {:.1} s ({:.3} s/step) -> {}",
        r.params,
        r.train_s,
        r.step_s,
        out.display()
    );
    Ok(())
}

fn main() {
    let cli = Cli::parse();
    if let Err(e) = run(cli) {
        eprintln!("evflow: error: {e:#}");
        std::process::exit(1);
    }
}
