//! Field mirrors over Zenoh (feature `zenoh`): a mirror's frames equal its origin's.
//!
//! Field mirrors over Zenoh (feature `zenoh`): two iceoryx2 domains stand for two hosts, a
//! bridge and a mirror link them over loopback TCP. Frames are compared by XXH3-64 of their
//! cells for the same sequence number, read from both domains by this process.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use pheromone_bridge::codec;
use pheromone_bridge::zenoh::{self, Wait};
use pheromone_field::shm::{create_node_in, FieldReader};
use pheromone_supervisor::{ChildId, ChildSpec, Supervisor};

use super::harness::*;

mod faults;
mod kills;
mod many;
mod netns;
mod secure;
mod wire;

/// The two "hosts" (fixed names: iceoryx2 keeps one management segment per domain prefix).
const ORIGIN: &str = "mirtestA";
const MIRROR: &str = "mirtestB";

/// A `pheromone bridge` process (stopped when dropped) and the endpoint it listens on.
struct BridgeProc {
    sup: Supervisor,
    id: ChildId,
    endpoint: String,
}

impl BridgeProc {
    fn kill(&self) {
        self.sup.signal(self.id, nix::sys::signal::Signal::SIGKILL);
    }

    /// Its `--json` summary after Ctrl-C.
    fn exit_json(mut self) -> serde_json::Value {
        self.sup.signal(self.id, nix::sys::signal::Signal::SIGINT);
        assert!(
            self.sup.wait_exit(self.id, Duration::from_secs(20)),
            "the bridge exits"
        );
        let (out, err) = self.sup.output(self.id);
        serde_json::from_str(out.lines().last().unwrap_or_default())
            .unwrap_or_else(|e| panic!("the bridge's summary: {e}: {out} {err}"))
    }
}

fn origin_field(name: &str) -> Proc {
    origin_field_of(name, 64)
}

/// An origin field of `side` × `side` cells of 0.1 m.
fn origin_field_of(name: &str, side: u32) -> Proc {
    Proc::spawn(
        &Cmd::new("field")
            .opt("--iox-domain", ORIGIN)
            .opt("--name", name)
            .grid(side, side)
            .cell_size(0.1)
            .model("exponential")
            .opt("--decay-per-s", 0.2)
            .tick_hz(50)
            .duration(120)
            .argv(),
    )
}

/// A bridge on a loopback port the system picks (`--print-address` tells which).
fn bridge(name: &str) -> BridgeProc {
    bridge_on(name, "tcp/127.0.0.1:0")
}

/// The command line of the tests' bridges: field `name` of the origin domain, on `listen`.
fn bridge_args<'a>(name: &'a str, listen: &'a str) -> [&'a str; 14] {
    [
        "bridge",
        "--iox-domain",
        ORIGIN,
        "--field",
        name,
        "--listen",
        listen,
        "--checksum-every",
        "5",
        "--keyframe-every-s",
        "2",
        "--duration",
        "120",
        "--json",
    ]
}

/// A bridge listening on `listen`; waits for the endpoint it prints.
fn bridge_on(name: &str, listen: &str) -> BridgeProc {
    bridge_with(name, listen, &[])
}

/// As [`bridge_on`], with `extra` flags.
fn bridge_with(name: &str, listen: &str, extra: &[&str]) -> BridgeProc {
    let mut args = bridge_args(name, listen).to_vec();
    args.push("--print-address");
    args.extend_from_slice(extra);
    let mut sup = Supervisor::new(&bin());
    let id = sup
        .spawn(ChildSpec::new(
            "bridge",
            None,
            args.iter().map(|a| a.to_string()).collect(),
        ))
        .expect("spawn the bridge");
    let endpoint = sup
        .next_line(id, Duration::from_secs(30))
        .expect("the bridge runs")
        .expect("the bridge prints its endpoint within 30 s")
        .trim()
        .to_string();
    assert!(
        endpoint.starts_with("tcp/127.0.0.1:") && !endpoint.ends_with(":0"),
        "{endpoint}"
    );
    BridgeProc { sup, id, endpoint }
}

fn mirror(name: &str, endpoint: &str) -> Proc {
    mirror_with(name, endpoint, &[])
}

