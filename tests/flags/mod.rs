//! Every numeric flag of every subcommand, fed values outside and inside its domain (issue 32).
//!
//! The flags are not listed by hand: `pheromone __flags` (hidden) walks clap's command tree and
//! prints every value-taking argument with the Rust type clap parses it into, so a numeric flag
//! added later shows up here, and fails the test until `DOMAINS` says what it accepts.
//!
//! Each flag gets `nan`, `inf`, `-1`, `0`, `1e300`, `""`, `junk` and a value just above its
//! largest (`--flag=VALUE`, so that clap takes `-1` as the value). A value outside the flag's
//! domain must exit with status 2 naming the flag, before anything starts; a value inside it must
//! not panic (it may exit 1 or 2 for another reason: the base command lines name a field or a
//! scenario that does not exist, so they fail fast once the flags are checked; a run still
//! going after `DEADLINE` is stopped with SIGINT, then SIGKILL). Every process runs in a
//! `crash::Run` directory (an iceoryx2 prefix of its own): the run must leave no node and no
//! /dev/shm entry behind.
//!
//! `PHEROMONE_FLAGS_BIN=PATH` runs the cases against another build (the flag list still comes
//! from the binary under test): how the figures "before" in the commit messages were measured.

use std::collections::BTreeSet;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use crate::crash::Run;
use crate::harness::*;

/// A run with a value inside the domain may go on (a view serving, a field ticking) this long.
const DEADLINE: Duration = Duration::from_secs(4);

/// What a numeric flag accepts: `lo ≤ v ≤ hi` (`lo < v` when `lo_open`); `int`: whole numbers.
#[derive(Clone, Copy, Debug)]
struct Domain {
    lo: f64,
    hi: f64,
    lo_open: bool,
    int: bool,
}

/// Real numbers from `lo` to `hi`.
const fn real(lo: f64, hi: f64) -> Domain {
    Domain {
        lo,
        hi,
        lo_open: false,
        int: false,
    }
}

/// Real numbers above 0, at most `hi`.
const fn pos(hi: f64) -> Domain {
    Domain {
        lo: 0.0,
        hi,
        lo_open: true,
        int: false,
    }
}

/// Whole numbers from `lo` to `hi`.
const fn int(lo: f64, hi: f64) -> Domain {
    Domain {
        lo,
        hi,
        lo_open: false,
        int: true,
    }
}

/// Positive seconds (at most 1e9, `cmd::MAX_SECONDS`).
const SECS: Domain = pos(1e9);
/// Seconds ≥ 0.
const SECS0: Domain = real(0.0, 1e9);
/// A coordinate, amount or level: finite, magnitude at most 1e9.
const ANY: Domain = real(-1e9, 1e9);
/// A channel index (a field has at most 64 channels).
const CHANNEL: Domain = int(0.0, 63.0);
const ANY_U32: Domain = int(0.0, u32::MAX as f64);
const ANY_U64: Domain = int(0.0, u64::MAX as f64);

