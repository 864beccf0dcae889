//! Seed 004's local maps as pictures (`sim --out` with `[mapping]` on), one pixel block per map
//! cell: occupancy grey when unknown, towards white when free and black when occupied, tinted
//! red by the pheromone map. `map_r<ID>.png`: robot ID's final map in its own frame (x to the
//! right, its start pose at the centre, marked by a red cross); `map_r<ID>_world.png`: the same
//! map placed in the world by the robot's true start pose, over the true walls (red), with the
//! robot's true trajectory (blue).

use super::style::{Picture, Rgb};
use roles::mapper::pose_in_frame;
use roles::team::RobotMap;
use sim::record::Recording;

const UNKNOWN: f32 = 160.0;
const WALL: Rgb = [220, 30, 30];
const PATH: Rgb = [40, 90, 220];
/// Pixels per metre of the world-frame picture.
const WORLD_PX_PER_M: f64 = 20.0;

/// The colour of a map cell: log-odds `l` (clamped at ±4), pheromone `p` (0–1).
fn cell_rgb(l: f32, p: f32) -> Rgb {
    let t = (l / 4.0).clamp(-1.0, 1.0);
    let g = if t < 0.0 {
        UNKNOWN + (255.0 - UNKNOWN) * -t
    } else {
        UNKNOWN * (1.0 - t)
    };
    let red = p.clamp(0.0, 1.0) * 0.6;
    [
        (g + (255.0 - g) * red) as u8,
        (g * (1.0 - red)) as u8,
        (g * (1.0 - red)) as u8,
    ]
}

fn put(pic: &mut Picture, x: i64, y: i64, c: Rgb) {
    if x >= 0 && y >= 0 && (x as u32) < pic.width && (y as u32) < pic.height {
        let i = (y as usize * pic.width as usize + x as usize) * 3;
        pic.rgb[i..i + 3].copy_from_slice(&c);
    }
}

/// A line of 2-px dots from `a` to `b` (pixels).
fn line(pic: &mut Picture, a: (f64, f64), b: (f64, f64), c: Rgb) {
    let n = ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as usize).max(1);
    for k in 0..=n {
        let f = k as f64 / n as f64;
        let (x, y) = (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1));
        for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            put(pic, x as i64 + dx, y as i64 + dy, c);
        }
    }
}

/// The map in its own frame, `scale` px per cell.
pub(super) fn own_frame(map: &RobotMap, scale: u32) -> Picture {
    let g = &map.geometry;
    let mut pic = Picture::new(g.width * scale, g.height * scale, [0, 0, 0]);
    for y in 0..g.height {
        for x in 0..g.width {
            let i = g.index(x, y);
            let c = cell_rgb(map.occupancy[i], map.pheromone[i]);
            let row = (g.height - 1 - y) * scale;
            for py in row..row + scale {
                for px in x * scale..(x + 1) * scale {
                    put(&mut pic, px as i64, py as i64, c);
                }
            }
        }
    }
    // The origin (the start pose): a red cross.
    let (ox, oy) = g.grid_from_world(0.0, 0.0);
    let (cx, cy) = (
        ox as f64 * scale as f64,
        (g.height as f64 - oy as f64) * scale as f64,
    );
    line(&mut pic, (cx - 8.0, cy), (cx + 8.0, cy), WALL);
    line(&mut pic, (cx, cy - 8.0), (cx, cy + 8.0), WALL);
    pic
}

