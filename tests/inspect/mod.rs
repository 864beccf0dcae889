//! `pheromone list`, `probe --follow` and `export` errors, each test in its own iceoryx2 prefix.
//!
//! Inspecting a host's fields (issue 16): `pheromone list` (fields found through iceoryx2's
//! service listing, tick rate over a window, readers and depositors), `pheromone probe
//! --follow` until Ctrl-C, and `pheromone export` errors. Every test runs in a `Run` of its own
//! (its own iceoryx2 prefix), so `list` sees exactly the test's fields and "nothing left" is
//! exact.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use serde_json::Value;

use crate::crash::{Run, WAIT};
use crate::harness::*;

fn start_field(run: &Run, name: &str, grid: (&str, &str), tick_hz: &str) -> Proc {
    let field = Cmd::field(name)
        .grid(grid.0, grid.1)
        .cell_size(0.1)
        .tick_hz(tick_hz)
        .model("none")
        .json();
    run.spawn(&field.argv(), name)
}

fn list(run: &Run) -> Vec<Value> {
    let o = run.run(&["list", "--json", "--window-s", "1"]);
    assert!(o.status.success(), "list: {:?} {}", o.status, stderr(&o));
    json(&o)["fields"].as_array().cloned().unwrap_or_default()
}

fn find<'a>(fields: &'a [Value], name: &str) -> Option<&'a Value> {
    fields.iter().find(|f| f["name"] == name)
}

/// `probe --follow` with its stdout piped; lines arrive on the channel.
struct Follower {
    child: std::process::Child,
    lines: mpsc::Receiver<String>,
}

impl Follower {
    fn start(run: &Run, field: &str, rate_hz: &str) -> Self {
        let mut child = Command::new(bin())
            .args([
                "probe", "--field", field, "--x", "0.5", "--y", "0.5", "--follow",
            ])
            .args(["--rate-hz", rate_hz, "--timeout", "20"])
            .env_remove(pheromone_field::shm::IOX_DOMAIN_ENV)
            .current_dir(&run.dir)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start probe --follow");
        let stdout = child.stdout.take().unwrap();
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Self { child, lines }
    }

    fn line(&self) -> String {
        self.lines
            .recv_timeout(WAIT)
            .expect("probe --follow printed no line")
    }

    /// Ctrl-C; returns the exit status and stderr.
    fn interrupt(mut self) -> (std::process::ExitStatus, String) {
        kill(Pid::from_raw(self.child.id() as i32), Signal::SIGINT).unwrap();
        let deadline = Instant::now() + WAIT;
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                let mut err = String::new();
                use std::io::Read;
                let _ = self.child.stderr.take().unwrap().read_to_string(&mut err);
                return (status, err);
            }
            assert!(Instant::now() < deadline, "probe --follow ignored SIGINT");
            std::thread::park_timeout(Duration::from_millis(20));
        }
    }
}

impl Drop for Follower {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn list_shows_two_fields_with_rates_and_readers_then_one_when_a_field_stops() {
    let run = Run::new("ls");
    let a = start_field(&run, "la", ("40", "30"), "50");
    let b = start_field(&run, "lb", ("20", "10"), "10");
    // A reader on `la` for the whole test, and a depositor on `lb` (in this process).
    let reader = Follower::start(&run, "la", "5");
    reader.line();
    let node = run.node("list-test");
    let depositor = eventually(WAIT, "a depositor on lb", || {
        pheromone_field::shm::DepositPublisher::attach(&node, "lb", 3).ok()
    });
    let fields = eventually(WAIT, "list to show both fields", || {
        let f = list(&run);
        (f.len() == 2).then_some(f)
    });
    let (fa, fb) = (find(&fields, "la").unwrap(), find(&fields, "lb").unwrap());
    eprintln!("list: {fields:?}");
    for (f, w, h, hz) in [(fa, 40, 30, 50.0), (fb, 20, 10, 10.0)] {
        assert_eq!(
            (f["width"].as_u64(), f["height"].as_u64()),
            (Some(w), Some(h)),
            "{f}"
        );
        assert_eq!(f["channels"], 1, "{f}");
        assert!(
            (f["cell_size_m"].as_f64().unwrap() - 0.1).abs() < 1e-6,
            "{f}"
        );
        assert_eq!(f["alive"], true, "{f}");
        // Frames come (the field ticks on wall time; a busy host may tick it slower, never
        // faster than asked).
        let rate = f["tick_hz"].as_f64().unwrap();
        assert!(rate > 0.0 && rate <= hz * 1.5, "tick_hz {rate} of {f}");
        assert!(f["sequence"].as_u64().unwrap() > 0, "{f}");
    }
    assert_eq!(fa["readers"], 1, "the probe reads la: {fa}");
    assert_eq!(fb["readers"], 0, "{fb}");
    assert_eq!(fa["depositors"], 0, "{fa}");
    assert_eq!(fb["depositors"], 1, "this test deposits on lb: {fb}");

