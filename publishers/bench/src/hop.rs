//! Hop latency of a small message between two processes, ping-pong / 2: ours (`pheromone_field::process::link`
//! with a 128-byte `PoseMsg`, as a localizer sends poses to a depositor) against raw iceoryx2
//! publish-subscribe of a `u64` (plus the same event in wait mode).

use std::time::{Duration, Instant};

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use pheromone_field::process::link::{LinkOptions, Receiver, Sender};
use pheromone_field::shm::{create_node, now_ns, Svc};
use pheromone_messages::PoseMsg;

use crate::peer::{say_ready, say_result, Launcher, Peer, PeerResult, PeerSpec};
use crate::BenchError;

/// Longest wait for one answer before the run is declared broken.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(5);

/// One end of a ping-pong: sends on one service, receives on the other.
trait End {
    fn send(&self, seq: u64) -> Result<(), BenchError>;
    fn try_recv(&self) -> Result<Option<u64>, BenchError>;
    fn wait(&self, timeout: Duration) -> Result<(), BenchError>;
}

fn link_options() -> LinkOptions {
    LinkOptions {
        max_publishers: 2,
        max_subscribers: 2,
        buffer: 4,
        keep_latest: true,
    }
}

struct Ours {
    tx: Sender<PoseMsg>,
    rx: Receiver<PoseMsg>,
}

impl Ours {
    fn new(node: &Node<Svc>, send_on: &str, recv_on: &str) -> Result<Self, BenchError> {
        Ok(Self {
            tx: Sender::create(node, send_on, &format!("{send_on}-ready"), link_options())?,
            rx: Receiver::create(node, recv_on, &format!("{recv_on}-ready"), link_options())?,
        })
    }
}

impl End for Ours {
    fn send(&self, seq: u64) -> Result<(), BenchError> {
        let msg = PoseMsg {
            stamp_ns: now_ns(),
            step: seq,
            x_m: 1.0,
            y_m: 2.0,
            cov: [0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.001],
            ..Default::default()
        };
        self.tx.send(msg)?;
        Ok(())
    }
    fn try_recv(&self) -> Result<Option<u64>, BenchError> {
        Ok(self.rx.try_recv()?.map(|m| m.step))
    }
    fn wait(&self, timeout: Duration) -> Result<(), BenchError> {
        Ok(self.rx.wait(timeout)?)
    }
}

struct Raw {
    publisher: Publisher<Svc, u64, ()>,
    notifier: Notifier<Svc>,
    subscriber: Subscriber<Svc, u64, ()>,
    listener: Listener<Svc>,
    notify: bool,
}

fn raw_err(what: &str, e: impl std::fmt::Debug) -> BenchError {
    BenchError::Peer(format!("raw iceoryx2 {what}: {e:?}"))
}

fn service_name(name: &str) -> Result<ServiceName, BenchError> {
    ServiceName::new(name).map_err(|e| raw_err(&format!("service name '{name}'"), e))
}

impl Raw {
    fn new(
        node: &Node<Svc>,
        send_on: &str,
        recv_on: &str,
        notify: bool,
    ) -> Result<Self, BenchError> {
        let pubsub = |name: &str| {
            node.service_builder(&service_name(name)?)
                .publish_subscribe::<u64>()
                .max_publishers(2)
                .max_subscribers(2)
                .history_size(0)
                .subscriber_max_buffer_size(4)
                .enable_safe_overflow(true)
                .open_or_create()
                .map_err(|e| raw_err(name, e))
        };
        let event = |name: &str| {
            node.service_builder(&service_name(&format!("{name}-ready"))?)
                .event()
                .open_or_create()
                .map_err(|e| raw_err(name, e))
        };
        Ok(Self {
            publisher: pubsub(send_on)?
                .publisher_builder()
                .create()
                .map_err(|e| raw_err("publisher", e))?,
            notifier: event(send_on)?
                .notifier_builder()
                .create()
                .map_err(|e| raw_err("notifier", e))?,
            subscriber: pubsub(recv_on)?
                .subscriber_builder()
                .create()
                .map_err(|e| raw_err("subscriber", e))?,
            listener: event(recv_on)?
                .listener_builder()
                .create()
                .map_err(|e| raw_err("listener", e))?,
            notify,
        })
    }
}

