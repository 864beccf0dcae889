//! A mirror behind a link with delay, jitter and loss: the test kit's fault-injecting TCP
//! proxy (`pheromone_testkit::proxy`) between the mirror and its bridge on loopback. While it lags, the
//! mirror's frame of sequence s is the origin's frame of s; once deposits stop it catches up
//! bit-identically. A second test measures the mirror's lag and the link's bytes/s over a grid
//! of delays and losses (the table in docs/mirrors.md).

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use pheromone_bridge::codec;
use pheromone_testkit::proxy::{Faults, FaultyProxy};

use super::{assert_identical, bridge, deposit, origin_field, CleanDomains, Hosts, ORIGIN};
use crate::harness::*;

/// The mirror's retransmission timeout stand-in (Linux's minimum RTO is 200 ms).
const RTO: Duration = Duration::from_millis(200);

/// A proxy in front of the bridge at `endpoint` (`tcp/127.0.0.1:PORT`).
fn proxy(endpoint: &str, delay_ms: u64, loss: f64) -> FaultyProxy {
    let upstream: SocketAddr = endpoint.trim_start_matches("tcp/").parse().unwrap();
    FaultyProxy::start(
        upstream,
        Faults {
            delay: Duration::from_millis(delay_ms),
            jitter: Duration::from_millis(delay_ms / 10),
            loss,
            rto: RTO,
            seed: 0x5eed ^ delay_ms,
        },
    )
    .unwrap()
}

/// Frames seen by this process on both hosts: per sequence its checksum and when first seen.
#[derive(Default)]
struct Seen {
    origin: BTreeMap<u64, (u64, Instant)>,
    mirror: BTreeMap<u64, (u64, Instant)>,
}

impl Seen {
    /// Watches both hosts for `window` (woken by each mirror frame, at least every 2 ms).
    fn watch(hosts: &mut Hosts, window: Duration) -> Self {
        let mut seen = Self::default();
        let end = Instant::now() + window;
        while Instant::now() < end {
            hosts.mirror.wait_frame(Duration::from_millis(2)).unwrap();
            hosts.origin.update().unwrap();
            let now = Instant::now();
            for (r, map) in [
                (&hosts.origin, &mut seen.origin),
                (&hosts.mirror, &mut seen.mirror),
            ] {
                if let Some(s) = r.sample() {
                    map.entry(s.user_header().sequence)
                        .or_insert_with(|| (codec::frame_checksum(s.payload()), now));
                }
            }
        }
        seen
    }

    /// (sequence, origin checksum, mirror checksum) of the sequences seen on both.
    fn common(&self) -> Vec<(u64, u64, u64)> {
        self.mirror
            .iter()
            .filter_map(|(s, (m, _))| self.origin.get(s).map(|(o, _)| (*s, *o, *m)))
            .collect()
    }

