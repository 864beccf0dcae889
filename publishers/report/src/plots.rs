//! The charts of a run (plotters, on white, `PLOT_W_PX` × `PLOT_H_PX`): probes against their
//! closed forms, exploration over time, distance to the path over time, and the leader's
//! deposits along its path. Their data are the [`super::series`] of the run.

use plotters::coord::combinators::LogCoord;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use super::series::{ExplorationSeries, LeaderDeposits, PathDistance, ProbeCurve};
use super::style::{colour, msg, robot_rgb, series_rgb, Picture, Rgb, FONT};

/// Size of every chart (px).
pub const PLOT_W_PX: u32 = 960;
pub const PLOT_H_PX: u32 = 540;
/// Robots named in a legend.
const MAX_LEGEND_ROBOTS: usize = 8;
/// Points of a closed-form curve.
const CURVE_POINTS: usize = 240;

pub(super) type Root<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

pub(super) fn text(size: u32) -> TextStyle<'static> {
    (FONT, size).into_font().color(&BLACK)
}

pub(super) fn blank() -> Picture {
    Picture::new(PLOT_W_PX, PLOT_H_PX, [255, 255, 255])
}

/// Title and subtitle at the top (the subtitle wrapped onto more lines if it is wider than the
/// picture); the rest of the picture for the chart.
pub(super) fn titled<'a>(root: &Root<'a>, title: &str, subtitle: &str) -> Result<Root<'a>, String> {
    root.draw_text(title, &text(22), (16, 10)).map_err(msg)?;
    let width = root.dim_in_pixel().0 as i32 - 32;
    let lines = super::summary::wrap(subtitle, 14, width);
    for (i, line) in lines.iter().enumerate() {
        let y = 40 + 18 * i as i32;
        root.draw_text(line, &text(14).color(&RGBColor(80, 80, 80)), (16, y))
            .map_err(msg)?;
    }
    let extra = 18 * (lines.len() as u32).saturating_sub(1);
    Ok(root.margin(64 + extra, 10, 10, 20))
}

/// A span of values with some room above, never empty.
fn upper(max: f64) -> f64 {
    if max.is_finite() && max > 0.0 {
        max * 1.08
    } else {
        1.0
    }
}

/// The legend's sample of a series: a line in its colour, with a dot of radius `$dot_px` on it
/// (0 for a series drawn as a line only).
macro_rules! legend {
    ($rgb:expr, $dot_px:expr) => {{
        let rgb: Rgb = $rgb;
        move |(x, y): (i32, i32)| {
            EmptyElement::at((x, y))
                + PathElement::new(vec![(0, 0), (24, 0)], colour(rgb).stroke_width(2))
                + Circle::new((12, 0), $dot_px, colour(rgb).filled())
        }
    }};
}

/// `evaporation`: each probe's readings (dots) against its closed form (line), as in seed 000
/// Figs. 6–8.
pub(super) fn probes_chart(curves: &[ProbeCurve], end_s: f64) -> Result<Picture, String> {
    let t_max = curves
        .iter()
        .flat_map(|c| c.readings.iter().map(|r| r.0))
        .fold(end_s, f64::max);
    let v_max = curves
        .iter()
        .flat_map(|c| c.readings.iter().map(|r| r.1 as f64))
        .fold(0.0, f64::max);
    let mut pic = blank();
    {
        let root = pic.area()?;
        let root = &root;
        let area = titled(
            root,
            "Probe readings against the closed form",
            "dots: the level each probe recorded in the run; lines: P(t) = Pa + (P0 − Pa)·e^(−K(t − t0)) \
             (seed 000 eqs. 19–22, Figs. 6–8)",
        )?;
        let mut chart = ChartBuilder::on(&area)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d(0.0..upper(t_max) / 1.08, 0.0..upper(v_max))
            .map_err(msg)?;
        chart
            .configure_mesh()
            .light_line_style(WHITE)
            .bold_line_style(RGBColor(225, 225, 225))
            .label_style(text(14))
            .axis_desc_style(text(15))
            .x_desc("time (s)")
            .y_desc("level (pheromone units)")
            .draw()
            .map_err(msg)?;
        for (i, c) in curves.iter().enumerate() {
            let rgb = series_rgb(i);
            let label = match c.closed_form {
                Some(f) => format!(
                    "{} at ({:.2}, {:.2}) m: P0 = {:.1}, Pa = {:.2}, K = {:.4} /s",
                    c.channel_name, c.x_m, c.y_m, f.p0, f.ambient, f.decay_per_s
                ),
                None => format!(
                    "{} at ({:.2}, {:.2}) m (no closed form)",
                    c.channel_name, c.x_m, c.y_m
                ),
            };
            if let Some(f) = c.closed_form {
                let t1 = c.readings.last().map_or(t_max, |r| r.0);
                let line = (0..=CURVE_POINTS).map(|k| {
                    let t = f.t0_s + (t1 - f.t0_s) * k as f64 / CURVE_POINTS as f64;
                    (t, f.at(t))
                });
                chart
                    .draw_series(LineSeries::new(line, colour(rgb).stroke_width(2)))
                    .map_err(msg)?;
            }
            chart
                .draw_series(
                    c.readings
                        .iter()
                        .map(|&(t, v)| Circle::new((t, v as f64), 5, colour(rgb).filled())),
                )
                .map_err(msg)?
                .label(label)
                .legend(legend!(rgb, 4));
        }
        series_labels(&mut chart, SeriesLabelPosition::UpperRight)?;
        root.present().map_err(msg)?;
    }
    Ok(pic)
}

