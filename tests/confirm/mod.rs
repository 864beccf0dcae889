//! Confirmed deposits (`pheromone deposit`, docs/field.md): applied in the frame the receipt
//! names at 0.2 Hz and 100 Hz, refusals exit 2 naming the value, and a sender SIGKILLed while it
//! waits never gets its deposit applied twice.

use std::time::Duration;

use crate::harness::*;

/// A field with no evaporation at `hz`, so the applied count and the mass are exact.
fn field(name: &str, hz: f64) -> Proc {
    Proc::spawn(
        &Cmd::field(name)
            .grid(64, 64)
            .cell_size(0.1)
            .model("none")
            .tick_hz(hz)
            .duration(120)
            .json()
            .argv(),
    )
}

/// The field's cumulative counters, read from its newest frame by `pheromone probe --json`.
fn counters(name: &str) -> serde_json::Value {
    let o = run(&Cmd::probe(name).timeout(30).json().argv());
    assert!(o.status.success(), "probe: {}", stderr(&o));
    json(&o)
}

/// The frame sequence a receipt names in "applied by field 'F' in frame N".
fn applied_frame(o: &std::process::Output) -> u64 {
    let text = stderr(o);
    let rest = text
        .split("in frame ")
        .nth(1)
        .unwrap_or_else(|| panic!("no frame in: {text}"));
    rest.split(':').next().unwrap().parse().unwrap()
}

#[test]
fn a_confirmed_deposit_is_applied_before_the_command_exits_at_0_2_hz_and_100_hz() {
    for (hz, senders) in [(0.2, 3), (100.0, 5)] {
        let name = unique("confirm");
        let f = field(&name, hz);
        // Senders in parallel, each its own process that exits as soon as it is confirmed: at
        // 0.2 Hz, before the fix, most such deposits were lost.
        let procs: Vec<_> = (0..senders)
            .map(|i| {
                let x = 1.0 + i as f64;
                let argv = Cmd::deposit(&name)
                    .at(x, 3.0)
                    .amount(0.5)
                    .timeout(30)
                    .opt("--robot", i)
                    .into_args();
                std::thread::spawn(move || {
                    let refs: Vec<&str> = argv.iter().map(String::as_str).collect();
                    run(&refs)
                })
            })
            .collect();
        let mut frames = Vec::new();
        for p in procs {
            let o = p.join().unwrap();
            assert!(o.status.success(), "{hz} Hz: {}", stderr(&o));
            frames.push(applied_frame(&o));
        }
        // Every sender has exited: every deposit is in the field, once.
        let c = counters(&name);
        assert_eq!(c["deposits_applied"], senders, "{hz} Hz: {c}");
        assert!(
            c["sequence"].as_u64().unwrap() >= *frames.iter().max().unwrap(),
            "{hz} Hz: {c} {frames:?}"
        );
        f.interrupt();
        let summary = json(&f.wait_exit(Duration::from_secs(20)));
        assert_eq!(summary["deposits_applied"], senders, "{summary}");
    }
}

#[test]
fn refused_deposits_exit_2_naming_the_value_and_no_wait_still_sends() {
    let name = unique("confirm-bad");
    let f = field(&name, 100.0);
    let bad_channel = run(&Cmd::deposit(&name)
        .at(1, 1)
        .amount(1)
        .opt("--channel", 7)
        .timeout(30)
        .argv());
    assert_eq!(
        bad_channel.status.code(),
        Some(2),
        "{}",
        stderr(&bad_channel)
    );
    assert!(
        stderr(&bad_channel).contains("channel = 7"),
        "{}",
        stderr(&bad_channel)
    );
    // A NaN never leaves the command.
    let nan = run(&Cmd::deposit(&name).at("nan", 1).amount(1).argv());
    assert_eq!(nan.status.code(), Some(2), "{}", stderr(&nan));
    assert!(stderr(&nan).contains("--x nan"), "{}", stderr(&nan));
    // Fire and forget: exit 0 without a receipt; the field still applies it.
    let sent = run(&Cmd::deposit(&name)
        .at(2, 2)
        .amount(1)
        .arg("--no-wait")
        .timeout(30)
        .argv());
    assert!(sent.status.success(), "{}", stderr(&sent));
    assert!(stderr(&sent).contains("not confirmed"), "{}", stderr(&sent));
    f.interrupt();
    let summary = json(&f.wait_exit(Duration::from_secs(20)));
    assert_eq!(summary["deposits_applied"], 1, "{summary}");
    assert_eq!(
        summary["deposits_rejected"]["unknown_channel"], 1,
        "{summary}"
    );
    assert_eq!(
        summary["deposits_rejected"]["non_finite"], 0,
        "the NaN was never sent: {summary}"
    );
}

