//! The `ros2` section's measurement (module docs: `ros2.rs`), with Zenoh.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use pheromone_bridge::{listen_locators, plain_session_config, with_admin_space};
use pheromone_field::shm::{create_node, should_stop, Svc};
use pheromone_supervisor::{ChildSpec, Supervisor};
use zenoh::Wait;

use super::{cpu_since, thread_cpu_ns, Idle, PublisherCpu, Ros2Report, Ros2Run};
use crate::peer::{say_ready, say_result, Launcher, Peer, PeerResult, PeerSpec};
use crate::BenchError;

type Node = iceoryx2::node::Node<Svc>;

/// The key prefixes of the two publishers' samples.
const ROS2_PREFIX: &str = "0/pheromone/";
const PLAIN_PREFIX: &str = "0/bench_plain/";

fn zerr(what: &str) -> impl Fn(zenoh::Error) -> BenchError + '_ {
    move |e| BenchError::Zenoh(format!("{what}: {e}"))
}

/// Samples and payload bytes per key.
#[derive(Debug, Default, Clone, Copy)]
struct KeyCount {
    messages: u64,
    bytes: u64,
    last_bytes: u64,
}

type Counts = Arc<Mutex<BTreeMap<String, KeyCount>>>;

/// The subscriber's session (listening), its counts, and whether a ROS node's token showed.
struct Subscriber {
    session: zenoh::Session,
    endpoint: String,
    counts: Counts,
    tokens_seen: Arc<AtomicBool>,
    _tokens: zenoh::pubsub::Subscriber<()>,
    samples: Option<zenoh::pubsub::Subscriber<()>>,
}

impl Subscriber {
    fn open() -> Result<Self, BenchError> {
        let listen = ["tcp/127.0.0.1:0".to_string()];
        // It stands for a ROS 2 subscriber: `pheromone ros2` presents no owner key.
        let config = plain_session_config("peer", &listen, &[])
            .and_then(with_admin_space)
            .map_err(|e| BenchError::Zenoh(e.to_string()))?;
        let session = zenoh::open(config)
            .wait()
            .map_err(zerr("open the subscriber's session"))?;
        let endpoint = listen_locators(&session)
            .map_err(|e| BenchError::Zenoh(e.to_string()))?
            .into_iter()
            .next()
            .ok_or_else(|| BenchError::Zenoh("the subscriber's session listens nowhere".into()))?;
        let tokens_seen = Arc::new(AtomicBool::new(false));
        let seen = tokens_seen.clone();
        let tokens = session
            .liveliness()
            .declare_subscriber("@ros2_lv/**")
            .history(true)
            .callback(move |_| seen.store(true, Ordering::Relaxed))
            .wait()
            .map_err(zerr("subscribe @ros2_lv/**"))?;
        Ok(Self {
            session,
            endpoint,
            counts: Counts::default(),
            tokens_seen,
            _tokens: tokens,
            samples: None,
        })
    }

    /// Declares the one subscriber, on `0/**`.
    fn subscribe(&mut self) -> Result<(), BenchError> {
        let counts = self.counts.clone();
        let sub = self
            .session
            .declare_subscriber("0/**")
            .callback(move |s| {
                let n = s.payload().len() as u64;
                let mut c = counts.lock().unwrap_or_else(|e| e.into_inner());
                let k = c.entry(s.key_expr().as_str().to_string()).or_default();
                k.messages += 1;
                k.bytes += n;
                k.last_bytes = n;
            })
            .wait()
            .map_err(zerr("subscribe 0/**"))?;
        self.samples = Some(sub);
        Ok(())
    }

    /// (messages, bytes, keys) under `prefix` so far.
    fn totals(&self, prefix: &str) -> (u64, u64, u64) {
        let c = self.counts.lock().unwrap_or_else(|e| e.into_inner());
        c.iter()
            .filter(|(k, _)| k.starts_with(prefix))
            .fold((0, 0, 0), |(m, b, n), (_, v)| {
                (m + v.messages, b + v.bytes, n + 1)
            })
    }

    /// Each topic's last payload size under `prefix`, in key order.
    fn topic_bytes(&self, prefix: &str) -> Vec<u64> {
        let c = self.counts.lock().unwrap_or_else(|e| e.into_inner());
        c.iter()
            .filter(|(k, _)| k.starts_with(prefix))
            .map(|(_, v)| v.last_bytes)
            .collect()
    }
}

/// Waits until `done`, at most `timeout`, pausing on `node` (a termination request ends it).
fn wait_until(
    node: &Node,
    timeout: Duration,
    what: &str,
    mut done: impl FnMut() -> Result<bool, BenchError>,
) -> Result<(), BenchError> {
    let deadline = Instant::now() + timeout;
    while !done()? {
        if Instant::now() >= deadline {
            return Err(BenchError::Peer(format!(
                "ros2 bench: {what} within {timeout:?}"
            )));
        }
        pheromone_field::shm::node_wait(node, Duration::from_millis(10))
            .map_err(|_| BenchError::Interrupted)?;
    }
    Ok(())
}