/// Every numeric flag: (subcommand path, flag, domain). A flag `pheromone __flags` reports as
/// numeric but missing here fails the test.
const DOMAINS: &[(&str, &str, Domain)] = &[
    ("sim", "--robots", int(1.0, 512.0)),
    ("sim", "--clients", int(1.0, 1024.0)),
    ("sim", "--seed", ANY_U64),
    ("sim", "--duration", SECS),
    ("sim", "--trials", int(2.0, 100_000.0)),
    ("sim", "--rc-m", pos(1e6)),
    ("sim", "--particles", int(10.0, 100_000.0)),
    ("sim", "--compare-robot", ANY_U32),
    ("sim", "--timeout", SECS),
    ("sim", "--attach-timeout", SECS),
    ("sim", "--stall-timeout", SECS),
    ("sweep", "--trials", int(1.0, 100_000.0)),
    ("sweep", "--duration", SECS),
    ("sweep", "--jobs", int(1.0, 1024.0)),
    ("field", "--width", int(1.0, 65_536.0)),
    ("field", "--height", int(1.0, 65_536.0)),
    ("field", "--cell-size", pos(1e6)),
    ("field", "--origin-x", ANY),
    ("field", "--origin-y", ANY),
    ("field", "--tick-hz", pos(1e5)),
    ("field", "--decay-per-s", real(0.0, 1e9)),
    ("field", "--alpha", real(0.0, 1.0)),
    ("field", "--ambient-radius", real(0.0, 1e6)),
    ("field", "--rho-per-tick", real(0.0, 1.0)),
    ("field", "--quantum", real(0.0, 1e9)),
    ("field", "--tau-s", pos(1e9)),
    ("field", "--diffusion", real(0.0, 1e9)),
    ("field", "--max-readers", int(1.0, 1024.0)),
    ("field", "--max-depositors", int(1.0, 4096.0)),
    ("field", "--deposit-buffer", int(1.0, 1_048_576.0)),
    ("field", "--ticks", int(1.0, 1e12)),
    ("field", "--duration", SECS0),
    ("field", "--checkpoint-every", SECS),
    ("field", "--publish-on-deposit-ms", real(0.0, 1e12)),
    ("field", "--threads", int(1.0, 256.0)),
    ("field", "--rt-priority", int(1.0, 99.0)),
    ("field", "--rt-cpu", int(0.0, 1023.0)),
    ("gateway", "--rt-priority", int(1.0, 99.0)),
    ("gateway", "--rt-cpu", int(0.0, 1023.0)),
    ("world", "--rt-priority", int(1.0, 99.0)),
    ("world", "--rt-cpu", int(0.0, 1023.0)),
    ("localizer", "--rt-priority", int(1.0, 99.0)),
    ("localizer", "--rt-cpu", int(0.0, 1023.0)),
    ("mapper", "--rt-priority", int(1.0, 99.0)),
    ("mapper", "--rt-cpu", int(0.0, 1023.0)),
    ("depositor", "--rt-priority", int(1.0, 99.0)),
    ("depositor", "--rt-cpu", int(0.0, 1023.0)),
    ("follower", "--rt-priority", int(1.0, 99.0)),
    ("sim", "--rt-priority", int(1.0, 99.0)),
    ("follower", "--rt-cpu", int(0.0, 1023.0)),
    ("field", "--deadline-slack-us", real(0.0, 1e15)),
    ("field", "--spin-us", real(0.0, 1e7)),
    ("field", "--stale-after-s", SECS),
    ("tune k", "--p0", ANY),
    ("tune k", "--ptm", ANY),
    ("tune k", "--tm", SECS),
    ("tune k", "--pa", ANY),
    ("tune threshold", "--p0", ANY),
    ("tune threshold", "--k", ANY),
    ("tune threshold", "--level", ANY),
    ("tune threshold", "--delta", ANY),
    ("tune threshold", "--pa", ANY),
    ("world", "--stall-timeout", SECS),
    ("world", "--attach-timeout", SECS),
    ("localizer", "--robot", ANY_U32),
    ("localizer", "--particles", int(10.0, 100_000.0)),
    ("mapper", "--robot", ANY_U32),
    ("depositor", "--robot", ANY_U32),
    ("depositor", "--channel", CHANNEL),
    ("depositor", "--interval-m", real(0.0, 1e6)),
    ("depositor", "--interval-s", SECS0),
    ("depositor", "--tau", pos(1e9)),
    ("depositor", "--range", pos(1e6)),
    ("follower", "--robot", ANY_U32),
    ("follower", "--channel", CHANNEL),
    ("follower", "--seed", ANY_U64),
    ("follower", "--client-id", int(0.0, 255.0)),
    ("follower", "--gateway-timeout-ms", int(1.0, 3_600_000.0)),
    ("follower", "--gateway-retries", int(0.0, 1000.0)),
    ("follower", "--deposit-amount", pos(1e9)),
    ("follower", "--deposit-every", int(1.0, 1e9)),
    ("follower", "--frame-timeout", SECS),
    ("graph", "--robots", int(1.0, 512.0)),
    ("graph", "--seed", ANY_U64),
    ("graph", "--attach-timeout", SECS),
    ("graph", "--stall-timeout", SECS),
    ("graph-robot", "--robot", int(1.0, 512.0)),
    ("graph-robot", "--robots", int(1.0, 512.0)),
    ("graph-robot", "--seed", ANY_U64),
    ("graph-robot", "--timeout", SECS),
    ("probe", "--x", ANY),
    ("probe", "--y", ANY),
    ("probe", "--channel", CHANNEL),
    ("probe", "--above", ANY),
    ("probe", "--below", ANY),
    ("probe", "--timeout", SECS0),
    ("probe", "--rate-hz", pos(1e4)),
    ("deposit", "--robot", ANY_U32),
    ("deposit", "--channel", CHANNEL),
    ("deposit", "--x", ANY),
    ("deposit", "--y", ANY),
    ("deposit", "--tau", ANY),
    ("deposit", "--cov", ANY),
    ("deposit", "--range", pos(1e6)),
    ("deposit", "--gamma-max", pos(1e9)),
    ("deposit", "--sigma", pos(1e6)),
    ("deposit", "--plateau", real(0.0, 1e6)),
    ("deposit", "--slope", real(0.0, 1e6)),
    ("deposit", "--timeout", SECS0),
    ("deposit", "--receipt-timeout", SECS),
    ("list", "--window-s", SECS),
    ("export", "--channel", CHANNEL),
    ("export", "--min", ANY),
    ("export", "--max", ANY),
    ("export", "--timeout-s", SECS),
    ("gateway", "--baud", int(1.0, 4_000_000.0)),
    ("gateway", "--rate-hz", real(0.0, 1e6)),
    ("gateway", "--plateau-m", real(0.0, 1e6)),
    ("gateway", "--slope-m", real(0.0, 1e6)),
    ("gateway", "--attach-timeout", SECS0),
    ("view", "--robots", int(0.0, 4096.0)),
    ("view", "--max-side", int(1.0, 4096.0)),
    ("bridge", "--checksum-every", int(1.0, 1e6)),
    ("bridge", "--keyframe-every-s", SECS),
    ("bridge", "--rate-hz", pos(1000.0)),
    ("bridge", "--downsample", int(1.0, 4096.0)),
    ("bridge", "--timeout", SECS),
    ("bridge", "--duration", SECS),
    ("ros2", "--rate-hz", pos(1000.0)),
    ("ros2", "--domain-id", int(0.0, 232.0)),
    ("ros2", "--tau", pos(1e9)),
    ("ros2", "--gamma-max", pos(1e9)),
    ("ros2", "--range-m", pos(1e6)),
    ("ros2", "--interval-m", real(0.0, 1e6)),
    ("ros2", "--interval-s", SECS0),
    ("ros2", "--channel", CHANNEL),
    ("ros2", "--robots", ANY_U32),
    ("ros2", "--path-rate-hz", pos(1000.0)),
    ("ros2", "--path-max-poses", int(1.0, 1e7)),
    ("ros2", "--timeout", SECS),
    ("ros2", "--duration", SECS),
    ("ros2", "--cache-rate-hz", real(0.0, 1000.0)),
    ("ros2", "--occupancy-min", real(-1e9, 1e9)),
    ("ros2", "--occupancy-max", real(-1e9, 1e9)),
    ("ros2", "--occupancy-unknown-below", real(-1e9, 1e9)),
    ("record", "--rate-hz", pos(1000.0)),
    ("record", "--timeout", SECS),
    ("record", "--duration", SECS),
    ("record", "--frames", int(1.0, 1e12)),
    ("record", "--occupancy-min", real(-1e9, 1e9)),
    ("record", "--occupancy-max", real(-1e9, 1e9)),
    ("record", "--occupancy-unknown-below", real(-1e9, 1e9)),
    ("bench", "--tick-hz", pos(1e4)),
    ("bench", "--visible-width", int(16.0, 4096.0)),
    ("bench", "--repeats", int(1.0, 100.0)),
    ("bench", "--scale-duration-s", pos(3600.0)),
    ("bench", "--scale-robots", int(1.0, 256.0)),
];

