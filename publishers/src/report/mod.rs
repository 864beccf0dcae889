//! The files a simulation run leaves behind (`pheromone sim --out DIR`): the metrics object, one
//! CSV time series per robot, the probe readings, and a heat-map picture of every channel of every
//! field snapshot with the robots' trajectories drawn over it.
//!
//! The pictures are drawn here without a plotting crate: a small colour-map lookup table
//! (viridis for unsigned channels, a dark-centred blue/orange diverging map for signed ones),
//! nearest-neighbour upscaling by an integer factor, Bresenham lines with Liang–Barsky clipping,
//! and a built-in 5×7 pixel font for the labels. y points up: row 0 of a plane (y = 0) is the
//! bottom row of the picture.
//!
//! The snapshot carries no grid origin, so the field is drawn with its origin at (0, 0) m, the
//! default of every scenario.

use std::fmt::Write as _;
use std::fs::{self, File};
use std::io::{BufWriter, Write as _};
use std::path::{Path, PathBuf};

use crate::sim::record::{Recording, RobotSample, Snapshot};

/// Writing the outputs of a run failed.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Creating the directory or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Encoding a picture failed (this includes I/O errors while writing it).
    #[error("{}: cannot write PNG: {source}", path.display())]
    Png {
        path: PathBuf,
        #[source]
        source: png::EncodingError,
    },
    /// The metrics object could not be serialized.
    #[error("{}: cannot serialize the metrics: {source}", path.display())]
    Json {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },
    /// A snapshot's size does not match its plane data.
    #[error("field snapshot at t = {t_s} s: {detail}")]
    BadSnapshot { t_s: f64, detail: String },
}

/// Header of `robot_<id>.csv`.
pub const ROBOT_CSV_HEADER: &str = "t_s,true_x_m,true_y_m,true_theta_rad,est_x_m,est_y_m,\
est_theta_rad,est_sigma_m,v_mps,omega_radps,state,sensed_level";

/// Header of `probes.csv`.
pub const PROBES_CSV_HEADER: &str = "t_s,x_m,y_m,channel,value";

/// The picture's width is at least this many pixels (if the cap below allows it).
const MIN_WIDTH_PX: usize = 800;
/// Neither side of the field part of the picture exceeds this many pixels.
const MAX_SIDE_PX: usize = 2000;
/// Height of the strip under the field with the title, colour bar, scale bar and legend.
const STRIP_HEIGHT_PX: usize = 52;

/// Writes every output of a run into `dir` (created if needed) and returns the paths written:
/// `metrics.json`, `robot_<id>.csv` per robot, `probes.csv` if there are probes, one
/// `field_<channel>_t<sss.s>s.png` per snapshot and channel, and `field_final.png` (the last
/// snapshot's first channel).
pub fn write_outputs(
    dir: &Path,
    rec: &Recording,
    metrics: &serde_json::Value,
) -> Result<Vec<PathBuf>, ReportError> {
    for snap in &rec.snapshots {
        check_snapshot(snap)?;
    }
    fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut written = Vec::new();

    let path = dir.join("metrics.json");
    let mut text = serde_json::to_string_pretty(metrics).map_err(|source| ReportError::Json {
        path: path.clone(),
        source,
    })?;
    text.push('\n');
    write_file(&path, text.as_bytes())?;
    written.push(path);

    for (id, rows) in &rec.robots {
        let path = dir.join(format!("robot_{id}.csv"));
        write_file(&path, robot_csv(rows).as_bytes())?;
        written.push(path);
    }

    if !rec.probes.is_empty() {
        let mut text = String::from(PROBES_CSV_HEADER);
        text.push('\n');
        for p in &rec.probes {
            let _ = writeln!(text, "{},{},{},{},{}", p.t_s, p.x, p.y, p.channel, p.value);
        }
        let path = dir.join("probes.csv");
        write_file(&path, text.as_bytes())?;
        written.push(path);
    }

    let mut final_png = None;
    for snap in &rec.snapshots {
        for (c, name) in snap.channels.iter().enumerate() {
            let canvas = render_snapshot(rec, snap, c);
            let path = dir.join(snapshot_file_name(name, snap.t_s));
            write_png(&path, &canvas)?;
            if c == 0 {
                final_png = Some(path.clone());
            }
            written.push(path);
        }
    }
    if let Some(last) = final_png {
        let path = dir.join("field_final.png");
        fs::copy(&last, &path).map_err(|source| ReportError::Io {
            path: path.clone(),
            source,
        })?;
        written.push(path);
    }
    Ok(written)
}

