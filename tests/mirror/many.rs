//! Three mirrors of one origin, each in a network namespace of its own (four "hosts": the
//! origin's namespace holds the bridge, joined to each mirror's by a veth pair), each mirror in
//! its own iceoryx2 domain. Every host has a local reader (this process) and a local depositor
//! (`pheromone deposit` run in that host's namespace and domain) depositing during the run.
//! Needs root (`ip netns`); elsewhere the test says why and passes without running.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use pheromone_bridge::codec;
use pheromone_field::shm::{create_node_in, FieldReader};
use pheromone_supervisor::ChildSpec;

use super::netns::ip;
use super::{origin_field, CleanDomains, MIRROR, ORIGIN};
use crate::harness::*;

/// The mirrors' iceoryx2 domains (fixed names, as [`ORIGIN`] and [`MIRROR`]).
const MIRRORS: [&str; 3] = [MIRROR, "mirtestC", "mirtestD"];

/// Removes what dead processes left in the extra domains (declared first, dropped last).
struct CleanExtra;

impl Drop for CleanExtra {
    fn drop(&mut self) {
        for d in &MIRRORS[1..] {
            pheromone_field::shm::cleanup_dead_nodes_of(
                &pheromone_field::shm::domain_config_of(Some(d)).unwrap(),
            );
        }
    }
}

/// The origin's namespace and one namespace per mirror, each joined to the origin's by a veth
/// pair (169.254.8i.1 on the origin's side, .2 on the mirror's); deleted when dropped.
struct Star {
    origin: String,
    mirrors: Vec<String>,
}

impl Star {
    fn make(tag: &str, n: usize) -> Result<Self, String> {
        let origin = format!("{tag}O");
        ip(&["netns", "add", &origin])?;
        let mut star = Self {
            origin,
            mirrors: Vec::new(),
        };
        ip(&["-n", &star.origin, "link", "set", "lo", "up"])?;
        for i in 0..n {
            let ns = format!("{tag}M{i}");
            ip(&["netns", "add", &ns])?;
            star.mirrors.push(ns.clone());
            let (vo, vm) = (format!("{tag}o{i}"), format!("{tag}m{i}"));
            ip(&["link", "add", &vo, "type", "veth", "peer", "name", &vm])?;
            ip(&["link", "set", &vo, "netns", &star.origin])?;
            ip(&["link", "set", &vm, "netns", &ns])?;
            for (side, dev, host) in [(&star.origin, &vo, 1), (&ns, &vm, 2)] {
                let addr = format!("169.254.{}.{host}/30", 80 + i);
                ip(&["-n", side, "addr", "add", &addr, "dev", dev])?;
                ip(&["-n", side, "link", "set", dev, "up"])?;
            }
            ip(&["-n", &ns, "link", "set", "lo", "up"])?;
        }
        Ok(star)
    }
}

impl Drop for Star {
    fn drop(&mut self) {
        for ns in self.mirrors.iter().chain([&self.origin]) {
            let _ = ip(&["netns", "del", ns]);
        }
    }
}

/// `pheromone ARGS` in namespace `ns`, in the background.
fn spawn_in(ns: &str, role: &str, args: &[&str]) -> Proc {
    let bin = bin();
    let mut all = vec!["netns", "exec", ns, bin.to_str().unwrap()];
    all.extend_from_slice(args);
    Proc::start(
        Path::new("ip"),
        ChildSpec::new(role, None, all.iter().map(|s| s.to_string()).collect()),
    )
}