/// Text flags that hold numbers (lists), checked the same way with the domain of each item.
const NUMERIC_TEXT: &[(&str, &str, Domain)] = &[
    ("sweep", "--robots", int(1.0, 512.0)),
    ("sweep", "--rc-m", pos(1e6)),
];

/// The command line a subcommand's cases start from: it fails fast once the flags are checked
/// (a field or scenario that does not exist, a timeout of 0). A tested flag the line already
/// gives is taken out of it first.
const BASE: &[(&str, &[&str])] = &[
    ("sim", &["sim", "fz-none.toml", "--no-out"]),
    ("sweep", &["sweep", "fz-none.toml", "--out", "fz-sweep"]),
    ("field", &["field", "--name", "fz-none", "--print-config"]),
    (
        "tune k",
        &["tune", "k", "--p0", "100", "--ptm", "10", "--tm", "10"],
    ),
    (
        "tune threshold",
        &[
            "tune",
            "threshold",
            "--p0",
            "100",
            "--k",
            "0.1",
            "--level",
            "10",
        ],
    ),
    ("world", &["world", "--scenario", "fz-none.toml"]),
    ("localizer", &["localizer", "--scenario", "fz-none.toml"]),
    ("mapper", &["mapper", "--scenario", "fz-none.toml"]),
    ("depositor", &["depositor", "--scenario", "fz-none.toml"]),
    (
        "follower",
        &[
            "follower",
            "--scenario",
            "fz-none.toml",
            "--gateway",
            "udp://127.0.0.1:9",
            "--deposit-amount",
            "1",
        ],
    ),
    (
        "graph",
        &["graph", "--scenario", "fz-none.toml", "--robots", "1"],
    ),
    (
        "graph-robot",
        &[
            "graph-robot",
            "--scenario",
            "fz-none.toml",
            "--robot",
            "1",
            "--robots",
            "1",
        ],
    ),
    (
        "probe",
        &["probe", "--field", "fz-none", "--timeout", "0", "--follow"],
    ),
    (
        "deposit",
        &[
            "deposit",
            "--field",
            "fz-none",
            "--x",
            "0",
            "--y",
            "0",
            "--tau",
            "1",
            "--timeout",
            "0",
        ],
    ),
    ("list", &["list", "--window-s", "0.1"]),
    (
        "export",
        &[
            "export",
            "--field",
            "fz-none",
            "--out",
            "fz.npy",
            "--timeout-s",
            "0.1",
        ],
    ),
    (
        "gateway",
        &[
            "gateway",
            "--field",
            "fz-none",
            "--serial",
            "fz-no-tty",
            "--attach-timeout",
            "0",
        ],
    ),
    (
        "view",
        &["view", "--field", "fz-none", "--listen", "127.0.0.1:0"],
    ),
    (
        "bridge",
        &[
            "bridge",
            "--field",
            "fz-none",
            "--listen",
            "tcp/127.0.0.1:0",
            "--frames",
            "--timeout",
            "0.1",
        ],
    ),
    (
        "ros2",
        &[
            "ros2",
            "--field",
            "fz-none",
            "--listen",
            "tcp/127.0.0.1:0",
            "--timeout",
            "0.1",
        ],
    ),
    (
        "record",
        &[
            "record",
            "--field",
            "fz-none",
            "--mcap",
            "fz.mcap",
            "--timeout",
            "0.1",
        ],
    ),
    ("bench", &["bench", "--smoke"]),
];

