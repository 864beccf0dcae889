//! What `pheromone sweep trail-following` writes (paper 002's parameter study,
//! `pheromone_sim::trail_sweep`): `sweep.csv` (one row per run and path: the parameter, its
//! value, whether it is the scenario's, the seed, the mean path error and the turning share),
//! `sweep.json` (the runs and the points, mean ± sd over the seeds) and `sweep_trail.png`: a
//! panel per parameter studied, the mean path error (mm, mean ± sd over the seeds) against
//! the parameter's value, a line per path, the scenario's own value a dotted black vertical
//! line and a larger dot on each path; one legend for all panels in a band under them.

use std::fs;
use std::path::{Path, PathBuf};

use plotters::element::DashedPathElement;
use plotters::prelude::*;

use super::files::{write_file, write_json, write_png};
use super::legend::{with_legend, Sample};
use super::plots::{text, PLOT_H_PX, PLOT_W_PX};
use super::style::{colour, msg, series_rgb, Picture};
use super::ReportError;
use pheromone_sim::trail_sweep::{TrailParam, TrailPoint, TrailSweep};

/// Header of the study's `sweep.csv`.
pub const TRAIL_CSV_HEADER: &str = "param,value,shipped,seed,path,mean_path_error_m,turning_share";

/// The study's `sweep.csv`: a row per run and path, in the study's order (a missing figure is
/// an empty field; `normalize_max` 0 is "by the larger reading").
pub fn trail_csv(r: &TrailSweep) -> String {
    let mut s = format!("{TRAIL_CSV_HEADER}\n");
    let f = |x: Option<f64>| x.map_or(String::new(), |v| format!("{v:.6}"));
    for x in &r.runs {
        s.push_str(&format!(
            "{},{},{},{},{},{},{}\n",
            x.param.name(),
            x.value,
            x.shipped,
            x.seed,
            x.path,
            f(x.mean_path_error_m),
            f(x.turning_share)
        ));
    }
    s
}

/// The study's lines on stderr: a line per parameter value and path.
pub fn trail_table(r: &TrailSweep) -> String {
    let mut s = String::new();
    for p in &r.points {
        let ms = |m: Option<pheromone_sim::sweep_stats::MeanSd>, k: f64, d: usize| {
            m.map_or("-".to_string(), |m| {
                format!("{:.d$} ± {:.d$}", k * m.mean, k * m.sd)
            })
        };
        s.push_str(&format!(
            "  {} = {}{}, {}: error {} m, turning {} %\n",
            p.param.name(),
            value_words(p.param, p.value),
            if p.shipped { " (the scenario's)" } else { "" },
            p.path,
            ms(p.mean_path_error_m, 1.0, 4),
            ms(p.turning_share, 100.0, 0),
        ));
    }
    s
}

fn value_words(p: TrailParam, v: f64) -> String {
    if p == TrailParam::Normalize && v == 0.0 {
        "max".to_string()
    } else {
        format!("{v}")
    }
}

