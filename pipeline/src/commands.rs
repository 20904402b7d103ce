//! What each `degs` sub-command does, given its parsed command line ([`crate::cli`]).

use crate::cli::{Command, ConfigCommand, EncodingArg, EventsCommand, ImportArgs, Where};
use crate::demo::{self, DemoOptions};
use crate::experiment::Experiment;
use crate::progress::Progress;
use crate::record::Action;
use crate::runner::{self, RunOptions};
use crate::{config_show, eval, stages, status, synth};
use anyhow::{Result, anyhow};
use std::path::Path;

/// Run one parsed `degs` command.
pub fn execute(command: Command) -> Result<()> {
    match command {
        Command::Run {
            experiment,
            place,
            until,
            force,
            jobs,
            verify,
            quiet,
        } => {
            let opts = RunOptions {
                until: until.as_deref().map(stages::parse_stage).transpose()?,
                force: force
                    .iter()
                    .map(|s| stages::parse_stage(s))
                    .collect::<Result<_>>()?,
                jobs,
                verify_full: verify,
            };
            run(&experiment, &place, &opts, quiet)
        }
        Command::Config {
            command: ConfigCommand::Show { experiment },
        } => {
            print!("{}", config_show::show(&Experiment::load(&experiment)?)?);
            Ok(())
        }
        Command::Synth {
            preset,
            config,
            set,
            out,
        } => synth_scene(&preset, config.as_deref(), &set, &out),
        Command::Status {
            experiment,
            place,
            verify,
        } => {
            let exp = Experiment::load_checked(&experiment)?;
            let rows = status::status(&exp, &place.context()?, verify)?;
            print!("{}", status::format_status(&rows));
            Ok(())
        }
        Command::Plan {
            experiment,
            place,
            all,
        } => {
            let exp = Experiment::load_checked(&experiment)?;
            print!("{}", status::plan(&exp, &place.context()?, all)?);
            Ok(())
        }
        Command::Gc { place, dry_run } => gc(&place, dry_run),
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
            convert_events(&input, &output, sensor.as_deref(), coord_scale)
        }
        Command::Demo {
            out,
            stages,
            preset,
            set,
            iterations,
            epochs,
            deform_iterations,
            full,
            jobs,
        } => {
            let size = demo::DEMO_SIZE;
            let mut all = vec![format!("width={size}"), format!("height={size}")];
            all.extend(set);
            let opts = DemoOptions {
                scene: synth::load_config(None, Some(&preset), &all)?,
                gaussians_iterations: (!full).then_some(iterations),
                evflow_epochs: (!full).then_some(epochs),
                deform_iterations: (!full).then_some(deform_iterations),
                jobs,
            };
            let place = Where {
                cache: Some(out),
                stages,
            };
            let summary = demo::demo(&opts, &place.context()?, &Progress::new(false))?;
            print!("{}", demo::format_summary(&summary));
            Ok(())
        }
        Command::Import(args) => import_recording(&args),
        Command::Eval { run, place } => {
            let dir = place.run_dir(&run)?;
            let m = eval::eval_run(&dir)?;
            print!(
                "{}",
                eval::compare_table(&[(m.experiment.clone(), m.clone())])
            );
            print!("\n{}", eval::baseline_block(&m));
            eprintln!("[degs] wrote {}", dir.join("metrics.json").display());
            Ok(())
        }
        Command::Compare { runs, place } => {
            let mut rows = Vec::new();
            for r in &runs {
                rows.push((r.clone(), eval::eval_run(&place.run_dir(r)?)?));
            }
            print!("{}", eval::compare_table(&rows));
            Ok(())
        }
    }
}

/// `degs run`: an error naming the failed stage, its error line and its log when a
/// stage failed.
fn run(experiment: &Path, place: &Where, opts: &RunOptions, quiet: bool) -> Result<()> {
    let exp = Experiment::load_checked(experiment)?;
    let ctx = place.context()?;
    let record = runner::run(&exp, &ctx, opts, &Progress::new(quiet))?;
    match record.stages.iter().find(|s| s.action == Action::Failed) {
        Some(f) => Err(anyhow!(
            "stage {} failed: {} (log: {})",
            f.stage,
            f.error.as_deref().unwrap_or("?"),
            f.log
                .as_deref()
                .map(|p| p.display().to_string())
                .unwrap_or_default()
        )),
        None => Ok(()),
    }
}

fn synth_scene(preset: &str, config: Option<&Path>, set: &[String], out: &Path) -> Result<()> {
    let cfg = synth::load_config(config, Some(preset), set)?;
    let s = synth::write_scene(&cfg, out)?;
    eprintln!(
        "[degs] synth: {} {}x{}, {} train + {} test frames + {} novel views, {} events in {:.2} s → {}",
        s.preset,
        s.width,
        s.height,
        s.train_frames,
        s.test_frames,
        s.novel_frames,
        s.events,
        s.total_s,
        out.display()
    );
    Ok(())
}

fn gc(place: &Where, dry_run: bool) -> Result<()> {
    let ctx = place.context()?;
    let r = status::gc(&ctx.cache, dry_run)?;
    let verb = if dry_run { "would remove" } else { "removed" };
    for (stage, key) in &r.removed {
        println!("{verb} {stage}/{key}");
    }
    println!(
        "{verb} {} entries ({:.1} MiB), kept {}",
        r.removed.len(),
        r.bytes as f64 / (1 << 20) as f64,
        r.kept
    );
    Ok(())
}

fn convert_events(
    input: &Path,
    output: &Path,
    sensor: Option<&str>,
    coord_scale: Option<f64>,
) -> Result<()> {
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
    let s = scene::formats::convert(input, output, &opts)?;
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

/// `degs import LAYOUT SRC OUT`: convert and print the summary.
fn import_recording(a: &ImportArgs) -> Result<()> {
    use scene::manifest::FrameEncoding;
    let opts = import::ImportOptions {
        test_every: a.test_every,
        train_fps: a.train_fps,
        contrast_threshold: a.contrast_threshold,
        frame_encoding: a.frame_encoding.map(|e| match e {
            EncodingArg::Srgb => FrameEncoding::Srgb,
            EncodingArg::Linear => FrameEncoding::Linear,
        }),
        static_camera: a.static_camera,
        calib: a.calib.clone(),
        blender: import::blender::BlenderOptions {
            events: a.events.clone(),
            time_offset: a.time_offset,
            duration: a.duration,
        },
    };
    let summary = import::import(a.layout.layout(), &a.src, &opts, &a.out)?;
    print!("{summary}");
    Ok(())
}