/// Flags that need another (clap's `requires`) or exclude one of the base line's: the arguments
/// added, and a base flag (with its value) taken out.
const NEEDS: &[(&str, &str, &[&str], Option<&str>)] = &[
    (
        "field",
        "--checkpoint-every",
        &["--checkpoint", "fz.cp"],
        None,
    ),
    ("field", "--rt-cpu", &["--rt-priority", "1"], None),
    ("gateway", "--rt-cpu", &["--rt-priority", "1"], None),
    ("world", "--rt-cpu", &["--rt-priority", "1"], None),
    ("localizer", "--rt-cpu", &["--rt-priority", "1"], None),
    ("mapper", "--rt-cpu", &["--rt-priority", "1"], None),
    ("depositor", "--rt-cpu", &["--rt-priority", "1"], None),
    ("follower", "--rt-cpu", &["--rt-priority", "1"], None),
    (
        "field",
        "--stale-after-s",
        &["--mirror", "zenoh:tcp/127.0.0.1:9"],
        Some("--print-config"),
    ),
    ("tune threshold", "--delta", &[], Some("--level")),
    ("sim", "--rc-m", &["--merge"], None),
    ("sim", "--compare-robot", &["--compare-filters"], None),
];

/// The values every flag gets, besides one just above its largest.
const VALUES: [&str; 7] = ["nan", "inf", "-1", "0", "1e300", "", "junk"];

/// One command line and what it must do.
struct Case {
    path: String,
    flag: String,
    value: String,
    argv: Vec<String>,
    inside: bool,
}

