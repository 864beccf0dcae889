//! One supervisor for the child processes of a run (`pheromone sim`, the node-graph runs,
//! `pheromone bench`, the integration tests): it starts each role as a child of the `pheromone`
//! binary, watches them, stops them in order, reports a failed child by role and robot with the
//! last lines of its stderr, reads each child's summary as a typed struct, and cleans up what a
//! killed child left in shared memory.
//!
//! Every child has a waiter thread that reaps it and reports its exit on a channel, so the
//! supervisor is woken by an exit (no polling of exit statuses), and a reader thread for each
//! of its pipes, so a chatty child never blocks on a full pipe. A child gets SIGTERM when the
//! thread that started it dies, even by SIGKILL (`death`), so no child outlives its run.

use std::collections::VecDeque;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde::de::DeserializeOwned;

mod death;

pub use death::{die_with_parent_as_asked, ParentGone, DIE_WITH_PARENT_ENV};

/// Lines of a child's stderr shown in its error report.
const STDERR_TAIL_LINES: usize = 12;

/// Lines of a child's stderr kept in all (the oldest go first).
const STDERR_KEPT_LINES: usize = 10_000;

/// One child to start: `pheromone ARGS`, known as `role` (of `robot`).
#[derive(Debug, Clone)]
pub struct ChildSpec {
    pub role: String,
    pub robot: Option<u32>,
    pub args: Vec<String>,
    /// Working directory (default: ours).
    pub cwd: Option<PathBuf>,
    /// Also write every stderr line to this file (created anew).
    pub log_file: Option<PathBuf>,
    /// Environment variables the child does not inherit (e.g. `PHEROMONE_IOX_DOMAIN` where the
    /// child's iceoryx2 configuration comes from its working directory).
    pub env_remove: Vec<String>,
}

impl ChildSpec {
    pub fn new(role: &str, robot: Option<u32>, args: Vec<String>) -> Self {
        Self {
            role: role.to_string(),
            robot,
            args,
            cwd: None,
            log_file: None,
            env_remove: Vec::new(),
        }
    }

    /// "field", "depositor r3".
    pub fn who(&self) -> String {
        match self.robot {
            Some(r) => format!("{} r{r}", self.role),
            None => self.role.clone(),
        }
    }
}

/// What went wrong with a child.
#[derive(Debug, thiserror::Error)]
pub enum SupervisorError {
    #[error("cannot start {who} ({exe}): {source}")]
    Spawn {
        who: String,
        exe: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{who} failed ({status}){}", tail_text(.stderr_tail))]
    Failed {
        who: String,
        role: String,
        robot: Option<u32>,
        status: String,
        stderr_tail: String,
    },
    #[error("{who}: its summary on stdout is {problem}: {detail}{}", tail_text(.stderr_tail))]
    Summary {
        who: String,
        problem: &'static str,
        detail: String,
        stderr_tail: String,
    },
    #[error("{who} closed its output ({status}) before printing what was expected{}", tail_text(.stderr_tail))]
    EndedEarly {
        who: String,
        status: String,
        stderr_tail: String,
    },
}

impl SupervisorError {
    /// The role and robot of the child the error is about.
    pub fn child(&self) -> Option<(&str, Option<u32>)> {
        match self {
            SupervisorError::Failed { role, robot, .. } => Some((role, *robot)),
            _ => None,
        }
    }
}

fn tail_text(tail: &str) -> String {
    if tail.trim().is_empty() {
        String::new()
    } else {
        format!("; its last output:\n{}", tail.trim_end())
    }
}

/// A handle to one started child.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChildId(usize);

struct Child {
    spec: ChildSpec,
    pid: u32,
    exit: Option<ExitStatus>,
    /// The child's stdout, line by line; closed when the child closes it.
    stdout: mpsc::Receiver<String>,
    /// Every stdout line taken from the channel so far.
    stdout_lines: Vec<String>,
    stderr: Option<JoinHandle<()>>,
    stderr_tail: Arc<Mutex<VecDeque<String>>>,
}

/// The children of one run.
pub struct Supervisor {
    exe: PathBuf,
    children: Vec<Child>,
    exits_tx: mpsc::Sender<(usize, Option<ExitStatus>)>,
    exits: mpsc::Receiver<(usize, Option<ExitStatus>)>,
    /// Echo every child's stderr lines to ours, prefixed with its name.
    pub echo_stderr: bool,
    /// Environment variables every child gets (beside ours).
    pub env: Vec<(String, String)>,
    /// The children are `pheromone` processes, which request their death signal themselves
    /// ([`die_with_parent_as_asked`], asked by [`DIE_WITH_PARENT_ENV`]): they are started by
    /// `posix_spawn`, without a `fork` that copies this process's page tables. Otherwise (the
    /// default, for any program) the request is made between fork and exec.
    pub death_signal_by_child: bool,
}

impl Supervisor {
    /// Children are started from the binary `exe`.
    pub fn new(exe: &Path) -> Self {
        let (exits_tx, exits) = mpsc::channel();
        Self {
            exe: exe.to_path_buf(),
            children: Vec::new(),
            exits_tx,
            exits,
            echo_stderr: false,
            env: Vec::new(),
            death_signal_by_child: false,
        }
    }

