//! Field mirrors over Zenoh (issue 15, feature `zenoh`): what crosses the network and how late a
//! mirror's frames are, on this host with two iceoryx2 domains standing for two hosts.
//!
//! - **Origin:** a `pheromone field` process in domain `benchmirA`, `width`² cells, one channel,
//!   ticking at `tick_hz` (it publishes its inputs for bridges, as every field does).
//! - **Bridge:** [`pheromone_bridge::Bridge`] on a thread of this process (domain A), listening
//!   on a loopback TCP port the system picks, checksum every 10 frames, a keyframe every `keyframe_every_s`
//!   (the `pheromone bridge` defaults).
//! - **Mirror:** [`pheromone_bridge::Mirror`] on another thread (domain `benchmirB`),
//!   connected to the bridge, publishing the replayed frames in domain B.
//! - This thread sends deposits to the origin at 10 and then 1000 per second, scattered over the
//!   field, for `window` each.
//!
//! Figures: the bytes the bridge put on the wire per second (its counters: inputs and checksums
//! over the window, plus the periodic keyframe amortized: the size of a keyframe of the field at
//! the end of the window, asked from the bridge by a third session, / `keyframe_every_s`) against
//! raw frames (`width`² × channels × 4 B × `tick_hz`); origin publish → mirror publish of each
//! replayed frame (both stamps are this host's CLOCK_MONOTONIC); the keyframe size after the
//! deposits (bytes and share of a raw frame); and the catch-up of a mirror started afresh: keyframe
//! request → keyframe published, and session open → first frame replayed from live inputs.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use pheromone_bridge::zenoh::{self, Wait};
use pheromone_bridge::{
    session_config_as, Bridge, BridgeOptions, BridgeStats, Keys, Mirror, MirrorOptions, MirrorStats,
};
use pheromone_field::shm::{create_node_in, DepositPublisher};
use pheromone_field::DepositMsg;
use pheromone_field::{Deposit, Kernel};
use pheromone_supervisor::{ChildSpec, Supervisor};
use serde::Serialize;

use crate::peer::Launcher;
use crate::stats::Latency;
use crate::BenchError;

/// The two "hosts" (fixed prefixes: iceoryx2 keeps one management segment per domain).
pub const ORIGIN_DOMAIN: &str = "benchmirA";
pub const MIRROR_DOMAIN: &str = "benchmirB";

#[derive(Debug, Clone, Copy)]
pub struct MirrorRun {
    pub width: u32,
    pub tick_hz: f32,
    /// How long deposits are sent at each rate.
    pub window: Duration,
    /// The bridge's periodic keyframe interval.
    pub keyframe_every: Duration,
    /// Pin the origin field to core 1.
    pub pin: bool,
}

/// Wire bytes at one deposit rate.
#[derive(Debug, Clone, Serialize)]
pub struct WireAtRate {
    pub deposits_per_s: f64,
    /// Deposits the origin applied per second over the window (from the inputs sent).
    pub applied_per_s: f64,
    /// Inputs lists (frames) per second the bridge sent.
    pub frames_per_s: f64,
    /// Inputs lists, bytes per second (envelopes included).
    pub inputs_bytes_per_s: f64,
    /// Checksums and other small messages, bytes per second.
    pub other_bytes_per_s: f64,
    /// A keyframe of the field at the end of the window (asked from the bridge), bytes.
    pub keyframe_bytes: u64,
    /// The periodic keyframe amortized: `keyframe_bytes` / the keyframe interval.
    pub keyframe_bytes_per_s: f64,
    /// All of it.
    pub wire_bytes_per_s: f64,
    /// `wire_bytes_per_s` / raw frames per second.
    pub ratio_to_raw: f64,
}