/// `field_<channel>_t<seconds>s.png`, seconds with one decimal and at least three integer
/// digits (`field_trail_t012.0s.png`); characters other than letters, digits, `-` and `_` in
/// the channel name become `_`.
pub fn snapshot_file_name(channel: &str, t_s: f64) -> String {
    let name: String = channel
        .chars()
        .map(|ch| {
            if ch.is_ascii_alphanumeric() || ch == '-' || ch == '_' {
                ch
            } else {
                '_'
            }
        })
        .collect();
    format!("field_{name}_t{t_s:05.1}s.png")
}

fn check_snapshot(snap: &Snapshot) -> Result<(), ReportError> {
    let bad = |detail: String| ReportError::BadSnapshot {
        t_s: snap.t_s,
        detail,
    };
    if snap.width == 0 || snap.height == 0 {
        return Err(bad(format!(
            "empty grid {} × {} cells",
            snap.width, snap.height
        )));
    }
    if !(snap.cell_size_m.is_finite() && snap.cell_size_m > 0.0) {
        return Err(bad(format!(
            "cell_size_m = {} is not a positive number",
            snap.cell_size_m
        )));
    }
    let expected = snap.width as usize * snap.height as usize * snap.channels.len();
    if snap.planes.len() != expected {
        return Err(bad(format!(
            "{} values for {} × {} cells × {} channels (expected {expected})",
            snap.planes.len(),
            snap.width,
            snap.height,
            snap.channels.len()
        )));
    }
    Ok(())
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    fs::write(path, bytes).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn robot_csv(rows: &[RobotSample]) -> String {
    fn opt<T: std::fmt::Display>(v: Option<T>) -> String {
        v.map(|v| v.to_string()).unwrap_or_default()
    }
    let mut text = String::with_capacity(64 * (rows.len() + 1));
    text.push_str(ROBOT_CSV_HEADER);
    text.push('\n');
    for r in rows {
        let est = r.est_pose;
        let _ = writeln!(
            text,
            "{},{},{},{},{},{},{},{},{},{},{},{}",
            r.t_s,
            r.true_pose[0],
            r.true_pose[1],
            r.true_pose[2],
            opt(est.map(|p| p[0])),
            opt(est.map(|p| p[1])),
            opt(est.map(|p| p[2])),
            opt(r.est_sigma_m),
            r.v_mps,
            r.omega_radps,
            r.state.map(|s| s.name()).unwrap_or(""),
            opt(r.sensed_level),
        );
    }
    text
}

// ---------------------------------------------------------------------------------------------
// Pictures

type Rgb = [u8; 3];

/// Colour of a cell whose value is NaN (never expected; shown rather than hidden).
const NAN_RGB: Rgb = [255, 0, 255];
/// Walls.
const WALL_RGB: Rgb = [215, 215, 215];
/// Background of the strip under the field, and its text.
const STRIP_RGB: Rgb = [24, 24, 28];
const TEXT_RGB: Rgb = [235, 235, 235];
const OUTLINE_RGB: Rgb = [0, 0, 0];
/// One colour per robot (by id, cycling), chosen to stand out on both colour maps.
const ROBOT_RGB: [Rgb; 5] = [
    [240, 40, 40],
    [0, 190, 255],
    [255, 150, 0],
    [255, 110, 200],
    [170, 130, 255],
];

/// viridis at 10 evenly spaced stops (matplotlib).
const VIRIDIS: [Rgb; 10] = [
    [0x44, 0x01, 0x54],
    [0x48, 0x28, 0x78],
    [0x3e, 0x4a, 0x89],
    [0x31, 0x68, 0x8e],
    [0x26, 0x82, 0x8e],
    [0x1f, 0x9e, 0x89],
    [0x35, 0xb7, 0x79],
    [0x6d, 0xcd, 0x59],
    [0xb4, 0xde, 0x2c],
    [0xfd, 0xe7, 0x25],
];

/// A diverging map for signed channels, −max … 0 … +max, dark at 0 so that walls and
/// trajectories stay visible: light blue, blue, near black, orange, light yellow.
const DIVERGING: [Rgb; 5] = [
    [150, 220, 255],
    [40, 120, 200],
    [20, 20, 28],
    [200, 90, 30],
    [255, 225, 120],
];

fn robot_rgb(id: u32) -> Rgb {
    ROBOT_RGB[id as usize % ROBOT_RGB.len()]
}

/// The lighter shade used for the estimated trajectory.
fn lighter(c: Rgb) -> Rgb {
    c.map(|v| v + (255 - v) / 2)
}

/// A colour map sampled into a table of `2·HALF + 1` (signed) or `HALF + 1` (unsigned) entries.
struct ColourMap {
    table: Vec<Rgb>,
    signed: bool,
    /// The value mapped to the top of the map (the plane's max, or max |v| if signed).
    max: f32,
}

const HALF: usize = 255;

fn interpolate(stops: &[Rgb], t: f64) -> Rgb {
    let t = t.clamp(0.0, 1.0) * (stops.len() - 1) as f64;
    let i = (t.floor() as usize).min(stops.len() - 2);
    let f = t - i as f64;
    let (a, b) = (stops[i], stops[i + 1]);
    std::array::from_fn(|k| (a[k] as f64 + (b[k] as f64 - a[k] as f64) * f).round() as u8)
}

impl ColourMap {
    /// Unsigned planes (no negative value) map 0 … max to viridis; signed planes map
    /// −max|v| … +max|v| to the diverging map. Non-finite values do not count for the max.
    fn for_plane(plane: &[f32]) -> ColourMap {
        let (mut lo, mut hi) = (0.0f32, 0.0f32);
        for &v in plane {
            if v.is_finite() {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        let signed = lo < 0.0;
        let max = if signed { hi.max(-lo) } else { hi };
        let table = if signed {
            (0..=2 * HALF)
                .map(|i| interpolate(&DIVERGING, i as f64 / (2 * HALF) as f64))
                .collect()
        } else {
            (0..=HALF)
                .map(|i| interpolate(&VIRIDIS, i as f64 / HALF as f64))
                .collect()
        };
        ColourMap { table, signed, max }
    }

    fn colour(&self, v: f32) -> Rgb {
        if v.is_nan() {
            return NAN_RGB;
        }
        let scale = if self.max > 0.0 { self.max } else { 1.0 };
        let u = (v / scale).clamp(if self.signed { -1.0 } else { 0.0 }, 1.0);
        let i = (u * HALF as f32).round() as isize + if self.signed { HALF as isize } else { 0 };
        self.table[i as usize]
    }

    /// The colour at fraction `t` ∈ [0, 1] of the bar (bottom … top of the map).
    fn bar_colour(&self, t: f64) -> Rgb {
        let n = self.table.len() - 1;
        self.table[((t.clamp(0.0, 1.0) * n as f64).round() as usize).min(n)]
    }
}

/// Where the grid lands in the picture.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Layout {
    width: usize,
    height: usize,
    /// Cells per picture block along each axis (> 1 only for grids larger than the cap).
    decimate: usize,
    /// Pixels per block along each axis.
    scale: usize,
    /// Blocks across and down.
    blocks_w: usize,
    blocks_h: usize,
    px_per_m: f64,
}

impl Layout {
    fn for_grid(width: u32, height: u32, cell_size_m: f32) -> Layout {
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
    fn pixel_from_world(&self, x_m: f64, y_m: f64) -> (f64, f64) {
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

/// An RGB picture; drawing outside it (or outside the clip height) is ignored.
struct Canvas {
    width: usize,
    height: usize,
    rgb: Vec<u8>,
}

impl Canvas {
    fn new(width: usize, height: usize, fill: Rgb) -> Canvas {
        let mut rgb = Vec::with_capacity(width * height * 3);
        for _ in 0..width * height {
            rgb.extend_from_slice(&fill);
        }
        Canvas { width, height, rgb }
    }

    fn put(&mut self, x: i64, y: i64, c: Rgb) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            let i = (y as usize * self.width + x as usize) * 3;
            self.rgb[i..i + 3].copy_from_slice(&c);
        }
    }

    #[cfg(test)]
    fn get(&self, x: usize, y: usize) -> Rgb {
        let i = (y * self.width + x) * 3;
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    fn fill_rect(&mut self, x: i64, y: i64, w: i64, h: i64, c: Rgb) {
        for yy in y..y + h {
            for xx in x..x + w {
                self.put(xx, yy, c);
            }
        }
    }

    fn disc(&mut self, cx: i64, cy: i64, r: i64, c: Rgb) {
        for dy in -r..=r {
            for dx in -r..=r {
                if dx * dx + dy * dy <= r * r + r {
                    self.put(cx + dx, cy + dy, c);
                }
            }
        }
    }

    fn ring(&mut self, cx: i64, cy: i64, r_in: i64, r_out: i64, c: Rgb) {
        for dy in -r_out..=r_out {
            for dx in -r_out..=r_out {
                let d2 = dx * dx + dy * dy;
                if d2 <= r_out * r_out + r_out && d2 > r_in * r_in + r_in {
                    self.put(cx + dx, cy + dy, c);
                }
            }
        }
    }
}

/// A line pen: thickness in pixels, colour, and an optional dash pattern (on, off) in pixels
/// whose phase carries from one segment to the next.
struct Pen {
    thick: i64,
    colour: Rgb,
    dash: Option<(u32, u32)>,
    phase: u32,
}

impl Pen {
    fn solid(thick: i64, colour: Rgb) -> Pen {
        Pen {
            thick,
            colour,
            dash: None,
            phase: 0,
        }
    }

    fn dashed(thick: i64, colour: Rgb, on: u32, off: u32) -> Pen {
        Pen {
            thick,
            colour,
            dash: Some((on, off)),
            phase: 0,
        }
    }

    /// Draws from `a` to `b` (pixels), clipped to `[0, w) × [0, h)`.
    fn line(&mut self, canvas: &mut Canvas, a: (f64, f64), b: (f64, f64), w: f64, h: f64) {
        self.segment(canvas, a, b, w, h, false);
    }

    /// Draws a path through `points` (pixels), clipped to `[0, w) × [0, h)`; `None` breaks it.
    /// Points closer than 2 px to the last one drawn are merged, so a densely sampled trajectory
    /// costs what its length in pixels costs and the dash pattern follows the distance drawn.
    fn path(
        &mut self,
        canvas: &mut Canvas,
        points: impl IntoIterator<Item = Option<(f64, f64)>>,
        w: f64,
        h: f64,
    ) {
        const MIN_STEP_PX: f64 = 2.0;
        let mut last: Option<(f64, f64)> = None;
        let mut pending: Option<(f64, f64)> = None;
        let mut continuing = false;
        let points = points
            .into_iter()
            .map(|p| p.filter(|p| p.0.is_finite() && p.1.is_finite()));
        for p in points.chain(std::iter::once(None)) {
            match (last, p) {
                (None, p) => {
                    last = p;
                    continuing = false;
                }
                (Some(a), Some(b)) => {
                    if (b.0 - a.0).hypot(b.1 - a.1) >= MIN_STEP_PX {
                        self.segment(canvas, a, b, w, h, continuing);
                        continuing = true;
                        last = Some(b);
                        pending = None;
                    } else {
                        pending = Some(b);
                    }
                }
                (Some(a), None) => {
                    if let Some(b) = pending.take() {
                        self.segment(canvas, a, b, w, h, continuing);
                    }
                    last = None;
                }
            }
        }
    }

    /// Draws from `a` to `b`; with `skip_first`, not the first pixel (the previous segment's
    /// last), so a path's dashes are not disturbed at the joints.
    fn segment(
        &mut self,
        canvas: &mut Canvas,
        a: (f64, f64),
        b: (f64, f64),
        w: f64,
        h: f64,
        skip_first: bool,
    ) {
        let Some((a, b)) = clip(a, b, w, h) else {
            return;
        };
        let mut skip = skip_first;
        let (mut x, mut y) = (a.0.floor() as i64, a.1.floor() as i64);
        let (x1, y1) = (b.0.floor() as i64, b.1.floor() as i64);
        let (dx, dy) = ((x1 - x).abs(), -(y1 - y).abs());
        let (sx, sy) = (if x < x1 { 1 } else { -1 }, if y < y1 { 1 } else { -1 });
        let mut err = dx + dy;
        let off = (self.thick - 1) / 2;
        loop {
            if !std::mem::take(&mut skip) {
                let on = match self.dash {
                    None => true,
                    Some((on, off)) => self.phase % (on + off) < on,
                };
                if on {
                    canvas.fill_rect(x - off, y - off, self.thick, self.thick, self.colour);
                }
                self.phase = self.phase.wrapping_add(1);
            }
            if x == x1 && y == y1 {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }
}

/// Liang–Barsky: the part of segment a–b inside `[0, w) × [0, h)`, if any.
fn clip(a: (f64, f64), b: (f64, f64), w: f64, h: f64) -> Option<((f64, f64), (f64, f64))> {
    if !(a.0.is_finite() && a.1.is_finite() && b.0.is_finite() && b.1.is_finite()) {
        return None;
    }
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (xmax, ymax) = (w - 1e-6, h - 1e-6);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [(-dx, a.0), (dx, xmax - a.0), (-dy, a.1), (dy, ymax - a.1)] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    (t0 <= t1).then_some((
        (a.0 + t0 * dx, a.1 + t0 * dy),
        (a.0 + t1 * dx, a.1 + t1 * dy),
    ))
}

/// The picture of channel `c` of `snap`, with walls and the robots' trajectories up to the
/// snapshot's time.
fn render_snapshot(rec: &Recording, snap: &Snapshot, c: usize) -> Canvas {
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
fn fmt_sig(v: f64) -> String {
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

// ---------------------------------------------------------------------------------------------
// A 5×7 pixel font: upper-case letters (lower case is drawn upper case), digits and a little
// punctuation. Each row is 5 bits, most significant on the left.

fn glyph(ch: char) -> [u8; 7] {
    match ch.to_ascii_uppercase() {
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        ',' => [0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08],
        '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        '+' => [0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00],
        '=' => [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00],
        '_' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F],
        ':' => [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00],
        '/' => [0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        _ => [0; 7],
    }
}

fn text_width(text: &str, scale: i64) -> i64 {
    text.chars().count() as i64 * 6 * scale - scale
}

/// Draws `text` with its top-left corner at (x, y), each font pixel `scale` pixels wide; with
/// `halo`, a 1-pixel black outline keeps it legible on any background.
/// Returns the width drawn.
fn draw_text(
    canvas: &mut Canvas,
    x: i64,
    y: i64,
    text: &str,
    scale: i64,
    colour: Rgb,
    halo: bool,
) -> i64 {
    let pixels = |f: &mut dyn FnMut(i64, i64)| {
        for (i, ch) in text.chars().enumerate() {
            let g = glyph(ch);
            let gx = x + i as i64 * 6 * scale;
            for (r, bits) in g.iter().enumerate() {
                for col in 0..5 {
                    if bits & (0x10 >> col) != 0 {
                        f(gx + col * scale, y + r as i64 * scale);
                    }
                }
            }
        }
    };
    if halo {
        pixels(&mut |px, py| canvas.fill_rect(px - 1, py - 1, scale + 2, scale + 2, OUTLINE_RGB));
    }
    pixels(&mut |px, py| canvas.fill_rect(px, py, scale, scale, colour));
    text_width(text, scale)
}

fn write_png(path: &Path, canvas: &Canvas) -> Result<(), ReportError> {
    let png_err = |source| ReportError::Png {
        path: path.to_path_buf(),
        source,
    };
    let file = File::create(path).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut out = BufWriter::new(file);
    {
        let mut encoder = png::Encoder::new(&mut out, canvas.width as u32, canvas.height as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_compression(png::Compression::Fast);
        let mut writer = encoder.write_header().map_err(png_err)?;
        writer.write_image_data(&canvas.rgb).map_err(png_err)?;
        writer.finish().map_err(png_err)?;
    }
    out.flush().map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })
}

// ---------------------------------------------------------------------------------------------
// Node-graph runs (seed 001 Figs. 4b, 5 and 7): the graph with its final link values

/// Writes a picture of a node-graph run: regions (green while held, grey once served, labelled
/// with their holders), links coloured by their final value (red anti-pheromone, blue
/// pheromone, dashed black −∞), terminal nodes red, the others green, the dock orange.
pub fn write_graph_png(
    path: &Path,
    state: &crate::graph::GraphState,
    report: &crate::graph::run::RunReport,
    dock: usize,
) -> Result<(), ReportError> {
    let nodes = state.graph.nodes();
    let regions = state.regions.regions();
    // World bounds: nodes and region boxes, with a margin.
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    let mut grow = |x: f64, y: f64| {
        x0 = x0.min(x);
        y0 = y0.min(y);
        x1 = x1.max(x);
        y1 = y1.max(y);
    };
    for n in nodes {
        grow(n.x_m as f64, n.y_m as f64);
    }
    for r in regions {
        let [a, b, c, d] = r.shape.bbox_m();
        grow(a as f64, b as f64);
        grow(c as f64, d as f64);
    }
    if x0 > x1 {
        (x0, y0, x1, y1) = (0.0, 0.0, 1.0, 1.0);
    }
    let margin_m = 1.0;
    let span_m = (x1 - x0 + 2.0 * margin_m).max(y1 - y0 + 2.0 * margin_m);
    let px_per_m = (1200.0 / span_m).clamp(10.0, 120.0);
    let w = ((x1 - x0 + 2.0 * margin_m) * px_per_m).ceil() as usize;
    let h = ((y1 - y0 + 2.0 * margin_m) * px_per_m).ceil() as usize;
    let (wf, hf) = (w as f64, h as f64);
    let to_px = |x: f64, y: f64| {
        (
            (x - x0 + margin_m) * px_per_m,
            hf - (y - y0 + margin_m) * px_per_m,
        )
    };
    let mut canvas = Canvas::new(w, h, [250, 250, 250]);
    let label = |c: &mut Canvas, x: f64, y: f64, text: &str| {
        draw_text(c, x as i64, y as i64, text, 2, TEXT_RGB, true);
    };
    for (r, area) in regions.iter().zip(&report.areas) {
        let [a, b, c, d] = r.shape.bbox_m();
        let (px0, py1) = to_px(a as f64, b as f64);
        let (px1, py0) = to_px(c as f64, d as f64);
        let fill = if !area.held_by.is_empty() {
            [170, 220, 170]
        } else if area.served {
            [205, 205, 205]
        } else {
            [230, 240, 200]
        };
        canvas.fill_rect(
            px0 as i64,
            py0 as i64,
            (px1 - px0) as i64,
            (py1 - py0) as i64,
            fill,
        );
        let holders: Vec<String> = area.held_by.iter().map(|i| format!("R{i}")).collect();
        let text = if holders.is_empty() {
            r.name.clone()
        } else {
            format!("{} {}", r.name, holders.join(" "))
        };
        label(&mut canvas, px0 + 4.0, py0 + 4.0, &text);
    }
    let value_of = |node: &str, dir: crate::graph::Dir| -> Option<f32> {
        let row = report.links.iter().find(|l| l.node == node)?;
        let text = match dir {
            crate::graph::Dir::Up => &row.up,
            crate::graph::Dir::Down => &row.down,
            crate::graph::Dir::Left => &row.left,
            crate::graph::Dir::Right => &row.right,
        };
        match text.as_str() {
            "-inf" => Some(f32::NEG_INFINITY),
            t => t.parse().ok(),
        }
    };
    let max_abs = report
        .links
        .iter()
        .flat_map(|l| [&l.up, &l.down, &l.left, &l.right])
        .filter_map(|t| t.parse::<f32>().ok())
        .filter(|v| v.is_finite())
        .fold(1.0f32, |m, v| m.max(v.abs()));
    for n in nodes {
        for (dir, link) in n.links() {
            let to = &nodes[link.to];
            let a = to_px(n.x_m as f64, n.y_m as f64);
            let b = to_px(to.x_m as f64, to.y_m as f64);
            // Each direction draws its half of the passage, so both values show.
            let mid = ((a.0 + b.0) / 2.0, (a.1 + b.1) / 2.0);
            let v = value_of(&n.name, dir).unwrap_or(link.value);
            let mut pen = if v == f32::NEG_INFINITY {
                Pen::dashed(4, [0, 0, 0], 8, 6)
            } else {
                let t = (v.abs() / max_abs).clamp(0.0, 1.0) as f64;
                let mix = |base: f64, full: f64| (base + (full - base) * t).round() as u8;
                let colour = if v < 0.0 {
                    [mix(160.0, 215.0), mix(160.0, 25.0), mix(160.0, 25.0)]
                } else if v > 0.0 {
                    [mix(160.0, 30.0), mix(160.0, 90.0), mix(160.0, 220.0)]
                } else {
                    [160, 160, 160]
                };
                Pen::solid(4, colour)
            };
            pen.line(&mut canvas, a, mid, wf, hf);
        }
    }
    for (i, n) in nodes.iter().enumerate() {
        let (x, y) = to_px(n.x_m as f64, n.y_m as f64);
        let colour = if i == dock {
            [245, 150, 30]
        } else if n.terminal {
            [210, 40, 40]
        } else {
            [40, 160, 70]
        };
        canvas.disc(x as i64, y as i64, 7, colour);
        label(&mut canvas, x + 9.0, y + 6.0, &n.name);
    }
    let title = format!(
        "{} {} {} robots: {}",
        report.scenario,
        report.strategy.name(),
        report.robots,
        report
            .finish_s
            .map_or("goal not reached".to_string(), |t| format!("{t:.1} s")),
    );
    label(&mut canvas, 6.0, 6.0, &title);
    if let Some(dir) = path.parent() {
        fs::create_dir_all(dir).map_err(|source| ReportError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
    }
    write_png(path, &canvas)
}

#[cfg(test)]
mod tests {
    use std::io::BufReader;
    use std::sync::atomic::{AtomicU32, Ordering};

    use super::*;
    use crate::messages::FollowerState;
    use crate::sim::record::ProbeReading;

    /// A directory under the system temp dir, unique per test and process, removed on drop.
    struct TempDir(PathBuf);

    impl TempDir {
        fn new(tag: &str) -> TempDir {
            static COUNTER: AtomicU32 = AtomicU32::new(0);
            let nanos = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.subsec_nanos())
                .unwrap_or(0);
            let n = COUNTER.fetch_add(1, Ordering::Relaxed);
            TempDir(std::env::temp_dir().join(format!(
                "pheromone-report-{tag}-{}-{nanos}-{n}",
                std::process::id()
            )))
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = fs::remove_dir_all(&self.0);
        }
    }

    fn sample(t_s: f64, x: f64, y: f64) -> RobotSample {
        RobotSample {
            t_s,
            true_pose: [x, y, 0.0],
            est_pose: None,
            est_sigma_m: None,
            v_mps: 0.5,
            omega_radps: 0.0,
            state: None,
            sensed_level: None,
        }
    }

    /// 100 × 50 cells of 0.1 m, channel "trail", zero except `(80, 40)` = 7 (the max). Robot 0
    /// drives along y = 1 m from x = 1 to 6 m without estimates; robot 1 drives along y = 3 m
    /// with estimates 0.5 m below its true path.
    fn scene() -> Recording {
        let (w, h) = (100u32, 50u32);
        let mut planes = vec![0.0f32; (w * h) as usize];
        planes[(40 * w + 80) as usize] = 7.0;
        let mut rec = Recording::default();
        rec.snapshots.push(Snapshot {
            t_s: 10.0,
            width: w,
            height: h,
            cell_size_m: 0.1,
            channels: vec!["trail".into()],
            planes,
        });
        rec.robots.insert(
            0,
            (0..=10)
                .map(|i| sample(i as f64, 1.0 + 0.5 * i as f64, 1.0))
                .collect(),
        );
        rec.robots.insert(
            1,
            (0..=10)
                .map(|i| {
                    let mut s = sample(i as f64, 1.0 + 0.5 * i as f64, 3.0);
                    s.est_pose = Some([1.0 + 0.5 * i as f64, 2.5, 0.0]);
                    s
                })
                .collect(),
        );
        rec
    }

    fn decode(path: &Path) -> (u32, u32, Vec<u8>) {
        let file = File::open(path).unwrap();
        let mut reader = png::Decoder::new(BufReader::new(file)).read_info().unwrap();
        let mut buf = vec![0u8; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!(info.color_type, png::ColorType::Rgb);
        assert_eq!(info.bit_depth, png::BitDepth::Eight);
        buf.truncate(info.buffer_size());
        (info.width, info.height, buf)
    }

    fn pixel(img: &(u32, u32, Vec<u8>), x: usize, y: usize) -> Rgb {
        let i = (y * img.0 as usize + x) * 3;
        [img.2[i], img.2[i + 1], img.2[i + 2]]
    }

    #[test]
    fn robot_csv_has_a_row_per_sample_and_empty_cells_for_none() {
        let tmp = TempDir::new("csv");
        let mut rec = Recording::default();
        let mut full = sample(0.5, 1.25, -2.0);
        full.est_pose = Some([1.0, -2.5, 0.25]);
        full.est_sigma_m = Some(0.125);
        full.state = Some(FollowerState::TrailAbandoned);
        full.sensed_level = Some(3.5);
        rec.robots.insert(
            3,
            vec![sample(0.0, 1.0, -2.0), full, sample(1.0, 1.5, -2.0)],
        );
        rec.probes.push(ProbeReading {
            t_s: 2.0,
            x: 1.5,
            y: 0.5,
            channel: 0,
            value: 0.25,
        });
        let metrics = serde_json::json!({"robots": 1, "distance_m": 0.5});
        let written = write_outputs(&tmp.0, &rec, &metrics).unwrap();
        let names: Vec<String> = written
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["metrics.json", "robot_3.csv", "probes.csv"]);

        let text = fs::read_to_string(tmp.0.join("robot_3.csv")).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 1 + 3);
        assert_eq!(lines[0], ROBOT_CSV_HEADER);
        let columns = lines[0].split(',').count();
        assert_eq!(columns, 12);
        for line in &lines[1..] {
            assert_eq!(line.split(',').count(), columns, "{line}");
        }
        assert_eq!(lines[1], "0,1,-2,0,,,,,0.5,0,,");
        assert_eq!(
            lines[2],
            "0.5,1.25,-2,0,1,-2.5,0.25,0.125,0.5,0,trail_abandoned,3.5"
        );

        let probes = fs::read_to_string(tmp.0.join("probes.csv")).unwrap();
        assert_eq!(probes, format!("{PROBES_CSV_HEADER}\n2,1.5,0.5,0,0.25\n"));
        let back: serde_json::Value =
            serde_json::from_str(&fs::read_to_string(tmp.0.join("metrics.json")).unwrap()).unwrap();
        assert_eq!(back, metrics);
    }

    #[test]
    fn png_has_the_expected_size_trajectories_and_top_of_the_colour_map() {
        let tmp = TempDir::new("png");
        let rec = scene();
        let written = write_outputs(&tmp.0, &rec, &serde_json::json!({})).unwrap();
        let final_png = tmp.0.join("field_final.png");
        let snap_png = tmp.0.join("field_trail_t010.0s.png");
        assert!(written.contains(&snap_png), "{written:?}");
        assert!(written.contains(&final_png), "{written:?}");
        assert_eq!(fs::read(&snap_png).unwrap(), fs::read(&final_png).unwrap());

        let img = decode(&snap_png);
        // 100 cells × 8 px wide; 50 cells × 8 px high plus the strip.
        assert_eq!((img.0, img.1), (800, 400 + STRIP_HEIGHT_PX as u32));
        let layout = Layout::for_grid(100, 50, 0.1);
        assert_eq!(layout.scale, 8);

        // Robot 0's true trajectory (y = 1 m) passes through x = 3 m: pixel (240, 320).
        let (x, y) = layout.pixel_from_world(3.0, 1.0);
        assert_eq!((x, y), (240.0, 320.0));
        assert_eq!(pixel(&img, 240, 320), ROBOT_RGB[0]);
        // Robot 1's estimate (y = 2.5 m, row 200) is dashed in a lighter shade of its colour.
        let est: Vec<Rgb> = (100..400).map(|x| pixel(&img, x, 200)).collect();
        assert!(est.contains(&lighter(ROBOT_RGB[1])));
        assert!(est.iter().any(|&c| c == VIRIDIS[0]), "dashes have gaps");
        assert_eq!(
            pixel(&img, 240, 160),
            ROBOT_RGB[1],
            "true path of robot 1 (y = 3 m)"
        );

        // The max cell (80, 40) is drawn at the top of the colour map, y up: block row
        // 50 − 1 − 40 = 9 from the top, i.e. picture rows 72..80, columns 640..648.
        assert_eq!(pixel(&img, 644, 76), VIRIDIS[9]);
        assert_eq!(pixel(&img, 644, 84), VIRIDIS[0]);
        assert_eq!(pixel(&img, 644, 400 - 76), VIRIDIS[0]);
        // A zero cell away from every line is the bottom of the map.
        assert_eq!(pixel(&img, 50, 50), VIRIDIS[0]);
    }

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
    fn nan_cells_get_their_own_colour_without_panicking() {
        let tmp = TempDir::new("nan");
        let mut rec = scene();
        let w = rec.snapshots[0].width as usize;
        rec.snapshots[0].planes[10 * w + 10] = f32::NAN;
        rec.snapshots[0].planes[11 * w + 10] = f32::INFINITY;
        let written = write_outputs(&tmp.0, &rec, &serde_json::json!({})).unwrap();
        assert!(written.iter().any(|p| p.ends_with("field_final.png")));
        let img = decode(&tmp.0.join("field_final.png"));
        // Cell (10, 10): columns 80..88, rows (49 − 10)·8 = 312..320.
        assert_eq!(pixel(&img, 84, 316), NAN_RGB);
        assert!(!VIRIDIS.contains(&NAN_RGB) && !ROBOT_RGB.contains(&NAN_RGB));
        // NaN and ∞ do not spoil the scale: the finite max is still the top of the map.
        assert_eq!(pixel(&img, 644, 76), VIRIDIS[9]);
        assert_eq!(pixel(&img, 84, 308), VIRIDIS[9], "+inf clamps to the top");
    }

    #[test]
    fn signed_planes_use_a_diverging_map_centred_on_zero() {
        let map = ColourMap::for_plane(&[-2.0, 0.0, 1.0, f32::NAN]);
        assert!(map.signed);
        assert_eq!(map.max, 2.0);
        assert_eq!(map.colour(0.0), DIVERGING[2]);
        assert_eq!(map.colour(-2.0), DIVERGING[0]);
        assert_eq!(map.colour(2.0), DIVERGING[4]);
        assert_eq!(map.colour(-1.0), DIVERGING[1]);
        let unsigned = ColourMap::for_plane(&[0.0, 0.5, 4.0]);
        assert!(!unsigned.signed);
        assert_eq!(unsigned.colour(4.0), VIRIDIS[9]);
        assert_eq!(unsigned.colour(0.0), VIRIDIS[0]);
        // An empty plane is all bottom colour, not a division by zero.
        let empty = ColourMap::for_plane(&[0.0; 4]);
        assert_eq!(empty.colour(0.0), VIRIDIS[0]);
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

    #[test]
    fn file_names_and_bad_snapshots() {
        assert_eq!(snapshot_file_name("trail", 12.0), "field_trail_t012.0s.png");
        assert_eq!(
            snapshot_file_name("anti trail", 3.26),
            "field_anti_trail_t003.3s.png"
        );
        assert_eq!(snapshot_file_name("x", 1234.5), "field_x_t1234.5s.png");
        let mut rec = scene();
        rec.snapshots[0].planes.pop();
        let tmp = TempDir::new("bad");
        let err = write_outputs(&tmp.0, &rec, &serde_json::json!({})).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("t = 10 s") && msg.contains("4999 values"),
            "{msg}"
        );
        assert!(!tmp.0.exists(), "nothing written for a bad recording");
        assert_eq!(fmt_sig(35.26), "35.3");
        assert_eq!(fmt_sig(0.012345), "0.0123");
        assert_eq!(fmt_sig(1.5e-5), "1.50e-5");
    }

    #[test]
    fn io_errors_name_the_path() {
        let tmp = TempDir::new("io");
        fs::create_dir_all(&tmp.0).unwrap();
        let blocker = tmp.0.join("file");
        fs::write(&blocker, b"not a directory").unwrap();
        let dir = blocker.join("out");
        let err = write_outputs(&dir, &scene(), &serde_json::json!({})).unwrap_err();
        assert!(matches!(err, ReportError::Io { .. }), "{err:?}");
        assert!(
            err.to_string().contains(&dir.display().to_string()),
            "{err}"
        );
    }
}
