//! Seed 004's local maps as pictures (`sim --out` with `[mapping]` on), one pixel block per map
//! cell: occupancy grey when unknown, towards white when free and black when occupied, tinted
//! red by the pheromone map. `map_r<ID>.png`: robot ID's final map in its own frame (x to the
//! right, its start pose at the centre, marked by a green cross); `map_r<ID>_world.png`: the
//! same map placed in the world by the robot's true start pose, over the true walls (yellow),
//! with the robot's true trajectory in its colour (`style::robot_rgb`, as in every picture of
//! the run). Each has a title naming the robot, axes in metres and a legend (`framed`).

use plotters::prelude::*;

use super::style::{colour, msg, robot_rgb, Picture, Rgb, FONT};
use pheromone_roles::mapper::pose_in_frame;
use pheromone_sim::recording::Recording;
use pheromone_world::team::RobotMap;

const UNKNOWN: f32 = 160.0;
/// The true walls (world frame): yellow, on the black of occupied cells.
const WALL: Rgb = [255, 215, 0];
/// The start pose's cross.
const START: Rgb = [0, 190, 60];
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
fn own_frame(map: &RobotMap, scale: u32) -> Picture {
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
    line(&mut pic, (cx - 8.0, cy), (cx + 8.0, cy), START);
    line(&mut pic, (cx, cy - 8.0), (cx, cy + 8.0), START);
    pic
}

/// The world extent (m) the world-frame picture covers: the walls' bounding box (±10 m without
/// walls), half a metre more all round so the outer walls are drawn.
fn world_extent(rec: &Recording) -> ([f64; 2], [f64; 2]) {
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
    ([lo[0] - 0.5, lo[1] - 0.5], [hi[0] + 0.5, hi[1] + 0.5])
}

/// The map placed in the world by its true start pose, over `rec`'s walls, with robot `id`'s
/// true path; the picture covers [`world_extent`].
fn world_frame(map: &RobotMap, rec: &Recording, id: u32) -> Picture {
    let (lo, hi) = world_extent(rec);
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
            line(&mut pic, px(a[0], a[1]), px(b[0], b[1]), robot_rgb(id));
        }
    }
    for (a, b) in &rec.walls {
        line(&mut pic, px(a[0], a[1]), px(b[0], b[1]), WALL);
    }
    let s = px(map.start[0], map.start[1]);
    line(&mut pic, (s.0 - 8.0, s.1), (s.0 + 8.0, s.1), START);
    line(&mut pic, (s.0, s.1 - 8.0), (s.0, s.1 + 8.0), START);
    pic
}

/// Pixels per map cell of `map_r<ID>.png`.
const OWN_PX_PER_CELL: u32 = 2;

/// `map_r<ID>.png`: robot `id`'s map in its own frame, framed.
pub(super) fn own_frame_picture(map: &RobotMap, id: u32) -> Result<Picture, String> {
    let g = &map.geometry;
    let raster = own_frame(map, OWN_PX_PER_CELL);
    let x0 = f64::from(g.origin_x_m);
    let y0 = f64::from(g.origin_y_m);
    framed(
        &raster,
        (x0, x0 + f64::from(g.width_m())),
        (y0, y0 + f64::from(g.height_m())),
        &format!("R{id}'s map in its own frame (its start pose at 0, 0)"),
        &map_keys(None),
    )
}

/// `map_r<ID>_world.png`: robot `id`'s map placed in the world, framed.
pub(super) fn world_frame_picture(
    map: &RobotMap,
    rec: &Recording,
    id: u32,
) -> Result<Picture, String> {
    let raster = world_frame(map, rec, id);
    let (lo, _) = world_extent(rec);
    // The raster is whole pixels: its extent, from its bottom-left corner.
    let (w_m, h_m) = (
        f64::from(raster.width) / WORLD_PX_PER_M,
        f64::from(raster.height) / WORLD_PX_PER_M,
    );
    framed(
        &raster,
        (lo[0], lo[0] + w_m),
        (lo[1], lo[1] + h_m),
        &format!("R{id}'s map placed in the world by its true start pose"),
        &map_keys(Some(id)),
    )
}

/// A legend entry's sample.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Key {
    Swatch(Rgb),
    Line(Rgb),
    Cross(Rgb),
}

