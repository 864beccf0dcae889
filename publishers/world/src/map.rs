//! ROS map_server occupancy maps: the YAML + PGM (P5 binary or P2 ASCII) loader of
//! [`OccupancyMap`], read in map_server's "trinary" mode, and its occupied cells merged into
//! wall rectangles for a world.

use std::path::{Path, PathBuf};

use pheromone_field::infile;
use thiserror::Error;

use super::WallConfig;

/// Why a ROS map could not be loaded. [`OccupancyMap::load`] names the file
/// ([`MapError::File`]); the causes name the line of the YAML or the byte of the PGM.
#[derive(Debug, Error)]
pub enum MapError {
    #[error("cannot read {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// A problem in file `path` (the YAML or the image it names).
    #[error("{}: {source}", path.display())]
    File {
        path: PathBuf,
        #[source]
        source: Box<MapError>,
    },
    #[error("map yaml line {line}: {reason}")]
    Yaml { line: usize, reason: String },
    #[error("map yaml: missing key `{0}`")]
    MissingKey(&'static str),
    #[error("map yaml line {line}: `{key}` = {value} is invalid ({expected})")]
    InvalidValue {
        line: usize,
        key: &'static str,
        value: f64,
        expected: &'static str,
    },
    /// The image, at byte offset `byte` of the PGM file.
    #[error("pgm image byte {byte}: {reason}")]
    Pgm { byte: usize, reason: String },
    /// Neither a file nor the name of a built-in map ([`BUILTIN_MAPS`]).
    #[error("{name}: no such file, and no built-in map of that name (built-in: {builtin})")]
    Unknown { name: String, builtin: String },
}

/// Built-in maps: (name, YAML text, PGM bytes), usable by name wherever a map file is taken
/// (`sim --map rooms`), from any directory. The files are in `examples/maps/`.
pub const BUILTIN_MAPS: &[(&str, &str, &[u8])] = &[(
    "rooms",
    include_str!("../../../examples/maps/rooms.yaml"),
    include_bytes!("../../../examples/maps/rooms.pgm"),
)];

/// The names of the built-in maps, comma-separated.
pub fn builtin_map_names() -> String {
    BUILTIN_MAPS
        .iter()
        .map(|(n, _, _)| *n)
        .collect::<Vec<_>>()
        .join(", ")
}

impl MapError {
    fn in_file(self, path: &Path) -> Self {
        MapError::File {
            path: path.to_path_buf(),
            source: Box::new(self),
        }
    }
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
    /// Loads `map.yaml` and the image it names (a relative `image` is relative to the YAML's
    /// directory). Errors name the file ([`MapError::File`]) and the line or byte.
    pub fn load(yaml_path: &Path) -> Result<Self, MapError> {
        let text =
            infile::read_text_bounded(yaml_path, infile::MAX_TEXT_BYTES).map_err(|source| {
                MapError::Io {
                    path: yaml_path.to_path_buf(),
                    source,
                }
            })?;
        let yaml = parse_map_yaml(&text).map_err(|e| e.in_file(yaml_path))?;
        let image_path = yaml_path
            .parent()
            .unwrap_or_else(|| Path::new("."))
            .join(&yaml.image);
        let bytes =
            infile::read_bounded(&image_path, infile::MAX_IMAGE_BYTES).map_err(|source| {
                MapError::Io {
                    path: image_path.clone(),
                    source,
                }
            })?;
        let image = parse_pgm(&bytes).map_err(|e| e.in_file(&image_path))?;
        Ok(Self::from_yaml_and_image(&yaml, image))
    }

    /// A map file (as [`OccupancyMap::load`]) or, if `name_or_path` is not a file, the built-in
    /// map of that name ([`BUILTIN_MAPS`]). A file wins over a built-in of the same name.
    pub fn open(name_or_path: &Path) -> Result<Self, MapError> {
        if name_or_path.is_file() {
            return Self::load(name_or_path);
        }
        let name = name_or_path.to_string_lossy();
        match BUILTIN_MAPS.iter().find(|(n, _, _)| *n == name) {
            Some((n, yaml, pgm)) => Self::from_parts(yaml, pgm).map_err(|e| MapError::File {
                path: PathBuf::from(format!("built-in map '{n}'")),
                source: Box::new(e),
            }),
            None if name_or_path.exists() => Self::load(name_or_path),
            None => Err(MapError::Unknown {
                name: name.into_owned(),
                builtin: builtin_map_names(),
            }),
        }
    }

