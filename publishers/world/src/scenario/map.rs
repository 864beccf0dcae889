//! ROS map_server maps in scenarios: `[world] map = "map.yaml"` (relative to the scenario
//! file) adds the map's occupied cells to the world's walls; `pheromone sim … --map FILE.yaml`
//! ([`Overrides::map`](super::Overrides)) puts a scenario on a user's map. Both also take the
//! name of a built-in map ([`BUILTIN_MAPS`](crate::BUILTIN_MAPS), e.g. `rooms`) when no file
//! of that name exists.
//!
//! A map is loaded once, where the scenario is loaded: its walls (occupied cells merged into
//! rectangles, [`OccupancyMap::to_walls`]) go into `world.walls` and `world.map` is cleared, so
//! the scenario file every process of a run reads holds the same walls, and both modes of a run
//! see the same world.

use std::path::Path;

use super::{Scenario, ScenarioError};
use crate::OccupancyMap;

fn load(key: &'static str, path: &Path) -> Result<OccupancyMap, ScenarioError> {
    OccupancyMap::open(path).map_err(|source| ScenarioError::Map { key, source })
}

impl Scenario {
    /// Loads `[world] map` (a relative path is relative to `base_dir`, the scenario file's
    /// directory; a built-in map's name if no such file exists) and adds its walls to the
    /// scenario's. Does nothing without a map.
    pub(super) fn load_world_map(&mut self, base_dir: &Path) -> Result<(), ScenarioError> {
        let Some(map) = self.world.map.take() else {
            return Ok(());
        };
        let in_dir = base_dir.join(&map);
        let builtin = crate::BUILTIN_MAPS.iter().any(|(n, _, _)| *n == map);
        let path = if builtin && !in_dir.exists() {
            Path::new(&map)
        } else {
            &in_dir
        };
        let map = load("world.map", path)?;
        self.world.walls.extend(map.to_walls());
        Ok(())
    }

    /// `--map FILE` (or a built-in map's name): the map's walls replace the scenario's, and the field and the exploration
    /// sectors (if any) cover the map's extent: the field's origin is the map's, its size the
    /// map's extent in the field's cells (rounded up); the sectors keep their count. The robots
    /// keep their start poses: one that starts in a wall of the map is refused by `validate`.
    pub(super) fn use_map(&mut self, path: &Path) -> Result<(), ScenarioError> {
        let map = load("--map", path)?;
        self.world.walls = map.to_walls();
        self.world.map = None;
        let (min_m, max_m) = map.extent_m();
        let cell_m = f64::from(self.field.cell_size_m);
        let cells = |len_m: f64| (len_m / cell_m - 1e-9).ceil().max(1.0);
        let (w, h) = (cells(max_m[0] - min_m[0]), cells(max_m[1] - min_m[1]));
        if w > f64::from(u32::MAX) || h > f64::from(u32::MAX) {
            return Err(ScenarioError::value(
                "--map",
                path.display(),
                "the map is too large for the field's cell size",
            ));
        }
        self.field.width = w as u32;
        self.field.height = h as u32;
        self.field.origin_x_m = min_m[0] as f32;
        self.field.origin_y_m = min_m[1] as f32;
        if let Some(e) = &mut self.metrics.exploration {
            e.min_m = min_m;
            e.max_m = max_m;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_map_replaces_the_walls_and_fits_the_field_and_the_sectors() {
        let dir = std::env::temp_dir().join(format!("pheromone-fit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // 10 × 5 cells of 0.5 m from (−2, 1): 5 m × 2.5 m, one occupied cell at the top left.
        let mut pgm = b"P5 10 5 255\n".to_vec();
        pgm.extend((0..50).map(|i| if i == 0 { 0u8 } else { 254 }));
        std::fs::write(dir.join("m.pgm"), pgm).unwrap();
        std::fs::write(
            dir.join("m.yaml"),
            "image: m.pgm\nresolution: 0.5\norigin: [-2.0, 1.0, 0.0]\n",
        )
        .unwrap();
        let mut s = Scenario::load("ias-ss").unwrap();
        assert!(s.world.walls.len() > 1);
        s.use_map(&dir.join("m.yaml")).unwrap();
        assert_eq!(s.world.walls.len(), 1, "{:?}", s.world.walls);
        assert_eq!((s.field.width, s.field.height), (50, 25));
        assert_eq!((s.field.origin_x_m, s.field.origin_y_m), (-2.0, 1.0));
        let e = s.metrics.exploration.as_ref().unwrap();
        assert_eq!(
            (e.min_m, e.max_m, e.cols, e.rows),
            ([-2.0, 1.0], [3.0, 3.5], 6, 4)
        );
        // The one wall is the top-left cell (the image's first row is the top of the map).
        match &s.world.walls[0] {
            crate::WallConfig::Rect {
                min_x_m, min_y_m, ..
            } => assert_eq!((*min_x_m, *min_y_m), (-2.0, 3.0)),
            w => panic!("{w:?}"),
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
