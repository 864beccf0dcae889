//! `pheromone bench`: glue over the `pheromone-bench` crate. The measured parties run as separate
//! processes: this binary again, through the hidden `bench-peer` subcommand.

use anyhow::Context;
use clap::Args;
use pheromone_bench::{Latency, Mode, Options, Report, Section, VisibleReport};

use super::{bad, bad_from};

/// Measure the field side by side with the alternatives, on this machine, in one run.
///
/// Hop latency (ours vs raw iceoryx2), frame delivery of 1 MiB and 16 MiB fields to 1 and 8
/// reader processes (ours vs a Unix socket with serde, and Zenoh on loopback in a build with
/// `--features zenoh`), deposit-to-visible latency, the tick/memcpy ratio at each size, and paper
/// 002's PIR round trip to a `pheromone gateway` over UDP loopback beside a direct shared-memory
/// read of the same antennas, with the PIRs per second one gateway core serves. With `--features
/// zenoh`, a field mirror over Zenoh (a 1024² origin at 100 Hz in one iceoryx2 domain, a bridge,
/// a mirror in another): bytes on the wire against raw frames at 10 and 1000 deposits/s,
/// origin-to-mirror lag, keyframe size and catch-up; and `pheromone ros2`'s CPU per published MB
/// against a plain Zenoh publisher of the same bytes. `--only mirror` (or any list of sections)
/// runs part of it. Progress goes to stderr. The default run takes a few minutes; `--quick` under
/// a minute.
#[derive(Args)]
pub struct BenchArgs {
    /// Print one JSON object on stdout instead of tables.
    #[arg(long)]
    json: bool,
    /// Fewer samples: well under a minute.
    #[arg(long, conflicts_with = "smoke")]
    quick: bool,
    /// A few samples of everything (for tests): checks that each measurement runs.
    #[arg(long, hide = true)]
    smoke: bool,
    /// Tick rate (Hz) of the field in the deposit-to-visible measurement.
    #[arg(long, value_parser = super::f32_pos(1e4), default_value_t = 100.0)]
    tick_hz: f32,
    /// Cells per side of the field in the deposit-to-visible measurement.
    #[arg(long, value_parser = super::int::<u32>(16, 4096), default_value_t = 1024)]
    visible_width: u32,
    /// Do not pin processes to cores.
    #[arg(long)]
    no_pin: bool,
    /// Run only these sections (comma-separated); the others are empty or null in --json.
    #[arg(long, value_enum, value_delimiter = ',', value_name = "SECTION")]
    only: Vec<SectionArg>,
    /// Run the whole measurement N times: the tables of the last run, then every target's
    /// min / median / max over the N runs, so the noise shows (--json: {"runs": [...],
    /// "targets": [...]}). Default: 5 for the full run, 1 with --quick.
    #[arg(long, value_parser = super::int::<usize>(1, 100), value_name = "N")]
    repeats: Option<usize>,
    /// `--only scale`: the robot counts (comma-separated; default 8,16,32,64,128,256, with
    /// --quick 8,16).
    #[arg(long, value_parser = super::int::<usize>(1, 256), value_delimiter = ',', value_name = "N,…")]
    scale_robots: Vec<usize>,
    /// `--only scale`: simulated seconds of each run (default 10, with --quick 5).
    #[arg(long, value_parser = super::f64_pos(3600.0), value_name = "SECS")]
    scale_duration_s: Option<f64>,
    /// `--only scale`: draw the chart (a log-log panel per figure) into this PNG.
    #[arg(long, value_parser = super::check::out_file(), value_name = "FILE.png")]
    scale_chart: Option<std::path::PathBuf>,
    /// The `peers` section: the Python interpreter that runs OpenCV, SciPy and NumPy (e.g.
    /// `.venv/bin/python` after `pip install ./python[peers]`).
    #[arg(long, default_value = "python3", value_name = "PYTHON")]
    peers_python: String,
}

