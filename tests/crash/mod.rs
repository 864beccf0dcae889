//! Clients SIGKILLed at random instants and restarted: the field keeps ticking and cleans up.
//!
//! Client crashes (issue 7, part 1): localizer, depositor, follower, world, reader and one-shot
//! depositor processes are killed with SIGKILL at random instants (seeded) and restarted. The
//! field must keep ticking (a reader in this test process sees a newer frame after every kill),
//! the dead node's resources must be cleaned (the field's services are sized exactly for the
//! clients, so a slot a dead client kept would stop its restart from attaching), and the
//! restarted client must attach again. Also: malformed scenario files exit with status 2 naming
//! the file, line and reason (part 5, the CLI side).
//!
//! Every run gets its own iceoryx2 file prefix (a `config/iceoryx2.toml` in the run's directory,
//! the processes' working directory), so "the run's /dev/shm entries are gone after shutdown" is
//! exact even while other tests run beside it. Tick gaps are measured and printed (`--nocapture`),
//! never asserted against time.
//!
//! `PHEROMONE_CRASH_ROUNDS` (default 12) sets the number of kills, `PHEROMONE_CRASH_SEED` the seed.

use std::path::PathBuf;
use std::process::Command;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use iceoryx2::config::Config;
use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use pheromone_field::shm::{FieldReader, FieldWatch, Svc};
use pheromone_supervisor::ChildSpec;

use crate::harness::*;

/// Longest wait for any condition (the machine may be busy).
pub const WAIT: Duration = Duration::from_secs(30);
/// After a kill, a newer frame must arrive within this.
pub const LIVENESS: Duration = Duration::from_secs(5);

/// A whole number from the environment, or `default`.
pub fn env_u64(name: &str, default: u64) -> u64 {
    match std::env::var(name) {
        Ok(v) => v
            .parse()
            .unwrap_or_else(|_| panic!("{name} = '{v}': expected a whole number")),
        Err(_) => default,
    }
}

/// SplitMix64: the seeded choices of what to kill and when.
pub struct Rng(pub u64);

impl Rng {
    pub fn below(&mut self, n: u64) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        (z ^ (z >> 31)) % n
    }
}

/// One test run: a directory (the processes' working directory) holding an iceoryx2 config with
/// a file prefix of its own, so everything the run creates in /dev/shm is recognisable.
pub struct Run {
    pub dir: PathBuf,
    pub prefix: String,
    pub config: Config,
}

impl Run {
    pub fn new(tag: &str) -> Self {
        let dir = std::env::temp_dir().join(unique(tag));
        std::fs::create_dir_all(dir.join("config")).unwrap();
        // Short: iceoryx2 file names are limited. `<tag><n>_iox2_`, as `--iox-domain` names
        // one: it matches CI's leftover check, and it does not begin with the default prefix
        // `iox2_`, so a default-domain process never takes this run's files for its own.
        let prefix = format!(
            "t{tag}{}_iox2_",
            std::process::id() % 100_000 * 100 + next_id()
        );
        let mut config = Config::default();
        config.global.prefix = FileName::new(prefix.as_bytes()).unwrap();
        std::fs::write(
            dir.join("config/iceoryx2.toml"),
            toml::to_string(&config).unwrap(),
        )
        .unwrap();
        Self {
            dir,
            prefix,
            config,
        }
    }

    /// Starts `pheromone ARGS` in the run's directory; stderr goes to `<name>.log` there. The
    /// run's iceoryx2 prefix comes from its config file, whatever domain the caller's shell
    /// names (`PHEROMONE_IOX_DOMAIN` would replace the prefix).
    pub fn spawn(&self, args: &[&str], name: &str) -> Proc {
        let mut spec = ChildSpec::new(name, None, args.iter().map(|a| a.to_string()).collect());
        spec.cwd = Some(self.dir.clone());
        spec.log_file = Some(self.dir.join(format!("{name}.log")));
        spec.env_remove = vec![pheromone_field::shm::IOX_DOMAIN_ENV.to_string()];
        Proc::spawn_spec(spec)
    }

    /// Runs `pheromone ARGS` to completion in the run's directory (without the caller's
    /// `PHEROMONE_IOX_DOMAIN`, as [`Run::spawn`]).
    pub fn run(&self, args: &[&str]) -> std::process::Output {
        Command::new(bin())
            .args(args)
            .env_remove(pheromone_field::shm::IOX_DOMAIN_ENV)
            .current_dir(&self.dir)
            .output()
            .expect("run pheromone")
    }

