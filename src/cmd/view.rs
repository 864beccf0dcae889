//! `pheromone view`: a live web page of a running field (heat map, robots, statistics).

use clap::Args;
use pheromone_field::shm::create_node;
use pheromone_view::server::{bind, serve, View, ViewConfig};
use pheromone_view::MAX_SIDE_LIMIT;

use super::bad;

/// Serve a live web page of a running field: a heat map of each channel (automatic or fixed
/// scale, colour bar), the robots' poses and recent paths (with --world) and the field's
/// statistics, polled about ten times a second. Frames are downsampled on the server.
///
/// Binds loopback unless told otherwise; the page is embedded in the binary (no internet
/// needed). The field may start after the view. Ctrl-C or SIGTERM stops it.
#[derive(Args, Debug)]
pub struct ViewArgs {
    /// Field name.
    #[arg(long, default_value = "main")]
    pub field: String,
    /// HTTP address to serve on (port 0: any free port; the address is printed).
    #[arg(long, default_value = "127.0.0.1:8080", value_parser = super::check::socket_addr())]
    pub listen: String,
    /// World whose robots' poses are shown (`pheromone/W/r<ID>/pose`).
    #[arg(long)]
    pub world: Option<String>,
    /// Robots r0..r<N-1> looked for in the world.
    #[arg(long, value_parser = super::int::<u32>(0, 4096), default_value_t = 32)]
    pub robots: u32,
    /// Largest side of a downsampled frame when the page asks for none (1–4096).
    #[arg(long, value_parser = super::int::<usize>(1, 4096), default_value_t = 256)]
    pub max_side: usize,
    /// Scenario (built-in name or TOML file) whose world's walls the page draws over the heat
    /// map: a field's frames carry no walls. `sim --view` passes its own.
    #[arg(long)]
    pub scenario: Option<String>,
}

pub fn run(a: ViewArgs) -> anyhow::Result<()> {
    if !(1..=MAX_SIDE_LIMIT).contains(&a.max_side) {
        return Err(bad(format!(
            "--max-side {}: must be between 1 and {MAX_SIDE_LIMIT}",
            a.max_side
        )));
    }
    pheromone_field::shm::check_name(&a.field).map_err(super::bad_from)?;
    let walls_m = match &a.scenario {
        Some(name) => scenario_walls(name)?,
        None => Vec::new(),
    };
    let node = create_node(&format!("view-{}", std::process::id()))?;
    let (server, local) = bind(&a.listen).map_err(super::bad_from)?;
    eprintln!("view: http://{local}/ (field '{}')", a.field);
    let mut view = View::new(ViewConfig {
        field: a.field,
        world: a.world,
        max_robots: a.robots,
        default_max_side: a.max_side,
        walls_m,
    });
    serve(&node, &server, &mut view)?;
    eprintln!("view: stopped");
    Ok(())
}

/// The wall segments of `scenario`'s world, `[x0, y0, x1, y1]` in metres (a bad scenario or
/// world is bad input, exit status 2).
fn scenario_walls(scenario: &str) -> anyhow::Result<Vec<[f64; 4]>> {
    let s = super::roles::load_scenario(scenario)?;
    let world = pheromone_world::World::new(s.world.clone(), s.seed).map_err(super::bad_from)?;
    Ok(world
        .wall_segments()
        .iter()
        .map(|w| [w.a_m[0], w.a_m[1], w.b_m[0], w.b_m[1]])
        .collect())
}
