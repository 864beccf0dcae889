use super::super::tests::{decode as decode_png, sample, TempDir};
use super::*;
use pheromone_messages::FollowerState;
use pheromone_sim::metrics::{scenario_metrics, RunMode};
use pheromone_sim::recording::Snapshot;
use pheromone_sim::single::{FieldSummary, RunSummary};

/// A recording of `scenario`'s grid at `t_s`: a trail along y = 1.5 m, the leader (R0) driving
/// from x = 3 m at 0.5 m/s, R1 behind it, following until 30 s at x = 15 m, then lost.
fn run(scenario: &Scenario, t_s: f64) -> Recording {
    let f = &scenario.field;
    let mut planes = vec![0.0f32; (f.width * f.height) as usize];
    let row = (1.5 / f64::from(f.cell_size_m)) as u32;
    for x in 0..f.width / 2 {
        planes[(row * f.width + x) as usize] = 5.0;
    }
    let mut rec = Recording::default();
    rec.snapshots.push(Snapshot {
        t_s,
        width: f.width,
        height: f.height,
        cell_size_m: f.cell_size_m,
        channels: vec!["R0 leader".into()],
        planes,
    });
    let leader = (0..=60)
        .map(|k| sample(f64::from(k), 3.0 + 0.5 * f64::from(k), 1.5))
        .collect();
    rec.robots.insert(0, leader);
    let follower = (0..=40)
        .map(|k| {
            let mut s = sample(f64::from(k), 0.5 * f64::from(k), 1.5);
            s.state = Some(if k < 30 {
                FollowerState::Following
            } else {
                FollowerState::LeaderLost
            });
            s
        })
        .collect();
    rec.robots.insert(1, follower);
    rec
}

fn headline_of(name: &str) -> Headline {
    let s = Scenario::load(name).unwrap();
    let rec = run(&s, 60.0);
    Headline::for_run(&s, &rec, &scenario_metrics(&s, &rec), 60.0, false)
}

/// Issue 51: blind-leader's headline says where the leader got lost (world x, as its marks)
/// and how far past it the follower followed; wrong-area's, where the leader got lost and where
/// the followers ended (A, B), with a line per robot.
#[test]
fn the_headline_is_the_scenarios_key_result() {
    let h = headline_of("blind-leader");
    assert_eq!(h.title, "blind-leader · seed 0 · 60.0 s simulated");
    assert!(
        h.headline
            .starts_with("R0 lost at x = 15.5 m (t = 25.0 s): R1 followed the trail"),
        "{}",
        h.headline
    );
    assert!(
        h.details
            .iter()
            .any(|d| d == "R1 gave the trail up at x = 15.0 m (t = 30.0 s)"),
        "{:?}",
        h.details
    );

    let h = headline_of("wrong-area");
    assert!(
        h.headline.contains("followers ended in A"),
        "{}",
        h.headline
    );
    assert!(h.headline.contains("reached B"), "{}", h.headline);
    assert!(
        h.details
            .iter()
            .any(|d| d.starts_with("R1 ended at (20.0, 1.5) m")),
        "{:?}",
        h.details
    );

    // ias-ss: the team's coverage and when it reached half of the sectors.
    let h = headline_of("ias-ss");
    assert!(h.headline.starts_with("Team visited "), "{}", h.headline);
    assert!(h.headline.contains(" sectors in 60 s"), "{}", h.headline);
    assert!(
        h.details[0].contains("half of the sectors"),
        "{:?}",
        h.details
    );

    // trail-following: each robot's mean path error.
    let h = headline_of("trail-following");
    assert!(
        h.headline.starts_with("Mean path error: R"),
        "{}",
        h.headline
    );

    // A scenario without metrics: how far the robots drove (30 m and 20 m).
    let h = headline_of("trail");
    assert_eq!(h.headline, "2 robot(s) drove 50.0 m in 60 s", "{h:?}");

    // A run stopped by a signal says so.
    let s = Scenario::load("blind-leader").unwrap();
    let rec = run(&s, 12.0);
    let h = Headline::for_run(&s, &rec, &scenario_metrics(&s, &rec), 12.0, true);
    assert!(
        h.title.ends_with("(stopped early by a signal)"),
        "{}",
        h.title
    );
}

/// The rows of `pic` (from `y0`) that hold a pixel of colour `rgb`.
fn rows_with(pic: &Picture, rgb: Rgb, y0: usize, y1: usize) -> Vec<usize> {
    (y0..y1)
        .filter(|&y| (0..pic.width as usize).any(|x| pic.get(x, y) == rgb))
        .collect()
}

