//! `pheromone bridge` and `pheromone field --mirror`: field mirrors over Zenoh (feature `zenoh`).

#[cfg(feature = "zenoh")]
use std::time::{Duration, Instant};

use clap::Args;

use super::field::FieldArgs;
#[cfg(feature = "zenoh")]
use super::{bad, bad_from};

/// Publish a running field's inputs on Zenoh so mirrors on other hosts replicate it
/// (docs/mirror-wire.md).
///
/// Per frame it publishes the deposits the field applied, in order (pheromone/F/inputs); it
/// answers requests for the configuration (pheromone/F/config) and for a keyframe
/// (pheromone/F/keyframe, zstd-compressed), publishes a keyframe every --keyframe-every-s
/// seconds and an XXH3-64 checksum of the shared frame every --checksum-every frames
/// (pheromone/F/checksum), and passes the deposits mirrors send (pheromone/F/deposit) to the
/// field. With --frames it also publishes downsampled compressed frames (pheromone/F/frames) for
/// consumers without a mirror. Needs a build with `--features zenoh`. Ctrl-C stops it.
#[derive(Args, Debug)]
pub struct BridgeArgs {
    /// The field to bridge (it must run on this host, in this iceoryx2 domain).
    #[arg(long, default_value = "main")]
    pub field: String,
    /// Zenoh endpoint to listen on (repeatable). Loopback by default: mirrors on other hosts
    /// need an address they reach, e.g. tls/10.0.0.1:7447 with --tls-cert/--tls-key and
    /// --users-file (plain tcp/ has no encryption and, without --users-file, no
    /// authentication: only on a network you trust).
    #[arg(
        long,
        value_name = "ENDPOINT",
        default_value = "tcp/127.0.0.1:7447",
        value_parser = super::check::zenoh_endpoint()
    )]
    pub listen: Vec<String>,
    /// Publish a frame checksum every N frames (sequence numbers divisible by N).
    #[arg(long, value_parser = super::int::<u32>(1, 1_000_000), value_name = "N", default_value_t = 10)]
    pub checksum_every: u32,
    /// Seconds between two periodic keyframes (keyframes are also sent on request).
    #[arg(long, value_parser = super::secs(), value_name = "K", default_value_t = 5.0)]
    pub keyframe_every_s: f64,
    /// Also publish downsampled, zstd-compressed frames on pheromone/F/frames.
    #[arg(long)]
    pub frames: bool,
    /// Frames per second with --frames.
    #[arg(long, value_parser = super::f64_pos(1000.0), value_name = "R", default_value_t = 5.0, requires = "frames")]
    pub rate_hz: f64,
    /// Average N × N cell blocks into one with --frames.
    #[arg(long, value_parser = super::int::<u32>(1, 4096), value_name = "N", default_value_t = 1, requires = "frames")]
    pub downsample: u32,
    /// Seconds to wait for the field to appear.
    #[arg(long, value_parser = super::secs(), value_name = "SECS", default_value_t = 10.0)]
    pub timeout: f64,
    /// Stop after this many seconds.
    #[arg(long, value_parser = super::secs(), value_name = "SECS")]
    pub duration: Option<f64>,
    /// At exit, print one JSON summary object on stdout.
    #[arg(long)]
    pub json: bool,
    /// Once listening, print each endpoint with the port it got, one line each (e.g.
    /// `tcp/127.0.0.1:41234`), on stdout before the --json summary: with `--listen
    /// tcp/127.0.0.1:0` the caller learns the port the system chose. Turns on the Zenoh
    /// session's read-only admin space.
    #[arg(long)]
    pub print_address: bool,
    #[command(flatten)]
    pub zenoh: super::zenoh_args::ZenohArgs,
}

#[cfg(feature = "zenoh")]
fn positive(flag: &str, v: f64) -> anyhow::Result<Duration> {
    if v.is_finite() && v > 0.0 {
        Ok(Duration::from_secs_f64(v))
    } else {
        Err(super::bad(format!(
            "--{flag} {v}: must be a positive number of seconds"
        )))
    }
}

