//! What each `degs` sub-command does, given its parsed command line ([`crate::cli`]).

use crate::cli::{Command, ConfigCommand, EncodingArg, EventsCommand, ImportArgs, Where};
use crate::demo::{self, DemoOptions};
use anyhow::{Context as _, Result, anyhow, bail};
use runner::experiment::Experiment;
use runner::plan::Plan;
use runner::progress::Progress;
use runner::record::Action;
use runner::run::{self, RunOptions};
use runner::{config_show, eval, plan, stages, status, synth};
use std::path::{Path, PathBuf};
use studies::sweep::Sweep;
use studies::sweep_run;

/// Run one parsed `degs` command.
pub fn execute(command: Command) -> Result<()> {
    match command {
        Command::Run {
            experiment,
            place,
            until,
            force,
            flags,
        } => {
            let opts = RunOptions {
                until: until.as_deref().map(stages::parse_stage).transpose()?,
                force: force
                    .iter()
                    .map(|s| stages::parse_stage(s))
                    .collect::<Result<_>>()?,
                ..flags.options()
            };
            run(&experiment, &place, &opts, flags.quiet)
        }
        Command::Config {
            command: ConfigCommand::Show { experiment, stages },
        } => {
            let ctx = Where {
                cache: None,
                stages,
            }
            .context()?;
            print!(
                "{}",
                config_show::show(&Experiment::load(&experiment)?, &ctx)?
            );
            Ok(())
        }
        Command::Synth {
            preset,
            config,
            set,
            out,
            force,
        } => synth_scene(&preset, config.as_deref(), &set, &out, force),
        Command::Status {
            experiment,
            place,
            verify,
        } => {
            let ctx = place.context()?;
            let exp = Experiment::load_checked(&experiment, &ctx)?;
            let rows = status::status(&exp, &ctx, verify)?;
            print!("{}", status::format_status(&rows));
            Ok(())
        }
        Command::Sweep {
            sweep,
            place,
            flags,
        } => run_sweep(&sweep, &place, &flags.options(), flags.quiet),
        Command::Stress {
            stress,
            place,
            flags,
        } => run_stress(&stress, &place, &flags.options(), flags.quiet),
        Command::Plan {
            experiment,
            place,
            all,
        } => plan(&experiment, &place, all),
        Command::Chart { runs, place, out } => {
            let (curves, runs): (Vec<String>, Vec<String>) = runs
                .into_iter()
                .partition(|r| charts::curve::is_curve_file(r));
            let records = chart_runs(&runs, &place)?;
            let out = match out {
                Some(o) => o,
                None => place.context()?.cache.root.join("charts"),
            };
            let mut files = Vec::new();
            if !records.is_empty() {
                files.extend(charts::write_charts(&records, &out)?);
            }
            if !curves.is_empty() {
                let paths: Vec<PathBuf> = curves.iter().map(PathBuf::from).collect();
                files.extend(charts::curve_draw::write_curve_charts(&paths, &out)?);
            }
            for f in &files {
                println!("{}", f.display());
            }
            eprintln!(
                "[degs] chart: {} runs, {} curves, {} files in {}",
                records.len(),
                curves.len(),
                files.len(),
                out.display()
            );
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
        Command::Export { run, fps, place } => {
            let dir = place.run_dir(&run)?;
            let (out, stage) =
                runner::export::export_run(&dir, &place.context()?, fps, &Progress::new(false))?;
            let plys = std::fs::read_dir(&out)?
                .flatten()
                .filter(|e| e.path().extension().is_some_and(|x| x == "ply"))
                .count();
            println!(
                "{plys} PLY files of the {stage} model in {} (and sequence.zip, times.json)",
                out.display()
            );
            Ok(())
        }
        Command::Render {
            run,
            path,
            fps,
            playback_fps,
            place,
        } => {
            let dir = place.run_dir(&run)?;
            let req = runner::video::VideoRequest {
                path,
                fps,
                playback_fps,
            };
            let (out, stage) =
                runner::video::render_run(&dir, &place.context()?, &req, &Progress::new(false))?;
            println!("{}", video_summary(&out, stage)?);
            Ok(())
        }
        Command::Eval { run, place } => {
            let dir = place.run_dir(&run)?;
            let m = eval::eval_run(&dir, &place.context()?, &Progress::new(false))?;
            for f in &m.scene_findings {
                eprintln!("[degs] scene {f}");
            }
            print!(
                "{}",
                eval::compare_table(&[(m.experiment.clone(), m.clone())])
            );
            print!("\n{}", eval::baseline_block(&m));
            if let Some(sheet) = &m.test_sheet {
                println!(
                    "  test frames beside the renders, the event pseudo image, the blend and ×4 \
                     differences: {}",
                    sheet.display()
                );
            }
            if let Some(map) = &m.test_error_map {
                println!(
                    "  where the error stays (mean |error| over the test frames ×8; model, event \
                     pseudo image, blend): {}",
                    map.display()
                );
            }
            let ssim = |s: Option<f64>, l: Option<f64>| {
                let l = l.map_or(String::new(), |l| format!(", LPIPS {l:.4}"));
                s.map_or(l.clone(), |s| format!(", SSIM {s:.4}{l}"))
            };
            if let Some(p) = m.novel_moving_psnr_mean {
                let depth = m.novel_moving_depth_error_mean.map_or(String::new(), |e| {
                    format!(", depth off by {:.1} % of the true depth", 100.0 * e)
                });
                println!(
                    "  novel views, pixels of moving objects: PSNR {p:.2} dB{}{depth} \
                     (where a model wrong in 3D smears)",
                    ssim(m.novel_moving_ssim_mean, m.novel_moving_lpips_mean)
                );
            }
            if let Some(p) = m.novel_covisible_psnr_mean {
                println!(
                    "  novel views, pixels some train view saw: PSNR {p:.2} dB{}",
                    ssim(m.novel_covisible_ssim_mean, m.novel_covisible_lpips_mean)
                );
            }
            if let Some(p) = m.novel_covisible_still_psnr_mean {
                println!(
                    "  novel views, of those the still ones (no moving object): PSNR {p:.2} dB{}",
                    ssim(m.novel_covisible_still_ssim_mean, None)
                );
            }
            if let Some(t) = &m.trajectory {
                let all = t.seen_motion_mean.map_or(String::new(), |v| {
                    format!(" (all of them move {v:.3} on average)")
                });
                println!(
                    "  moving objects in 3D: {:.0} % of the Gaussians on their pixels lie on \
                     their surface{all}; those move {:.3} where the objects move {:.3} \
                     (error {:.3}, {:.0} % of the true motion)",
                    100.0 * t.on_surface_fraction,
                    t.model_motion_mean,
                    t.true_motion_mean,
                    t.motion_error_mean,
                    100.0 * t.relative_error
                );
            }
            if let Some(sheet) = &m.novel_sheet {
                println!(
                    "  novel views beside their renders and ×4 differences: {}",
                    sheet.display()
                );
            }
            let f = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.4}"));
            match (&m.lpips_net, &m.lpips_note) {
                (Some(net), _) => println!(
                    "LPIPS ({net}, lower is better): test {}, novel views {}",
                    f(m.lpips_mean),
                    f(m.novel_lpips_mean)
                ),
                (None, Some(why)) => eprintln!("[degs] {why}"),
                (None, None) => {}
            }
            for w in &m.warnings {
                eprintln!("[degs] {w}");
            }
            eprintln!("[degs] wrote {}", dir.join("metrics.json").display());
            Ok(())
        }
        Command::Compare { runs, place } => {
            let ctx = place.context()?;
            let mut rows = Vec::new();
            for r in &runs {
                let m = eval::eval_run(&place.run_dir(r)?, &ctx, &Progress::new(false))?;
                rows.push((r.clone(), m));
            }
            print!("{}", eval::compare_table(&rows));
            Ok(())
        }
    }
}

