//! Crashes, restarts, checkpoints and the standby field: the field or its standby keeps serving.
//!
//! Crashes, restarts, checkpoints and the standby field (docs/reliability.md): processes are
//! killed with SIGKILL at arbitrary points and the field (or its standby) must keep serving.
//!
//! Times are measured and printed (run with `--nocapture` to see them), never asserted.

use std::time::Duration;

use iceoryx2::prelude::Node;
use pheromone_field::process::checkpoint;
use pheromone_field::shm::{create_node, now_ns, DepositPublisher, FieldReader, FieldWatch, Svc};
use pheromone_field::DepositMsg;
use pheromone_field::{Deposit, Kernel};

use crate::harness::*;

const WAIT: Duration = Duration::from_secs(30);

/// A small field on wall time with no evaporation, so values are exact.
fn small_field(name: &str) -> Cmd {
    Cmd::field(name)
        .grid(64, 64)
        .cell_size(0.1)
        .model("none")
        .tick_hz(50)
        .duration(120)
        .json()
}

fn watch(node: &Node<Svc>, name: &str) -> FieldWatch {
    eventually(WAIT, "the field's services", || {
        FieldWatch::open(node, name).ok()
    })
}

/// A deposit of amount `tau` at (x, y) through the CLI (its own process).
fn deposit(name: &str, x: f32, y: f32, tau: f32) {
    let o = run(&Cmd::deposit(name).at(x, y).amount(tau).timeout(30).argv());
    assert!(o.status.success(), "deposit: {}", stderr(&o));
}

fn value_at(reader: &mut FieldReader, x: f32, y: f32, above: f32, what: &str) -> f32 {
    let frame = reader
        .wait_until(WAIT, |f| f.view.value(0, x, y) > above)
        .expect("wait for frames");
    match frame {
        Some(f) => f.view.value(0, x, y),
        None => panic!("{what}: the value at ({x}, {y}) never rose above {above}"),
    }
}

#[test]
fn readers_killed_while_holding_frames_are_cleaned_up_and_the_field_keeps_publishing() {
    let name = unique("rel-readers");
    let field = Proc::spawn(&small_field(&name).opt("--max-readers", 2).argv());
    let node = create_node(&unique("rel-watch")).unwrap();
    let w = watch(&node, &name);
    eventually(WAIT, "the field's publisher", || {
        (w.status().publishers == 1).then_some(())
    });
    // Twice as many readers as the field admits, one after the other, each killed while it
    // holds frames (a probe waiting for a value that never comes holds the newest frame).
    let kills = 4;
    for i in 0..kills {
        let reader = Proc::spawn(&Cmd::probe(&name).opt("--above", "1e9").timeout(60).argv());
        eventually(WAIT, &format!("reader {i} to attach"), || {
            (w.status().subscribers == 2).then_some(())
        });
        // SIGKILL + reap. The field cleans up once a second (any process starting on the host
        // also cleans up dead nodes, so which one did it is not asserted).
        drop(reader);
        eventually(WAIT, &format!("reader {i} to be cleaned up"), || {
            (w.status().subscribers == 1).then_some(())
        });
    }
    // The pool is not exhausted: a new reader gets fresh frames, and deposits still land.
    deposit(&name, 3.2, 3.2, 0.5);
    let mut reader = FieldReader::attach_within(&node, &name, WAIT).unwrap();
    value_at(&mut reader, 3.2, 3.2, 1.0, "after the kills");
    let first = reader.frame().unwrap().header.sequence;
    let next = reader
        .wait_until(WAIT, |f| f.header.sequence > first + 5)
        .unwrap();
    assert!(
        next.is_some(),
        "the field stopped publishing after frame {first}"
    );
    drop(reader);
    field.interrupt();
    let out = field.wait_exit(WAIT);
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    let s = json(&out);
    assert!(s["longest_tick_gap_ms"].as_f64().unwrap() > 0.0, "{s}");
    eprintln!(
        "readers killed: {kills}; field ticks {}, dead nodes it cleaned {}, longest gap {} ms",
        s["ticks"], s["dead_nodes_cleaned"], s["longest_tick_gap_ms"]
    );
}

