//! What `pheromone sweep` writes: `sweep.csv` (one row per run: what it computed, the same bytes
//! on every host), `sweep_times.csv` (each run's wall time), `sweep.json` (the points with
//! mean ± sd, the comparisons with Welch's and the paired t) and the charts drawn like the
//! run's (plotters, `PLOT_W_PX` × `PLOT_H_PX`): `sweep_robots.png`, exploration against the
//! number of robots (whole-number ticks) with and without merging, and `sweep_rc.png`,
//! exploration against R_C, written only when the sweep has two radii or more (one radius is
//! no line). Both plot the sweep's figure (`--figure`: known, merged or visited) mean per
//! robot, mean ± sd over the trials (error bars); merge on is a solid line with filled dots,
//! merge off a dashed line with hollow dots, each legend entry starts with "merge" or "no
//! merge" and names the steering; the paper's own values (`pheromone_sim::paper`) are black crosses
//! (robots chart) and its peak R_C a dotted vertical line (R_C chart), inside the axes; the
//! legend is drawn in a band under the chart (`legend.rs`), clear of the data. `sweep_paper.md`
//! puts each of the paper's values beside what the sweep measured.

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use std::ops::Range;

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::coord::types::RangedCoordf64;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use super::files::{write_file, write_json, write_png};
use super::legend::{with_legend, Sample};
use super::plots::{blank, text, titled};
use super::style::{colour, msg, series_rgb, Picture, Rgb};
use super::ReportError;
use pheromone_sim::paper::{PaperKind, PaperValue};
use pheromone_sim::sweep::{Point, PointKey, RunResult, SweepResult};

/// Header of `sweep.csv`: what each run computed, nothing it measured, so that the same sweep
/// writes the same bytes on any host, at any `--jobs`, sharded or not (each run's wall time is in
/// `sweep_times.csv`).
pub const SWEEP_CSV_HEADER: &str = "robots,rc_m,merge,strategy,steer_on,merge_rule,\
merge_idle_iterations,seed,known_mean,known_team,merged_mean,merged_team,visited_mean,visited_team,merges,alignment_error_m";

/// Header of `sweep_times.csv`: each run's point and seed, and its wall time (s).
pub const SWEEP_TIMES_CSV_HEADER: &str =
    "robots,rc_m,merge,strategy,steer_on,merge_rule,merge_idle_iterations,seed,wall_s";

/// A run's point and seed, the first eight columns of both CSV files.
fn run_key(x: &RunResult) -> String {
    let k = &x.point;
    format!(
        "{},{},{},{},{},{},{},{}",
        k.robots,
        k.rc_m,
        k.merge,
        k.strategy.name(),
        k.steer_on.name(),
        k.integration.merge_rule.name(),
        k.integration.merge_idle_iterations,
        x.seed
    )
}

/// `sweep.csv`: one row per run, in grid order.
pub fn sweep_csv(r: &SweepResult) -> String {
    let mut text = String::from(SWEEP_CSV_HEADER);
    text.push('\n');
    for x in &r.runs {
        // Writing into a String cannot fail.
        let _ = writeln!(
            text,
            "{},{},{},{},{},{},{},{},{}",
            run_key(x),
            x.known_mean,
            x.known_team,
            x.merged_mean,
            x.merged_team,
            x.visited_mean,
            x.visited_team,
            x.merges,
            x.alignment_error_m
                .map(|e| e.to_string())
                .unwrap_or_default(),
        );
    }
    text
}

/// `sweep_times.csv`: each run's wall time, in the rows' order of `sweep.csv`.
pub fn sweep_times_csv(r: &SweepResult) -> String {
    let mut text = String::from(SWEEP_TIMES_CSV_HEADER);
    text.push('\n');
    for x in &r.runs {
        let _ = writeln!(text, "{},{}", run_key(x), x.wall_s);
    }
    text
}

