//! `summary.png`: one picture per run with its headline, the scenario's key result in numbers,
//! over the run's final picture. A run of a world scenario: what ran (scenario, seed, simulated
//! time) and the headline its metrics give (`wrong_area`: where the leader got lost and where
//! the followers ended; `blind_leader`: where the leader got lost and how far past it the
//! follower followed; `exploration`: the team's coverage and when it reached half of the
//! sectors; path metrics: each robot's mean path error; probes: the largest gap between a
//! reading and its closed form; otherwise the distance the robots drove), over
//! `field_final.png`'s heat map. A regions run (paper 001's graph): the time until every region
//! was served per robot count and strategy, over the first run's graph picture.

use std::path::{Path, PathBuf};

use plotters::prelude::*;

use super::files::write_png;
use super::marks::{position_at, Mark};
use super::series;
use super::style::{colour, msg, Picture, Rgb, FONT};
use super::ReportError;
use pheromone_sim::metrics::{BlindLeader, Exploration, RunMetrics, ScenarioMetrics};
use pheromone_sim::recording::Recording;
use pheromone_sim::wrong_area::WrongArea;
use pheromone_world::scenario::Scenario;

/// The picture's file name.
pub const SUMMARY_PNG: &str = "summary.png";

/// Background of the band above the picture, and the colours of its three kinds of text (none
/// a blend of another with the background, so that a test tells them apart).
pub(super) const BAND_RGB: Rgb = [255, 255, 255];
pub(super) const TITLE_RGB: Rgb = [95, 80, 125];
/// The headline: a dark blue no picture below uses for text.
pub(super) const HEADLINE_RGB: Rgb = [10, 50, 150];
pub(super) const DETAIL_RGB: Rgb = [20, 20, 20];
/// Font sizes (px) of the title, the headline and the details.
const TITLE_PX: u32 = 18;
const HEADLINE_PX: u32 = 28;
const DETAIL_PX: u32 = 17;
/// Margin around the text (px) and the narrowest picture (px).
const MARGIN_PX: i32 = 14;
const MIN_W_PX: u32 = 760;

/// What a `summary.png` says: what ran, the key result, and further figures.
#[derive(Debug, Clone, PartialEq)]
pub struct Headline {
    /// What ran: scenario, seed, simulated time.
    pub title: String,
    /// The scenario's key result, in large type.
    pub headline: String,
    /// Further figures, one a line.
    pub details: Vec<String>,
}

impl Headline {
    /// The headline of a run of `scenario` whose metrics are `m`, `sim_time_s` simulated
    /// (`interrupted`: stopped early by a signal).
    pub fn for_run(
        scenario: &Scenario,
        rec: &Recording,
        m: &ScenarioMetrics,
        sim_time_s: f64,
        interrupted: bool,
    ) -> Headline {
        let title = format!(
            "{} · seed {} · {sim_time_s:.1} s simulated{}",
            scenario.name,
            scenario.seed,
            if interrupted {
                " (stopped early by a signal)"
            } else {
                ""
            }
        );
        let (headline, details) = if let Some(w) = &m.wrong_area {
            wrong_area(w)
        } else if let (Some(b), Some(cfg)) = (&m.blind_leader, &scenario.metrics.blind_leader) {
            blind_leader(b, rec, cfg.leader, cfg.follower)
        } else if let (Some(e), Some(cfg)) = (&m.exploration, &scenario.metrics.exploration) {
            exploration(e, &series::exploration_over_time(cfg, rec), m, sim_time_s)
        } else if let Some(errors) = &m.mean_path_error_m {
            path_error(scenario, errors, m)
        } else if !rec.probes.is_empty() {
            probes(&series::probe_curves(scenario, rec))
        } else {
            driven(rec, sim_time_s)
        };
        Headline {
            title,
            headline,
            details,
        }
    }
}

fn xy(p: [f64; 2]) -> String {
    format!("({:.1}, {:.1}) m", p[0], p[1])
}

fn percent(share: f64) -> String {
    format!("{:.0} %", share * 100.0)
}