/// The `mirror` section of the report.
#[derive(Debug, Clone, Serialize)]
pub struct MirrorReport {
    pub width: u32,
    pub channels: u32,
    pub tick_hz: f64,
    pub raw_frame_bytes: u64,
    /// Raw frames per second: `raw_frame_bytes` × `tick_hz`.
    pub raw_bytes_per_s: f64,
    pub keyframe_every_s: f64,
    pub wire: Vec<WireAtRate>,
    /// Origin publish → mirror publish of each replayed frame, µs (both windows).
    pub lag_us: Latency,
    /// A keyframe of the field after both windows' deposits (zstd level 1), bytes.
    pub keyframe_bytes: u64,
    /// `keyframe_bytes` / `raw_frame_bytes`.
    pub keyframe_ratio: f64,
    /// A mirror started afresh: keyframe request → keyframe published in its domain, ms.
    pub catch_up_ms: f64,
    /// The same mirror: its Zenoh session opened → first frame replayed from live inputs, ms.
    pub start_to_live_ms: f64,
    pub checksums_matched: u64,
    pub checksum_mismatches: u64,
    pub method: &'static str,
}

/// What the bridge or mirror thread shares with this one.
#[derive(Default)]
struct Shared {
    bridge: BridgeStats,
    mirror: MirrorStats,
    lags_ns: Vec<u64>,
    /// The mirror's first frame from live inputs, and when its session opened.
    live_at: Option<Instant>,
    opened_at: Option<Instant>,
    /// The bridge's endpoint, with the port the system chose.
    endpoint: Option<String>,
    error: Option<String>,
}

type Snapshot = Arc<Mutex<Shared>>;

fn lock(s: &Snapshot) -> std::sync::MutexGuard<'_, Shared> {
    // A thread that panicked holding it left plain counters: still readable.
    s.lock().unwrap_or_else(|e| e.into_inner())
}

/// A thread that runs until `stop`, recording into `shared`; `Err` text in `shared.error`.
struct Worker {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
    shared: Snapshot,
}

impl Worker {
    fn spawn(
        what: &'static str,
        body: impl FnOnce(&AtomicBool, &Snapshot) -> Result<(), String> + Send + 'static,
    ) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let shared: Snapshot = Arc::default();
        let (s, sh) = (stop.clone(), shared.clone());
        let handle = std::thread::spawn(move || {
            // Off this process's pinned core: the scheduler places the bridge and the mirror.
            crate::machine::unpin();
            if let Err(e) = body(&s, &sh) {
                lock(&sh).error = Some(format!("{what}: {e}"));
            }
        });
        Self {
            stop,
            handle: Some(handle),
            shared,
        }
    }

    fn check(&self) -> Result<(), BenchError> {
        match &lock(&self.shared).error {
            Some(e) => Err(BenchError::Peer(e.clone())),
            None => Ok(()),
        }
    }

    fn finish(mut self) -> Result<(), BenchError> {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            h.join()
                .map_err(|_| BenchError::Peer("a mirror bench thread panicked".into()))?;
        }
        self.check()
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// The bridge, listening on a loopback port the system picks (`shared.endpoint` once it does).
fn bridge_worker(name: String, keyframe_every: Duration) -> Worker {
    Worker::spawn("bridge", move |stop, shared| {
        let node = create_node_in(
            &format!("bench-bridge-{}", std::process::id()),
            Some(ORIGIN_DOMAIN),
        )
        .map_err(|e| e.to_string())?;
        let mut bridge = Bridge::start(
            &node,
            BridgeOptions {
                field: name,
                listen: vec!["tcp/127.0.0.1:0".into()],
                checksum_every: 10,
                keyframe_every,
                frames: None,
                admin_space: true,
                security: Default::default(),
            },
            Duration::from_secs(20),
        )
        .map_err(|e| e.to_string())?;
        let endpoint = bridge
            .listen_locators()
            .map_err(|e| e.to_string())?
            .into_iter()
            .next()
            .ok_or("the bridge listens nowhere")?;
        lock(shared).endpoint = Some(endpoint);
        while !stop.load(Ordering::Relaxed) && !pheromone_field::shm::should_stop(&node) {
            bridge
                .step(Duration::from_millis(20))
                .map_err(|e| e.to_string())?;
            lock(shared).bridge = bridge.stats;
        }
        bridge.close();
        Ok(())
    })
}