/// Writes `sweep.csv`, `sweep_times.csv`, `sweep.json`, `sweep_paper.md` (the paper's values beside ours),
/// `sweep_robots.png` and, when the sweep has two radii or more ([`rc_values`]),
/// `sweep_rc.png` into `dir` (created if needed) and returns the paths written.
pub fn write_sweep(
    dir: &Path,
    r: &SweepResult,
    paper: &[PaperValue],
) -> Result<Vec<PathBuf>, ReportError> {
    fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut written = Vec::new();
    let path = dir.join("sweep.csv");
    write_file(&path, sweep_csv(r).as_bytes())?;
    written.push(path);
    let path = dir.join("sweep_times.csv");
    write_file(&path, sweep_times_csv(r).as_bytes())?;
    written.push(path);
    let path = dir.join("sweep.json");
    write_json(&path, r)?;
    written.push(path);
    let path = dir.join("sweep_paper.md");
    write_file(&path, paper_table(r, paper).as_bytes())?;
    written.push(path);
    let subtitle = format!(
        "'{}', {} s, seeds 1–{} per point; {}, mean per robot of {} sectors ± sd; black: the paper",
        r.scenario,
        r.duration_s,
        r.trials,
        figure_words(r.figure),
        r.sectors
    );
    let mut charts = vec![("sweep_robots.png", Axis::Robots)];
    if rc_values(r).len() > 1 {
        charts.push(("sweep_rc.png", Axis::Rc));
    }
    for (name, axis) in charts {
        let path = dir.join(name);
        let (pic, ..) = chart(r, paper, axis, &subtitle).map_err(|detail| ReportError::Draw {
            path: path.clone(),
            detail,
        })?;
        write_png(&path, &pic)?;
        written.push(path);
    }
    Ok(written)
}

/// The figure's words on a chart.
fn figure_words(f: pheromone_sim::sweep::Figure) -> &'static str {
    match f {
        pheromone_sim::sweep::Figure::Known => "known: mapped or merged",
        pheromone_sim::sweep::Figure::Merged => "merged: visited or received by a merge",
        pheromone_sim::sweep::Figure::Visited => "visited",
    }
}

/// `sweep_paper.md`: a Markdown table, one row per paper value: its table, the value and
/// ours beside it (what the sweep has no point for says so).
pub fn paper_table(r: &SweepResult, paper: &[PaperValue]) -> String {
    let mut text = format!(
        "# Paper 004 beside sweep '{}' ({} s, {} trial(s), figure: {})\n\n| table | paper | ours |\n| --- | --- | --- |\n",
        r.scenario,
        r.duration_s,
        r.trials,
        r.figure.name()
    );
    for (p, ours) in pheromone_sim::paper::beside(paper, r) {
        let what = match p.kind {
            PaperKind::MeanPct => format!("mean {} %", p.value),
            PaperKind::MaxPct => format!("at most {} %", p.value),
            PaperKind::WelchT => format!("Welch t = {}", p.value),
            PaperKind::PairedTAbove => format!("every paired t > {}", p.value),
            PaperKind::PeakRcM => format!("peak at R_C = {} m, slow decay beyond", p.value),
        };
        let setting = format!(
            "{}, {}{}",
            p.strategy.name(),
            if p.integration {
                "integration"
            } else {
                "no integration"
            },
            p.robots.map_or(String::new(), |n| format!(", {n} robots"))
        );
        let _ = writeln!(
            text,
            "| {} | {what} ({setting}) | {} |",
            p.table,
            ours.unwrap_or_else(|| "not in this sweep".into())
        );
    }
    text
}

