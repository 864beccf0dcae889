//! The README's Rust snippet, as a whole program, beside `pheromone field`:
//! `cargo run --release -p pheromone-examples --example readme`. `tests/examples` checks that
//! the README shows this file below this comment.

// Cargo.toml: pheromone-field = { path = "<this repository>/field" }
use std::time::Duration;

use pheromone_field::shm::{create_node, DepositPublisher, FieldReader};
use pheromone_field::{Deposit, Kernel};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    pheromone_field::shm::set_verbose(false); // no iceoryx2 config warnings
    let node = create_node("my-follower")?;
    let mut reader = FieldReader::attach_within(&node, "main", Duration::from_secs(5))?;
    reader.wait_frame(Duration::from_secs(1))?; // woken by the field's event
    let frame = reader.frame().expect("a frame after wait_frame"); // borrowed, no copy
    let (gx, gy) = frame.view.gradient(0, 1.0, 2.0);
    println!("gradient at (1, 2) m: ({gx}, {gy})");
    let mut depositor = DepositPublisher::attach(&node, "main", 7)?;
    let kernel = Kernel::Ellipse {
        tau: 0.2,
        cov_m2: [0.01, 0.0, 0.01],
        range_m: 1.0,
        gamma_max: 100.0,
    };
    depositor.send(
        Deposit {
            channel: 0,
            x_m: 1.0,
            y_m: 2.0,
            kernel,
        }
        .into(),
    )?;
    Ok(())
}
