//! `pheromone gateway`: paper 002's pheromone server for thin radio clients (DLE/CRC frames over
//! UDP or a serial line), in front of a running field.

use std::time::Duration;

use clap::Args;
use pheromone_field::shm::create_node;
use pheromone_gateway::line::Line;
use pheromone_gateway::{serial, Gateway, GatewayConfig, Source};

use super::bad;

/// Serve a field to thin clients (paper 002): robots send DLE/CRC frames (docs/gateway-wire.md)
/// with their pose and get back the two virtual-antenna readings (PIR), send deposits, or ping.
///
/// Binds loopback unless told otherwise. Bad CRCs are dropped and counted; malformed frames,
/// unknown channels, out-of-range values, clients not on --allow and clients over --rate-hz
/// get an error reply and are never applied. Counters go to stderr once a second; --json prints
/// them as one JSON object at the end (Ctrl-C or SIGTERM stops the gateway).
///
/// What a loopback bind protects: other hosts cannot reach it. Other users of this host can
/// send to it under any client ID (the wire carries no key): by default a loopback datagram is
/// served only if the socket it came from belongs to the gateway's user or root
/// (`--local-users`). `--allow ID@IP:PORT` serves an ID only from the socket its client holds
/// (another user cannot send from it while the client runs, but can take the port while it is
/// down).
/// Each client ID has a rate bucket per source, so a flood under a real client's ID from
/// another socket is limited without starving that client. To keep local users out, serve on a
/// serial line or in a network namespace of your own (docs/reliability.md).
#[derive(Args, Debug)]
pub struct GatewayArgs {
    /// Field name.
    #[arg(long, default_value = "main")]
    pub field: String,
    #[command(flatten)]
    pub rt: super::rt::RtArgs,
    /// UDP address to serve on (default 127.0.0.1:7402 when --serial is not given).
    #[arg(long, conflicts_with = "serial", value_parser = super::check::socket_addr())]
    pub udp: Option<String>,
    /// Serve on this serial line instead (a tty such as /dev/ttyUSB0 or a pty /dev/pts/N):
    /// raw, 8N1, at --baud; frames are a byte stream, each answered on the same line.
    #[arg(long)]
    pub serial: Option<String>,
    /// Baud rate of --serial (a standard termios rate: 9600, 19200, 115200, …).
    #[arg(long, value_parser = super::int::<u32>(1, 4_000_000), default_value_t = 9600, requires = "serial")]
    pub baud: u32,
    /// Client IDs served, e.g. `1,2,7` or `1-20`; default 1–255 (ID 0 is not protected by the
    /// CRC's zero start value, see docs/gateway-wire.md). `ID@ADDR` (ADDR an IP address or
    /// IP:PORT) serves ID only from that UDP source (repeat it for several sources).
    #[arg(long, value_delimiter = ',')]
    pub allow: Vec<String>,
    /// Local users served from loopback sources, by the owner of the sending socket (the
    /// kernel's /proc/net/udp): `owner` (the gateway's own user and root), `any`, or uids
    /// (`1000,1001`). Others get reason 6; sources on other hosts are not checked.
    #[arg(long, value_delimiter = ',', default_value = "owner")]
    pub local_users: Vec<String>,
    /// Requests per second each client ID may send from each source (UDP address or the
    /// serial line; 0 = unlimited).
    #[arg(long, value_parser = super::f64_in(0.0, 1e6), default_value_t = 100.0)]
    pub rate_hz: f64,
    /// Plateau c of the Z-shape deposit (m).
    #[arg(long, value_parser = super::f32_in(0.0, 1e6), default_value_t = 0.2)]
    pub plateau_m: f32,
    /// Slope width σ of the Z-shape deposit (m).
    #[arg(long, value_parser = super::f32_in(0.0, 1e6), default_value_t = 0.3)]
    pub slope_m: f32,
    /// Seconds to wait for the field and its first frame.
    #[arg(long, value_parser = super::secs0(), default_value_t = 10.0)]
    pub attach_timeout: f64,
    /// Print the final counters as one JSON object on stdout.
    #[arg(long)]
    pub json: bool,
    /// Once serving, print the UDP address as one line `udp://HOST:PORT` on stdout (before the
    /// --json counters): with `--udp 127.0.0.1:0` the caller learns the port the system chose.
    #[arg(long, conflicts_with = "serial")]
    pub print_address: bool,
}

/// Where the gateway serves when neither --udp nor --serial is given.
const DEFAULT_UDP: &str = "127.0.0.1:7402";

/// Client IDs bound to a source, as `GatewayConfig::bound` takes them.
type Bound = Vec<(u8, Source)>;

