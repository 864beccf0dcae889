//! A Rust program that embeds the field keeps its own SIGTERM handling (issue 47): its handler
//! runs during a blocking wait on a live field, the wait returns "interrupted", every SIGTERM
//! sent from outside reaches the handler, and no signal's disposition changes. A standby's poll
//! is interrupted the same way. Then the program registers its stop flag (`shm::stop_when`),
//! which its handler sets: a busy-poll wait (no system call a signal could cut) ends
//! "interrupted", and the library's loops (lockstep's wait for participants) see the request.
//!
//! Its own test binary without libtest's harness (`harness = false`): the waits run on the main
//! thread, the only one that does not block SIGTERM, so a SIGTERM sent to the process (by the
//! `kill` command) lands in them. The field runs on a thread of this process that publishes its
//! first frame and never ticks, so only a signal can end a wait early.
#![allow(unsafe_code)]

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{mpsc, Arc, OnceLock};
use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use nix::sys::signal::{pthread_sigmask, SigSet, SigmaskHow, Signal};
use pheromone_field::process::lockstep::{Conductor, LockstepError};
use pheromone_field::shm::Svc;
use pheromone_field::shm::{
    create_node, should_stop, stop_when, DepositClient, FieldReader, FieldServer, ReceiveError,
    SendError, Standby, StandbyError, StandbyEvent, WaitPolicy,
};
use pheromone_field::{ChannelSpec, Deposit, DepositMsg, Evaporation, FieldConfig, Kernel};

static SEEN: AtomicUsize = AtomicUsize::new(0);

/// The program's stop flag, once it registered one with the library (`stop_when`).
static STOP: OnceLock<Arc<AtomicBool>> = OnceLock::new();

extern "C" fn on_term(_: libc::c_int) {
    SEEN.fetch_add(1, Ordering::SeqCst);
    // An atomic load of the cell, then an atomic store: async-signal-safe.
    if let Some(flag) = STOP.get() {
        flag.store(true, Ordering::SeqCst);
    }
}

/// The handler and flags of every signal that has a disposition.
fn dispositions() -> Vec<(i32, usize, i32)> {
    (1..65)
        .filter_map(|s| {
            // SAFETY: a zeroed sigaction is a valid output buffer; a NULL new action only reads.
            let mut old: libc::sigaction = unsafe { std::mem::zeroed() };
            // SAFETY: valid pointers for the call; `s` may be invalid, which sigaction reports.
            let ok = unsafe { libc::sigaction(s, std::ptr::null(), &mut old) } == 0;
            ok.then_some((s, old.sa_sigaction, old.sa_flags))
        })
        .collect()
}

fn install_handler() {
    // SAFETY: zeroed is a valid sigaction; the handler only touches an atomic
    // (async-signal-safe); no SA_RESTART.
    unsafe {
        let mut sa: libc::sigaction = std::mem::zeroed();
        sa.sa_sigaction = on_term as extern "C" fn(libc::c_int) as usize;
        libc::sigemptyset(&mut sa.sa_mask);
        sa.sa_flags = 0;
        assert_eq!(
            libc::sigaction(libc::SIGTERM, &sa, std::ptr::null_mut()),
            0,
            "sigaction(SIGTERM)"
        );
    }
}

/// Runs `f` on a new thread that blocks SIGTERM (it inherits the mask set around its spawn).
fn spawn_blocking_sigterm<T: Send + 'static>(
    f: impl FnOnce() -> T + Send + 'static,
) -> std::thread::JoinHandle<T> {
    let mut term = SigSet::empty();
    term.add(Signal::SIGTERM);
    pthread_sigmask(SigmaskHow::SIG_BLOCK, Some(&term), None).expect("block SIGTERM");
    let h = std::thread::spawn(f);
    pthread_sigmask(SigmaskHow::SIG_UNBLOCK, Some(&term), None).expect("unblock SIGTERM");
    h
}