/// A section of `pheromone bench` (`--only`).
#[derive(Clone, Copy, clap::ValueEnum, Debug)]
enum SectionArg {
    /// Tick vs memcpy.
    Tick,
    /// Hop latency.
    Hop,
    /// Frame delivery.
    Frames,
    /// Deposit to visible, and the field's CPU.
    Visible,
    /// Paper 002's PIR through a gateway.
    Gateway,
    /// A field mirror over Zenoh (a build with --features zenoh).
    Mirror,
    /// libpheromone's C reader against the Rust reader (frame latency, sampling cost).
    CAbi,
    /// The cost of a bigger swarm: ias-ss at 8 … 256 robots as processes and in one process
    /// (only when named: it takes long).
    Scale,
    /// Tick-start lateness beside two busy loops, with and without real-time scheduling.
    Timing,
    /// Paper 004's map merge vs memcpy.
    Merge,
    /// CPU per published MB of `pheromone ros2` against a plain Zenoh publisher (a build with
    /// --features zenoh).
    Ros2,
    /// The ambient tick and the merge against OpenCV, SciPy and NumPy (--peers-python).
    Peers,
}

impl From<SectionArg> for Section {
    fn from(s: SectionArg) -> Self {
        match s {
            SectionArg::Tick => Section::Tick,
            SectionArg::Hop => Section::Hop,
            SectionArg::Frames => Section::Frames,
            SectionArg::Visible => Section::Visible,
            SectionArg::Gateway => Section::Gateway,
            SectionArg::Mirror => Section::Mirror,
            SectionArg::CAbi => Section::CAbi,
            SectionArg::Scale => Section::Scale,
            SectionArg::Timing => Section::Timing,
            SectionArg::Merge => Section::Merge,
            SectionArg::Ros2 => Section::Ros2,
            SectionArg::Peers => Section::Peers,
        }
    }
}

/// `--only` of a section that needs Zenoh (mirror, ros2), in a build without it: refused.
fn check_zenoh_sections(only: &[SectionArg]) -> anyhow::Result<()> {
    let zenoh_only = only
        .iter()
        .find(|s| matches!(s, SectionArg::Mirror | SectionArg::Ros2));
    match (pheromone_bench::ZENOH_BUILT, zenoh_only) {
        (false, Some(s)) => Err(bad(format!(
            "--only {}: this build has no Zenoh: rebuild with `cargo build --release --features zenoh`",
            serde_json::to_string(&Section::from(*s))?.trim_matches('"')
        ))),
        _ => Ok(()),
    }
}

/// One peer process of a measurement (started by `pheromone bench`).
#[derive(Args)]
pub struct BenchPeerArgs {
    /// The peer's specification, JSON.
    spec: String,
}

pub fn run(a: BenchArgs) -> anyhow::Result<()> {
    // --tick-hz and --visible-width: their parsers have checked the ranges.
    check_zenoh_sections(&a.only)?;
    let program = std::env::current_exe().context("find this executable to start the peers")?;
    let opts = Options {
        mode: if a.smoke {
            Mode::Smoke
        } else if a.quick {
            Mode::Quick
        } else {
            Mode::Full
        },
        only: a.only.iter().map(|s| Section::from(*s)).collect(),
        pin: !a.no_pin,
        tick_hz: a.tick_hz,
        visible_width: a.visible_width,
        progress: true,
        launcher: pheromone_bench::Launcher {
            program,
            args: vec!["bench-peer".into()],
        },
        scale: pheromone_bench::scale::ScaleOptions {
            robots: a.scale_robots.clone(),
            duration_s: a.scale_duration_s,
            chart: a.scale_chart.clone(),
        },
        peers_python: a.peers_python.clone(),
    };
    let repeats = a
        .repeats
        .unwrap_or(if opts.mode == Mode::Full && !scale_only(&opts) {
            5
        } else {
            1
        });
    let mut runs = Vec::with_capacity(repeats);
    for i in 0..repeats {
        if repeats > 1 {
            eprintln!("bench: run {} of {repeats}", i + 1);
        }
        runs.push(pheromone_bench::run(&opts)?);
    }
    let spread = pheromone_bench::targets::spread(&runs);
    match (a.json, runs.as_slice()) {
        (true, [one]) => println!("{}", serde_json::to_string(one)?),
        (true, _) => println!("{}", serde_json::json!({ "runs": runs, "targets": spread })),
        (false, [.., last]) => {
            print_tables(last);
            if runs.len() > 1 {
                print_spread(&spread, runs.len());
            }
        }
        (false, []) => {}
    }
    Ok(())
}

