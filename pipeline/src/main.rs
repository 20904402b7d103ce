//! `degs`: run DEGS experiments stage by stage with a content-addressed cache.
//! The command line is [`pipeline::cli`]; what each command does, [`pipeline::commands`].

use clap::Parser;
use pipeline::cli::Cli;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = Cli::parse();
    stagekit::exit_on_error("degs", || {
        pipeline::commands::execute(cli.command).map(|()| ExitCode::SUCCESS)
    })
}
