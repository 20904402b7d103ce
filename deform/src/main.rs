//! `deform`: the joint training of the dynamic Gaussians with RGB, event and motion
//! supervision (DEGS §3.4–3.5). The library ([`deform::stage`]) does the work.

use clap::{Parser, Subcommand};
use deform::stage::{self, TrainArgs};
use stagekit::{Progress, exit_on_error, sigint_flag};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    version,
    about = "Joint RGB + event + motion training of the dynamic Gaussians (DEGS)"
)]
struct Cli {
    #[command(subcommand)]
    verb: Verb,
}

#[derive(Subcommand)]
enum Verb {
    /// Train from the warm-up model with the event and motion losses; writes the model,
    /// posenet.safetensors, depth/, renders/ of the test frames, settings.toml, report.json.
    Train(TrainArgs),
    /// The settings of `deform train`: `--defaults` prints them as TOML, `--check FILE`
    /// checks a settings file. The runner learns the settings this way.
    Settings(stagekit::SettingsArgs),
}

fn main() -> ExitCode {
    exit_on_error("deform", || match Cli::parse().verb {
        Verb::Settings(a) => {
            stagekit::verb::run::<deform::settings::DeformSettings>(&a, stagekit::verb::no_files)
        }
        Verb::Train(args) => {
            let total = stage::joint_iterations(&args)?;
            let progress = Progress::new("deform", total as u64);
            let o = stage::train(&args, sigint_flag(), |s| {
                progress.set(s.iteration as u64, || {
                    format!(
                        "rgb {:.4} event {:.4} motion {:.4}  PSNR {:.2} dB  {} bound",
                        s.l_rgb, s.l_event, s.l_motion, s.psnr, s.bound
                    )
                })
            })?;
            progress.finish();
            let r = &o.report;
            eprintln!(
                "{}: {} joint iterations, {} Gaussians, test {}{}",
                o.out.display(),
                r.iterations,
                r.gaussians,
                r.test.figures(),
                if r.interrupted { " (interrupted)" } else { "" }
            );
            Ok::<_, scene::Error>(if r.interrupted {
                ExitCode::from(130)
            } else {
                ExitCode::SUCCESS
            })
        }
    })
}
