//! A mirror on another "host": network namespaces made by the test, linked by a veth pair with
//! link-local addresses, the bridge in one and the mirror in the other (each in its own
//! iceoryx2 domain; namespaces share `/dev/shm`). A partition is the link taken down and up.
//! Needs root (`ip netns`); where namespaces cannot be made the test says so and passes
//! without running (CI runs as root).

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use pheromone_field::shm::{create_node_in, mirror_info};
use pheromone_supervisor::ChildSpec;

use super::{assert_identical, deposit, origin_field, CleanDomains, Hosts, MIRROR, ORIGIN};
use crate::harness::*;

/// Two namespaces and the veth pair between them; deleted when dropped (which removes the
/// pair too).
pub(super) struct Link {
    pub(super) a: String,
    pub(super) b: String,
    /// The veth end in `a`.
    dev_a: String,
}

pub(super) const ADDR_A: &str = "169.254.77.1";
pub(super) const ADDR_B: &str = "169.254.77.2";

pub(super) fn ip(args: &[&str]) -> Result<(), String> {
    let o = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("ip {}: {e}", args.join(" ")))?;
    if o.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&o.stderr).trim()
        ))
    }
}

impl Link {
    /// `None` (with the reason) where namespaces cannot be made here.
    pub(super) fn make(tag: &str) -> Result<Self, String> {
        let (va, vb) = (format!("{tag}a"), format!("{tag}b"));
        let (a, b) = (format!("{tag}A"), format!("{tag}B"));
        ip(&["netns", "add", &a])?;
        let link = Self {
            a,
            b,
            dev_a: va.clone(),
        };
        ip(&["netns", "add", &link.b])?;
        ip(&["link", "add", &va, "type", "veth", "peer", "name", &vb])?;
        ip(&["link", "set", &va, "netns", &link.a])?;
        ip(&["link", "set", &vb, "netns", &link.b])?;
        for (ns, dev, addr) in [(&link.a, &va, ADDR_A), (&link.b, &vb, ADDR_B)] {
            ip(&["-n", ns, "addr", "add", &format!("{addr}/30"), "dev", dev])?;
            ip(&["-n", ns, "link", "set", dev, "up"])?;
            ip(&["-n", ns, "link", "set", "lo", "up"])?;
        }
        Ok(link)
    }

    /// Takes the A side of the link down (`up = false`) or up.
    fn set(&self, up: bool) {
        let state = if up { "up" } else { "down" };
        ip(&["-n", &self.a, "link", "set", &self.dev_a, state]).unwrap();
    }

    /// `pheromone ARGS` inside namespace `ns`.
    pub(super) fn spawn_in(&self, ns: &str, role: &str, args: &[&str]) -> Proc {
        let bin = bin();
        let mut all = vec!["netns", "exec", ns, bin.to_str().unwrap()];
        all.extend_from_slice(args);
        Proc::start(
            Path::new("ip"),
            ChildSpec::new(role, None, all.iter().map(|s| s.to_string()).collect()),
        )
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        let _ = ip(&["netns", "del", &self.a]);
        let _ = ip(&["netns", "del", &self.b]);
    }
}

/// Waits (at most `timeout`) until the mirror says it is stale (`true`) or live.
pub(super) fn until_mirror(
    node: &iceoryx2::node::Node<pheromone_field::shm::Svc>,
    name: &str,
    stale: bool,
) {
    eventually(
        Duration::from_secs(30),
        if stale {
            "the mirror to go stale"
        } else {
            "the mirror to be live"
        },
        || {
            let m = mirror_info(node, name).unwrap()?;
            if m.stale == stale {
                Some(())
            } else {
                // The mirror updates its state every round (20 ms).
                let _ = pheromone_field::shm::node_wait(node, Duration::from_millis(20));
                None
            }
        },
    );
}

#[test]
fn a_partitioned_mirror_is_stale_meanwhile_and_bit_identical_again_after_the_link_heals() {
    let _clean = CleanDomains;
    let tag = format!("ph{}", std::process::id() % 100_000);
    let link = match Link::make(&tag) {
        Ok(l) => l,
        Err(why) => {
            eprintln!("skipped: network namespaces cannot be made here ({why})");
            return;
        }
    };
    let name = unique("mirns");
    let _field = origin_field(&name);
    let endpoint = format!("tcp/{ADDR_A}:7447");
    let _bridge = link.spawn_in(&link.a, "bridge", &super::bridge_args(&name, &endpoint));
    let mirror = link.spawn_in(
        &link.b,
        "mirror",
        &[
            "field",
            "--iox-domain",
            MIRROR,
            "--name",
            &name,
            "--mirror",
            &format!("zenoh:{endpoint}"),
            "--stale-after-s",
            "0.5",
            "--duration",
            "120",
            "--json",
        ],
    );
    let mut hosts = Hosts::attach(&name);
    assert_identical(&hosts.common(10, |_| true));
    let node = create_node_in(&unique("mirns-watch"), Some(MIRROR)).unwrap();
    until_mirror(&node, &name, false);

    // A 5 s partition, with a deposit on the origin meanwhile.
    link.set(false);
    let cut = Instant::now();
    until_mirror(&node, &name, true);
    let stale_after = cut.elapsed();
    deposit(ORIGIN, &name, "3.2", "3.2");
    let during = hosts.origin_sequence();
    let _ = pheromone_field::shm::node_wait(
        &node,
        Duration::from_secs(5).saturating_sub(cut.elapsed()),
    );
    link.set(true);
    let healed = Instant::now();
    // Bit-identical again, with the partition's deposit, on frames newer than the partition.
    let both = hosts.common(5, |f| {
        f.header.sequence > during && super::value_at(f, 3.2, 3.2) > 0.1
    });
    let resync = healed.elapsed();
    assert_identical(&both);
    until_mirror(&node, &name, false);
    println!(
        "partition of {:.1} s: stale after {:.2} s, bit-identical again {:.2} s after the link came back",
        (healed - cut).as_secs_f64(),
        stale_after.as_secs_f64(),
        resync.as_secs_f64()
    );
    let j = super::mirror_exit(mirror);
    let s = &j["mirror"];
    assert!(s["stale_periods"].as_u64().unwrap() >= 1, "{s}");
    assert_eq!(s["checksum_mismatches"], 0, "{s}");
}

