//! The charts of `pheromone sim --compare-filters` (seed 000 Figs. 13–18), one series per
//! filter in the palette's order: errors and deposits against time, and σ against the
//! deposit on log–log axes. Their data are [`super::filters::FilterRun`]s.

use std::fs;
use std::path::{Path, PathBuf};

use plotters::prelude::*;

use super::files::{write_file, write_png};
use super::filters::{filters_csv, FilterRun, FilterStep};
use super::plots::{blank, series_labels, text, titled};
use super::style::{colour, msg, series_rgb, Picture, Rgb};
use super::ReportError;

/// What an [`error_chart`] draws against time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum ErrorKind {
    X,
    Y,
    Phi,
    Combined,
    Deposit,
}

impl ErrorKind {
    fn value(self, p: &FilterStep) -> Option<f64> {
        match self {
            Self::X => Some(p.err_x_m),
            Self::Y => Some(p.err_y_m),
            Self::Phi => Some(p.err_phi_rad),
            Self::Combined => Some(p.err_xy_m),
            Self::Deposit => p.deposit.map(f64::from).filter(|v| *v > 0.0),
        }
    }

    /// Title, subtitle and the y axis's description.
    fn words(self) -> (&'static str, &'static str, &'static str) {
        match self {
            Self::X => (
                "Estimation error in x (seed 000 Fig. 14)",
                "estimate − truth at each step, one run per filter on the same scenario and seed",
                "error in x (m)",
            ),
            Self::Y => (
                "Estimation error in y (seed 000 Fig. 15)",
                "estimate − truth at each step, one run per filter on the same scenario and seed",
                "error in y (m)",
            ),
            Self::Phi => (
                "Estimation error in φ (seed 000 Fig. 13)",
                "estimate − truth at each step, wrapped to (−π, π]",
                "error in φ (rad)",
            ),
            Self::Combined => (
                "Combined position error (seed 000 Fig. 16)",
                "√(error in x² + error in y²) at each step",
                "position error (m)",
            ),
            Self::Deposit => (
                "Pheromone deposited at each step (seed 000 Fig. 17)",
                "peak of each deposit, γ = τ / det Σxy capped at γmax (seed 000 eq. 12)",
                "deposit (pheromone units, log scale)",
            ),
        }
    }
}

/// The legend's sample of a series: a line in its colour.
macro_rules! legend_line {
    ($rgb:expr) => {{
        let rgb: Rgb = $rgb;
        move |(x, y): (i32, i32)| {
            EmptyElement::at((x, y))
                + PathElement::new(vec![(0, 0), (24, 0)], colour(rgb).stroke_width(2))
        }
    }};
}

/// Each run's value of `kind` against time; the deposits on a log scale.
pub(super) fn error_chart(
    robot: u32,
    runs: &[FilterRun],
    kind: ErrorKind,
) -> Result<Picture, String> {
    let series: Vec<Vec<(f64, f64)>> = runs
        .iter()
        .map(|r| {
            r.steps
                .iter()
                .filter_map(|p| Some((p.t_s, kind.value(p)?)))
                .filter(|p| p.1.is_finite())
                .collect()
        })
        .collect();
    let all = || series.iter().flatten();
    let t_max = all().map(|p| p.0).fold(1e-9, f64::max);
    let lo = all().map(|p| p.1).fold(f64::INFINITY, f64::min);
    let hi = all().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
    let (title, subtitle, y_desc) = kind.words();
    let mut pic = blank();
    {
        let root = pic.area()?;
        let area = titled(&root, &format!("{title}, R{robot}"), subtitle)?;
        let mut builder = ChartBuilder::on(&area);
        builder.x_label_area_size(44).y_label_area_size(80);
        if kind == ErrorKind::Deposit {
            let (lo, hi) = if lo.is_finite() {
                (lo / 2.0, hi * 2.0)
            } else {
                (0.1, 10.0)
            };
            let mut chart = builder
                .build_cartesian_2d(0.0..t_max, (lo..hi).log_scale())
                .map_err(msg)?;
            mesh(&mut chart, "time (s)", y_desc)?;
            for (i, (r, pts)) in runs.iter().zip(&series).enumerate() {
                let rgb = series_rgb(i);
                chart
                    .draw_series(pts.iter().map(|&p| Circle::new(p, 2, colour(rgb).filled())))
                    .map_err(msg)?
                    .label(format!("{}: {} deposits", r.filter, pts.len()))
                    .legend(legend_line!(rgb));
            }
            series_labels(&mut chart, SeriesLabelPosition::LowerLeft)?;
        } else {
            let span = if lo.is_finite() {
                (hi - lo).max(1e-6)
            } else {
                1.0
            };
            let (lo, hi) = if lo.is_finite() {
                (lo - 0.05 * span, hi + 0.05 * span)
            } else {
                (-1.0, 1.0)
            };
            let mut chart = builder
                .build_cartesian_2d(0.0..t_max, lo..hi)
                .map_err(msg)?;
            mesh(&mut chart, "time (s)", y_desc)?;
            for (i, (r, pts)) in runs.iter().zip(&series).enumerate() {
                let rgb = series_rgb(i);
                let rms =
                    (pts.iter().map(|p| p.1 * p.1).sum::<f64>() / pts.len().max(1) as f64).sqrt();
                chart
                    .draw_series(LineSeries::new(
                        pts.iter().copied(),
                        colour(rgb).stroke_width(2),
                    ))
                    .map_err(msg)?
                    .label(format!("{}: RMS {rms:.3}", r.filter))
                    .legend(legend_line!(rgb));
            }
            series_labels(&mut chart, SeriesLabelPosition::UpperLeft)?;
        }
        root.present().map_err(msg)?;
    }
    Ok(pic)
}