    /// The tail of a process's log, for failure messages.
    pub fn log(&self, name: &str) -> String {
        let text =
            std::fs::read_to_string(self.dir.join(format!("{name}.log"))).unwrap_or_default();
        let start = text.len().saturating_sub(2000);
        let start = (start..text.len())
            .find(|&i| text.is_char_boundary(i))
            .unwrap_or(text.len());
        text[start..].to_string()
    }

    /// A node of this run in the test process (no dead-node cleanup: that is the clients' job).
    pub fn node(&self, name: &str) -> Node<Svc> {
        NodeBuilder::new()
            .name(&NodeName::new(name).unwrap())
            .config(&self.config)
            .create::<Svc>()
            .unwrap()
    }

    /// Names of the run's nodes, alive and dead.
    pub fn nodes(&self) -> (Vec<String>, Vec<String>) {
        let (mut alive, mut dead) = (Vec::new(), Vec::new());
        let name = |d: &Option<iceoryx2::node::NodeDetails>| {
            d.as_ref()
                .map(|d| d.name().as_str().to_string())
                .unwrap_or_else(|| "?".into())
        };
        Node::<Svc>::list(&self.config, |state| {
            match state {
                NodeState::Alive(v) => alive.push(name(v.details())),
                NodeState::Dead(v) => dead.push(name(v.details())),
                NodeState::Inaccessible(id) | NodeState::Undefined(id) => {
                    dead.push(format!("{id:?} (inaccessible or undefined)"))
                }
            }
            CallbackProgression::Continue
        })
        .unwrap();
        (alive, dead)
    }

    /// Stops the field with SIGINT (it must exit with 130 after its summary), drops the test's own node, then
    /// waits for the run's nodes to be gone: the field's summary, the dead nodes cleaned and the
    /// run's /dev/shm entries left.
    pub fn stop_field(
        &self,
        field: Proc,
        node: Node<Svc>,
    ) -> (serde_json::Value, u64, Vec<String>) {
        field.interrupt();
        let out = field.wait_exit(WAIT);
        assert!(
            out.status.code() == Some(130),
            "field: {:?} {}",
            out.status,
            self.log("field")
        );
        drop(node);
        let cleaned = self.wait_nodes_gone(Duration::from_secs(10));
        (json(&out), cleaned, self.shm_entries())
    }

    /// After shutdown: waits until no process of the run is alive, then removes the stale
    /// resources of dead nodes (as any process of the run would: a client that a SIGINT caught
    /// before it installed its handler dies without cleaning up). Returns how many dead nodes it
    /// cleaned; panics naming the nodes still there after `timeout`.
    pub fn wait_nodes_gone(&self, timeout: Duration) -> u64 {
        let deadline = Instant::now() + timeout;
        let mut cleaned = 0;
        loop {
            let (alive, _) = self.nodes();
            if alive.is_empty() {
                cleaned += pheromone_field::shm::cleanup_dead_nodes_of(&self.config);
                // A process killed while it created its node leaves an entry iceoryx2 lists as
                // dead but cannot read ("?"), nor remove.
                cleaned += self.remove_half_created_nodes();
            }
            let (alive, dead) = self.nodes();
            if alive.is_empty() && dead.is_empty() {
                return cleaned;
            }
            assert!(
                Instant::now() < deadline,
                "after {timeout:?} the run still has nodes: alive {alive:?}, dead {dead:?}"
            );
            std::thread::park_timeout(Duration::from_millis(20));
        }
    }

