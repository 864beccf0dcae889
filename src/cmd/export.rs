//! `pheromone export`: the next frame of a running field as a NumPy `.npy` file (every
//! channel) or as a ROS map_server map (one channel, PGM + YAML). The writers are
//! `pheromone_report::export`, the wait for the frame `pheromone_report::export::live`.

use std::path::{Path, PathBuf};
use std::time::Duration;

use clap::Args;
use pheromone_field::shm::{create_node, FieldReader, Frame};
use pheromone_report::export::live::next_frame;
use pheromone_report::export::npy::write_npy;
use pheromone_report::export::ros_map::{write_ros_map, PlaneRef};

use super::bad;

/// Save the next frame of a running field: `--out frame.npy` writes every channel as a
/// `(channels, height, width)` little-endian float32 NumPy array (`numpy.load`); `--out
/// map.yaml` writes one channel (`--channel`) as a ROS map_server map, `map.pgm` beside it,
/// scaled to 0–255 (the scale is in the YAML's comments), with the field's cell size as
/// `resolution` and its lower-left corner as `origin`, for RViz or map_server.
///
/// It waits up to --timeout-s for the field and then for a frame newer than the one it finds;
/// a field that publishes none in that time (paused, or waiting for its clock) is exported as
/// its current frame, as is a mirror whose origin went silent (at once, and said so).
#[derive(Args, Debug)]
pub struct ExportArgs {
    /// Field name.
    #[arg(long, default_value = "main")]
    pub field: String,
    /// Output file: `*.npy`, or `*.yaml` / `*.yml` (a map_server map; the PGM gets the same
    /// name with `.pgm`).
    #[arg(long, value_name = "FILE", value_parser = super::check::out_file())]
    pub out: PathBuf,
    /// Channel of a map_server map.
    #[arg(long, value_parser = super::int::<usize>(0, 63), default_value_t = 0)]
    pub channel: usize,
    /// The value that becomes pixel 0 of a map [default: min(0, the channel's smallest)].
    #[arg(long, value_parser = super::f32_any(), allow_negative_numbers = true)]
    pub min: Option<f32>,
    /// The value that becomes pixel 255 of a map [default: the channel's largest].
    #[arg(long, value_parser = super::f32_any(), allow_negative_numbers = true)]
    pub max: Option<f32>,
    /// Seconds to wait for the field, and then for its next frame.
    #[arg(long, value_parser = super::secs(), default_value_t = 5.0, value_name = "SECS")]
    pub timeout_s: f64,
    /// Print one JSON object on stdout (what was written, from which frame).
    #[arg(long)]
    pub json: bool,
}

enum Format {
    Npy,
    RosMap,
}

pub fn run(a: ExportArgs) -> anyhow::Result<()> {
    let format = format_of(&a.out)?;
    let timeout = Duration::from_secs_f64(a.timeout_s);
    let node = create_node(&format!("export-{}", std::process::id()))?;
    let mut reader = FieldReader::attach_within(&node, &a.field, timeout)?;
    let next = next_frame(&node, &mut reader, &a.field, timeout)?;
    let Some(frame) = reader.frame() else {
        anyhow::bail!(
            "field '{}' published no frame within {} s",
            a.field,
            a.timeout_s
        );
    };
    if let Some(m) = next.stale_mirror() {
        eprintln!(
            "field '{}' is stale ({}): exporting its current frame {}",
            a.field,
            m.describe(),
            frame.header.sequence
        );
    } else if !next.fresh {
        eprintln!(
            "field '{}' published no new frame within {} s: exporting its current frame {}",
            a.field, a.timeout_s, frame.header.sequence
        );
    }
    let h = *frame.header;
    let (c, height, width) = (h.channels as usize, h.height as usize, h.width as usize);
    let mut report = serde_json::json!({
        "field": a.field, "out": a.out, "sequence": h.sequence, "sim_time_s": h.sim_time_s,
        "fresh": next.fresh, "shape": [c, height, width], "cell_size_m": h.cell_size_m,
        "origin_m": [h.origin_x_m, h.origin_y_m], "mirror": next.mirror,
    });
    match format {
        Format::Npy => {
            write_npy(&a.out, c, height, width, frame.view.cells)?;
            eprintln!(
                "frame {} of field '{}' ({c} × {height} × {width} float32) written to {}",
                h.sequence,
                a.field,
                a.out.display()
            );
        }
        Format::RosMap => export_ros_map(&a, &frame, &mut report)?,
    }
    if a.json {
        println!("{report}");
    }
    Ok(())
}

/// The format `--out`'s extension asks for.
fn format_of(out: &Path) -> anyhow::Result<Format> {
    match out.extension().and_then(|e| e.to_str()) {
        Some("npy") => Ok(Format::Npy),
        Some("yaml" | "yml") => Ok(Format::RosMap),
        _ => Err(bad(format!(
            "--out {}: the file must end in .npy (NumPy) or .yaml (ROS map_server map)",
            out.display()
        ))),
    }
}

/// Writes `--channel` of `frame` as a ROS map_server map and adds what was written to `report`.
fn export_ros_map(
    a: &ExportArgs,
    frame: &Frame<'_>,
    report: &mut serde_json::Value,
) -> anyhow::Result<()> {
    let h = *frame.header;
    let (c, height, width) = (h.channels as usize, h.height as usize, h.width as usize);
    if a.channel >= c {
        return Err(bad(format!(
            "--channel {}: field '{}' has {c} channel(s)",
            a.channel, a.field
        )));
    }
    let plane = PlaneRef {
        cells: frame.view.plane(a.channel),
        width,
        height,
        cell_size_m: h.cell_size_m,
        origin_m: [h.origin_x_m, h.origin_y_m],
    };
    let scale = map_scale(a, plane.cells)?;
    let comment = format!(
        "pheromone export: field '{}', channel {}, frame {} at t = {} s",
        a.field, a.channel, h.sequence, h.sim_time_s
    );
    let w = write_ros_map(&a.out, plane, scale, &comment)?;
    eprintln!(
        "channel {} of frame {} of field '{}' written to {} and {} (scale {} … {})",
        a.channel,
        h.sequence,
        a.field,
        w.yaml.display(),
        w.pgm.display(),
        w.scale_min,
        w.scale_max
    );
    report["channel"] = a.channel.into();
    report["pgm"] = serde_json::json!(w.pgm);
    report["scale"] = serde_json::json!([w.scale_min, w.scale_max]);
    Ok(())
}

/// The map's scale from `--min` / `--max` (defaults from the channel), checked.
fn map_scale(a: &ExportArgs, cells: &[f32]) -> anyhow::Result<Option<(f32, f32)>> {
    let (lo, hi) = pheromone_report::export::ros_map::default_scale(cells);
    let scale = match (a.min, a.max) {
        (None, None) => None,
        (min, max) => Some((min.unwrap_or(lo), max.unwrap_or(hi))),
    };
    if let Some((min, max)) = scale {
        if !(min.is_finite() && max.is_finite() && min < max) {
            return Err(bad(format!(
                "--min {min} --max {max}: the scale needs finite numbers with min < max"
            )));
        }
    }
    Ok(scale)
}