pub(super) fn series_labels<'a, 'b: 'a, X, Y>(
    chart: &mut ChartContext<'a, BitMapBackend<'b>, Cartesian2d<X, Y>>,
    at: SeriesLabelPosition,
) -> Result<(), String>
where
    X: plotters::coord::ranged1d::Ranged,
    Y: plotters::coord::ranged1d::Ranged,
{
    chart
        .configure_series_labels()
        .position(at)
        .label_font(text(14))
        .background_style(WHITE.mix(0.9))
        .border_style(RGBColor(150, 150, 150))
        .draw()
        .map_err(msg)
}

/// `ias-ss`: the share of sectors each robot, and the team, has visited over time (seed 004).
pub(super) fn exploration_chart(s: &ExplorationSeries, end_s: f64) -> Result<Picture, String> {
    let t_max = s.team.last().map_or(end_s, |p| p.0).max(end_s);
    let mut pic = blank();
    {
        let root = pic.area()?;
        let root = &root;
        let area = titled(
            root,
            "Exploration over time",
            &format!(
                "share of the {} sectors each robot has visited, and the team (visited by at least one robot)",
                s.sectors
            ),
        )?;
        let mut chart = ChartBuilder::on(&area)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d(0.0..t_max.max(1e-9), 0.0..105.0)
            .map_err(msg)?;
        chart
            .configure_mesh()
            .light_line_style(WHITE)
            .bold_line_style(RGBColor(225, 225, 225))
            .label_style(text(14))
            .axis_desc_style(text(15))
            .x_desc("time (s)")
            .y_desc("sectors visited (%)")
            .draw()
            .map_err(msg)?;
        let team_rgb = [20, 20, 20];
        chart
            .draw_series(LineSeries::new(
                s.team.iter().map(|&(t, v)| (t, 100.0 * v)),
                colour(team_rgb).stroke_width(3),
            ))
            .map_err(msg)?
            .label(format!(
                "team: {:.0} %",
                100.0 * s.team.last().map_or(0.0, |p| p.1)
            ))
            .legend(legend!(team_rgb, 0));
        for (k, (&id, points)) in s.per_robot.iter().enumerate() {
            let rgb = robot_rgb(id);
            let anno = chart
                .draw_series(LineSeries::new(
                    points.iter().map(|&(t, v)| (t, 100.0 * v)),
                    colour(rgb).stroke_width(2),
                ))
                .map_err(msg)?;
            // The legend names the first robots only; the rest would cover the chart.
            if k < MAX_LEGEND_ROBOTS {
                anno.label(format!(
                    "R{id}: {:.0} %",
                    100.0 * points.last().map_or(0.0, |p| p.1)
                ))
                .legend(legend!(rgb, 0));
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .label_font(text(14))
            .background_style(WHITE.mix(0.9))
            .border_style(RGBColor(150, 150, 150))
            .draw()
            .map_err(msg)?;
        root.present().map_err(msg)?;
    }
    Ok(pic)
}

/// `trail-following`: each follower's distance to its path over time, the metric's window
/// shaded and its mean drawn over it (seed 002).
pub(super) fn path_distance_chart(paths: &[PathDistance], end_s: f64) -> Result<Picture, String> {
    let t_max = paths
        .iter()
        .filter_map(|p| p.points.last().map(|q| q.0))
        .fold(end_s, f64::max);
    let d_max = paths
        .iter()
        .flat_map(|p| p.points.iter().map(|q| q.1))
        .fold(0.0, f64::max);
    let mut pic = blank();
    {
        let root = pic.area()?;
        let root = &root;
        let area = titled(
            root,
            "Distance to the path over time",
            "each robot's distance to its target path; dashed: the run's mean_path_error_m over its \
             window (shaded when shorter than the run)",
        )?;
        let mut chart = ChartBuilder::on(&area)
            .x_label_area_size(44)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..t_max.max(1e-9), 0.0..upper(d_max))
            .map_err(msg)?;
        chart
            .configure_mesh()
            .light_line_style(WHITE)
            .bold_line_style(RGBColor(225, 225, 225))
            .label_style(text(14))
            .axis_desc_style(text(15))
            .x_desc("time (s)")
            .y_desc("distance to the path (m)")
            .draw()
            .map_err(msg)?;
        for (i, p) in paths.iter().enumerate() {
            // The robot's colour of every picture, unless it follows two paths.
            let shared = paths.iter().filter(|q| q.robot == p.robot).count() > 1;
            let rgb = if shared {
                series_rgb(i)
            } else {
                robot_rgb(p.robot)
            };
            // The window, shaded unless it is the whole run.
            if p.from_s > 1e-9 || p.to_s < t_max - 1e-9 {
                chart
                    .draw_series(std::iter::once(Rectangle::new(
                        [(p.from_s, 0.0), (p.to_s.min(t_max), upper(d_max))],
                        colour(rgb).mix(0.08).filled(),
                    )))
                    .map_err(msg)?;
            }
            chart
                .draw_series(LineSeries::new(
                    p.points.iter().copied(),
                    colour(rgb).stroke_width(2),
                ))
                .map_err(msg)?
                .label(match p.mean_m {
                    Some(m) => format!(
                        "{} (R{}): mean {:.3} m over {:.0}–{:.0} s",
                        p.name, p.robot, m, p.from_s, p.to_s
                    ),
                    None => format!("{} (R{}): no sample in the window", p.name, p.robot),
                })
                .legend(legend!(rgb, 0));
            if let Some(m) = p.mean_m {
                chart
                    .draw_series(std::iter::once(DashedPathElement::new(
                        vec![(p.from_s, m), (p.to_s, m)],
                        8,
                        5,
                        colour(rgb).stroke_width(2),
                    )))
                    .map_err(msg)?;
            }
        }
        series_labels(&mut chart, SeriesLabelPosition::UpperRight)?;
        root.present().map_err(msg)?;
    }
    Ok(pic)
}

/// The deposits chart's axes: distance (m) against a log level.
type DepositChart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, LogCoord<f64>>>;

/// Seed 000 Fig. 23's stated values (crosses) and the follower's threshold (a line to `x_end`)
/// on the deposits chart whose levels span `lo..hi`.
fn draw_paper_and_threshold<'a, 'b: 'a>(
    chart: &mut DepositChart<'a, 'b>,
    d: &LeaderDeposits,
    x_end: f64,
    (lo, hi): (f64, f64),
) -> Result<(), String> {
    if !d.paper.is_empty() {
        chart
            .draw_series(
                d.paper
                    .iter()
                    .map(|&p| Cross::new(p, 7, colour([0, 0, 0]).stroke_width(2))),
            )
            .map_err(msg)?
            .label("paper 000 Fig. 23 (L11 11.35, L12 8.15) at this run's L11, L12")
            .legend(|(x, y)| Cross::new((x + 12, y), 5, colour([0, 0, 0]).stroke_width(2)));
    }
    if let Some(t) = d.threshold.filter(|t| (lo..hi).contains(t)) {
        chart
            .draw_series(std::iter::once(DashedPathElement::new(
                vec![(0.0, t), (x_end, t)],
                4,
                4,
                colour([0, 120, 0]).stroke_width(2),
            )))
            .map_err(msg)?
            .label(format!("the follower's threshold: {t}"))
            .legend(legend!([0, 120, 0], 0));
    }
    Ok(())
}