/// `wrong_area`: where the leader got lost, how many followers ended in A or reached B; a line
/// per robot where it ended.
fn wrong_area(w: &WrongArea) -> (String, Vec<String>) {
    let lost = match (w.leader.lost_at_s, w.leader.lost_at_m) {
        (Some(t), Some(at)) => format!("R0 lost at x = {:.1} m (t = {t:.1} s)", at[0]),
        _ => "R0 never lost".to_string(),
    };
    let n = w.followers.len();
    let headline = format!(
        "{lost}: {} of {n} followers ended in A, {} reached B",
        w.followers_ended_in_a, w.followers_reached_b
    );
    let mut details = Vec::new();
    if let Some(end) = w.leader.true_final_m {
        let mut line = format!("R0 (leader) ended at {}", xy(end));
        if let Some(d) = w.leader.true_final_distance_to_b_m {
            line += &format!(", {d:.1} m from B");
        }
        if let Some(d) = w.leader.estimate_final_distance_to_a_m {
            line += &format!("; it believed itself {d:.1} m from A");
        }
        details.push(line);
    }
    for f in &w.followers {
        let Some(end) = f.final_m else { continue };
        let mut line = format!("R{} ended at {}", f.id, xy(end));
        match (f.ended_in_a, f.final_distance_to_a_m) {
            (true, _) => line += ", in A",
            (false, Some(d)) => line += &format!(", {d:.1} m from A"),
            _ => {}
        }
        if let Some(t) = f.reached_b_at_s {
            line += &format!(", reached B at t = {t:.1} s");
        }
        if let (Some(t), Some(at)) = (f.abandoned_at_s, f.abandoned_at_m) {
            line += &format!("; gave the trail up at x = {:.1} m (t = {t:.1} s)", at[0]);
        }
        details.push(line);
    }
    (headline, details)
}

/// `blind_leader`: where the leader got lost (world x) and how far past it the follower
/// followed the trail.
fn blind_leader(
    b: &BlindLeader,
    rec: &Recording,
    leader: u32,
    follower: u32,
) -> (String, Vec<String>) {
    let lost = match b.leader_lost_at_s {
        Some(t) => match position_at(rec, leader, t) {
            Some(at) => format!("R{leader} lost at x = {:.1} m (t = {t:.1} s)", at[0]),
            None => format!("R{leader} lost at t = {t:.1} s"),
        },
        None => format!("R{leader} never lost"),
    };
    let headline = match b.follower_followed_past_loss_m {
        Some(d) => format!("{lost}: R{follower} followed the trail {d:.1} m past it"),
        None => lost,
    };
    let mut details = Vec::new();
    if let Some(t) = b.follower_abandoned_at_s {
        match position_at(rec, follower, t) {
            Some(at) => details.push(format!(
                "R{follower} gave the trail up at x = {:.1} m (t = {t:.1} s)",
                at[0]
            )),
            None => details.push(format!("R{follower} gave the trail up at t = {t:.1} s")),
        }
    } else {
        details.push(format!("R{follower} never gave the trail up"));
    }
    details.push(format!(
        "R{follower} strayed at most {:.1} m from R{leader}'s path and drove {:.1} m",
        b.follower_max_off_leader_path_m, b.follower_distance_travelled_m
    ));
    if let Some(e) = b.leader_final_estimate_error_m {
        details.push(format!(
            "R{leader}'s estimate ended {e:.1} m from its true position"
        ));
    }
    (headline, details)
}

