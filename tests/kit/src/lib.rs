//! The test kit shared by every test binary of the workspace (dev-only): names no other test
//! uses ([`unique`]), the TOML mutator of the fuzz suites ([`toml_fuzz`]), the argv of a
//! `pheromone` command ([`Cmd`]), a runner for the binary ([`Cli`]) and a background process
//! under the project's supervisor ([`Proc`]), a fault-injecting TCP proxy ([`proxy`]).

mod cmd;
pub mod proxy;
pub use cmd::Cmd;

use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use nix::sys::signal::Signal;
use pheromone_supervisor::{ChildId, ChildSpec, Supervisor};

/// A name no other test (or test run) on this host uses: the tag, the process id, a counter and
/// the clock's nanoseconds.
pub fn unique(tag: &str) -> String {
    use std::sync::atomic::{AtomicU32, Ordering};
    static N: AtomicU32 = AtomicU32::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.subsec_nanos())
        .unwrap_or(0);
    format!(
        "{tag}-{}-{}-{nanos}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    )
}

/// Mutations of a TOML file for the fuzz suites: a value replaced with something wild, the file
/// truncated at a byte, or an arbitrary line inserted.
pub mod toml_fuzz {
    use proptest::prelude::*;

    /// One mutation: the line it applies to, and what it does (kind 0 replace the value, 1
    /// truncate at the byte given, 2 insert the line given).
    pub type Mutation = (usize, (u8, String));

    /// Values that break parsers and validators: non-finite, negative, huge, tiny, wrong types.
    pub const WILD_VALUES: [&str; 19] = [
        "nan",
        "inf",
        "-inf",
        "-1",
        "0",
        "1e39",
        "1e308",
        "-1e-45",
        "99999999999",
        "\"x\"",
        "[]",
        "{}",
        "true",
        "1.5",
        "4294967296",
        "18446744073709551616",
        "-0.0",
        "[1, 2]",
        "[ -1e39, nan ]",
    ];

    /// One mutation of a file of `lines` lines.
    pub fn mutation(lines: usize) -> impl Strategy<Value = Mutation> {
        (
            0..lines.max(1),
            prop_oneof![
                prop::sample::select(WILD_VALUES.to_vec()).prop_map(|v| (0u8, v.to_string())),
                (0usize..4000).prop_map(|n| (1u8, n.to_string())),
                "[ -~]{0,40}".prop_map(|s| (2u8, s)),
            ],
        )
    }

    /// One to three mutations of a file of `lines` lines.
    pub fn mutations(lines: usize) -> impl Strategy<Value = Vec<Mutation>> {
        prop::collection::vec(mutation(lines), 1..4)
    }

    /// The text after applying `muts` to `lines`, in order.
    pub fn apply(lines: &[String], muts: &[Mutation]) -> String {
        let mut lines = lines.to_vec();
        let mut truncated = None;
        for (at, (kind, arg)) in muts {
            let at = (*at).min(lines.len().saturating_sub(1));
            match kind {
                0 => {
                    if let Some((key, _)) = lines.get(at).and_then(|l| l.split_once(" = ")) {
                        lines[at] = format!("{key} = {arg}");
                    }
                }
                1 => {
                    let joined = lines.join("\n");
                    let mut n = arg.parse::<usize>().unwrap_or(0).min(joined.len());
                    while !joined.is_char_boundary(n) {
                        n -= 1;
                    }
                    truncated = Some(joined[..n].to_string());
                }
                _ => lines.insert(at, arg.clone()),
            }
        }
        truncated.unwrap_or_else(|| lines.join("\n"))
    }
}

/// A command line of the `pheromone` binary at `bin`.
pub struct Cli {
    command: Command,
}

impl Cli {
    pub fn new(bin: &Path) -> Self {
        Self {
            command: Command::new(bin),
        }
    }

    pub fn args<I: IntoIterator<Item = S>, S: AsRef<std::ffi::OsStr>>(mut self, args: I) -> Self {
        self.command.args(args);
        self
    }

    /// Runs in directory `dir` (where an `config/iceoryx2.toml` of a test run may lie).
    pub fn current_dir(mut self, dir: &Path) -> Self {
        self.command.current_dir(dir);
        self
    }

    /// Runs it to completion.
    pub fn output(mut self) -> Output {
        self.command.output().expect("run pheromone")
    }
}

/// A background `pheromone` process under the project's supervisor; stopped (SIGTERM, then
/// SIGKILL) and reaped on drop.
pub struct Proc {
    sup: Supervisor,
    id: ChildId,
    pub what: String,
}

impl Proc {
    /// Starts `bin` as `spec` says (arguments, working directory, log file).
    pub fn start(bin: &Path, spec: ChildSpec) -> Self {
        let what = spec.args.join(" ");
        let mut sup = Supervisor::new(bin);
        let id = sup.spawn(spec).expect("spawn pheromone");
        Self { sup, id, what }
    }

    pub fn pid(&self) -> u32 {
        self.sup.pid(self.id)
    }

    /// Sends SIGINT (as Ctrl-C would).
    pub fn interrupt(&self) {
        self.sup.signal(self.id, Signal::SIGINT);
    }

    /// Sends SIGTERM (as a service manager stops it).
    pub fn terminate(&self) {
        self.sup.signal(self.id, Signal::SIGTERM);
    }

    /// Kills the process (SIGKILL), as a crash would.
    pub fn kill(&self) {
        self.sup.signal(self.id, Signal::SIGKILL);
    }

    /// Waits up to `timeout` for the process to exit (woken by its exit); whether it still runs.
    pub fn runs_after(&mut self, timeout: Duration) -> bool {
        if self.sup.exit_status(self.id).is_none() {
            self.sup.poll(timeout);
        }
        self.sup.exit_status(self.id).is_none()
    }

    /// Whether the process is still running.
    pub fn is_running(&mut self) -> bool {
        self.sup.poll(Duration::ZERO);
        self.sup.exit_status(self.id).is_none()
    }

    /// Waits for the process to exit by itself (woken by its exit), at most `timeout`; returns
    /// its output.
    pub fn wait_exit(mut self, timeout: Duration) -> Output {
        assert!(
            self.sup.wait_exit(self.id, timeout),
            "'pheromone {}' did not exit within {timeout:?}",
            self.what
        );
        let status = self.sup.exit_status(self.id).expect("exited");
        let (stdout, stderr) = self.sup.output(self.id);
        Output {
            status,
            stdout: stdout.into_bytes(),
            stderr: stderr.into_bytes(),
        }
    }
}