/// The vertical marks of [`leader_deposits_chart`]: (distance along the path (m), t_s, what,
/// colour) where the leader got lost (scripted), where its deposit first fell below the
/// follower's threshold, and where the follower gave the trail up.
fn leader_deposit_marks(d: &LeaderDeposits) -> Vec<(Option<f64>, Option<f64>, String, Rgb)> {
    let below = d.below_threshold_at();
    vec![
        (
            d.metric.leader_lost_at_m,
            d.metric.leader_lost_at_s,
            "leader lost its localization".into(),
            [200, 0, 0],
        ),
        (
            below.map(|b| b.0),
            below.map(|b| b.1),
            format!(
                "leader's deposit below the threshold ({})",
                d.threshold.unwrap_or_default()
            ),
            [0, 120, 0],
        ),
        (
            d.metric.follower_abandoned_at_m,
            d.metric.follower_abandoned_at_s,
            "follower gave the trail up".into(),
            [90, 90, 90],
        ),
    ]
}

/// `blind-leader`: the peak of each of the leader's deposits by distance along its path, the
/// point where it lost its localization, where its deposit fell below the follower's threshold
/// (drawn as a line) and where the follower gave up marked (seed 000, Fig. 23).
pub(super) fn leader_deposits_chart(d: &LeaderDeposits) -> Result<Picture, String> {
    let x_max = d
        .deposits
        .iter()
        .map(|p| p.0)
        .chain(d.metric.follower_abandoned_at_m)
        .fold(1.0, f64::max);
    let peaks = d.deposits.iter().map(|p| p.1 as f64).filter(|v| *v > 0.0);
    let lo = peaks.clone().fold(f64::INFINITY, f64::min);
    let hi = peaks.fold(0.0, f64::max);
    let (lo, hi) = if lo.is_finite() && hi > 0.0 {
        (lo / 2.0, hi * 2.0)
    } else {
        (0.1, 10.0)
    };
    let mut pic = blank();
    {
        let root = pic.area()?;
        let root = &root;
        let area = titled(
            root,
            &format!("Deposits of the leader (R{}) along its path", d.leader),
            "peak of each deposit (seed 000 eqs. 11-12: it falls as the leader's uncertainty \
             grows), against the distance the leader travelled",
        )?;
        let mut chart = ChartBuilder::on(&area)
            .x_label_area_size(44)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..x_max * 1.02, (lo..hi).log_scale())
            .map_err(msg)?;
        chart
            .configure_mesh()
            .light_line_style(WHITE)
            .bold_line_style(RGBColor(225, 225, 225))
            .label_style(text(14))
            .axis_desc_style(text(15))
            .x_desc("distance along the leader's path (m)")
            .y_desc("deposit peak (pheromone units, log scale)")
            .y_label_formatter(&|v| super::heatmap::fmt_sig(*v))
            .draw()
            .map_err(msg)?;
        let rgb = robot_rgb(d.leader);
        let points: Vec<(f64, f64)> = d
            .deposits
            .iter()
            .filter(|p| p.1 > 0.0)
            .map(|p| (p.0, p.1 as f64))
            .collect();
        chart
            .draw_series(LineSeries::new(
                points.iter().copied(),
                colour(rgb).mix(0.5).stroke_width(1),
            ))
            .map_err(msg)?;
        chart
            .draw_series(
                points
                    .iter()
                    .map(|&p| Circle::new(p, 3, colour(rgb).filled())),
            )
            .map_err(msg)?
            .label(format!(
                "R{}: one dot per deposit ({})",
                d.leader,
                points.len()
            ))
            .legend(legend!(rgb, 4));
        draw_paper_and_threshold(&mut chart, d, x_max * 1.02, (lo, hi))?;
        for (at_m, at_s, what, mark_rgb) in leader_deposit_marks(d) {
            let (Some(m), Some(s)) = (at_m, at_s) else {
                continue;
            };
            chart
                .draw_series(std::iter::once(DashedPathElement::new(
                    vec![(m, lo), (m, hi)],
                    8,
                    5,
                    colour(mark_rgb).stroke_width(2),
                )))
                .map_err(msg)?
                .label(format!("{what}: {m:.2} m, t = {s:.1} s"))
                .legend(legend!(mark_rgb, 0));
        }
        series_labels(&mut chart, SeriesLabelPosition::LowerLeft)?;
        root.present().map_err(msg)?;
    }
    Ok(pic)
}