/// `degs run`: an error naming the failed stage, its error line and its log when a
/// stage failed.
fn run(experiment: &Path, place: &Where, opts: &RunOptions, quiet: bool) -> Result<()> {
    let ctx = place.context()?;
    let exp = Experiment::load_checked(experiment, &ctx)?;
    let record = run::run(&exp, &ctx, opts, &Progress::new(quiet))?;
    for w in runner::record::warning_lines(&record.stages) {
        eprintln!("[degs] {w}");
    }
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
        None => match record.stages.iter().find(|s| s.action.could_not_run()) {
            Some(s) => Err(anyhow!(
                "stage {} could not run: {}",
                s.stage,
                s.error.as_deref().unwrap_or("?")
            )),
            None => Ok(()),
        },
    }
}

/// `degs stress`: failed variants are the point of it, so only a broken stress file or
/// an unmakeable clean scene is an error.
fn run_stress(file: &Path, place: &Where, opts: &RunOptions, quiet: bool) -> Result<()> {
    let stress = studies::stress::variants::StressFile::load(file)?;
    let ctx = place.context()?;
    let record = studies::stress::run(&stress, &ctx, opts, &Progress::new(quiet))?;
    let dir = ctx.cache.run_dir(&stress.name);
    let failed = record.results.iter().filter(|r| r.error.is_some()).count();
    println!(
        "{} runs ({} with an error), report: {}",
        record.results.len(),
        failed,
        dir.join("report.md").display()
    );
    eprintln!("[degs] wrote {}", dir.join("stress.json").display());
    Ok(())
}

/// `degs sweep`: an error naming the experiments with a failed stage.
fn run_sweep(file: &Path, place: &Where, opts: &RunOptions, quiet: bool) -> Result<()> {
    let sweep = Sweep::load(file)?;
    let ctx = place.context()?;
    let record = sweep_run::run(&sweep, &ctx, opts, &Progress::new(quiet))?;
    print!("{}", sweep_run::format_summary(&record));
    eprintln!(
        "[degs] wrote {}",
        ctx.cache.run_dir(&sweep.name).join("sweep.json").display()
    );
    let failed: Vec<&str> = record
        .experiments
        .iter()
        .filter(|e| e.status.as_deref() != Some("ok"))
        .map(|e| e.name.as_str())
        .collect();
    if failed.is_empty() {
        Ok(())
    } else {
        Err(anyhow!(
            "a stage failed in {} (see runs/<name>/run.json and the stage logs)",
            failed.join(", ")
        ))
    }
}