impl Domain {
    /// Whether `value` is inside the domain.
    fn contains(&self, value: &str) -> bool {
        let Ok(v) = value.parse::<f64>() else {
            return false;
        };
        if !v.is_finite() || (self.int && (v.fract() != 0.0 || value.contains(['e', '.']))) {
            return false;
        }
        let above_lo = if self.lo_open {
            v > self.lo
        } else {
            v >= self.lo
        };
        above_lo && v <= self.hi
    }

    /// A value just above the largest, if the type can hold one.
    fn above(&self) -> Option<String> {
        if self.int {
            (self.hi < u32::MAX as f64).then(|| format!("{}", self.hi as u64 + 1))
        } else {
            Some(format!("{:e}", self.hi * 2.0))
        }
    }
}

/// `flag` appears in `text` as a whole flag (`--robot` is not found in `--robots`).
fn names_flag(text: &str, flag: &str) -> bool {
    text.match_indices(flag).any(|(i, _)| {
        !text[i + flag.len()..]
            .chars()
            .next()
            .is_some_and(|c| c.is_ascii_alphanumeric() || c == '-')
    })
}

/// Every (subcommand path, flag, type) line of `pheromone __flags`.
fn discovered() -> Vec<(String, String, String)> {
    let out = run(&["__flags"]);
    assert!(out.status.success(), "__flags: {}", stderr(&out));
    stdout(&out)
        .lines()
        .filter(|l| !l.is_empty())
        .map(|l| {
            let f: Vec<&str> = l.split('\t').collect();
            assert_eq!(f.len(), 3, "__flags line {l:?}");
            (f[0].to_string(), f[1].to_string(), f[2].to_string())
        })
        .collect()
}

/// The base line of `path` for `flag`, with what `NEEDS` says.
fn base_line(path: &str, flag: &str) -> Vec<String> {
    let base = BASE
        .iter()
        .find(|(p, _)| *p == path)
        .unwrap_or_else(|| panic!("no BASE command line for '{path}': add one"))
        .1;
    let need = NEEDS.iter().find(|(p, f, _, _)| *p == path && *f == flag);
    let drop_flag = need.and_then(|n| n.3);
    let mut argv = Vec::new();
    let mut i = 0;
    while i < base.len() {
        let a = base[i];
        let takes_value = base.get(i + 1).is_some_and(|n| !n.starts_with("--"));
        if a == flag || Some(a) == drop_flag {
            // The flag and its value (if it has one).
            i += if takes_value && a.starts_with("--") {
                2
            } else {
                1
            };
            continue;
        }
        argv.push(a.to_string());
        i += 1;
    }
    if let Some((_, _, extra, _)) = need {
        argv.extend(extra.iter().map(|s| s.to_string()));
    }
    argv
}

/// `DOMAINS` and `NUMERIC_TEXT` but the flags of `pheromone bench` in a build without it (the
/// feature `bench`: there `bench` takes no flags and says how to get it).
fn built_domains() -> impl Iterator<Item = &'static (&'static str, &'static str, Domain)> {
    DOMAINS
        .iter()
        .chain(NUMERIC_TEXT)
        .filter(|(path, _, _)| cfg!(feature = "bench") || !path.starts_with("bench"))
}

/// The cases of every numeric flag; panics naming the flags `DOMAINS` lacks.
fn cases(flags: &[(String, String, String)]) -> Vec<Case> {
    let numeric: Vec<&(String, String, String)> =
        flags.iter().filter(|(_, _, ty)| ty != "text").collect();
    let unclassified: Vec<String> = numeric
        .iter()
        .filter(|(p, f, _)| !DOMAINS.iter().any(|(dp, df, _)| dp == p && df == f))
        .map(|(p, f, ty)| format!("pheromone {p} {f} ({ty})"))
        .collect();
    assert!(
        unclassified.is_empty(),
        "numeric flags without a domain: classify each in tests/flags/mod.rs DOMAINS \
         (and give it a bounded value parser, src/cmd/mod.rs):\n{}",
        unclassified.join("\n")
    );
    let positional: Vec<_> = numeric
        .iter()
        .filter(|(_, f, _)| !f.starts_with("--"))
        .collect();
    assert!(
        positional.is_empty(),
        "numeric positional arguments: {positional:?}"
    );
    let known: BTreeSet<(&str, &str)> = flags
        .iter()
        .map(|(p, f, _)| (p.as_str(), f.as_str()))
        .collect();
    let stale: Vec<_> = built_domains()
        .filter(|(p, f, _)| !known.contains(&(*p, *f)))
        .collect();
    assert!(
        stale.is_empty(),
        "DOMAINS names flags that no longer exist: {stale:?}"
    );
    let mut out = Vec::new();
    for (path, flag, domain) in built_domains() {
        let above = domain.above();
        for value in VALUES.iter().copied().chain(above.as_deref()) {
            let mut argv = base_line(path, flag);
            argv.push(format!("{flag}={value}"));
            out.push(Case {
                path: path.to_string(),
                flag: flag.to_string(),
                value: value.to_string(),
                argv,
                inside: domain.contains(value),
            });
        }
    }
    out
}

