//! A frame as files other tools read: a NumPy `.npy` array of every channel ([`npy`]), and one
//! channel as a ROS map_server map, PGM + YAML, for RViz or map_server ([`ros_map`]). Used by
//! `pheromone export` and by `pheromone sim --out` (`field_final.npy`); [`live`] waits for the
//! frame `pheromone export` writes.

pub mod live;
pub mod npy;
pub mod ros_map;

use std::path::Path;

/// Writing an export failed.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// Writing the file failed, or its path names something other than a regular file.
    #[error(transparent)]
    Output(#[from] pheromone_field::outfile::OutputError),
    /// The cells do not fill the announced shape.
    #[error("{} values for {channels} × {height} × {width} cells", len)]
    Shape {
        len: usize,
        channels: usize,
        height: usize,
        width: usize,
    },
    /// The scale of a ROS map is empty or not finite.
    #[error("scale {min} … {max}: needs finite numbers with min < max")]
    Scale { min: f32, max: f32 },
}

/// Writes `bytes` to a temporary file beside `path` and renames it over `path`
/// ([`pheromone_field::outfile`]): a reader never sees half a file, and a path naming anything
/// but a regular file is refused.
pub(crate) fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    pheromone_field::outfile::write_file(path, bytes)?;
    Ok(())
}
