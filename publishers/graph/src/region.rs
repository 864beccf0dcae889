//! The region table (paper 001 Sec. 4.2): service regions that robots capture, serve and
//! release. A region never holds more than its Max-R robots; a capture lowers its value by 1
//! (anti-pheromone: served or being served), and eq. 9 sends a robot to the nearest region with
//! room and the largest value.

use serde::{Deserialize, Serialize};

/// The outline of a region: a polygon, or a list of grid cells.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum RegionShape {
    /// Vertices in world metres, in order (either winding).
    Polygon { vertices_m: Vec<[f32; 2]> },
    /// Square cells of `cell_size_m` whose lower-left corners are `origin_m + cell·cell_size_m`.
    Cells {
        cell_size_m: f32,
        #[serde(default)]
        origin_m: [f32; 2],
        cells: Vec<[i32; 2]>,
    },
}

impl RegionShape {
    /// Whether a world point lies inside.
    pub fn contains(&self, x_m: f32, y_m: f32) -> bool {
        match self {
            RegionShape::Polygon { vertices_m: v } => {
                // Even-odd ray casting.
                let mut inside = false;
                let mut j = v.len().wrapping_sub(1);
                for i in 0..v.len() {
                    let ([xi, yi], [xj, yj]) = (v[i], v[j]);
                    if (yi > y_m) != (yj > y_m) && x_m < (xj - xi) * (y_m - yi) / (yj - yi) + xi {
                        inside = !inside;
                    }
                    j = i;
                }
                inside
            }
            RegionShape::Cells {
                cell_size_m,
                origin_m,
                cells,
            } => {
                let cx = ((x_m - origin_m[0]) / cell_size_m).floor() as i32;
                let cy = ((y_m - origin_m[1]) / cell_size_m).floor() as i32;
                cells.contains(&[cx, cy])
            }
        }
    }

    /// Area in m².
    pub fn area_m2(&self) -> f32 {
        match self {
            RegionShape::Polygon { vertices_m: v } => {
                let mut s = 0.0;
                for i in 0..v.len() {
                    let j = (i + 1) % v.len();
                    s += v[i][0] * v[j][1] - v[j][0] * v[i][1];
                }
                (s * 0.5).abs()
            }
            RegionShape::Cells {
                cell_size_m, cells, ..
            } => cells.len() as f32 * cell_size_m * cell_size_m,
        }
    }

    /// `[x_min, y_min, x_max, y_max]` in world metres.
    pub fn bbox_m(&self) -> [f32; 4] {
        let pts: Vec<[f32; 2]> = match self {
            RegionShape::Polygon { vertices_m } => vertices_m.clone(),
            RegionShape::Cells {
                cell_size_m,
                origin_m,
                cells,
            } => cells
                .iter()
                .flat_map(|c| {
                    let x = origin_m[0] + c[0] as f32 * cell_size_m;
                    let y = origin_m[1] + c[1] as f32 * cell_size_m;
                    [[x, y], [x + cell_size_m, y + cell_size_m]]
                })
                .collect(),
        };
        pts.iter().fold(
            [
                f32::INFINITY,
                f32::INFINITY,
                f32::NEG_INFINITY,
                f32::NEG_INFINITY,
            ],
            |b, p| {
                [
                    b[0].min(p[0]),
                    b[1].min(p[1]),
                    b[2].max(p[0]),
                    b[3].max(p[1]),
                ]
            },
        )
    }

    fn validate(&self) -> Result<(), ShapeError> {
        match self {
            RegionShape::Polygon { vertices_m } => {
                if vertices_m.len() < 3 {
                    return Err(ShapeError::FewVertices(vertices_m.len()));
                }
                if vertices_m.iter().flatten().any(|v| !v.is_finite()) {
                    return Err(ShapeError::NonFiniteVertex);
                }
            }
            RegionShape::Cells {
                cell_size_m,
                origin_m,
                cells,
            } => {
                if !(cell_size_m.is_finite() && *cell_size_m > 0.0) {
                    return Err(ShapeError::CellSize(*cell_size_m));
                }
                if origin_m.iter().any(|v| !v.is_finite()) || cells.is_empty() {
                    return Err(ShapeError::NoCells);
                }
            }
        }
        Ok(())
    }
}

/// `[[region]]` of a scenario.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionConfig {
    pub name: String,
    /// The graph node a robot stands on to serve the region (by name) …
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub node: String,
    /// … or the node nearest this point (graphs extracted from a map).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at_m: Option<[f32; 2]>,
    pub shape: RegionShape,
    /// Max-R: most robots that may hold the region at once.
    #[serde(default = "one")]
    pub max_r: u32,
}

fn one() -> u32 {
    1
}

/// One row of the region table.
#[derive(Debug, Clone, PartialEq)]
pub struct Region {
    pub name: String,
    pub node: usize,
    pub shape: RegionShape,
    pub max_r: u32,
    /// Robot ids holding the region, in capture order.
    pub captured_by: Vec<u32>,
    /// 0 = never served; −1 per capture; positive after a robot relinquished it to attract.
    pub value: f32,
}

