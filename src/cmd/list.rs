//! `pheromone list`: the fields on this host, like `iox2 service list` (the work is
//! `field::shm::survey`).

use clap::Args;
use field::shm::{create_node, survey, FieldInfo};

use super::seconds;

/// List the fields running on this host: name, grid, channels, cell size, the tick rate
/// measured over --window-s and the newest sequence, readers (subscribers of the frame
/// service) and depositors (publishers of the deposit service), and whether frames still come
/// ("alive") or not ("stale": the field died, or it is paused waiting for its clock).
#[derive(Args, Debug)]
pub struct ListArgs {
    /// Seconds over which the tick rate is measured.
    #[arg(long, value_parser = super::secs(), default_value_t = 1.0, value_name = "SECS")]
    pub window_s: f64,
    /// Print one JSON object on stdout: `{"fields": [...]}`.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: ListArgs) -> anyhow::Result<()> {
    let window = seconds("window-s", a.window_s)?;
    let node = create_node(&format!("list-{}", std::process::id()))?;
    let fields = survey(&node, window)?;
    if a.json {
        #[derive(serde::Serialize)]
        struct Listing<'a> {
            fields: &'a [FieldInfo],
        }
        println!("{}", serde_json::to_string(&Listing { fields: &fields })?);
        return Ok(());
    }
    if fields.is_empty() {
        eprintln!("no field is running on this host");
        return Ok(());
    }
    println!(
        "{:<24} {:>11} {:>3} {:>8} {:>9} {:>10} {:>7} {:>10}  state",
        "field", "grid", "ch", "cell_m", "tick_hz", "sequence", "readers", "depositors"
    );
    for f in &fields {
        println!("{}", row(f));
    }
    Ok(())
}

fn row(f: &FieldInfo) -> String {
    let state = match (f.alive, f.publisher_alive) {
        (true, _) => "alive",
        (false, true) => "stale (no frame in the window)",
        (false, false) => "stale (no live publisher)",
    };
    format!(
        "{:<24} {:>11} {:>3} {:>8} {:>9.1} {:>10} {:>7} {:>10}  {state}",
        f.name,
        format!("{}×{}", f.width, f.height),
        f.channels,
        f.cell_size_m,
        f.tick_hz,
        f.sequence,
        f.readers,
        f.depositors
    )
}
