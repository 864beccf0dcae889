//! A reading process: attaches to the field `main` and prints, for every frame it is woken for,
//! the value and gradient at a point. Run beside `pheromone field` and `cargo run --example deposit`:
//!
//!     cargo run --release -- field            # terminal 1
//!     cargo run --release --example read      # terminal 2
//!     cargo run --release --example deposit   # terminal 3

use std::time::Duration;

use pheromone_field::shm::{create_node, FieldReader};

const FIELD: &str = "main";
const POINT_M: (f32, f32) = (12.8, 12.8);

fn main() -> anyhow::Result<()> {
    pheromone_field::shm::set_verbose(false);
    // A program of its own: Ctrl-C ends the loop below (`node.wait` fails) instead of killing
    // the process before it cleans up.
    pheromone_field::shm::handle_termination_requests();
    let node = create_node(&format!("example-read-{}", std::process::id()))?;
    let mut reader = FieldReader::attach_within(&node, FIELD, Duration::from_secs(30))?;
    let mut last_print = 0u64;
    while node.wait(Duration::ZERO).is_ok() {
        // Woken by the field's frame-ready event; no polling.
        if !reader.wait_frame(Duration::from_secs(1))? {
            eprintln!("no frame for 1 s: is the field '{FIELD}' still running?");
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
        let (x, y) = POINT_M;
        let (gx, gy) = frame.view.gradient(0, x, y);
        println!(
            "frame {:>6}  t = {:>7.2} s  P({x}, {y}) = {:>9.4}  ∇P = ({gx:>8.3}, {gy:>8.3})  deposits {} applied / {} rejected",
            h.sequence,
            h.sim_time_s,
            frame.view.value(0, x, y),
            h.deposits_applied,
            h.deposits_rejected_total()
        );
    }
    Ok(())
}