/// The distinct R_C values of the sweep's points, ascending.
pub fn rc_values(r: &SweepResult) -> Vec<f64> {
    let mut v: Vec<f64> = r.points.iter().map(|p| p.key.rc_m).collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Axis {
    Robots,
    Rc,
}

impl Axis {
    fn x(self, k: &PointKey) -> f64 {
        match self {
            Axis::Robots => k.robots as f64,
            Axis::Rc => k.rc_m,
        }
    }

    /// The settings a line keeps fixed, in words, merge or not first.
    fn label(self, k: &PointKey) -> String {
        let merge = match (k.merge, k.integration.words()) {
            (false, _) => "no merge".to_string(),
            (true, w) if w.is_empty() => "merge".to_string(),
            (true, w) => format!("merge {w}"),
        };
        let (s, steer) = (k.strategy.name(), k.steer_on.name());
        match self {
            Axis::Robots => format!("{merge}: {s}, {steer}, R_C = {} m", k.rc_m),
            Axis::Rc => format!("{merge}: {s}, {steer}, {} robot(s)", k.robots),
        }
    }

    /// The x axis with its ticks: whole numbers for robots (at most about ten), plotters' round
    /// values for R_C.
    fn x_coord(self, lo: f64, hi: f64) -> Ticked {
        let points = match self {
            Axis::Robots => {
                let (first, last) = (lo.ceil().max(0.0) as u64, hi.floor().max(0.0) as u64);
                let step = (last.saturating_sub(first) / 10).max(1) as usize;
                (first..=last).step_by(step).map(|n| n as f64).collect()
            }
            Axis::Rc => {
                let r: RangedCoordf64 = (lo..hi).into();
                r.key_points(10)
            }
        };
        Ticked {
            range: (lo..hi).into(),
            ticks: points,
        }
    }

    /// A tick label: `3` for robots, `12.5` or `8` for R_C.
    fn tick(self, x: f64) -> String {
        match self {
            Axis::Robots => format!("{x:.0}"),
            Axis::Rc => {
                let s = format!("{x:.3}");
                s.trim_end_matches('0').trim_end_matches('.').to_string()
            }
        }
    }
}

/// An f64 axis with the ticks given (plotters' own f64 axis picks its ticks, 1.0, 1.5, …).
struct Ticked {
    range: RangedCoordf64,
    ticks: Vec<f64>,
}

impl Ranged for Ticked {
    type ValueType = f64;
    type FormatOption = DefaultFormatting;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.range.map(value, limit)
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            Vec::new()
        } else {
            self.ticks.clone()
        }
    }

    fn range(&self) -> Range<f64> {
        self.range.range()
    }
}

/// One line of a chart: the points sharing every setting but the axis', by x.
struct Line<'a> {
    key: PointKey,
    points: Vec<&'a Point>,
}

/// The lines of a chart; where some have two x values or more, only those (a line of one point
/// says nothing about the axis).
fn lines(points: &[Point], axis: Axis) -> Vec<Line<'_>> {
    let mut out: Vec<Line<'_>> = Vec::new();
    for p in points {
        let fixed = |k: &PointKey| match axis {
            Axis::Robots => PointKey { robots: 0, ..*k },
            Axis::Rc => PointKey { rc_m: 0.0, ..*k },
        };
        match out.iter_mut().find(|l| fixed(&l.key) == fixed(&p.key)) {
            Some(l) => l.points.push(p),
            None => out.push(Line {
                key: p.key,
                points: vec![p],
            }),
        }
    }
    for l in &mut out {
        l.points
            .sort_by(|a, b| axis.x(&a.key).total_cmp(&axis.x(&b.key)));
    }
    // Without merging R_C changes nothing (the sweep runs those points at one R_C): on the R_C
    // chart they stay, drawn across the axis.
    if out.iter().any(|l| l.points.len() > 1) {
        out.retain(|l| l.points.len() > 1 || (axis == Axis::Rc && !l.key.merge));
    }
    out
}

/// A sweep chart: exploration (%) against the axis' setting.
type Chart<'a, 'b> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<Ticked, RangedCoordf64>>;

/// What [`chart`] drew: the picture, its plotting area (x and y pixel ranges), the legend's box
/// under it (x0, y0, x1, y1) and the pixels of the paper's marks.
type Drawn = (Picture, (Range<i32>, Range<i32>), [i32; 4], Vec<(i32, i32)>);