impl End for Raw {
    fn send(&self, seq: u64) -> Result<(), BenchError> {
        self.publisher
            .send_copy(seq)
            .map_err(|e| raw_err("send", e))?;
        if self.notify {
            self.notifier.notify().map_err(|e| raw_err("notify", e))?;
        }
        Ok(())
    }
    fn try_recv(&self) -> Result<Option<u64>, BenchError> {
        Ok(self
            .subscriber
            .receive()
            .map_err(|e| raw_err("receive", e))?
            .map(|s| *s.payload()))
    }
    fn wait(&self, timeout: Duration) -> Result<(), BenchError> {
        pheromone_field::shm::listener_timed_wait(&self.listener, timeout)
            .map(|_| ())
            .map_err(|e| raw_err("wait", e))
    }
}

/// Receives the message numbered `seq` (older ones are skipped), busy-polling or waiting.
fn receive(end: &dyn End, seq: u64, busy: bool) -> Result<(), BenchError> {
    let deadline = Instant::now() + ANSWER_TIMEOUT;
    loop {
        while let Some(got) = end.try_recv()? {
            if got == seq {
                return Ok(());
            }
        }
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(BenchError::Peer(format!(
                "no answer to ping {seq} within {ANSWER_TIMEOUT:?}"
            )));
        }
        if busy {
            std::hint::spin_loop();
        } else {
            end.wait(left)?;
        }
    }
}

/// One hop-latency measurement.
#[derive(Debug, Clone, Copy)]
pub struct HopRun {
    pub raw: bool,
    pub busy: bool,
    pub warmup: usize,
    pub count: usize,
    /// Pin the parent to core 0 and the peer to core 1.
    pub pin: bool,
}

/// Runs a ping-pong with a peer process; returns one-way latencies (RTT / 2) in ns.
pub fn measure(launcher: &Launcher, tag: &str, run: HopRun) -> Result<Vec<u64>, BenchError> {
    let node = create_node(&format!("bench-hop-{tag}"))?;
    let ping = format!("bench/{tag}/ping");
    let pong = format!("bench/{tag}/pong");
    let end: Box<dyn End> = if run.raw {
        Box::new(Raw::new(&node, &ping, &pong, !run.busy)?)
    } else {
        Box::new(Ours::new(&node, &ping, &pong)?)
    };
    let total = run.warmup + run.count;
    let mut peer = Peer::spawn(
        launcher,
        &PeerSpec::HopEcho {
            raw: run.raw,
            busy: run.busy,
            ping: ping.clone(),
            pong: pong.clone(),
            count: total,
            core: run.pin.then_some(1),
        },
    )?;
    peer.wait_ready(Duration::from_secs(10))?;
    let mut samples = Vec::with_capacity(run.count);
    for seq in 1..=total as u64 {
        let t0 = now_ns();
        end.send(seq)?;
        receive(end.as_ref(), seq, run.busy)?;
        let rtt = now_ns().saturating_sub(t0);
        if seq as usize > run.warmup {
            samples.push(rtt / 2);
        }
    }
    peer.result(Duration::from_secs(5))?;
    Ok(samples)
}

/// The peer side: echoes `count` pings.
pub fn echo(raw: bool, busy: bool, ping: &str, pong: &str, count: usize) -> Result<(), BenchError> {
    let node = create_node(&format!("bench-echo-{}", std::process::id()))?;
    let end: Box<dyn End> = if raw {
        Box::new(Raw::new(&node, pong, ping, !busy)?)
    } else {
        Box::new(Ours::new(&node, pong, ping)?)
    };
    say_ready();
    for seq in 1..=count as u64 {
        receive(end.as_ref(), seq, busy)?;
        end.send(seq)?;
    }
    say_result(&PeerResult::default());
    Ok(())
}
