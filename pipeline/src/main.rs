//! `degs`: run DEGS experiments stage by stage with a content-addressed cache.
//! The command line is [`pipeline::cli`]; what each command does, [`pipeline::commands`].

use clap::Parser;
use pipeline::cli::Cli;

fn main() {
    if let Err(e) = pipeline::commands::execute(Cli::parse().command) {
        eprintln!("degs: {e:#}");
        std::process::exit(1);
    }
}