    /// Starts `pheromone ARGS` (stdin closed, stdout and stderr captured). The child gets
    /// SIGTERM if this thread dies first, by any signal (`PR_SET_PDEATHSIG`).
    pub fn spawn(&mut self, spec: ChildSpec) -> Result<ChildId, SupervisorError> {
        let mut log = match &spec.log_file {
            Some(path) => {
                Some(
                    std::fs::File::create(path).map_err(|source| SupervisorError::Spawn {
                        who: format!("{} (log file {})", spec.who(), path.display()),
                        exe: self.exe.display().to_string(),
                        source,
                    })?,
                )
            }
            None => None,
        };
        let mut command = Command::new(&self.exe);
        if self.death_signal_by_child {
            death::ask_child_to_die_with_parent(&mut command);
        } else {
            death::die_with_parent(&mut command);
        }
        if let Some(dir) = &spec.cwd {
            command.current_dir(dir);
        }
        for var in &spec.env_remove {
            command.env_remove(var);
        }
        for (var, value) in &self.env {
            command.env(var, value);
        }
        let mut child = command
            .args(&spec.args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|source| SupervisorError::Spawn {
                who: spec.who(),
                exe: self.exe.display().to_string(),
                source,
            })?;
        let index = self.children.len();
        let pid = child.id();
        let (lines_tx, stdout) = mpsc::channel();
        if let Some(o) = child.stdout.take() {
            std::thread::spawn(move || {
                // A read error ends the stream: the summary check reports what is missing.
                for line in BufReader::new(o).lines() {
                    let Ok(line) = line else { break };
                    if lines_tx.send(line).is_err() {
                        break;
                    }
                }
            });
        }
        let stderr_tail = Arc::new(Mutex::new(VecDeque::new()));
        let stderr = child.stderr.take().map(|e| {
            let mut log = log.take();
            let tail = Arc::clone(&stderr_tail);
            let (who, echo) = (spec.who(), self.echo_stderr);
            std::thread::spawn(move || {
                for line in BufReader::new(e).lines() {
                    let Ok(line) = line else { break };
                    if echo {
                        eprintln!("[{who}] {line}");
                    }
                    if let Some(f) = log.as_mut() {
                        use std::io::Write;
                        // A log that cannot be written loses lines, not the child's output:
                        // say so once and stop writing it.
                        if let Err(e) = writeln!(f, "{line}") {
                            eprintln!("[{who}] cannot write its log: {e}; the log ends here");
                            log = None;
                        }
                    }
                    if let Ok(mut t) = tail.lock() {
                        if t.len() == STDERR_KEPT_LINES {
                            t.pop_front();
                        }
                        t.push_back(line);
                    }
                }
            })
        });
        let tx = self.exits_tx.clone();
        std::thread::spawn(move || {
            let status = child.wait().ok();
            // The supervisor may be gone (dropped after a panic): nobody to tell.
            let _ = tx.send((index, status));
        });
        self.children.push(Child {
            spec,
            pid,
            exit: None,
            stdout,
            stdout_lines: Vec::new(),
            stderr,
            stderr_tail,
        });
        Ok(ChildId(index))
    }

    /// Every child started, in order.
    pub fn ids(&self) -> Vec<ChildId> {
        (0..self.children.len()).map(ChildId).collect()
    }

    pub fn pid(&self, id: ChildId) -> u32 {
        self.children[id.0].pid
    }

    pub fn spec(&self, id: ChildId) -> &ChildSpec {
        &self.children[id.0].spec
    }

    /// The child's exit status, once it has exited.
    pub fn exit_status(&self, id: ChildId) -> Option<ExitStatus> {
        self.children[id.0].exit
    }

    /// Takes the exits reported so far, waiting up to `timeout` for the first one.
    pub fn poll(&mut self, timeout: Duration) {
        let first = if timeout.is_zero() {
            self.exits.try_recv().ok()
        } else {
            self.exits.recv_timeout(timeout).ok()
        };
        let mut next = first;
        while let Some((i, status)) = next {
            // A child whose status could not be read counts as failed.
            self.children[i].exit = Some(
                status.unwrap_or_else(|| std::os::unix::process::ExitStatusExt::from_raw(1 << 8)),
            );
            next = self.exits.try_recv().ok();
        }
    }

