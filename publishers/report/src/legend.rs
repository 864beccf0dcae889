//! A chart's legend drawn by hand in a band under the chart, outside its plotting area, so that
//! it covers no data (plotters' own series labels are drawn, and clipped, inside the plotting
//! area). The entries run left to right in columns as wide as the widest, as many columns as
//! the picture's width holds, in a box with a light border.

use plotters::element::DashedPathElement;
use plotters::prelude::*;

use super::heatmap::text_width;
use super::plots::text;
use super::style::{colour, msg, Picture, Rgb};

/// What an entry's sample looks like.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Sample {
    /// A line in `rgb`: solid through a filled dot (`solid`), or two dashes around a ring.
    Line { solid: bool, rgb: Rgb },
    /// A black cross (a paper's value).
    Cross,
    /// A dotted black line (a paper's value across the chart).
    Dotted,
}

/// The legend box's border.
pub(super) const BORDER_RGB: Rgb = [150, 150, 170];
/// A row's height, the sample's width and the gap after it, the padding inside the box and
/// around it (px).
const ROW_PX: i32 = 22;
pub(super) const SAMPLE_PX: i32 = 24;
const GAP_PX: i32 = 8;
const PAD_PX: i32 = 10;
const OUTER_PX: i32 = 12;

/// Each entry's place in a band `width_px` wide, (x, y) of its sample's left end relative to
/// the band's top-left corner, and the band's height.
pub(super) fn layout(labels: &[String], width_px: i32) -> (Vec<(i32, i32)>, i32) {
    if labels.is_empty() {
        return (Vec::new(), 0);
    }
    let col_w =
        labels.iter().map(|l| text_width(l)).max().unwrap_or(0) + SAMPLE_PX + 2 * GAP_PX + 16;
    let inner = width_px - 2 * (OUTER_PX + PAD_PX);
    let cols = (inner / col_w.max(1)).clamp(1, labels.len() as i32);
    let rows = (labels.len() as i32 + cols - 1) / cols;
    let at = (0..labels.len() as i32)
        .map(|i| {
            (
                OUTER_PX + PAD_PX + (i % cols) * col_w,
                PAD_PX + (i / cols) * ROW_PX + ROW_PX / 2,
            )
        })
        .collect();
    (at, rows * ROW_PX + 2 * PAD_PX + OUTER_PX)
}

/// `top` with a band under it holding the legend of `entries`; returns the picture and the
/// legend box (x0, y0, x1, y1) in its pixels.
pub(super) fn with_legend(
    top: &Picture,
    entries: &[(Sample, String)],
) -> Result<(Picture, [i32; 4]), String> {
    let labels: Vec<String> = entries.iter().map(|(_, l)| l.clone()).collect();
    let (at, band_h) = layout(&labels, top.width as i32);
    let mut pic = Picture::new(top.width, top.height + band_h as u32, [255, 255, 255]);
    pic.rgb[..top.rgb.len()].copy_from_slice(&top.rgb);
    let y0 = top.height as i32;
    let x1 = at
        .iter()
        .zip(&labels)
        .map(|(&(x, _), l)| x + SAMPLE_PX + GAP_PX + text_width(l))
        .max()
        .unwrap_or(OUTER_PX)
        + PAD_PX;
    let boxed = [OUTER_PX, y0, x1, y0 + band_h - OUTER_PX];
    if entries.is_empty() {
        return Ok((pic, boxed));
    }
    pic.draw(|root| {
        root.draw(&Rectangle::new(
            [(boxed[0], boxed[1]), (boxed[2], boxed[3])],
            colour(BORDER_RGB),
        ))
        .map_err(msg)?;
        for ((sample, label), &(x, y)) in entries.iter().zip(&at) {
            draw_sample(root, *sample, (x, y0 + y))?;
            root.draw_text(label, &text(14), (x + SAMPLE_PX + GAP_PX, y0 + y - 8))
                .map_err(msg)?;
        }
        Ok(())
    })?;
    Ok((pic, boxed))
}

/// An entry's sample, its left end at `(x, y)`, [`SAMPLE_PX`] wide.
pub(super) fn draw_sample(
    root: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    sample: Sample,
    (x, y): (i32, i32),
) -> Result<(), String> {
    let black = colour([0, 0, 0]).stroke_width(2);
    match sample {
        Sample::Line { solid, rgb } => {
            let st = colour(rgb).stroke_width(2);
            let (left, right) = if solid { (12, 12) } else { (3, 21) };
            let fill = if solid { colour(rgb) } else { WHITE };
            root.draw(&PathElement::new(vec![(x, y), (x + left, y)], st))
                .map_err(msg)?;
            root.draw(&PathElement::new(
                vec![(x + right, y), (x + SAMPLE_PX, y)],
                st,
            ))
            .map_err(msg)?;
            root.draw(&Circle::new((x + 12, y), 4, fill.filled()))
                .map_err(msg)?;
            root.draw(&Circle::new((x + 12, y), 4, st)).map_err(msg)
        }
        Sample::Cross => root.draw(&Cross::new((x + 12, y), 6, black)).map_err(msg),
        Sample::Dotted => root
            .draw(&DashedPathElement::new(
                vec![(x, y), (x + SAMPLE_PX, y)],
                4,
                6,
                black,
            ))
            .map_err(msg),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Merge's sample is a solid line through a filled dot, no merge's two dashes around a ring
    /// with a white centre.
    #[test]
    fn solid_and_dashed_samples_differ() {
        let mut pics = Vec::new();
        for solid in [true, false] {
            let mut pic = Picture::new(40, 20, [255, 255, 255]);
            pic.draw(|root| {
                draw_sample(
                    root,
                    Sample::Line {
                        solid,
                        rgb: [200, 0, 0],
                    },
                    (8, 10),
                )
            })
            .unwrap();
            pics.push(pic);
        }
        let red = |p: &Picture, x: usize| p.get(x, 10)[1] < 100;
        // Between the dash and the ring (x = 8 + 5): line on, gap off.
        assert!(red(&pics[0], 13) && !red(&pics[1], 13));
        // The dot's centre (x = 20): filled on, white off.
        assert!(red(&pics[0], 20) && !red(&pics[1], 20));
        // Both have their ends.
        assert!(red(&pics[0], 9) && red(&pics[1], 9));
    }

    /// Entries fill columns left to right, a narrow picture takes more rows, and the box
    /// holds every entry inside the picture.
    #[test]
    fn the_legend_wraps_into_rows_inside_the_picture() {
        let labels: Vec<String> = (0..5).map(|i| format!("entry number {i}")).collect();
        let (at, wide_h) = layout(&labels, 960);
        assert_eq!(at[0].1, at[1].1, "two entries on the first row");
        let (narrow_at, narrow_h) = layout(&labels, 200);
        assert!(narrow_h > wide_h);
        assert!(
            narrow_at.iter().all(|&(x, _)| x == narrow_at[0].0),
            "one column"
        );
        let top = Picture::new(960, 100, [255, 255, 255]);
        let entries: Vec<(Sample, String)> =
            labels.iter().map(|l| (Sample::Cross, l.clone())).collect();
        let (pic, b) = with_legend(&top, &entries).unwrap();
        assert_eq!(pic.height as i32, 100 + wide_h);
        assert!(
            b[0] >= 0 && b[2] < 960 && b[1] >= 100 && b[3] < pic.height as i32,
            "{b:?}"
        );
        assert_eq!(pic.get(b[0] as usize, (b[1] + 5) as usize), BORDER_RGB);
        assert_eq!(pic.get((b[0] + 40) as usize, b[3] as usize), BORDER_RGB);
    }
}
