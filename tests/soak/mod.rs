//! Soak: a field and 25 robot processes under random SIGKILLs for a bounded time.
//!
//! Soak (issue 7, part 6): one field and eight robots — a world on wall time and, per robot, a
//! localizer, a depositor and a follower: 25 client processes — with random SIGKILLs (seeded)
//! and restarts for a bounded time. Asserts that the field stayed alive (a newer frame after every
//! kill), that frame sequence numbers only grew, that no cell went non-finite, that every killed
//! client's node was cleaned and its restart attached again (the field's services have exactly as
//! many reader and depositor slots as clients), and that none of the run's nodes nor /dev/shm
//! entries remain after shutdown.
//!
//! `PHEROMONE_SOAK_SECS` (default 60; CI runs the default) sets how long clients are killed,
//! `PHEROMONE_SOAK_SEED` the seed. Figures are printed (`--nocapture`), never asserted.

use std::time::{Duration, Instant};

use pheromone_field::shm::FieldWatch;

use crate::crash::{
    env_u64, exited, interrupt_all, kill, wait_attached, FrameWatch, Rng, Run, LIVENESS, WAIT,
};
use crate::harness::*;

const ROBOTS: u32 = 8;

// A test reads as one scenario, top to bottom (the line limit is for non-test code).
#[allow(clippy::too_many_lines)]
#[test]
fn a_field_and_eight_robots_survive_random_kills_and_leave_nothing_behind() {
    let run = Run::new("s");
    let field = unique("sf");
    let world = unique("sw");
    let scenario = run.scenario(ROBOTS);
    let soak = Duration::from_secs(env_u64("PHEROMONE_SOAK_SECS", 60));
    let seed = env_u64("PHEROMONE_SOAK_SEED", 11);
    let mut rng = Rng(seed);
    let readers = ROBOTS + 1; // the followers and this test
    let depositors = ROBOTS + 1; // the depositors and the world (scripted trail)
    let field_cmd = Cmd::field(&field)
        .opt("--scenario", &scenario)
        .tick_hz(50)
        .opt("--max-readers", readers)
        .opt("--max-depositors", depositors)
        .json();
    let mut field_proc = run.spawn(&field_cmd.argv(), "field");
    let watch = FrameWatch::start(&run, &field);
    watch.wait_newer(0, WAIT, "the field's first frame");
    let node = run.node(&format!("soak-test-{}", std::process::id()));
    let status = eventually(WAIT, "the field's services", || {
        FieldWatch::open(&node, &field).ok()
    });

    // Client k: 0 = the world, then localizer, depositor, follower of robot (k − 1) / 3.
    let clients = 1 + 3 * ROBOTS as usize;
    let spawn = |k: usize| -> Proc {
        let (cmd, name) = if k == 0 {
            (Cmd::new("world").arg("--realtime"), "world".to_string())
        } else {
            let robot = (k - 1) / 3;
            let role = ["localizer", "depositor", "follower"][(k - 1) % 3];
            (
                Cmd::new(role).opt("--robot", robot),
                format!("{role}-r{robot}"),
            )
        };
        let cmd = cmd
            .opt("--scenario", &scenario)
            .opt("--world", &world)
            .opt("--field", &field);
        run.spawn(&cmd.argv(), &name)
    };
    let mut procs: Vec<Proc> = (0..clients).map(spawn).collect();
    let attached = |s: &pheromone_field::shm::FieldStatus| {
        s.publishers == 1
            && s.subscribers == readers as usize + 1
            && s.depositors == depositors as usize
    };
    wait_attached(
        &run,
        &status,
        attached,
        "every client to attach",
        Duration::from_secs(120),
        || {},
    );

    let started = Instant::now();
    let (mut kills, mut self_exits, mut rounds) = (0u64, 0u64, 0u64);
    while started.elapsed() < soak {
        rounds += 1;
        let k = rng.below(clients as u64) as usize;
        // The instant: after 0–50 more frames (up to a second at 50 Hz).
        let frames = rng.below(51);
        watch.wait_newer(watch.sequence() + frames, WAIT, "frames before the kill");
        let at = watch.sequence();
        kills += kill(&mut procs[k]) as u64;
        watch.wait_newer(
            at,
            LIVENESS,
            &format!("a frame after killing client {k} (round {rounds})"),
        );
        procs[k] = spawn(k);
        // Roles stop by themselves when the world is gone: restart whatever exited.
        wait_attached(
            &run,
            &status,
            attached,
            &format!("the clients to attach again after killing client {k} (round {rounds})"),
            WAIT,
            || {
                for (i, p) in procs.iter_mut().enumerate() {
                    if exited(p) {
                        self_exits += 1;
                        *p = spawn(i);
                    }
                }
            },
        );
        assert!(
            !exited(&mut field_proc),
            "round {rounds}: the field died: {}",
            run.log("field")
        );
    }
    let elapsed = started.elapsed();

    interrupt_all(procs);
    drop(status);
    let report = watch.finish();
    let (summary, cleaned_after, shm_left) = run.stop_field(field_proc, node);
    eprintln!(
        "soak: {kills} kills in {rounds} rounds over {:.1} s (seed {seed}), {self_exits} roles \
         stopped by themselves and were restarted; frames seen {} (sequence {}..{}, {} missed by \
         the reader), longest tick gap {:.1} ms at frame {}, field ticks {}, deposits applied {} \
         rejected {}; dead nodes cleaned after shutdown {cleaned_after}; /dev/shm entries \
         left: {}",
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
    eprintln!(
        "soak: reader errors (attached again): {:?}",
        report.reader_errors
    );
    assert!(report.error.is_none(), "{:?}", report.error);
    assert!(
        report.regressions.is_empty(),
        "sequence went back: {:?}",
        report.regressions
    );
    assert_eq!(report.non_finite_frames, 0, "frames with non-finite cells");
    assert!(kills > 0);
    assert!(shm_left.is_empty(), "left in /dev/shm: {shm_left:?}");
}
