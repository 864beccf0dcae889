//! Seed 002's pheromone information request (PIR) over the gateway against a direct read of the
//! same two antenna values in shared memory, and how many PIRs one gateway serves per second.
//!
//! - A field peer ticks a 512² one-channel field; a `pheromone gateway` process serves it on a
//!   loopback port the system picks (`--udp 127.0.0.1:0 --print-address`, no rate limit).
//! - **Round trip:** this process sends a PIR with the thin client
//!   ([`pheromone_gateway::client::GatewayClient`]) and waits for its reply, one at a time.
//! - **Direct read:** this process's [`FieldReader`] takes the newest frame (`update`) and reads
//!   `FrameView::antennas` at the same pose: what a follower in shared memory does per step.
//! - **Throughput:** a client keeps a window of PIRs in flight on one UDP socket (each reply
//!   sends the next request) for a while; the gateway's replies per second of wall time and
//!   its CPU time over the same interval (`/proc/PID/schedstat`) give the PIRs per second of
//!   one core. The gateway is pinned to core 1 and this process to core 0 where there are two
//!   cores or more.

use std::net::UdpSocket;
use std::time::{Duration, Instant};

use pheromone_field::shm::{create_node, FieldReader};
use pheromone_field::SamplePose;
use pheromone_gateway::client::{ClientConfig, GatewayClient, Transport};
use pheromone_gateway_codec::{
    decode, encode, Message, PirRequest, MAX_ENCODED_BYTES, MAX_WIRE_BYTES,
};
use pheromone_supervisor::{ChildId, ChildSpec, Supervisor};
use serde::Serialize;

use crate::machine::cpu_ns;
use crate::peer::{Launcher, Peer, PeerSpec};
use crate::stats::Latency;
use crate::BenchError;

#[derive(Debug, Clone, Copy)]
pub struct GatewayRun {
    pub warmup: usize,
    pub count: usize,
    /// How long the gateway is flooded.
    pub flood: Duration,
    /// Requests in flight during the flood.
    pub window: usize,
    pub pin: bool,
}

/// PIRs per second of one gateway, flooded by one client.
#[derive(Debug, Clone, Serialize)]
pub struct FloodReport {
    /// Replies received per second of wall time.
    pub pirs_per_s: f64,
    /// The gateway's CPU time over the flood (s).
    pub gateway_cpu_s: f64,
    pub wall_s: f64,
    /// Replies per second of the gateway's CPU time: what one core serves.
    pub pirs_per_cpu_s: f64,
    pub replies: u64,
    /// Requests re-sent after no reply came for 100 ms (lost datagrams).
    pub resent: u64,
    pub window: usize,
}

/// PIR over UDP loopback beside the direct shared-memory read, ns.
#[derive(Debug, Clone, Serialize)]
pub struct GatewayReport {
    /// One PIR sent and its reply received by the thin client (round trip).
    pub pir_round_trip_ns: Latency,
    /// `FieldReader::update` + `FrameView::antennas` on the newest frame.
    pub shm_antennas_ns: Latency,
    pub flood: FloodReport,
    pub width: u32,
    pub method: &'static str,
}

pub(crate) fn pin_pid(pid: u32, core: usize) {
    use nix::sched::{sched_setaffinity, CpuSet};
    use nix::unistd::Pid;
    let mut set = CpuSet::new();
    if set.set(core % crate::machine::cores()).is_ok() {
        // Pinning is best effort: the figures say whether it was asked for, not whether it held.
        let _ = sched_setaffinity(Pid::from_raw(pid as i32), &set);
    }
}

/// A field peer and a `pheromone gateway` serving it on a loopback port.
struct Served {
    /// Held for its drop (the peer is stopped then).
    _field: Peer,
    sup: Supervisor,
    gw: ChildId,
    address: String,
    name: String,
}

impl Drop for Served {
    fn drop(&mut self) {
        self.sup.stop_all(Duration::from_secs(5));
    }
}

