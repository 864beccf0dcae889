//! A reading process: attaches to the field `main` and prints, about twice a second, where the
//! trail is strongest (the depositor's track: `deposit.rs` walks a 3 m circle around the field's
//! centre) with its value and gradient there, and the value at the circle's start, where the
//! depositor's first deposit lands. Run beside `pheromone field` and the `deposit` example:
//!
//!     cargo run --release -- field                                # terminal 1
//!     cargo run --release -p pheromone-examples --example read     # terminal 2 (`-- NAME`: field NAME)
//!     cargo run --release -p pheromone-examples --example deposit  # terminal 3
//!
//! Within a second of the depositor starting, `peak` moves onto its circle and `start` rises.

use std::time::Duration;

use pheromone_field::shm::{create_node, FieldReader};

/// Where `deposit.rs` starts its circle: 3 m east of the default field's centre.
const START_M: (f32, f32) = (15.8, 12.8);

fn main() -> anyhow::Result<()> {
    pheromone_field::shm::set_verbose(false);
    // A program of its own: Ctrl-C ends the loop below (`node.wait` fails) instead of killing
    // the process before it cleans up.
    pheromone_field::shm::handle_termination_requests();
    // The field's name: the first argument, else the default field `main`.
    let field = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "main".to_string());
    let node = create_node(&format!("example-read-{}", std::process::id()))?;
    let mut reader = FieldReader::attach_within(&node, &field, Duration::from_secs(30))?;
    let mut last_print = 0u64;
    while !pheromone_field::shm::should_stop(&node) {
        // Woken by the field's frame-ready event; no polling.
        if !reader.wait_frame(Duration::from_secs(1))? {
            eprintln!("no frame for 1 s: is the field '{field}' still running?");
            continue;
        }
        let Some(frame) = reader.frame() else {
            continue;
        };
        let h = frame.header;
        // Print at most ~2 lines per second.
        if h.sequence < last_print + (0.5 / h.dt_s as f64) as u64 {
            continue;
        }
        last_print = h.sequence;
        let view = frame.view;
        let start = view.value(0, START_M.0, START_M.1);
        let (i, peak) =
            view.plane(0)
                .iter()
                .copied()
                .enumerate()
                .fold(
                    (0, 0.0f32),
                    |best, (i, v)| if v > best.1 { (i, v) } else { best },
                );
        let t = h.sim_time_s;
        if peak <= 0.0 {
            println!("t = {t:>7.2} s  the field is empty: is the `deposit` example running?");
            continue;
        }
        let g = view.geometry;
        let (x, y) =
            g.world_from_grid((i % g.width as usize) as u32, (i / g.width as usize) as u32);
        let (gx, gy) = view.gradient(0, x, y);
        println!(
            "t = {t:>7.2} s  peak {peak:>8.3} at ({x:5.2}, {y:5.2}) m, ∇P = ({gx:>7.2}, {gy:>7.2})  \
             start ({}, {}) {start:>8.3}  deposits applied {}",
            START_M.0, START_M.1, h.deposits_applied,
        );
    }
    Ok(())
}
