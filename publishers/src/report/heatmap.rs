//! The heat-map picture of one channel of a field snapshot: where the grid lands in the picture
//! (`Layout`), the cells, walls, trajectories and robot markers, and the strip under the field
//! with the title, colour bar, scale bar and legend.

use super::font::{draw_text, text_width};
use super::raster::{
    lighter, robot_rgb, Canvas, ColourMap, Pen, OUTLINE_RGB, STRIP_RGB, TEXT_RGB, WALL_RGB,
};
use crate::sim::record::{Recording, RobotSample, Snapshot};

/// The picture's width is at least this many pixels (if the cap below allows it).
const MIN_WIDTH_PX: usize = 800;
/// Neither side of the field part of the picture exceeds this many pixels.
const MAX_SIDE_PX: usize = 2000;
/// Height of the strip under the field with the title, colour bar, scale bar and legend.
pub(super) const STRIP_HEIGHT_PX: usize = 52;

/// Where the grid lands in the picture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Layout {
    width: usize,
    height: usize,
    /// Cells per picture block along each axis (> 1 only for grids larger than the cap).
    decimate: usize,
    /// Pixels per block along each axis.
    pub(super) scale: usize,
    /// Blocks across and down.
    blocks_w: usize,
    blocks_h: usize,
    px_per_m: f64,
}

impl Layout {
    pub(super) fn for_grid(width: u32, height: u32, cell_size_m: f32) -> Layout {
        let (width, height) = (width as usize, height as usize);
        let long = width.max(height);
        let decimate = long.div_ceil(MAX_SIDE_PX).max(1);
        let (blocks_w, blocks_h) = (width.div_ceil(decimate), height.div_ceil(decimate));
        let mut scale = MIN_WIDTH_PX.div_ceil(blocks_w).max(1);
        while scale > 1 && blocks_w.max(blocks_h) * scale > MAX_SIDE_PX {
            scale -= 1;
        }
        Layout {
            width,
            height,
            decimate,
            scale,
            blocks_w,
            blocks_h,
            px_per_m: scale as f64 / (decimate as f64 * f64_from_decimal(cell_size_m)),
        }
    }

    fn field_w_px(&self) -> usize {
        self.blocks_w * self.scale
    }

    fn field_h_px(&self) -> usize {
        self.blocks_h * self.scale
    }

    /// Picture coordinates (pixels, y down) of a world point (metres, y up).
    pub(super) fn pixel_from_world(&self, x_m: f64, y_m: f64) -> (f64, f64) {
        (
            x_m * self.px_per_m,
            self.field_h_px() as f64 - y_m * self.px_per_m,
        )
    }

    /// The value drawn for block (bx, by), by counted from y = 0: the cell itself, or the max
    /// of the block's cells when decimating (a thin trail must not vanish), NaN if any is NaN.
    fn block_value(&self, plane: &[f32], bx: usize, by: usize) -> f32 {
        if self.decimate == 1 {
            return plane[by * self.width + bx];
        }
        let (x0, y0) = (bx * self.decimate, by * self.decimate);
        let (x1, y1) = (
            (x0 + self.decimate).min(self.width),
            (y0 + self.decimate).min(self.height),
        );
        let mut m = f32::NEG_INFINITY;
        for y in y0..y1 {
            for &v in &plane[y * self.width + x0..y * self.width + x1] {
                if v.is_nan() {
                    return f32::NAN;
                }
                m = m.max(v);
            }
        }
        m
    }
}

/// The f64 closest to the decimal an f32 prints as (0.1f32 → 0.1, not 0.100000001490116): the
/// cell size came from a decimal in a scenario, and pixel positions should land where that
/// decimal puts them.
fn f64_from_decimal(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(v as f64)
}