    // The text form has a row per field.
    let o = run.run(&["list", "--window-s", "0.3"]);
    let text = stdout(&o);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        text.lines()
            .any(|l| l.starts_with("la ") && l.contains("40×30") && l.ends_with("alive")),
        "{text}"
    );
    assert!(
        text.lines()
            .any(|l| l.starts_with("lb ") && l.contains("20×10")),
        "{text}"
    );

    drop(depositor);
    b.interrupt();
    let out = b.wait_exit(WAIT);
    assert!(
        out.status.code() == Some(130),
        "lb: {:?} {}",
        out.status,
        run.log("lb")
    );
    let fields = eventually(WAIT, "list to show one field", || {
        let f = list(&run);
        (f.len() == 1).then_some(f)
    });
    assert_eq!(fields[0]["name"], "la", "{fields:?}");
    assert_eq!(fields[0]["readers"], 1, "{fields:?}");

    let (status, err) = reader.interrupt();
    assert!(status.success(), "probe --follow: {status:?} {err}");
    drop(node);
    a.interrupt();
    let out = a.wait_exit(WAIT);
    assert!(
        out.status.code() == Some(130),
        "la: {:?} {}",
        out.status,
        run.log("la")
    );
    run.wait_nodes_gone(Duration::from_secs(10));
    assert_eq!(run.shm_entries(), Vec::<String>::new());
    assert!(list(&run).is_empty());
}

/// A field stopped with SIGSTOP is listed as stopped (its process is there, no frame comes),
/// not left out as if no field ran; after SIGCONT it is alive again with its grid.
#[test]
fn list_shows_a_stopped_field_as_stopped_not_gone() {
    let run = Run::new("lstop");
    let field = start_field(&run, "ls", ("24", "16"), "50");
    eventually(WAIT, "list to show the field alive", || {
        let f = list(&run);
        (find(&f, "ls")?["alive"] == true).then_some(())
    });
    let pid = Pid::from_raw(field.pid() as i32);
    kill(pid, Signal::SIGSTOP).unwrap();
    let fields = list(&run);
    let stopped =
        find(&fields, "ls").unwrap_or_else(|| panic!("a stopped field is listed: {fields:?}"));
    assert_eq!(stopped["alive"], false, "{stopped}");
    assert_eq!(stopped["publisher_alive"], true, "{stopped}");
    // A stopped field sends no frame: its grid is unknown, not made up.
    assert!(
        stopped["width"].is_null() && stopped["sequence"].is_null(),
        "{stopped}"
    );
    assert_eq!(stopped["tick_hz"], 0.0, "{stopped}");
    let o = run.run(&["list", "--window-s", "0.3"]);
    let text = stdout(&o);
    assert!(
        text.lines()
            .any(|l| l.starts_with("ls ") && l.contains("stopped (")),
        "{text}"
    );
    kill(pid, Signal::SIGCONT).unwrap();
    let alive = eventually(WAIT, "the field alive again", || {
        let f = list(&run);
        let f = find(&f, "ls")?.clone();
        (f["alive"] == true).then_some(f)
    });
    assert_eq!(
        (alive["width"].as_u64(), alive["height"].as_u64()),
        (Some(24), Some(16))
    );
    field.interrupt();
    let out = field.wait_exit(WAIT);
    assert_eq!(out.status.code(), Some(130), "{}", run.log("ls"));
    run.wait_nodes_gone(Duration::from_secs(10));
    assert_eq!(run.shm_entries(), Vec::<String>::new());
}

