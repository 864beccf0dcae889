//! Peer processes: the bench starts each measured party as a separate process (the same binary,
//! a hidden subcommand), hands it a `PeerSpec` as JSON, and reads two lines from its stdout:
//! `ready` once its ports exist, then one JSON `PeerResult` when it is done.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use crate::BenchError;

/// How to start a peer: the program and the arguments before the spec (e.g. the current
/// executable and `bench-peer --spec`).
#[derive(Debug, Clone)]
pub struct Launcher {
    pub program: PathBuf,
    pub args: Vec<String>,
}

/// Transport a frame reader receives on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum FrameTransport {
    /// `field::shm::FieldReader`: the frame in shared memory, no copy.
    Ours,
    /// The plane serialized with serde (postcard) over a Unix domain socket.
    UdsSerde,
    /// The plane as bytes over Zenoh on loopback TCP.
    Zenoh,
}

/// What a peer process does.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum PeerSpec {
    /// Answers every ping on `ping` with the same message on `pong`, `count` times.
    HopEcho {
        raw: bool,
        busy: bool,
        ping: String,
        pong: String,
        count: usize,
        core: Option<usize>,
    },
    /// Receives frames; records (receive time − publish stamp) for `count` frames after skipping
    /// `skip`.
    FrameReader {
        transport: FrameTransport,
        /// Field name, socket path or Zenoh endpoint.
        source: String,
        busy: bool,
        skip: usize,
        count: usize,
        core: Option<usize>,
    },
    /// Runs a field ticking at `tick_hz` until terminated.
    Field {
        name: String,
        width: u32,
        tick_hz: f32,
        core: Option<usize>,
    },
}

/// What a peer reports when done.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct PeerResult {
    pub samples_ns: Vec<u64>,
}

enum Line {
    Text(String),
    Eof,
}

/// A running peer process: terminated (SIGTERM, then SIGKILL) and reaped when dropped.
pub struct Peer {
    child: Child,
    what: String,
    lines: mpsc::Receiver<Line>,
    exited: bool,
}

impl Peer {
    pub fn spawn(launcher: &Launcher, spec: &PeerSpec) -> Result<Self, BenchError> {
        let json = serde_json::to_string(spec).map_err(|e| BenchError::Peer(e.to_string()))?;
        let mut child = Command::new(&launcher.program)
            .args(&launcher.args)
            .arg(&json)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| BenchError::Io {
                what: format!("start peer {}", launcher.program.display()),
                source: e,
            })?;
        let stdout = child.stdout.take().expect("stdout is piped");
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines() {
                match line {
                    Ok(l) => {
                        if tx.send(Line::Text(l)).is_err() {
                            return;
                        }
                    }
                    Err(_) => break,
                }
            }
            let _ = tx.send(Line::Eof);
        });
        Ok(Self {
            child,
            what: format!("{spec:?}"),
            lines,
            exited: false,
        })
    }

    fn next_line(&mut self, deadline: Instant) -> Result<String, BenchError> {
        if self.exited {
            return Err(BenchError::Peer(format!("peer {} has exited", self.what)));
        }
        let left = deadline.saturating_duration_since(Instant::now());
        match self.lines.recv_timeout(left) {
            Ok(Line::Text(l)) => Ok(l),
            Ok(Line::Eof) | Err(mpsc::RecvTimeoutError::Disconnected) => {
                self.exited = true;
                let status = self.child.wait().ok();
                Err(BenchError::Peer(format!(
                    "peer {} exited early ({status:?})",
                    self.what
                )))
            }
            Err(mpsc::RecvTimeoutError::Timeout) => Err(BenchError::Peer(format!(
                "peer {} did not answer in time",
                self.what
            ))),
        }
    }

    /// Waits until the peer says `ready`.
    pub fn wait_ready(&mut self, timeout: Duration) -> Result<(), BenchError> {
        let line = self.next_line(Instant::now() + timeout)?;
        if line.trim() == "ready" {
            Ok(())
        } else {
            Err(BenchError::Peer(format!(
                "peer {} said '{line}' instead of 'ready'",
                self.what
            )))
        }
    }

    /// The peer's result, if it has printed it (does not wait).
    pub fn try_result(&mut self) -> Result<Option<PeerResult>, BenchError> {
        match self.next_line(Instant::now()) {
            Ok(l) => parse_result(&l).map(Some),
            Err(e) if self.exited => Err(e),
            Err(_) => Ok(None),
        }
    }

    /// Waits for the peer's result.
    pub fn result(&mut self, timeout: Duration) -> Result<PeerResult, BenchError> {
        let line = self.next_line(Instant::now() + timeout)?;
        parse_result(&line)
    }
}

fn parse_result(line: &str) -> Result<PeerResult, BenchError> {
    serde_json::from_str(line)
        .map_err(|e| BenchError::Peer(format!("peer printed '{line}' instead of a result: {e}")))
}

impl Drop for Peer {
    fn drop(&mut self) {
        if self.exited {
            return;
        }
        use nix::sys::signal::{kill, Signal};
        use nix::unistd::Pid;
        let pid = Pid::from_raw(self.child.id() as i32);
        // A peer handles SIGTERM (its iceoryx2 node stops waiting) and removes its services.
        let _ = kill(pid, Signal::SIGTERM);
        let deadline = Instant::now() + Duration::from_secs(2);
        loop {
            match self
                .lines
                .recv_timeout(deadline.saturating_duration_since(Instant::now()))
            {
                Ok(Line::Text(_)) => continue,
                Ok(Line::Eof) | Err(mpsc::RecvTimeoutError::Disconnected) => break,
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    let _ = self.child.kill();
                    break;
                }
            }
        }
        let _ = self.child.wait();
    }
}

/// Tells the parent this peer is ready.
pub fn say_ready() {
    println!("ready");
}

/// Prints the result line.
pub fn say_result(r: &PeerResult) {
    println!(
        "{}",
        serde_json::to_string(r).expect("a list of integers serializes")
    );
}