/// Sends SIGTERM to this process with the `kill` command until `done` reaches `target`: one,
/// then another every 0.5 s while the step it waits for has not come (a SIGTERM that lands
/// between two waits runs the handler without interrupting a wait). Returns how many it sent.
fn sender(done: Arc<AtomicUsize>, target: usize) -> usize {
    let pid = std::process::id().to_string();
    let mut sent = 0;
    let deadline = Instant::now() + Duration::from_secs(60);
    while done.load(Ordering::SeqCst) < target {
        assert!(
            Instant::now() < deadline,
            "the waits were not all interrupted within 60 s"
        );
        let step = done.load(Ordering::SeqCst);
        let status = std::process::Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .expect("run kill");
        assert!(status.success(), "kill -TERM {pid}: {status}");
        sent += 1;
        let resend = Instant::now() + Duration::from_millis(500);
        while done.load(Ordering::SeqCst) == step && Instant::now() < resend {
            std::thread::sleep(Duration::from_millis(5));
        }
    }
    sent
}

fn config() -> FieldConfig {
    FieldConfig {
        width: 32,
        height: 32,
        cell_size_m: 0.1,
        channels: vec![ChannelSpec::new("trail", Evaporation::None)],
        ..FieldConfig::default()
    }
}

fn main() {
    const WAITS: usize = 4;
    pheromone_field::shm::set_verbose(false);
    install_handler();
    let before = dispositions();
    let name = pheromone_testkit::unique("sig");

    // The field: its first frame, then no tick until told to stop.
    let (started_tx, started_rx) = mpsc::channel();
    let (stop_tx, stop_rx) = mpsc::channel::<()>();
    let field_name = name.clone();
    let server = spawn_blocking_sigterm(move || {
        let node = create_node(&format!("{field_name}-field")).expect("field node");
        let server = FieldServer::start(&node, &field_name, config(), None).expect("field");
        started_tx.send(()).expect("tell main");
        // Hands the first frame to readers that attach (the field's history); no tick. Stops
        // after the reader and the client are gone.
        while let Err(mpsc::RecvTimeoutError::Timeout) =
            stop_rx.recv_timeout(Duration::from_millis(5))
        {
            server.serve_new_readers().expect("serve readers");
        }
        drop(server);
    });
    started_rx
        .recv_timeout(Duration::from_secs(30))
        .expect("the field started");

    let node = create_node(&format!("{name}-main")).expect("node");
    let mut reader =
        FieldReader::attach_within(&node, &name, Duration::from_secs(10)).expect("attach");
    let deadline = Instant::now() + Duration::from_secs(10);
    while reader.frame().is_none() {
        assert!(Instant::now() < deadline, "no first frame within 10 s");
        reader.update().expect("update");
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut client = DepositClient::attach(&node, &name, 3).expect("deposit client");

    let done = Arc::new(AtomicUsize::new(0));
    let sending = {
        let done = Arc::clone(&done);
        spawn_blocking_sigterm(move || sender(done, WAITS + 3))
    };
    let mut spurious = 0;
    for i in 1..=WAITS {
        let r = handled(&mut spurious, || {
            if i % 2 == 1 {
                reader.wait_frame_with(WaitPolicy::Event, Duration::from_secs(60))
            } else {
                reader.wait_frame(Duration::from_secs(60))
            }
        });
        assert!(
            matches!(r, Err(ReceiveError::Interrupted { .. })),
            "wait {i}: {r:?}, expected ReceiveError::Interrupted after the handler ran"
        );
        done.store(i, Ordering::SeqCst);
    }
    let msg = DepositMsg::from(Deposit {
        channel: 0,
        x_m: 1.0,
        y_m: 1.0,
        kernel: Kernel::Ellipse {
            tau: 0.01,
            cov_m2: [0.04, 0.0, 0.04],
            range_m: 0.5,
            gamma_max: 100.0,
        },
    });
    let r = handled(&mut spurious, || {
        client.deposit(msg, Duration::from_secs(60))
    });
    assert!(
        matches!(r, Err(SendError::Interrupted { .. })),
        "confirmed deposit: {r:?}, expected SendError::Interrupted after the handler ran"
    );
    done.store(WAITS + 1, Ordering::SeqCst);

    standby_poll_interrupted(&node, &name, &done);
    busy_poll_stops_on_the_flag(&node, &mut reader, &done);
    let sent = sending.join().expect("sender");
    lockstep_stops_on_the_flag(&node, &name);

    assert_eq!(
        SEEN.load(Ordering::SeqCst),
        sent,
        "SIGTERMs the program's handler saw, of those sent"
    );
    assert_eq!(dispositions(), before, "a signal's disposition changed");
    drop(client);
    drop(reader);
    drop(node);
    stop_tx.send(()).expect("stop the field");
    server.join().expect("field thread");
    println!(
        "signals: {WAITS} waits, a confirmed deposit, a standby poll and a busy poll interrupted; \
         the handler saw {sent} of {sent} SIGTERMs ({spurious} interruption(s) without it); \
         lockstep stopped on the program's flag"
    );
}

/// Calls `wait` until it returns after the program's handler ran during it (`SEEN` grew). An
/// "interrupted" with no run of the handler is counted in `spurious` and the wait called again:
/// Linux cuts a socket wait with a timeout short (`EINTR`) without any handler when the process
/// is stopped and continued (signal(7)), which the program's loop must take as spurious too.
fn handled<T: std::fmt::Debug, E: std::fmt::Debug>(
    spurious: &mut usize,
    mut wait: impl FnMut() -> Result<T, E>,
) -> Result<T, E> {
    loop {
        let at_start = SEEN.load(Ordering::SeqCst);
        let r = wait();
        if SEEN.load(Ordering::SeqCst) > at_start {
            return r;
        }
        assert!(
            r.is_err(),
            "the wait ended without a signal: it waits for a frame that never comes"
        );
        *spurious += 1;
        assert!(
            *spurious < 20,
            "20 interruptions without the handler: {r:?}"
        );
    }
}

/// A standby mirroring the field: a poll with no frame to mirror is cut short by a SIGTERM.
fn standby_poll_interrupted(node: &Node<Svc>, name: &str, done: &AtomicUsize) {
    let mut standby =
        Standby::attach_within(node, name, config(), Duration::from_secs(10)).expect("standby");
    let at_start = SEEN.load(Ordering::SeqCst);
    let deadline = Instant::now() + Duration::from_secs(60);
    let r = loop {
        assert!(
            Instant::now() < deadline,
            "the standby's polls were not interrupted within 60 s"
        );
        match standby.poll(Duration::from_secs(5)) {
            Ok(StandbyEvent::Mirrored { .. } | StandbyEvent::Waiting) => continue,
            // Cut short without the handler (stopped and continued): spurious, as in `handled`.
            Err(StandbyError::Interrupted { .. }) if SEEN.load(Ordering::SeqCst) == at_start => {
                continue
            }
            other => break other,
        }
    };
    assert!(
        matches!(r, Err(StandbyError::Interrupted { .. })),
        "standby poll: {r:?}, expected StandbyError::Interrupted"
    );
    assert!(
        SEEN.load(Ordering::SeqCst) > at_start,
        "standby: the handler did not run"
    );
    drop(standby);
    done.store(done.load(Ordering::SeqCst) + 1, Ordering::SeqCst);
}

/// The program registers its stop flag, which its handler sets: a busy-poll wait (no system
/// call a signal could cut) ends "interrupted".
fn busy_poll_stops_on_the_flag(node: &Node<Svc>, reader: &mut FieldReader, done: &AtomicUsize) {
    let flag = Arc::new(AtomicBool::new(false));
    assert!(stop_when(Arc::clone(&flag)), "the first stop flag is taken");
    assert!(
        !stop_when(Arc::new(AtomicBool::new(false))),
        "a second stop flag is refused"
    );
    STOP.set(Arc::clone(&flag)).expect("the handler's flag");
    assert!(!should_stop(node), "no stop before the signal");
    let r = reader.wait_frame_with(WaitPolicy::BusyPoll, Duration::from_secs(60));
    assert!(
        matches!(r, Err(ReceiveError::Interrupted { .. })),
        "busy-poll wait: {r:?}, expected ReceiveError::Interrupted"
    );
    assert!(flag.load(Ordering::SeqCst), "the handler set the flag");
    done.store(done.load(Ordering::SeqCst) + 1, Ordering::SeqCst);
}

/// A loop of the library ends on the program's flag: lockstep's wait for participants that
/// never come.
fn lockstep_stops_on_the_flag(node: &Node<Svc>, name: &str) {
    assert!(should_stop(node), "should_stop after the flag is set");
    let conductor = Conductor::create(node, &format!("{name}-world"), true).expect("conductor");
    let r = conductor.wait_for_participants(node, 1, "robots", Duration::from_secs(60));
    assert!(
        matches!(r, Err(LockstepError::Interrupted { .. })),
        "lockstep wait: {r:?}, expected LockstepError::Interrupted"
    );
    drop(conductor);
}