/// The picture of channel `c` of `snap`, with walls and the robots' trajectories up to the
/// snapshot's time.
pub(super) fn render_snapshot(rec: &Recording, snap: &Snapshot, c: usize) -> Canvas {
    let layout = Layout::for_grid(snap.width, snap.height, snap.cell_size_m);
    let plane = snap.plane(c);
    let map = ColourMap::for_plane(plane);
    let (fw, fh) = (layout.field_w_px(), layout.field_h_px());
    let mut canvas = Canvas::new(fw, fh + STRIP_HEIGHT_PX, STRIP_RGB);

    // The field: one picture row of blocks, repeated `scale` times; block row 0 (y = 0) at the
    // bottom.
    let row_bytes = fw * 3;
    let mut row = vec![0u8; row_bytes];
    for by in 0..layout.blocks_h {
        for bx in 0..layout.blocks_w {
            let colour = map.colour(layout.block_value(plane, bx, by));
            for k in 0..layout.scale {
                let i = (bx * layout.scale + k) * 3;
                row[i..i + 3].copy_from_slice(&colour);
            }
        }
        let top = (layout.blocks_h - 1 - by) * layout.scale;
        for r in top..top + layout.scale {
            canvas.rgb[r * row_bytes..(r + 1) * row_bytes].copy_from_slice(&row);
        }
    }

    let (wf, hf) = (fw as f64, fh as f64);
    let mut wall_pen = Pen::solid(3, WALL_RGB);
    for (a, b) in &rec.walls {
        wall_pen.line(
            &mut canvas,
            layout.pixel_from_world(a[0], a[1]),
            layout.pixel_from_world(b[0], b[1]),
            wf,
            hf,
        );
    }

    // Trajectories up to the snapshot's time: true solid, estimated dashed in a lighter shade.
    let mut markers = Vec::new();
    for (&id, rows) in &rec.robots {
        let rows: Vec<&RobotSample> = rows.iter().filter(|r| r.t_s <= snap.t_s + 1e-9).collect();
        let colour = robot_rgb(id);
        Pen::solid(2, colour).path(
            &mut canvas,
            rows.iter()
                .map(|r| Some(layout.pixel_from_world(r.true_pose[0], r.true_pose[1]))),
            wf,
            hf,
        );
        // A gap in the estimates (None) breaks the line; it starts again at the next one.
        Pen::dashed(2, lighter(colour), 6, 5).path(
            &mut canvas,
            rows.iter()
                .map(|r| r.est_pose.map(|e| layout.pixel_from_world(e[0], e[1]))),
            wf,
            hf,
        );
        if let Some(last) = rows.last() {
            markers.push((id, colour, last.true_pose, last.est_pose));
        }
    }
    // Markers last, so no trajectory hides them.
    for (id, colour, pose, est) in markers {
        if let Some(e) = est {
            let (x, y) = layout.pixel_from_world(e[0], e[1]);
            if x.is_finite() && y.is_finite() {
                canvas.ring(x as i64, y as i64, 4, 6, lighter(colour));
            }
        }
        let (x, y) = layout.pixel_from_world(pose[0], pose[1]);
        if x.is_finite() && y.is_finite() && x.abs() < 1e9 && y.abs() < 1e9 {
            let (x, y) = (x.floor() as i64, y.floor() as i64);
            canvas.disc(x, y, 7, OUTLINE_RGB);
            canvas.disc(x, y, 5, colour);
            let label = format!("R{id}");
            draw_text(&mut canvas, x + 10, y - 22, &label, 2, colour, true);
        }
    }

    draw_strip(&mut canvas, &layout, &map, &snap.channels[c], snap.t_s, rec);
    canvas
}

/// The strip under the field: title and time, colour bar with its range, scale bar, legend.
fn draw_strip(
    canvas: &mut Canvas,
    layout: &Layout,
    map: &ColourMap,
    channel: &str,
    t_s: f64,
    rec: &Recording,
) {
    let y0 = layout.field_h_px() as i64;
    let w = canvas.width as i64;
    let (row1, row2) = (y0 + 8, y0 + 30);

    let title = format!("{channel}  t={t_s:.1} s");
    draw_text(canvas, 10, row1, &title, 2, TEXT_RGB, false);

    // Colour bar on the right half, its range under it.
    let bar_x0 = (w * 11 / 20).max(10);
    let bar_x1 = w - 16;
    if bar_x1 > bar_x0 + 20 {
        let n = (bar_x1 - bar_x0) as f64;
        for x in bar_x0..bar_x1 {
            let c = map.bar_colour((x - bar_x0) as f64 / n);
            canvas.fill_rect(x, row1, 1, 14, c);
        }
        let max = fmt_sig(map.max as f64);
        let (lo, hi) = if map.signed {
            (format!("-{max}"), max)
        } else {
            ("0".to_string(), max)
        };
        draw_text(canvas, bar_x0, row2, &lo, 2, TEXT_RGB, false);
        if map.signed {
            let mid = (bar_x0 + bar_x1) / 2;
            draw_text(canvas, mid - 5, row2, "0", 2, TEXT_RGB, false);
        }
        let hi_w = text_width(&hi, 2);
        draw_text(canvas, bar_x1 - hi_w, row2, &hi, 2, TEXT_RGB, false);
    }

    // Scale bar: a round length close to a sixth of the picture.
    let target_m = layout.field_w_px() as f64 / 6.0 / layout.px_per_m;
    let mut x = 10i64;
    if target_m.is_finite() && target_m > 0.0 {
        let exp = target_m.log10().floor();
        let base = 10f64.powf(exp);
        let len_m = [5.0, 2.0, 1.0]
            .into_iter()
            .map(|k| k * base)
            .find(|&l| l <= target_m)
            .unwrap_or(base);
        let len_px = (len_m * layout.px_per_m).round() as i64;
        canvas.fill_rect(x, row2 + 5, len_px, 4, TEXT_RGB);
        canvas.fill_rect(x, row2 + 1, 2, 12, TEXT_RGB);
        canvas.fill_rect(x + len_px - 2, row2 + 1, 2, 12, TEXT_RGB);
        let decimals = (-exp).max(0.0) as usize;
        let label = format!("{len_m:.decimals$} m");
        x += len_px + 10;
        x += draw_text(canvas, x, row2, &label, 2, TEXT_RGB, false) + 20;
    }

    // Legend: line styles, then one coloured label per robot.
    if !rec.robots.is_empty() {
        let mut pen = Pen::solid(2, TEXT_RGB);
        let (wc, hc) = (canvas.width as f64, canvas.height as f64);
        let ly = (row2 + 7) as f64;
        pen.line(canvas, (x as f64, ly), ((x + 27) as f64, ly), wc, hc);
        x += 34;
        x += draw_text(canvas, x, row2, "true", 2, TEXT_RGB, false) + 14;
        let mut pen = Pen::dashed(2, TEXT_RGB, 6, 5);
        pen.line(canvas, (x as f64, ly), ((x + 27) as f64, ly), wc, hc);
        x += 34;
        x += draw_text(canvas, x, row2, "est", 2, TEXT_RGB, false) + 14;
        for &id in rec.robots.keys() {
            x += draw_text(canvas, x, row2, &format!("R{id}"), 2, robot_rgb(id), false) + 12;
        }
    }
}

