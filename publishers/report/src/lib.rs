//! The files a simulation run leaves behind (`pheromone sim --out DIR`): the metrics object, one
//! CSV time series per robot, the probe readings, a heat-map picture of every channel of every
//! field snapshot with the robots' trajectories drawn over it, and the charts the scenario's
//! records call for.
//!
//! Everything is drawn with plotters (its bitmap backend, no image codec: the `png` crate
//! encodes the buffer) and DejaVu Sans, embedded in the binary. Heat maps: a colour-map lookup
//! table (viridis for unsigned channels, a dark-centred blue/orange diverging map for signed
//! ones), nearest-neighbour upscaling by a whole factor, axes in metres, anti-aliased
//! trajectories (true solid, estimated dashed), a legend and a colour bar with its unit. y points
//! up: row 0 of a plane (y = 0) is the bottom row of the field in the picture.
//!
//! The snapshot carries no grid origin, so the field is drawn with its origin at (0, 0) m, the
//! default of every scenario.
//!
//! Submodules: `style` the font, palette, colour maps and picture buffer; `heatmap` a snapshot's
//! picture; `marks` the places it marks (from the scenario's metrics: `wrong_area`'s A and B); `series` the data of the charts, from the run; `plots` the charts; `graph_png` the
//! picture of a node-graph run; `legend` a chart's legend drawn in a band outside its axes;
//! `summary` a run's `summary.png` (its headline over its final
//! picture); `files` writes the CSV and PNG files; `sweep` the files of
//! `pheromone sweep` (CSV, JSON, exploration against robots and against R_C); `filters` and
//! `filters_plots` the comparison of localization filters (`sim --compare-filters`, seed 000
//! Figs. 13–18); `probe` and `export::live` read a running field (`pheromone probe`,
//! `pheromone export`).

pub mod export;
mod files;
pub mod filters;
mod filters_plots;
mod graph_png;
mod heatmap;
mod legend;
mod loglog;
mod maps;
mod marks;
mod plots;
pub mod probe;
pub mod rundir;
pub mod series;
mod style;
mod summary;
mod sweep;
mod sweep_shard;
mod trail_sweep;

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use files::{robot_csv, write_file, write_png};
use heatmap::render_snapshot;
use pheromone_sim::recording::{Recording, Snapshot};
use pheromone_world::scenario::Scenario;
use style::ColourMap;

pub use filters::{FilterRun, FilterSummary};
pub use filters_plots::write_filter_comparison;
pub use graph_png::{graph_headline, write_graph_png, write_graph_summary};
pub use loglog::{write_log_log_panels, LogLogPanel, LogLogSeries};
pub use marks::{marks, Mark, Shape};
pub use plots::{PLOT_H_PX, PLOT_W_PX};
pub use summary::{write_summary, Headline, SUMMARY_PNG};
pub use sweep::{
    paper_table, rc_values, sweep_csv, sweep_times_csv, write_sweep, SWEEP_CSV_HEADER,
    SWEEP_TIMES_CSV_HEADER,
};
pub use sweep_shard::{parse_sweep_csv, read_shard, write_shard, ShardFileError};
pub use trail_sweep::{trail_csv, trail_table, write_trail_sweep, TRAIL_CSV_HEADER};

