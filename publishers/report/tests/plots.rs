//! The charts `pheromone sim` writes (`pheromone_report::write_plots`), from real single-process runs of
//! the built-in scenarios: each is a PNG of the expected size that is not blank, and the series
//! it draws are the run's — its probe readings, its trajectories, its deposits — and end at
//! (or carry) the run's metrics.

use std::fs::{self, File};
use std::io::BufReader;
use std::path::{Path, PathBuf};

use pheromone_report::series::{
    exploration_over_time, leader_deposits, path_distances, probe_curves,
};
use pheromone_report::{write_outputs, write_plots, PLOT_H_PX, PLOT_W_PX};
use pheromone_sim::metrics::{distance_to_polyline_m, scenario_metrics, RunMetrics, RunMode};
use pheromone_sim::recording::Recording;
use pheromone_sim::single::{run_single_process, SingleProcessOptions};
use pheromone_world::scenario::{Overrides, Scenario};

/// A directory unique to the test, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new(tag: &str) -> TempDir {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.subsec_nanos())
            .unwrap_or(0);
        TempDir(std::env::temp_dir().join(format!(
            "pheromone-plots-{tag}-{}-{nanos}",
            std::process::id()
        )))
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}

fn run(name: &str, duration_s: Option<f64>) -> (Scenario, Recording, serde_json::Value) {
    let mut s = Scenario::load(name).unwrap();
    s.apply(&Overrides {
        duration_s,
        ..Overrides::default()
    })
    .unwrap();
    let (summary, rec) = run_single_process(&s, SingleProcessOptions::default()).unwrap();
    let m = RunMetrics::new(&s, &summary, &rec, RunMode::SingleProcess, 1.0);
    let m = serde_json::to_value(m).unwrap();
    (s, rec, m)
}

/// Writes what `pheromone sim` writes and returns the chart's path, after checking it is listed.
fn write_all(
    dir: &Path,
    s: &Scenario,
    rec: &Recording,
    m: &serde_json::Value,
    chart: &str,
) -> PathBuf {
    write_outputs(dir, rec, m, &pheromone_report::marks(s, rec)).unwrap();
    let written = write_plots(dir, s, rec).unwrap();
    let path = dir.join(chart);
    assert!(written.contains(&path), "{chart} not in {written:?}");
    path
}