#[test]
fn a_killed_depositor_is_cleaned_up_and_a_restarted_one_attaches() {
    let name = unique("rel-dep");
    let world = unique("rel-world");
    // One depositor at a time: a dead one's port must be freed for the next.
    let field = Proc::spawn(&small_field(&name).opt("--max-depositors", 1).argv());
    let node = create_node(&unique("rel-watch")).unwrap();
    let w = watch(&node, &name);
    for i in 0..3 {
        let depositor = Proc::spawn(&[
            "depositor",
            "--scenario",
            "trail",
            "--world",
            &world,
            "--field",
            &name,
        ]);
        eventually(WAIT, &format!("depositor {i} to attach"), || {
            (w.status().depositors == 1).then_some(())
        });
        drop(depositor);
        eventually(
            WAIT,
            &format!("the field to clean up depositor {i}"),
            || (w.status().depositors == 0).then_some(()),
        );
    }
    // A restarted depositor attaches and its deposit is applied.
    deposit(&name, 2.0, 2.0, 0.5);
    let mut reader = FieldReader::attach_within(&node, &name, WAIT).unwrap();
    value_at(
        &mut reader,
        2.0,
        2.0,
        1.0,
        "the restarted depositor's deposit",
    );
    drop(reader);
    field.interrupt();
    let s = json(&field.wait_exit(WAIT));
    assert_eq!(s["deposits_applied"], 1, "{s}");
    eprintln!(
        "depositors killed: 3; longest gap between frames {} ms",
        s["longest_tick_gap_ms"]
    );
}

#[test]
fn a_reader_keeps_its_frame_when_the_field_is_killed_and_sees_the_field_restarted_under_that_name()
{
    let name = unique("rel-restart");
    let node = create_node(&unique("rel-reader")).unwrap();
    let field = Proc::spawn(&small_field(&name).argv());
    deposit(&name, 3.0, 3.0, 0.5);
    let mut reader = FieldReader::attach_within(&node, &name, WAIT).unwrap();
    let before = value_at(&mut reader, 3.0, 3.0, 1.0, "the first field");
    assert!(reader.field_alive());
    assert_eq!(reader.generation(), 1, "frames of one field process");
    drop(field); // SIGKILL
    eventually(WAIT, "the reader to notice the field is gone", || {
        (!reader.field_alive()).then_some(())
    });
    // No frame comes, and the last one is still readable.
    reader.update().unwrap();
    let last = reader.frame().expect("the last frame is kept");
    assert_eq!(last.view.value(0, 3.0, 3.0), before);
    let (last_sequence, last_stamp) = (last.header.sequence, last.header.stamp_ns);
    // The same name again: no stale-service trap.
    let field = Proc::spawn(&small_field(&name).argv());
    let frame = reader
        .wait_until(WAIT, |f| f.header.stamp_ns > last_stamp)
        .unwrap()
        .unwrap_or_else(|| panic!("no frame of the restarted field (last {last_sequence})"));
    // A new field without --restore starts empty.
    assert_eq!(frame.view.value(0, 3.0, 3.0), 0.0);
    assert!(reader.field_alive());
    assert_eq!(
        reader.generation(),
        2,
        "the restarted field is the second process read"
    );
    deposit(&name, 1.0, 1.0, 0.5);
    value_at(&mut reader, 1.0, 1.0, 1.0, "the restarted field");
    drop(reader);
    field.interrupt();
    let out = field.wait_exit(WAIT);
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
}

