//! The raster drawing the pictures are made of: the palette, the colour maps (viridis and a
//! diverging map), an RGB canvas with filled shapes, and line pens (Bresenham lines, dashes,
//! Liang–Barsky clipping).

pub(super) type Rgb = [u8; 3];

/// Colour of a cell whose value is NaN (never expected; shown rather than hidden).
pub(super) const NAN_RGB: Rgb = [255, 0, 255];
/// Walls.
pub(super) const WALL_RGB: Rgb = [215, 215, 215];
/// Background of the strip under the field, and its text.
pub(super) const STRIP_RGB: Rgb = [24, 24, 28];
pub(super) const TEXT_RGB: Rgb = [235, 235, 235];
pub(super) const OUTLINE_RGB: Rgb = [0, 0, 0];
/// One colour per robot (by id, cycling), chosen to stand out on both colour maps.
pub(super) const ROBOT_RGB: [Rgb; 5] = [
    [240, 40, 40],
    [0, 190, 255],
    [255, 150, 0],
    [255, 110, 200],
    [170, 130, 255],
];

/// viridis at 10 evenly spaced stops (matplotlib).
pub(super) const VIRIDIS: [Rgb; 10] = [
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

pub(super) fn robot_rgb(id: u32) -> Rgb {
    ROBOT_RGB[id as usize % ROBOT_RGB.len()]
}

/// The lighter shade used for the estimated trajectory.
pub(super) fn lighter(c: Rgb) -> Rgb {
    c.map(|v| v + (255 - v) / 2)
}

/// A colour map sampled into a table of `2·HALF + 1` (signed) or `HALF + 1` (unsigned) entries.
pub(super) struct ColourMap {
    table: Vec<Rgb>,
    pub(super) signed: bool,
    /// The value mapped to the top of the map (the plane's max, or max |v| if signed).
    pub(super) max: f32,
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
    pub(super) fn for_plane(plane: &[f32]) -> ColourMap {
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

    pub(super) fn colour(&self, v: f32) -> Rgb {
        if v.is_nan() {
            return NAN_RGB;
        }
        let scale = if self.max > 0.0 { self.max } else { 1.0 };
        let u = (v / scale).clamp(if self.signed { -1.0 } else { 0.0 }, 1.0);
        let i = (u * HALF as f32).round() as isize + if self.signed { HALF as isize } else { 0 };
        self.table[i as usize]
    }

    /// The colour at fraction `t` ∈ [0, 1] of the bar (bottom … top of the map).
    pub(super) fn bar_colour(&self, t: f64) -> Rgb {
        let n = self.table.len() - 1;
        self.table[((t.clamp(0.0, 1.0) * n as f64).round() as usize).min(n)]
    }
}

/// An RGB picture; drawing outside it (or outside the clip height) is ignored.
pub(super) struct Canvas {
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) rgb: Vec<u8>,
}

impl Canvas {
    pub(super) fn new(width: usize, height: usize, fill: Rgb) -> Canvas {
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
    pub(super) fn get(&self, x: usize, y: usize) -> Rgb {
        let i = (y * self.width + x) * 3;
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    pub(super) fn fill_rect(&mut self, x: i64, y: i64, w: i64, h: i64, c: Rgb) {
        for yy in y..y + h {
            for xx in x..x + w {
                self.put(xx, yy, c);
            }
        }
    }

    pub(super) fn disc(&mut self, cx: i64, cy: i64, r: i64, c: Rgb) {
        for dy in -r..=r {
            for dx in -r..=r {
                if dx * dx + dy * dy <= r * r + r {
                    self.put(cx + dx, cy + dy, c);
                }
            }
        }
    }

    pub(super) fn ring(&mut self, cx: i64, cy: i64, r_in: i64, r_out: i64, c: Rgb) {
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
pub(super) struct Pen {
    thick: i64,
    colour: Rgb,
    dash: Option<(u32, u32)>,
    phase: u32,
}

impl Pen {
    pub(super) fn solid(thick: i64, colour: Rgb) -> Pen {
        Pen {
            thick,
            colour,
            dash: None,
            phase: 0,
        }
    }

    pub(super) fn dashed(thick: i64, colour: Rgb, on: u32, off: u32) -> Pen {
        Pen {
            thick,
            colour,
            dash: Some((on, off)),
            phase: 0,
        }
    }

    /// Draws from `a` to `b` (pixels), clipped to `[0, w) × [0, h)`.
    pub(super) fn line(
        &mut self,
        canvas: &mut Canvas,
        a: (f64, f64),
        b: (f64, f64),
        w: f64,
        h: f64,
    ) {
        self.segment(canvas, a, b, w, h, false);
    }

    /// Draws a path through `points` (pixels), clipped to `[0, w) × [0, h)`; `None` breaks it.
    /// Points closer than 2 px to the last one drawn are merged, so a densely sampled trajectory
    /// costs what its length in pixels costs and the dash pattern follows the distance drawn.
    pub(super) fn path(
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
