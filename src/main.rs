//! `pheromone`: the command-line front end. Thin glue over the `field` and `publishers` crates.

// The CLI's doc comments are its `--help` text (clap), written for a terminal: `<NAME>` and
// `[mapping]` in them are placeholders and TOML tables, not HTML tags or links.
#![allow(rustdoc::invalid_html_tags, rustdoc::broken_intra_doc_links)]

// Printing never panics (issue 54): std's `println!`, `eprintln!`, `print!` and `eprint!` panic
// when stdout or stderr is a pipe whose reader has gone (`pheromone sim … 2>&1 | head -1`), which
// stopped a run before it wrote its files. These shadow them in the whole binary (declared
// before `mod cmd`) and drop what cannot be written: the run goes on, writes its files and exits
// with its own status.
macro_rules! println {
    () => { $crate::print_quietly(false, format_args!("\n")) };
    ($($arg:tt)*) => { $crate::print_quietly(false, format_args!("{}\n", format_args!($($arg)*))) };
}
macro_rules! eprintln {
    () => { $crate::print_quietly(true, format_args!("\n")) };
    ($($arg:tt)*) => { $crate::print_quietly(true, format_args!("{}\n", format_args!($($arg)*))) };
}
macro_rules! print {
    ($($arg:tt)*) => { $crate::print_quietly(false, format_args!($($arg)*)) };
}
macro_rules! eprint {
    ($($arg:tt)*) => { $crate::print_quietly(true, format_args!($($arg)*)) };
}

mod cmd;

use std::process::ExitCode;

/// Writes to stderr (`to_stderr`) or stdout, dropping what a closed pipe or a full disk refuses.
fn print_quietly(to_stderr: bool, args: std::fmt::Arguments) {
    use std::io::Write as _;
    let _ = if to_stderr {
        std::io::stderr().write_fmt(args)
    } else {
        std::io::stdout().write_fmt(args)
    };
}

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

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
    /// iceoryx2 domain: services and nodes use the prefix `<D>_iox2_` instead of `iox2_`
    /// (`<D>_iox2u<uid>_` for a user other than root: a domain belongs to one user), so
    /// processes of two domains on one host share nothing (as on two hosts). Also taken from
    /// the environment variable PHEROMONE_IOX_DOMAIN, which children inherit.
    #[arg(long, global = true, value_name = "D", value_parser = cmd::check::iox_domain())]
    iox_domain: Option<String>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a whole scenario as separate processes and report what happened.
    Sim(Box<cmd::sim::SimArgs>),
    /// Run paper 004's grid of experiments on all cores (exploration vs robots, R_C, merging), or
    /// paper 002's parameter study of trail following (`sweep trail-following`).
    Sweep(cmd::sweep::SweepArgs),
    /// Run a field process: owns the grid, ticks, publishes frames, applies deposits.
    Field(Box<cmd::field::FieldArgs>),
    /// Closed-form tuning of the evaporation rate (paper 000 eqs. 23 and 26).
    Tune(cmd::tune::TuneArgs),
    /// Run the simulator process (true poses, sensors, scripted deposits, the lockstep clock).
    World(cmd::roles::WorldArgs),
    /// Run the localizer (EKF) of one robot.
    Localizer(cmd::roles::LocalizerArgs),
    /// Run the mapper of one robot: its occupancy + pheromone map, published as a field frame.
    Mapper(cmd::roles::MapperArgs),
    /// Run the depositor of one robot.
    Depositor(cmd::roles::DepositorArgs),
    /// Run the follower of one robot.
    Follower(cmd::roles::FollowerArgs),
    /// Run the graph writer of a node-graph (regions) run: graph, regions and lockstep clock.
    Graph(cmd::graph::GraphArgs),
    /// Run one robot of a node-graph (regions) run.
    GraphRobot(cmd::graph::GraphRobotArgs),
    /// Read a running field: print its header and the value at a point (a minimal reader).
    Probe(cmd::probe::ProbeArgs),
    /// Send one deposit to a running field.
    Deposit(cmd::deposit::DepositArgs),
    /// List the fields on this host: grid, tick rate, sequence, readers, depositors, alive.
    List(cmd::list::ListArgs),
    /// Save a running field's next frame as NumPy .npy or as a ROS map_server map (PGM + YAML).
    Export(cmd::export::ExportArgs),
    /// Serve a field to thin radio clients (paper 002's DLE/CRC frames over UDP).
    Gateway(cmd::gateway::GatewayArgs),
    /// Serve a live web page of a running field: heat map, robots, statistics.
    View(cmd::view::ViewArgs),
    /// Publish a field's inputs on Zenoh for mirrors on other hosts (and frames for dashboards).
    Bridge(cmd::bridge::BridgeArgs),
    /// Show a field to ROS 2 over Zenoh (rmw_zenoh): GridMap, OccupancyGrid; poses → deposits.
    Ros2(Box<cmd::ros2::Ros2Args>),
    /// Record a field as a ROS 2 MCAP file (GridMap and OccupancyGrid messages).
    Record(cmd::ros2::RecordArgs),
    /// Measure latency and throughput side by side with raw iceoryx2, a Unix socket and Zenoh.
    Bench(cmd::bench::BenchArgs),
    /// One peer process of `pheromone bench` (started by it).
    #[cfg(feature = "bench")]
    #[command(hide = true)]
    BenchPeer(cmd::bench::BenchPeerArgs),
    /// Every value-taking flag of every subcommand with its type (for the flag-fuzzing test).
    #[command(name = "__flags", hide = true)]
    Flags,
}