fn mirror_worker(name: String, endpoint: String, tag: String) -> Worker {
    Worker::spawn("mirror", move |stop, shared| {
        let node = create_node_in(&format!("bench-mirror-{tag}"), Some(MIRROR_DOMAIN))
            .map_err(|e| e.to_string())?;
        let opened = Instant::now();
        let mut mirror = Mirror::start(MirrorOptions {
            field: name,
            connect: vec![endpoint],
            stale_after: Duration::from_secs(1),
            security: Default::default(),
        })
        .map_err(|e| e.to_string())?;
        lock(shared).opened_at = Some(opened);
        while !stop.load(Ordering::Relaxed) && !pheromone_field::shm::should_stop(&node) {
            mirror
                .step(&node, Duration::from_millis(20))
                .map_err(|e| e.to_string())?;
            let mut s = lock(shared);
            s.mirror = mirror.stats;
            s.lags_ns.extend(mirror.lags_ns.drain(..));
            if s.live_at.is_none() && mirror.stats.frames_applied > 0 {
                s.live_at = Some(Instant::now());
            }
        }
        mirror.close();
        Ok(())
    })
}

/// Waits until `done` holds on `w`'s shared state (checking the thread's error), at most
/// `timeout`, pausing on `node` (a termination request ends the wait).
fn wait_for(
    node: &iceoryx2::node::Node<pheromone_field::shm::Svc>,
    w: &Worker,
    timeout: Duration,
    what: &str,
    done: impl Fn(&Shared) -> bool,
) -> Result<(), BenchError> {
    let deadline = Instant::now() + timeout;
    loop {
        w.check()?;
        if done(&lock(&w.shared)) {
            return Ok(());
        }
        if Instant::now() >= deadline {
            return Err(BenchError::Peer(format!(
                "mirror bench: {what} within {timeout:?}"
            )));
        }
        pheromone_field::shm::node_wait(node, Duration::from_millis(10))
            .map_err(|_| BenchError::Interrupted)?;
    }
}

/// The size of the keyframe the bridge serves now (a `get` on its queryable).
fn keyframe_now(session: &zenoh::Session, key: &str) -> Result<u64, BenchError> {
    let zerr = |e: zenoh::Error| BenchError::Zenoh(format!("get {key}: {e}"));
    for _ in 0..3 {
        let replies = session
            .get(key)
            .timeout(Duration::from_secs(5))
            .wait()
            .map_err(zerr)?;
        while let Ok(reply) = replies.recv() {
            if let Ok(sample) = reply.result() {
                return Ok(sample.payload().len() as u64);
            }
        }
    }
    Err(BenchError::Peer(format!(
        "mirror bench: the bridge answered no request on {key}"
    )))
}