/// `--only scale`: one run of it is long enough.
fn scale_only(o: &Options) -> bool {
    o.only.iter().all(|s| *s == Section::Scale) && !o.only.is_empty()
}

/// The scale section: a row per size and mode, then each figure's growth exponent.
fn print_scale(x: &pheromone_bench::scale::ScaleReport) {
    println!(
        "\nscale: '{}' with N robots, {} simulated s per run ({} build)\n\
         robots mode            start-up s  wall s/sim s  processes  services  RSS MiB  PSS MiB  shm MiB",
        x.scenario, x.duration_s, x.build
    );
    let mib = |b: u64| b as f64 / 1048576.0;
    for r in &x.rows {
        let mode = serde_json::to_string(&r.mode).unwrap_or_default();
        match &r.error {
            Some(e) => println!("{:>6} {:<15} FAILED: {e}", r.robots, mode.trim_matches('"')),
            None => println!(
                "{:>6} {:<15} {:>10.2} {:>13.3} {:>10} {:>9} {:>8.0} {:>8.0} {:>8.1}",
                r.robots,
                mode.trim_matches('"'),
                r.startup_s,
                r.wall_per_sim_s,
                r.processes,
                r.services,
                mib(r.peak_rss_bytes),
                mib(r.peak_pss_bytes),
                mib(r.shm_bytes)
            ),
        }
    }
    let b: Vec<String> = x
        .growth
        .iter()
        .map(|(k, g)| format!("{k} {:.2}", g.exponent))
        .collect();
    println!("growth exponents (figure ∝ N^b): {}", b.join(", "));
    if let Some(c) = &x.chart {
        println!("chart: {}", c.display());
    }
}

/// Every target's measured value over the runs: min / median / max, and how often it was met.
fn print_spread(spread: &[pheromone_bench::targets::Spread], runs: usize) {
    println!(
        "
targets over {runs} runs                      min     median        max   met"
    );
    for t in spread {
        println!(
            "  {} {} {}\n      {:>10.3} {:>10.3} {:>10.3}   {}/{}",
            t.name, t.op, t.limit, t.min, t.median, t.max, t.met, t.runs
        );
    }
}

pub fn run_peer(a: BenchPeerArgs) -> anyhow::Result<()> {
    pheromone_bench::run_peer(&a.spec).map_err(|e| match e {
        pheromone_bench::BenchError::Spec { .. } => bad_from(e),
        e => e.into(),
    })
}

fn lat(l: &Latency, scale: f64, unit: &str) -> String {
    format!(
        "{:>9.1} {:>9.1} {:>9.1} {:>9.1} {unit}",
        l.p50 * scale,
        l.p99 * scale,
        l.p999 * scale,
        l.max * scale
    )
}

fn print_tables(r: &Report) {
    println!(
        "machine: {} ({} cores, {} {}), {} run{}",
        r.machine.cpu_model,
        r.machine.cores,
        r.machine.os,
        r.machine.kernel,
        serde_json::to_string(&r.mode)
            .unwrap_or_default()
            .trim_matches('"'),
        if r.pinned { ", pinned" } else { "" }
    );
    if !r.tick_vs_memcpy.is_empty() {
        print_ticks(r);
    }
    if !r.merge_vs_memcpy.is_empty() {
        print_merges(r);
    }
    print_hop(r);
    print_frames(r);
    print_visible(r);
    print_timing(r);
    print_gateway(r);
    if let Some(m) = &r.mirror {
        print_mirror(m);
    }
    if let Some(c) = &r.c_abi {
        print_c_abi(c);
    }
    if let Some(x) = &r.scale {
        print_scale(x);
    }
    if let Some(x) = &r.ros2 {
        print_ros2(x);
    }
    if let Some(x) = &r.peers {
        print_peers(x);
    }
    print_targets(r);
}