/// The chart of one axis: each line's mean ± sd against the axis' setting, the paper's values
/// in black, the legend in a band under the chart (it covers no data).
fn chart(
    r: &SweepResult,
    paper: &[PaperValue],
    axis: Axis,
    subtitle: &str,
) -> Result<Drawn, String> {
    let figure = r.figure;
    let lines = lines(&r.points, axis);
    let (lo, hi) = x_span(&lines, axis);
    // The axis holds the paper's marks too, so that none is cut at the edge.
    let (plo, phi) = paper_x_span(r, paper, axis).unwrap_or((lo, hi));
    let (lo, hi) = (lo.min(plo), hi.max(phi));
    let pad = ((hi - lo) * 0.06).max(0.5);
    let (title, x_desc) = titles(axis);
    let mut top = blank();
    let mut entries = Vec::new();
    let (plot, paper_px) = {
        let root = top.area()?;
        let root = &root;
        let area = titled(root, title, subtitle)?;
        let mut chart = ChartBuilder::on(&area)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d(axis.x_coord(lo - pad, hi + pad), 0.0..105.0)
            .map_err(msg)?;
        let tick = |x: &f64| axis.tick(*x);
        chart
            .configure_mesh()
            .x_label_formatter(&tick)
            .light_line_style(WHITE)
            .bold_line_style(RGBColor(225, 225, 225))
            .label_style(text(14))
            .axis_desc_style(text(15))
            .x_desc(x_desc)
            .y_desc(format!("sectors {}, mean per robot (%)", figure.name()))
            .draw()
            .map_err(msg)?;
        // One colour per line whatever its merge setting; merge off dashed.
        let mut colours: Vec<PointKey> = Vec::new();
        for l in &lines {
            let rgb: Rgb = series_rgb(colour_index(&mut colours, axis, &l.key));
            let label = draw_line(&mut chart, l, axis, rgb, (lo, hi), pad, figure)?;
            let solid = l.key.merge;
            entries.push((Sample::Line { solid, rgb }, label));
        }
        let mut paper_px = Vec::new();
        for (sample, label, points) in draw_paper(&mut chart, r, paper, axis)? {
            entries.push((sample, label));
            paper_px.extend(points.iter().map(|p| chart.backend_coord(p)));
        }
        let plot = chart.plotting_area().get_pixel_range();
        root.present().map_err(msg)?;
        (plot, paper_px)
    };
    let (pic, legend) = with_legend(&top, &entries)?;
    Ok((pic, plot, legend, paper_px))
}

/// The lowest and highest x of the paper's marks [`draw_paper`] draws on `axis`, if any.
fn paper_x_span(r: &SweepResult, paper: &[PaperValue], axis: Axis) -> Option<(f64, f64)> {
    let ran = |p: &&PaperValue| r.points.iter().any(|x| x.key.strategy == p.strategy);
    let xs = paper
        .iter()
        .filter(ran)
        .filter_map(|p| match (axis, p.kind, p.robots) {
            (Axis::Robots, PaperKind::MeanPct | PaperKind::MaxPct, Some(n)) => Some(n as f64),
            (Axis::Rc, PaperKind::PeakRcM, _) => Some(p.value),
            _ => None,
        });
    xs.fold(None, |span, x| match span {
        None => Some((x, x)),
        Some((a, b)) => Some((x.min(a), x.max(b))),
    })
}