#[cfg(feature = "zenoh")]
pub fn run(a: BridgeArgs) -> anyhow::Result<()> {
    use pheromone_bridge::{Bridge, BridgeOptions, FramesOptions};
    pheromone_field::shm::check_name(&a.field).map_err(bad_from)?;
    if a.checksum_every == 0 {
        return Err(bad("--checksum-every 0: must be at least 1"));
    }
    if a.frames && !(a.rate_hz.is_finite() && a.rate_hz > 0.0 && a.rate_hz <= 1000.0) {
        return Err(bad(format!(
            "--rate-hz {}: must be within (0, 1000]",
            a.rate_hz
        )));
    }
    if a.downsample == 0 {
        return Err(bad("--downsample 0: must be at least 1"));
    }
    let keyframe_every = positive("keyframe-every-s", a.keyframe_every_s)?;
    let timeout = positive("timeout", a.timeout)?;
    let duration = a.duration.map(|d| positive("duration", d)).transpose()?;
    let node = pheromone_field::shm::create_node(&format!("bridge-{}", std::process::id()))?;
    let mut bridge = Bridge::start(
        &node,
        BridgeOptions {
            field: a.field.clone(),
            listen: a.listen.clone(),
            checksum_every: a.checksum_every,
            keyframe_every,
            frames: a.frames.then_some(FramesOptions {
                rate_hz: a.rate_hz,
                downsample: a.downsample,
            }),
            admin_space: a.print_address,
            security: a.zenoh.security(),
        },
        timeout,
    )
    .map_err(|e| match e {
        pheromone_bridge::BridgeError::Security(_) => bad_from(e),
        e => e.into(),
    })?;
    if a.print_address {
        let locators = bridge.listen_locators()?;
        eprintln!("bridge '{}': listening on {locators:?}", a.field);
        use std::io::Write;
        let mut out = std::io::stdout().lock();
        for l in &locators {
            writeln!(out, "{l}")?;
        }
        out.flush()?;
    } else {
        eprintln!("bridge '{}': listening on {:?}", a.field, a.listen);
    }
    let started = Instant::now();
    let mut last_log = Instant::now();
    let mut last_cleanup = Instant::now();
    while node.wait(Duration::ZERO).is_ok() && duration.is_none_or(|d| started.elapsed() < d) {
        bridge.step(Duration::from_millis(20))?;
        if last_cleanup.elapsed() >= Duration::from_secs(1) {
            last_cleanup = Instant::now();
            pheromone_field::shm::cleanup_dead_nodes(&node);
        }
        if last_log.elapsed() >= Duration::from_secs(5) {
            last_log = Instant::now();
            let s = &bridge.stats;
            eprintln!(
                "bridge '{}': frame {}, {} inputs ({} deposits), {} keyframes, {} checksums, {} deposits forwarded{}",
                a.field,
                s.last_sequence,
                s.inputs_sent,
                s.deposits_in_inputs,
                s.keyframes_sent,
                s.checksums_sent,
                s.deposits_forwarded,
                if bridge.field_alive() { "" } else { "; the field is not running" }
            );
        }
    }
    let stats = bridge.stats;
    bridge.close();
    if a.json {
        println!(
            "{}",
            serde_json::json!({ "field": a.field, "bridge": stats })
        );
    }
    Ok(())
}

#[cfg(not(feature = "zenoh"))]
pub fn run(_a: BridgeArgs) -> anyhow::Result<()> {
    Err(super::bad(
        "this build has no Zenoh: rebuild with `cargo build --release --features zenoh`",
    ))
}