/// The section, from a thread of its own off this process's pinned core: the children it starts
/// and the subscriber's Zenoh threads may run on any core, the same for both publishers.
pub fn measure(launcher: &Launcher, tag: &str, run: Ros2Run) -> Result<Ros2Report, BenchError> {
    let (launcher, tag) = (launcher.clone(), tag.to_string());
    std::thread::spawn(move || {
        crate::machine::unpin();
        measure_unpinned(&launcher, &tag, run)
    })
    .join()
    .map_err(|_| BenchError::Peer("the ros2 bench thread panicked".into()))?
}

fn measure_unpinned(
    launcher: &Launcher,
    tag: &str,
    run: Ros2Run,
) -> Result<Ros2Report, BenchError> {
    let name = format!("bench-ros2-{tag}");
    let node = create_node(&format!("bench-ros2-main-{tag}"))?;
    let mut field = Peer::spawn(
        launcher,
        &PeerSpec::Field {
            name: name.clone(),
            width: run.width,
            tick_hz: run.rate_hz as f32,
            core: None,
            on_deposit: false,
            rt_priority: None,
            spin_us: 0,
        },
    )?;
    field.wait_ready(Duration::from_secs(20))?;
    let mut sub = Subscriber::open()?;
    let (ros2, idle) = measure_node(&node, launcher, &name, &mut sub, run)?;
    let topic_bytes = sub.topic_bytes(ROS2_PREFIX);
    let plain = Peer::spawn(
        launcher,
        &PeerSpec::PlainZenoh {
            connect: sub.endpoint.clone(),
            topic_bytes: topic_bytes.clone(),
            rate_hz: ros2.frames_per_s,
        },
    )?;
    let plain_zenoh = measure_plain(&node, plain, &sub, run)?;
    let _ = sub.session.close().wait();
    drop(field);
    Ok(Ros2Report {
        width: run.width,
        rate_hz: run.rate_hz,
        topic_bytes,
        cpu_per_mb_ratio: ros2.cpu_ms_per_mb / plain_zenoh.cpu_ms_per_mb,
        ros2,
        plain_zenoh,
        idle,
        method:
            "field peer -> `pheromone ros2 --connect` (rmw_zenoh's session settings otherwise) \
                 and, after it, a plain Zenoh publisher peer of the same topic sizes at the frame \
                 rate the node kept -> one subscriber (0/**) in the bench process; CPU: the \
                 publisher process's CPU time, every thread (/proc/PID/task/TID/schedstat), per MB the subscriber got",
    })
}

/// `pheromone ros2`: its CPU with nobody subscribed, then with the subscriber.
fn measure_node(
    node: &Node,
    launcher: &Launcher,
    field: &str,
    sub: &mut Subscriber,
    run: Ros2Run,
) -> Result<(PublisherCpu, Idle), BenchError> {
    let mut sup = Supervisor::new(&launcher.program);
    sup.echo_stderr = false;
    let args = [
        "ros2",
        "--field",
        field,
        "--rate-hz",
        &run.rate_hz.to_string(),
        "--connect",
        &sub.endpoint,
        "--timeout",
        "30",
        "--json",
    ];
    let mut spec = ChildSpec::new(
        "pheromone ros2",
        None,
        args.iter().map(|s| s.to_string()).collect(),
    );
    // rmw_zenoh's default session settings, not a caller's file.
    spec.env_remove.push("ZENOH_SESSION_CONFIG_URI".to_string());
    let id = sup.spawn(spec)?;
    let pid = sup.pid(id);
    let measured = (|| {
        wait_until(
            node,
            Duration::from_secs(40),
            "pheromone ros2's liveliness tokens",
            || Ok(sub.tokens_seen.load(Ordering::Relaxed)),
        )?;
        let (cpu0, started) = (thread_cpu_ns(pid)?, Instant::now());
        pheromone_field::shm::node_wait(node, run.idle).map_err(|_| BenchError::Interrupted)?;
        let idle_cpu_s = cpu_since(&cpu0, &thread_cpu_ns(pid)?);
        let idle_s = started.elapsed().as_secs_f64();
        sub.subscribe()?;
        let cpu = cpu_window(node, sub, pid, ROS2_PREFIX, run)?;
        Ok((cpu, idle_s, idle_cpu_s))
    })();
    let measured = measured.map_err(|e: BenchError| {
        BenchError::Peer(format!("{e}; pheromone ros2 said: {}", sup.stderr_tail(id)))
    });
    sup.stop_all(Duration::from_secs(10));
    let (cpu, idle_s, idle_cpu_s) = measured?;
    // The node's --json summary, printed as it stopped.
    let summary: Option<serde_json::Value> = sup
        .next_line(id, Duration::from_secs(2))
        .ok()
        .flatten()
        .and_then(|l| serde_json::from_str(&l).ok());
    let count = |k: &str| summary.as_ref().and_then(|s| s["ros2"][k].as_u64());
    let idle = Idle {
        seconds: idle_s,
        cpu_share: idle_cpu_s / idle_s,
        frames_without_subscribers: count("frames_without_subscribers"),
        frames_for_cache: count("frames_for_cache"),
    };
    Ok((cpu, idle))
}