/// The lowest and highest x of the lines' points ((0, 1) if there is none).
fn x_span(lines: &[Line<'_>], axis: Axis) -> (f64, f64) {
    let xs = lines
        .iter()
        .flat_map(|l| l.points.iter().map(|p| axis.x(&p.key)));
    let (lo, hi) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    if lo.is_finite() {
        (lo, hi)
    } else {
        (0.0, 1.0)
    }
}

/// The chart's title and the x axis' description.
fn titles(axis: Axis) -> (&'static str, &'static str) {
    match axis {
        Axis::Robots => (
            "Exploration against the number of robots, with and without merging",
            "robots",
        ),
        Axis::Rc => (
            "Exploration against the communication radius R_C",
            "R_C (m)",
        ),
    }
}

/// The colour index of a line: the same for both merge settings of a key, new keys appended.
fn colour_index(colours: &mut Vec<PointKey>, axis: Axis, key: &PointKey) -> usize {
    let base = PointKey {
        merge: true,
        ..*key
    };
    match colours
        .iter()
        .position(|k| axis.label(k) == axis.label(&base))
    {
        Some(i) => i,
        None => {
            colours.push(base);
            colours.len() - 1
        }
    }
}

/// Draws one line (dashed without merging), its error bars and dots; returns the legend entry's
/// text.
fn draw_line<'a, 'b: 'a>(
    chart: &mut Chart<'a, 'b>,
    l: &Line<'_>,
    axis: Axis,
    rgb: Rgb,
    (lo, hi): (f64, f64),
    pad: f64,
    figure: pheromone_sim::sweep::Figure,
) -> Result<String, String> {
    let style = colour(rgb).stroke_width(2);
    let mut xy: Vec<(f64, f64)> = l
        .points
        .iter()
        .map(|p| (axis.x(&p.key), 100.0 * p.figure(figure).mean))
        .collect();
    let across = axis == Axis::Rc && !l.key.merge && xy.len() == 1 && hi > lo;
    if across {
        xy = vec![(lo, xy[0].1), (hi, xy[0].1)];
    }
    if l.key.merge {
        chart
            .draw_series(LineSeries::new(xy.clone(), style))
            .map_err(msg)?;
    } else {
        chart
            .draw_series(std::iter::once(DashedPathElement::new(
                xy.clone(),
                8,
                5,
                style,
            )))
            .map_err(msg)?;
    }
    let merge = l.key.merge;
    let label = line_label(l, axis, across);
    draw_error_bars(chart, l, axis, style, 0.12 * pad, figure)?;
    // The dots: filled with merging, rings (white inside) without.
    let xy: Vec<(f64, f64)> = l
        .points
        .iter()
        .map(|p| (axis.x(&p.key), 100.0 * p.figure(figure).mean))
        .collect();
    let fill = if merge { colour(rgb) } else { WHITE };
    chart
        .draw_series(xy.iter().map(|&p| Circle::new(p, 4, fill.filled())))
        .map_err(msg)?;
    if !merge {
        chart
            .draw_series(
                xy.iter()
                    .map(|&p| Circle::new(p, 4, colour(rgb).stroke_width(2))),
            )
            .map_err(msg)?;
    }
    Ok(label)
}

/// A line's legend text; a no-merge line drawn across the R_C axis says so.
fn line_label(l: &Line<'_>, axis: Axis, across: bool) -> String {
    if across {
        format!(
            "no merge: {}, {}, {} robot(s) (any R_C)",
            l.key.strategy.name(),
            l.key.steer_on.name(),
            l.key.robots
        )
    } else {
        axis.label(&l.key)
    }
}

/// Error bars: mean ± sd, capped (plotters' ErrorBar needs a feature; three lines).
fn draw_error_bars<'a, 'b: 'a>(
    chart: &mut Chart<'a, 'b>,
    l: &Line<'_>,
    axis: Axis,
    style: ShapeStyle,
    cap: f64,
    figure: pheromone_sim::sweep::Figure,
) -> Result<(), String> {
    for p in &l.points {
        let x = axis.x(&p.key);
        let m = p.figure(figure);
        let (m, s) = (100.0 * m.mean, 100.0 * m.sd);
        let (y0, y1) = ((m - s).max(0.0), (m + s).min(105.0));
        chart
            .draw_series([
                PathElement::new(vec![(x, y0), (x, y1)], style),
                PathElement::new(vec![(x - cap, y0), (x + cap, y0)], style),
                PathElement::new(vec![(x - cap, y1), (x + cap, y1)], style),
            ])
            .map_err(msg)?;
    }
    Ok(())
}

