//! ROS map_server occupancy maps: the YAML + PGM (P5 binary or P2 ASCII) loader of
//! [`OccupancyMap`], read in map_server's "trinary" mode, and its occupied cells merged into
//! wall rectangles for a world.

use std::path::{Path, PathBuf};

use thiserror::Error;

use super::WallConfig;

/// Why a ROS map could not be loaded.
#[derive(Debug, Error)]
pub enum MapError {
    #[error("cannot read {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("map yaml line {line}: {reason}")]
    Yaml { line: usize, reason: String },
    #[error("map yaml: missing key `{0}`")]
    MissingKey(&'static str),
    #[error("map yaml: `{key}` = {value} is invalid ({expected})")]
    InvalidValue {
        key: &'static str,
        value: f64,
        expected: &'static str,
    },
    #[error("pgm image: {0}")]
    Pgm(String),
}

/// An occupancy grid read from a ROS map_server map (YAML + PGM image).
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyMap {
    pub width: usize,
    pub height: usize,
    pub resolution_m: f64,
    /// World position of the lower-left corner of cell (0, 0).
    pub origin_m: [f64; 2],
    /// Row-major from the bottom row (y up), `true` = occupied.
    pub occupied: Vec<bool>,
}

/// The keys of a map_server YAML file.
#[derive(Debug, Clone, PartialEq)]
struct MapYaml {
    image: String,
    resolution_m: f64,
    origin: [f64; 3],
    negate: bool,
    occupied_thresh: f64,
}

impl OccupancyMap {
    /// Loads `map.yaml` and the image it names (relative to the YAML's directory).
    pub fn load(yaml_path: &Path) -> Result<Self, MapError> {
        let text = std::fs::read_to_string(yaml_path).map_err(|source| MapError::Io {
            path: yaml_path.to_path_buf(),
            source,
        })?;
        let yaml = parse_map_yaml(&text)?;
        let image_path = yaml_path
            .parent()
            .unwrap_or_else(|| Path::new("."))
            .join(&yaml.image);
        let bytes = std::fs::read(&image_path).map_err(|source| MapError::Io {
            path: image_path.clone(),
            source,
        })?;
        Self::from_parts(&text, &bytes)
    }

    /// Builds a map from the YAML text and the PGM bytes (P5 binary or P2 ASCII). A cell is
    /// occupied when its occupancy probability exceeds `occupied_thresh` (map_server "trinary"
    /// reading: p = (max − value)/max, or value/max with `negate: 1`).
    pub fn from_parts(yaml_text: &str, pgm_bytes: &[u8]) -> Result<Self, MapError> {
        let yaml = parse_map_yaml(yaml_text)?;
        let (width, height, maxval, pixels) = parse_pgm(pgm_bytes)?;
        let mut occupied = vec![false; width * height];
        for row in 0..height {
            // The image's first row is the top of the map.
            let y = height - 1 - row;
            for x in 0..width {
                let v = f64::from(pixels[row * width + x]) / f64::from(maxval);
                let p = if yaml.negate { v } else { 1.0 - v };
                occupied[y * width + x] = p > yaml.occupied_thresh;
            }
        }
        Ok(Self {
            width,
            height,
            resolution_m: yaml.resolution_m,
            origin_m: [yaml.origin[0], yaml.origin[1]],
            occupied,
        })
    }