fn mesh<X, Y>(
    chart: &mut ChartContext<'_, BitMapBackend<'_>, Cartesian2d<X, Y>>,
    x_desc: &str,
    y_desc: &str,
) -> Result<(), String>
where
    X: plotters::coord::ranged1d::Ranged<ValueType = f64>
        + plotters::coord::ranged1d::ValueFormatter<f64>,
    Y: plotters::coord::ranged1d::Ranged<ValueType = f64>
        + plotters::coord::ranged1d::ValueFormatter<f64>,
{
    chart
        .configure_mesh()
        .light_line_style(WHITE)
        .bold_line_style(RGBColor(225, 225, 225))
        .label_style(text(14))
        .axis_desc_style(text(15))
        .x_desc(x_desc)
        .y_desc(y_desc)
        .draw()
        .map_err(msg)
}

/// Fig. 18: each step's σ against its deposit, both on log scales, one colour per filter.
pub(super) fn scatter_chart(robot: u32, runs: &[FilterRun]) -> Result<Picture, String> {
    let series: Vec<Vec<(f64, f64)>> = runs
        .iter()
        .map(|r| {
            r.steps
                .iter()
                .filter_map(|p| Some((p.sigma_m?, f64::from(p.deposit?))))
                .filter(|(s, d)| *s > 0.0 && *d > 0.0 && s.is_finite() && d.is_finite())
                .collect()
        })
        .collect();
    let all = || series.iter().flatten();
    let range = |v: Vec<f64>| {
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(0.0, f64::max);
        if lo.is_finite() {
            (lo / 2.0, hi * 2.0)
        } else {
            (0.01, 1.0)
        }
    };
    let (x_lo, x_hi) = range(all().map(|p| p.0).collect());
    let (y_lo, y_hi) = range(all().map(|p| p.1).collect());
    let mut pic = blank();
    {
        let root = pic.area()?;
        let area = titled(
            &root,
            &format!("Uncertainty against deposit (seed 000 Fig. 18), R{robot}"),
            "one dot per deposit: the estimate's σ (√ of the largest eigenvalue of Σxy) and the \
             deposit's peak γ, log–log",
        )?;
        let mut chart = ChartBuilder::on(&area)
            .x_label_area_size(44)
            .y_label_area_size(80)
            .build_cartesian_2d((x_lo..x_hi).log_scale(), (y_lo..y_hi).log_scale())
            .map_err(msg)?;
        mesh(
            &mut chart,
            "σ of the estimate (m, log scale)",
            "deposit γ (log scale)",
        )?;
        for (i, (r, pts)) in runs.iter().zip(&series).enumerate() {
            let rgb = series_rgb(i);
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 3, colour(rgb).filled())))
                .map_err(msg)?
                .label(format!("{}: {} deposits", r.filter, pts.len()))
                .legend(legend_line!(rgb));
        }
        series_labels(&mut chart, SeriesLabelPosition::UpperRight)?;
        root.present().map_err(msg)?;
    }
    Ok(pic)
}

/// Writes `filters.csv` and the charts of seed 000 Figs. 13–18 for robot `robot` into `dir`:
/// `filter_error_phi.png` (Fig. 13), `filter_error_x.png` (14), `filter_error_y.png` (15),
/// `filter_error_xy.png` (16), `filter_deposits.png` (17) and `filter_sigma_deposit.png` (18).
pub fn write_filter_comparison(
    dir: &Path,
    robot: u32,
    runs: &[FilterRun],
) -> Result<Vec<PathBuf>, ReportError> {
    fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let path = dir.join("filters.csv");
    write_file(&path, filters_csv(runs).as_bytes())?;
    let mut written = vec![path];
    let charts = [
        ("filter_error_phi.png", ErrorKind::Phi),
        ("filter_error_x.png", ErrorKind::X),
        ("filter_error_y.png", ErrorKind::Y),
        ("filter_error_xy.png", ErrorKind::Combined),
        ("filter_deposits.png", ErrorKind::Deposit),
    ];
    for (name, kind) in charts {
        let path = dir.join(name);
        let pic = error_chart(robot, runs, kind).map_err(|detail| ReportError::Draw {
            path: path.clone(),
            detail,
        })?;
        write_png(&path, &pic)?;
        written.push(path);
    }
    let path = dir.join("filter_sigma_deposit.png");
    let pic = scatter_chart(robot, runs).map_err(|detail| ReportError::Draw {
        path: path.clone(),
        detail,
    })?;
    write_png(&path, &pic)?;
    written.push(path);
    Ok(written)
}
