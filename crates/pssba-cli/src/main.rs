//! `pssba`: LiDAR bundle adjustment with progressive spatial smoothing, from the command line.
//! `main` only parses and reports; each subcommand's `run` does the work and returns anyhow
//! errors, printed once here with their chain.

mod adjust;
mod balm;
mod bench;
mod cli;
mod demo;
mod eval;
mod export;
mod import;
mod input;
mod inspect;
mod logging;
mod report;
mod run;
mod simulate;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = cli::Cli::parse();
    logging::init(cli.verbose, cli.quiet);
    let outcome = match cli.command {
        cli::Command::Adjust(args) => adjust::run(&args),
        cli::Command::Inspect(args) => inspect::run(&args),
        cli::Command::Import(args) => import::run(&args),
        cli::Command::Eval(cli::EvalCommand::Ape(args)) => eval::run_ape(&args),
        cli::Command::Eval(cli::EvalCommand::Occupancy(args)) => eval::run_occupancy(&args),
        cli::Command::Demo(args) => demo::run(&args),
        cli::Command::Export(args) => export::run(&args),
        cli::Command::Run(args) => run::run(&args, cli.verbose),
        cli::Command::Stage(stage) => run::stage(stage),
        cli::Command::Simulate(args) => simulate::run(&args),
        cli::Command::Bench(args) => bench::run(&args),
    };
    match outcome {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            ExitCode::FAILURE
        }
    }
}
