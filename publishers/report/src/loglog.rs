//! Figures against a size on log-log axes, one panel per figure (`pheromone bench --only
//! scale`'s chart, issue 52): each panel's series as lines with dots, a dashed grey line of
//! slope 1 through the first series' first point for "linear", and each series' label with its
//! fitted exponent.

use std::path::Path;

use plotters::element::DashedPathElement;
use plotters::prelude::*;

use crate::files::write_png;
use crate::plots::{text, titled};
use crate::style::{colour, msg, series_rgb, Picture};
use crate::ReportError;

/// One line of a panel: its label (the fitted exponent in it, e.g. "processes (b = 1.02)")
/// and its (size, value) points; values ≤ 0 or not finite are left out.
#[derive(Debug, Clone)]
pub struct LogLogSeries {
    pub label: String,
    pub points: Vec<(f64, f64)>,
}

/// One panel: a figure with its unit.
#[derive(Debug, Clone)]
pub struct LogLogPanel {
    pub title: String,
    pub series: Vec<LogLogSeries>,
}

/// Panels in a grid of `columns` columns, `x_label` under each, as a PNG at `path`.
pub fn write_log_log_panels(
    path: &Path,
    title: &str,
    subtitle: &str,
    x_label: &str,
    panels: &[LogLogPanel],
    columns: usize,
) -> Result<(), ReportError> {
    let draw_err = |detail: String| ReportError::Draw {
        path: path.to_path_buf(),
        detail,
    };
    let columns = columns.max(1);
    let rows = panels.len().div_ceil(columns).max(1);
    let mut pic = Picture::new(
        480 * columns as u32,
        80 + 340 * rows as u32,
        [255, 255, 255],
    );
    pic.draw(|root| {
        let body = titled(root, title, subtitle)?;
        let cells = body.split_evenly((rows, columns));
        for (panel, area) in panels.iter().zip(cells.iter()) {
            draw_panel(area, panel, x_label)?;
        }
        Ok(())
    })
    .map_err(draw_err)?;
    write_png(path, &pic)
}

type Area<'a> = plotters::drawing::DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

/// The span of `values` (positive, finite) widened a little on a log scale.
fn span(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if lo > hi {
        return (0.1, 10.0);
    }
    (lo / 1.6, hi * 1.6)
}

/// A tick label with as many decimals as its size needs (1000, 25, 2.5, 0.25, 0.025).
fn short(v: f64) -> String {
    let decimals = (1.0 - v.abs().log10().floor()).clamp(0.0, 6.0) as usize;
    format!("{v:.decimals$}")
}

/// The label of a log axis's tick: only 1, 2 and 5 times a power of ten are labelled (the ticks
/// between them are dense enough that their labels run into each other: "60708090100").
fn log_tick(v: f64, label: impl Fn(f64) -> String) -> String {
    if !(v.is_finite() && v > 0.0) {
        return String::new();
    }
    let mantissa = v / 10f64.powf(v.log10().floor());
    let lead = mantissa.round();
    match [1.0, 2.0, 5.0, 10.0].contains(&lead) && (mantissa - lead).abs() < 0.01 * lead {
        true => label(v),
        false => String::new(),
    }
}

fn draw_panel(area: &Area<'_>, panel: &LogLogPanel, x_label: &str) -> Result<(), String> {
    let points = |s: &LogLogSeries| -> Vec<(f64, f64)> {
        s.points
            .iter()
            .copied()
            .filter(|(x, y)| x.is_finite() && *x > 0.0 && y.is_finite() && *y > 0.0)
            .collect()
    };
    let all: Vec<(f64, f64)> = panel.series.iter().flat_map(points).collect();
    let (x0, x1) = span(all.iter().map(|p| p.0));
    let (y0, y1) = span(all.iter().map(|p| p.1));
    let mut chart = ChartBuilder::on(&area.margin(8, 8, 8, 8))
        .caption(&panel.title, text(15))
        .x_label_area_size(34)
        .y_label_area_size(58)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
        .map_err(msg)?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .x_label_style(text(12))
        .y_label_style(text(12))
        .light_line_style(WHITE)
        .x_label_formatter(&|v| log_tick(*v, |v| format!("{v:.0}")))
        .y_label_formatter(&|v| log_tick(*v, short))
        .draw()
        .map_err(msg)?;
    if let Some(&(fx, fy)) = panel
        .series
        .first()
        .and_then(|s| points(s).first().copied())
        .as_ref()
    {
        let linear = vec![(fx, fy), (x1, fy * x1 / fx)];
        chart
            .draw_series(std::iter::once(DashedPathElement::new(
                linear,
                4,
                4,
                RGBColor(150, 150, 150).stroke_width(1),
            )))
            .map_err(msg)?
            .label("slope 1 (linear)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(150, 150, 150)));
    }
    for (i, s) in panel.series.iter().enumerate() {
        let c = colour(series_rgb(i));
        let pts = points(s);
        chart
            .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))
            .map_err(msg)?
            .label(&s.label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart
            .draw_series(pts.into_iter().map(|p| Circle::new(p, 3, c.filled())))
            .map_err(msg)?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font(text(11))
        .background_style(WHITE.mix(0.8))
        .border_style(RGBColor(200, 200, 200))
        .draw()
        .map_err(msg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_one_two_and_five_times_a_power_of_ten_are_labelled() {
        let l = |v: f64| log_tick(v, short);
        assert_eq!(l(10.0), "10");
        assert_eq!(l(20.0), "20");
        assert_eq!(l(500.0), "500");
        assert_eq!(l(0.05), "0.050");
        assert_eq!(l(1000.0000001), "1000");
        for v in [30.0, 60.0, 70.0, 80.0, 90.0, 0.3, 4000.0, 0.0, f64::NAN] {
            assert_eq!(l(v), "", "{v}");
        }
    }

    #[test]
    fn tick_labels_carry_the_decimals_their_size_needs() {
        assert_eq!(short(1000.0), "1000");
        assert_eq!(short(25.0), "25");
        assert_eq!(short(2.5), "2.5");
        assert_eq!(short(0.25), "0.25");
        assert_eq!(short(0.025), "0.025");
    }

    #[test]
    fn panels_are_drawn_into_a_png_of_the_grid_size() {
        let path = std::env::temp_dir().join(format!("loglog-{}.png", std::process::id()));
        let series = |label: &str, k: f64| LogLogSeries {
            label: label.into(),
            points: [8.0, 16.0, 32.0, 0.0]
                .iter()
                .map(|&n| (n, k * n))
                .chain(std::iter::once((64.0, f64::NAN)))
                .collect(),
        };
        let panels = vec![
            LogLogPanel {
                title: "start-up (s)".into(),
                series: vec![series("processes", 0.1), series("one process", 0.01)],
            },
            LogLogPanel {
                title: "empty".into(),
                series: vec![],
            },
            LogLogPanel {
                title: "memory".into(),
                series: vec![series("x", 1e6)],
            },
        ];
        write_log_log_panels(&path, "t", "s", "robots", &panels, 2).unwrap();
        let png = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        // Width and height in the IHDR chunk: 2 columns × 480, 80 + 2 rows × 340.
        assert_eq!(u32::from_be_bytes(png[16..20].try_into().unwrap()), 960);
        assert_eq!(u32::from_be_bytes(png[20..24].try_into().unwrap()), 760);
    }
}