/// `degs plan`: an experiment file, or a sweep file (one with `base` or `[axes]`).
fn plan(file: &Path, place: &Where, all: bool) -> Result<()> {
    // absolute paths: the commands run from wherever the scheduler starts them
    let mut ctx = place.context()?;
    ctx.cache.root = std::path::absolute(&ctx.cache.root)?;
    ctx.stage_dir = ctx.stage_dir.map(std::path::absolute).transpose()?;
    let p = if studies::sweep::is_sweep_file(file) {
        let sweep = Sweep::load(file)?;
        let exps: Vec<Experiment> = sweep_run::write_experiments(&sweep, &ctx)?
            .into_iter()
            .map(|(e, _)| e)
            .collect();
        Plan::build(&sweep.name, &exps, &ctx)?
    } else {
        let exp = Experiment::load_checked(file, &ctx)?;
        Plan::build(&exp.name, std::slice::from_ref(&exp), &ctx)?
    };
    print!("{}", p.shell(all));
    let (snake, slurm) = plan::write_files(&p, &ctx, all)?;
    eprintln!(
        "[degs] plan: {} stages ({} to run); wrote {} and {}",
        p.jobs.len(),
        p.to_run(all).count(),
        snake.display(),
        slurm.display()
    );
    Ok(())
}

/// The run records named by `runs`: run directories, experiment names, or sweep names
/// (`runs/<sweep>/sweep.json`: every experiment of the sweep that has a record).
fn chart_runs(runs: &[String], place: &Where) -> Result<Vec<runner::record::RunRecord>> {
    let mut out: Vec<runner::record::RunRecord> = Vec::new();
    for r in runs {
        let sweep = [PathBuf::from(r), place.context()?.cache.run_dir(r)]
            .into_iter()
            .map(|d| d.join("sweep.json"))
            .find(|p| p.is_file());
        let dirs = match sweep {
            Some(p) => {
                let rec: sweep_run::SweepRecord = serde_json::from_slice(
                    &std::fs::read(&p).with_context(|| format!("{}: cannot read", p.display()))?,
                )
                .with_context(|| format!("{}: not a degs sweep record", p.display()))?;
                rec.experiments
                    .iter()
                    .map(|e| e.run_record.clone())
                    .filter(|p| p.is_file())
                    .filter_map(|p| p.parent().map(Path::to_path_buf))
                    .collect()
            }
            None => vec![place.run_dir(r)?],
        };
        for d in dirs {
            let rec = runner::record::RunRecord::read(&d.join("run.json"))?;
            if !out.iter().any(|o| o.experiment == rec.experiment) {
                out.push(rec);
            }
        }
    }
    Ok(out)
}

fn synth_scene(
    preset: &str,
    config: Option<&Path>,
    set: &[String],
    out: &Path,
    force: bool,
) -> Result<()> {
    let mut rule = scene::atomic::OutputRule::new(::synth::SYNTH_COMMAND).force(force);
    if let Some(c) = config {
        rule = rule.source(c);
    }
    let cfg = synth::load_config(config, Some(preset), set)?;
    let s = synth::write_scene(&cfg, out, &rule)?;
    eprintln!("[degs] synth: {} → {}", s.line(), out.display());
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
    let same = |p: &Path| std::fs::canonicalize(p).ok();
    if output.exists() && same(input) == same(output) {
        bail!(
            "{}: the output is the input; write the converted events elsewhere",
            output.display()
        );
    }
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
        alignment: import::EventsAlignment {
            events: a.events.clone(),
            time_offset: a.time_offset,
            duration: a.duration,
        },
        downscale: a.downscale,
        timestamps: a.timestamps.clone(),
        name_seconds: a.name_seconds,
        force: a.force,
    };
    let summary = import::import(a.layout.layout(), &a.src, &opts, &a.out)?;
    print!("{summary}");
    Ok(())
}

/// One line on a `degs render` output folder: frames, previews, and why no MP4.
pub(crate) fn video_summary(out: &std::path::Path, stage: &str) -> anyhow::Result<String> {
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("report.json"))?)?;
    let mp4 = match r["mp4"].as_str() {
        Some(m) => format!(", {m}"),
        None => format!(" ({})", r["mp4_note"].as_str().unwrap_or("no MP4")),
    };
    Ok(format!(
        "{} frames of the {stage} model ({} path, {}×{}) in {}: frames/, preview.gif{mp4}",
        r["frames"],
        r["path"].as_str().unwrap_or("?"),
        r["width"],
        r["height"],
        out.display()
    ))
}
