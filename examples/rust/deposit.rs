//! A depositing process: walks a circle around the centre of the default field `main` and
//! deposits a seed 000 ellipse every 0.2 s, with an uncertainty that grows and shrinks.
//! See `read.rs` for how to run the pair.

use std::time::Duration;

use pheromone_field::shm::{create_node, DepositPublisher};
use pheromone_field::DepositMsg;
use pheromone_field::{Deposit, Kernel};

const PERIOD: Duration = Duration::from_millis(200);

fn main() -> anyhow::Result<()> {
    pheromone_field::shm::set_verbose(false);
    // A program of its own: Ctrl-C ends the loop below (`node.wait` fails) instead of killing
    // the process before it cleans up.
    pheromone_field::shm::handle_termination_requests();
    // The field's name: the first argument, else the default field `main`.
    let field = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "main".to_string());
    let node = create_node(&format!("example-deposit-{}", std::process::id()))?;
    let mut publisher = DepositPublisher::attach_within(&node, &field, 1, Duration::from_secs(30))?;
    let mut step = 0u32;
    while pheromone_field::shm::wait_or_stop(&node, PERIOD) {
        let angle = step as f32 * 0.1;
        let (x, y) = (12.8 + 3.0 * angle.cos(), 12.8 + 3.0 * angle.sin());
        // Σxy grows from (5 cm)² to (25 cm)² and back: γ = τ/det Σxy falls as uncertainty grows.
        let sigma_m = 0.05 + 0.2 * (0.5 - 0.5 * (angle * 0.3).cos());
        let var = sigma_m * sigma_m;
        let msg = DepositMsg::from(Deposit {
            channel: 0,
            x_m: x,
            y_m: y,
            kernel: Kernel::Ellipse {
                tau: 0.2,
                cov_m2: [var, 0.0, var],
                range_m: 1.0,
                gamma_max: 100.0,
            },
        });
        match publisher.send(msg) {
            Ok(()) => println!("deposit {step:>4} at ({x:6.2}, {y:6.2}) m, σ = {sigma_m:.3} m"),
            Err(e) => eprintln!("deposit {step} not delivered: {e}"),
        }
        step += 1;
    }
    Ok(())
}