/// Writes `sweep.csv`, `sweep.json` and `sweep_trail.png` into `dir`.
pub fn write_trail_sweep(dir: &Path, r: &TrailSweep) -> Result<Vec<PathBuf>, ReportError> {
    fs::create_dir_all(dir).map_err(|source| ReportError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let path = dir.join("sweep.csv");
    write_file(&path, trail_csv(r).as_bytes())?;
    let mut written = vec![path];
    let path = dir.join("sweep.json");
    write_json(&path, r)?;
    written.push(path);
    let path = dir.join("sweep_trail.png");
    let pic = chart(r).map_err(|detail| ReportError::Draw {
        path: path.clone(),
        detail,
    })?;
    write_png(&path, &pic)?;
    written.push(path);
    Ok(written)
}

/// The paths of the study, in the runs' order.
fn paths(r: &TrailSweep) -> Vec<&str> {
    let mut v: Vec<&str> = Vec::new();
    for x in &r.runs {
        if !v.contains(&x.path.as_str()) {
            v.push(&x.path);
        }
    }
    v
}

/// One panel per parameter studied, three to a row.
fn chart(r: &TrailSweep) -> Result<Picture, String> {
    let params: Vec<TrailParam> = r.shipped.keys().copied().collect();
    let cols = params.len().clamp(1, 3);
    let rows = params.len().div_ceil(3).max(1);
    let (w, h) = (
        PLOT_W_PX * cols as u32 / 2,
        70 + PLOT_H_PX * rows as u32 * 3 / 4,
    );
    let mut pic = Picture::new(w.max(PLOT_W_PX), h, [255, 255, 255]);
    {
        let root = pic.area()?;
        root.draw_text(
            &format!("Paper 002's parameter study: '{}'", r.scenario),
            &text(22),
            (16, 10),
        )
        .map_err(msg)?;
        let sub = format!(
            "mean path error, mean ± sd over seeds 1–{}; one setting varied at a time; dotted: the scenario's value",
            r.trials
        );
        let lines = super::summary::wrap(&sub, 14, w.max(PLOT_W_PX) as i32 - 32);
        for (i, line) in lines.iter().enumerate() {
            let y = 40 + 18 * i as i32;
            root.draw_text(line, &text(14).color(&RGBColor(80, 80, 80)), (16, y))
                .map_err(msg)?;
        }
        let body = root.margin(70 + 18 * (lines.len() as u32 - 1), 0, 0, 0);
        let panels = body.split_evenly((rows, cols));
        for (param, area) in params.iter().zip(panels.iter()) {
            panel(area, r, *param)?;
        }
        root.present().map_err(msg)?;
    }
    // One legend for every panel, in a band under them (outside every plotting area).
    let mut entries: Vec<(Sample, String)> = paths(r)
        .into_iter()
        .enumerate()
        .map(|(i, path)| {
            let rgb = series_rgb(i);
            (Sample::Line { solid: true, rgb }, format!("path '{path}'"))
        })
        .collect();
    entries.push((
        Sample::Dotted,
        "the scenario's own value (larger dot)".into(),
    ));
    Ok(with_legend(&pic, &entries)?.0)
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

/// A parameter's panel: a line per path, error bars, the scenario's value.
fn panel(area: &Area<'_>, r: &TrailSweep, param: TrailParam) -> Result<(), String> {
    let points: Vec<&TrailPoint> = r.points.iter().filter(|p| p.param == param).collect();
    let mm = |p: &TrailPoint| p.mean_path_error_m.map(|m| (1e3 * m.mean, 1e3 * m.sd));
    let (lo, hi) = points.iter().fold((f64::MAX, f64::MIN), |(a, b), p| {
        (a.min(p.value), b.max(p.value))
    });
    let pad = ((hi - lo) * 0.08).max(0.05 * hi.abs()).max(1e-3);
    let top = points
        .iter()
        .filter_map(|p| mm(p))
        .fold(1.0f64, |t, (m, s)| t.max(m + s))
        * 1.1;
    let mut chart = ChartBuilder::on(area)
        .margin(12)
        .caption(param.name(), text(16))
        .x_label_area_size(32)
        .y_label_area_size(52)
        .build_cartesian_2d((lo - pad)..(hi + pad), 0.0..top)
        .map_err(msg)?;
    let tick = |x: &f64| {
        if param == TrailParam::Normalize && *x == 0.0 {
            "max".to_string()
        } else {
            let s = format!("{x:.3}");
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        }
    };
    chart
        .configure_mesh()
        .x_label_formatter(&tick)
        .x_labels(6)
        .light_line_style(WHITE)
        .bold_line_style(RGBColor(225, 225, 225))
        .label_style(text(12))
        .axis_desc_style(text(13))
        .y_desc("mean path error (mm)")
        .draw()
        .map_err(msg)?;
    if let Some(&v) = r.shipped.get(&param) {
        chart
            .draw_series(std::iter::once(DashedPathElement::new(
                vec![(v, 0.0), (v, top)],
                3,
                4,
                BLACK.stroke_width(1),
            )))
            .map_err(msg)?;
    }
    for (i, path) in paths(r).into_iter().enumerate() {
        let style = colour(series_rgb(i)).stroke_width(2);
        let xy: Vec<(f64, f64, f64, bool)> = points
            .iter()
            .filter(|p| p.path == path)
            .filter_map(|p| mm(p).map(|(m, s)| (p.value, m, s, p.shipped)))
            .collect();
        chart
            .draw_series(LineSeries::new(
                xy.iter().map(|&(x, m, _, _)| (x, m)),
                style,
            ))
            .map_err(msg)?;
        let cap = 0.15 * pad;
        for &(x, m, s, shipped) in &xy {
            let (y0, y1) = ((m - s).max(0.0), m + s);
            chart
                .draw_series([
                    PathElement::new(vec![(x, y0), (x, y1)], style),
                    PathElement::new(vec![(x - cap, y0), (x + cap, y0)], style),
                    PathElement::new(vec![(x - cap, y1), (x + cap, y1)], style),
                ])
                .map_err(msg)?;
            let ring = if shipped { 6 } else { 3 };
            chart
                .draw_series(std::iter::once(Circle::new((x, m), ring, style.filled())))
                .map_err(msg)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use pheromone_sim::sweep_stats::MeanSd;
    use pheromone_sim::trail_sweep::TrailRun;

    /// Issue 51: one legend for every panel, under them: each path's colour in the band below
    /// the panels (outside every plotting area).
    #[test]
    fn the_legend_sits_under_the_panels() {
        let mut r = TrailSweep {
            scenario: "trail-following".into(),
            trials: 2,
            shipped: [(TrailParam::OmegaGain, 3.0)].into_iter().collect(),
            runs: Vec::new(),
            points: Vec::new(),
            simulations: 0,
        };
        for path in ["straight", "curved"] {
            for (value, err) in [(1.0, 0.03), (3.0, 0.01), (5.0, 0.02)] {
                r.runs.push(TrailRun {
                    param: TrailParam::OmegaGain,
                    value,
                    shipped: value == 3.0,
                    seed: 1,
                    path: path.into(),
                    mean_path_error_m: Some(err),
                    turning_share: Some(0.5),
                });
                r.points.push(TrailPoint {
                    param: TrailParam::OmegaGain,
                    value,
                    shipped: value == 3.0,
                    path: path.into(),
                    mean_path_error_m: Some(MeanSd {
                        mean: err,
                        sd: 0.002,
                        n: 2,
                    }),
                    turning_share: None,
                });
            }
        }
        let pic = chart(&r).unwrap();
        let panels_h = 70 + PLOT_H_PX as usize * 3 / 4;
        assert!(pic.height as usize > panels_h, "no band under the panels");
        for i in 0..2 {
            let rgb = series_rgb(i);
            let below = (panels_h..pic.height as usize)
                .any(|y| (0..pic.width as usize).any(|x| pic.get(x, y) == rgb));
            assert!(below, "path {i}'s sample is not under the panels");
        }
    }
}