/// Decodes an 8-bit RGB PNG and checks its size and that it shows something: many colours, and
/// a fair share of pixels that are neither white nor grey (the series).
fn assert_chart(path: &Path) {
    let file = File::open(path).unwrap();
    let mut reader = png::Decoder::new(BufReader::new(file)).read_info().unwrap();
    let mut buf = vec![0u8; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    assert_eq!(info.color_type, png::ColorType::Rgb, "{}", path.display());
    assert_eq!(
        (info.width, info.height),
        (PLOT_W_PX, PLOT_H_PX),
        "{}",
        path.display()
    );
    let pixels: Vec<[u8; 3]> = buf[..info.buffer_size()]
        .chunks(3)
        .map(|p| [p[0], p[1], p[2]])
        .collect();
    let coloured = pixels
        .iter()
        .filter(|p| {
            let (lo, hi) = (*p.iter().min().unwrap(), *p.iter().max().unwrap());
            hi - lo > 60
        })
        .count();
    let mut distinct = pixels.clone();
    distinct.sort();
    distinct.dedup();
    assert!(
        coloured > 1500 && distinct.len() > 100,
        "{}: {coloured} coloured pixels, {} colours: blank?",
        path.display(),
        distinct.len()
    );
}

fn csv_rows(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    (header, rows)
}

#[test]
fn evaporation_chart_draws_each_probe_against_its_closed_form() {
    let (s, rec, m) = run("evaporation", None);
    let curves = probe_curves(&s, &rec);
    assert_eq!(curves.len(), s.probes.len());
    // The dots are the run's readings, probe by probe, in the order recorded.
    for (c, spec) in curves.iter().zip(&s.probes) {
        let recorded: Vec<(f64, f32)> = rec
            .probes
            .iter()
            .filter(|p| p.x_m == c.x_m && p.y_m == c.y_m && p.channel == c.channel)
            .map(|p| (p.t_s, p.value))
            .collect();
        assert_eq!(c.readings, recorded);
        assert_eq!(c.readings.len(), spec.times_s.len());
    }
    // Closed forms: P0 = 50 and 35 without ambient, 35 on Pa = 10 with it, K = 0.0057 /s; the
    // ambient level is the model's own window mean around C (10 plus a little of the peak).
    let expected = [(50.0, 0.0), (35.0, 0.0), (35.0, 10.0)];
    for (c, (p0, pa)) in curves.iter().zip(expected) {
        let f = c.closed_form.expect("every channel here has a closed form");
        assert!((f.p0 - p0).abs() < 0.05, "{c:?}");
        assert!((f.ambient - pa).abs() < 0.2, "{c:?}");
        assert!((f.decay_per_s - 0.0057).abs() < 1e-6, "{c:?}");
        // …and the run follows it (seed 000 Figs. 6–8).
        for &(t, v) in &c.readings {
            let err = (v as f64 - f.at(t)).abs();
            assert!(
                err < 0.05 + 2e-3 * f.at(t),
                "{c:?} at {t} s: {v} vs {}",
                f.at(t)
            );
        }
    }
    let tmp = TempDir::new("evaporation");
    assert_chart(&write_all(&tmp.0, &s, &rec, &m, "probes.png"));
}

#[test]
fn exploration_chart_ends_at_the_run_metric() {
    let (s, rec, m) = run("ias-ss", Some(60.0));
    let metric = s.metrics.exploration.as_ref().unwrap();
    let series = exploration_over_time(metric, &rec);
    let e = &m["metrics"]["exploration"];
    assert_eq!(series.per_robot.len(), rec.robots.len());
    for (k, (id, points)) in series.per_robot.iter().enumerate() {
        assert_eq!(points.len(), rec.robots[id].len(), "one point per step");
        assert!(
            points.windows(2).all(|p| p[1].1 >= p[0].1),
            "never decreases"
        );
        assert_eq!(
            points.last().unwrap().1,
            e["per_robot"][k].as_f64().unwrap()
        );
    }
    let team = series.team.last().unwrap().1;
    assert_eq!(team, e["team"].as_f64().unwrap());
    // The team has seen at least what its best robot has, at every time.
    let best = series
        .per_robot
        .values()
        .map(|p| p.last().unwrap().1)
        .fold(0.0, f64::max);
    assert!(team >= best && team > 0.0, "{e}");

    let tmp = TempDir::new("ias-ss");
    let png = write_all(&tmp.0, &s, &rec, &m, "exploration.png");
    assert_chart(&png);
    // The CSV holds the same series.
    let (header, rows) = csv_rows(&tmp.0.join("exploration.csv"));
    assert_eq!(header.first().map(String::as_str), Some("t_s"));
    assert_eq!(header.last().map(String::as_str), Some("team"));
    assert_eq!(header.len(), 2 + rec.robots.len());
    assert_eq!(rows.len(), series.team.len());
    let last = rows.last().unwrap();
    assert_eq!(last.last().unwrap().parse::<f64>().unwrap(), team);
    for (k, v) in last[1..last.len() - 1].iter().enumerate() {
        assert_eq!(
            v.parse::<f64>().unwrap(),
            e["per_robot"][k].as_f64().unwrap()
        );
    }
}

#[test]
fn path_distance_chart_draws_the_trajectories_and_the_metric() {
    let (s, rec, m) = run("trail-following", None);
    let paths = path_distances(&s, &rec);
    assert_eq!(paths.len(), s.metrics.paths.len());
    let metrics = scenario_metrics(&s, &rec);
    for (p, spec) in paths.iter().zip(&s.metrics.paths) {
        let rows = &rec.robots[&p.robot];
        assert_eq!(p.points.len(), rows.len());
        for (q, r) in p.points.iter().zip(rows) {
            assert_eq!(q.0, r.t_s);
            let d = distance_to_polyline_m([r.true_pose[0], r.true_pose[1]], &spec.points);
            assert_eq!(q.1, d);
        }
        assert_eq!(
            p.mean_m,
            metrics.mean_path_error_m.as_ref().unwrap()[&p.name],
            "the dashed mean is the run's metric"
        );
        // Within the window the robot is on its path (seed 002's evaluation).
        let inside: Vec<f64> = p
            .points
            .iter()
            .filter(|q| q.0 >= p.from_s && q.0 <= p.to_s)
            .map(|q| q.1)
            .collect();
        assert!(
            !inside.is_empty() && inside.iter().all(|d| *d < 0.5),
            "{}",
            p.name
        );
    }
    let tmp = TempDir::new("trail-following");
    assert_chart(&write_all(&tmp.0, &s, &rec, &m, "path_distance.png"));
    let (header, rows) = csv_rows(&tmp.0.join("path_distance.csv"));
    assert_eq!(header, ["t_s", "path", "robot", "distance_m"]);
    assert_eq!(
        rows.len(),
        paths.iter().map(|p| p.points.len()).sum::<usize>()
    );
}

#[test]
fn leader_deposit_chart_shows_the_deposits_fade_where_the_leader_got_lost() {
    let (s, rec, m) = run("blind-leader", None);
    let metric = s.metrics.blind_leader.as_ref().unwrap();
    let d = leader_deposits(&s, metric, &rec);
    let b = &m["metrics"]["blind_leader"];
    let lost_m = b["leader_lost_at_m"].as_f64().unwrap();
    assert_eq!(
        d.metric.leader_lost_at_m,
        Some(lost_m),
        "the mark is the run's metric"
    );
    assert_eq!(
        d.metric.follower_abandoned_at_m,
        b["follower_abandoned_at_m"].as_f64()
    );
    // The dots are the deposit_peak column of the leader's CSV, in order.
    let tmp = TempDir::new("blind-leader");
    assert_chart(&write_all(&tmp.0, &s, &rec, &m, "leader_deposits.png"));
    let (header, rows) = csv_rows(&tmp.0.join(format!("robot_{}.csv", metric.leader)));
    let col = header.iter().position(|h| h == "deposit_peak").unwrap();
    let t_col = header.iter().position(|h| h == "t_s").unwrap();
    let from_csv: Vec<(f64, f32)> = rows
        .iter()
        .filter(|r| !r[col].is_empty())
        .map(|r| (r[t_col].parse().unwrap(), r[col].parse().unwrap()))
        .collect();
    let drawn: Vec<(f64, f32)> = d.deposits.iter().map(|p| (p.2, p.1)).collect();
    assert_eq!(drawn, from_csv);
    assert!(drawn.len() > 20, "{} deposits", drawn.len());
    // What the chart shows: well localized, the leader deposits at the cap (γmax = 100); two
    // metres past the loss, a small fraction of it.
    let before: Vec<f32> = d
        .deposits
        .iter()
        .filter(|p| p.0 < lost_m - 1.0)
        .map(|p| p.1)
        .collect();
    let after: Vec<f32> = d
        .deposits
        .iter()
        .filter(|p| p.0 > lost_m + 2.0)
        .map(|p| p.1)
        .collect();
    assert!(!before.is_empty() && !after.is_empty());
    let mean = |v: &[f32]| v.iter().map(|x| *x as f64).sum::<f64>() / v.len() as f64;
    assert!(mean(&before) > 50.0, "before the loss: {before:?}");
    assert!(
        mean(&after) < 0.2 * mean(&before),
        "after the loss: {after:?}"
    );
}