/// The legend of a map picture; with `Some(id)` the world frame's walls and robot id's path.
fn map_keys(world_of: Option<u32>) -> Vec<(Key, String)> {
    let mut keys = vec![
        (Key::Swatch(cell_rgb(-4.0, 0.0)), "free".to_string()),
        (Key::Swatch(cell_rgb(0.0, 0.0)), "unknown".to_string()),
        (Key::Swatch(cell_rgb(4.0, 0.0)), "occupied".to_string()),
        (
            Key::Swatch(cell_rgb(-4.0, 1.0)),
            "pheromone 1 (free)".to_string(),
        ),
        (Key::Cross(START), "start pose".to_string()),
    ];
    if let Some(id) = world_of {
        keys.push((Key::Line(WALL), "true walls".to_string()));
        keys.push((Key::Line(robot_rgb(id)), format!("R{id}'s true path")));
    }
    keys
}

/// Room around a framed map (px): title above, y axis left, x axis under, legend right.
const TITLE_PX: u32 = 40;
const AXIS_LEFT_PX: u32 = 64;
const AXIS_BOTTOM_PX: u32 = 52;
const GAP_PX: u32 = 16;
const LEGEND_W_PX: u32 = 200;
const LEGEND_ROW_PX: i32 = 24;
const FRAME_TEXT: Rgb = [20, 20, 20];

/// Where a framed picture puts the raster (its top-left pixel) and the legend's left edge.
fn frame_layout(raster: &Picture) -> ((u32, u32), u32) {
    (
        (AXIS_LEFT_PX, TITLE_PX),
        AXIS_LEFT_PX + raster.width + GAP_PX,
    )
}

/// `raster` on white with a title, axes in metres (`x_m`, `y_m`: the raster's left … right and
/// bottom … top) and a legend on the right.
fn framed(
    raster: &Picture,
    x_m: (f64, f64),
    y_m: (f64, f64),
    title: &str,
    keys: &[(Key, String)],
) -> Result<Picture, String> {
    let ((rx, ry), legend_x) = frame_layout(raster);
    let legend_h = TITLE_PX as i32 + 12 + LEGEND_ROW_PX * keys.len() as i32;
    let h = (ry + raster.height + AXIS_BOTTOM_PX).max(legend_h.max(0) as u32);
    let w = legend_x + LEGEND_W_PX;
    let mut pic = Picture::new(w, h, [255, 255, 255]);
    let row = raster.width as usize * 3;
    for y in 0..raster.height as usize {
        let at = ((ry as usize + y) * w as usize + rx as usize) * 3;
        pic.rgb[at..at + row].copy_from_slice(&raster.rgb[y * row..(y + 1) * row]);
    }
    let text = |size: u32| (FONT, size).into_font().color(&colour(FRAME_TEXT));
    pic.draw(|root| {
        root.draw_text(title, &text(18), (AXIS_LEFT_PX as i32, 12))
            .map_err(msg)?;
        let (main, legend) = root.split_horizontally(legend_x);
        let mut chart = ChartBuilder::on(&main)
            .margin_top(TITLE_PX)
            .margin_right(GAP_PX)
            .margin_bottom(h - ry - raster.height - AXIS_BOTTOM_PX)
            .x_label_area_size(AXIS_BOTTOM_PX)
            .y_label_area_size(AXIS_LEFT_PX)
            .build_cartesian_2d(x_m.0..x_m.1, y_m.0..y_m.1)
            .map_err(msg)?;
        let (xr, yr) = chart.plotting_area().get_pixel_range();
        let expected = (
            rx as i32..(rx + raster.width) as i32,
            ry as i32..(ry + raster.height) as i32,
        );
        if (xr.clone(), yr.clone()) != expected {
            return Err(format!(
                "the axes' area {xr:?} × {yr:?} px is not the map's {expected:?}"
            ));
        }
        let tick = |v: &f64| {
            let s = format!("{v:.2}");
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        };
        chart
            .configure_mesh()
            .disable_mesh()
            .x_label_formatter(&tick)
            .y_label_formatter(&tick)
            .label_style(text(13))
            .axis_desc_style(text(14))
            .x_desc("x (m)")
            .y_desc("y (m)")
            .draw()
            .map_err(msg)?;
        draw_legend(&legend, keys, &text(14))
    })?;
    Ok(pic)
}