    /// Once no node of the run is left: removes the node directories whose details file is
    /// empty, left by a process SIGKILLed (after its stop's grace period, on a loaded machine)
    /// while it created its node. iceoryx2 cannot read such an entry, so no cleanup of its own
    /// removes it; the run's unique prefix makes it this run's. Returns how many it removed
    /// (printed: a figure, not an error).
    fn remove_half_created_nodes(&self) -> u64 {
        let root = self.config.global.node_dir().to_string();
        let mut removed = 0;
        for dir in std::fs::read_dir(&root).into_iter().flatten().flatten() {
            if !dir.path().is_dir() {
                continue;
            }
            let ours: Vec<_> = std::fs::read_dir(dir.path())
                .into_iter()
                .flatten()
                .flatten()
                .filter(|f| f.file_name().to_string_lossy().starts_with(&self.prefix))
                .collect();
            // Killed before its details were written (empty or missing): iceoryx2 cannot read
            // the node, nor remove it.
            let readable = ours.iter().any(|f| {
                f.file_name().to_string_lossy().ends_with("node.details")
                    && f.metadata().is_ok_and(|m| m.len() > 0)
            });
            if ours.is_empty() || readable || std::fs::remove_dir_all(dir.path()).is_err() {
                continue;
            }
            removed += 1;
            // Its monitor files beside the directory: `<prefix><id>.node_monitor…`.
            let id = dir.file_name().to_string_lossy().into_owned();
            let monitor = format!("{}{id}.node_monitor", self.prefix);
            for f in std::fs::read_dir(&root).into_iter().flatten().flatten() {
                if f.file_name().to_string_lossy().starts_with(&monitor) {
                    let _ = std::fs::remove_file(f.path());
                }
            }
        }
        if removed > 0 {
            println!(
                "run {}: removed {removed} half-created node entr(ies)",
                self.prefix
            );
        }
        removed
    }

    /// The run's entries in /dev/shm, except iceoryx2's host-wide management segment
    /// (`….global_mgmt`, one per prefix, kept by design: with the default prefix every run on the
    /// host shares it).
    pub fn shm_entries(&self) -> Vec<String> {
        shm_entries()
            .into_iter()
            .filter(|e| e.starts_with(&self.prefix) && !e.ends_with(".global_mgmt"))
            .collect()
    }

    /// Writes a scenario file: the built-in trail for `robots` robots (one behind the other on
    /// the trail, each with a localizer, depositor and follower), lasting an hour.
    pub fn scenario(&self, robots: u32) -> String {
        let trail = include_str!("../../examples/scenarios/trail.toml");
        let (head, tail) = trail
            .split_once("[[world.robots]]")
            .expect("trail.toml has a [[world.robots]] section");
        let scripted = &tail[tail
            .find("[[deposit]]")
            .expect("trail.toml has [[deposit]]")..];
        let mut text = head.replace("duration_s = 8.0", "duration_s = 3600.0");
        assert!(text.contains("3600"), "trail.toml's duration moved");
        for id in 0..robots {
            text += &format!(
                "[[world.robots]]\nid = {id}\nstart = {{ x_m = {x:.2}, y_m = {y:.2}, theta_rad = 0.0 }}\n\n",
                x = 1.0 + 1.3 * id as f64,
                y = if id % 2 == 0 { 2.5 } else { 2.2 },
            );
        }
        for id in 0..robots {
            text += &format!(
                "[[robot]]\nid = {id}\n[robot.follower]\nstrategy = \"gradient\"\n\
                 [robot.depositor]\nmode = \"uncertainty-aware\"\nchannel = 1\ninterval_m = 0.25\n\n"
            );
        }
        text += scripted;
        let path = self.dir.join(format!("trail-{robots}.toml"));
        std::fs::write(&path, text).unwrap();
        path.to_string_lossy().into_owned()
    }
}