impl Region {
    pub fn has_room(&self) -> bool {
        (self.captured_by.len() as u32) < self.max_r
    }
}

/// Why a region's shape cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ShapeError {
    #[error("a polygon needs at least 3 vertices, got {0}")]
    FewVertices(usize),
    #[error("polygon vertices must be finite")]
    NonFiniteVertex,
    #[error("cell_size_m {0} must be > 0")]
    CellSize(f32),
    #[error("cells need a finite origin and at least one cell")]
    NoCells,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RegionError {
    #[error("region '{region}': {detail}")]
    Invalid { region: String, detail: String },
    #[error("region '{region}': {source}")]
    Shape {
        region: String,
        #[source]
        source: ShapeError,
    },
    #[error("region index {0} out of range")]
    Index(usize),
    #[error("region '{region}': robot {robot} cannot release it, it does not hold it")]
    NotHeld { region: String, robot: u32 },
    #[error("region '{region}': value change {amount} is not finite")]
    Amount { region: String, amount: f32 },
}

/// What a capture attempt did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CaptureOutcome {
    Captured,
    /// The robot held it already; nothing changed.
    AlreadyHeld,
    /// The region holds Max-R robots; nothing changed.
    Full,
}

/// The regions of a map.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RegionTable {
    regions: Vec<Region>,
}

impl RegionTable {
    /// Builds the table; `node_of` maps a node name to its graph index.
    pub fn new(
        configs: &[RegionConfig],
        node_of: impl Fn(&str) -> Option<usize>,
    ) -> Result<Self, RegionError> {
        let mut regions: Vec<Region> = Vec::with_capacity(configs.len());
        for c in configs {
            let bad = |detail: String| RegionError::Invalid {
                region: c.name.clone(),
                detail,
            };
            if c.name.is_empty() || regions.iter().any(|r| r.name == c.name) {
                return Err(bad("names must be non-empty and unique".into()));
            }
            if c.max_r == 0 {
                return Err(bad("max_r 0: a region must admit at least one robot".into()));
            }
            c.shape.validate().map_err(|source| RegionError::Shape {
                region: c.name.clone(),
                source,
            })?;
            let node =
                node_of(&c.node).ok_or_else(|| bad(format!("unknown graph node '{}'", c.node)))?;
            regions.push(Region {
                name: c.name.clone(),
                node,
                shape: c.shape.clone(),
                max_r: c.max_r,
                captured_by: Vec::new(),
                value: 0.0,
            });
        }
        Ok(Self { regions })
    }

    pub fn len(&self) -> usize {
        self.regions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.regions.is_empty()
    }

    pub fn regions(&self) -> &[Region] {
        &self.regions
    }

    pub fn get(&self, i: usize) -> Result<&Region, RegionError> {
        self.regions.get(i).ok_or(RegionError::Index(i))
    }

    pub fn find(&self, name: &str) -> Option<usize> {
        self.regions.iter().position(|r| r.name == name)
    }