    /// The first child (in start order) that exited unsuccessfully, as an error.
    pub fn check(&mut self) -> Result<(), SupervisorError> {
        self.poll(Duration::ZERO);
        for i in 0..self.children.len() {
            if let Some(status) = self.children[i].exit {
                if !status.success() {
                    return Err(self.failure(ChildId(i)));
                }
            }
        }
        Ok(())
    }

    /// The error of a child that failed: its role, robot, status and last stderr lines.
    pub fn failure(&mut self, id: ChildId) -> SupervisorError {
        let status = match self.children[id.0].exit {
            Some(s) => describe(s),
            None => "still running".to_string(),
        };
        let stderr_tail = self.stderr_tail(id);
        let spec = &self.children[id.0].spec;
        SupervisorError::Failed {
            who: spec.who(),
            role: spec.role.clone(),
            robot: spec.robot,
            status,
            stderr_tail,
        }
    }

    /// The last lines the child wrote to stderr (all of them once it has exited).
    pub fn stderr_tail(&mut self, id: ChildId) -> String {
        self.join_stderr(id);
        let c = &self.children[id.0];
        c.stderr_tail
            .lock()
            .map(|t| {
                let skip = t.len().saturating_sub(STDERR_TAIL_LINES);
                t.iter().skip(skip).cloned().collect::<Vec<_>>().join("\n")
            })
            .unwrap_or_default()
    }

    /// Once the child has exited, waits for its stderr reader (the pipe closes when the child
    /// exits). A reader that panicked left what it had read.
    fn join_stderr(&mut self, id: ChildId) {
        let c = &mut self.children[id.0];
        if c.exit.is_some() {
            if let Some(h) = c.stderr.take() {
                if h.join().is_err() {
                    eprintln!(
                        "supervisor: the stderr reader of {} panicked; its output may be cut short",
                        c.spec.who()
                    );
                }
            }
        }
    }

    /// Takes what the child has printed on stdout so far into its kept lines (all of it once
    /// it has exited: the pipe is closed by then).
    fn drain_stdout(&mut self, id: ChildId) {
        let c = &mut self.children[id.0];
        if c.exit.is_none() {
            while let Ok(l) = c.stdout.try_recv() {
                c.stdout_lines.push(l);
            }
            return;
        }
        // Exited: the reader thread may still be passing on the last lines; it ends at the
        // pipe's end (bounded: a grandchild could hold the pipe open).
        let deadline = Instant::now() + Duration::from_secs(5);
        while let Ok(l) = c
            .stdout
            .recv_timeout(deadline.saturating_duration_since(Instant::now()))
        {
            c.stdout_lines.push(l);
        }
    }

    /// Everything the child printed: its stdout and its stderr (the last lines kept), each
    /// line ending in a newline.
    pub fn output(&mut self, id: ChildId) -> (String, String) {
        self.join_stderr(id);
        self.drain_stdout(id);
        let c = &self.children[id.0];
        let join = |lines: &mut dyn Iterator<Item = &String>| {
            lines.fold(String::new(), |mut acc, l| {
                acc.push_str(l);
                acc.push('\n');
                acc
            })
        };
        let stdout = join(&mut c.stdout_lines.iter());
        let stderr = c
            .stderr_tail
            .lock()
            .map(|t| join(&mut t.iter()))
            .unwrap_or_default();
        (stdout, stderr)
    }

    /// Sends `signal` to the child unless it is known to have exited.
    pub fn signal(&self, id: ChildId, signal: nix::sys::signal::Signal) {
        let c = &self.children[id.0];
        if c.exit.is_none() {
            send_signal(c, signal);
        }
    }

    /// Waits until `id` exits (woken by its exit), at most `timeout`. Returns whether it
    /// exited.
    pub fn wait_exit(&mut self, id: ChildId, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        while self.children[id.0].exit.is_none() {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            self.poll(left);
        }
        true
    }

    /// The summary a child printed on stdout as one JSON object, once it has exited
    /// successfully. A failed child, or a missing or malformed summary, is an error naming it.
    pub fn summary<T: DeserializeOwned>(&mut self, id: ChildId) -> Result<T, SupervisorError> {
        match self.children[id.0].exit {
            Some(s) if s.success() => {}
            _ => return Err(self.failure(id)),
        }
        self.drain_stdout(id);
        let who = self.children[id.0].spec.who();
        let last = self.children[id.0]
            .stdout_lines
            .iter()
            .rev()
            .find(|l| !l.trim().is_empty())
            .cloned();
        let Some(line) = last else {
            return Err(SupervisorError::Summary {
                who,
                problem: "missing",
                detail: "it printed nothing".into(),
                stderr_tail: self.stderr_tail(id),
            });
        };
        let line = line.as_str();
        serde_json::from_str(line).map_err(|e| SupervisorError::Summary {
            who,
            problem: "malformed",
            detail: format!("{e} in {line:?}"),
            stderr_tail: self.stderr_tail(id),
        })
    }