/// `exploration`: the team's share of the sectors at the end and when it reached half of them.
fn exploration(
    e: &Exploration,
    over_time: &series::ExplorationSeries,
    m: &ScenarioMetrics,
    sim_time_s: f64,
) -> (String, Vec<String>) {
    let headline = format!(
        "Team visited {} of {} sectors in {sim_time_s:.0} s",
        percent(e.team),
        e.sectors
    );
    let mut details = Vec::new();
    let half = over_time.team.iter().find(|&&(_, share)| share >= 0.5);
    details.push(match half {
        Some((t, _)) => format!("half of the sectors by t = {t:.1} s"),
        None => "never half of the sectors".to_string(),
    });
    let each: Vec<String> = over_time
        .per_robot
        .keys()
        .zip(&e.per_robot)
        .map(|(id, share)| format!("R{id} {}", percent(*share)))
        .collect();
    details.push(format!(
        "each robot: {} (mean {})",
        each.join(", "),
        percent(e.mean)
    ));
    if let Some(mapping) = &m.mapping {
        if let Some(merged) = &mapping.exploration_merged {
            details.push(format!(
                "visited or received by merges (paper 004's count): team {}, {} merges",
                percent(merged.team),
                mapping.merges
            ));
        }
        if let Some(known) = &mapping.exploration_known {
            details.push(format!(
                "mapped in the final maps: team {}",
                percent(known.team)
            ));
        }
    }
    (headline, details)
}

/// Path metrics: each robot's mean distance to its path, and how often it turned.
fn path_error(
    scenario: &Scenario,
    errors: &std::collections::BTreeMap<String, Option<f64>>,
    m: &ScenarioMetrics,
) -> (String, Vec<String>) {
    let robot_of = |name: &str| {
        scenario
            .metrics
            .paths
            .iter()
            .find(|p| p.name == name)
            .map_or(String::new(), |p| format!("R{} ", p.robot))
    };
    let each: Vec<String> = errors
        .iter()
        .map(|(name, e)| match e {
            Some(e) => format!("{}{e:.2} m", robot_of(name)),
            None => format!("{}no sample", robot_of(name)),
        })
        .collect();
    let headline = format!("Mean path error: {}", each.join(", "));
    let mut details = Vec::new();
    if let Some(turning) = &m.turning_share {
        for (name, share) in turning {
            if let Some(s) = share {
                details.push(format!(
                    "{}(path '{name}') turned at {} of the samples",
                    robot_of(name),
                    percent(*s)
                ));
            }
        }
    }
    (headline, details)
}

/// Probes: the largest gap between a reading and its closed form.
fn probes(curves: &[series::ProbeCurve]) -> (String, Vec<String>) {
    let mut worst = 0.0f64;
    let mut peak = 0.0f64;
    for c in curves {
        for &(t, v) in &c.readings {
            peak = peak.max(f64::from(v).abs());
            if let Some(f) = &c.closed_form {
                worst = worst.max((f64::from(v) - f.at(t)).abs());
            }
        }
    }
    let checked = curves.iter().filter(|c| c.closed_form.is_some()).count();
    let headline = format!(
        "{} probes: readings at most {} from the closed form",
        curves.len(),
        super::heatmap::fmt_sig(worst)
    );
    let details = vec![format!(
        "{checked} of {} probes have a closed form; the largest reading is {}",
        curves.len(),
        super::heatmap::fmt_sig(peak)
    )];
    (headline, details)
}

/// No metric: how far the robots drove.
fn driven(rec: &Recording, sim_time_s: f64) -> (String, Vec<String>) {
    let length = |rows: &[pheromone_sim::recording::RobotSample]| -> f64 {
        rows.windows(2)
            .map(|w| {
                let (a, b) = (w[0].true_pose, w[1].true_pose);
                ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt()
            })
            .filter(|d| d.is_finite())
            .sum()
    };
    let total: f64 = rec.robots.values().map(|r| length(r)).sum();
    let headline = format!(
        "{} robot(s) drove {total:.1} m in {sim_time_s:.0} s",
        rec.robots.len()
    );
    let details = rec
        .robots
        .iter()
        .map(|(id, rows)| format!("R{id} drove {:.1} m", length(rows)))
        .collect();
    (headline, details)
}

/// `s` cut into lines at spaces, each at most `width_px` wide in the `size_px` font.
pub(super) fn wrap(s: &str, size_px: u32, width_px: i32) -> Vec<String> {
    let fits = |line: &str| {
        (FONT, size_px)
            .into_font()
            .box_size(line)
            .map_or(true, |(w, _)| w as i32 <= width_px)
    };
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in s.split(' ') {
        let longer = if line.is_empty() {
            word.to_string()
        } else {
            format!("{line} {word}")
        };
        if fits(&longer) || line.is_empty() {
            line = longer;
        } else {
            lines.push(std::mem::take(&mut line));
            line = word.to_string();
        }
    }
    lines.push(line);
    lines
}