    /// The regions at graph node `node`.
    pub fn at_node(&self, node: usize) -> impl Iterator<Item = usize> + '_ {
        (0..self.regions.len()).filter(move |&i| self.regions[i].node == node)
    }

    /// The region a robot holds, if any.
    pub fn held_by(&self, robot: u32) -> Option<usize> {
        self.regions
            .iter()
            .position(|r| r.captured_by.contains(&robot))
    }

    /// Captures `region` for `robot` unless it already holds Max-R robots.
    pub fn capture(&mut self, region: usize, robot: u32) -> Result<CaptureOutcome, RegionError> {
        let r = self
            .regions
            .get_mut(region)
            .ok_or(RegionError::Index(region))?;
        if r.captured_by.contains(&robot) {
            return Ok(CaptureOutcome::AlreadyHeld);
        }
        if !r.has_room() {
            return Ok(CaptureOutcome::Full);
        }
        r.captured_by.push(robot);
        r.value -= 1.0;
        Ok(CaptureOutcome::Captured)
    }

    /// Releases `region`; an error if `robot` does not hold it.
    pub fn release(&mut self, region: usize, robot: u32) -> Result<(), RegionError> {
        let r = self
            .regions
            .get_mut(region)
            .ok_or(RegionError::Index(region))?;
        let Some(k) = r.captured_by.iter().position(|&x| x == robot) else {
            return Err(RegionError::NotHeld {
                region: r.name.clone(),
                robot,
            });
        };
        r.captured_by.remove(k);
        Ok(())
    }

    /// Adds `amount` to a region's value (Sec. 4.3: a large positive value attracts others).
    pub fn add_value(&mut self, region: usize, amount: f32) -> Result<f32, RegionError> {
        let r = self
            .regions
            .get_mut(region)
            .ok_or(RegionError::Index(region))?;
        if !amount.is_finite() {
            return Err(RegionError::Amount {
                region: r.name.clone(),
                amount,
            });
        }
        r.value += amount;
        Ok(r.value)
    }

    /// Sets a region's dynamic state (a reader rebuilding the table from a snapshot).
    pub(crate) fn set_state(&mut self, region: usize, captured_by: &[u32], value: f32) {
        if let Some(r) = self.regions.get_mut(region) {
            r.captured_by = captured_by.to_vec();
            r.value = value;
        }
    }

    /// Paper 001 Algorithm 1 lines 10–14: the landmarks a robot matches observations against.
    /// A robot holding a region: the landmarks inside it, l(A_c). Otherwise: every landmark
    /// not inside a region captured by someone, l(A) − l(A_c). Indices into `landmarks_m`,
    /// for `localizer::Ekf::set_landmark_filter`.
    pub fn landmark_set(&self, robot: u32, landmarks_m: &[[f64; 2]]) -> Vec<usize> {
        let inside = |r: &Region, p: &[f64; 2]| r.shape.contains(p[0] as f32, p[1] as f32);
        match self.held_by(robot) {
            Some(i) => {
                let r = &self.regions[i];
                (0..landmarks_m.len())
                    .filter(|&k| inside(r, &landmarks_m[k]))
                    .collect()
            }
            None => (0..landmarks_m.len())
                .filter(|&k| {
                    !self
                        .regions
                        .iter()
                        .any(|r| !r.captured_by.is_empty() && inside(r, &landmarks_m[k]))
                })
                .collect(),
        }
    }

    /// Eq. 9: among the regions with room (and `admit`ted), those with the largest value; of
    /// these the one with the smallest `distance_m`. `None` if none qualifies.
    pub fn target(
        &self,
        distance_m: impl Fn(&Region) -> f32,
        admit: impl Fn(usize, &Region) -> bool,
    ) -> Option<usize> {
        let open: Vec<usize> = (0..self.regions.len())
            .filter(|&i| self.regions[i].has_room() && admit(i, &self.regions[i]))
            .filter(|&i| distance_m(&self.regions[i]).is_finite())
            .collect();
        let best = open
            .iter()
            .map(|&i| self.regions[i].value)
            .max_by(f32::total_cmp)?;
        open.into_iter()
            .filter(|&i| self.regions[i].value == best)
            .min_by(|&a, &b| {
                distance_m(&self.regions[a])
                    .total_cmp(&distance_m(&self.regions[b]))
                    .then(a.cmp(&b))
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(max_r: u32) -> RegionTable {
        let cfg = [RegionConfig {
            name: "A".into(),
            node: "n".into(),
            at_m: None,
            shape: RegionShape::Polygon {
                vertices_m: vec![[0.0, 0.0], [4.0, 0.0], [4.0, 5.0], [0.0, 5.0]],
            },
            max_r,
        }];
        RegionTable::new(&cfg, |_| Some(0)).unwrap()
    }

    #[test]
    fn capture_respects_max_r_and_release_frees() {
        let mut t = table(2);
        assert_eq!(t.capture(0, 1).unwrap(), CaptureOutcome::Captured);
        assert_eq!(t.capture(0, 1).unwrap(), CaptureOutcome::AlreadyHeld);
        assert_eq!(t.capture(0, 2).unwrap(), CaptureOutcome::Captured);
        assert_eq!(t.capture(0, 3).unwrap(), CaptureOutcome::Full);
        assert_eq!(t.get(0).unwrap().captured_by, vec![1, 2]);
        assert_eq!(t.get(0).unwrap().value, -2.0);
        assert!(t.release(0, 3).unwrap_err().to_string().contains("robot 3"));
        t.release(0, 1).unwrap();
        assert_eq!(t.capture(0, 3).unwrap(), CaptureOutcome::Captured);
    }

    #[test]
    fn landmark_set_follows_algorithm_1() {
        let mut t = table(1);
        // Two landmarks inside region A (x 0..4), two outside.
        let lms = [[1.0, 1.0], [3.0, 4.0], [6.0, 1.0], [9.0, 2.0]];
        assert_eq!(t.landmark_set(5, &lms), vec![0, 1, 2, 3]);
        t.capture(0, 7).unwrap();
        assert_eq!(t.landmark_set(7, &lms), vec![0, 1]);
        assert_eq!(t.landmark_set(5, &lms), vec![2, 3]);
    }

    #[test]
    fn shapes() {
        let t = table(1);
        let s = &t.get(0).unwrap().shape;
        assert!(s.contains(1.0, 1.0) && !s.contains(5.0, 1.0));
        assert_eq!(s.area_m2(), 20.0);
        let c = RegionShape::Cells {
            cell_size_m: 0.5,
            origin_m: [0.0, 0.0],
            cells: vec![[0, 0], [1, 0]],
        };
        assert!(c.contains(0.9, 0.2) && !c.contains(1.1, 0.2));
        assert_eq!(c.area_m2(), 0.5);
        assert_eq!(c.bbox_m(), [0.0, 0.0, 1.0, 0.5]);
        let bad = [RegionConfig {
            name: "Z".into(),
            node: "n".into(),
            at_m: None,
            shape: c,
            max_r: 0,
        }];
        let e = RegionTable::new(&bad, |_| Some(0)).unwrap_err().to_string();
        assert!(e.contains("'Z'") && e.contains("max_r 0"), "{e}");
    }
}