#[test]
fn a_sender_killed_while_it_waits_for_its_receipt_is_applied_at_most_once() {
    let name = unique("confirm-kill");
    let f = field(&name, 0.2);
    let node = pheromone_field::shm::create_node(&unique("confirm-watch")).unwrap();
    let watch = eventually(Duration::from_secs(30), "the field's services", || {
        pheromone_field::shm::FieldWatch::open(&node, &name).ok()
    });
    let first = counters(&name)["sequence"].as_u64().unwrap();
    let kills = 3;
    for i in 0..kills {
        let sender = Proc::spawn(
            &Cmd::deposit(&name)
                .at(2, 2)
                .amount(1)
                .opt("--robot", i)
                .timeout(30)
                .argv(),
        );
        // The sender is attached (its client port is up) and sends as soon as it is: SIGKILL it
        // while it waits for the next tick.
        eventually(Duration::from_secs(30), "the sender's client port", || {
            (watch.status().confirm_clients == 1).then_some(())
        });
        sender.kill();
        eventually(
            Duration::from_secs(30),
            "the killed sender cleaned up",
            || (watch.status().confirm_clients == 0).then_some(()),
        );
    }
    // One more tick: whatever was taken is applied by then.
    let mut reader =
        pheromone_field::shm::FieldReader::attach_within(&node, &name, Duration::from_secs(30))
            .unwrap();
    let last = reader
        .wait_until(Duration::from_secs(30), |f| f.header.sequence > first + 1)
        .unwrap();
    assert!(last.is_some(), "no new frame");
    f.interrupt();
    let summary = json(&f.wait_exit(Duration::from_secs(20)));
    let applied = summary["deposits_applied"].as_u64().unwrap();
    eprintln!("{applied} of {kills} killed senders' deposits applied");
    assert!(applied <= kills as u64, "applied twice: {summary}");
}

#[test]
fn no_wait_to_a_field_slower_than_1_hz_waits_until_taken_and_a_stopped_field_exits_3() {
    use nix::sys::signal::{kill, Signal};
    use nix::unistd::Pid;
    // One tick every 2.5 s: each deposit waits longer in the queue than the publisher's own
    // 1 s flush on drop, which lost every one of them (issue 54 item 3).
    let name = unique("nowait-slow");
    let f = field(&name, 0.4);
    let no_wait = || {
        Cmd::deposit(&name)
            .at(2, 2)
            .amount(1)
            .arg("--no-wait")
            .timeout(30)
    };
    for _ in 0..2 {
        let o = run(&no_wait().argv());
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(stderr(&o).contains("taken by field"), "{}", stderr(&o));
    }
    eventually(Duration::from_secs(30), "both deposits applied", || {
        (counters(&name)["deposits_applied"] == 2).then_some(())
    });
    // A stopped field takes nothing: "queued, not confirmed", exit 3.
    let pid = Pid::from_raw(f.pid() as i32);
    kill(pid, Signal::SIGSTOP).unwrap();
    let o = run(&no_wait().opt("--receipt-timeout", 1).argv());
    kill(pid, Signal::SIGCONT).unwrap();
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("queued") && stderr(&o).contains("not confirmed"),
        "{}",
        stderr(&o)
    );
    f.interrupt();
    // Once this field ran on after SIGINT: the pacing's sleep between deposits had read and
    // cleared iceoryx2's record of it (now latched, field/tests/termination_latch.rs).
    let summary = json(&f.wait_exit(Duration::from_secs(20)));
    assert!(
        summary["deposits_applied"].as_u64().unwrap() >= 2,
        "{summary}"
    );
}
