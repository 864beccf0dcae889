//! What every picture shares: the embedded font, the palette, the colour maps of the heat maps
//! (viridis for unsigned channels, a dark-centred diverging map for signed ones), the picture
//! buffer and the one place a plotters drawing area is made over it.

use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::{BitMapBackend, DrawingArea, IntoDrawingArea, RGBColor};

pub(super) type Rgb = [u8; 3];

/// The family name the embedded font is registered under.
pub(super) const FONT: &str = "sans-serif";
/// DejaVu Sans (Bitstream Vera licence, `publishers/assets/DejaVuSans-LICENSE.txt`): the
/// pictures look the same on every machine, whatever fonts it has.
static FONT_TTF: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

/// Colour of a cell whose value is NaN (never expected; shown rather than hidden).
pub(super) const NAN_RGB: Rgb = [255, 0, 255];
/// Walls.
pub(super) const WALL_RGB: Rgb = [215, 215, 215];
/// Background of the strip under the field, and its text.
pub(super) const STRIP_RGB: Rgb = [24, 24, 28];
pub(super) const TEXT_RGB: Rgb = [235, 235, 235];
pub(super) const OUTLINE_RGB: Rgb = [0, 0, 0];
/// The first robots' colours (ids 0–4), chosen to stand out on both colour maps and on white;
/// [`robot_rgb`] continues the palette for any id.
pub(super) const ROBOT_RGB: [Rgb; 5] = [
    [240, 40, 40],
    [0, 170, 240],
    [255, 150, 0],
    [230, 90, 190],
    [150, 110, 255],
];
/// Line colours of the charts (on white), cycling.
pub(super) const SERIES_RGB: [Rgb; 8] = [
    [31, 119, 180],
    [214, 39, 40],
    [44, 160, 44],
    [255, 127, 14],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [23, 190, 207],
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
pub(super) const DIVERGING: [Rgb; 5] = [
    [150, 220, 255],
    [40, 120, 200],
    [20, 20, 28],
    [200, 90, 30],
    [255, 225, 120],
];

/// Robot `id`'s colour, the same in every picture of a run (heat maps, charts, maps) since it
/// depends on the id alone. Ids 0–4 get [`ROBOT_RGB`]; ids up to [`PALETTE_LEN`] − 1 continue
/// a palette built greedily, each colour the candidate farthest (CIELAB ΔE) from every earlier
/// one and from the colours the pictures reserve (NaN, walls, black, white); any larger id gets
/// a golden-ratio hue step. Robots 0..64 are at least ΔE 18 apart (the tests check).
pub(super) fn robot_rgb(id: u32) -> Rgb {
    match robot_palette().get(id as usize) {
        Some(&c) => c,
        None => {
            let h = (f64::from(id) * 0.618_033_988_749_895).fract();
            let (s, v) = [(0.9, 0.95), (0.6, 1.0), (1.0, 0.7)][id as usize % 3];
            hsv_rgb(h, s, v)
        }
    }
}

/// Robots with a palette colour (ids 0..PALETTE_LEN).
pub(super) const PALETTE_LEN: usize = 256;

fn robot_palette() -> &'static [Rgb] {
    static PALETTE: OnceLock<Vec<Rgb>> = OnceLock::new();
    PALETTE.get_or_init(|| {
        let mut candidates = Vec::new();
        for h in (0..360).step_by(5) {
            for s in [0.55, 0.75, 1.0] {
                for v in [0.6, 0.8, 1.0] {
                    candidates.push(hsv_rgb(f64::from(h) / 360.0, s, v));
                }
            }
        }
        let cand_lab: Vec<[f64; 3]> = candidates.iter().map(|&c| lab(c)).collect();
        // Each candidate's distance to the nearest colour taken (or reserved) so far.
        let mut nearest: Vec<f64> = vec![f64::INFINITY; candidates.len()];
        let take = |c: Rgb, nearest: &mut Vec<f64>| {
            let l = lab(c);
            for (n, cl) in nearest.iter_mut().zip(&cand_lab) {
                *n = n.min(delta_e(l, *cl));
            }
        };
        for c in [NAN_RGB, WALL_RGB, STRIP_RGB, [255, 255, 255]] {
            take(c, &mut nearest);
        }
        let mut palette: Vec<Rgb> = ROBOT_RGB.to_vec();
        for &c in &ROBOT_RGB {
            take(c, &mut nearest);
        }
        while palette.len() < PALETTE_LEN {
            // The first farthest candidate: deterministic.
            let (i, _) =
                nearest
                    .iter()
                    .enumerate()
                    .fold((0, f64::NEG_INFINITY), |best, (i, &d)| {
                        if d > best.1 {
                            (i, d)
                        } else {
                            best
                        }
                    });
            palette.push(candidates[i]);
            take(candidates[i], &mut nearest);
        }
        palette
    })
}