/// Deposits on one host (`pheromone deposit` in namespace `ns`, or in this one) from a thread
/// of its own until stopped; the thread returns how many were acknowledged.
fn depositor(
    ns: Option<String>,
    domain: &'static str,
    name: &str,
    row: f32,
    stop: Arc<AtomicBool>,
) -> std::thread::JoinHandle<u64> {
    let name = name.to_string();
    std::thread::spawn(move || {
        let mut sent = 0u64;
        while !stop.load(Ordering::SeqCst) {
            let x = format!("{:.1}", 0.5 + (sent % 11) as f32 * 0.5);
            let args = Cmd::new("deposit")
                .opt("--iox-domain", domain)
                .opt("--field", &name)
                .at(&x, format!("{row:.1}"))
                .amount(2)
                .opt("--cov", "0.02,0,0.02")
                .timeout(20)
                .into_args();
            let out = match &ns {
                Some(ns) => Command::new("ip")
                    .args(["netns", "exec", ns, bin().to_str().unwrap()])
                    .args(&args)
                    .output()
                    .unwrap(),
                None => Command::new(bin()).args(&args).output().unwrap(),
            };
            assert!(
                out.status.success(),
                "deposit in {domain}: {}",
                stderr(&out)
            );
            sent += 1;
        }
        sent
    })
}

/// A reader on one host and every (sequence → checksum of the cells, deposits applied) it saw.
struct Host {
    reader: FieldReader,
    seen: BTreeMap<u64, (u64, u64)>,
    _node: iceoryx2::node::Node<pheromone_field::shm::Svc>,
}

impl Host {
    fn attach(domain: &str, name: &str) -> Self {
        let node = create_node_in(&unique("mirmany-r"), Some(domain)).unwrap();
        let reader = FieldReader::attach_within(&node, name, Duration::from_secs(30))
            .unwrap_or_else(|e| panic!("a field in {domain}: {e}"));
        Self {
            reader,
            seen: BTreeMap::new(),
            _node: node,
        }
    }

    /// Takes the newest frame (if any) into `seen`.
    fn record(&mut self) {
        self.reader.update().unwrap();
        if let Some(s) = self.reader.sample() {
            let h = s.user_header();
            self.seen.insert(
                h.sequence,
                (codec::frame_checksum(s.payload()), h.deposits_applied),
            );
        }
    }

    /// The newest recorded frame: (sequence, deposits applied).
    fn newest(&self) -> Option<(u64, u64)> {
        self.seen.iter().next_back().map(|(s, (_, a))| (*s, *a))
    }
}

/// Records every host's frames (the origin's woken by its frames, the mirrors' polled) until
/// `done` holds, at most `timeout`.
fn record_until(hosts: &mut [Host], timeout: Duration, what: &str, done: impl Fn(&[Host]) -> bool) {
    let deadline = Instant::now() + timeout;
    loop {
        hosts[0]
            .reader
            .wait_frame(Duration::from_millis(10))
            .unwrap();
        for h in hosts.iter_mut() {
            h.record();
        }
        if done(hosts) {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "{what} within {timeout:?} (newest: {:?})",
            hosts.iter().map(Host::newest).collect::<Vec<_>>()
        );
    }
}

/// Every sequence seen both on the origin and on mirror `i` has the same cells and the same
/// deposits-applied count; returns how many were compared.
fn agree(hosts: &[Host], i: usize) -> usize {
    let mut n = 0;
    for (seq, m) in &hosts[i].seen {
        if let Some(o) = hosts[0].seen.get(seq) {
            assert_eq!(
                o, m,
                "frame {seq}: origin (checksum, applied) {o:x?}, mirror {i} {m:x?}"
            );
            n += 1;
        }
    }
    n
}

/// A mirror of `name` in each mirror namespace, in its own domain, connecting to the bridge.
fn start_mirrors(star: &Star, name: &str) -> Vec<Proc> {
    (0..3)
        .map(|i| {
            let endpoint = format!("zenoh:tcp/169.254.{}.1:7447", 80 + i);
            spawn_in(
                &star.mirrors[i],
                "mirror",
                &Cmd::new("field")
                    .opt("--iox-domain", MIRRORS[i])
                    .opt("--name", name)
                    .opt("--mirror", &endpoint)
                    .opt("--stale-after-s", 0.5)
                    .duration(120)
                    .json()
                    .argv(),
            )
        })
        .collect()
}