/// A paper value's legend sample and text, and the chart points its mark covers.
type PaperMark = (Sample, String, Vec<(f64, f64)>);

/// The paper's values on a chart, in black: on the robots axis a cross at each percentage of a
/// strategy the sweep ran (Tables 2 and 6); on the R_C axis a dotted vertical line at its peak
/// (Table 9). Each has a legend entry citing its table. Returns each entry's sample and text and
/// the points its mark covers.
fn draw_paper<'a, 'b: 'a>(
    chart: &mut Chart<'a, 'b>,
    r: &SweepResult,
    paper: &[PaperValue],
    axis: Axis,
) -> Result<Vec<PaperMark>, String> {
    let mut drawn = Vec::new();
    let black = colour([0, 0, 0]).stroke_width(2);
    let ran = |p: &PaperValue| r.points.iter().any(|x| x.key.strategy == p.strategy);
    for p in paper.iter().filter(|p| ran(p)) {
        match (axis, p.kind, p.robots) {
            (Axis::Robots, PaperKind::MeanPct | PaperKind::MaxPct, Some(n)) => {
                let at = (n as f64, p.value);
                let words = if p.kind == PaperKind::MeanPct {
                    "mean"
                } else {
                    "at most"
                };
                let label = format!(
                    "paper, Table {}: {}, {n} robots, {words} {} %",
                    p.table,
                    p.strategy.name(),
                    p.value
                );
                drawn.push((Sample::Cross, label, vec![at]));
                chart
                    .draw_series(std::iter::once(Cross::new(at, 6, black)))
                    .map_err(msg)?;
            }
            (Axis::Rc, PaperKind::PeakRcM, _) => {
                chart
                    .draw_series(std::iter::once(DashedPathElement::new(
                        vec![(p.value, 0.0), (p.value, 105.0)],
                        2,
                        4,
                        black,
                    )))
                    .map_err(msg)?;
                let label = format!("paper, Table {}: peak at R_C = {} m", p.table, p.value);
                let line = (0..=21).map(|k| (p.value, 5.0 * k as f64)).collect();
                drawn.push((Sample::Dotted, label, line));
            }
            _ => {}
        }
    }
    Ok(drawn)
}

#[cfg(test)]
mod tests {
    use super::*;
    use pheromone_roles::follower::StrategyKind;
    use pheromone_roles::mapper::SteerOn;
    use pheromone_sim::sweep::{comparisons, points, Figure, RunResult};

    fn run(robots: usize, merge: bool, seed: u64, known: f64) -> RunResult {
        RunResult {
            point: PointKey {
                robots,
                rc_m: 8.0,
                merge,
                strategy: StrategyKind::Inverse,
                steer_on: SteerOn::OwnMap,
                integration: Default::default(),
            },
            seed,
            known_mean: known,
            known_team: known,
            merged_mean: known,
            merged_team: known,
            visited_mean: 0.5,
            visited_team: 0.6,
            merges: 3,
            alignment_error_m: merge.then_some(0.25),
            wall_s: 0.1,
        }
    }

    /// A sweep of 1 and 4 robots with and without merging at R_C = 8 m, two seeds each; with
    /// `rc_m` = 4 m too if `two_radii`.
    fn small_sweep(two_radii: bool) -> SweepResult {
        let mut runs = Vec::new();
        for (robots, merge, known) in [
            (1, true, 0.5),
            (1, false, 0.5),
            (4, true, 0.95),
            (4, false, 0.55),
        ] {
            for seed in 1..=2 {
                runs.push(run(robots, merge, seed, known + 0.05 * seed as f64));
            }
        }
        if two_radii {
            for x in runs.clone() {
                runs.push(RunResult {
                    point: PointKey {
                        rc_m: 4.0,
                        ..x.point
                    },
                    ..x
                });
            }
        }
        sweep_of(runs)
    }

