//! A frame as files other tools read: a NumPy `.npy` array of every channel ([`npy`]), and one
//! channel as a ROS map_server map, PGM + YAML, for RViz or map_server ([`ros_map`]). Used by
//! `pheromone export` and by `pheromone sim --out` (`field_final.npy`); [`live`] waits for the
//! frame `pheromone export` writes.

pub mod live;
pub mod npy;
pub mod ros_map;

use std::io::Write as _;
use std::path::{Path, PathBuf};

/// Writing an export failed.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// Creating or writing the file failed.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
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

/// Writes `bytes` to `path.tmp` and renames it to `path`: a reader never sees half a file.
pub(crate) fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    let io = |source| ExportError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    let mut f = std::fs::File::create(&tmp).map_err(io)?;
    f.write_all(bytes).map_err(io)?;
    f.sync_all().map_err(io)?;
    drop(f);
    std::fs::rename(&tmp, path).map_err(io)
}