pub fn measure(launcher: &Launcher, tag: &str, run: MirrorRun) -> Result<MirrorReport, BenchError> {
    let name = format!("bench-mir-{tag}");
    let node = create_node_in(&format!("bench-mirror-main-{tag}"), Some(ORIGIN_DOMAIN))?;
    let mut sup = Supervisor::new(&launcher.program);
    sup.echo_stderr = false;
    let width = run.width.to_string();
    let tick_hz = run.tick_hz.to_string();
    let origin = sup.spawn(ChildSpec::new(
        "field",
        None,
        [
            "--iox-domain",
            ORIGIN_DOMAIN,
            "field",
            "--name",
            &name,
            "--width",
            &width,
            "--height",
            &width,
            "--tick-hz",
            &tick_hz,
            "--model",
            "exponential",
            "--decay-per-s",
            "0.0057",
            "--max-readers",
            "2",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect(),
    ))?;
    if run.pin {
        crate::gateway::pin_pid(sup.pid(origin), 1);
    }
    let result = measure_with(&node, &name, tag, run);
    sup.stop_all(Duration::from_secs(10));
    drop(node);
    for d in [ORIGIN_DOMAIN, MIRROR_DOMAIN] {
        if let Ok(c) = pheromone_field::shm::domain_config_of(Some(d)) {
            pheromone_field::shm::cleanup_dead_nodes_of(&c);
        }
    }
    result
}

fn measure_with(
    node: &iceoryx2::node::Node<pheromone_field::shm::Svc>,
    name: &str,
    tag: &str,
    run: MirrorRun,
) -> Result<MirrorReport, BenchError> {
    let bridge = bridge_worker(name.to_string(), run.keyframe_every);
    let mut depositor = DepositPublisher::attach_within(node, name, 1, Duration::from_secs(20))?;
    let start_timeout = Duration::from_secs(30);
    wait_for(node, &bridge, start_timeout, "the bridge listened", |s| {
        s.endpoint.is_some()
    })?;
    let listen = lock(&bridge.shared).endpoint.clone().expect("waited for");
    let mirror = mirror_worker(name.to_string(), listen.clone(), format!("{tag}-1"));
    wait_for(node, &mirror, start_timeout, "the mirror went live", |s| {
        s.mirror.frames_applied >= 10
    })?;
    let asker = zenoh::open(
        session_config_as("client", &[], std::slice::from_ref(&listen))
            .map_err(|e| BenchError::Zenoh(e.to_string()))?,
    )
    .wait()
    .map_err(|e| BenchError::Zenoh(format!("connect to the bridge: {e}")))?;
    let keyframe_key = Keys::of(name).keyframe;
    let raw_frame_bytes = run.width as u64 * run.width as u64 * 4;
    let raw_bytes_per_s = raw_frame_bytes as f64 * run.tick_hz as f64;
    let rig = Rig {
        node,
        bridge: &bridge,
        mirror: &mirror,
        asker: &asker,
        keyframe_key: &keyframe_key,
        run,
        side_m: run.width as f32 * pheromone_field::FieldConfig::default().cell_size_m,
        raw_bytes_per_s,
    };
    let mut rng = 0x9e37_79b9_7f4a_7c15u64;
    let mut wire = Vec::new();
    lock(&mirror.shared).lags_ns.clear();
    for rate in [10.0, 1000.0] {
        wire.push(rig.wire_at_rate(&mut depositor, rate, &mut rng)?);
    }
    let lags_ns = std::mem::take(&mut lock(&mirror.shared).lags_ns);
    let lag_us = Latency::from_ns_as_us(&lags_ns)
        .ok_or_else(|| BenchError::Peer("mirror bench: no frame replayed".into()))?;
    let first = lock(&mirror.shared).mirror;
    mirror.finish()?;
    // A mirror started afresh catches up on the field as the deposits left it.
    let (catch_up, start_to_live_ms, catch_up_bytes) =
        fresh_mirror_catch_up(node, name, listen, tag, start_timeout)?;
    let _ = asker.close().wait();
    drop(depositor);
    bridge.finish()?;
    // The fresh mirror's keyframe: the field after both windows (else the last one asked).
    let keyframe_bytes = match catch_up_bytes {
        0 => wire.last().map_or(0, |w| w.keyframe_bytes),
        n => n,
    };
    Ok(MirrorReport {
        width: run.width,
        channels: 1,
        tick_hz: run.tick_hz as f64,
        raw_frame_bytes,
        raw_bytes_per_s,
        keyframe_every_s: run.keyframe_every.as_secs_f64(),
        wire,
        lag_us,
        keyframe_bytes,
        keyframe_ratio: keyframe_bytes as f64 / raw_frame_bytes as f64,
        catch_up_ms: round(catch_up, 2),
        start_to_live_ms: round(start_to_live_ms, 2),
        checksums_matched: first.checksums_matched,
        checksum_mismatches: first.checksum_mismatches,
        method: "origin field process (domain A) -> Bridge thread -> Zenoh over loopback TCP -> Mirror thread (domain B); bytes from the bridge's counters, keyframe amortized over its interval",
    })
}

/// `v` rounded to `digits` decimal digits.
fn round(v: f64, digits: i32) -> f64 {
    let f = 10f64.powi(digits);
    (v * f).round() / f
}

/// What the deposit windows drive and watch, and the run's figures.
struct Rig<'a> {
    node: &'a iceoryx2::node::Node<pheromone_field::shm::Svc>,
    bridge: &'a Worker,
    mirror: &'a Worker,
    asker: &'a zenoh::Session,
    keyframe_key: &'a str,
    run: MirrorRun,
    /// The field's side (m).
    side_m: f32,
    /// Raw frames per second, bytes.
    raw_bytes_per_s: f64,
}