    /// The world rectangle the map covers: `[min_x, min_y]`, `[max_x, max_y]` (m).
    pub fn extent_m(&self) -> ([f64; 2], [f64; 2]) {
        let [x0, y0] = self.origin_m;
        (
            [x0, y0],
            [
                x0 + self.width as f64 * self.resolution_m,
                y0 + self.height as f64 * self.resolution_m,
            ],
        )
    }

    /// Builds a map from the YAML text and the PGM bytes (P5 binary or P2 ASCII). A cell is
    /// occupied when its occupancy probability exceeds `occupied_thresh` (map_server "trinary"
    /// reading: p = (max − value)/max, or value/max with `negate: 1`); free cells (p <
    /// `free_thresh`) and unknown ones are open space for the simulator. `free_thresh` is
    /// checked (in [0, 1], at most `occupied_thresh`).
    pub fn from_parts(yaml_text: &str, pgm_bytes: &[u8]) -> Result<Self, MapError> {
        let yaml = parse_map_yaml(yaml_text)?;
        Ok(Self::from_yaml_and_image(&yaml, parse_pgm(pgm_bytes)?))
    }

    fn from_yaml_and_image(yaml: &MapYaml, image: (usize, usize, u16, Vec<u16>)) -> Self {
        let (width, height, maxval, pixels) = image;
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
        Self {
            width,
            height,
            resolution_m: yaml.resolution_m,
            origin_m: [yaml.origin[0], yaml.origin[1]],
            occupied,
        }
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

/// The keys of a map_server YAML file as read, before they are checked: each value with the
/// line it was on (the thresholds' defaults on line 0).
struct RawMapYaml {
    image: Option<String>,
    resolution: Option<(f64, usize)>,
    origin: Option<([f64; 3], usize)>,
    negate: bool,
    occupied_thresh: (f64, usize),
    free_thresh: (f64, usize),
}

impl Default for RawMapYaml {
    /// No keys read yet: map_server's default thresholds.
    fn default() -> Self {
        Self {
            image: None,
            resolution: None,
            origin: None,
            negate: false,
            occupied_thresh: (0.65, 0),
            free_thresh: (0.196, 0),
        }
    }
}

/// The error of line `line`: `reason`.
fn yaml_err(line: usize, reason: String) -> MapError {
    MapError::Yaml { line, reason }
}

/// A number of line `line`, or the error naming it.
fn yaml_number(v: &str, line: usize) -> Result<f64, MapError> {
    v.trim()
        .parse::<f64>()
        .map_err(|_| yaml_err(line, format!("`{}` is not a number", v.trim())))
}

/// An `origin` value, `[x, y, yaw]`, of line `line`.
fn yaml_origin(value: &str, line: usize) -> Result<[f64; 3], MapError> {
    let inner = value
        .strip_prefix('[')
        .and_then(|v| v.strip_suffix(']'))
        .ok_or_else(|| yaml_err(line, "origin must be `[x, y, yaw]`".into()))?;
    let parts: Vec<&str> = inner.split(',').collect();
    if parts.len() != 3 {
        return Err(yaml_err(line, "origin must be `[x, y, yaw]`".into()));
    }
    Ok([
        yaml_number(parts[0], line)?,
        yaml_number(parts[1], line)?,
        yaml_number(parts[2], line)?,
    ])
}

impl RawMapYaml {
    /// Reads one line (`line_no` from 1) of the YAML: a comment, a blank or one known key.
    fn read_line(&mut self, line_no: usize, raw: &str) -> Result<(), MapError> {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            return Ok(());
        }
        let (key, value) = line
            .split_once(':')
            .ok_or_else(|| yaml_err(line_no, format!("expected `key: value`, got `{line}`")))?;
        let value = value.trim();
        let number = |v: &str| yaml_number(v, line_no);
        match key.trim() {
            "image" => {
                let name = value.trim_matches(['"', '\'']);
                if name.is_empty() {
                    return Err(yaml_err(line_no, "`image` is empty".into()));
                }
                self.image = Some(name.to_string());
            }
            "resolution" => self.resolution = Some((number(value)?, line_no)),
            "origin" => self.origin = Some((yaml_origin(value, line_no)?, line_no)),
            "negate" => self.negate = number(value)? != 0.0,
            "occupied_thresh" => self.occupied_thresh = (number(value)?, line_no),
            "free_thresh" => self.free_thresh = (number(value)?, line_no),
            "mode" => {
                if value.trim_matches(['"', '\'']) != "trinary" {
                    return Err(yaml_err(
                        line_no,
                        format!("mode `{value}` unsupported (trinary only)"),
                    ));
                }
            }
            other => return Err(yaml_err(line_no, format!("unknown key `{other}`"))),
        }
        Ok(())
    }

    /// The resolution, present, finite and from `MIN_RESOLUTION_M` to `MAX_RESOLUTION_M`.
    fn resolution_m(&self) -> Result<f64, MapError> {
        let (resolution_m, line) = self.resolution.ok_or(MapError::MissingKey("resolution"))?;
        if !(resolution_m.is_finite()
            && (MIN_RESOLUTION_M..=MAX_RESOLUTION_M).contains(&resolution_m))
        {
            return Err(MapError::InvalidValue {
                line,
                key: "resolution",
                value: resolution_m,
                expected: "a finite number of metres per cell from 0.001 to 1000",
            });
        }
        Ok(resolution_m)
    }

    /// The origin, present, finite and with yaw 0.
    fn origin(&self) -> Result<[f64; 3], MapError> {
        let (origin, line) = self.origin.ok_or(MapError::MissingKey("origin"))?;
        if let Some(v) = origin.iter().find(|v| !v.is_finite()) {
            return Err(MapError::InvalidValue {
                line,
                key: "origin",
                value: *v,
                expected: "finite",
            });
        }
        if origin[2].abs() > 1e-9 {
            return Err(MapError::InvalidValue {
                line,
                key: "origin",
                value: origin[2],
                expected: "yaw 0: walls are axis-aligned",
            });
        }
        Ok(origin)
    }

    /// Checks both thresholds are in [0, 1] and `free_thresh` at most `occupied_thresh`.
    fn check_thresholds(&self) -> Result<(), MapError> {
        let (occupied_thresh, free_thresh) = (self.occupied_thresh, self.free_thresh);
        for (key, (v, line)) in [
            ("occupied_thresh", occupied_thresh),
            ("free_thresh", free_thresh),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(MapError::InvalidValue {
                    line,
                    key,
                    value: v,
                    expected: "in [0, 1]",
                });
            }
        }
        if free_thresh.0 > occupied_thresh.0 {
            return Err(MapError::InvalidValue {
                line: free_thresh.1,
                key: "free_thresh",
                value: free_thresh.0,
                expected: "at most occupied_thresh",
            });
        }
        Ok(())
    }