/// Starts the field peer (512², 100 Hz) and the gateway (`--rt-priority N --rt-best-effort`
/// with `rt_priority`) and waits for the gateway's address.
fn serve(
    launcher: &Launcher,
    tag: &str,
    run: GatewayRun,
    rt_priority: Option<i32>,
) -> Result<Served, BenchError> {
    let name = format!("bench-{tag}");
    let mut field = Peer::spawn(
        launcher,
        &PeerSpec::Field {
            name: name.clone(),
            width: WIDTH,
            tick_hz: 100.0,
            core: run.pin.then_some(1),
            on_deposit: false,
            rt_priority: None,
            spin_us: 0,
        },
    )?;
    field.wait_ready(Duration::from_secs(20))?;
    let mut sup = Supervisor::new(&launcher.program);
    sup.echo_stderr = false;
    let mut args: Vec<String> = [
        "gateway",
        "--field",
        &name,
        "--udp",
        "127.0.0.1:0",
        "--rate-hz",
        "0",
        "--print-address",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    if let Some(p) = rt_priority {
        args.extend([
            "--rt-priority".into(),
            p.to_string(),
            "--rt-best-effort".into(),
        ]);
    }
    let gw = sup.spawn(ChildSpec::new("gateway", None, args))?;
    let line = sup
        .next_line(gw, Duration::from_secs(20))?
        .ok_or_else(|| BenchError::Peer("the gateway did not serve within 20 s".into()))?;
    let address = line
        .trim()
        .strip_prefix("udp://")
        .ok_or_else(|| BenchError::Peer(format!("the gateway announced '{line}'")))?
        .to_string();
    if run.pin {
        pin_pid(sup.pid(gw), 1);
    }
    Ok(Served {
        _field: field,
        sup,
        gw,
        address,
        name,
    })
}

/// Side of the field (cells) in the gateway measurements.
const WIDTH: u32 = 512;

/// The pose of every PIR: the middle of the field, heading along +x, antennas 0.15 m to each
/// side.
fn pir_pose() -> (SamplePose, f32) {
    let c = 0.5 * WIDTH as f32 * pheromone_field::FieldConfig::default().cell_size_m;
    (SamplePose::new(c, c, 0.3), 0.15)
}

/// `warmup + count` PIRs one at a time from the thin client; the last `count` round trips (ns).
fn round_trips(address: &str, warmup: usize, count: usize) -> Result<Vec<u64>, BenchError> {
    let (pose, half_m) = pir_pose();
    let mut client = GatewayClient::new(
        Transport::udp(address).map_err(|e| BenchError::Peer(e.to_string()))?,
        ClientConfig {
            client_id: 1,
            timeout: Duration::from_secs(1),
            retries: 0,
            ..ClientConfig::default()
        },
    );
    let mut rtt = Vec::with_capacity(count);
    for i in 0..warmup + count {
        let t0 = Instant::now();
        client
            .pir(pose.x_m, pose.y_m, pose.theta_rad, half_m, 0)
            .map_err(|e| BenchError::Peer(e.to_string()))?;
        if i >= warmup {
            rtt.push(t0.elapsed().as_nanos() as u64);
        }
    }
    Ok(rtt)
}

pub fn measure(
    launcher: &Launcher,
    tag: &str,
    run: GatewayRun,
) -> Result<GatewayReport, BenchError> {
    let node = create_node(&format!("bench-gateway-{tag}"))?;
    let served = serve(launcher, tag, run, None)?;
    let mut reader = FieldReader::attach_within(&node, &served.name, Duration::from_secs(10))?;
    reader.wait_frame(Duration::from_secs(10))?;
    let (pose, half_m) = pir_pose();
    let rtt = round_trips(&served.address, run.warmup, run.count)?;
    let mut direct = Vec::with_capacity(run.count);
    let mut sink = 0.0f32;
    for i in 0..run.warmup + run.count {
        let t0 = Instant::now();
        reader.update()?;
        let f = reader
            .frame()
            .ok_or_else(|| BenchError::Peer("no frame".into()))?;
        let (l, r) = f.view.antennas(0, pose, 2.0 * half_m);
        sink += l + r;
        if i >= run.warmup {
            direct.push(t0.elapsed().as_nanos() as u64);
        }
    }
    std::hint::black_box(sink);
    let flood = flood(
        &served.address,
        served.sup.pid(served.gw),
        pose,
        half_m,
        run,
    )?;
    drop(reader);
    drop(served);
    Ok(GatewayReport {
        pir_round_trip_ns: Latency::from_ns(&rtt)
            .ok_or_else(|| BenchError::Peer("PIR: no samples".into()))?,
        shm_antennas_ns: Latency::from_ns(&direct)
            .ok_or_else(|| BenchError::Peer("direct read: no samples".into()))?,
        flood,
        width: WIDTH,
        method: "round trip: one PIR at a time from GatewayClient over UDP loopback; direct: \
                 FieldReader::update + FrameView::antennas in this process; flood: a window \
                 of PIRs in flight on one socket, gateway CPU from /proc/PID/schedstat",
    })
}

/// The PIR round trip beside busy loops, the gateway and the client thread at `SCHED_FIFO`.
#[derive(Debug, Clone, Serialize)]
pub struct LoadedPirReport {
    pub pir_round_trip_ns: Latency,
    pub busy_loops: usize,
    pub rt_priority: i32,
    /// Whether both the gateway and the client thread got `SCHED_FIFO` (else the OS refused).
    pub realtime: bool,
}

/// Issue 33: the PIR round trip beside `busy_loops` busy processes, with the gateway at
/// `SCHED_FIFO rt_priority` and this thread (the client: on a robot, its own MCU) too.
pub fn measure_loaded(
    launcher: &Launcher,
    tag: &str,
    run: GatewayRun,
    (busy_loops, rt_priority): (usize, i32),
) -> Result<LoadedPirReport, BenchError> {
    let mut busy = Vec::with_capacity(busy_loops);
    for _ in 0..busy_loops {
        let mut p = Peer::spawn(launcher, &PeerSpec::Busy { seconds: 600.0 })?;
        p.wait_ready(Duration::from_secs(20))?;
        busy.push(p);
    }
    let served = serve(launcher, tag, run, Some(rt_priority))?;
    let client_rt = pheromone_field::process::realtime::fifo_for_this_thread(rt_priority).is_ok();
    let rtt = round_trips(&served.address, run.warmup, run.count);
    pheromone_field::process::realtime::default_scheduling_for_this_thread();
    let mut served = served;
    let gateway_said = served.sup.stderr_tail(served.gw);
    drop(served);
    drop(busy);
    let rtt = rtt?;
    Ok(LoadedPirReport {
        pir_round_trip_ns: Latency::from_ns(&rtt)
            .ok_or_else(|| BenchError::Peer("PIR under load: no samples".into()))?,
        busy_loops,
        rt_priority,
        realtime: client_rt && !gateway_said.contains("going on without"),
    })
}

/// Keeps `run.window` PIRs in flight for `run.flood`; counts the replies.
fn flood(
    address: &str,
    gateway_pid: u32,
    pose: SamplePose,
    half_m: f32,
    run: GatewayRun,
) -> Result<FloodReport, BenchError> {
    let io = |what: &str| {
        let what = what.to_string();
        move |source| BenchError::Io { what, source }
    };
    let socket = UdpSocket::bind("127.0.0.1:0").map_err(io("bind the flood socket"))?;
    socket
        .connect(address)
        .map_err(io("connect the flood socket"))?;
    socket
        .set_read_timeout(Some(Duration::from_millis(100)))
        .map_err(io("set the flood socket's timeout"))?;
    let mut request = [0u8; MAX_ENCODED_BYTES];
    let n = encode(
        &Message::Pir(PirRequest {
            x_m: pose.x_m,
            y_m: pose.y_m,
            theta_rad: pose.theta_rad,
            half_wheel_base_m: half_m,
            channel: 0,
        }),
        2,
        &mut request,
    )
    .map_err(|e| BenchError::Peer(format!("encode a PIR: {e}")))?;
    let request = &request[..n];
    let mut buf = [0u8; MAX_WIRE_BYTES + 1];
    let (mut replies, mut resent) = (0u64, 0u64);
    let cpu0 = cpu_ns(gateway_pid)?;
    let t0 = Instant::now();
    for _ in 0..run.window {
        socket.send(request).map_err(io("send a PIR"))?;
    }
    while t0.elapsed() < run.flood {
        match socket.recv(&mut buf) {
            Ok(len) => {
                if let Some(Ok(f)) = decode(&buf[..len]) {
                    if matches!(f.message, Message::PirReply(_)) {
                        replies += 1;
                    }
                }
                socket.send(request).map_err(io("send a PIR"))?;
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                // Datagrams lost: fill the window again.
                for _ in 0..run.window {
                    socket.send(request).map_err(io("send a PIR"))?;
                }
                resent += run.window as u64;
            }
            Err(e) => return Err(io("receive a PIR reply")(e)),
        }
    }
    let wall_s = t0.elapsed().as_secs_f64();
    let gateway_cpu_s = cpu_ns(gateway_pid)?.saturating_sub(cpu0) as f64 * 1e-9;
    let round = |v: f64| (v * 10.0).round() / 10.0;
    Ok(FloodReport {
        pirs_per_s: round(replies as f64 / wall_s),
        gateway_cpu_s: (gateway_cpu_s * 1e4).round() / 1e4,
        wall_s: (wall_s * 1e3).round() / 1e3,
        pirs_per_cpu_s: round(replies as f64 / gateway_cpu_s.max(1e-9)),
        replies,
        resent,
        window: run.window,
    })
}