/// The text of the band, line by line: (text, font size, colour).
fn band_lines(h: &Headline, width_px: i32) -> Vec<(String, u32, Rgb)> {
    let mut out = Vec::new();
    let text_w = width_px - 2 * MARGIN_PX;
    for l in wrap(&h.title, TITLE_PX, text_w) {
        out.push((l, TITLE_PX, TITLE_RGB));
    }
    for l in wrap(&h.headline, HEADLINE_PX, text_w) {
        out.push((l, HEADLINE_PX, HEADLINE_RGB));
    }
    for d in &h.details {
        for l in wrap(d, DETAIL_PX, text_w) {
            out.push((l, DETAIL_PX, DETAIL_RGB));
        }
    }
    out
}

/// The height (px) of a line in the `size_px` font.
fn line_h(size_px: u32) -> i32 {
    (size_px as f64 * 1.35).round() as i32
}

/// The band's height (px) for `h` in a picture `width_px` wide.
pub(super) fn band_h_px(h: &Headline, width_px: u32) -> u32 {
    let text: i32 = band_lines(h, width_px as i32)
        .iter()
        .map(|(_, size, _)| line_h(*size))
        .sum();
    (text + 2 * MARGIN_PX) as u32
}

/// The summary picture: the band with `h`'s text on top, `below` under it (centred).
pub(super) fn summary_picture(h: &Headline, below: &Picture) -> Result<Picture, String> {
    let w = below.width.max(MIN_W_PX);
    let band = band_h_px(h, w);
    let mut pic = Picture::new(w, band + below.height, BAND_RGB);
    let x0 = ((w - below.width) / 2) as usize;
    let row = below.width as usize * 3;
    for y in 0..below.height as usize {
        let to = ((band as usize + y) * w as usize + x0) * 3;
        pic.rgb[to..to + row].copy_from_slice(&below.rgb[y * row..(y + 1) * row]);
    }
    let lines = band_lines(h, w as i32);
    pic.draw(|root| {
        let mut y = MARGIN_PX;
        for (text, size, rgb) in &lines {
            let style = (FONT, *size).into_font().color(&colour(*rgb));
            root.draw_text(text, &style, (MARGIN_PX, y)).map_err(msg)?;
            y += line_h(*size);
        }
        Ok(())
    })?;
    Ok(pic)
}

/// Writes `summary.png` of a world scenario's run into `dir`: its headline over the final
/// heat map (`field_final.png`'s picture, `marks` drawn), or over nothing if the run took no
/// snapshot.
pub fn write_summary(
    dir: &Path,
    scenario: &Scenario,
    rec: &Recording,
    metrics: &RunMetrics,
    marks: &[Mark],
) -> Result<PathBuf, ReportError> {
    let path = dir.join(SUMMARY_PNG);
    let draw_err = |detail: String| ReportError::Draw {
        path: path.clone(),
        detail,
    };
    let h = Headline::for_run(
        scenario,
        rec,
        &metrics.metrics,
        metrics.sim_time_s,
        metrics.interrupted,
    );
    let below = match super::final_picture(rec, marks) {
        Some(pic) => pic.map_err(draw_err)?,
        None => Picture::new(MIN_W_PX, 1, BAND_RGB),
    };
    let pic = summary_picture(&h, &below).map_err(draw_err)?;
    write_png(&path, &pic)?;
    Ok(path)
}

/// Writes `summary.png` of a picture `below` and its headline `h` into `dir`.
pub(super) fn write_summary_of(
    dir: &Path,
    h: &Headline,
    below: &Picture,
) -> Result<PathBuf, ReportError> {
    let path = dir.join(SUMMARY_PNG);
    let pic = summary_picture(h, below).map_err(|detail| ReportError::Draw {
        path: path.clone(),
        detail,
    })?;
    write_png(&path, &pic)?;
    Ok(path)
}

#[cfg(test)]
mod tests;
