//! Writing the files of a run: a whole file at once, the CSV time series of one robot, and a
//! picture as an 8-bit RGB PNG.

use std::fmt::Write as _;
use std::path::Path;

use pheromone_field::outfile::OutFile;

use super::style::Picture;
use super::{ReportError, ROBOT_CSV_HEADER};
use pheromone_sim::recording::RobotSample;

/// Writes the whole file through [`pheromone_field::outfile`]: a regular file or a new path only,
/// never a half-written file under its name.
pub(super) fn write_file(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    pheromone_field::outfile::write_file(path, bytes)?;
    Ok(())
}

/// Writes `value` as pretty JSON, as [`write_file`] does; a value JSON cannot hold is an error
/// naming the path.
pub(super) fn write_json<T: serde::Serialize + ?Sized>(
    path: &Path,
    value: &T,
) -> Result<(), ReportError> {
    let json = serde_json::to_string_pretty(value).map_err(|source| ReportError::Json {
        path: path.to_path_buf(),
        source,
    })?;
    write_file(path, json.as_bytes())
}

pub(super) fn robot_csv(rows: &[RobotSample]) -> String {
    fn opt<T: std::fmt::Display>(v: Option<T>) -> String {
        v.map(|v| v.to_string()).unwrap_or_default()
    }
    let mut text = String::with_capacity(64 * (rows.len() + 1));
    text.push_str(ROBOT_CSV_HEADER);
    text.push('\n');
    for r in rows {
        let est = r.est_pose;
        // Writing into a String cannot fail.
        let _ = writeln!(
            text,
            "{},{},{},{},{},{},{},{},{},{},{},{},{}",
            r.t_s,
            r.true_pose[0],
            r.true_pose[1],
            r.true_pose[2],
            opt(est.map(|p| p[0])),
            opt(est.map(|p| p[1])),
            opt(est.map(|p| p[2])),
            opt(r.est_sigma_m),
            r.v_m_per_s,
            r.omega_rad_per_s,
            r.state.map(|s| s.name()).unwrap_or(""),
            opt(r.sensed_level),
            opt(r.deposit_peak),
        );
    }
    text
}

pub(super) fn write_png(path: &Path, pic: &Picture) -> Result<(), ReportError> {
    let png_err = |source| ReportError::Png {
        path: path.to_path_buf(),
        source,
    };
    let mut out = OutFile::create(path)?;
    {
        let mut encoder = png::Encoder::new(&mut out, pic.width, pic.height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_compression(png::Compression::Balanced);
        let mut writer = encoder.write_header().map_err(png_err)?;
        writer.write_image_data(&pic.rgb).map_err(png_err)?;
        writer.finish().map_err(png_err)?;
    }
    out.commit()?;
    Ok(())
}