/// The hop latency table, if the run measured it.
fn print_hop(r: &Report) {
    if let Some(h) = &r.hop_ns {
        println!("\nhop (one way)                    p50       p99     p99.9       max");
        println!("ours, wait             {}", lat(&h.ours, 1e-3, "µs"));
        println!(
            "raw iceoryx2, wait     {}",
            lat(&h.raw_iceoryx2, 1e-3, "µs")
        );
        println!(
            "ours, busy-poll        {}",
            lat(&h.busy_poll.ours, 1e-3, "µs")
        );
        println!(
            "raw iceoryx2, busy     {}",
            lat(&h.busy_poll.raw_iceoryx2, 1e-3, "µs")
        );
    }
}

/// The frame delivery table: every reader's latency and CPU share, per frame size.
fn print_frames(r: &Report) {
    if !r.frame_ns.is_empty() {
        println!("\nframe delivery                       p50       p99     p99.9       max");
    }
    for (size, f) in &r.frame_ns {
        let rows: [(&str, Option<&Latency>); 11] = [
            ("ours, 1 reader", Some(&f.ours)),
            ("UDS+serde, 1 reader", Some(&f.uds_serde)),
            ("Zenoh, 1 reader", f.zenoh.as_ref()),
            ("ours, 8 readers", Some(&f.readers_8.ours)),
            ("UDS+serde, 8 readers", Some(&f.readers_8.uds_serde)),
            ("Zenoh, 8 readers", f.readers_8.zenoh.as_ref()),
            ("ours, busy-poll", Some(&f.ours_busy_poll)),
            ("raw iceoryx2, wait", Some(&f.raw_iceoryx2)),
            ("raw iceoryx2, busy", Some(&f.raw_iceoryx2_busy_poll)),
            ("ours, paced spin", Some(&f.ours_spin)),
            ("raw, paced spin", Some(&f.raw_iceoryx2_spin)),
        ];
        for (what, l) in rows {
            match l {
                Some(l) => println!("{size:>5} {what:<20} {}", lat(l, 1e-3, "µs")),
                None => println!("{size:>5} {what:<20} (not built: --features zenoh)"),
            }
        }
        let c = &f.reader_cpu_share;
        let share = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.3}"));
        println!(
            "{size:>5} reader CPU (share of a core): ours wait {} spin {} busy {}; raw wait {} spin {} busy {}",
            share(c.ours_wait),
            share(c.ours_spin),
            share(c.ours_busy_poll),
            share(c.raw_iceoryx2_wait),
            share(c.raw_iceoryx2_spin),
            share(c.raw_iceoryx2_busy_poll)
        );
    }
}

/// Deposit to visible (ticking and publishing on deposit) and the field's CPU, if measured.
fn print_visible(r: &Report) {
    if let (Some(v), Some(o)) = (
        &r.deposit_to_visible_us,
        &r.deposit_to_visible_on_deposit_us,
    ) {
        println!(
            "\ndeposit to visible, {w}x{w} at {} Hz  {}",
            v.tick_hz,
            lat(&v.latency, 1e-3, "ms"),
            w = v.width
        );
        println!(
            "  publishing on deposit            {}   (tick compute p50 {:.0} µs)",
            lat(&o.latency, 1.0, "µs"),
            o.tick_compute_us.p50
        );
        let rt = r.deposit_to_visible_on_deposit_rt_us.as_ref();
        if let Some(rt) = rt {
            println!(
                "  on deposit, FIFO + spin + busy   {}",
                lat(&rt.latency, 1.0, "µs")
            );
        }
        print_visible_stages(
            [("ticking", v), ("on deposit", o)]
                .into_iter()
                .chain(rt.map(|rt| ("FIFO + spin", rt))),
        );
        println!(
            "field CPU (share of a core)   deposits/s  ticking  on deposit  frames/s  FIFO+spin"
        );
        for (i, (t, d)) in v.field_cpu.iter().zip(&o.field_cpu).enumerate() {
            let spin = rt
                .and_then(|rt| rt.field_cpu.get(i))
                .map_or("-".to_string(), |c| format!("{:.3}", c.cpu_share));
            println!(
                "                              {:>10.0} {:>8.3} {:>10.3} {:>9.0} {:>10}",
                t.deposits_per_s, t.cpu_share, d.cpu_share, d.frames_per_s, spin
            );
        }
    }
}

