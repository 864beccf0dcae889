//! The heat-map picture of one channel of a field snapshot: where the grid lands in the picture
//! (`Layout`), the cells (one colour per cell, upscaled by a whole factor), and, drawn over them
//! with plotters, the axes in metres, walls, anti-aliased trajectories (true solid, estimated
//! dashed), robot markers, the places the scenario's metrics name (`marks`: area A, location
//! B, where a follower explored from), and the strip under the field with the title, legend and
//! colour bar.

use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use super::marks::{Mark, Shape};
use super::style::{
    colour, lighter, msg, robot_rgb, ColourMap, Picture, Rgb, FONT, OUTLINE_RGB, STRIP_RGB,
    TEXT_RGB, WALL_RGB,
};
use pheromone_sim::recording::{Recording, RobotSample, Snapshot};

/// The field part of the picture is at least this many pixels wide (if the cap below allows it).
const MIN_WIDTH_PX: usize = 800;
/// Neither side of the field part of the picture exceeds this many pixels.
const MAX_SIDE_PX: usize = 2000;
/// Left of the field: the y axis and its labels (m).
pub(super) const LEFT_PX: u32 = 48;
/// Above the field (the y axis' unit) and right of it.
pub(super) const TOP_PX: u32 = 28;
pub(super) const RIGHT_PX: u32 = 24;
/// Under the field: the x axis and its labels (m).
pub(super) const AXIS_PX: u32 = 40;
/// Under the axis: title, legend and colour bar.
pub(super) const STRIP_PX: u32 = 64;
/// Stroke widths (px): trajectories, walls.
const PATH_PX: u32 = 3;
const WALL_PX: u32 = 3;

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

    pub(super) fn field_w_px(&self) -> usize {
        self.blocks_w * self.scale
    }

    pub(super) fn field_h_px(&self) -> usize {
        self.blocks_h * self.scale
    }

    /// The whole picture (px).
    pub(super) fn picture_px(&self) -> (u32, u32) {
        (
            LEFT_PX + self.field_w_px() as u32 + RIGHT_PX,
            TOP_PX + self.field_h_px() as u32 + AXIS_PX + STRIP_PX,
        )
    }

    /// Picture coordinates (pixels, y down) of a world point (metres, y up).
    pub(super) fn pixel_from_world(&self, x_m: f64, y_m: f64) -> (f64, f64) {
        (
            LEFT_PX as f64 + x_m * self.px_per_m,
            TOP_PX as f64 + self.field_h_px() as f64 - y_m * self.px_per_m,
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

    /// The world extent drawn (m).
    fn extent_m(&self) -> (f64, f64) {
        (
            self.field_w_px() as f64 / self.px_per_m,
            self.field_h_px() as f64 / self.px_per_m,
        )
    }
}

/// The f64 closest to the decimal an f32 prints as (0.1f32 → 0.1, not 0.100000001490116): the
/// cell size came from a decimal in a scenario, and pixel positions should land where that
/// decimal puts them.
fn f64_from_decimal(v: f32) -> f64 {
    v.to_string().parse().unwrap_or(v as f64)
}

/// A backend coordinate, or None when it is not finite or absurdly far out.
fn coord((x, y): (f64, f64)) -> Option<(i32, i32)> {
    (x.is_finite() && y.is_finite() && x.abs() < 1e7 && y.abs() < 1e7)
        .then(|| (x.round() as i32, y.round() as i32))
}

/// The picture of channel `c` of `snap` in colour scale `map` (the run's for that channel),
/// with walls, the robots' trajectories up to the
/// snapshot's time and the `marks` due by then (outlines under the trajectories, labels and
/// crosses over them, robot markers over everything).
pub(super) fn render_snapshot(
    rec: &Recording,
    snap: &Snapshot,
    c: usize,
    marks: &[Mark],
    map: &ColourMap,
) -> Result<Picture, String> {
    let layout = Layout::for_grid(snap.width, snap.height, snap.cell_size_m);
    let plane = snap.plane(c);
    let (w, h) = layout.picture_px();
    let mut pic = Picture::new(w, h, STRIP_RGB);
    fill_cells(&mut pic, &layout, plane, map);
    pic.draw(|root| {
        draw_axes(root, &layout)?;
        let (x0, y0) = (LEFT_PX as i32, TOP_PX as i32);
        let field = root.clone().shrink(
            (x0, y0),
            (layout.field_w_px() as u32, layout.field_h_px() as u32),
        );
        // Coordinates within the field area: the picture's, shifted.
        let px = |x_m: f64, y_m: f64| {
            let (x, y) = layout.pixel_from_world(x_m, y_m);
            coord((x - x0 as f64, y - y0 as f64))
        };
        for (a, b) in &rec.walls {
            if let (Some(a), Some(b)) = (px(a[0], a[1]), px(b[0], b[1])) {
                let style = colour(WALL_RGB).stroke_width(WALL_PX);
                field
                    .draw(&PathElement::new(vec![a, b], style))
                    .map_err(msg)?;
            }
        }
        let marks: Vec<&Mark> = marks
            .iter()
            .filter(|m| m.from_s <= snap.t_s + 1e-9)
            .collect();
        for m in &marks {
            draw_outline(&field, &layout, m, &px)?;
        }
        let mut markers = Vec::new();
        for (&id, rows) in &rec.robots {
            let rows: Vec<&RobotSample> =
                rows.iter().filter(|r| r.t_s <= snap.t_s + 1e-9).collect();
            let rgb = robot_rgb(id);
            draw_trajectory(&field, &rows, rgb, &px)?;
            if let Some(last) = rows.last() {
                markers.push((id, rgb, last.true_pose, last.est_pose));
            }
        }
        // The robots' own labels (drawn last, at their markers) are taken places too.
        let mut placed: Vec<[i32; 4]> = markers
            .iter()
            .filter_map(|(id, _, pose, _)| {
                let p = px(pose[0], pose[1])?;
                let tw = text_width(&format!("R{id}"));
                Some([p.0 + 5, p.1 - 31, p.0 + 13 + tw, p.1 - 6])
            })
            .collect();
        for m in &marks {
            draw_mark_label(&field, &layout, m, &px, &mut placed)?;
        }
        // Markers last, so no trajectory hides them.
        draw_markers(&field, markers, &px)?;
        let strip = root.clone().shrink(
            (0, (TOP_PX + layout.field_h_px() as u32 + AXIS_PX) as i32),
            (w, STRIP_PX),
        );
        draw_strip(&strip, map, &snap.channels[c], snap.t_s, rec)
    })?;
    Ok(pic)
}

type Field<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// A robot's true trajectory (solid) and its estimate (dashed, lighter; a gap in the estimates
/// breaks the line, which starts again at the next).
fn draw_trajectory(
    field: &Field<'_>,
    rows: &[&RobotSample],
    rgb: [u8; 3],
    px: &impl Fn(f64, f64) -> Option<(i32, i32)>,
) -> Result<(), String> {
    let truth: Vec<Option<(i32, i32)>> = rows
        .iter()
        .map(|r| px(r.true_pose[0], r.true_pose[1]))
        .collect();
    for run in runs(&truth) {
        let style = colour(rgb).stroke_width(PATH_PX);
        field.draw(&PathElement::new(run, style)).map_err(msg)?;
    }
    let est: Vec<Option<(i32, i32)>> = rows
        .iter()
        .map(|r| r.est_pose.and_then(|e| px(e[0], e[1])))
        .collect();
    for run in runs(&est) {
        let style = colour(lighter(rgb)).stroke_width(PATH_PX);
        field
            .draw(&DashedPathElement::new(run, 7, 5, style))
            .map_err(msg)?;
    }
    Ok(())
}

/// A robot's ID, colour, last true pose and last estimate.
type RobotMarker = (u32, [u8; 3], [f64; 3], Option<[f64; 3]>);

/// Each robot's marker at its last true pose (labelled `R<id>`) and a ring at its estimate.
fn draw_markers(
    field: &Field<'_>,
    markers: Vec<RobotMarker>,
    px: &impl Fn(f64, f64) -> Option<(i32, i32)>,
) -> Result<(), String> {
    for (id, rgb, pose, est) in markers {
        if let Some(e) = est.and_then(|e| px(e[0], e[1])) {
            let ring = colour(lighter(rgb)).stroke_width(2);
            field.draw(&Circle::new(e, 5, ring)).map_err(msg)?;
        }
        if let Some(p) = px(pose[0], pose[1]) {
            field
                .draw(&Circle::new(p, 7, colour(OUTLINE_RGB).filled()))
                .map_err(msg)?;
            field
                .draw(&Circle::new(p, 5, colour(rgb).filled()))
                .map_err(msg)?;
            boxed_label(field, &format!("R{id}"), (p.0 + 9, p.1 - 24), rgb)?;
        }
    }
    Ok(())
}

/// Stroke width (px) of the marks' outlines and crosses.
const MARK_PX: u32 = 3;

/// `s` in 15 px text of colour `rgb` at `at`, on a dark box, so that it stays readable over a
/// trail or a path.
fn boxed_label(area: &Field<'_>, s: &str, at: (i32, i32), rgb: Rgb) -> Result<(), String> {
    let style = (FONT, 15).into_font().color(&colour(rgb));
    let (tw, th) = style.font.box_size(s).map_err(msg)?;
    let (lx, ly) = at;
    area.draw(&Rectangle::new(
        [(lx - 3, ly - 6), (lx + tw as i32 + 3, ly + th as i32)],
        colour(OUTLINE_RGB).mix(0.7).filled(),
    ))
    .map_err(msg)?;
    area.draw_text(s, &style, (lx, ly)).map_err(msg)
}

/// A mark's outline: a rectangle's or circle's, in its colour over a dark edge so that it stays
/// visible on the heat map's bright parts. Crosses are drawn with the labels.
fn draw_outline(
    field: &Field<'_>,
    layout: &Layout,
    m: &Mark,
    px: &impl Fn(f64, f64) -> Option<(i32, i32)>,
) -> Result<(), String> {
    let styles = [
        colour(OUTLINE_RGB).stroke_width(MARK_PX + 2),
        colour(m.rgb).stroke_width(MARK_PX),
    ];
    match m.shape {
        Shape::Rect { min_m, max_m } => {
            let corners = [
                px(min_m[0], min_m[1]),
                px(max_m[0], min_m[1]),
                px(max_m[0], max_m[1]),
                px(min_m[0], max_m[1]),
                px(min_m[0], min_m[1]),
            ];
            if let Some(ring) = corners.into_iter().collect::<Option<Vec<_>>>() {
                for style in styles {
                    field
                        .draw(&PathElement::new(ring.clone(), style))
                        .map_err(msg)?;
                }
            }
        }
        Shape::Circle { centre_m, radius_m } => {
            let r = radius_m * layout.px_per_m;
            if let (Some(c), true) = (px(centre_m[0], centre_m[1]), r.is_finite() && r < 1e6) {
                for style in styles {
                    field
                        .draw(&Circle::new(c, r.round() as i32, style))
                        .map_err(msg)?;
                }
            }
        }
        Shape::Point { .. } => {}
    }
    Ok(())
}

/// A mark's label, kept inside the field: inside a rectangle's top-left corner, above a circle
/// (under it if there is no room), beside a cross (drawn here, over the trajectories): right
/// and under it, else right and above, left and under, left and above, or further down,
/// whichever first overlaps no label in `placed` (the labels drawn so far, to which it adds).
fn draw_mark_label(
    field: &Field<'_>,
    layout: &Layout,
    m: &Mark,
    px: &impl Fn(f64, f64) -> Option<(i32, i32)>,
    placed: &mut Vec<[i32; 4]>,
) -> Result<(), String> {
    if m.label.is_empty() && !matches!(m.shape, Shape::Point { .. }) {
        return Ok(()); // an outline with no label (the leader's σ circles but the last)
    }
    let (tw, th) = (FONT, 15).into_font().box_size(&m.label).map_err(msg)?;
    let (tw, th) = (tw as i32, th as i32);
    let (fw, fh) = (layout.field_w_px() as i32, layout.field_h_px() as i32);
    let clamp = |(x, y): (i32, i32)| {
        (
            x.clamp(6, (fw - tw - 6).max(6)),
            y.clamp(8, (fh - th - 4).max(8)),
        )
    };
    let free = |(x, y): (i32, i32)| {
        let r = [x - 4, y - 7, x + tw + 4, y + th + 1];
        placed
            .iter()
            .all(|p| r[2] <= p[0] || p[2] <= r[0] || r[3] <= p[1] || p[3] <= r[1])
    };
    let at = match m.shape {
        Shape::Rect { min_m, max_m } => px(min_m[0], max_m[1]).map(|p| (p.0 + 10, p.1 + 14)),
        Shape::Circle { centre_m, radius_m } => px(centre_m[0], centre_m[1]).map(|c| {
            let r = (radius_m * layout.px_per_m).min(1e6) as i32;
            let above = c.1 - r - th - 8;
            (c.0 - tw / 2, if above >= 8 { above } else { c.1 + r + 12 })
        }),
        Shape::Point { at_m } => match px(at_m[0], at_m[1]) {
            Some(p) => {
                let d = 6;
                for (w, rgb) in [(MARK_PX + 2, OUTLINE_RGB), (MARK_PX, m.rgb)] {
                    for seg in [
                        [(p.0 - d, p.1 - d), (p.0 + d, p.1 + d)],
                        [(p.0 - d, p.1 + d), (p.0 + d, p.1 - d)],
                    ] {
                        let style = colour(rgb).stroke_width(w);
                        field.draw(&PathElement::new(seg, style)).map_err(msg)?;
                    }
                }
                let (right, left) = (p.0 + 12, p.0 - 12 - tw);
                let (under, above) = (p.1 + 8, p.1 - th - 14);
                let step = th + 10;
                let tries = [(right, under), (right, above), (left, under), (left, above)]
                    .into_iter()
                    .chain(
                        (1..8).flat_map(|k| [(right, under + k * step), (right, above - k * step)]),
                    );
                let mut tries = tries.map(clamp);
                let first = clamp((right, under));
                Some(tries.find(|&t| free(t)).unwrap_or(first))
            }
            None => None,
        },
    };
    if let Some(at) = at {
        let (x, y) = clamp(at);
        placed.push([x - 4, y - 7, x + tw + 4, y + th + 1]);
        boxed_label(field, &m.label, (x, y), m.rgb)?;
    }
    Ok(())
}

/// The cells: one colour per block, `scale` × `scale` pixels each, block row 0 (y = 0) at the
/// bottom of the field area.
fn fill_cells(pic: &mut Picture, layout: &Layout, plane: &[f32], map: &ColourMap) {
    let row_bytes = pic.width as usize * 3;
    let mut row = vec![0u8; layout.field_w_px() * 3];
    let x0 = LEFT_PX as usize * 3;
    for by in 0..layout.blocks_h {
        for bx in 0..layout.blocks_w {
            let c = map.colour(layout.block_value(plane, bx, by));
            for k in 0..layout.scale {
                let i = (bx * layout.scale + k) * 3;
                row[i..i + 3].copy_from_slice(&c);
            }
        }
        let top = TOP_PX as usize + (layout.blocks_h - 1 - by) * layout.scale;
        for r in top..top + layout.scale {
            let at = r * row_bytes + x0;
            pic.rgb[at..at + row.len()].copy_from_slice(&row);
        }
    }
}

/// The axes around the field, in metres; the field area itself is left as it is.
fn draw_axes(root: &DrawingArea<BitMapBackend<'_>, Shift>, layout: &Layout) -> Result<(), String> {
    let (w_m, h_m) = layout.extent_m();
    let mut chart = ChartBuilder::on(root)
        .margin_top(TOP_PX)
        .margin_right(RIGHT_PX)
        .margin_bottom(STRIP_PX)
        .x_label_area_size(AXIS_PX)
        .y_label_area_size(LEFT_PX)
        .build_cartesian_2d(0.0..w_m, 0.0..h_m)
        .map_err(msg)?;
    let (xr, yr) = chart.plotting_area().get_pixel_range();
    let expected = (
        LEFT_PX as i32..(LEFT_PX as usize + layout.field_w_px()) as i32,
        TOP_PX as i32..(TOP_PX as usize + layout.field_h_px()) as i32,
    );
    if (xr.clone(), yr.clone()) != expected {
        return Err(format!(
            "the axes' area {xr:?} × {yr:?} px is not the field's {expected:?}"
        ));
    }
    let text = (FONT, 13).into_font().color(&colour(TEXT_RGB));
    let x_ticks = (layout.field_w_px() / 90).clamp(2, 20);
    let y_ticks = (layout.field_h_px() / 40).clamp(2, 12);
    chart
        .configure_mesh()
        .disable_mesh()
        .axis_style(colour(TEXT_RGB))
        .label_style(text.clone())
        .axis_desc_style(text)
        .x_labels(x_ticks)
        .y_labels(y_ticks)
        .x_desc("x (m)")
        .x_label_formatter(&|v| trim(*v))
        .y_label_formatter(&|v| trim(*v))
        .draw()
        .map_err(msg)?;
    let style = (FONT, 13).into_font().color(&colour(TEXT_RGB));
    root.draw_text("y (m)", &style, (6, 6)).map_err(msg)?;
    Ok(())
}

/// A tick label: as short as it can be (`2`, `1.5`, `0.25`).
fn trim(v: f64) -> String {
    let s = format!("{v:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.into()
    }
}

/// The unbroken stretches of a path whose points may be missing.
fn runs(points: &[Option<(i32, i32)>]) -> Vec<Vec<(i32, i32)>> {
    let mut out = Vec::new();
    let mut cur: Vec<(i32, i32)> = Vec::new();
    for p in points {
        match p {
            Some(p) => {
                if cur.last() != Some(p) {
                    cur.push(*p);
                }
            }
            None => {
                if !cur.is_empty() {
                    out.push(std::mem::take(&mut cur));
                }
            }
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// Width of the colour bar's part of the strip: the right half.
pub(super) fn bar_span_px(strip_w: u32) -> (i32, i32) {
    ((strip_w / 2) as i32 + 40, strip_w as i32 - RIGHT_PX as i32)
}

/// The strip under the field: the title and legend on the left half, the colour bar with its
/// caption (channel and unit) and ticks on the right half; the halves never overlap.
fn draw_strip(
    strip: &DrawingArea<BitMapBackend<'_>, Shift>,
    map: &ColourMap,
    channel: &str,
    t_s: f64,
    rec: &Recording,
) -> Result<(), String> {
    let (w, _) = strip.dim_in_pixel();
    let text = |size: u32| (FONT, size).into_font().color(&colour(TEXT_RGB));
    strip
        .draw_text(&format!("{channel}, t = {t_s:.1} s"), &text(18), (12, 6))
        .map_err(msg)?;

    // Legend, left half: line styles, then a coloured name per robot, as many as fit.
    let (bar_x0, bar_x1) = bar_span_px(w);
    let legend_end = bar_x0 - 40;
    if !rec.robots.is_empty() {
        let y = 44;
        let mut x = 12;
        let white = colour(TEXT_RGB).stroke_width(PATH_PX);
        strip
            .draw(&PathElement::new(vec![(x, y), (x + 28, y)], white))
            .map_err(msg)?;
        x += 34;
        x += label(strip, "true", x, y - 8, TEXT_RGB)? + 14;
        strip
            .draw(&DashedPathElement::new(
                vec![(x, y), (x + 28, y)],
                7,
                5,
                white,
            ))
            .map_err(msg)?;
        x += 34;
        x += label(strip, "estimated", x, y - 8, TEXT_RGB)? + 16;
        let ids: Vec<u32> = rec.robots.keys().copied().collect();
        for (i, &id) in ids.iter().enumerate() {
            let name = format!("R{id}");
            let left = ids.len() - i;
            let need = text_width(&name) + if left > 1 { text_width(" …") + 10 } else { 0 };
            if x + need > legend_end {
                label(strip, "…", x, y - 8, TEXT_RGB)?;
                break;
            }
            x += label(strip, &name, x, y - 8, robot_rgb(id))? + 10;
        }
    }

    // Colour bar, right half: caption above, ticks under it.
    let (lo, hi) = map.range();
    let bar_y = 24;
    let bar_h = 14;
    let n = (bar_x1 - bar_x0).max(1);
    for i in 0..n {
        let c = colour(map.bar_colour(i as f64 / (n - 1).max(1) as f64));
        strip
            .draw(&Rectangle::new(
                [(bar_x0 + i, bar_y), (bar_x0 + i + 1, bar_y + bar_h)],
                c.filled(),
            ))
            .map_err(msg)?;
    }
    let caption = format!("{channel} level (pheromone units)");
    let cw = text_width(&caption);
    label(strip, &caption, bar_x1 - cw, 4, TEXT_RGB)?;
    let ticks = bar_ticks(lo, hi, bar_x1 - bar_x0);
    for v in ticks {
        let x = bar_x0 + ((v - lo) / (hi - lo) * (n - 1) as f64).round() as i32;
        strip
            .draw(&PathElement::new(
                vec![(x, bar_y + bar_h), (x, bar_y + bar_h + 4)],
                colour(TEXT_RGB),
            ))
            .map_err(msg)?;
        let s = fmt_sig(v);
        let tw = text_width(&s);
        label(strip, &s, x - tw / 2, bar_y + bar_h + 6, TEXT_RGB)?;
    }
    Ok(())
}

/// Draws `s` at (x, y) in the strip's 14 px text and returns its width.
fn label(
    area: &DrawingArea<BitMapBackend<'_>, Shift>,
    s: &str,
    x: i32,
    y: i32,
    rgb: Rgb,
) -> Result<i32, String> {
    let style = (FONT, 14).into_font().color(&colour(rgb));
    area.draw_text(s, &style, (x, y)).map_err(msg)?;
    Ok(text_width(s))
}

/// Width (px) of `s` in the 14 px text.
pub(super) fn text_width(s: &str) -> i32 {
    (FONT, 14)
        .into_font()
        .box_size(s)
        .map(|(w, _)| w as i32)
        .unwrap_or(8 * s.chars().count() as i32)
}

/// Round tick values on the bar from `lo` to `hi`, as many as fit `width_px` without two labels
/// closer than their widths (plotters' key points; the ends always among them).
pub(super) fn bar_ticks(lo: f64, hi: f64, width_px: i32) -> Vec<f64> {
    use plotters::coord::ranged1d::Ranged;
    use plotters::coord::types::RangedCoordf64;
    let range: RangedCoordf64 = (lo..hi).into();
    let mut n = 11usize;
    loop {
        let mut v: Vec<f64> = range.key_points(n);
        if v.first().is_none_or(|f| (*f - lo).abs() > 1e-9 * (hi - lo)) {
            v.insert(0, lo);
        }
        if v.last().is_none_or(|l| (*l - hi).abs() > 1e-9 * (hi - lo)) {
            // The top of the scale replaces a round tick too close to it.
            while v
                .last()
                .is_some_and(|l| (hi - *l) / (hi - lo) * (width_px as f64) < 60.0)
            {
                v.pop();
            }
            v.push(hi);
        }
        let px = |t: f64| (t - lo) / (hi - lo) * width_px as f64;
        let fits = v.windows(2).all(|p| {
            let half = (text_width(&fmt_sig(p[0])) + text_width(&fmt_sig(p[1]))) as f64 / 2.0;
            px(p[1]) - px(p[0]) > half + 12.0
        });
        if fits || n <= 2 {
            return v;
        }
        n -= 1;
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
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

#[cfg(test)]
mod tests;