/// HSV (each in [0, 1]) to 8-bit RGB.
fn hsv_rgb(h: f64, s: f64, v: f64) -> Rgb {
    let h6 = (h.rem_euclid(1.0)) * 6.0;
    let f = h6 - h6.floor();
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    let (r, g, b) = match h6.floor() as u32 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    [r, g, b].map(|u| (u * 255.0).round().clamp(0.0, 255.0) as u8)
}

/// CIELAB (D65) of an sRGB colour.
pub(super) fn lab(c: Rgb) -> [f64; 3] {
    let lin = |u: u8| {
        let u = f64::from(u) / 255.0;
        if u <= 0.04045 {
            u / 12.92
        } else {
            ((u + 0.055) / 1.055).powf(2.4)
        }
    };
    let [r, g, b] = c.map(lin);
    let x = (0.4124 * r + 0.3576 * g + 0.1805 * b) / 0.95047;
    let y = 0.2126 * r + 0.7152 * g + 0.0722 * b;
    let z = (0.0193 * r + 0.1192 * g + 0.9505 * b) / 1.08883;
    let f = |t: f64| {
        if t > 216.0 / 24389.0 {
            t.cbrt()
        } else {
            (24389.0 / 27.0 * t + 16.0) / 116.0
        }
    };
    let (fx, fy, fz) = (f(x), f(y), f(z));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// CIE76 colour difference.
pub(super) fn delta_e(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

pub(super) fn series_rgb(i: usize) -> Rgb {
    SERIES_RGB[i % SERIES_RGB.len()]
}

/// The lighter shade used for the estimated trajectory.
pub(super) fn lighter(c: Rgb) -> Rgb {
    c.map(|v| v + (255 - v) / 2)
}

pub(super) fn colour(c: Rgb) -> RGBColor {
    RGBColor(c[0], c[1], c[2])
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
        Self::for_planes(std::iter::once(plane))
    }

    /// One scale for several planes (a channel's snapshots over a run), as [`Self::for_plane`]
    /// of all their values.
    pub(super) fn for_planes<'a>(planes: impl IntoIterator<Item = &'a [f32]>) -> ColourMap {
        let (mut lo, mut hi) = (0.0f32, 0.0f32);
        for &v in planes.into_iter().flatten() {
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

    /// The values at the ends of the bar: 0 … max, or −max … max.
    pub(super) fn range(&self) -> (f64, f64) {
        let max = if self.max > 0.0 { self.max as f64 } else { 1.0 };
        (if self.signed { -max } else { 0.0 }, max)
    }
}

/// An 8-bit RGB picture, row-major, row 0 at the top.
pub(super) struct Picture {
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) rgb: Vec<u8>,
}

impl Picture {
    pub(super) fn new(width: u32, height: u32, fill: Rgb) -> Picture {
        let n = width as usize * height as usize;
        let mut rgb = Vec::with_capacity(n * 3);
        for _ in 0..n {
            rgb.extend_from_slice(&fill);
        }
        Picture { width, height, rgb }
    }

    #[cfg(test)]
    pub(super) fn get(&self, x: usize, y: usize) -> Rgb {
        let i = (y * self.width as usize + x) * 3;
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    /// A plotters drawing area over the picture (the font registered first); call `present`
    /// on it when done.
    pub(super) fn area(&mut self) -> Result<DrawingArea<BitMapBackend<'_>, Shift>, String> {
        register_font()?;
        Ok(
            BitMapBackend::with_buffer(&mut self.rgb, (self.width, self.height))
                .into_drawing_area(),
        )
    }

    /// Draws on the picture with plotters (the font registered first); the error is plotters'
    /// message.
    pub(super) fn draw<F>(&mut self, f: F) -> Result<(), String>
    where
        F: FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>) -> Result<(), String>,
    {
        register_font()?;
        let root = BitMapBackend::with_buffer(&mut self.rgb, (self.width, self.height))
            .into_drawing_area();
        f(&root)?;
        root.present().map_err(|e| e.to_string())
    }
}