    /// The sweep result of `runs` (ias-ss, 10 s, 2 seeds, the known figure).
    fn sweep_of(runs: Vec<RunResult>) -> SweepResult {
        let pts = points(&runs);
        SweepResult {
            scenario: "ias-ss".into(),
            duration_s: 10.0,
            trials: 2,
            sectors: 24,
            jobs: 2,
            figure: Figure::Known,
            wall_s: 1.0,
            comparisons: comparisons(&runs, &pts, Figure::Known),
            points: pts,
            runs,
        }
    }

    /// Issue 51: the legend sits in a band under the chart, its box clear of the plotting
    /// area; every entry's sample is inside the box; the paper's marks (Table 6's 5 robots on a
    /// 1–4 robot sweep, Table 9's peak at 24 m on a 4–8 m one) are inside the axes; a subtitle
    /// too long for one line wraps instead of running off the picture.
    #[test]
    fn the_legend_sits_under_the_plot_and_the_papers_marks_inside_it() {
        let paper = pheromone_sim::paper::seed004().unwrap();
        let long = "a subtitle of many words ".repeat(8);
        for (axis, r) in [
            (Axis::Robots, small_sweep(false)),
            (Axis::Rc, small_sweep(true)),
        ] {
            let (pic, (xs, ys), b, paper_px) = chart(&r, &paper, axis, &long).unwrap();
            assert!(
                ys.end <= b[1],
                "{axis:?}: the legend box {b:?} overlaps the plot {ys:?}"
            );
            assert!(
                b[0] >= 0 && b[2] < pic.width as i32 && b[3] < pic.height as i32,
                "{axis:?}: {b:?} outside the picture"
            );
            assert!(!paper_px.is_empty(), "{axis:?}: the paper's mark is drawn");
            for (x, y) in paper_px {
                assert!(
                    xs.contains(&x) && ys.contains(&y),
                    "{axis:?}: the paper at ({x}, {y})"
                );
            }
            // The first line's colour (merge, solid) in the box: its sample.
            let first = series_rgb(0);
            let in_box = (b[1]..b[3])
                .any(|y| (b[0]..b[2]).any(|x| pic.get(x as usize, y as usize) == first));
            assert!(in_box, "{axis:?}: no sample in the legend");
            // The subtitle wraps: nothing drawn in the picture's last 4 columns above the plot.
            for y in 0..ys.start as usize {
                for x in pic.width as usize - 4..pic.width as usize {
                    assert_eq!(
                        pic.get(x, y),
                        [255, 255, 255],
                        "{axis:?}: text at ({x}, {y})"
                    );
                }
            }
        }
    }