#[test]
fn list_shows_a_field_whose_reader_slots_are_all_taken_and_does_not_fail() {
    // Seen in CI: another test's field with every reader slot taken made `list` fail for the
    // whole host ("create subscriber failed: ExceedsMaxSupportedSubscribers").
    let run = Run::new("lfull");
    let field = Cmd::field("lf")
        .grid(24, 16)
        .tick_hz(50)
        .opt("--max-readers", 1)
        .json();
    let field = run.spawn(&field.argv(), "lf");
    let reader = run.spawn(
        &Cmd::probe("lf").opt("--above", "1e9").timeout(60).argv(),
        "reader",
    );
    let full = eventually(WAIT, "list to show the field full", || {
        let f = list(&run);
        let f = find(&f, "lf")?.clone();
        (f["readers_full"] == true).then_some(f)
    });
    assert!(full["width"].is_null(), "{full}");
    assert_eq!(full["publisher_alive"], true, "{full}");
    let o = run.run(&["list", "--window-s", "0.3"]);
    assert!(
        stdout(&o)
            .lines()
            .any(|l| l.starts_with("lf ") && l.contains("full (")),
        "{}",
        stdout(&o)
    );
    reader.interrupt();
    reader.wait_exit(WAIT);
    field.interrupt();
    let out = field.wait_exit(WAIT);
    assert_eq!(out.status.code(), Some(130), "{}", run.log("lf"));
    run.wait_nodes_gone(Duration::from_secs(10));
    assert_eq!(run.shm_entries(), Vec::<String>::new());
}

#[test]
fn probe_follow_prints_lines_until_ctrl_c_and_leaves_nothing() {
    let run = Run::new("pf");
    let field = start_field(&run, "pf", ("30", "20"), "50");
    let probe = Follower::start(&run, "pf", "20");
    let seq_of = |l: &str| -> u64 {
        assert!(
            l.contains("(30×20×1, 0.1 m): value at (0.5, 0.5) channel 0 = 0"),
            "{l}"
        );
        l.strip_prefix("frame ")
            .and_then(|r| r.split_whitespace().next())
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("no sequence in {l}"))
    };
    // The lines follow the field: non-decreasing, and a newer frame within the deadline (a
    // loaded host may starve the field for a few lines).
    let mut seqs = vec![seq_of(&probe.line())];
    eventually(WAIT, "a line with a newer frame", || {
        seqs.push(seq_of(&probe.line()));
        (seqs[seqs.len() - 1] > seqs[0]).then_some(())
    });
    assert!(seqs.windows(2).all(|w| w[0] <= w[1]), "{seqs:?}");
    let (status, err) = probe.interrupt();
    assert!(
        status.success(),
        "probe --follow after SIGINT: {status:?} {err}"
    );
    field.interrupt();
    let out = field.wait_exit(WAIT);
    assert_eq!(out.status.code(), Some(130), "{}", run.log("pf"));
    run.wait_nodes_gone(Duration::from_secs(10));
    assert_eq!(run.shm_entries(), Vec::<String>::new());
}

#[test]
fn export_refuses_bad_arguments_with_status_2() {
    let run = Run::new("ex");
    for (args, needle) in [
        (
            &["export", "--field", "nf", "--out", "x.png"][..],
            "--out x.png",
        ),
        (
            &[
                "export",
                "--field",
                "nf",
                "--out",
                "x.npy",
                "--timeout-s",
                "0",
            ][..],
            "--timeout-s 0",
        ),
        (
            &["probe", "--field", "nf", "--follow", "--rate-hz", "0"][..],
            "--rate-hz 0",
        ),
        (&["list", "--window-s=-1"][..], "--window-s -1"),
    ] {
        let o = run.run(args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
        assert!(e.contains(needle), "{args:?}: {e}");
    }
}
