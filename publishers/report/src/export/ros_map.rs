//! One channel of a frame as a ROS map_server map: an 8-bit binary PGM (P5) and its YAML, for
//! RViz (`nav2_map_server`, `map_server`) or for [`OccupancyMap`](pheromone_world::OccupancyMap).
//!
//! A value v becomes the pixel `round(255 · (v − min) / (max − min))` (clamped to 0–255) and the
//! YAML says `negate: 1`, so map_server reads the occupancy probability p = pixel / 255 — the
//! value scaled to [0, 1]: where the pheromone is strong, the map is "occupied". The scale is
//! written into the YAML as comments (`# scale_min:`, `# scale_max:`) that map_server skips.
//! The image's first row is the top of the map (largest y), as map_server expects; `resolution`
//! is the field's cell size and `origin` its lower-left corner.

use std::path::{Path, PathBuf};

use super::{write_atomically, ExportError};

/// One plane of a frame and where it lies.
#[derive(Debug, Clone, Copy)]
pub struct PlaneRef<'a> {
    /// `height` rows of `width` cells, row 0 at the bottom (y = origin).
    pub cells: &'a [f32],
    pub width: usize,
    pub height: usize,
    pub cell_size_m: f32,
    /// World position of the lower-left corner of cell (0, 0) (m).
    pub origin_m: [f32; 2],
}

/// What [`write_ros_map`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct RosMapWritten {
    pub yaml: PathBuf,
    pub pgm: PathBuf,
    pub scale_min: f32,
    pub scale_max: f32,
}

/// The default scale of a plane: from min(0, smallest value) to its largest value (1 above the
/// minimum when the plane is flat).
pub fn default_scale(cells: &[f32]) -> (f32, f32) {
    let finite = cells.iter().copied().filter(|v| v.is_finite());
    let (lo, hi) = finite.fold((0.0f32, f32::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if hi > lo {
        (lo, hi)
    } else {
        (lo, lo + 1.0)
    }
}

/// The 8-bit pixel of a value on the scale `min … max`.
pub fn pixel(v: f32, min: f32, max: f32) -> u8 {
    let p = (255.0 * (v - min) / (max - min)).round();
    // NaN (never in a frame) would become 0 too.
    p.clamp(0.0, 255.0) as u8
}

/// Writes `yaml_path` and the PGM beside it (same stem, `.pgm`); `comment` goes at the top of
/// the YAML (what was exported); `scale` defaults to [`default_scale`].
pub fn write_ros_map(
    yaml_path: &Path,
    plane: PlaneRef<'_>,
    scale: Option<(f32, f32)>,
    comment: &str,
) -> Result<RosMapWritten, ExportError> {
    let PlaneRef {
        cells,
        width,
        height,
        ..
    } = plane;
    if width * height != cells.len() {
        return Err(ExportError::Shape {
            len: cells.len(),
            channels: 1,
            height,
            width,
        });
    }
    let (min, max) = scale.unwrap_or_else(|| default_scale(cells));
    if !(min.is_finite() && max.is_finite() && min < max) {
        return Err(ExportError::Scale { min, max });
    }
    let comment = comment.replace(['\n', '\r'], " ");
    let pgm_path = yaml_path.with_extension("pgm");
    let mut pgm = format!("P5\n# {comment}\n{width} {height}\n255\n").into_bytes();
    pgm.reserve(cells.len());
    for row in cells.chunks_exact(width.max(1)).rev() {
        pgm.extend(row.iter().map(|&v| pixel(v, min, max)));
    }
    let image = pgm_path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let yaml = format!(
        "# {comment}\n\
         # pixel = round(255 * (value - scale_min) / (scale_max - scale_min)), clamped to 0..255;\n\
         # value = scale_min + pixel * (scale_max - scale_min) / 255. negate: 1, so p = pixel / 255.\n\
         # scale_min: {min}\n\
         # scale_max: {max}\n\
         image: {image}\n\
         mode: trinary\n\
         resolution: {res}\n\
         origin: [{ox}, {oy}, 0.0]\n\
         negate: 1\n\
         occupied_thresh: 0.65\n\
         free_thresh: 0.196\n",
        res = plane.cell_size_m,
        ox = plane.origin_m[0],
        oy = plane.origin_m[1],
    );
    write_atomically(&pgm_path, &pgm)?;
    write_atomically(yaml_path, yaml.as_bytes())?;
    Ok(RosMapWritten {
        yaml: yaml_path.to_path_buf(),
        pgm: pgm_path,
        scale_min: min,
        scale_max: max,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use pheromone_world::OccupancyMap;

    #[test]
    fn a_channel_round_trips_through_the_map_server_loader() {
        let (width, height) = (7, 5);
        // A ramp with its largest values at the top right: the image must not be flipped.
        let cells: Vec<f32> = (0..width * height)
            .map(|i| ((i % width) + 2 * (i / width)) as f32 * 0.3 - 0.4)
            .collect();
        let dir = std::env::temp_dir().join(format!("pheromone-rosmap-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let plane = PlaneRef {
            cells: &cells,
            width,
            height,
            cell_size_m: 0.25,
            origin_m: [-1.5, 2.0],
        };
        let out = write_ros_map(&dir.join("trail.yaml"), plane, None, "test\nexport").unwrap();
        assert_eq!(out.pgm, dir.join("trail.pgm"));
        let max = cells.iter().copied().fold(f32::MIN, f32::max);
        assert_eq!((out.scale_min, out.scale_max), (-0.4, max));
        let yaml = std::fs::read_to_string(&out.yaml).unwrap();
        assert!(yaml.contains(&format!("# scale_max: {max}\n")), "{yaml}");
        assert!(
            yaml.contains("image: trail.pgm\n") && yaml.contains("negate: 1\n"),
            "{yaml}"
        );

        let map = OccupancyMap::load(&out.yaml).unwrap();
        assert_eq!((map.width, map.height), (width, height));
        assert_eq!(map.resolution_m, 0.25);
        assert_eq!(map.origin_m, [-1.5, 2.0]);
        let mut occupied = 0;
        for (i, &v) in cells.iter().enumerate() {
            let p = f64::from(pixel(v, out.scale_min, out.scale_max)) / 255.0;
            let scaled = f64::from((v - out.scale_min) / (out.scale_max - out.scale_min));
            assert!(
                (p - scaled).abs() <= 0.5 / 255.0 + 1e-6,
                "cell {i}: {p} vs {scaled}"
            );
            assert_eq!(map.occupied[i], p > 0.65, "cell {i} (value {v})");
            occupied += usize::from(map.occupied[i]);
        }
        assert!(occupied > 0 && occupied < cells.len(), "{occupied}");
        // The bottom-left cell (smallest value) is free, the top-right one occupied.
        assert!(!map.occupied[0] && map.occupied[width * height - 1]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_scale_is_checked_and_flat_planes_get_one() {
        assert_eq!(default_scale(&[0.0; 4]), (0.0, 1.0));
        assert_eq!(default_scale(&[-2.0, 1.0]), (-2.0, 1.0));
        assert_eq!(pixel(5.0, 0.0, 1.0), 255);
        assert_eq!(pixel(-1.0, 0.0, 1.0), 0);
        let plane = PlaneRef {
            cells: &[0.0; 4],
            width: 2,
            height: 2,
            cell_size_m: 1.0,
            origin_m: [0.0, 0.0],
        };
        let e = write_ros_map(
            Path::new("/nonexistent/x.yaml"),
            plane,
            Some((1.0, 1.0)),
            "",
        )
        .unwrap_err();
        assert!(e.to_string().contains("scale 1 … 1"), "{e}");
    }
}