/// How one case ended.
struct Outcome {
    code: Option<i32>,
    stderr: String,
    /// Still running at the deadline (stopped by the test).
    stopped: bool,
}

/// Runs `argv` in `dir` for at most `DEADLINE`, then SIGINT and, 5 s later, SIGKILL.
fn run_bounded(bin: &Path, dir: &Path, argv: &[String]) -> Outcome {
    let mut child = Command::new(bin)
        .args(argv)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start pheromone");
    // Read stderr while it runs, so a chatty run never blocks on a full pipe.
    let mut pipe = child.stderr.take().expect("stderr piped");
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = pipe.read_to_string(&mut s);
        s
    });
    let wait = |child: &mut std::process::Child, limit: Duration| {
        let until = Instant::now() + limit;
        loop {
            if let Some(status) = child.try_wait().expect("try_wait") {
                return Some(status);
            }
            if Instant::now() >= until {
                return None;
            }
            std::thread::park_timeout(Duration::from_millis(5));
        }
    };
    let mut stopped = false;
    let status = match wait(&mut child, DEADLINE) {
        Some(s) => s,
        None => {
            stopped = true;
            let pid = nix::unistd::Pid::from_raw(child.id() as i32);
            let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT);
            match wait(&mut child, Duration::from_secs(5)) {
                Some(s) => s,
                None => {
                    let _ = child.kill();
                    child.wait().expect("wait")
                }
            }
        }
    };
    Outcome {
        code: status.code(),
        stderr: reader.join().expect("stderr reader"),
        stopped,
    }
}

/// What is wrong with `o` for case `c`, if anything.
fn failure(c: &Case, o: &Outcome) -> Option<String> {
    let panicked = o.stderr.contains("panicked") || o.code == Some(101);
    let wrong = if c.inside {
        panicked || (o.code.is_none() && !o.stopped)
    } else {
        panicked || o.code != Some(2) || !names_flag(&o.stderr, &c.flag)
    };
    wrong.then(|| {
        format!(
            "pheromone {} ({}; {} {:?}): exit {:?}{}: {}",
            c.argv.join(" "),
            if c.inside { "inside" } else { "outside" },
            c.path,
            c.value,
            o.code,
            if o.stopped {
                ", stopped at the deadline"
            } else {
                ""
            },
            o.stderr.trim()
        )
    })
}

#[test]
fn every_numeric_flag_of_every_subcommand_refuses_values_outside_its_domain_with_exit_2() {
    let flags = discovered();
    let cases = cases(&flags);
    let bin = std::env::var_os("PHEROMONE_FLAGS_BIN")
        .map(PathBuf::from)
        .unwrap_or_else(bin);
    let run_dir = Run::new("fz");
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<(usize, Outcome)>> = Mutex::new(Vec::new());
    let started = Instant::now();
    std::thread::scope(|s| {
        for _ in 0..3 {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(c) = cases.get(i) else { break };
                let o = run_bounded(&bin, &run_dir.dir, &c.argv);
                results.lock().unwrap().push((i, o));
            });
        }
    });
    let results = results.into_inner().unwrap();
    let mut failures: Vec<String> = results
        .iter()
        .filter_map(|(i, o)| failure(&cases[*i], o))
        .collect();
    failures.sort();
    let count = |f: &dyn Fn(&Case, &Outcome) -> bool| {
        results.iter().filter(|(i, o)| f(&cases[*i], o)).count()
    };
    let panicked = count(&|_, o| o.stderr.contains("panicked") || o.code == Some(101));
    let outside_not_2 = count(&|c, o| !c.inside && o.code != Some(2));
    let stopped = count(&|_, o| o.stopped);
    println!(
        "{} numeric flags ({} discovered lines), {} cases ({} inside the domain) in {:.1} s: \
         {panicked} panicked, {outside_not_2} outside the domain exited ≠ 2, {stopped} stopped \
         at the deadline, {} failures",
        built_domains().count(),
        flags.len(),
        cases.len(),
        cases.iter().filter(|c| c.inside).count(),
        started.elapsed().as_secs_f64(),
        failures.len()
    );
    run_dir.wait_nodes_gone(Duration::from_secs(30));
    assert_eq!(
        run_dir.shm_entries(),
        Vec::<String>::new(),
        "left in /dev/shm"
    );
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n")
    );
}

