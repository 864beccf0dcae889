//! `field --publish-on-deposit-ms`: a deposit is in a frame at once, stepped by the real time.

use std::time::Duration;

use pheromone_field::shm::{create_node, now_ns, DepositPublisher, FieldReader};
use pheromone_field::DepositMsg;
use pheromone_field::{Deposit, Kernel};

use crate::harness::*;

const WAIT: Duration = Duration::from_secs(30);

#[test]
fn a_deposit_is_published_at_once_instead_of_at_the_next_tick() {
    let name = unique("ondep");
    // One regular tick every 50 s: any frame with the deposit before that came on deposit.
    let field = Proc::spawn(
        &Cmd::field(&name)
            .grid(64, 64)
            .cell_size(0.1)
            .model("exponential")
            .opt("--decay-per-s", 0.5)
            .tick_hz(0.02)
            .opt("--publish-on-deposit-ms", 2)
            .duration(120)
            .json()
            .argv(),
    );
    let node = create_node(&unique("ondep-client")).unwrap();
    let mut reader = FieldReader::attach_within(&node, &name, WAIT).unwrap();
    let mut depositor = DepositPublisher::attach_within(&node, &name, 3, WAIT).unwrap();
    // A reader that attached between ticks gets the current frame within 100 ms.
    let first = *reader
        .wait_until(Duration::from_secs(10), |_| true)
        .unwrap()
        .expect("the first frame long before the first tick")
        .header;
    let mut sent_ns = Vec::new();
    for (i, x) in [1.0f32, 2.0, 3.0].into_iter().enumerate() {
        sent_ns.push(now_ns());
        depositor
            .send(DepositMsg::from(Deposit {
                channel: 0,
                x_m: x,
                y_m: 3.0,
                kernel: Kernel::Ellipse {
                    tau: 0.5,
                    cov_m2: [0.01, 0.0, 0.01],
                    range_m: 1.0,
                    gamma_max: 100.0,
                },
            }))
            .unwrap();
        let frame = reader
            .wait_until(Duration::from_secs(20), |f| f.view.value(0, x, 3.0) > 1.0)
            .unwrap()
            .unwrap_or_else(|| panic!("deposit {i} not published within 20 s (tick period 50 s)"));
        let h = frame.header;
        assert_eq!(h.sequence, first.sequence + 1 + i as u64, "{h:?}");
        assert_eq!(h.deposits_applied, 1 + i as u64);
        // Stepped by the real time since the last frame, not by the 50 s period.
        assert!(
            h.sim_time_s < 20.0,
            "frame {} at field time {} s",
            h.sequence,
            h.sim_time_s
        );
        eprintln!(
            "deposit {i}: visible {:.3} ms after the send (frame {}, t = {:.4} s)",
            (h.stamp_ns.saturating_sub(sent_ns[i])) as f64 / 1e6,
            h.sequence,
            h.sim_time_s
        );
    }
    // The earlier deposits evaporated by e^(−0.5·t) over the real elapsed field time.
    let f = reader.frame().unwrap();
    let t = f.header.sim_time_s;
    assert!(f.view.value(0, 1.0, 3.0) > 0.0 && t > 0.0);
    drop(depositor);
    drop(reader);
    field.interrupt();
    let out = field.wait_exit(WAIT);
    assert_eq!(out.status.code(), Some(130), "{}", stderr(&out));
    let s = json(&out);
    assert!(
        s["frames_on_deposit"].as_u64().is_some_and(|n| n >= 3),
        "{s}"
    );
    assert_eq!(s["deposits_applied"], 3, "{s}");
}

#[test]
fn publish_on_deposit_is_refused_with_a_clock_and_with_a_bad_interval() {
    let o = run(&["field", "--publish-on-deposit-ms=nan", "--duration", "0"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("--publish-on-deposit-ms"),
        "{}",
        stderr(&o)
    );
    let o = run(&["field", "--publish-on-deposit-ms", "1", "--clock", "w"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
}