    /// The mirror's lag behind the origin per common sequence, sorted (ms).
    fn lags_ms(&self) -> Vec<f64> {
        let mut l: Vec<f64> = self
            .mirror
            .iter()
            .filter_map(|(s, (_, tm))| {
                let (_, to) = self.origin.get(s)?;
                Some(tm.saturating_duration_since(*to).as_secs_f64() * 1e3)
            })
            .collect();
        l.sort_by(f64::total_cmp);
        l
    }
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// Deposits on the origin every `every` from a thread of its own until `stop`; joined on drop.
struct Depositor {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Depositor {
    fn start(name: &str, every: Duration) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let (s, name) = (stop.clone(), name.to_string());
        let thread = std::thread::spawn(move || {
            let mut i = 0u32;
            while !s.load(Ordering::SeqCst) {
                let at = format!("{:.1}", 0.5 + f64::from(i % 11) * 0.5);
                deposit(ORIGIN, &name, &at, "3.0");
                i += 1;
                // The deposits' cadence (the load), not a wait for a condition.
                std::thread::sleep(every);
            }
        });
        Self {
            stop,
            thread: Some(thread),
        }
    }
}

impl Drop for Depositor {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[test]
fn behind_200_ms_delay_and_5_percent_loss_a_mirror_lags_but_never_differs_then_catches_up() {
    let _clean = CleanDomains;
    let name = unique("mirlag");
    let _field = origin_field(&name);
    let b = bridge(&name);
    let p = proxy(&b.endpoint, 200, 0.05);
    let m = super::mirror(&name, &format!("tcp/{}", p.addr()));
    let mut hosts = Hosts::attach(&name);
    let depositor = Depositor::start(&name, Duration::from_millis(200));
    let seen = Seen::watch(&mut hosts, Duration::from_secs(6));
    drop(depositor);
    let stopped = Instant::now();
    let both = seen.common();
    // Enough frames for the comparison to mean something (not a rate: the cores are shared).
    assert!(both.len() >= 10, "only {} common frames in 6 s", both.len());
    assert_identical(&both);
    let lags = seen.lags_ms();
    let (p50, p99) = (quantile(&lags, 0.5), quantile(&lags, 0.99));
    // The link's delay is a floor (less would mean the proxy did not delay); no ceiling: how
    // far behind a loaded machine falls is measured and printed, not asserted.
    assert!(
        p50 >= 160.0,
        "the mirror lags {p50:.0} ms (p50) behind a 200 ms link"
    );
    // After the deposits stop: identical on frames newer than the last one.
    let last = hosts.origin_sequence();
    assert_identical(&hosts.common(10, |f| f.header.sequence > last));
    println!(
        "200 ms + 5 % loss: lag p50 {p50:.0} ms, p99 {p99:.0} ms over {} frames; bit-identical \
         {:.2} s after the deposits stopped",
        lags.len(),
        stopped.elapsed().as_secs_f64()
    );
    let s = super::mirror_summary(m);
    assert_eq!(s["checksum_mismatches"], 0, "{s}");
}

/// One row of the table: a fresh proxy and mirror, 4 s watched under deposits every 100 ms.
fn measure(name: &str, endpoint: &str, delay_ms: u64, loss: f64) -> (usize, f64, f64, f64) {
    let p = proxy(endpoint, delay_ms, loss);
    let m = super::mirror(name, &format!("tcp/{}", p.addr()));
    let mut hosts = Hosts::attach(name);
    let _ = Seen::watch(&mut hosts, Duration::from_secs(1));
    let (bytes0, t0) = (p.bytes(), Instant::now());
    let depositor = Depositor::start(name, Duration::from_millis(100));
    let seen = Seen::watch(&mut hosts, Duration::from_secs(4));
    drop(depositor);
    let bytes_per_s = (p.bytes() - bytes0) as f64 / t0.elapsed().as_secs_f64();
    assert_identical(&seen.common());
    let lags = seen.lags_ms();
    assert!(
        lags.len() >= 10,
        "{delay_ms} ms, {loss}: {} frames",
        lags.len()
    );
    let (p50, p99) = (quantile(&lags, 0.5), quantile(&lags, 0.99));
    // The delay is a floor (80 %: the watcher sees the origin's frame a little late at times);
    // no ceiling, since a loaded machine's lag is a figure to print, not a pass/fail.
    assert!(
        p50 >= 0.8 * delay_ms as f64,
        "{delay_ms} ms, loss {loss}: lag p50 {p50:.0} ms"
    );
    drop(hosts);
    let s = super::mirror_summary(m);
    assert_eq!(s["checksum_mismatches"], 0, "{s}");
    (lags.len(), p50, p99, bytes_per_s)
}

#[test]
fn mirror_lag_and_bytes_per_second_over_delays_and_losses() {
    let _clean = CleanDomains;
    let name = unique("mirgrid");
    let _field = origin_field(&name);
    let b = bridge(&name);
    println!("delay ms | loss % | frames | lag p50 ms | lag p99 ms | bytes/s (both ways)");
    for delay_ms in [0, 50, 200] {
        for loss in [0.0, 0.01, 0.05] {
            let (n, p50, p99, bps) = measure(&name, &b.endpoint, delay_ms, loss);
            println!(
                "{delay_ms:>8} | {:>6.0} | {n:>6} | {p50:>10.1} | {p99:>10.1} | {bps:>9.0}",
                loss * 100.0
            );
        }
    }
}