/// Addresses, endpoints, the iceoryx2 domain, output directories and files: each bad one is
/// refused with exit status 2 naming the flag and the value, before anything starts (no run
/// line, no field, no process).
#[test]
fn every_place_a_flag_names_is_checked_before_anything_starts() {
    let dir = std::env::temp_dir().join(unique("fz-places"));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("a-file");
    std::fs::write(&file, b"x").unwrap();
    let file = file.to_string_lossy().into_owned();
    let under_file = format!("{file}/sub");
    let dir_s = dir.to_string_lossy().into_owned();
    let cases: Vec<(Vec<&str>, &str, &str)> = vec![
        (vec!["list"], "--iox-domain", "a b"),
        (vec!["sim", "trail", "--no-out"], "--view", "999.1.1.1:80"),
        (vec!["sim", "trail", "--no-out"], "--ros2", "nonsense"),
        (vec!["sim", "trail"], "--out", &file),
        (vec!["sim", "trail"], "--out", &under_file),
        (
            vec!["sim", "trail", "--no-out"],
            "--record",
            "/nonexistent/x.mcap",
        ),
        (vec!["sweep", "ias-ss"], "--out", &file),
        (
            vec!["field", "--name", "fz-p"],
            "--checkpoint",
            "/nonexistent/cp",
        ),
        (vec!["field", "--name", "fz-p"], "--checkpoint", &dir_s),
        (
            vec!["field", "--name", "fz-p"],
            "--mirror",
            "zenoh:nonsense",
        ),
        (
            vec!["field", "--name", "fz-p"],
            "--mirror",
            "tcp/127.0.0.1:7447",
        ),
        (vec!["gateway", "--field", "fz-p"], "--udp", "nonsense"),
        (vec!["view", "--field", "fz-p"], "--listen", "nonsense"),
        (vec!["bridge", "--field", "fz-p"], "--listen", "nonsense"),
        (
            vec!["bridge", "--field", "fz-p"],
            "--listen",
            "tcp/127.0.0.1:99999",
        ),
        (vec!["ros2", "--field", "fz-p"], "--connect", "tcp/"),
        (vec!["ros2", "--field", "fz-p"], "--listen", "udp/host"),
        (
            vec!["record", "--field", "fz-p"],
            "--mcap",
            "/nonexistent/x.mcap",
        ),
        (
            vec!["export", "--field", "fz-p"],
            "--out",
            "/nonexistent/x.npy",
        ),
    ];
    let mut failures = Vec::new();
    for (head, flag, value) in &cases {
        let mut argv: Vec<String> = head.iter().map(|s| s.to_string()).collect();
        argv.push(format!("{flag}={value}"));
        let o = run_bounded(&bin(), &dir, &argv);
        let named = names_flag(&o.stderr, flag) && o.stderr.contains(value);
        // Nothing started: no run line of `sim`, no field, no waiting for one.
        let started = o.stderr.contains("field '") || o.stderr.contains("sim '");
        if o.code != Some(2) || !named || started || o.stderr.contains("panicked") {
            failures.push(format!(
                "pheromone {}: exit {:?}: {}",
                argv.join(" "),
                o.code,
                o.stderr.trim()
            ));
        }
    }
    // The inherited domain too.
    let o = Command::new(bin())
        .args(["list", "--window-s", "0.1"])
        .env("PHEROMONE_IOX_DOMAIN", "a/b")
        .output()
        .unwrap();
    let err = stderr(&o);
    if o.status.code() != Some(2) || !err.contains("PHEROMONE_IOX_DOMAIN=a/b") {
        failures.push(format!("PHEROMONE_IOX_DOMAIN=a/b: {:?}: {err}", o.status));
    }
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