/// Writing the outputs of a run failed.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Creating the directory or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Encoding a picture failed (this includes I/O errors while writing it).
    #[error("{}: cannot write PNG: {source}", path.display())]
    Png {
        path: PathBuf,
        #[source]
        source: png::EncodingError,
    },
    /// The metrics object could not be serialized.
    #[error("{}: cannot serialize the metrics: {source}", path.display())]
    Json {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    /// Drawing a picture failed (plotters' message).
    #[error("{}: cannot draw: {detail}", path.display())]
    Draw { path: PathBuf, detail: String },
    /// A snapshot's size does not match its plane data.
    #[error("field snapshot at t = {t_s} s: {detail}")]
    BadSnapshot { t_s: f64, detail: String },
    /// Writing `field_final.npy` failed.
    #[error(transparent)]
    Export(#[from] crate::export::ExportError),
    /// Writing a file failed, or its path names something other than a regular file.
    #[error(transparent)]
    Output(#[from] pheromone_field::outfile::OutputError),
}

/// Header of `robot_<id>.csv`.
pub const ROBOT_CSV_HEADER: &str = "t_s,true_x_m,true_y_m,true_theta_rad,est_x_m,est_y_m,\
est_theta_rad,est_sigma_m,v_m_per_s,omega_rad_per_s,state,sensed_level,deposit_peak";

/// Header of `probes.csv`.
pub const PROBES_CSV_HEADER: &str = "t_s,x_m,y_m,channel,value";
/// Writes every output of a run into `dir` (created if needed) and returns the paths written:
/// `metrics.json`, `robot_<id>.csv` per robot, `probes.csv` if there are probes, one
/// `field_<channel>_t<sss.s>s.png` per snapshot and channel, `field_final.png` (the last
/// snapshot's only channel, or all its channels at once) with `field_final_<channel>.png` per
/// channel when there are several, and `field_final.npy` (the last snapshot, every channel:
/// `crate::export::npy`). The heat maps draw `marks` (from [`marks`]: the places the
/// scenario's metrics name, such as `wrong_area`'s A and B).
pub fn write_outputs(
    dir: &Path,
    rec: &Recording,
    metrics: &impl serde::Serialize,
    marks: &[Mark],
) -> Result<Vec<PathBuf>, ReportError> {
    for snap in &rec.snapshots {
        check_snapshot(snap)?;
    }
    fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut written = Vec::new();

    let path = dir.join("metrics.json");
    let mut text = serde_json::to_string_pretty(metrics).map_err(|source| ReportError::Json {
        path: path.clone(),
        source,
    })?;
    text.push('\n');
    write_file(&path, text.as_bytes())?;
    written.push(path);

    for (id, rows) in &rec.robots {
        let path = dir.join(format!("robot_{id}.csv"));
        write_file(&path, robot_csv(rows).as_bytes())?;
        written.push(path);
    }

    if !rec.probes.is_empty() {
        let mut text = String::from(PROBES_CSV_HEADER);
        text.push('\n');
        for p in &rec.probes {
            // Writing into a String cannot fail.
            let _ = writeln!(
                text,
                "{},{},{},{},{}",
                p.t_s, p.x_m, p.y_m, p.channel, p.value
            );
        }
        let path = dir.join("probes.csv");
        write_file(&path, text.as_bytes())?;
        written.push(path);
    }

    let mut last_pngs = Vec::new();
    for snap in &rec.snapshots {
        last_pngs.clear();
        for (c, name) in snap.channels.iter().enumerate() {
            let path = dir.join(snapshot_file_name(name, snap.t_s));
            // One colour scale per channel for the whole run, so that snapshots compare.
            let scale = run_scale(rec, name);
            let pic = render_snapshot(rec, snap, c, marks, &scale).map_err(|detail| {
                ReportError::Draw {
                    path: path.clone(),
                    detail,
                }
            })?;
            write_png(&path, &pic)?;
            last_pngs.push((name.clone(), path.clone()));
            written.push(path);
        }
    }
    written.extend(write_final_pngs(dir, rec, marks, &last_pngs)?);
    if let Some(last) = rec.snapshots.last() {
        written.push(crate::export::npy::write_snapshot(dir, last)?);
    }
    Ok(written)
}

/// The final pictures: `field_final_<channel>.png` per channel (copies of the last snapshot's)
/// when the field has several, and `field_final.png`: the only channel's picture, or with
/// several channels every channel at once ([`all_channels`]), so that no trail is missing.
fn write_final_pngs(
    dir: &Path,
    rec: &Recording,
    marks: &[Mark],
    last_pngs: &[(String, PathBuf)],
) -> Result<Vec<PathBuf>, ReportError> {
    let copy = |from: &Path, to: PathBuf| {
        fs::copy(from, &to).map_err(|source| ReportError::Io {
            path: to.clone(),
            source,
        })?;
        Ok::<_, ReportError>(to)
    };
    let mut written = Vec::new();
    match (last_pngs, rec.snapshots.last()) {
        ([(_, only)], _) => written.push(copy(only, dir.join("field_final.png"))?),
        (several, Some(last)) if several.len() > 1 => {
            for (name, png) in several {
                written.push(copy(png, dir.join(final_file_name(name)))?);
            }
            let path = dir.join("field_final.png");
            let pic = final_of_several(rec, last, marks).map_err(|detail| ReportError::Draw {
                path: path.clone(),
                detail,
            })?;
            write_png(&path, &pic)?;
            written.push(path);
        }
        _ => {}
    }
    Ok(written)
}

/// `field_final.png` of a field with several channels: every channel at once but the walls'.
fn final_of_several(
    rec: &Recording,
    last: &Snapshot,
    marks: &[Mark],
) -> Result<style::Picture, String> {
    let all = all_channels(last, rec.wall_channel);
    let scale = ColourMap::for_plane(all.plane(0));
    render_snapshot(rec, &all, 0, marks, &scale)
}

/// The picture of `field_final.png` (none without a snapshot): the last snapshot's only
/// channel in the run's scale, or every channel at once ([`final_of_several`]).
fn final_picture(rec: &Recording, marks: &[Mark]) -> Option<Result<style::Picture, String>> {
    let last = rec.snapshots.last()?;
    Some(match last.channels.as_slice() {
        [] => return None,
        [only] => render_snapshot(rec, last, 0, marks, &run_scale(rec, only)),
        _ => final_of_several(rec, last, marks),
    })
}

/// `field_final_<channel>.png`, the channel name as in [`snapshot_file_name`].
pub fn final_file_name(channel: &str) -> String {
    format!("field_final_{}.png", file_safe(channel))
}

/// The colour scale of channel `name` over every snapshot of the run: 0 … the largest level
/// any snapshot holds (−max … max for a signed channel).
fn run_scale(rec: &Recording, name: &str) -> ColourMap {
    ColourMap::for_planes(rec.snapshots.iter().filter_map(|s| {
        let c = s.channels.iter().position(|n| n == name)?;
        Some(s.plane(c))
    }))
}

/// One plane holding every channel of `snap` but the walls' marks (`wall_channel`, drawn as
/// walls anyway: their level would swamp the pheromone's scale): per cell the value of largest
/// magnitude (a cell on any channel's trail shows), named after the channels it combines.
fn all_channels(snap: &Snapshot, wall_channel: Option<usize>) -> Snapshot {
    let n = snap.width as usize * snap.height as usize;
    let mut shown: Vec<usize> = (0..snap.channels.len())
        .filter(|&c| Some(c) != wall_channel)
        .collect();
    if shown.is_empty() {
        shown = (0..snap.channels.len()).collect();
    }
    let mut plane = snap.plane(shown[0]).to_vec();
    for &c in &shown[1..] {
        for (v, &w) in plane.iter_mut().zip(snap.plane(c)) {
            if w.is_nan() || w.abs() > v.abs() {
                *v = w;
            }
        }
    }
    debug_assert_eq!(plane.len(), n);
    let names: Vec<&str> = shown.iter().map(|&c| snap.channels[c].as_str()).collect();
    let name = match names.as_slice() {
        [one] => (*one).to_string(),
        several => format!("{} (largest |level|)", several.join(" + ")),
    };
    Snapshot {
        t_s: snap.t_s,
        width: snap.width,
        height: snap.height,
        cell_size_m: snap.cell_size_m,
        channels: vec![name],
        planes: plane,
    }
}

/// Header of `exploration.csv`: then one `r<id>` column per robot, then `team`.
pub const EXPLORATION_CSV_HEADER: &str = "t_s";
/// Header of `path_distance.csv`.
pub const PATH_DISTANCE_CSV_HEADER: &str = "t_s,path,robot,distance_m";

/// Writes the charts the scenario's records call for into `dir` (created if needed), with the
/// time series they draw, and returns the paths written:
/// - probes (seed 000 Figs. 6–8, `evaporation`): `probes.png`, each probe's readings against its
///   closed form;
/// - an exploration metric (seed 004, `ias-ss`): `exploration.png` and `exploration.csv`, the
///   share of sectors visited over time per robot and for the team;
/// - path metrics (seed 002, `trail-following`): `path_distance.png` and `path_distance.csv`,
///   each robot's distance to its path over time;
/// - a blind-leader metric (seed 000, `blind-leader`): `leader_deposits.png`, the peak of each
///   of the leader's deposits along its path (`deposit_peak` in `robot_<id>.csv`), the point of
///   loss marked;
/// - seed 004's mapping (`[mapping]` on): `map_r<ID>.png` and `map_r<ID>_world.png`, each
///   robot's final map in its own frame and placed in the world over the true walls
///   (`maps.rs`).
pub fn write_plots(
    dir: &Path,
    scenario: &Scenario,
    rec: &Recording,
) -> Result<Vec<PathBuf>, ReportError> {
    fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut written = Vec::new();
    let end_s = scenario.duration_s;
    let draw = |name: &str, pic: Result<style::Picture, String>| -> Result<PathBuf, ReportError> {
        let path = dir.join(name);
        let pic = pic.map_err(|detail| ReportError::Draw {
            path: path.clone(),
            detail,
        })?;
        write_png(&path, &pic)?;
        Ok(path)
    };
    if !rec.probes.is_empty() {
        let curves = series::probe_curves(scenario, rec);
        written.push(draw("probes.png", plots::probes_chart(&curves, end_s))?);
    }
    if let Some(m) = &scenario.metrics.exploration {
        let s = series::exploration_over_time(m, rec);
        let path = dir.join("exploration.csv");
        write_file(&path, exploration_csv(&s).as_bytes())?;
        written.push(path);
        written.push(draw(
            "exploration.png",
            plots::exploration_chart(&s, end_s),
        )?);
    }
    if !scenario.metrics.paths.is_empty() {
        let paths = series::path_distances(scenario, rec);
        let mut text = String::from(PATH_DISTANCE_CSV_HEADER);
        text.push('\n');
        for p in &paths {
            for (t, d) in &p.points {
                // Writing into a String cannot fail.
                let _ = writeln!(text, "{t},{},{},{d}", p.name, p.robot);
            }
        }
        let path = dir.join("path_distance.csv");
        write_file(&path, text.as_bytes())?;
        written.push(path);
        written.push(draw(
            "path_distance.png",
            plots::path_distance_chart(&paths, end_s),
        )?);
    }
    if let Some(m) = &scenario.metrics.blind_leader {
        let d = series::leader_deposits(scenario, m, rec);
        written.push(draw(
            "leader_deposits.png",
            plots::leader_deposits_chart(&d),
        )?);
    }
    if let Some(mapping) = &rec.mapping {
        for (id, map) in &mapping.maps {
            written.push(draw(
                &format!("map_r{id}.png"),
                maps::own_frame_picture(map, *id),
            )?);
            written.push(draw(
                &format!("map_r{id}_world.png"),
                maps::world_frame_picture(map, rec, *id),
            )?);
        }
    }
    Ok(written)
}

/// `exploration.csv`: one row per time any robot recorded; a robot's share is empty before its
/// first sample.
fn exploration_csv(s: &series::ExplorationSeries) -> String {
    let mut text = String::from(EXPLORATION_CSV_HEADER);
    for id in s.per_robot.keys() {
        let _ = write!(text, ",r{id}");
    }
    text.push_str(",team\n");
    let mut at: Vec<usize> = vec![0; s.per_robot.len()];
    for &(t, team) in &s.team {
        let _ = write!(text, "{t}");
        for (k, points) in s.per_robot.values().enumerate() {
            while at[k] + 1 < points.len() && points[at[k] + 1].0 <= t {
                at[k] += 1;
            }
            match points.get(at[k]).filter(|p| p.0 <= t) {
                Some(p) => {
                    let _ = write!(text, ",{}", p.1);
                }
                None => text.push(','),
            }
        }
        let _ = writeln!(text, ",{team}");
    }
    text
}

/// `field_<channel>_t<seconds>s.png`, seconds with one decimal and at least three integer
/// digits (`field_trail_t012.0s.png`); characters other than letters, digits, `-` and `_` in
/// the channel name become `_`.
pub fn snapshot_file_name(channel: &str, t_s: f64) -> String {
    format!("field_{}_t{t_s:05.1}s.png", file_safe(channel))
}

/// A channel name in a file name: characters other than letters, digits, `-` and `_` become
/// `_`.
fn file_safe(channel: &str) -> String {
    channel
        .chars()
        .map(|ch| {
            if ch.is_ascii_alphanumeric() || ch == '-' || ch == '_' {
                ch
            } else {
                '_'
            }
        })
        .collect()
}

fn check_snapshot(snap: &Snapshot) -> Result<(), ReportError> {
    let bad = |detail: String| ReportError::BadSnapshot {
        t_s: snap.t_s,
        detail,
    };
    if snap.width == 0 || snap.height == 0 {
        return Err(bad(format!(
            "empty grid {} × {} cells",
            snap.width, snap.height
        )));
    }
    if !(snap.cell_size_m.is_finite() && snap.cell_size_m > 0.0) {
        return Err(bad(format!(
            "cell_size_m = {} is not a positive number",
            snap.cell_size_m
        )));
    }
    let expected = snap.width as usize * snap.height as usize * snap.channels.len();
    if snap.planes.len() != expected {
        return Err(bad(format!(
            "{} values for {} × {} cells × {} channels (expected {expected})",
            snap.planes.len(),
            snap.width,
            snap.height,
            snap.channels.len()
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
