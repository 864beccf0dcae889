//! Random SIGKILLs: the origin field, the bridge and the mirror each killed once, in a seeded
//! order at random moments, each restarted as a supervisor would, with deposits flowing on both hosts
//! (loopback, two iceoryx2 domains). `PHEROMONE_KILL_SEED=N` replays a run (the seed is printed).

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use pheromone_field::shm::create_node_in;

use super::netns::until_mirror;
use super::{assert_identical, bridge, bridge_on, mirror, origin_field, CleanDomains, Hosts};
use super::{MIRROR, ORIGIN};
use crate::harness::*;

/// splitmix64: the test's choices, a function of the seed only.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
}

/// Deposits on one host (`domain`) from a thread until dropped; counts acknowledged ones
/// (exit 0: applied, or on the mirror's host taken and forwarded) and failed ones (no field to
/// attach to, or no receipt in 1 s). Paused between phases so the counts can be compared.
struct Depositor {
    ok: Arc<AtomicU64>,
    failed: Arc<AtomicU64>,
    pause: Arc<AtomicBool>,
    idle: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Depositor {
    fn start(domain: &'static str, name: &str, row: &'static str) -> Self {
        let mut d = Self {
            ok: Arc::default(),
            failed: Arc::default(),
            pause: Arc::new(AtomicBool::new(true)),
            idle: Arc::new(AtomicBool::new(true)),
            stop: Arc::default(),
            thread: None,
        };
        let (ok, failed, pause, idle, stop) = (
            d.ok.clone(),
            d.failed.clone(),
            d.pause.clone(),
            d.idle.clone(),
            d.stop.clone(),
        );
        let name = name.to_string();
        let thread = std::thread::spawn(move || {
            let mut i = 0u64;
            while !stop.load(Ordering::SeqCst) {
                if pause.load(Ordering::SeqCst) {
                    idle.store(true, Ordering::SeqCst);
                    std::thread::park_timeout(Duration::from_millis(10));
                    continue;
                }
                idle.store(false, Ordering::SeqCst);
                let x = format!("{:.1}", 0.5 + (i % 11) as f64 * 0.5);
                let out = run(&Cmd::new("deposit")
                    .opt("--iox-domain", domain)
                    .opt("--field", &name)
                    .at(&x, row)
                    .amount(2)
                    .opt("--cov", "0.02,0,0.02")
                    .timeout(1)
                    .opt("--receipt-timeout", 1)
                    .argv());
                let n = if out.status.success() { &ok } else { &failed };
                n.fetch_add(1, Ordering::SeqCst);
                i += 1;
            }
        });
        d.thread = Some(thread);
        d
    }

    fn resume(&self) {
        self.pause.store(false, Ordering::SeqCst);
    }

    /// Pauses and waits until no deposit is in flight; the (acknowledged, failed) counts.
    fn pause(&self) -> (u64, u64) {
        self.pause.store(true, Ordering::SeqCst);
        self.idle.store(false, Ordering::SeqCst);
        eventually(Duration::from_secs(10), "the depositor to pause", || {
            self.idle.load(Ordering::SeqCst).then_some(())
        });
        (
            self.ok.load(Ordering::SeqCst),
            self.failed.load(Ordering::SeqCst),
        )
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

/// Watches both hosts for `span`: every sequence both showed has the same cells.
fn watch(hosts: &mut Hosts, span: Duration) {
    let t0 = Instant::now();
    let mut both = 0;
    while t0.elapsed() < span {
        // `common` records both sides and returns the sequences both showed.
        let c = hosts.common(3, |_| true);
        assert_identical(&c);
        both += c.len();
    }
    assert!(both >= 3, "no common frames in {span:?}");
}

/// The origin's deposits applied in its current run, once quiet (no change for 0.3 s).
fn applied_now(hosts: &mut Hosts) -> u64 {
    let mut last = (u64::MAX, Instant::now());
    eventually(
        Duration::from_secs(10),
        "the origin's deposit count to settle",
        || {
            hosts.origin.wait_frame(Duration::from_millis(20)).unwrap();
            let a = hosts.origin.frame()?.header.deposits_applied;
            if a != last.0 {
                last = (a, Instant::now());
            }
            (last.1.elapsed() >= Duration::from_millis(300)).then_some(a)
        },
    )
}

/// Waits until the origin's run has applied `want` deposits (10 s), or fails naming the count.
fn every_acknowledged_deposit_applied(hosts: &mut Hosts, want: u64) {
    let mut seen = 0;
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline {
        hosts.origin.wait_frame(Duration::from_millis(20)).unwrap();
        seen = hosts
            .origin
            .frame()
            .map_or(seen, |f| f.header.deposits_applied);
        if seen >= want {
            return;
        }
    }
    panic!("after a bridge kill the origin applied {seen} deposits of the {want} acknowledged");
}

/// The three parties, each restarted after it is killed.
struct Parties {
    name: String,
    endpoint: String,
    field: Proc,
    bridge: super::BridgeProc,
    mirror: Proc,
    watcher: iceoryx2::node::Node<pheromone_field::shm::Svc>,
}

impl Parties {
    /// SIGKILLs `target`, waits until the mirror is stale if it lost its origin, restarts the
    /// party and waits until the mirror is bit-identical and live again. New readers, the time
    /// until stale (if it applies) and the resync time after the restart.
    fn kill_and_restart(&mut self, target: &str, hosts: Hosts) -> (Hosts, Option<f64>, f64) {
        let killed = Instant::now();
        match target {
            "origin" => self.field.kill(),
            "bridge" => self.bridge.kill(),
            _ => self.mirror.kill(),
        }
        let stale_after = (target != "mirror").then(|| {
            // No origin behind it: the mirror says so while the party is down.
            until_mirror(&self.watcher, &self.name, true);
            killed.elapsed().as_secs_f64()
        });
        drop(hosts);
        match target {
            "origin" => self.field = origin_field(&self.name),
            "bridge" => self.bridge = bridge_on(&self.name, &self.endpoint),
            _ => self.mirror = mirror(&self.name, &self.endpoint),
        }
        let restarted = Instant::now();
        let mut hosts = Hosts::attach(&self.name);
        let last = hosts.origin_sequence();
        assert_identical(&hosts.common(5, |f| f.header.sequence > last));
        until_mirror(&self.watcher, &self.name, false);
        (hosts, stale_after, restarted.elapsed().as_secs_f64())
    }
}

#[test]
fn random_sigkills_of_origin_bridge_and_mirror_resync_and_apply_no_deposit_twice() {
    let _clean = CleanDomains;
    let seed = std::env::var("PHEROMONE_KILL_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| u64::from(std::process::id()) ^ 0x5eed);
    println!("random kills: seed {seed} (PHEROMONE_KILL_SEED={seed} replays the choices)");
    let mut rng = Rng(seed);
    let name = unique("mirkill");
    let field = origin_field(&name);
    let bridge = bridge(&name);
    let endpoint = bridge.endpoint.clone();
    let mut p = Parties {
        mirror: mirror(&name, &endpoint),
        watcher: create_node_in(&unique("mirkill-watch"), Some(MIRROR)).unwrap(),
        name: name.clone(),
        endpoint,
        field,
        bridge,
    };
    let mut hosts = Hosts::attach(&name);
    assert_identical(&hosts.common(5, |_| true));
    let on_origin = Depositor::start(ORIGIN, &name, "1.0");
    let on_mirror = Depositor::start(MIRROR, &name, "2.0");
    let (mut before, mut applied_before) = ((0, 0, 0, 0), 0);
    // Each party once, in a seeded order.
    let mut order = ["origin", "bridge", "mirror"];
    for i in (1..order.len()).rev() {
        order.swap(i, (rng.next() % (i as u64 + 1)) as usize);
    }
    for (k, target) in order.into_iter().enumerate() {
        let wait = Duration::from_millis(300 + rng.next() % 1200);
        on_origin.resume();
        on_mirror.resume();
        watch(&mut hosts, wait);
        let (h, stale_after, resync) = p.kill_and_restart(target, hosts);
        hosts = h;
        let (oo, of) = on_origin.pause();
        let (mo, mf) = on_mirror.pause();
        let (ao, am) = (oo - before.0, mo - before.2);
        if target == "bridge" {
            // None lost: a batch the killed bridge took but never answered is sent again.
            every_acknowledged_deposit_applied(&mut hosts, applied_before + ao + am);
        }
        let applied = applied_now(&mut hosts);
        let failed = (of - before.1) + (mf - before.3);
        // Applied in this phase: the origin's count went on, or a new run started from 0.
        let phase = if target == "origin" {
            applied
        } else {
            applied - applied_before
        };
        assert!(
            phase <= ao + am + failed,
            "kill {k} ({target}): {phase} applied, more than the {} acknowledged and {failed} \
             unacknowledged deposits made: one was applied twice",
            ao + am
        );
        let stale = stale_after.map_or(String::new(), |s| format!("stale {s:.2} s after it; "));
        let fate = if target == "origin" {
            " by the restarted origin (the killed run's field is gone with it)".to_string()
        } else {
            format!(
                ", acknowledged but not applied {}",
                (ao + am).saturating_sub(phase)
            )
        };
        println!(
            "kill {k}: {target} after {:.2} s; {stale}resync {resync:.2} s after the restart; \
             deposits acknowledged {} (origin host {ao}, mirror host {am}), failed {failed}, \
             applied {phase}{fate}",
            wait.as_secs_f64(),
            ao + am
        );
        (before, applied_before) = ((oo, of, mo, mf), applied);
    }
    drop((on_origin, on_mirror));
    let j = super::mirror_exit(p.mirror);
    assert_eq!(j["mirror"]["checksum_mismatches"], 0, "{j}");
    println!(
        "the last mirror run sent {} deposit batch(es) again",
        j["mirror"]["deposit_batches_resent"]
    );
}