/// Where a deposit's time goes, stage by stage: p50 / p99 of each, and their means over the
/// slowest 1 % of the deposits.
fn print_visible_stages<'r>(runs: impl Iterator<Item = (&'static str, &'r VisibleReport)>) {
    println!(
        "  stages µs (p50 / p99; mean of the slowest 1 %)   to the field's tick      compute      to the follower   (send p50 / p99)"
    );
    for (what, v) in runs {
        let s = &v.slowest_1pct_us;
        println!(
            "  {what:<12} {:>8.0} / {:<6.0} ({:>6.0}) {:>6.0} / {:<5.0} ({:>5.0}) {:>6.0} / {:<6.0} ({:>6.0}) ({:.0} / {:.0})",
            v.to_field_us.p50,
            v.to_field_us.p99,
            s.to_field,
            v.tick_compute_us.p50,
            v.tick_compute_us.p99,
            s.compute,
            v.to_reader_us.p50,
            v.to_reader_us.p99,
            s.to_reader,
            v.send_us.p50,
            v.send_us.p99
        );
    }
}

/// Tick-start lateness beside busy loops, if measured.
fn print_timing(r: &Report) {
    if r.tick_timing.is_empty() {
        return;
    }
    println!("\ntick timing beside busy loops    lateness µs: p50    p99  p99.9    max  gap (periods) missed  CPU  steal ms");
    for t in &r.tick_timing {
        let l = &t.field.lateness;
        println!(
            "{:>5} Hz {:<12} spin {:>4} µs {:>16} {:>6} {:>6} {:>6} {:>14.2} {:>6} {:>4.2} {:>9}",
            t.tick_hz,
            if t.realtime { "SCHED_FIFO" } else { "default" },
            t.spin_us,
            l.p50_us,
            l.p99_us,
            l.p999_us,
            l.max_us,
            t.field.longest_gap_periods,
            t.field.missed_deadlines,
            t.field.cpu_share,
            t.steal_ms.map_or("-".into(), |s| format!("{s:.0}"))
        );
    }
}

/// Paper 002's PIR through a gateway: round trip, the shared-memory read and the flood.
fn print_gateway(r: &Report) {
    if let Some(g) = &r.gateway_pir {
        println!("\ngateway (paper 002 PIR)           p50       p99     p99.9       max");
        println!(
            "PIR round trip, UDP    {}",
            lat(&g.pir_round_trip_ns, 1e-3, "µs")
        );
        println!(
            "antennas from shm      {}",
            lat(&g.shm_antennas_ns, 1e-3, "µs")
        );
        if let Some(l) = &r.gateway_pir_loaded_rt {
            println!(
                "PIR, {} busy, FIFO{} {}",
                l.busy_loops,
                if l.realtime { "  " } else { "? " },
                lat(&l.pir_round_trip_ns, 1e-3, "µs")
            );
        }
        println!(
            "flood: {:.0} PIR/s over {:.1} s, gateway CPU {:.2} s → {:.0} PIR per CPU-second ({} in flight)",
            g.flood.pirs_per_s, g.flood.wall_s, g.flood.gateway_cpu_s, g.flood.pirs_per_cpu_s, g.flood.window
        );
    }
}

