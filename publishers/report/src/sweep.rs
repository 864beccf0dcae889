//! What `pheromone sweep` writes: `sweep.csv` (one row per run), `sweep.json` (the points with
//! mean ± sd, the comparisons with Welch's and the paired t) and two charts drawn like the
//! run's (plotters, `PLOT_W_PX` × `PLOT_H_PX`): `sweep_robots.png`, exploration against the
//! number of robots with and without merging, and `sweep_rc.png`, exploration against R_C.
//! Both plot `exploration_known` mean per robot, mean ± sd over the trials (error bars); merge
//! off is dashed.

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use plotters::coord::types::RangedCoordf64;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use super::files::{write_file, write_png};
use super::plots::{blank, series_labels, text, titled};
use super::style::{colour, msg, series_rgb, Picture, Rgb};
use super::ReportError;
use sim::sweep::{Point, PointKey, SweepResult};

/// Header of `sweep.csv`.
pub const SWEEP_CSV_HEADER: &str = "robots,rc_m,merge,strategy,seed,known_mean,known_team,\
visited_mean,visited_team,merges,alignment_error_m,wall_s";

/// `sweep.csv`: one row per run, in grid order.
pub fn sweep_csv(r: &SweepResult) -> String {
    let mut text = String::from(SWEEP_CSV_HEADER);
    text.push('\n');
    for x in &r.runs {
        // Writing into a String cannot fail.
        let _ = writeln!(
            text,
            "{},{},{},{},{},{},{},{},{},{},{},{}",
            x.point.robots,
            x.point.rc_m,
            x.point.merge,
            x.point.strategy.name(),
            x.seed,
            x.known_mean,
            x.known_team,
            x.visited_mean,
            x.visited_team,
            x.merges,
            x.alignment_error_m
                .map(|e| e.to_string())
                .unwrap_or_default(),
            x.wall_s,
        );
    }
    text
}

/// Writes `sweep.csv`, `sweep.json`, `sweep_robots.png` and `sweep_rc.png` into `dir` (created
/// if needed) and returns the paths written.
pub fn write_sweep(dir: &Path, r: &SweepResult) -> Result<Vec<PathBuf>, ReportError> {
    fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut written = Vec::new();
    let path = dir.join("sweep.csv");
    write_file(&path, sweep_csv(r).as_bytes())?;
    written.push(path);
    let path = dir.join("sweep.json");
    let json = serde_json::to_string_pretty(r).map_err(|source| ReportError::Json {
        path: path.clone(),
        source,
    })?;
    write_file(&path, json.as_bytes())?;
    written.push(path);
    let subtitle = format!(
        "'{}', {} s, {} trial(s) per point (seeds 1..={}); known: visited or merged, mean per robot over the {} sectors; mean ± sd",
        r.scenario, r.duration_s, r.trials, r.trials, r.sectors
    );
    for (name, axis) in [
        ("sweep_robots.png", Axis::Robots),
        ("sweep_rc.png", Axis::Rc),
    ] {
        let path = dir.join(name);
        let pic = chart(&r.points, axis, &subtitle).map_err(|detail| ReportError::Draw {
            path: path.clone(),
            detail,
        })?;
        write_png(&path, &pic)?;
        written.push(path);
    }
    Ok(written)
}