/// As [`mirror`], with `extra` flags.
fn mirror_with(name: &str, endpoint: &str, extra: &[&str]) -> Proc {
    Proc::spawn(
        &Cmd::new("field")
            .opt("--iox-domain", MIRROR)
            .opt("--name", name)
            .opt("--mirror", format!("zenoh:{endpoint}"))
            .opt("--stale-after-s", 0.5)
            .duration(120)
            .json()
            .args(extra)
            .argv(),
    )
}

struct Hosts {
    origin: FieldReader,
    mirror: FieldReader,
    // Dropped after the readers (declaration order).
    _nodes: (
        iceoryx2::node::Node<pheromone_field::shm::Svc>,
        iceoryx2::node::Node<pheromone_field::shm::Svc>,
    ),
}

/// Declared first in every test, so dropped last, once every process of the test has exited:
/// removes what killed processes left in either domain (the SIGKILLed bridge, or a process that
/// outlived its SIGTERM grace on drop). In the default domain the next process's node creation
/// does that; these two domains may see no other process after the last test.
struct CleanDomains;

impl Drop for CleanDomains {
    fn drop(&mut self) {
        for d in [ORIGIN, MIRROR] {
            pheromone_field::shm::cleanup_dead_nodes_of(
                &pheromone_field::shm::domain_config_of(Some(d)).unwrap(),
            );
        }
    }
}

impl Hosts {
    fn attach(name: &str) -> Self {
        let on = create_node_in(&unique("mirtest-ro"), Some(ORIGIN)).unwrap();
        let mn = create_node_in(&unique("mirtest-rm"), Some(MIRROR)).unwrap();
        let origin = FieldReader::attach_within(&on, name, Duration::from_secs(20)).unwrap();
        let mirror = FieldReader::attach_within(&mn, name, Duration::from_secs(30))
            .expect("the mirror publishes its first frame (from a keyframe)");
        Self {
            origin,
            mirror,
            _nodes: (on, mn),
        }
    }

    /// The origin's newest sequence now.
    fn origin_sequence(&mut self) -> u64 {
        self.origin.update().unwrap();
        self.origin.frame().map_or(0, |f| f.header.sequence)
    }