/// Each mirror forwarded its host's deposits, the bridge all of them, no checksum differed.
fn check_exits(mirrors: Vec<Proc>, bridge: Proc, sent: &[u64]) {
    for (i, m) in mirrors.into_iter().enumerate() {
        let j = super::mirror_exit(m);
        let s = &j["mirror"];
        assert_eq!(s["checksum_mismatches"], 0, "mirror {i}: {s}");
        assert_eq!(s["deposits_forwarded"], sent[i + 1], "mirror {i}: {s}");
        assert_eq!(s["deposits_confirmed"], sent[i + 1], "mirror {i}: {s}");
    }
    bridge.interrupt();
    let b = json(&bridge.wait_exit(Duration::from_secs(20)));
    assert_eq!(
        b["bridge"]["deposits_forwarded"],
        sent[1..].iter().sum::<u64>(),
        "{b}"
    );
}

#[test]
fn three_mirrors_with_local_depositors_all_see_one_order_of_deposits() {
    let _clean = CleanDomains;
    let _extra = CleanExtra;
    let tag = format!("m3{}", std::process::id() % 100_000);
    let star = match Star::make(&tag, 3) {
        Ok(s) => s,
        Err(why) => {
            eprintln!("skipped: network namespaces cannot be made here ({why})");
            return;
        }
    };
    let name = unique("mirmany");
    let _field = origin_field(&name);
    let bridge = spawn_in(
        &star.origin,
        "bridge",
        &super::bridge_args(&name, "tcp/0.0.0.0:7447"),
    );
    let started = Instant::now();
    let mirrors = start_mirrors(&star, &name);
    let mut hosts = vec![Host::attach(ORIGIN, &name)];
    hosts.extend(MIRRORS.iter().map(|d| Host::attach(d, &name)));
    // Each mirror showed 5 frames the origin showed too.
    record_until(
        &mut hosts,
        Duration::from_secs(30),
        "three live mirrors",
        |h| (1..4).all(|i| agree(h, i) >= 5),
    );
    let live = started.elapsed();

    // A depositor on each host for 3 s.
    let stop = Arc::new(AtomicBool::new(false));
    let workers: Vec<_> = (0..4)
        .map(|h| {
            let (ns, domain) = if h == 0 {
                (None, ORIGIN)
            } else {
                (Some(star.mirrors[h - 1].clone()), MIRRORS[h - 1])
            };
            depositor(ns, domain, &name, 1.0 + h as f32, stop.clone())
        })
        .collect();
    let t0 = Instant::now();
    record_until(
        &mut hosts,
        Duration::from_secs(10),
        "3 s of deposits",
        |_| t0.elapsed() >= Duration::from_secs(3),
    );
    stop.store(true, Ordering::SeqCst);
    let sent: Vec<u64> = workers.into_iter().map(|w| w.join().unwrap()).collect();
    let total: u64 = sent.iter().sum();
    let stopped = Instant::now();

    // The origin applies each deposit once; every mirror reaches a frame with all of them.
    record_until(
        &mut hosts,
        Duration::from_secs(30),
        "every deposit applied on every host",
        |h| {
            h.iter()
                .all(|x| x.newest().is_some_and(|(_, a)| a >= total))
        },
    );
    let settled = stopped.elapsed();
    let last = hosts[0].newest().unwrap().0;
    record_until(
        &mut hosts,
        Duration::from_secs(30),
        "5 more common frames",
        |h| {
            (1..4).all(|i| {
                h[i].seen
                    .range(last..)
                    .filter(|(s, _)| h[0].seen.contains_key(s))
                    .count()
                    >= 5
            })
        },
    );
    let compared: Vec<usize> = (1..4).map(|i| agree(&hosts, i)).collect();
    let applied = hosts[0].newest().unwrap().1;
    assert_eq!(
        applied, total,
        "deposits sent {sent:?}, applied on the origin {applied}"
    );
    println!(
        "three mirrors: live {:.2} s after start; deposits sent per host (origin, m1, m2, m3) \
         {sent:?} = {total}, applied on the origin {applied}; every host at {total} applied \
         {:.2} s after the deposits stopped; frames compared per mirror {compared:?}, all equal",
        live.as_secs_f64(),
        settled.as_secs_f64()
    );
    drop(hosts);
    check_exits(mirrors, bridge, &sent);
}
