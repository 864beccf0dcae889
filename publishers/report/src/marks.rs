//! What a heat map marks besides the field and the robots: the places the scenario's metrics
//! name (paper 000). `blind_leader` and `wrong_area`: in the leader's colour, a cross where the
//! leader lost its localization, labelled with its world x and the time. `blind_leader`: a cross
//! where the follower gave the trail up. `wrong_area` (Figs. 1 and 24): area A (an outlined
//! rectangle), location B (a circle of the radius within which a robot has reached it) and, in
//! each follower's colour, a cross where it gave the trail up and explored on its own; in the
//! leader's, a cross where its deposit first fell below the follower's threshold (Fig. 23) and
//! a circle of radius σ at its estimate at each of L1–L15 (Fig. 22). The crosses and circles
//! come from the metrics computed on the run, so they are in the pictures from their time on.

use super::style::{robot_rgb, Rgb};
use pheromone_sim::recording::{Recording, RobotSample};
use pheromone_sim::wrong_area::{wrong_area, Checkpoint};
use pheromone_world::scenario::Scenario;

/// Outline of area A (`wrong_area`): magenta, apart from the robots' colours, the walls' grey
/// and both colour maps.
pub(super) const AREA_A_RGB: Rgb = [255, 60, 220];
/// Outline of location B: bright green.
pub(super) const AREA_B_RGB: Rgb = [90, 255, 90];

/// The shape of a mark, in world coordinates (m).
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// An outlined rectangle, its label inside its top-left corner.
    Rect { min_m: [f64; 2], max_m: [f64; 2] },
    /// An outlined circle, its label above it (under it if there is no room above).
    Circle { centre_m: [f64; 2], radius_m: f64 },
    /// A cross, its label right of it.
    Point { at_m: [f64; 2] },
}

/// One thing a heat map marks.
#[derive(Debug, Clone, PartialEq)]
pub struct Mark {
    pub shape: Shape,
    pub label: String,
    pub rgb: [u8; 3],
    /// Drawn only in the pictures of snapshots at or after this time (s).
    pub from_s: f64,
}

/// The true position of `robot` at its first sample at or after `t_s`.
pub(super) fn position_at(rec: &Recording, robot: u32, t_s: f64) -> Option<[f64; 2]> {
    rec.robots
        .get(&robot)?
        .iter()
        .find(|r: &&RobotSample| r.t_s >= t_s - 1e-9)
        .map(|r| [r.true_pose[0], r.true_pose[1]])
        .filter(|p| p[0].is_finite() && p[1].is_finite())
}

/// A cross at `at_m` in robot `id`'s colour from `t_s` on, labelled `what` with the world x and
/// the time ("R0 lost at x = 15.5 m (t = 25.0 s)").
fn event(id: u32, what: &str, at_m: [f64; 2], t_s: f64) -> Mark {
    Mark {
        shape: Shape::Point { at_m },
        label: format!("R{id} {what} x = {:.1} m (t = {t_s:.1} s)", at_m[0]),
        rgb: robot_rgb(id),
        from_s: t_s,
    }
}

/// The leader's loss of its localization: the scripted time (`[robot.localizer.loss]
/// after_s`) where the scenario has one.
fn leader_lost(scenario: &Scenario, rec: &Recording, leader: u32) -> Option<Mark> {
    let t = scenario.roles(leader)?.localizer.loss.after_s?;
    let at = position_at(rec, leader, t)?;
    Some(event(leader, "lost at", at, t))
}

/// Seed 000 Fig. 22: the leader's uncertainty along its path, a circle of radius σ (√ of its
/// Σxy's largest eigenvalue: the 1σ ellipse's major semi-axis) at its estimate at each of
/// L1–L15, each from its time on; the last one labelled.
fn sigma_circles(leader: u32, checkpoints: &[Checkpoint]) -> Vec<Mark> {
    let n = checkpoints.len();
    checkpoints
        .iter()
        .enumerate()
        .filter_map(|(k, c)| {
            let (at, sigma) = (c.estimate_m?, c.sigma_m?);
            let label = if k + 1 == n {
                format!("R{leader} σ at L1–L{n} (estimate)")
            } else {
                String::new()
            };
            Some(Mark {
                shape: Shape::Circle {
                    centre_m: at,
                    radius_m: sigma,
                },
                label,
                rgb: robot_rgb(leader),
                from_s: c.t_s,
            })
        })
        .collect()
}

/// The marks the scenario's metrics call for, in drawing order (none if they name no place).
pub fn marks(scenario: &Scenario, rec: &Recording) -> Vec<Mark> {
    let mut out = Vec::new();
    if let Some(m) = &scenario.metrics.blind_leader {
        out.extend(leader_lost(scenario, rec, m.leader));
        if let Some(t) = rec.trail_abandoned_at_s(m.follower) {
            if let Some(at) = position_at(rec, m.follower, t) {
                out.push(event(m.follower, "gave up at", at, t));
            }
        }
    }
    if let Some(m) = &scenario.metrics.wrong_area {
        out.push(Mark {
            shape: Shape::Rect {
                min_m: m.a_min_m,
                max_m: m.a_max_m,
            },
            label: "A (wrong area)".into(),
            rgb: AREA_A_RGB,
            from_s: f64::NEG_INFINITY,
        });
        out.push(Mark {
            shape: Shape::Circle {
                centre_m: m.b_m,
                radius_m: m.b_radius_m,
            },
            label: "B (leader's true goal)".into(),
            rgb: AREA_B_RGB,
            from_s: f64::NEG_INFINITY,
        });
        let outcome = wrong_area(scenario, m, rec);
        if let (Some(t), Some(at)) = (outcome.leader.lost_at_s, outcome.leader.lost_at_m) {
            out.push(event(m.leader, "lost at", at, t));
        }
        if let Some(c) = &outcome.deposit_below_threshold {
            let what = format!("deposit < {} at", c.threshold);
            out.push(event(m.leader, &what, c.true_m, c.t_s));
        }
        out.extend(sigma_circles(m.leader, &outcome.checkpoints));
        for f in outcome.followers {
            if let (Some(t), Some(at_m)) = (f.exploring_from_s, f.exploring_from_m) {
                out.push(event(f.id, "explores from", at_m, t));
            }
        }
    }
    // A scenario with both metrics names one event twice (the leader's loss; a follower
    // giving up where it starts exploring): one cross per robot and place.
    let mut kept: Vec<Mark> = Vec::new();
    for m in out {
        let twice = matches!(m.shape, Shape::Point { .. })
            && kept.iter().any(|k| k.shape == m.shape && k.rgb == m.rgb);
        if !twice {
            kept.push(m);
        }
    }
    kept
}
