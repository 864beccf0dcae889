//! `pheromone bridge` and `pheromone field --mirror`: field mirrors over Zenoh (feature `zenoh`).

#[cfg(feature = "zenoh")]
use std::time::Duration;

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
    /// authentication: only on a network you trust). On loopback endpoints only and without
    /// credentials, the bridge admits only its own user's sessions: they present the key in
    /// $TMPDIR/pheromone-<uid>/zenoh/owner.key (made 0600 by the first that needs it), which
    /// other local users cannot read.
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

/// The bridge's options from its flags (their parsers have checked the values).
#[cfg(feature = "zenoh")]
fn bridge_options(a: &BridgeArgs) -> pheromone_bridge::BridgeOptions {
    pheromone_bridge::BridgeOptions {
        field: a.field.clone(),
        listen: a.listen.clone(),
        checksum_every: a.checksum_every,
        keyframe_every: Duration::from_secs_f64(a.keyframe_every_s),
        frames: a.frames.then_some(pheromone_bridge::FramesOptions {
            rate_hz: a.rate_hz,
            downsample: a.downsample,
        }),
        admin_space: a.print_address,
        security: a.zenoh.security(),
    }
}

#[cfg(feature = "zenoh")]
pub fn run(a: BridgeArgs) -> anyhow::Result<()> {
    pheromone_field::shm::check_name(&a.field).map_err(bad_from)?;
    let node = pheromone_field::shm::create_node(&format!("bridge-{}", std::process::id()))?;
    let timeout = Duration::from_secs_f64(a.timeout);
    let bridge = pheromone_bridge::Bridge::start(&node, bridge_options(&a), timeout).map_err(
        |e| match e {
            pheromone_bridge::BridgeError::Security(_) => bad_from(e),
            e => e.into(),
        },
    )?;
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
    eprintln!("bridge '{}': {}", a.field, admits_text(bridge.admits()));
    let stats = bridge.run(&node, a.duration.map(Duration::from_secs_f64))?;
    if a.json {
        println!(
            "{}",
            serde_json::json!({ "field": a.field, "bridge": stats })
        );
    }
    Ok(())
}

/// Whom the bridge admits, for its start-up line.
#[cfg(feature = "zenoh")]
fn admits_text(admits: &pheromone_bridge::owner::Admits) -> String {
    use pheromone_bridge::owner::Admits;
    match admits {
        Admits::Owner(key) => format!(
            "admits only this user's sessions (owner key {}); other local users need \
             --users-file credentials",
            key.display()
        ),
        Admits::Dictionary => "admits the sessions that present a user of its dictionary".into(),
        Admits::Anyone => "admits anyone who reaches its endpoints: no authentication (not \
             loopback only, and no --users-file)"
            .into(),
    }
}

#[cfg(not(feature = "zenoh"))]
pub fn run(_a: BridgeArgs) -> anyhow::Result<()> {
    Err(super::bad(
        "this build has no Zenoh: rebuild with `cargo build --release --features zenoh`",
    ))
}

#[cfg(feature = "zenoh")]
pub fn run_mirror(a: &FieldArgs, endpoint: &str) -> anyhow::Result<()> {
    use pheromone_bridge::{BridgeError, Mirror, MirrorOptions};
    pheromone_field::shm::check_name(&a.name).map_err(bad_from)?;
    // The flag's parser checked the `zenoh:` prefix and the endpoint.
    let endpoint = endpoint.strip_prefix("zenoh:").unwrap_or(endpoint);
    // `field --duration` takes 0 (a field that only starts); a mirror needs a positive one.
    let duration = match a.duration {
        Some(d) if d <= 0.0 => {
            return Err(bad(format!(
                "--duration {d}: must be a positive number of seconds"
            )))
        }
        d => d.map(Duration::from_secs_f64),
    };
    let node = pheromone_field::shm::create_node(&format!("mirror-{}", a.name))?;
    let mirror = Mirror::start(MirrorOptions {
        field: a.name.clone(),
        connect: vec![endpoint.to_string()],
        stale_after: Duration::from_secs_f64(a.stale_after_s.unwrap_or(1.0)),
        security: a.zenoh.security(),
    })
    .map_err(|e| match e {
        BridgeError::Security(_) => bad_from(e),
        e => e.into(),
    })?;
    eprintln!("mirror '{}': connecting to {endpoint}", a.name);
    let run = mirror.run(&node, duration).map_err(|e| match e {
        BridgeError::Config(_) => bad_from(e),
        e => e.into(),
    })?;
    if a.json {
        println!(
            "{}",
            serde_json::json!({ "field": a.name, "stale": run.stale, "mirror": run.stats })
        );
    }
    Ok(())
}

#[cfg(not(feature = "zenoh"))]
pub fn run_mirror(_a: &FieldArgs, _endpoint: &str) -> anyhow::Result<()> {
    Err(super::bad(
        "--mirror: this build has no Zenoh: rebuild with `cargo build --release --features zenoh`",
    ))
}