    /// Occupied cells merged into rectangles: runs along each row, then identical runs of
    /// consecutive rows joined, so a wall of many cells becomes a few rectangles.
    pub fn to_walls(&self) -> Vec<WallConfig> {
        let res = self.resolution_m;
        let mut open: std::collections::HashMap<(usize, usize), usize> = Default::default();
        let mut rects: Vec<(usize, usize, usize, usize)> = Vec::new(); // x0, x1 (excl), y0, y1 (excl)
        for y in 0..self.height {
            let mut next_open = std::collections::HashMap::new();
            let row = &self.occupied[y * self.width..(y + 1) * self.width];
            let mut x = 0;
            while x < self.width {
                if !row[x] {
                    x += 1;
                    continue;
                }
                let start = x;
                while x < self.width && row[x] {
                    x += 1;
                }
                let key = (start, x);
                let idx = match open.get(&key) {
                    Some(&idx) => {
                        rects[idx].3 = y + 1;
                        idx
                    }
                    None => {
                        rects.push((start, x, y, y + 1));
                        rects.len() - 1
                    }
                };
                next_open.insert(key, idx);
            }
            open = next_open;
        }
        rects
            .into_iter()
            .map(|(x0, x1, y0, y1)| WallConfig::Rect {
                min_x_m: self.origin_m[0] + x0 as f64 * res,
                max_x_m: self.origin_m[0] + x1 as f64 * res,
                min_y_m: self.origin_m[1] + y0 as f64 * res,
                max_y_m: self.origin_m[1] + y1 as f64 * res,
            })
            .collect()
    }
}

fn parse_map_yaml(text: &str) -> Result<MapYaml, MapError> {
    let mut image = None;
    let mut resolution = None;
    let mut origin = None;
    let mut negate = false;
    let mut occupied_thresh = 0.65;
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let yaml_err = |reason: String| MapError::Yaml {
            line: line_no,
            reason,
        };
        let (key, value) = line
            .split_once(':')
            .ok_or_else(|| yaml_err(format!("expected `key: value`, got `{line}`")))?;
        let value = value.trim();
        let number = |v: &str| -> Result<f64, MapError> {
            v.trim()
                .parse::<f64>()
                .map_err(|_| yaml_err(format!("`{}` is not a number", v.trim())))
        };
        match key.trim() {
            "image" => image = Some(value.trim_matches(['"', '\'']).to_string()),
            "resolution" => resolution = Some(number(value)?),
            "origin" => {
                let inner = value
                    .strip_prefix('[')
                    .and_then(|v| v.strip_suffix(']'))
                    .ok_or_else(|| yaml_err("origin must be `[x, y, yaw]`".into()))?;
                let parts: Vec<&str> = inner.split(',').collect();
                if parts.len() != 3 {
                    return Err(yaml_err("origin must be `[x, y, yaw]`".into()));
                }
                origin = Some([number(parts[0])?, number(parts[1])?, number(parts[2])?]);
            }
            "negate" => negate = number(value)? != 0.0,
            "occupied_thresh" => occupied_thresh = number(value)?,
            "free_thresh" => {
                number(value)?;
            }
            "mode" => {
                if value.trim_matches(['"', '\'']) != "trinary" {
                    return Err(yaml_err(format!(
                        "mode `{value}` unsupported (trinary only)"
                    )));
                }
            }
            other => return Err(yaml_err(format!("unknown key `{other}`"))),
        }
    }
    let resolution_m = resolution.ok_or(MapError::MissingKey("resolution"))?;
    if !(resolution_m.is_finite() && resolution_m > 0.0) {
        return Err(MapError::InvalidValue {
            key: "resolution",
            value: resolution_m,
            expected: "finite and > 0",
        });
    }
    let origin = origin.ok_or(MapError::MissingKey("origin"))?;
    if !origin.iter().all(|v| v.is_finite()) {
        return Err(MapError::InvalidValue {
            key: "origin",
            value: f64::NAN,
            expected: "finite",
        });
    }
    if origin[2].abs() > 1e-9 {
        return Err(MapError::InvalidValue {
            key: "origin",
            value: origin[2],
            expected: "yaw 0: walls are axis-aligned",
        });
    }
    if !(0.0..=1.0).contains(&occupied_thresh) {
        return Err(MapError::InvalidValue {
            key: "occupied_thresh",
            value: occupied_thresh,
            expected: "in [0, 1]",
        });
    }
    Ok(MapYaml {
        image: image.ok_or(MapError::MissingKey("image"))?,
        resolution_m,
        origin,
        negate,
        occupied_thresh,
    })
}