impl Rig<'_> {
    /// Sends deposits at `rate` per second for the run's window and measures the wire bytes.
    fn wire_at_rate(
        &self,
        depositor: &mut DepositPublisher,
        rate: f64,
        rng: &mut u64,
    ) -> Result<WireAtRate, BenchError> {
        let b0 = lock(&self.bridge.shared).bridge;
        let started = Instant::now();
        self.send_deposits(depositor, started, rate, rng)?;
        let b1 = lock(&self.bridge.shared).bridge;
        let secs = started.elapsed().as_secs_f64();
        let keyframe_bytes = keyframe_now(self.asker, self.keyframe_key)?;
        let per_s = |a: u64, b: u64| b.saturating_sub(a) as f64 / secs;
        let inputs_bytes_per_s = per_s(b0.inputs_bytes, b1.inputs_bytes);
        let other_bytes_per_s = per_s(b0.other_bytes, b1.other_bytes);
        let keyframe_bytes_per_s = keyframe_bytes as f64 / self.run.keyframe_every.as_secs_f64();
        let wire_bytes_per_s = inputs_bytes_per_s + other_bytes_per_s + keyframe_bytes_per_s;
        Ok(WireAtRate {
            deposits_per_s: rate,
            applied_per_s: per_s(b0.deposits_in_inputs, b1.deposits_in_inputs),
            frames_per_s: per_s(b0.inputs_sent, b1.inputs_sent),
            inputs_bytes_per_s,
            other_bytes_per_s,
            keyframe_bytes,
            keyframe_bytes_per_s,
            wire_bytes_per_s,
            ratio_to_raw: wire_bytes_per_s / self.raw_bytes_per_s,
        })
    }

    /// Sends scattered deposits at `rate` per second for the window, checking both threads.
    fn send_deposits(
        &self,
        depositor: &mut DepositPublisher,
        started: Instant,
        rate: f64,
        rng: &mut u64,
    ) -> Result<(), BenchError> {
        let interval = Duration::from_secs_f64(1.0 / rate);
        let mut next = started;
        while started.elapsed() < self.run.window {
            // Scattered over the field (xorshift), as robots' trails are.
            let mut coord = || scattered(rng, self.side_m);
            let (x, y) = (coord(), coord());
            depositor.send(DepositMsg::from(Deposit {
                channel: 0,
                x_m: x,
                y_m: y,
                kernel: Kernel::Ellipse {
                    tau: 0.001,
                    cov_m2: [0.01, 0.0, 0.01],
                    range_m: 0.5,
                    gamma_max: 100.0,
                },
            }))?;
            next += interval;
            let now = Instant::now();
            if next > now {
                pheromone_field::shm::node_wait(self.node, next - now)
                    .map_err(|_| BenchError::Interrupted)?;
            }
            self.bridge.check()?;
            self.mirror.check()?;
        }
        Ok(())
    }
}

/// The next coordinate in `0..side_m` from the xorshift state `rng`.
fn scattered(rng: &mut u64, side_m: f32) -> f32 {
    *rng ^= *rng << 13;
    *rng ^= *rng >> 7;
    *rng ^= *rng << 17;
    (*rng >> 40) as f32 / (1u64 << 24) as f32 * side_m
}

/// A fresh mirror's catch-up (ms), session open → live (ms) and keyframe bytes.
fn fresh_mirror_catch_up(
    node: &iceoryx2::node::Node<pheromone_field::shm::Svc>,
    name: &str,
    listen: String,
    tag: &str,
    start_timeout: Duration,
) -> Result<(f64, f64, u64), BenchError> {
    let again = mirror_worker(name.to_string(), listen, format!("{tag}-2"));
    wait_for(
        node,
        &again,
        start_timeout,
        "the restarted mirror went live",
        |s| s.live_at.is_some(),
    )?;
    let caught_up = {
        let s = lock(&again.shared);
        let opened = s.opened_at.expect("set before the mirror steps");
        let live = s.live_at.expect("waited for");
        (
            s.mirror.last_catch_up_ms,
            live.duration_since(opened).as_secs_f64() * 1e3,
            s.mirror.last_keyframe_bytes,
        )
    };
    again.finish()?;
    Ok(caught_up)
}
