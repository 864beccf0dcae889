//! What a heat map marks besides the field and the robots: the places the scenario's metrics
//! name. Today `wrong_area` (seed 000 Figs. 1 and 24): area A (an outlined rectangle), location
//! B (a circle of the radius within which a robot has reached it) and, in each follower's
//! colour, a cross where it gave the trail up and explored on its own (from the metric computed
//! on the run, so only in the pictures from that time on).

use super::style::{robot_rgb, Rgb};
use pheromone_sim::recording::Recording;
use pheromone_sim::wrong_area::wrong_area;
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

/// The marks the scenario's metrics call for, in drawing order (none if they name no place).
pub fn marks(scenario: &Scenario, rec: &Recording) -> Vec<Mark> {
    let mut out = Vec::new();
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
        for f in wrong_area(scenario, m, rec).followers {
            if let (Some(t), Some(at_m)) = (f.exploring_from_s, f.exploring_from_m) {
                out.push(Mark {
                    shape: Shape::Point { at_m },
                    label: format!("R{} explores", f.id),
                    rgb: robot_rgb(f.id),
                    from_s: t,
                });
            }
        }
    }
    out
}