/// Parses a PGM image (P5 binary with maxval < 256 or ≥ 256, or P2 ASCII) into
/// `(width, height, maxval, pixels)`, pixels row-major from the top row.
fn parse_pgm(bytes: &[u8]) -> Result<(usize, usize, u16, Vec<u16>), MapError> {
    let err = |m: &str| MapError::Pgm(m.to_string());
    let mut pos = 0;
    // Header tokens, skipping whitespace and `#` comments.
    let next_token = |pos: &mut usize| -> Option<String> {
        loop {
            while *pos < bytes.len() && bytes[*pos].is_ascii_whitespace() {
                *pos += 1;
            }
            if *pos < bytes.len() && bytes[*pos] == b'#' {
                while *pos < bytes.len() && bytes[*pos] != b'\n' {
                    *pos += 1;
                }
                continue;
            }
            break;
        }
        let start = *pos;
        while *pos < bytes.len() && !bytes[*pos].is_ascii_whitespace() {
            *pos += 1;
        }
        (start < *pos).then(|| String::from_utf8_lossy(&bytes[start..*pos]).into_owned())
    };
    let magic = next_token(&mut pos).ok_or_else(|| err("empty file"))?;
    let mut header_num = |name: &str| -> Result<usize, MapError> {
        next_token(&mut pos)
            .and_then(|t| t.parse::<usize>().ok())
            .ok_or_else(|| MapError::Pgm(format!("bad or missing {name}")))
    };
    let width = header_num("width")?;
    let height = header_num("height")?;
    let maxval = header_num("maxval")?;
    if width == 0 || height == 0 || !(1..=65535).contains(&maxval) {
        return Err(err("width, height must be > 0 and maxval in 1..=65535"));
    }
    let n = width
        .checked_mul(height)
        .ok_or_else(|| err("image too large"))?;
    // Never reserve more than the file can hold: a header may claim any size.
    let mut pixels = Vec::with_capacity(n.min(bytes.len()));
    match magic.as_str() {
        "P5" => {
            pos += 1; // single whitespace after maxval
            let bpp = if maxval < 256 { 1 } else { 2 };
            let data = n
                .checked_mul(bpp)
                .and_then(|len| pos.checked_add(len))
                .and_then(|end| bytes.get(pos..end))
                .ok_or_else(|| err("truncated pixel data"))?;
            if bpp == 1 {
                pixels.extend(data.iter().map(|&b| u16::from(b)));
            } else {
                pixels.extend(
                    data.chunks_exact(2)
                        .map(|c| u16::from_be_bytes([c[0], c[1]])),
                );
            }
        }
        "P2" => {
            for _ in 0..n {
                let v = next_token(&mut pos)
                    .and_then(|t| t.parse::<u16>().ok())
                    .ok_or_else(|| err("truncated or bad ASCII pixel data"))?;
                pixels.push(v);
            }
        }
        other => {
            return Err(MapError::Pgm(format!(
                "unsupported magic `{other}` (P5 or P2)"
            )))
        }
    }
    if pixels.iter().any(|&v| usize::from(v) > maxval) {
        return Err(err("pixel above maxval"));
    }
    Ok((width, height, maxval as u16, pixels))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::roles::world::test_support::one_robot;
    use crate::roles::world::{World, WorldPose};
    use std::f64::consts::FRAC_PI_2;

    const MAP_YAML: &str = "image: map.pgm\nresolution: 0.5\norigin: [-1.0, -2.0, 0.0]\n\
                            negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196 # comment\n";

    #[test]
    fn ros_map_p2_becomes_merged_rectangles() {
        // 4×3 image, top row first; 0 = black = occupied.
        let pgm = b"P2\n# made by hand\n4 3\n255\n0 0 255 255\n0 0 255 254\n255 255 255 0\n";
        let map = OccupancyMap::from_parts(MAP_YAML, pgm).unwrap();
        assert_eq!((map.width, map.height), (4, 3));
        // Bottom row (image row 2): only x = 3 occupied.
        assert_eq!(&map.occupied[0..4], &[false, false, false, true]);
        let walls = map.to_walls();
        assert_eq!(walls.len(), 2);
        assert!(walls.contains(&WallConfig::Rect {
            min_x_m: -1.0,
            max_x_m: 0.0,
            min_y_m: -1.5,
            max_y_m: -0.5,
        }));
        assert!(walls.contains(&WallConfig::Rect {
            min_x_m: 0.5,
            max_x_m: 1.0,
            min_y_m: -2.0,
            max_y_m: -1.5,
        }));
        // A world built from them blocks a robot.
        let mut cfg = one_robot(WorldPose::new(-0.5, -3.0, FRAC_PI_2));
        cfg.robot_radius_m = 0.1;
        cfg.walls = walls;
        let mut world = World::new(cfg, 0).unwrap();
        for _ in 0..40 {
            world.step(&[(1.0, 0.0)]);
        }
        assert!(world.poses()[0].y_m <= -1.5 - 0.1 + 1e-9);
    }

    #[test]
    fn ros_map_p5_and_errors() {
        let mut pgm = b"P5 2 2 255\n".to_vec();
        pgm.extend([0u8, 255, 255, 10]);
        let map = OccupancyMap::from_parts(MAP_YAML, &pgm).unwrap();
        assert_eq!(map.occupied, vec![false, true, true, false]);
        let negated = MAP_YAML.replace("negate: 0", "negate: 1");
        let map = OccupancyMap::from_parts(&negated, &pgm).unwrap();
        assert_eq!(map.occupied, vec![true, false, false, true]);
        assert!(matches!(
            OccupancyMap::from_parts(MAP_YAML, b"P5 2 2 255\n\x00"),
            Err(MapError::Pgm(_))
        ));
        assert!(matches!(
            OccupancyMap::from_parts("image: a.pgm\nresolution: 0.1\n", &pgm),
            Err(MapError::MissingKey("origin"))
        ));
        assert!(matches!(
            OccupancyMap::from_parts(&format!("{MAP_YAML}bogus: 1\n"), &pgm),
            Err(MapError::Yaml { line: 7, .. })
        ));
    }
}