    /// The summary a child that has exited printed last on stdout, whatever its exit status
    /// (a child stopped by SIGINT/SIGTERM prints its summary and exits 130/143); `None` when it
    /// is still running, printed none, or the line is not one JSON `T`.
    pub fn last_summary<T: DeserializeOwned>(&mut self, id: ChildId) -> Option<T> {
        self.children[id.0].exit?;
        self.drain_stdout(id);
        let line = self.children[id.0]
            .stdout_lines
            .iter()
            .rev()
            .find(|l| !l.trim().is_empty())?;
        serde_json::from_str(line).ok()
    }

    /// The next line the child prints on stdout, waiting up to `timeout`; `None` on timeout.
    /// A child that closed its stdout (exited) before printing one is an error naming it.
    pub fn next_line(
        &mut self,
        id: ChildId,
        timeout: Duration,
    ) -> Result<Option<String>, SupervisorError> {
        match self.children[id.0].stdout.recv_timeout(timeout) {
            Ok(l) => {
                self.children[id.0].stdout_lines.push(l.clone());
                Ok(Some(l))
            }
            Err(mpsc::RecvTimeoutError::Timeout) => Ok(None),
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                self.wait_exit(id, Duration::from_secs(5));
                match self.children[id.0].exit {
                    Some(s) if s.success() => Err(SupervisorError::EndedEarly {
                        who: self.children[id.0].spec.who(),
                        status: describe(s),
                        stderr_tail: self.stderr_tail(id),
                    }),
                    _ => Err(self.failure(id)),
                }
            }
        }
    }

    /// Sends `signal` to every child still running.
    fn signal_running(&self, signal: nix::sys::signal::Signal) {
        for c in self.children.iter().rev() {
            if c.exit.is_none() {
                send_signal(c, signal);
            }
        }
    }

    /// Stops every child still running: SIGTERM (each stops cleanly, as on Ctrl-C), then after
    /// `grace` SIGKILL. Returns who had to be killed.
    pub fn stop_all(&mut self, grace: Duration) -> Vec<String> {
        self.poll(Duration::ZERO);
        self.signal_running(nix::sys::signal::Signal::SIGTERM);
        let deadline = Instant::now() + grace;
        while self.children.iter().any(|c| c.exit.is_none()) {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                break;
            }
            self.poll(left);
        }
        let killed: Vec<String> = self
            .children
            .iter()
            .filter(|c| c.exit.is_none())
            .map(|c| c.spec.who())
            .collect();
        self.signal_running(nix::sys::signal::Signal::SIGKILL);
        // SIGKILL cannot be caught; the bound only guards against a child stuck in the kernel.
        let deadline = Instant::now() + Duration::from_secs(10);
        while self.children.iter().any(|c| c.exit.is_none()) && Instant::now() < deadline {
            self.poll(Duration::from_millis(500));
        }
        killed
    }

    /// Whether every child has exited.
    pub fn all_exited(&mut self) -> bool {
        self.poll(Duration::ZERO);
        self.children.iter().all(|c| c.exit.is_some())
    }
}

impl Drop for Supervisor {
    fn drop(&mut self) {
        if !self.children.iter().all(|c| c.exit.is_some()) {
            self.stop_all(Duration::from_secs(3));
        }
    }
}

/// Sends `signal` to the child. A child that exited between the check and the signal (ESRCH)
/// is not an error; any other failure is reported.
fn send_signal(c: &Child, signal: nix::sys::signal::Signal) {
    match nix::sys::signal::kill(nix::unistd::Pid::from_raw(c.pid as i32), signal) {
        Ok(()) | Err(nix::errno::Errno::ESRCH) => {}
        Err(e) => eprintln!(
            "supervisor: cannot send {signal} to {} (pid {}): {e}",
            c.spec.who(),
            c.pid
        ),
    }
}

/// "exit status 3", "killed by SIGKILL".
fn describe(s: ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match (s.code(), s.signal()) {
        (Some(c), _) => format!("exit status {c}"),
        (None, Some(sig)) => match nix::sys::signal::Signal::try_from(sig) {
            Ok(n) => format!("killed by {n}"),
            Err(_) => format!("killed by signal {sig}"),
        },
        _ => s.to_string(),
    }
}