    /// Records (sequence → checksum) on both hosts until `common` sequences were seen on both
    /// (after `pred` held on the mirror's frame); returns the common ones.
    fn common(
        &mut self,
        common: usize,
        pred: impl Fn(&pheromone_field::shm::Frame<'_>) -> bool,
    ) -> Vec<(u64, u64, u64)> {
        let mut o = BTreeMap::new();
        let mut m = BTreeMap::new();
        let deadline = Instant::now() + Duration::from_secs(30);
        let mut ready = false;
        loop {
            self.origin.wait_frame(Duration::from_millis(20)).unwrap();
            self.mirror.update().unwrap();
            for (r, map) in [(&self.origin, &mut o), (&self.mirror, &mut m)] {
                if let Some(s) = r.sample() {
                    map.insert(s.user_header().sequence, codec::frame_checksum(s.payload()));
                }
            }
            ready |= self.mirror.frame().as_ref().is_some_and(&pred);
            let both: Vec<_> = m
                .iter()
                .filter_map(|(seq, ms)| o.get(seq).map(|os| (*seq, *os, *ms)))
                .collect();
            if ready && both.len() >= common {
                return both;
            }
            assert!(
                Instant::now() < deadline,
                "only {} common frames in 30 s (origin {:?}…, mirror {:?}…, condition {ready})",
                both.len(),
                o.keys().last(),
                m.keys().last()
            );
            if !ready {
                o.clear();
                m.clear();
            }
        }
    }
}

fn assert_identical(both: &[(u64, u64, u64)]) {
    for (seq, o, m) in both {
        assert_eq!(
            o, m,
            "frame {seq}: origin checksum {o:016x}, mirror {m:016x}"
        );
    }
}

fn value_at(f: &pheromone_field::shm::Frame<'_>, x: f32, y: f32) -> f32 {
    f.view.value(0, x, y)
}

fn deposit(domain: &str, name: &str, x: &str, y: &str) {
    let out = run(&Cmd::new("deposit")
        .opt("--iox-domain", domain)
        .opt("--field", name)
        .at(x, y)
        .amount(2)
        .opt("--cov", "0.02,0,0.02")
        .timeout(20)
        .argv());
    assert!(out.status.success(), "deposit failed: {}", stderr(&out));
}

fn mirror_summary(m: Proc) -> serde_json::Value {
    mirror_exit(m)["mirror"].clone()
}

/// The mirror's whole `--json` summary (`stale`, `mirror`) after Ctrl-C; every keyframe it
/// published answered one of its requests (none is counted twice).
fn mirror_exit(m: Proc) -> serde_json::Value {
    m.interrupt();
    let out = m.wait_exit(Duration::from_secs(20));
    let j = json(&out);
    let s = &j["mirror"];
    assert!(
        s["keyframes_applied"].as_u64().unwrap() <= s["keyframe_requests"].as_u64().unwrap(),
        "{s}"
    );
    j
}

/// Waits (at most 20 s) until the mirror has published no frame for `quiet`.
fn until_quiet(r: &mut FieldReader, quiet: Duration) {
    let deadline = Instant::now() + Duration::from_secs(20);
    while r
        .wait_frame_with(pheromone_field::shm::WaitPolicy::Event, quiet)
        .unwrap()
    {
        assert!(
            Instant::now() < deadline,
            "the mirror kept publishing frames for 20 s after its origin stopped (at {:?})",
            r.frame().map(|f| f.header.sequence)
        );
    }
}

#[test]
fn a_mirror_shows_bit_identical_frames_and_deposits_go_both_ways() {
    let _clean = CleanDomains;
    let name = unique("mir1");
    let _field = origin_field(&name);
    let bridge = bridge(&name);
    let m = mirror(&name, &bridge.endpoint);
    let mut hosts = Hosts::attach(&name);
    assert_identical(&hosts.common(30, |_| true));
    // A deposit made on the mirror's host goes to the origin and comes back in its inputs.
    deposit(MIRROR, &name, "2.0", "3.0");
    let both = hosts.common(20, |f| value_at(f, 2.0, 3.0) > 0.1);
    assert_identical(&both);
    let o = hosts.origin.frame().unwrap();
    assert!(
        value_at(&o, 2.0, 3.0) > 0.1,
        "the origin never saw the mirror host's deposit"
    );
    // And one made on the origin's host reaches the mirror.
    deposit(ORIGIN, &name, "4.5", "1.5");
    assert_identical(&hosts.common(20, |f| value_at(f, 4.5, 1.5) > 0.1));
    let j = mirror_exit(m);
    let s = &j["mirror"];
    assert!(s["checksums_matched"].as_u64().unwrap() >= 5, "{s}");
    assert_eq!(s["checksum_mismatches"], 0, "{s}");
    assert_eq!(s["deposits_forwarded"], 1, "{s}");
    assert_eq!(s["deposits_confirmed"], 1, "{s}");
    assert_eq!(s["deposits_unconfirmed"], 0, "{s}");
    assert_eq!(j["stale"], false, "{j}");
}

#[test]
fn a_mirror_follows_its_origin_restarted_with_another_grid_and_stays_stale_meanwhile() {
    let _clean = CleanDomains;
    let name = unique("mir4");
    let field = origin_field_of(&name, 64);
    let bridge = bridge(&name);
    let m = mirror(&name, &bridge.endpoint);
    let mut hosts = Hosts::attach(&name);
    assert_identical(&hosts.common(10, |f| f.header.width == 64));
    // The origin stops; the bridge stays. The mirror goes stale and publishes nothing (no
    // keyframe of the dead run), through several keyframe requests (every 0.2 s).
    field.interrupt();
    field.wait_exit(Duration::from_secs(20));
    until_quiet(&mut hosts.mirror, Duration::from_secs(2));
    // It starts again on a 96 × 96 grid: the mirror takes the new configuration.
    let _field2 = origin_field_of(&name, 96);
    hosts
        .origin
        .wait_until(Duration::from_secs(20), |f| f.header.width == 96)
        .unwrap()
        .expect("the restarted origin publishes its 96 x 96 frames");
    // A deposit outside the old grid (9 m > 6.4 m).
    deposit(ORIGIN, &name, "9.0", "8.5");
    let both = hosts.common(20, |f| {
        f.header.width == 96 && f.header.height == 96 && value_at(f, 9.0, 8.5) > 0.1
    });
    assert_identical(&both);
    let j = mirror_exit(m);
    let s = &j["mirror"];
    assert!(s["epochs"].as_u64().unwrap() >= 2, "{s}");
    assert_eq!(s["stale_periods"], 1, "{s}");
    assert_eq!(s["checksum_mismatches"], 0, "{s}");
    assert!(s["checksums_matched"].as_u64().unwrap() >= 1, "{s}");
    assert_eq!(j["stale"], false, "{j}");
}

#[test]
fn a_mirror_survives_a_killed_bridge_and_a_restarted_origin() {
    let _clean = CleanDomains;
    let name = unique("mir2");
    let field = origin_field(&name);
    let b = bridge(&name);
    let m = mirror(&name, &b.endpoint);
    let mut hosts = Hosts::attach(&name);
    assert_identical(&hosts.common(20, |_| true));
    // SIGKILL the bridge; the origin goes on (and takes a deposit) while the mirror is cut off.
    b.kill();
    let endpoint = b.endpoint.clone();
    drop(b);
    deposit(ORIGIN, &name, "1.0", "1.0");
    // Restarted on the same port (the mirror reconnects to it).
    let _b2 = bridge_on(&name, &endpoint);
    let both = hosts.common(20, |f| value_at(f, 1.0, 1.0) > 0.1);
    assert_identical(&both);
    // The origin stops and starts again: its sequence starts from 0 in a new epoch.
    field.interrupt();
    field.wait_exit(Duration::from_secs(20));
    let last = hosts.mirror.frame().unwrap().header.sequence;
    let _field2 = origin_field(&name);
    // The restarted field publishes to the services the reader holds.
    hosts
        .origin
        .wait_until(Duration::from_secs(20), |f| f.header.sequence < last)
        .unwrap()
        .expect("the restarted origin publishes");
    deposit(ORIGIN, &name, "5.0", "5.0");
    let both = hosts.common(20, |f| {
        value_at(f, 5.0, 5.0) > 0.1 && value_at(f, 1.0, 1.0) == 0.0
    });
    assert_identical(&both);
    assert!(
        both[0].0 < last,
        "the restarted origin's frames ({}) follow the old ones ({last})",
        both[0].0
    );
    let s = mirror_summary(m);
    assert!(s["keyframes_applied"].as_u64().unwrap() >= 2, "{s}");
    assert!(s["epochs"].as_u64().unwrap() >= 2, "{s}");
    // It noticed the cut (a gap in the sequence, or silence if the restart took long).
    let noticed = s["gaps"].as_u64().unwrap() + s["stale_periods"].as_u64().unwrap();
    assert!(noticed >= 1, "{s}");
}

#[test]
fn corrupted_lists_and_keyframes_are_rejected_and_counted() {
    let _clean = CleanDomains;
    let name = unique("mir3");
    let _field = origin_field(&name);
    let bridge = bridge(&name);
    let m = mirror(&name, &bridge.endpoint);
    let mut hosts = Hosts::attach(&name);
    assert_identical(&hosts.common(10, |_| true));
    // A third peer puts damaged messages on the mirror's keys.
    let session = zenoh::open(
        pheromone_bridge::session_config_as("client", &[], std::slice::from_ref(&bridge.endpoint))
            .unwrap(),
    )
    .wait()
    .unwrap();
    let keys = pheromone_bridge::Keys::of(&name);
    let seq = hosts.origin.frame().unwrap().header.sequence + 1_000_000;
    let header = pheromone_field::messages::InputsHeader {
        sequence: seq,
        epoch: 1,
        dt_s: 0.02,
        dt_time_s: 0.02,
        ..Default::default()
    };
    let mut list = codec::encode_inputs(&header, &[]);
    let n = list.len();
    list[n - 3] ^= 0x40;
    let cells = vec![1.0f32; 64 * 64];
    let fh = *hosts.origin.frame().unwrap().header;
    let mut key = codec::encode_keyframe(1, &fh, &cells);
    let n = key.len();
    key[n - 1] ^= 0x01;
    let deadline = Instant::now() + Duration::from_secs(5);
    // Until the mirror's subscriber surely saw them (the session connects in the background).
    while Instant::now() < deadline {
        session.put(&keys.inputs, list.clone()).wait().unwrap();
        session.put(&keys.keyframe, key.clone()).wait().unwrap();
        std::thread::park_timeout(Duration::from_millis(100));
    }
    let _ = session.close().wait();
    // Nothing of them reached the frames.
    assert_identical(&hosts.common(10, |_| true));
    let s = mirror_summary(m);
    assert!(s["rejected_inputs"].as_u64().unwrap() >= 1, "{s}");
    assert!(s["rejected_keyframes"].as_u64().unwrap() >= 1, "{s}");
    assert_eq!(s["checksum_mismatches"], 0, "{s}");
    assert_eq!(s["gaps"], 0, "{s}");
}

/// `pheromone list`, `probe` and `export` on the mirror's host, before and after its origin
/// went away: the mirror is listed (not "no field is running"), marked stale with how long its
/// origin has been silent, and its current frame is still read and exported.
#[test]
fn list_probe_and_export_see_a_mirror_that_lost_its_origin_and_mark_it_stale() {
    let _clean = CleanDomains;
    let name = unique("mir7");
    let field = origin_field(&name);
    let bridge = bridge(&name);
    let m = mirror(&name, &bridge.endpoint);
    let mut hosts = Hosts::attach(&name);
    assert_identical(&hosts.common(5, |_| true));
    let listed = |window: &str| -> serde_json::Value {
        let o = run(&[
            "list",
            "--iox-domain",
            MIRROR,
            "--json",
            "--window-s",
            window,
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let j = json(&o);
        j["fields"]
            .as_array()
            .unwrap()
            .iter()
            .find(|f| f["name"] == name.as_str())
            .cloned()
            .unwrap_or_else(|| panic!("the mirror '{name}' is not listed: {j}"))
    };
    let live = listed("0.5");
    assert_eq!(live["alive"], true, "{live}");
    assert_eq!(live["mirror"]["stale"], false, "{live}");
    // The origin goes, and the bridge with it (SIGKILL).
    field.interrupt();
    field.wait_exit(Duration::from_secs(20));
    bridge.kill();
    // A killed bridge leaves its record of handed-over batches for a successor; none comes.
    let _ = std::fs::remove_file(pheromone_bridge::journal_path(
        &format!("{ORIGIN}_iox2_"),
        &name,
    ));
    until_quiet(&mut hosts.mirror, Duration::from_secs(1));
    let last = hosts.mirror.frame().unwrap().header.sequence;
    let stale = listed("0.3");
    assert_eq!(stale["alive"], false, "{stale}");
    assert_eq!(stale["publisher_alive"], true, "{stale}");
    assert_eq!(stale["sequence"], last, "{stale}");
    assert_eq!(stale["mirror"]["stale"], true, "{stale}");
    assert_eq!(stale["mirror"]["last_sequence"], last, "{stale}");
    assert!(
        stale["mirror"]["inputs_age_s"].as_f64().unwrap() >= 0.5,
        "{stale}"
    );
    let text = run(&["list", "--iox-domain", MIRROR, "--window-s", "0.3"]);
    let row = stdout(&text)
        .lines()
        .find(|l| l.starts_with(name.as_str()))
        .map(str::to_string)
        .unwrap_or_else(|| panic!("no row for {name}: {}", stdout(&text)));
    assert!(
        row.contains("stale (mirror: no inputs from its origin for "),
        "{row}"
    );
    let probe = run(&["probe", "--iox-domain", MIRROR, "--field", &name, "--json"]);
    assert!(probe.status.success(), "{}", stderr(&probe));
    let p = json(&probe);
    assert_eq!(p["sequence"], last, "{p}");
    assert_eq!(p["mirror"]["stale"], true, "{p}");
    assert!(
        stderr(&probe).contains("is stale (mirror: "),
        "{}",
        stderr(&probe)
    );
    let dir = std::env::temp_dir().join(unique("mir7out"));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("mirror.npy");
    let export = run(&[
        "export",
        "--iox-domain",
        MIRROR,
        "--field",
        &name,
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(export.status.success(), "{}", stderr(&export));
    let e = json(&export);
    assert_eq!(e["sequence"], last, "{e}");
    assert_eq!(e["fresh"], false, "{e}");
    assert_eq!(e["mirror"]["stale"], true, "{e}");
    assert!(out.exists());
    std::fs::remove_dir_all(&dir).unwrap();
    let j = mirror_exit(m);
    assert_eq!(j["stale"], true, "{j}");
}