    #[test]
    fn the_files_hold_every_run_and_point_and_the_charts_are_pngs() {
        let runs = vec![
            run(1, true, 1, 0.5),
            run(1, true, 2, 0.6),
            run(1, false, 1, 0.5),
            run(1, false, 2, 0.55),
            run(4, true, 1, 0.9),
            run(4, true, 2, 1.0),
            run(4, false, 1, 0.5),
            run(4, false, 2, 0.6),
        ];
        let r = sweep_of(runs);
        assert_eq!(r.points.len(), 4);
        assert!((r.points[0].known_mean.mean - 0.55).abs() < 1e-12);
        // 4 robots: on 0.95 ± 0.0707, off 0.55 ± 0.0707: Welch t = 0.4 / 0.0707 = 5.657, df 2.
        let c = &r.comparisons[1];
        assert_eq!((c.a.robots, c.kind), (4, "merge"));
        let w = c.welch.unwrap();
        assert!(
            (w.t - 5.656_854).abs() < 1e-5 && (w.df - 2.0).abs() < 1e-9,
            "{w:?}"
        );
        assert_eq!(c.paired, None, "equal differences: undefined");
        let dir = std::env::temp_dir().join(format!("sweep-report-{}", std::process::id()));
        let paper = pheromone_sim::paper::seed004().unwrap();
        let files = write_sweep(&dir, &r, &paper).unwrap();
        // One R_C (8 m): no R_C chart.
        assert_eq!(rc_values(&r), [8.0]);
        assert_eq!(files.len(), 5, "{files:?}");
        assert!(!dir.join("sweep_rc.png").exists());
        let csv = fs::read_to_string(dir.join("sweep.csv")).unwrap();
        assert_eq!(csv.lines().count(), 1 + 8);
        assert!(csv
            .lines()
            .nth(1)
            .unwrap()
            .starts_with("1,8,true,inverse,own-map,average,0,1,0.5,"));
        // The paper beside ours: every value of the paper's file, its table first.
        let md = fs::read_to_string(dir.join("sweep_paper.md")).unwrap();
        assert_eq!(
            md.lines()
                .filter(|l| l.starts_with("| ")
                    && !l.starts_with("| table")
                    && !l.starts_with("| ---"))
                .count(),
            paper.len()
        );
        assert!(
            md.contains("| 6 | mean 80 % (inverse, integration, 5 robots) | not in this sweep |"),
            "{md}"
        );
        assert!(
            md.contains("| 8 | every paired t > 1.83 (inverse, integration) | own-map: "),
            "{md}"
        );
        let json: serde_json::Value =
            serde_json::from_str(&fs::read_to_string(dir.join("sweep.json")).unwrap()).unwrap();
        assert_eq!(json["points"].as_array().unwrap().len(), 4);
        assert_eq!(json["points"][0]["strategy"], "inverse");
        let b = fs::read(dir.join("sweep_robots.png")).unwrap();
        assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n");
        // Two radii: both charts.
        let mut runs = r.runs.clone();
        for x in &r.runs {
            runs.push(RunResult {
                point: PointKey {
                    rc_m: 4.0,
                    ..x.point
                },
                ..x.clone()
            });
        }
        let pts = points(&runs);
        let r2 = SweepResult {
            comparisons: comparisons(&runs, &pts, Figure::Known),
            points: pts,
            runs,
            ..r
        };
        assert_eq!(rc_values(&r2), [4.0, 8.0]);
        let files = write_sweep(&dir, &r2, &paper).unwrap();
        assert_eq!(files.len(), 6, "{files:?}");
        let md = fs::read_to_string(dir.join("sweep_paper.md")).unwrap();
        // Table 9 is about 5 robots: this sweep has none.
        assert!(
            md.contains("| 9 | peak at R_C = 24 m, slow decay beyond (inverse, integration, 5 robots) | not in this sweep |"),
            "{md}"
        );
        assert!(dir.join("sweep_rc.png").is_file());
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_robot_axis_has_whole_number_ticks_and_the_legend_names_merge_first() {
        let x = Axis::Robots.x_coord(0.5, 8.5);
        assert_eq!(x.ticks, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]);
        assert_eq!(Axis::Robots.tick(3.0), "3");
        let wide = Axis::Robots.x_coord(0.0, 40.0);
        assert!(wide.ticks.iter().all(|v| v.fract() == 0.0));
        assert!(wide.ticks.len() <= 11, "{:?}", wide.ticks);
        assert_eq!(Axis::Rc.tick(12.5), "12.5");
        assert_eq!(Axis::Rc.tick(8.0), "8");
        let key = run(2, true, 1, 0.5).point;
        assert_eq!(
            Axis::Robots.label(&key),
            "merge: inverse, own-map, R_C = 8 m"
        );
        let off = PointKey {
            merge: false,
            ..key
        };
        assert_eq!(
            Axis::Robots.label(&off),
            "no merge: inverse, own-map, R_C = 8 m"
        );
    }
}