/// The command line, where a negative number is a value wherever a value is expected (`--x -3`;
/// `--robots -1` is refused by its flag's parser, naming it, not taken for an unknown flag).
fn parse_cli() -> Cli {
    fn negatives(c: clap::Command) -> clap::Command {
        c.allow_negative_numbers(true).mut_subcommands(negatives)
    }
    let matches = negatives(Cli::command()).get_matches();
    Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit())
}

/// What the process does before its command: the death signal its supervisor asked for, the
/// signal handling, the command line, the iceoryx2 domain. `Err`: exit with this status.
fn start() -> Result<Cli, ExitCode> {
    // Started by a supervisor that asked it (before any thread exists): SIGTERM when the
    // supervisor dies; the request is not passed on to this process's own children.
    let gone = pheromone_supervisor::die_with_parent_as_asked();
    std::env::remove_var(pheromone_supervisor::DIE_WITH_PARENT_ENV);
    if let Err(e) = gone {
        eprintln!("error: {e}");
        return Err(ExitCode::from(1));
    }
    // This program owns its process: its nodes stop on SIGINT/SIGTERM through iceoryx2's handler
    // (the library's default is to install none, for programs that embed it).
    pheromone_field::shm::handle_termination_requests();
    let cli = parse_cli();
    pheromone_field::shm::set_verbose(cli.verbose);
    // The inherited domain is checked as the flag is, before anything starts.
    if cli.iox_domain.is_none() {
        if let Ok(d) = std::env::var(pheromone_field::shm::IOX_DOMAIN_ENV) {
            if let Err(e) = cmd::check::parse_iox_domain(&d) {
                eprintln!("error: {}={d}: {e}", pheromone_field::shm::IOX_DOMAIN_ENV);
                return Err(ExitCode::from(2));
            }
        }
    }
    if let Some(d) = &cli.iox_domain {
        // Single-threaded here: every node this process creates reads it (`domain_config`).
        std::env::set_var(pheromone_field::shm::IOX_DOMAIN_ENV, d);
    }
    Ok(cli)
}

fn main() -> ExitCode {
    let cli = match start() {
        Ok(cli) => cli,
        Err(code) => return code,
    };
    let result = match cli.command {
        Command::Sim(a) => cmd::sim::run(*a),
        Command::Sweep(a) => cmd::sweep::run(a),
        Command::Field(a) => match a.mirror.clone() {
            Some(endpoint) => cmd::bridge::run_mirror(&a, &endpoint),
            None => cmd::field::run(*a),
        },
        Command::Tune(a) => cmd::tune::run(a),
        Command::World(a) => cmd::roles::run_world_cmd(a),
        Command::Localizer(a) => cmd::roles::run_localizer_cmd(a),
        Command::Mapper(a) => cmd::roles::run_mapper_cmd(a),
        Command::Depositor(a) => cmd::roles::run_depositor_cmd(a),
        Command::Follower(a) => cmd::roles::run_follower_cmd(a),
        Command::Graph(a) => cmd::graph::run_writer(a),
        Command::GraphRobot(a) => cmd::graph::run_robot(a),
        Command::Probe(a) => cmd::probe::run_probe(a),
        Command::Deposit(a) => cmd::deposit::run_deposit(a),
        Command::List(a) => cmd::list::run(a),
        Command::Export(a) => cmd::export::run(a),
        Command::Gateway(a) => cmd::gateway::run(a),
        Command::View(a) => cmd::view::run(a),
        Command::Bridge(a) => cmd::bridge::run(a),
        Command::Ros2(a) => cmd::ros2::run(*a),
        Command::Record(a) => cmd::ros2::run_record(a),
        Command::Bench(a) => cmd::bench::run(a),
        #[cfg(feature = "bench")]
        Command::BenchPeer(a) => cmd::bench::run_peer(a),
        Command::Flags => cmd::flags::print(Cli::command()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.downcast_ref::<cmd::stop::Stopped>().is_some() => {
            let stopped = e.downcast_ref::<cmd::stop::Stopped>().expect("checked");
            ExitCode::from(stopped.exit_status())
        }
        Err(e) => {
            eprintln!("error: {}", cmd::one_line(&e));
            if cmd::is_bad_input(&e) {
                ExitCode::from(2)
            } else if e.downcast_ref::<cmd::deposit::NotTaken>().is_some() {
                ExitCode::from(3)
            } else {
                ExitCode::from(1)
            }
        }
    }
}