/// Each target, met or missed, with what was measured.
fn print_targets(r: &Report) {
    println!("\ntargets");
    for t in &r.targets {
        match &t.unavailable {
            Some(why) => println!("  n/a  {}: {why}", t.name),
            None => println!(
                "  {:<4} {} {} {}: measured {}",
                if t.met { "met" } else { "MISS" },
                t.name,
                t.op,
                t.limit,
                t.measured
            ),
        }
    }
}

/// A peer's time, ours / its, and its largest difference from ours against the bound.
fn peer_cell(f: &pheromone_bench::peers::PeerFigure) -> String {
    match (f.us, f.ratio) {
        (Some(us), Some(ratio)) => format!(
            "{us:>10.1} µs  ours/peer {ratio:>6.3}  max diff {:.2e} (bound {:.2e})",
            f.max_abs_diff.unwrap_or(f64::NAN),
            f.bound.unwrap_or(f64::NAN)
        ),
        _ => format!("unavailable: {}", f.unavailable.as_deref().unwrap_or("?")),
    }
}

/// The `peers` section (issue 53): each case, ours beside each peer.
fn print_peers(x: &pheromone_bench::peers::PeersReport) {
    println!(
        "\npeers (Python {}, {:?})",
        x.python_version.as_deref().unwrap_or("unavailable"),
        x.versions
    );
    for a in &x.ambient {
        println!(
            "ambient {0}x{0} r={1:<3} ours {2:>10.1} µs\n  OpenCV boxFilter        {3}\n  SciPy uniform_filter    {4}",
            a.side,
            a.radius_cells,
            a.ours_us,
            peer_cell(&a.opencv_box),
            peer_cell(&a.scipy_uniform)
        );
    }
    for m in &x.merge {
        println!(
            "merge {0}x{0} {1:<13} ours {2:>10.1} µs\n  OpenCV warpAffine+NumPy {3}",
            m.side,
            m.rule,
            m.ours_us,
            peer_cell(&m.opencv_numpy)
        );
    }
}

fn print_c_abi(c: &pheromone_bench::c_abi::CAbiReport) {
    println!(
        "\nC ABI (libpheromone) vs Rust, {w}x{w} frame   p50       p99     p99.9       max",
        w = c.width
    );
    println!(
        "Rust reader, wait      {}",
        lat(&c.frame_rust_ns, 1e-3, "µs")
    );
    println!("C reader, wait         {}", lat(&c.frame_c_ns, 1e-3, "µs"));
    println!(
        "C / Rust: frame latency {:.3} (p50), {:.3} (p99); value + gradient {:.1} ns vs {:.1} ns \
         per point = {:.3}",
        c.frame_ratio_p50, c.frame_ratio_p99, c.sample_c_ns, c.sample_rust_ns, c.sample_ratio
    );
}

fn print_merges(r: &Report) {
    println!(
        "\nmerge / memcpy           memcpy µs   merge µs  ratio   reference µs  ratio   average µs  \
         ratio   average reference µs  ratio"
    );
    for (size, m) in &r.merge_vs_memcpy {
        println!(
            "{size:<22} {:>10.1} {:>10.1} {:>6.2} {:>14.1} {:>6.2} {:>12.1} {:>6.2} {:>22.1} {:>6.2}",
            m.memcpy_us,
            m.merge_us,
            m.merge_ratio,
            m.reference_us,
            m.reference_ratio,
            m.average_us,
            m.average_ratio,
            m.average_reference_us,
            m.average_reference_ratio
        );
    }
}