/// `v` with three significant digits, in exponent form when very large or small.
pub(super) fn fmt_sig(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let mag = v.abs().log10().floor();
    if !(-2.0..5.0).contains(&mag) {
        return format!("{v:.2e}");
    }
    let decimals = (2.0 - mag).max(0.0) as usize;
    format!("{v:.decimals$}")
}

#[cfg(test)]
mod tests {
    use super::super::raster::{lighter, Rgb, OUTLINE_RGB, ROBOT_RGB, VIRIDIS};
    use super::super::tests::scene;
    use super::*;

    #[test]
    fn trajectories_stop_at_the_snapshot_time() {
        let mut rec = scene();
        rec.snapshots[0].t_s = 4.0; // robot 0 is at x = 3 m then
        let canvas = render_snapshot(&rec, &rec.snapshots[0], 0);
        let layout = Layout::for_grid(100, 50, 0.1);
        let (x, y) = layout.pixel_from_world(2.0, 1.0);
        assert_eq!(canvas.get(x as usize, y as usize), ROBOT_RGB[0]);
        let (x, y) = layout.pixel_from_world(5.0, 1.0);
        assert_eq!(canvas.get(x as usize, y as usize), VIRIDIS[0]);
        // The marker sits at the position at t = 4 s.
        let (x, y) = layout.pixel_from_world(3.0, 1.0);
        assert_eq!(canvas.get(x as usize, y as usize), ROBOT_RGB[0]);
        assert_eq!(canvas.get(x as usize + 6, y as usize), OUTLINE_RGB);
    }

    #[test]
    fn a_gap_in_the_estimates_breaks_the_dashed_line() {
        let mut rec = scene();
        let rows = rec.robots.get_mut(&1).unwrap();
        for r in &mut rows[4..=6] {
            r.est_pose = None; // x = 3 … 4 m
        }
        let canvas = render_snapshot(&rec, &rec.snapshots[0], 0);
        let layout = Layout::for_grid(100, 50, 0.1);
        let row = |x0_m: f64, x1_m: f64| -> Vec<Rgb> {
            let (x0, y) = layout.pixel_from_world(x0_m, 2.5);
            let (x1, _) = layout.pixel_from_world(x1_m, 2.5);
            (x0 as usize..x1 as usize)
                .map(|x| canvas.get(x, y as usize))
                .collect()
        };
        let shade = lighter(ROBOT_RGB[1]);
        assert!(row(1.0, 2.5).contains(&shade));
        assert!(row(4.5, 6.0).contains(&shade));
        assert!(row(2.6, 4.4).iter().all(|&c| c == VIRIDIS[0]));
    }
    #[test]
    fn picture_size_stays_between_800_and_2000_pixels() {
        for (w, h) in [
            (30, 20),
            (100, 50),
            (600, 400),
            (512, 512),
            (1500, 900),
            (10, 1000),
        ] {
            let l = Layout::for_grid(w, h, 0.05);
            assert_eq!(l.decimate, 1);
            assert!(
                l.field_w_px().max(l.field_h_px()) <= MAX_SIDE_PX,
                "{w}×{h}: {l:?}"
            );
            if (h as usize) * MIN_WIDTH_PX.div_ceil(w as usize) <= MAX_SIDE_PX {
                assert!(l.field_w_px() >= MIN_WIDTH_PX, "{w}×{h}: {l:?}");
            }
        }
        // A grid larger than the cap is reduced by whole blocks, keeping each block's max.
        let l = Layout::for_grid(5000, 7, 0.05);
        assert_eq!(
            (l.decimate, l.blocks_w, l.blocks_h, l.scale),
            (3, 1667, 3, 1)
        );
        let mut plane = vec![0.0f32; 5000 * 7];
        plane[6 * 5000 + 4999] = 2.0; // the last, partial block
        assert_eq!(l.block_value(&plane, 1666, 2), 2.0);
        assert_eq!(l.block_value(&plane, 0, 0), 0.0);
    }
}