/// The picture: the band holds the title, then the headline in its colour and large type, then
/// the details, all inside the picture's width; the run's picture sits under the band unchanged.
#[test]
fn the_summary_draws_the_headline_above_the_runs_picture() {
    let below = {
        let mut p = Picture::new(800, 300, [0, 0, 0]);
        for (i, px) in p.rgb.chunks_mut(3).enumerate() {
            px.copy_from_slice(&[(i % 251) as u8, (i % 241) as u8, 7]);
        }
        p
    };
    let h = Headline {
        title: "blind-leader · seed 1 · 80.0 s simulated".into(),
        headline: "R0 lost at x = 15.5 m (t = 25.0 s)".into(),
        details: vec!["R1 gave the trail up at x = 16.5 m (t = 36.0 s)".into()],
    };
    let pic = summary_picture(&h, &below).unwrap();
    let band = band_h_px(&h, 800) as usize;
    assert_eq!((pic.width, pic.height as usize), (800, band + 300));
    for y in 0..300 {
        for x in 0..800 {
            assert_eq!(pic.get(x, band + y), below.get(x, y), "({x}, {y}) below");
        }
    }
    let title = rows_with(&pic, TITLE_RGB, 0, band);
    let headline = rows_with(&pic, HEADLINE_RGB, 0, band);
    let detail = rows_with(&pic, DETAIL_RGB, 0, band);
    assert!(!title.is_empty() && !headline.is_empty() && !detail.is_empty());
    // In that order, the headline in the largest type.
    assert!(title.last() < headline.first() && headline.last() < detail.first());
    let span = |rows: &[usize]| rows.last().unwrap() - rows.first().unwrap();
    assert!(span(&headline) > span(&title) && span(&headline) > span(&detail));
    // Nothing of the text at the band's right edge.
    for y in 0..band {
        for x in 800 - MARGIN_PX as usize / 2..800 {
            assert_eq!(pic.get(x, y), BAND_RGB, "text at ({x}, {y})");
        }
    }

    // A headline too long for the width wraps onto more lines (a taller band), still inside.
    let long = Headline {
        headline: "R0 lost at x = 13.5 m (t = 20.0 s): 2 of 2 followers ended in A, 0 reached B, \
                   and this sentence goes on to be far wider than the picture"
            .into(),
        ..h.clone()
    };
    let narrow = summary_picture(&long, &below).unwrap();
    let band_long = band_h_px(&long, 800) as usize;
    assert!(band_long > band);
    let rows = rows_with(&narrow, HEADLINE_RGB, 0, band_long);
    assert!(span(&rows) > 2 * span(&headline), "{rows:?}");
    for y in 0..band_long {
        for x in 800 - MARGIN_PX as usize / 2..800 {
            assert_eq!(narrow.get(x, y), BAND_RGB, "text at ({x}, {y})");
        }
    }
    // A narrow run picture is centred in a picture of the least width.
    let small = Picture::new(200, 50, [1, 2, 3]);
    let pic = summary_picture(&h, &small).unwrap();
    assert_eq!(pic.width, MIN_W_PX);
    let x0 = (MIN_W_PX as usize - 200) / 2;
    assert_eq!(pic.get(x0, band + 10), [1, 2, 3]);
    assert_eq!(pic.get(x0 - 1, band + 10), BAND_RGB);
}

/// `write_summary` writes `summary.png`: the final heat map (`field_final.png`, pixel for
/// pixel) under the band.
#[test]
fn write_summary_puts_the_final_picture_under_the_headline() {
    let tmp = TempDir::new("summary");
    let s = Scenario::load("blind-leader").unwrap();
    let rec = run(&s, 60.0);
    let marks = super::super::marks(&s, &rec);
    let summary = RunSummary {
        steps: 600,
        sim_time_s: 60.0,
        ticks: 600,
        field: FieldSummary::default(),
        robots: Vec::new(),
        scripted_deposits: 0,
    };
    let metrics = RunMetrics::new(&s, &summary, &rec, RunMode::SingleProcess, 1.0);
    super::super::write_outputs(&tmp.0, &rec, &metrics, &marks).unwrap();
    let path = write_summary(&tmp.0, &s, &rec, &metrics, &marks).unwrap();
    assert_eq!(path, tmp.0.join("summary.png"));
    let fin = decode_png(&tmp.0.join("field_final.png"));
    let sum = decode_png(&path);
    let h = Headline::for_run(&s, &rec, &metrics.metrics, 60.0, false);
    let w = fin.0.max(MIN_W_PX);
    let band = band_h_px(&h, w);
    assert_eq!((sum.0, sum.1), (w, band + fin.1));
    let x0 = ((w - fin.0) / 2) as usize;
    let row = fin.0 as usize * 3;
    for y in 0..fin.1 as usize {
        let at = ((band as usize + y) * w as usize + x0) * 3;
        assert!(
            sum.2[at..at + row] == fin.2[y * row..(y + 1) * row],
            "row {y}"
        );
    }
    // The headline's colour is in the band.
    let headline_px = sum.2[..band as usize * w as usize * 3]
        .chunks(3)
        .filter(|p| *p == HEADLINE_RGB)
        .count();
    assert!(headline_px > 50, "{headline_px} headline pixels");
}