fn print_ticks(r: &Report) {
    println!(
        "\ntick / memcpy            memcpy µs   plain µs  ratio   ambient µs  ratio   reference µs  ratio"
    );
    for (size, t) in &r.tick_vs_memcpy {
        println!(
            "{size:<22} {:>10.1} {:>10.1} {:>6.2} {:>12.1} {:>6.2} {:>14.1} {:>6.2}",
            t.memcpy_us,
            t.exponential_us,
            t.exponential_ratio,
            t.ambient_us,
            t.ambient_ratio,
            t.ambient_reference_us,
            t.ambient_reference_ratio
        );
    }
    println!(
        "\nambient by radius ({} kernels)   radius cells: ratio (reference's) …   2 threads µs  speedup",
        { r.tick_vs_memcpy.values().next().map_or("-", |t| t.kernels) }
    );
    for (size, t) in &r.tick_vs_memcpy {
        let radii: Vec<String> = t
            .ambient_by_radius
            .iter()
            .map(|b| {
                format!(
                    "r{}: {:.2} (ref {:.2})",
                    b.radius_cells, b.ambient_ratio, b.reference_ratio
                )
            })
            .collect();
        println!(
            "{size:<22} {:<52} {:>12.1} {:>8.2}",
            radii.join("  "),
            t.ambient_2_threads_us,
            t.ambient_thread_speedup
        );
    }
}

#[cfg(feature = "zenoh")]
fn print_mirror(m: &pheromone_bench::MirrorSection) {
    println!(
        "\nmirror over Zenoh, {w}x{w} x {} channel at {} Hz: raw frames {:.1} MB/s",
        m.channels,
        m.tick_hz,
        m.raw_bytes_per_s / 1e6,
        w = m.width
    );
    println!("deposits/s  frames/s  inputs B/s  other B/s  keyframe B/s  wire B/s  / raw frames");
    for w in &m.wire {
        println!(
            "{:>10.0} {:>9.1} {:>11.0} {:>10.0} {:>13.0} {:>9.0}  {:.2e}",
            w.deposits_per_s,
            w.frames_per_s,
            w.inputs_bytes_per_s,
            w.other_bytes_per_s,
            w.keyframe_bytes_per_s,
            w.wire_bytes_per_s,
            w.ratio_to_raw
        );
    }
    println!("                                 p50       p99     p99.9       max");
    println!("origin → mirror publish {}", lat(&m.lag_us, 1e-3, "ms"));
    println!(
        "keyframe {} bytes ({:.2} % of a raw frame, every {} s), catch-up {:.1} ms (request → \
         keyframe published), {:.1} ms from session open to live; checksums {} matched, {} mismatched",
        m.keyframe_bytes,
        m.keyframe_ratio * 100.0,
        m.keyframe_every_s,
        m.catch_up_ms,
        m.start_to_live_ms,
        m.checksums_matched,
        m.checksum_mismatches
    );
}

/// Issue 46: `pheromone ros2` against a plain Zenoh publisher, CPU per published MB.
fn print_ros2(x: &pheromone_bench::ros2::Ros2Report) {
    println!(
        "\nros2, {w}x{w} field at {} Hz, topics of {:?} bytes, one subscriber",
        x.rate_hz,
        x.topic_bytes,
        w = x.width
    );
    println!("publisher            frames/s      MB/s   CPU (core)   CPU ms/MB");
    for (who, p) in [("pheromone ros2", &x.ros2), ("plain Zenoh", &x.plain_zenoh)] {
        println!(
            "{who:<18} {:>10.1} {:>9.1} {:>12.3} {:>11.2}",
            p.frames_per_s, p.mb_per_s, p.cpu_share, p.cpu_ms_per_mb
        );
    }
    println!(
        "ratio {:.2}; with nobody subscribed for {:.1} s: {:.3} of a core, {} frames not \
         serialized, {} for the transient-local cache",
        x.cpu_per_mb_ratio,
        x.idle.seconds,
        x.idle.cpu_share,
        x.idle
            .frames_without_subscribers
            .map_or("?".into(), |n| n.to_string()),
        x.idle
            .frames_for_cache
            .map_or("?".into(), |n| n.to_string()),
    );
}

#[cfg(not(feature = "zenoh"))]
fn print_mirror(m: &pheromone_bench::MirrorSection) {
    match *m {}
}