/// Registers the embedded font once per process.
fn register_font() -> Result<(), String> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        plotters::style::register_font(FONT, plotters::style::FontStyle::Normal, FONT_TTF)
            .map_err(|_| "the embedded DejaVu Sans font does not load".to_string())
    })
    .clone()
}

/// Maps any plotters error to its message.
pub(super) fn msg<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use plotters::style::IntoFont;

    #[test]
    fn signed_planes_use_a_diverging_map_centred_on_zero() {
        let map = ColourMap::for_plane(&[-2.0, 0.0, 1.0, f32::NAN]);
        assert!(map.signed);
        assert_eq!(map.max, 2.0);
        assert_eq!(map.range(), (-2.0, 2.0));
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
        assert_eq!(empty.range(), (0.0, 1.0));
    }

    #[test]
    fn robot_colours_are_distinct_for_any_team_up_to_64_and_depend_on_the_id_alone() {
        for n in 1..=64u32 {
            let mut min = f64::INFINITY;
            for a in 0..n {
                for b in 0..a {
                    min = min.min(delta_e(lab(robot_rgb(a)), lab(robot_rgb(b))));
                }
            }
            let floor = if n <= 16 { 35.0 } else { 18.0 };
            assert!(
                min >= floor,
                "{n} robots: two colours only ΔE {min:.1} apart"
            );
            // Never the NaN colour, nor the walls'.
            let c = robot_rgb(n - 1);
            assert!(delta_e(lab(c), lab(NAN_RGB)) > 15.0, "{n}: {c:?}");
            assert!(delta_e(lab(c), lab(WALL_RGB)) > 15.0, "{n}: {c:?}");
        }
        // The first five are the fixed palette; a robot's colour is the same whatever else is
        // drawn (no state: the same id gives the same colour in any order).
        assert_eq!(robot_rgb(0), ROBOT_RGB[0]);
        assert_eq!(robot_rgb(4), ROBOT_RGB[4]);
        let later: Vec<Rgb> = (0..70).rev().map(robot_rgb).collect();
        let earlier: Vec<Rgb> = (0..70).map(robot_rgb).collect();
        assert_eq!(later.into_iter().rev().collect::<Vec<_>>(), earlier);
        // Beyond the palette: still defined, and not all one colour.
        let big = PALETTE_LEN as u32;
        assert_ne!(robot_rgb(big), robot_rgb(big + 1));
        assert_ne!(robot_rgb(big), robot_rgb(big - 1));
    }

    #[test]
    fn text_is_drawn_with_the_embedded_font() {
        let mut pic = Picture::new(120, 40, [255, 255, 255]);
        pic.draw(|root| {
            root.draw_text(
                "Trail 12 m",
                &(FONT, 20).into_font().color(&colour([0, 0, 0])),
                (4, 8),
            )
            .map_err(msg)
        })
        .unwrap();
        let dark = pic.rgb.chunks(3).filter(|p| p[0] < 128).count();
        let grey = pic
            .rgb
            .chunks(3)
            .filter(|p| p[0] > 20 && p[0] < 235)
            .count();
        assert!(dark > 100, "{dark} dark pixels: no text drawn");
        assert!(grey > 50, "{grey} partly covered pixels: not anti-aliased");
    }
}