#[test]
fn a_checkpoint_restores_a_killed_field_and_a_damaged_one_is_refused() {
    let name = unique("rel-ckpt");
    let dir = std::env::temp_dir().join(unique("rel-ckpt"));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("field.ckpt");
    let file_s = file.to_str().unwrap();
    let node = create_node(&unique("rel-reader")).unwrap();
    let field = Proc::spawn(
        &small_field(&name)
            .opt("--checkpoint", file_s)
            .opt("--checkpoint-every", 0.2)
            .argv(),
    );
    deposit(&name, 3.0, 3.0, 0.5);
    let mut reader = FieldReader::attach_within(&node, &name, WAIT).unwrap();
    let value = value_at(&mut reader, 3.0, 3.0, 1.0, "the deposit");
    // Wait for a checkpoint written after the deposit landed.
    eventually(WAIT, "a checkpoint holding the deposit", || {
        checkpoint::read(&file)
            .ok()
            .filter(|c| c.header.deposits_applied == 1)
    });
    drop(field); // SIGKILL, possibly while writing: only complete checkpoints exist
    let killed_ns = now_ns();
    let cp = checkpoint::read(&file).expect("the last checkpoint is complete");
    assert_eq!(cp.header.deposits_applied, 1);
    // Restore: the value is back, the sequence and field time continue.
    let restored = Proc::spawn(&small_field(&name).opt("--restore", file_s).argv());
    let frame = reader
        .wait_until(WAIT, |f| {
            f.header.stamp_ns > killed_ns && f.header.sequence > cp.header.sequence
        })
        .unwrap()
        .expect("frames of the restored field");
    assert_eq!(frame.view.value(0, 3.0, 3.0), value);
    assert!(frame.header.sim_time_s > cp.header.sim_time_s);
    drop(reader);
    restored.interrupt();
    let s = json(&restored.wait_exit(WAIT));
    assert_eq!(s["restored_sequence"], cp.header.sequence, "{s}");
    assert_eq!(s["deposits_applied"], 1, "{s}");
    // Damaged files: refused with status 2, naming the file and the problem.
    let bytes = std::fs::read(&file).unwrap();
    let cases: [(&str, Vec<u8>, &str); 3] = [
        ("truncated", bytes[..bytes.len() / 2].to_vec(), "truncated"),
        (
            "flipped",
            {
                let mut b = bytes.clone();
                let i = b.len() - 100;
                b[i] ^= 0x01;
                b
            },
            "checksum",
        ),
        (
            "garbage",
            b"not a checkpoint at all".to_vec(),
            "not a pheromone checkpoint",
        ),
    ];
    for (what, content, expect) in cases {
        let bad = dir.join(format!("{what}.ckpt"));
        std::fs::write(&bad, content).unwrap();
        let o = run(&Cmd::field(&unique("rel-bad"))
            .grid(64, 64)
            .cell_size(0.1)
            .opt("--restore", bad.display())
            .ticks(1)
            .argv());
        assert_eq!(o.status.code(), Some(2), "{what}: {}", stderr(&o));
        let e = stderr(&o);
        assert!(
            e.contains(&format!("{what}.ckpt")) && e.contains(expect),
            "{what}: {e}"
        );
    }
    // Another grid than the checkpoint's is refused too.
    let o = run(&Cmd::field(&unique("rel-bad"))
        .opt("--restore", file_s)
        .ticks(1)
        .argv());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("64×64"), "{}", stderr(&o));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_standby_takes_over_when_the_primary_is_killed_and_keeps_the_deposits() {
    let name = unique("rel-standby");
    let node = create_node(&unique("rel-client")).unwrap();
    let primary = Proc::spawn(&small_field(&name).argv());
    let w = watch(&node, &name);
    let standby = Proc::spawn(&small_field(&name).arg("--standby").argv());
    eventually(WAIT, "the standby to attach", || {
        (w.status().deposit_subscribers == 2).then_some(())
    });
    let mut reader = FieldReader::attach_within(&node, &name, WAIT).unwrap();
    let mut depositor = DepositPublisher::attach_within(&node, &name, 7, WAIT).unwrap();
    let d = |x: f32| {
        DepositMsg::from(Deposit {
            channel: 0,
            x_m: x,
            y_m: 3.0,
            kernel: Kernel::Ellipse {
                tau: 0.5,
                cov_m2: [0.01, 0.0, 0.01],
                range_m: 1.0,
                gamma_max: 100.0,
            },
        })
    };
    depositor.send(d(1.0)).unwrap();
    let before = value_at(&mut reader, 1.0, 3.0, 1.0, "a deposit to the primary");
    // Let the standby mirror the frame with that deposit, then kill the primary.
    reader.wait_frame(WAIT).unwrap();
    let last = *reader.frame().unwrap().header;
    drop(primary); // SIGKILL
                   // A deposit sent while nobody publishes: the standby keeps it for its first frame.
    depositor.send(d(5.0)).unwrap();
    let mut longest_gap_ns = 0u64;
    let mut previous = last;
    let frame = reader
        .wait_until(WAIT, |f| {
            let h = f.header;
            if h.stamp_ns > previous.stamp_ns {
                longest_gap_ns = longest_gap_ns.max(h.stamp_ns - previous.stamp_ns);
                previous = *h;
            }
            h.sequence > last.sequence && f.view.value(0, 5.0, 3.0) > 1.0
        })
        .unwrap()
        .unwrap_or_else(|| panic!("no frame of the standby with the second deposit"));
    // Continued from the last frame: the first deposit is still there, nothing was doubled.
    assert_eq!(frame.view.value(0, 1.0, 3.0), before);
    assert_eq!(frame.header.deposits_applied, 2);
    assert!(reader.field_alive());
    drop(depositor);
    drop(reader);
    standby.interrupt();
    let out = standby.wait_exit(WAIT);
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    let s = json(&out);
    assert_eq!(s["standby"]["took_over"], true, "{s}");
    assert_eq!(s["deposits_applied"], 2, "{s}");
    eprintln!(
        "standby takeover: last primary frame {}, longest gap seen by a reader {:.1} ms, \
         the standby's own measure {} ms (tick period 20 ms)",
        last.sequence,
        longest_gap_ns as f64 / 1e6,
        s["standby"]["takeover_gap_ms"]
    );
}
