//! `pheromone list`: the fields on this host, like `iox2 service list` (the work is
//! `pheromone_field::shm::survey`).

use clap::Args;
use pheromone_field::shm::{create_node, survey, FieldInfo};

use super::seconds;

/// List the fields running on this host: name, grid, channels, cell size, the tick rate
/// measured over --window-s and the newest sequence, readers (subscribers of the frame
/// service) and depositors (publishers of the deposit service), missed deadlines and the
/// longest gap between two frames (ms) since the field started, and whether frames still come
/// ("alive") or not ("stale": the field died, or it is paused waiting for its clock, or it is a
/// mirror whose origin went silent: then it says for how long). A field whose process is there
/// but sends no frame at all (stopped with SIGSTOP, or hung) is "stopped", its grid unknown
/// ("-"; `null` in --json).
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
        "{:<24} {:>11} {:>3} {:>8} {:>9} {:>10} {:>7} {:>10} {:>6} {:>8}  state",
        "field",
        "grid",
        "ch",
        "cell_m",
        "tick_hz",
        "sequence",
        "readers",
        "depositors",
        "missed",
        "gap_ms"
    );
    for f in &fields {
        println!("{}", row(f));
    }
    Ok(())
}

fn row(f: &FieldInfo) -> String {
    let state = match (f.alive, f.publisher_alive, &f.mirror) {
        _ if f.readers_full => "full (every reader slot is taken: its --max-readers)".to_string(),
        (_, true, _) if f.sequence.is_none() => {
            "stopped (its process is there but sent no frame: SIGSTOP, or hung)".to_string()
        }
        (_, true, Some(m)) if m.stale => format!("stale ({})", m.describe()),
        (true, _, Some(_)) => "alive (mirror)".to_string(),
        (true, _, None) => "alive".to_string(),
        (false, true, _) => "stale (no frame in the window)".to_string(),
        (false, false, _) => "stale (no live publisher)".to_string(),
    };
    // Missed deadlines and the longest gap between frames, when the field keeps them.
    let (missed, gap_ms) = match &f.timing {
        Some(t) => (
            t.missed_deadlines.to_string(),
            format!("{:.1}", t.longest_tick_gap_ms),
        ),
        None => ("-".to_string(), "-".to_string()),
    };
    // A stopped field's frame facts are unknown: "-".
    let known = |v: Option<String>| v.unwrap_or_else(|| "-".to_string());
    let grid = known(f.width.zip(f.height).map(|(w, h)| format!("{w}×{h}")));
    format!(
        "{:<24} {grid:>11} {:>3} {:>8} {:>9.1} {:>10} {:>7} {:>10} {missed:>6} {gap_ms:>8}  {state}",
        f.name,
        known(f.channels.map(|c| c.to_string())),
        known(f.cell_size_m.map(|c| c.to_string())),
        f.tick_hz,
        known(f.sequence.map(|c| c.to_string())),
        f.readers,
        f.depositors
    )
}