/// The map placed in the world by its true start pose, over `rec`'s walls, with robot `id`'s
/// true path; the picture covers the walls' bounding box.
pub(super) fn world_frame(map: &RobotMap, rec: &Recording, id: u32) -> Picture {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for (a, b) in &rec.walls {
        for p in [a, b] {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
    }
    if !(lo[0] < hi[0] && lo[1] < hi[1]) {
        lo = [-10.0; 2];
        hi = [10.0; 2];
    }
    // Half a metre around the walls, so the outer ones are drawn.
    lo = [lo[0] - 0.5, lo[1] - 0.5];
    hi = [hi[0] + 0.5, hi[1] + 0.5];
    let w = ((hi[0] - lo[0]) * WORLD_PX_PER_M).ceil() as u32;
    let h = ((hi[1] - lo[1]) * WORLD_PX_PER_M).ceil() as u32;
    let mut pic = Picture::new(w, h, [0, 0, 0]);
    let g = &map.geometry;
    let px = |x: f64, y: f64| {
        (
            (x - lo[0]) * WORLD_PX_PER_M,
            h as f64 - (y - lo[1]) * WORLD_PX_PER_M,
        )
    };
    for py in 0..h {
        for qx in 0..w {
            let x = lo[0] + (qx as f64 + 0.5) / WORLD_PX_PER_M;
            let y = lo[1] + (h as f64 - py as f64 - 0.5) / WORLD_PX_PER_M;
            let q = pose_in_frame(map.start, [x, y, 0.0]);
            let c = match g.cell_at(q[0] as f32, q[1] as f32) {
                Some((cx, cy)) => {
                    let i = g.index(cx, cy);
                    cell_rgb(map.occupancy[i], map.pheromone[i])
                }
                None => [UNKNOWN as u8; 3],
            };
            put(&mut pic, qx as i64, py as i64, c);
        }
    }
    if let Some(rows) = rec.robots.get(&id) {
        for w in rows.windows(2) {
            let (a, b) = (w[0].true_pose, w[1].true_pose);
            line(&mut pic, px(a[0], a[1]), px(b[0], b[1]), PATH);
        }
    }
    for (a, b) in &rec.walls {
        line(&mut pic, px(a[0], a[1]), px(b[0], b[1]), WALL);
    }
    let s = px(map.start[0], map.start[1]);
    line(&mut pic, (s.0 - 8.0, s.1), (s.0 + 8.0, s.1), WALL);
    line(&mut pic, (s.0, s.1 - 8.0), (s.0, s.1 + 8.0), WALL);
    pic
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map() -> RobotMap {
        let geometry = field::GridGeometry::new(10, 10, 1.0)
            .unwrap()
            .with_origin(-5.0, -5.0)
            .unwrap();
        let mut occupancy = vec![0.0; 100];
        occupancy[geometry.index(7, 5)] = 4.0; // (2.5, 0.5) of its frame: occupied
        occupancy[geometry.index(6, 5)] = -4.0; // (1.5, 0.5): free
        RobotMap {
            start: [10.0, 10.0, std::f64::consts::FRAC_PI_2],
            geometry,
            occupancy,
            pheromone: vec![0.0; 100],
        }
    }

    #[test]
    fn cells_are_drawn_where_their_frame_puts_them() {
        let m = map();
        let own = own_frame(&m, 2);
        // Cell (7, 5) is row 10 − 1 − 5 = 4 from the top.
        assert_eq!(own.get(14, 8), [0, 0, 0]);
        assert_eq!(own.get(12, 8), [255, 255, 255]);
        assert_eq!(own.get(2, 2), [160, 160, 160]);
        // In the world, the start heading +y turns the frame's x axis up: (2.5, 0.5) of the
        // frame is (9.5, 12.5) of the world.
        let rec = Recording {
            walls: vec![([0.0, 0.0], [20.0, 0.0]), ([20.0, 0.0], [20.0, 20.0])],
            ..Recording::default()
        };
        let w = world_frame(&m, &rec, 0);
        // The picture spans [−0.5, 20.5] m both ways.
        let at = |x: f64, y: f64| w.get(((x + 0.5) * 20.0) as usize, ((20.5 - y) * 20.0) as usize);
        assert_eq!((w.width, w.height), (420, 420));
        assert_eq!(at(9.5, 12.5), [0, 0, 0]);
        assert_eq!(at(9.5, 11.5), [255, 255, 255]);
        assert_eq!(at(3.0, 3.0), [160, 160, 160]);
        assert_eq!(at(10.0, 0.0), WALL);
    }
}