#[derive(Clone, Copy, PartialEq)]
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

    /// The settings a line keeps fixed, in words.
    fn label(self, k: &PointKey) -> String {
        let merge = if k.merge { "merge" } else { "no merge" };
        match self {
            Axis::Robots => format!("{}, {merge}, R_C = {} m", k.strategy.name(), k.rc_m),
            Axis::Rc => format!("{}, {merge}, {} robot(s)", k.strategy.name(), k.robots),
        }
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
type Chart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The chart of one axis: each line's mean ± sd against the axis' setting.
fn chart(points: &[Point], axis: Axis, subtitle: &str) -> Result<Picture, String> {
    let lines = lines(points, axis);
    let (lo, hi) = x_span(&lines, axis);
    let pad = ((hi - lo) * 0.06).max(0.5);
    let (title, x_desc) = titles(axis);
    let mut pic = blank();
    {
        let root = pic.area()?;
        let root = &root;
        let area = titled(root, title, subtitle)?;
        let mut chart = ChartBuilder::on(&area)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d((lo - pad)..(hi + pad), 0.0..105.0)
            .map_err(msg)?;
        chart
            .configure_mesh()
            .light_line_style(WHITE)
            .bold_line_style(RGBColor(225, 225, 225))
            .label_style(text(14))
            .axis_desc_style(text(15))
            .x_desc(x_desc)
            .y_desc("sectors known, mean per robot (%)")
            .draw()
            .map_err(msg)?;
        // One colour per line whatever its merge setting; merge off dashed.
        let mut colours: Vec<PointKey> = Vec::new();
        for l in &lines {
            let rgb: Rgb = series_rgb(colour_index(&mut colours, axis, &l.key));
            draw_line(&mut chart, l, axis, rgb, (lo, hi), pad)?;
        }
        series_labels(&mut chart, SeriesLabelPosition::LowerRight)?;
        root.present().map_err(msg)?;
    }
    Ok(pic)
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

/// Draws one line (dashed without merging), its legend entry, error bars and dots.
fn draw_line<'a, 'b: 'a>(
    chart: &mut Chart<'a, 'b>,
    l: &Line<'_>,
    axis: Axis,
    rgb: Rgb,
    (lo, hi): (f64, f64),
    pad: f64,
) -> Result<(), String> {
    let style = colour(rgb).stroke_width(2);
    let mut xy: Vec<(f64, f64)> = l
        .points
        .iter()
        .map(|p| (axis.x(&p.key), 100.0 * p.known_mean.mean))
        .collect();
    let across = axis == Axis::Rc && !l.key.merge && xy.len() == 1 && hi > lo;
    if across {
        xy = vec![(lo, xy[0].1), (hi, xy[0].1)];
    }
    let anno = if l.key.merge {
        chart
            .draw_series(LineSeries::new(xy.clone(), style))
            .map_err(msg)?
    } else {
        chart
            .draw_series(std::iter::once(DashedPathElement::new(
                xy.clone(),
                8,
                5,
                style,
            )))
            .map_err(msg)?
    };
    let dashed = !l.key.merge;
    anno.label(line_label(l, axis, across))
        .legend(move |(x, y)| {
            let st = colour(rgb).stroke_width(2);
            let mid = if dashed {
                vec![]
            } else {
                vec![(9, 0), (15, 0)]
            };
            EmptyElement::at((x, y))
                + PathElement::new(vec![(0, 0), (9, 0)], st)
                + PathElement::new(mid, st)
                + PathElement::new(vec![(15, 0), (24, 0)], st)
                + Circle::new((12, 0), 4, colour(rgb).filled())
        });
    draw_error_bars(chart, l, axis, style, 0.12 * pad)?;
    chart
        .draw_series(l.points.iter().map(|p| {
            let xy = (axis.x(&p.key), 100.0 * p.known_mean.mean);
            Circle::new(xy, 4, colour(rgb).filled())
        }))
        .map_err(msg)?;
    Ok(())
}

/// A line's legend text; a no-merge line drawn across the R_C axis says so.
fn line_label(l: &Line<'_>, axis: Axis, across: bool) -> String {
    if across {
        format!(
            "{}, no merge, {} robot(s) (any R_C)",
            l.key.strategy.name(),
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
) -> Result<(), String> {
    for p in &l.points {
        let x = axis.x(&p.key);
        let (m, s) = (100.0 * p.known_mean.mean, 100.0 * p.known_mean.sd);
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

#[cfg(test)]
mod tests {
    use super::*;
    use roles::follower::StrategyKind;
    use sim::sweep::{comparisons, points, RunResult};

    fn run(robots: usize, merge: bool, seed: u64, known: f64) -> RunResult {
        RunResult {
            point: PointKey {
                robots,
                rc_m: 8.0,
                merge,
                strategy: StrategyKind::Inverse,
            },
            seed,
            known_mean: known,
            known_team: known,
            visited_mean: 0.5,
            visited_team: 0.6,
            merges: 3,
            alignment_error_m: merge.then_some(0.25),
            wall_s: 0.1,
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
        let pts = points(&runs);
        let r = SweepResult {
            scenario: "ias-ss".into(),
            duration_s: 10.0,
            trials: 2,
            sectors: 24,
            jobs: 2,
            wall_s: 1.0,
            comparisons: comparisons(&runs, &pts),
            points: pts,
            runs,
        };
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
        let files = write_sweep(&dir, &r).unwrap();
        assert_eq!(files.len(), 4);
        let csv = fs::read_to_string(dir.join("sweep.csv")).unwrap();
        assert_eq!(csv.lines().count(), 1 + 8);
        assert!(csv
            .lines()
            .nth(1)
            .unwrap()
            .starts_with("1,8,true,inverse,1,0.5,"));
        let json: serde_json::Value =
            serde_json::from_str(&fs::read_to_string(dir.join("sweep.json")).unwrap()).unwrap();
        assert_eq!(json["points"].as_array().unwrap().len(), 4);
        assert_eq!(json["points"][0]["strategy"], "inverse");
        for png in ["sweep_robots.png", "sweep_rc.png"] {
            let b = fs::read(dir.join(png)).unwrap();
            assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n", "{png}");
        }
        fs::remove_dir_all(&dir).unwrap();
    }
}