/// The `ID@ADDR` items of --allow (each ID bound to its sources), and the others.
fn parse_bound(items: &[String]) -> anyhow::Result<(Bound, Vec<String>)> {
    let mut bound = Vec::new();
    let mut rest = Vec::new();
    for item in items {
        let Some((id, addr)) = item.split_once('@') else {
            rest.push(item.clone());
            continue;
        };
        let id = id.trim().parse::<u8>().map_err(|e| {
            bad(format!(
                "--allow {item}: '{id}' is not a client ID 0–255: {e}"
            ))
        })?;
        let source = addr.trim().parse::<Source>().map_err(|e| {
            bad(format!(
                "--allow {item}: '{addr}' is not an IP address or IP:PORT: {e}"
            ))
        })?;
        bound.push((id, source));
    }
    Ok((bound, rest))
}

/// `1,2,7` and ranges `1-20`; every ID 0–255.
fn parse_allow(items: &[String]) -> anyhow::Result<Vec<u8>> {
    if items.is_empty() {
        return Ok(GatewayConfig::default().allow);
    }
    let id = |s: &str| {
        s.trim()
            .parse::<u8>()
            .map_err(|e| bad(format!("--allow: '{s}' is not a client ID 0–255: {e}")))
    };
    let mut ids = Vec::new();
    for item in items {
        match item.split_once('-') {
            Some((a, b)) => {
                let (a, b) = (id(a)?, id(b)?);
                if a > b {
                    return Err(bad(format!("--allow: range '{item}' is empty")));
                }
                ids.extend(a..=b);
            }
            None => ids.push(id(item)?),
        }
    }
    ids.sort_unstable();
    ids.dedup();
    Ok(ids)
}

/// The gateway's configuration from `--allow`, `--rate-hz` and the deposit's shape.
fn gateway_config(a: &GatewayArgs) -> anyhow::Result<GatewayConfig> {
    let (bound, ids) = parse_bound(&a.allow)?;
    if !bound.is_empty() && a.serial.is_some() {
        return Err(bad(
            "--allow ID@ADDR: a serial line has no source address; bind IDs over --udp only",
        ));
    }
    // Bound IDs are served (from their sources); with only bound IDs, only they are.
    let mut allow = if ids.is_empty() && !bound.is_empty() {
        Vec::new()
    } else {
        parse_allow(&ids)?
    };
    allow.extend(bound.iter().map(|(id, _)| *id));
    allow.sort_unstable();
    allow.dedup();
    Ok(GatewayConfig {
        allow,
        bound,
        rate_per_s: a.rate_hz,
        local_users: local_users(&a.local_users)?,
        plateau_m: a.plateau_m,
        slope_m: a.slope_m,
    })
}

/// `--local-users`: `owner`, `any` or uids.
fn local_users(v: &[String]) -> anyhow::Result<pheromone_gateway::peer::LocalUsers> {
    use pheromone_gateway::peer::LocalUsers;
    match v {
        [one] if one == "owner" => Ok(LocalUsers::owner()),
        [one] if one == "any" => Ok(LocalUsers::Any),
        uids => uids
            .iter()
            .map(|u| {
                u.parse::<u32>()
                    .map_err(|_| bad(format!("--local-users {u}: not 'owner', 'any' or a uid")))
            })
            .collect::<anyhow::Result<Vec<u32>>>()
            .map(LocalUsers::Only),
    }
}

/// The serial line of `--serial` or the socket of `--udp`.
fn open_line(a: &GatewayArgs) -> anyhow::Result<Line> {
    Ok(match &a.serial {
        Some(path) => {
            if serial::baud_rate(a.baud).is_none() {
                return Err(bad(format!(
                    "--baud {}: not a standard termios rate (e.g. 9600, 19200, 115200)",
                    a.baud
                )));
            }
            Line::serial(path, a.baud)?
        }
        None => Line::udp(a.udp.as_deref().unwrap_or(DEFAULT_UDP))?,
    })
}

pub fn run(a: GatewayArgs) -> anyhow::Result<()> {
    a.rt.apply("gateway")?;
    let config = gateway_config(&a)?;
    // The line or socket first: a bad path, rate or address fails before the field is waited for.
    let mut line = open_line(&a)?;
    let node = create_node(&format!("gateway-{}", std::process::id()))?;
    let attach_timeout = Duration::from_secs_f64(a.attach_timeout);
    let mut gateway = match Gateway::attach(&node, &a.field, config, attach_timeout) {
        Ok(g) => g,
        Err(e @ pheromone_gateway::GatewayError::Config { .. }) => return Err(bad(e.to_string())),
        Err(e) => return Err(e.into()),
    };
    eprintln!(
        "gateway: serving field '{}' on {}",
        a.field,
        line.describe()?
    );
    if a.print_address {
        if let Some(url) = line.udp_url()? {
            println!("{url}");
        }
    }
    line.serve(&node, &mut gateway)?;
    if a.json {
        println!("{}", serde_json::to_string(gateway.counters())?);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn allow_lists_take_ids_and_ranges_and_refuse_the_rest() {
        let s = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(parse_allow(&s(&["3", "1-2", "2"])).unwrap(), vec![1, 2, 3]);
        assert_eq!(parse_allow(&[]).unwrap().len(), 255);
        assert!(parse_allow(&s(&["256"])).is_err());
        assert!(parse_allow(&s(&["5-1"])).is_err());
    }
}