/// The legend's rows: a sample, then its name.
fn draw_legend(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    keys: &[(Key, String)],
    text: &TextStyle<'_>,
) -> Result<(), String> {
    for (i, (key, name)) in keys.iter().enumerate() {
        let y = TITLE_PX as i32 + 12 + LEGEND_ROW_PX * i as i32;
        match *key {
            Key::Swatch(c) => {
                area.draw(&Rectangle::new(
                    [(0, y - 7), (22, y + 7)],
                    colour(c).filled(),
                ))
                .map_err(msg)?;
                area.draw(&Rectangle::new(
                    [(0, y - 7), (22, y + 7)],
                    colour(FRAME_TEXT),
                ))
                .map_err(msg)?;
            }
            Key::Line(c) => {
                area.draw(&Rectangle::new([(0, y - 7), (22, y + 7)], BLACK.filled()))
                    .map_err(msg)?;
                area.draw(&PathElement::new(
                    vec![(2, y), (20, y)],
                    colour(c).stroke_width(3),
                ))
                .map_err(msg)?;
            }
            Key::Cross(c) => {
                for seg in [[(3, y), (19, y)], [(11, y - 8), (11, y + 8)]] {
                    area.draw(&PathElement::new(seg, colour(c).stroke_width(2)))
                        .map_err(msg)?;
                }
            }
        }
        area.draw_text(name, text, (30, y - 8)).map_err(msg)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tests::sample;

    fn map() -> RobotMap {
        let geometry = pheromone_field::GridGeometry::new(10, 10, 1.0)
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

    /// The pictures written have a title, axes and a legend around the map, the map itself
    /// unchanged inside; the world frame draws the path in the robot's colour.
    #[test]
    fn framed_maps_have_the_map_inside_and_text_around_it() {
        let m = map();
        let rec = Recording {
            walls: vec![([0.0, 0.0], [20.0, 0.0]), ([20.0, 0.0], [20.0, 20.0])],
            robots: [(7, vec![sample(0.0, 2.0, 5.0), sample(1.0, 18.0, 5.0)])].into(),
            ..Recording::default()
        };
        for (pic, raster, id) in [
            (own_frame_picture(&m, 7).unwrap(), own_frame(&m, 2), 7),
            (
                world_frame_picture(&m, &rec, 7).unwrap(),
                world_frame(&m, &rec, 7),
                7,
            ),
        ] {
            let ((rx, ry), legend_x) = frame_layout(&raster);
            assert_eq!(pic.width, legend_x + LEGEND_W_PX);
            assert!(pic.height >= ry + raster.height + AXIS_BOTTOM_PX);
            // The map, pixel for pixel, where the layout puts it.
            for (x, y) in [(0, 0), (3, 5), (raster.width - 1, raster.height - 1)] {
                assert_eq!(
                    pic.get((rx + x) as usize, (ry + y) as usize),
                    raster.get(x as usize, y as usize)
                );
            }
            let dark = |x0: u32, x1: u32, y0: u32, y1: u32| {
                (y0..y1)
                    .flat_map(|y| (x0..x1).map(move |x| (x, y)))
                    .filter(|&(x, y)| pic.get(x as usize, y as usize)[0] < 100)
                    .count()
            };
            assert!(dark(rx, pic.width, 0, ry) > 100, "R{id}: no title");
            assert!(
                dark(0, rx, ry, ry + raster.height) > 100,
                "y axis and its labels"
            );
            assert!(
                dark(rx, rx + raster.width, ry + raster.height + 2, pic.height) > 100,
                "x axis and its labels"
            );
            // The legend: each swatch of the map's colours is there.
            let legend: Vec<Rgb> = (ry..pic.height)
                .flat_map(|y| (legend_x..legend_x + 22).map(move |x| (x, y)))
                .map(|(x, y)| pic.get(x as usize, y as usize))
                .collect();
            for c in [cell_rgb(-4.0, 0.0), cell_rgb(0.0, 0.0), cell_rgb(-4.0, 1.0)] {
                assert!(legend.contains(&c), "legend swatch {c:?}");
            }
        }
        // The path in the world frame: robot 7's colour, as in the heat maps.
        let w = world_frame(&m, &rec, 7);
        let on_path = w.get(
            ((10.0 + 0.5) * 20.0) as usize,
            ((20.5 - 5.0) * 20.0) as usize,
        );
        assert_eq!(on_path, robot_rgb(7));
    }

    #[test]
    fn write_plots_writes_the_framed_maps() {
        use pheromone_world::team::MappingRecord;
        let m = map();
        let rec = Recording {
            mapping: Some(MappingRecord {
                maps: [(3, m.clone())].into(),
                merges: Vec::new(),
                counters: Default::default(),
            }),
            ..Recording::default()
        };
        let dir = std::env::temp_dir().join(format!("maps-framed-{}", std::process::id()));
        let scenario = pheromone_world::scenario::Scenario::load("evaporation").unwrap();
        let written = crate::write_plots(&dir, &scenario, &rec).unwrap();
        assert!(written.contains(&dir.join("map_r3.png")), "{written:?}");
        let decoder = png::Decoder::new(std::io::BufReader::new(
            std::fs::File::open(dir.join("map_r3.png")).unwrap(),
        ));
        let info = decoder.read_info().unwrap();
        let want = own_frame_picture(&m, 3).unwrap();
        assert_eq!(
            (info.info().width, info.info().height),
            (want.width, want.height)
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