#[cfg(feature = "zenoh")]
pub fn run_mirror(a: &FieldArgs, endpoint: &str) -> anyhow::Result<()> {
    use pheromone_bridge::{Mirror, MirrorOptions};
    pheromone_field::shm::check_name(&a.name).map_err(bad_from)?;
    let Some(endpoint) = endpoint.strip_prefix("zenoh:") else {
        return Err(bad(format!(
            "--mirror {endpoint}: expected zenoh:ENDPOINT, e.g. zenoh:tcp/10.0.0.1:7447"
        )));
    };
    let stale_after = positive("stale-after-s", a.stale_after_s.unwrap_or(1.0))?;
    let duration = a.duration.map(|d| positive("duration", d)).transpose()?;
    let node = pheromone_field::shm::create_node(&format!("mirror-{}", a.name))?;
    let security = a.zenoh.security();
    let mut mirror = Mirror::start(MirrorOptions {
        field: a.name.clone(),
        connect: vec![endpoint.to_string()],
        stale_after,
        security: security.clone(),
    })
    .map_err(|e| match e {
        pheromone_bridge::BridgeError::Security(_) => bad_from(e),
        e => e.into(),
    })?;
    eprintln!("mirror '{}': connecting to {endpoint}", a.name);
    let refused = watch_refusal(security, endpoint.to_string());
    let started = Instant::now();
    let mut last_log = Instant::now();
    let mut last_cleanup = Instant::now();
    while node.wait(Duration::ZERO).is_ok() && duration.is_none_or(|d| started.elapsed() < d) {
        if let Ok(why) = refused.try_recv() {
            mirror.close();
            anyhow::bail!(
                "mirror '{}': {endpoint} refused the connection: {why}",
                a.name
            );
        }
        if let Err(e) = mirror.step(&node, Duration::from_millis(20)) {
            match e {
                pheromone_bridge::BridgeError::Config(_) => return Err(bad_from(e)),
                e => return Err(e.into()),
            }
        }
        if last_cleanup.elapsed() >= Duration::from_secs(1) {
            last_cleanup = Instant::now();
            pheromone_field::shm::cleanup_dead_nodes(&node);
        }
        if last_log.elapsed() >= Duration::from_secs(5) {
            last_log = Instant::now();
            let s = &mirror.stats;
            eprintln!(
                "mirror '{}': {} at frame {}, {} frames applied, {} keyframes, checksums {} matched / {} mismatched, {} gaps, {} rejected",
                a.name,
                if mirror.is_stale() { "stale" } else { "live" },
                s.last_sequence,
                s.frames_applied,
                s.keyframes_applied,
                s.checksums_matched,
                s.checksum_mismatches,
                s.gaps,
                s.rejected_inputs + s.rejected_keyframes + s.rejected_other
            );
        }
    }
    let stats = mirror.stats;
    let stale = mirror.is_stale();
    mirror.close();
    if a.json {
        println!(
            "{}",
            serde_json::json!({ "field": a.name, "stale": stale, "mirror": stats })
        );
    }
    Ok(())
}

/// Until a connection to the bridge opens: one attempt at a time, a second apart, in a thread
/// of its own (an attempt may take as long as a TCP connect and a TLS handshake), whose refusal for good (a
/// certificate, CA or password the bridge does not accept) is sent on the channel: the
/// mirror's own session would retry it forever, logging nothing.
#[cfg(feature = "zenoh")]
fn watch_refusal(
    security: pheromone_bridge::Security,
    endpoint: String,
) -> std::sync::mpsc::Receiver<String> {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || loop {
        match pheromone_bridge::try_connect(&security, &endpoint) {
            Ok(()) => return,
            Err(e) => {
                if let Some(why) = pheromone_bridge::refusal(&e) {
                    let _ = tx.send(why);
                    return;
                }
            }
        }
        // The period between two connection attempts (a cadence, not a wait for a condition:
        // the attempt itself is what waits for the bridge).
        std::thread::sleep(Duration::from_secs(1));
    });
    rx
}

#[cfg(not(feature = "zenoh"))]
pub fn run_mirror(_a: &FieldArgs, _endpoint: &str) -> anyhow::Result<()> {
    Err(super::bad(
        "--mirror: this build has no Zenoh: rebuild with `cargo build --release --features zenoh`",
    ))
}