impl Drop for Run {
    fn drop(&mut self) {
        // The management segment of this run's own prefix: nobody else will ever use it.
        for e in shm_entries() {
            if e.starts_with(&self.prefix) && e.ends_with(".global_mgmt") {
                let _ = std::fs::remove_file(std::path::Path::new("/dev/shm").join(e));
            }
        }
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

fn next_id() -> u32 {
    static N: AtomicU64 = AtomicU64::new(0);
    N.fetch_add(1, Ordering::Relaxed) as u32 % 100
}

/// What the test's own reader saw of the field.
#[derive(Debug, Default, Clone)]
pub struct WatchReport {
    pub frames: u64,
    pub first_sequence: u64,
    pub last_sequence: u64,
    /// Frames the reader did not see (it holds one, the field moves on).
    pub missed_frames: u64,
    /// Longest interval between the stamps of two consecutive frames (sequence n, n + 1).
    pub longest_gap_ns: u64,
    pub longest_gap_at: u64,
    /// Sequence numbers that did not grow: (previous, next).
    pub regressions: Vec<(u64, u64)>,
    pub non_finite_frames: u64,
    pub deposits_applied: u64,
    pub deposits_rejected: u64,
    /// Errors the reader recovered from by attaching again.
    pub reader_errors: Vec<String>,
    pub error: Option<String>,
}

/// A reader on a thread of the test process, recording every frame's sequence number and stamp.
pub struct FrameWatch {
    stop: Arc<AtomicBool>,
    latest: Arc<AtomicU64>,
    handle: Option<JoinHandle<WatchReport>>,
}

impl FrameWatch {
    pub fn start(run: &Run, field: &str) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let latest = Arc::new(AtomicU64::new(0));
        let (config, field) = (run.config.clone(), field.to_string());
        let (stop2, latest2) = (stop.clone(), latest.clone());
        let handle = std::thread::spawn(move || {
            let mut r = WatchReport::default();
            let node = NodeBuilder::new()
                .name(&NodeName::new(&format!("watch-{field}")).unwrap())
                .config(&config)
                .create::<Svc>()
                .unwrap();
            let mut reader = match FieldReader::attach_within(&node, &field, WAIT) {
                Ok(r) => r,
                Err(e) => {
                    r.error = Some(format!("attach: {e}"));
                    return r;
                }
            };
            let mut prev: Option<(u64, u64)> = None;
            while !stop2.load(Ordering::Acquire) {
                match reader.wait_frame(Duration::from_millis(100)) {
                    Ok(true) => {}
                    Ok(false) => continue,
                    Err(e) => {
                        // Recorded and reported; the reader attaches again like any client.
                        r.reader_errors.push(format!("wait: {e}"));
                        drop(reader);
                        reader = match FieldReader::attach_within(&node, &field, WAIT) {
                            Ok(r) => r,
                            Err(e) => {
                                r.error = Some(format!("attach again: {e}"));
                                break;
                            }
                        };
                        continue;
                    }
                }
                let Some(f) = reader.frame() else { continue };
                let (seq, stamp) = (f.header.sequence, f.header.stamp_ns);
                match prev {
                    None => r.first_sequence = seq,
                    Some((ps, _)) if seq <= ps => r.regressions.push((ps, seq)),
                    Some((ps, pstamp)) if seq == ps + 1 => {
                        let gap = stamp.saturating_sub(pstamp);
                        if gap > r.longest_gap_ns {
                            r.longest_gap_ns = gap;
                            r.longest_gap_at = seq;
                        }
                    }
                    Some((ps, _)) => r.missed_frames += seq - ps - 1,
                }
                prev = Some((seq, stamp));
                r.frames += 1;
                r.last_sequence = seq;
                r.deposits_applied = f.header.deposits_applied;
                r.deposits_rejected = f.header.deposits_rejected_total();
                if f.view.non_finite_cells() > 0 {
                    r.non_finite_frames += 1;
                }
                latest2.store(seq, Ordering::Release);
            }
            r
        });
        Self {
            stop,
            latest,
            handle: Some(handle),
        }
    }

    /// Sequence number of the newest frame seen (0 before the first).
    pub fn sequence(&self) -> u64 {
        self.latest.load(Ordering::Acquire)
    }

    /// Waits until a frame newer than `after` has arrived; panics after `timeout`.
    pub fn wait_newer(&self, after: u64, timeout: Duration, what: &str) -> u64 {
        eventually(timeout, what, || {
            let s = self.sequence();
            (s > after).then_some(s)
        })
    }

    pub fn finish(mut self) -> WatchReport {
        self.stop.store(true, Ordering::Release);
        self.handle
            .take()
            .unwrap()
            .join()
            .expect("frame watch thread")
    }
}

impl Drop for FrameWatch {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// SIGKILLs a process and reaps it; returns whether it was still running.
pub fn kill(p: &mut Proc) -> bool {
    let running = p.is_running();
    p.kill();
    eventually(
        Duration::from_secs(10),
        "the killed process to be reaped",
        || (!p.is_running()).then_some(()),
    );
    running
}

/// Whether a process has exited (by itself or killed).
pub fn exited(p: &mut Proc) -> bool {
    !p.is_running()
}

/// Stops every process with SIGINT (as Ctrl-C would), then waits for each.
pub fn interrupt_all(procs: Vec<Proc>) {
    for p in &procs {
        p.interrupt();
    }
    for p in procs {
        p.wait_exit(WAIT);
    }
}

/// Waits until the field's ports match `attached` and no node of the run is dead, calling
/// `supervise` (restart what exited) in between; the panic shows the last counts and nodes.
pub fn wait_attached(
    run: &Run,
    status: &FieldWatch,
    attached: impl Fn(&pheromone_field::shm::FieldStatus) -> bool,
    what: &str,
    timeout: Duration,
    mut supervise: impl FnMut(),
) {
    let deadline = Instant::now() + timeout;
    loop {
        supervise();
        let s = status.status();
        let (alive, dead) = run.nodes();
        if attached(&s) && dead.is_empty() {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "timed out after {timeout:?} waiting for {what}: {s:?}, dead nodes {dead:?}, alive {alive:?}"
        );
        std::thread::park_timeout(Duration::from_millis(50));
    }
}

/// A client role of the crash test.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    World,
    Localizer,
    Depositor,
    Follower,
    Reader,
    OneShot,
}

const ROLES: [Role; 6] = [
    Role::World,
    Role::Localizer,
    Role::Depositor,
    Role::Follower,
    Role::Reader,
    Role::OneShot,
];

// A test reads as one scenario, top to bottom (the line limit is for non-test code).
#[allow(clippy::too_many_lines)]
#[test]
fn clients_killed_at_any_instant_leave_the_field_ticking_and_attach_again() {
    let run = Run::new("c");
    let field = unique("cf");
    let world = unique("cw");
    let scenario = run.scenario(1);
    let rounds = env_u64("PHEROMONE_CRASH_ROUNDS", 12);
    let seed = env_u64("PHEROMONE_CRASH_SEED", 7);
    let mut rng = Rng(seed);
    // Exactly as many slots as clients: readers = this test's, the follower's and the probe's;
    // deposit publishers = the world's (scripted trail), the depositor's and a one-shot's.
    let field_cmd = Cmd::field(&field)
        .opt("--scenario", &scenario)
        .tick_hz(50)
        .opt("--max-readers", 3)
        .opt("--max-depositors", 3)
        .json();
    let mut field_proc = run.spawn(&field_cmd.argv(), "field");
    let watch = FrameWatch::start(&run, &field);
    watch.wait_newer(0, WAIT, "the field's first frame");
    let node = run.node(&format!("crash-test-{}", std::process::id()));
    let status = eventually(WAIT, "the field's services", || {
        FieldWatch::open(&node, &field).ok()
    });

    let args = |role: Role| -> Cmd {
        let cmd = match role {
            Role::World => Cmd::new("world").arg("--realtime"),
            Role::Localizer => Cmd::new("localizer").opt("--robot", 0),
            Role::Depositor => Cmd::new("depositor").opt("--robot", 0),
            Role::Follower => Cmd::new("follower").opt("--robot", 0),
            Role::Reader => return Cmd::probe(&field).opt("--above", "1e9").timeout(3600),
            Role::OneShot => return Cmd::deposit(&field).at(3, 1).amount(0.1).timeout(20),
        };
        cmd.opt("--scenario", &scenario)
            .opt("--world", &world)
            .opt("--field", &field)
    };
    let spawn =
        |role: Role| -> Proc { run.spawn(&args(role).argv(), &format!("{role:?}").to_lowercase()) };
    let persistent = [
        Role::World,
        Role::Localizer,
        Role::Depositor,
        Role::Follower,
        Role::Reader,
    ];
    let mut procs: Vec<(Role, Proc)> = persistent.iter().map(|&r| (r, spawn(r))).collect();
    let expected = |s: &pheromone_field::shm::FieldStatus| s.subscribers == 4 && s.depositors == 2;
    let all_attached = |what: &str| {
        eventually(WAIT, what, || {
            let s = status.status();
            expected(&s).then_some(s)
        })
    };
    all_attached("every client attached at the start");

    let started = Instant::now();
    let mut kills = 0u64;
    let mut self_exits = 0u64;
    let mut one_shots_completed = 0u64;
    for round in 0..rounds {
        let role = ROLES[rng.below(ROLES.len() as u64) as usize];
        // The instant: after 0–40 more frames (0–0.8 s at 50 Hz) — during start-up, attach or
        // steady state of the victim.
        let frames = rng.below(41);
        if role == Role::OneShot {
            let mut p = spawn(Role::OneShot);
            watch.wait_newer(watch.sequence() + frames, WAIT, "frames before the kill");
            let at = watch.sequence();
            kills += kill(&mut p) as u64;
            watch.wait_newer(at, LIVENESS, "a frame after killing a one-shot depositor");
            // A new one-shot cleans up after the dead one and delivers its deposit.
            let o = run.run(&args(Role::OneShot).argv());
            assert!(
                o.status.success(),
                "round {round}: a one-shot deposit after a killed one failed: {}",
                stderr(&o)
            );
            one_shots_completed += 1;
        } else {
            let i = procs.iter().position(|(r, _)| *r == role).unwrap();
            watch.wait_newer(watch.sequence() + frames, WAIT, "frames before the kill");
            let at = watch.sequence();
            kills += kill(&mut procs[i].1) as u64;
            watch.wait_newer(
                at,
                LIVENESS,
                &format!("a frame after killing the {role:?} (round {round})"),
            );
            procs[i].1 = spawn(role);
        }
        // Roles stop by themselves when the world is gone: restart whatever exited.
        wait_attached(
            &run,
            &status,
            |s| expected(s) && s.publishers == 1,
            &format!("the clients to attach again after killing the {role:?} (round {round})"),
            WAIT,
            || {
                for (r, p) in procs.iter_mut() {
                    if exited(p) {
                        self_exits += 1;
                        *p = spawn(*r);
                    }
                }
            },
        );
        assert!(
            !exited(&mut field_proc),
            "round {round}: the field died: {}",
            run.log("field")
        );
    }
    let elapsed = started.elapsed();

    interrupt_all(procs.into_iter().map(|(_, p)| p).collect());
    drop(status);
    let report = watch.finish();
    let (summary, cleaned_after, shm_left) = run.stop_field(field_proc, node);
    eprintln!(
        "crash: {kills} clients killed over {rounds} rounds in {:.1} s (seed {seed}), {self_exits} \
         roles stopped by themselves and were restarted, {one_shots_completed} one-shot deposits \
         after a kill; frames seen {} (sequence {}..{}, {} missed by the reader), longest tick \
         gap {:.1} ms at frame {}, field ticks {}, deposits applied {} rejected {}; dead nodes \
         cleaned after shutdown {cleaned_after}; /dev/shm entries left: {}",
        elapsed.as_secs_f64(),
        report.frames,
        report.first_sequence,
        report.last_sequence,
        report.missed_frames,
        report.longest_gap_ns as f64 / 1e6,
        report.longest_gap_at,
        summary["ticks"],
        summary["deposits_applied"],
        report.deposits_rejected,
        shm_left.len()
    );
    assert!(report.error.is_none(), "{:?}", report.error);
    assert!(
        report.regressions.is_empty(),
        "sequence went back: {:?}",
        report.regressions
    );
    assert_eq!(report.non_finite_frames, 0);
    assert!(kills > 0);
    assert!(shm_left.is_empty(), "left in /dev/shm: {shm_left:?}");
}

/// A scenario file with a syntax error, a wrong type or an unknown key: status 2, and stderr
/// names the file, the line and what is wrong — for every process that reads scenarios.
#[test]
fn malformed_scenario_files_exit_2_naming_file_line_and_reason() {
    let dir = std::env::temp_dir().join(unique("badscn"));
    std::fs::create_dir_all(&dir).unwrap();
    let trail = include_str!("../../examples/scenarios/trail.toml");
    let cases: [(&str, String, &str); 4] = [
        (
            "typo.toml",
            trail.replace("sensor_range_m = 6.0", "sensor_rang_m = 6.0"),
            "sensor_rang_m",
        ),
        (
            "type.toml",
            trail.replace("tick_hz = 10.0", "tick_hz = \"fast\""),
            "tick_hz",
        ),
        (
            "truncated.toml",
            trail[..trail.find("start = {").unwrap() + 12].to_string(),
            "",
        ),
        ("binary.toml", "name = \"x\"\n\u{0}\u{1}\u{2}\n".into(), ""),
    ];
    for (file, text, key) in &cases {
        let path = dir.join(file);
        std::fs::write(&path, text).unwrap();
        let p = path.to_str().unwrap();
        for args in [
            vec!["world", "--scenario", p, "--world", "bad"],
            vec!["field", "--scenario", p, "--ticks", "1"],
            vec!["sim", p],
        ] {
            let o = run(&args);
            let e = stderr(&o);
            assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
            assert!(
                e.contains(file),
                "{args:?}: the error does not name the file: {e}"
            );
            assert!(
                e.contains("line "),
                "{args:?}: the error does not name the line: {e}"
            );
            assert!(
                e.contains(key),
                "{args:?}: the error does not name '{key}': {e}"
            );
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