/// The plain Zenoh publisher peer, once the subscriber gets its samples.
fn measure_plain(
    node: &Node,
    mut plain: Peer,
    sub: &Subscriber,
    run: Ros2Run,
) -> Result<PublisherCpu, BenchError> {
    plain.wait_ready(Duration::from_secs(30))?;
    cpu_window(node, sub, plain.pid(), PLAIN_PREFIX, run)
}

/// Once the subscriber got a few samples under `prefix`: the publisher `pid`'s CPU over the
/// run's window, per MB the subscriber got in it.
fn cpu_window(
    node: &Node,
    sub: &Subscriber,
    pid: u32,
    prefix: &str,
    run: Ros2Run,
) -> Result<PublisherCpu, BenchError> {
    let what = format!("samples under {prefix}");
    wait_until(node, Duration::from_secs(30), &what, || {
        Ok(sub.totals(prefix).0 >= 4)
    })?;
    let (m0, b0, _) = sub.totals(prefix);
    let (cpu0, started) = (thread_cpu_ns(pid)?, Instant::now());
    pheromone_field::shm::node_wait(node, run.window).map_err(|_| BenchError::Interrupted)?;
    let (m1, b1, keys) = sub.totals(prefix);
    let cpu_s = cpu_since(&cpu0, &thread_cpu_ns(pid)?);
    let window_s = started.elapsed().as_secs_f64();
    let mb = (b1 - b0) as f64 / 1e6;
    if mb <= 0.0 || cpu_s <= 0.0 {
        return Err(BenchError::Peer(format!(
            "ros2 bench: {prefix}: {mb} MB received, {cpu_s} s of CPU in {window_s:.1} s"
        )));
    }
    Ok(PublisherCpu {
        window_s,
        frames_per_s: (m1 - m0) as f64 / keys.max(1) as f64 / window_s,
        mb_per_s: mb / window_s,
        cpu_share: cpu_s / window_s,
        cpu_ms_per_mb: cpu_s * 1e3 / mb,
    })
}

/// The plain Zenoh publisher peer: a fresh buffer of each size on `0/bench_plain/topic_<i>`,
/// `rate_hz` times a second, through a peer session connected to `connect`, until terminated.
pub fn plain_publisher(connect: &str, topic_bytes: &[u64], rate_hz: f64) -> Result<(), BenchError> {
    if !(rate_hz > 0.0 && rate_hz.is_finite()) {
        return Err(BenchError::Peer(format!(
            "plain zenoh publisher: rate {rate_hz} Hz"
        )));
    }
    let node = create_node(&format!("bench-plain-zenoh-{}", std::process::id()))?;
    let config = plain_session_config("peer", &[], &[connect.to_string()])
        .map_err(|e| BenchError::Zenoh(e.to_string()))?;
    let session = zenoh::open(config).wait().map_err(zerr("open"))?;
    let mut publishers = Vec::new();
    for i in 0..topic_bytes.len() {
        let key = format!("{PLAIN_PREFIX}topic_{i}");
        publishers.push(
            session
                .declare_publisher(key)
                .wait()
                .map_err(zerr("declare"))?,
        );
    }
    // A frame's bytes: a pattern, the first byte changed each frame.
    let templates: Vec<Vec<u8>> = topic_bytes
        .iter()
        .map(|&n| (0..n).map(|i| (i % 251) as u8).collect())
        .collect();
    say_ready();
    let period = Duration::from_secs_f64(1.0 / rate_hz);
    let mut next = Instant::now();
    let mut frame = 0u8;
    while !should_stop(&node) {
        for (p, t) in publishers.iter().zip(&templates) {
            let mut bytes = t.clone();
            if let Some(b) = bytes.first_mut() {
                *b = frame;
            }
            p.put(bytes).wait().map_err(zerr("put"))?;
        }
        frame = frame.wrapping_add(1);
        // Deadlines advance by whole periods; one that fell behind starts over.
        let now = Instant::now();
        next = if next + period > now {
            next + period
        } else {
            now + period
        };
        if pheromone_field::shm::node_wait(&node, next - now).is_err() {
            break;
        }
    }
    let _ = session.close().wait();
    say_result(&PeerResult::default());
    Ok(())
}
