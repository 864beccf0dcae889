//! `pheromone`: the command-line front end. Thin glue over the `field` and `publishers` crates.

mod cmd;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// A zero-copy shared-memory pheromone field for robots on one host.
///
/// One `field` process owns the grid in iceoryx2 shared memory and publishes an immutable frame
/// every tick; localizer, depositor and follower processes attach to it by name.
#[derive(Parser)]
#[command(name = "pheromone", version, propagate_version = true)]
struct Cli {
    /// Show iceoryx2's own log output.
    #[arg(long, global = true)]
    verbose: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a field process: owns the grid, ticks, publishes frames, applies deposits.
    Field(cmd::field::FieldArgs),
    /// Closed-form tuning of the evaporation rate (seed 000 eqs. 23 and 26).
    Tune(cmd::tune::TuneArgs),
    /// Read a running field: print its header and the value at a point (a minimal reader).
    Probe(cmd::probe::ProbeArgs),
    /// Send one deposit to a running field.
    Deposit(cmd::probe::DepositArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    field::shm::set_verbose(cli.verbose);
    let result = match cli.command {
        Command::Field(a) => cmd::field::run(a),
        Command::Tune(a) => cmd::tune::run(a),
        Command::Probe(a) => cmd::probe::run_probe(a),
        Command::Deposit(a) => cmd::probe::run_deposit(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            if e.downcast_ref::<cmd::BadInput>().is_some() {
                ExitCode::from(2)
            } else {
                ExitCode::from(1)
            }
        }
    }
}