/// Two deposits made on the mirror's host while the link is down for longer than Zenoh's lease
/// (10 s: the session to the bridge is closed meanwhile) each reach the origin once, after the
/// link heals: one made just after the cut, which the mirror, not yet stale, puts on a session
/// that then dies (so it is lost unless sent again), and one made 11 s in, which the stale
/// mirror holds. The bridge passes exactly two deposits to the field, and the mirror shows both.
#[test]
fn deposits_made_on_a_partitioned_mirror_are_applied_once_after_the_link_heals() {
    let _clean = CleanDomains;
    let tag = format!("pd{}", std::process::id() % 100_000);
    let link = match Link::make(&tag) {
        Ok(l) => l,
        Err(why) => {
            eprintln!("skipped: network namespaces cannot be made here ({why})");
            return;
        }
    };
    let name = unique("mirdep");
    let _field = origin_field(&name);
    let endpoint = format!("tcp/{ADDR_A}:7447");
    let bridge = link.spawn_in(&link.a, "bridge", &super::bridge_args(&name, &endpoint));
    // Stale only 3 s after the cut: the first deposit surely comes while the mirror still
    // sends.
    let mirror = link.spawn_in(
        &link.b,
        "mirror",
        &[
            "field",
            "--iox-domain",
            MIRROR,
            "--name",
            &name,
            "--mirror",
            &format!("zenoh:{endpoint}"),
            "--stale-after-s",
            "3",
            "--duration",
            "120",
            "--json",
        ],
    );
    let mut hosts = Hosts::attach(&name);
    assert_identical(&hosts.common(5, |_| true));
    let node = create_node_in(&unique("mirdep-watch"), Some(MIRROR)).unwrap();
    until_mirror(&node, &name, false);
    link.set(false);
    let cut = Instant::now();
    deposit_on_mirror_host(&link, &name, "2.0");
    let early = cut.elapsed();
    until_mirror(&node, &name, true);
    assert!(
        early < Duration::from_secs(3),
        "the first deposit came {early:?} after the cut, when the mirror may be stale"
    );
    // Past the lease: the mirror's session has dropped the bridge.
    let _ = pheromone_field::shm::node_wait(
        &node,
        Duration::from_secs(11).saturating_sub(cut.elapsed()),
    );
    deposit_on_mirror_host(&link, &name, "4.0");
    let _ = pheromone_field::shm::node_wait(
        &node,
        Duration::from_secs(12).saturating_sub(cut.elapsed()),
    );
    link.set(true);
    let healed = Instant::now();
    let both = hosts.common(5, |f| {
        super::value_at(f, 4.0, 4.0) > 0.1 && super::value_at(f, 2.0, 2.0) > 0.1
    });
    assert_identical(&both);
    println!(
        "deposits made {:.2} s and 11 s into a {:.1} s partition: on the mirror {:.2} s after \
         the link came back",
        early.as_secs_f64(),
        (healed - cut).as_secs_f64(),
        healed.elapsed().as_secs_f64()
    );
    let m = super::mirror_exit(mirror);
    bridge.interrupt();
    let b = json(&bridge.wait_exit(Duration::from_secs(20)));
    assert_eq!(m["mirror"]["deposits_forwarded"], 2, "{m}");
    assert_eq!(m["mirror"]["deposits_confirmed"], 2, "{m}");
    // The first went out before the cut was noticed and was lost with the session.
    assert!(
        m["mirror"]["deposit_batches_resent"].as_u64().unwrap() >= 1,
        "{m}"
    );
    assert_eq!(b["bridge"]["deposits_forwarded"], 2, "{b}");
}

/// A deposit at (`x`, `x`) made on the mirror's host, in its namespace (iceoryx2's wake-ups do
/// not cross network namespaces: from outside, the receipt would come only when the client's
/// wait times out).
fn deposit_on_mirror_host(link: &Link, name: &str, x: &str) {
    let args = Cmd::new("deposit")
        .opt("--iox-domain", MIRROR)
        .opt("--field", name)
        .at(x, x)
        .amount(2)
        .opt("--cov", "0.02,0,0.02")
        .timeout(20)
        .into_args();
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let out = link
        .spawn_in(&link.b, "deposit", &args)
        .wait_exit(Duration::from_secs(20));
    let said = stderr(&out);
    assert!(
        out.status.success() && said.contains("forwarded to its origin"),
        "{said}"
    );
}