    /// The checked keys: resolution, origin, thresholds, then the image, in that order.
    fn finish(self) -> Result<MapYaml, MapError> {
        let resolution_m = self.resolution_m()?;
        let origin = self.origin()?;
        self.check_thresholds()?;
        Ok(MapYaml {
            image: self.image.ok_or(MapError::MissingKey("image"))?,
            resolution_m,
            origin,
            negate: self.negate,
            occupied_thresh: self.occupied_thresh.0,
        })
    }
}

/// Parses and checks a map_server YAML file's text.
/// The finest map resolution taken (m per cell): finer is a unit mistake (mm given as m), and
/// its walls would be far below any field cell.
pub const MIN_RESOLUTION_M: f64 = 1e-3;
/// The coarsest map resolution taken (m per cell).
pub const MAX_RESOLUTION_M: f64 = 1e3;

fn parse_map_yaml(text: &str) -> Result<MapYaml, MapError> {
    let mut raw = RawMapYaml::default();
    for (i, line) in text.lines().enumerate() {
        raw.read_line(i + 1, line)?;
    }
    raw.finish()
}

/// Parses a PGM image (P5 binary with maxval < 256 or ≥ 256, or P2 ASCII) into
/// `(width, height, maxval, pixels)`, pixels row-major from the top row. Errors carry the byte
/// offset where the problem is.
fn parse_pgm(bytes: &[u8]) -> Result<(usize, usize, u16, Vec<u16>), MapError> {
    let err = |byte: usize, m: &str| MapError::Pgm {
        byte,
        reason: m.to_string(),
    };
    let mut pos = 0;
    // Header tokens, skipping whitespace and `#` comments: (offset, text).
    let next_token = |pos: &mut usize| -> (usize, Option<String>) {
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
        (
            start,
            (start < *pos).then(|| String::from_utf8_lossy(&bytes[start..*pos]).into_owned()),
        )
    };
    let (at, magic) = next_token(&mut pos);
    let magic = magic.ok_or_else(|| err(at, "empty file"))?;
    if magic != "P5" && magic != "P2" {
        return Err(err(at, &format!("unsupported magic `{magic}` (P5 or P2)")));
    }
    let mut header_num = |name: &str| -> Result<(usize, usize), MapError> {
        let (at, t) = next_token(&mut pos);
        t.and_then(|t| t.parse::<usize>().ok())
            .map(|v| (v, at))
            .ok_or_else(|| err(at, &format!("bad or missing {name}")))
    };
    let (width, at_w) = header_num("width")?;
    let (height, at_h) = header_num("height")?;
    let (maxval, at_m) = header_num("maxval")?;
    if width == 0 {
        return Err(err(at_w, "width must be > 0"));
    }
    if height == 0 {
        return Err(err(at_h, "height must be > 0"));
    }
    if !(1..=65535).contains(&maxval) {
        return Err(err(at_m, "maxval must be in 1..=65535"));
    }
    let n = width
        .checked_mul(height)
        .ok_or_else(|| err(at_w, "image too large"))?;
    // Never reserve more than the file can hold: a header may claim any size.
    let mut pixels = Vec::with_capacity(n.min(bytes.len()));
    if magic == "P5" {
        pos += 1; // single whitespace after maxval
        let bpp = if maxval < 256 { 1 } else { 2 };
        let data = n
            .checked_mul(bpp)
            .and_then(|len| pos.checked_add(len))
            .and_then(|end| bytes.get(pos..end))
            .ok_or_else(|| {
                err(
                    bytes.len(),
                    &format!(
                        "truncated pixel data: {width}×{height} pixels need {} bytes from byte {pos}",
                        n.saturating_mul(bpp)
                    ),
                )
            })?;
        if bpp == 1 {
            pixels.extend(data.iter().map(|&b| u16::from(b)));
        } else {
            pixels.extend(
                data.chunks_exact(2)
                    .map(|c| u16::from_be_bytes([c[0], c[1]])),
            );
        }
        if let Some(i) = pixels.iter().position(|&v| usize::from(v) > maxval) {
            return Err(err(pos + i * bpp, "pixel above maxval"));
        }
    } else {
        for _ in 0..n {
            let (at, t) = next_token(&mut pos);
            let v = t
                .and_then(|t| t.parse::<u16>().ok())
                .ok_or_else(|| err(at, "truncated or bad ASCII pixel data"))?;
            if usize::from(v) > maxval {
                return Err(err(at, "pixel above maxval"));
            }
            pixels.push(v);
        }
    }
    Ok((width, height, maxval as u16, pixels))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::one_robot;
    use crate::{World, WorldPose};
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
            Err(MapError::Pgm { .. })
        ));
        assert!(matches!(
            OccupancyMap::from_parts("image: a.pgm\nresolution: 0.1\n", &pgm),
            Err(MapError::MissingKey("origin"))
        ));
        assert!(matches!(
            OccupancyMap::from_parts(&format!("{MAP_YAML}bogus: 1\n"), &pgm),
            Err(MapError::Yaml { line: 7, .. })
        ));
        // Absurd resolutions: named with the line, whatever the rest of the map.
        for (res, ok) in [
            ("1e-6", false),
            ("0", false),
            ("1e300", false),
            ("0.001", true),
        ] {
            let yaml = MAP_YAML.replace("resolution: 0.5", &format!("resolution: {res}"));
            assert_ne!(yaml, MAP_YAML, "MAP_YAML's resolution moved");
            let r = OccupancyMap::from_parts(&yaml, &pgm);
            if ok {
                assert!(r.is_ok(), "resolution {res}: {r:?}");
            } else {
                assert!(
                    matches!(
                        r,
                        Err(MapError::InvalidValue {
                            key: "resolution",
                            ..
                        })
                    ),
                    "resolution {res}: {r:?}"
                );
            }
        }
    }

    fn example_map() -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/maps/rooms.yaml")
    }

    #[test]
    fn a_built_in_map_is_the_file_and_a_name_that_is_neither_says_so() {
        let dir =
            std::env::temp_dir().join(format!("pheromone-builtin-map-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // Opened by name from another directory's point of view: no file called "rooms" here.
        assert!(!Path::new("rooms").exists());
        let named = OccupancyMap::open(Path::new("rooms")).unwrap();
        assert_eq!(named, OccupancyMap::load(&example_map()).unwrap());
        // A file wins over the built-in name.
        let mut pgm = b"P5 2 1 255\n".to_vec();
        pgm.extend([0u8, 254]);
        std::fs::write(dir.join("m.pgm"), pgm).unwrap();
        std::fs::write(
            dir.join("rooms"),
            "image: m.pgm\nresolution: 0.5\norigin: [0, 0, 0]\n",
        )
        .unwrap();
        let file = OccupancyMap::open(&dir.join("rooms")).unwrap();
        assert_eq!((file.width, file.height), (2, 1));
        let e = OccupancyMap::open(Path::new("no-such-map"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no-such-map") && e.contains("built-in: rooms"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_example_map_gives_its_rooms_walls() {
        let map = OccupancyMap::load(&example_map()).unwrap();
        assert_eq!((map.width, map.height, map.resolution_m), (150, 100, 0.2));
        assert_eq!(map.extent_m(), ([0.0, 0.0], [30.0, 20.0]));
        // Outer walls, three inner walls with their doors, a 4 × 4-cell pillar.
        assert_eq!(map.occupied.iter().filter(|&&o| o).count(), 756);
        let walls = map.to_walls();
        let near = |a: f64, b: f64| (a - b).abs() < 1e-9;
        assert!(
            walls.iter().any(|w| matches!(w, WallConfig::Rect { min_x_m, max_x_m, min_y_m, max_y_m }
                if near(*min_x_m, 15.6) && near(*max_x_m, 16.4) && near(*min_y_m, 9.6) && near(*max_y_m, 10.4))),
            "the pillar: {walls:?}"
        );
        let mut cfg = one_robot(WorldPose::new(2.5, 2.5, 0.0));
        cfg.walls = walls;
        let world = World::new(cfg, 0).unwrap();
        // Rooms, doors and the hall are free; walls and the pillar are not.
        for (x, y) in [
            (2.5, 2.5),
            (6.0, 10.1),
            (12.1, 4.0),
            (12.1, 16.0),
            (20.1, 9.0),
            (20.1, 11.0),
            (25.0, 10.1),
            (15.0, 7.5),
        ] {
            assert!(world.is_free(x, y), "({x}, {y}) should be free");
        }
        for (x, y) in [
            (12.1, 8.0),
            (20.1, 3.0),
            (2.0, 10.1),
            (16.0, 10.0),
            (0.1, 5.0),
            (29.9, 19.9),
        ] {
            assert!(!world.is_free(x, y), "({x}, {y}) should be a wall");
        }
    }

    #[test]
    fn a_malformed_map_names_the_file_and_the_line_or_byte() {
        let dir = std::env::temp_dir().join(format!("pheromone-map-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let yaml = dir.join("m.yaml");
        std::fs::write(&yaml, "image: m.pgm\nresolution: 0.1\norigin: [0, 0, x]\n").unwrap();
        let e = OccupancyMap::load(&yaml).unwrap_err().to_string();
        assert!(
            e.contains("m.yaml") && e.contains("line 3") && e.contains("`x`"),
            "{e}"
        );
        std::fs::write(&yaml, "image: m.pgm\nresolution: -0.1\norigin: [0, 0, 0]\n").unwrap();
        let e = OccupancyMap::load(&yaml).unwrap_err().to_string();
        assert!(
            e.contains("m.yaml") && e.contains("line 2") && e.contains("resolution"),
            "{e}"
        );
        std::fs::write(&yaml, "image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n").unwrap();
        // 2 × 2 pixels announced, 3 given: the error is at the end of the file (byte 14).
        std::fs::write(dir.join("m.pgm"), b"P5\n2 2\n255\n\x00\xff\x00").unwrap();
        let e = OccupancyMap::load(&yaml).unwrap_err().to_string();
        assert!(
            e.contains("m.pgm") && e.contains("byte 14") && e.contains("truncated"),
            "{e}"
        );
        std::fs::write(dir.join("m.pgm"), b"P2\n2 2\n255\n0 255 9 x\n").unwrap();
        let e = OccupancyMap::load(&yaml).unwrap_err().to_string();
        assert!(e.contains("m.pgm") && e.contains("byte 19"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
