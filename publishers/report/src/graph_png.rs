//! The picture of a node-graph run (seed 001 Figs. 4b, 5 and 7): regions, links coloured by
//! their final value, nodes and the dock.

use std::fs;
use std::path::Path;

use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;

use super::files::write_png;
use super::style::{colour, msg, Picture, FONT};
use super::ReportError;

/// Text on the graph's light background.
const GRAPH_TEXT_RGB: [u8; 3] = [30, 30, 35];

/// Writes a picture of a node-graph run: regions (green while held, grey once served, labelled
/// with their holders), links coloured by their final value (red anti-pheromone, blue
/// pheromone, dashed black −∞), terminal nodes red, the others green, the dock orange.
pub fn write_graph_png(
    path: &Path,
    state: &pheromone_graph::GraphState,
    report: &pheromone_graph::run::RunReport,
    dock: usize,
) -> Result<(), ReportError> {
    let nodes = state.graph.nodes();
    let regions = state.regions.regions();
    let frame = Frame::around(nodes, regions);
    let max_abs = max_abs_value(report);
    let mut pic = Picture::new(frame.w as u32, frame.h as u32, [250, 250, 250]);
    pic.draw(|root| {
        let text = (FONT, 16).into_font().color(&colour(GRAPH_TEXT_RGB));
        draw_regions(root, &frame, regions, report, &text)?;
        draw_links(root, &frame, nodes, report, max_abs)?;
        draw_nodes(root, &frame, nodes, dock, &text)?;
        let style = (FONT, 20).into_font().color(&colour(GRAPH_TEXT_RGB));
        root.draw_text(&title(report), &style, (8, 14)).map_err(msg)
    })
    .map_err(|detail| ReportError::Draw {
        path: path.to_path_buf(),
        detail,
    })?;
    if let Some(dir) = path.parent() {
        fs::create_dir_all(dir).map_err(|source| ReportError::Io {
            path: dir.to_path_buf(),
            source,
        })?;
    }
    write_png(path, &pic)
}

/// The drawing area the graph picture is drawn on.
type Root<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// The mapping from world metres to picture pixels, and the picture's size.
struct Frame {
    x0: f64,
    y0: f64,
    margin_m: f64,
    px_per_m: f64,
    w: usize,
    h: usize,
}

impl Frame {
    /// The frame around the nodes and the region boxes, with a margin.
    fn around(nodes: &[pheromone_graph::Node], regions: &[pheromone_graph::Region]) -> Frame {
        let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        let mut grow = |x: f64, y: f64| {
            x0 = x0.min(x);
            y0 = y0.min(y);
            x1 = x1.max(x);
            y1 = y1.max(y);
        };
        for n in nodes {
            grow(n.x_m as f64, n.y_m as f64);
        }
        for r in regions {
            let [a, b, c, d] = r.shape.bbox_m();
            grow(a as f64, b as f64);
            grow(c as f64, d as f64);
        }
        if x0 > x1 {
            (x0, y0, x1, y1) = (0.0, 0.0, 1.0, 1.0);
        }
        let margin_m = 1.0;
        let span_m = (x1 - x0 + 2.0 * margin_m).max(y1 - y0 + 2.0 * margin_m);
        let px_per_m = (1200.0 / span_m).clamp(10.0, 120.0);
        let w = ((x1 - x0 + 2.0 * margin_m) * px_per_m).ceil() as usize;
        let h = ((y1 - y0 + 2.0 * margin_m) * px_per_m).ceil() as usize;
        Frame {
            x0,
            y0,
            margin_m,
            px_per_m,
            w,
            h,
        }
    }

    /// The pixel of a world point (y up in the world, down in the picture).
    fn to_px(&self, x: f64, y: f64) -> (i32, i32) {
        (
            ((x - self.x0 + self.margin_m) * self.px_per_m).round() as i32,
            (self.h as f64 - (y - self.y0 + self.margin_m) * self.px_per_m).round() as i32,
        )
    }
}

/// The final value of a node's link in one direction, as the report gives it.
fn link_value(
    report: &pheromone_graph::run::RunReport,
    node: &str,
    dir: pheromone_graph::Dir,
) -> Option<f32> {
    let row = report.links.iter().find(|l| l.node == node)?;
    let text = match dir {
        pheromone_graph::Dir::Up => &row.up,
        pheromone_graph::Dir::Down => &row.down,
        pheromone_graph::Dir::Left => &row.left,
        pheromone_graph::Dir::Right => &row.right,
    };
    match text.as_str() {
        "-inf" => Some(f32::NEG_INFINITY),
        t => t.parse().ok(),
    }
}

/// The largest finite |value| among the report's links, at least 1.
fn max_abs_value(report: &pheromone_graph::run::RunReport) -> f32 {
    report
        .links
        .iter()
        .flat_map(|l| [&l.up, &l.down, &l.left, &l.right])
        .filter_map(|t| t.parse::<f32>().ok())
        .filter(|v| v.is_finite())
        .fold(1.0f32, |m, v| m.max(v.abs()))
}

/// Draws the region boxes, filled by state and labelled with their holders.
fn draw_regions(
    root: &Root<'_>,
    frame: &Frame,
    regions: &[pheromone_graph::Region],
    report: &pheromone_graph::run::RunReport,
    text: &TextStyle<'_>,
) -> Result<(), String> {
    for (r, area) in regions.iter().zip(&report.areas) {
        let [a, b, c, d] = r.shape.bbox_m();
        let (px0, py1) = frame.to_px(a as f64, b as f64);
        let (px1, py0) = frame.to_px(c as f64, d as f64);
        let fill = if !area.held_by.is_empty() {
            [170, 220, 170]
        } else if area.served {
            [205, 205, 205]
        } else {
            [230, 240, 200]
        };
        root.draw(&Rectangle::new(
            [(px0, py0), (px1, py1)],
            colour(fill).filled(),
        ))
        .map_err(msg)?;
        let holders: Vec<String> = area.held_by.iter().map(|i| format!("R{i}")).collect();
        let label = if holders.is_empty() {
            r.name.clone()
        } else {
            format!("{} {}", r.name, holders.join(" "))
        };
        root.draw_text(&label, text, (px0 + 4, py0 + 10))
            .map_err(msg)?;
    }
    Ok(())
}

/// Draws each link as its half of the passage (so both directions' values show).
fn draw_links(
    root: &Root<'_>,
    frame: &Frame,
    nodes: &[pheromone_graph::Node],
    report: &pheromone_graph::run::RunReport,
    max_abs: f32,
) -> Result<(), String> {
    for n in nodes {
        for (dir, link) in n.links() {
            let to = &nodes[link.to];
            let a = frame.to_px(n.x_m as f64, n.y_m as f64);
            let b = frame.to_px(to.x_m as f64, to.y_m as f64);
            // Each direction draws its half of the passage, so both values show.
            let mid = ((a.0 + b.0) / 2, (a.1 + b.1) / 2);
            let v = link_value(report, &n.name, dir).unwrap_or(link.value);
            if v == f32::NEG_INFINITY {
                let style = colour([0, 0, 0]).stroke_width(4);
                root.draw(&DashedPathElement::new(vec![a, mid], 8, 6, style))
                    .map_err(msg)?;
            } else {
                let rgb = link_rgb(v, max_abs);
                root.draw(&PathElement::new(vec![a, mid], colour(rgb).stroke_width(4)))
                    .map_err(msg)?;
            }
        }
    }
    Ok(())
}

/// The colour of a finite link value: grey at 0, towards red (negative) or blue (positive).
fn link_rgb(v: f32, max_abs: f32) -> [u8; 3] {
    let t = (v.abs() / max_abs).clamp(0.0, 1.0) as f64;
    let mix = |base: f64, full: f64| (base + (full - base) * t).round() as u8;
    if v < 0.0 {
        [mix(160.0, 215.0), mix(160.0, 25.0), mix(160.0, 25.0)]
    } else if v > 0.0 {
        [mix(160.0, 30.0), mix(160.0, 90.0), mix(160.0, 220.0)]
    } else {
        [160, 160, 160]
    }
}

/// Draws the nodes (dock orange, terminal red, the others green) with their names.
fn draw_nodes(
    root: &Root<'_>,
    frame: &Frame,
    nodes: &[pheromone_graph::Node],
    dock: usize,
    text: &TextStyle<'_>,
) -> Result<(), String> {
    for (i, n) in nodes.iter().enumerate() {
        let p = frame.to_px(n.x_m as f64, n.y_m as f64);
        let rgb = if i == dock {
            [245, 150, 30]
        } else if n.terminal {
            [210, 40, 40]
        } else {
            [40, 160, 70]
        };
        root.draw(&Circle::new(p, 7, colour(rgb).filled()))
            .map_err(msg)?;
        root.draw_text(&n.name, text, (p.0 + 9, p.1 + 6))
            .map_err(msg)?;
    }
    Ok(())
}

/// The picture's title: scenario, strategy, robots and the goal (`until`), reached when or not.
fn title(report: &pheromone_graph::run::RunReport) -> String {
    use pheromone_graph::agent::Until;
    let goal = match (report.until, report.finish_s) {
        (Until::Served, Some(t)) => format!("every region served at {t:.1} s"),
        (Until::Captured, Some(t)) => format!("every region captured at {t:.1} s"),
        (Until::Time, Some(t)) => format!("ran its {t:.1} s (until = time)"),
        (Until::Served, None) => "goal not reached: not every region served".to_string(),
        (Until::Captured, None) => "goal not reached: not every region captured".to_string(),
        (Until::Time, None) => "stopped before the end of max_time_s".to_string(),
    };
    format!(
        "{}: {}, {} robots, {goal}",
        report.scenario,
        report.strategy.name(),
        report.robots,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use pheromone_graph::agent::{GraphStrategy, RegionsScenario};
    use pheromone_graph::run::simulate;

    /// Runs that reach their goal say so: a run for a fixed time (regions-backup, until =
    /// time) was titled "goal not reached" before the time goal counted as reached.
    #[test]
    fn the_title_says_whether_the_goal_was_reached() {
        let backup = RegionsScenario::builtin("regions-backup").unwrap();
        let r = simulate(&backup, GraphStrategy::Pheromone, 2, 1).unwrap();
        let t = title(&r);
        assert!(t.contains("ran its 60.0 s"), "{t}");
        assert!(!t.contains("not reached"), "{t}");
        let regions = RegionsScenario::builtin("regions").unwrap();
        let mut r = simulate(&regions, GraphStrategy::Pheromone, 2, 1).unwrap();
        let t = title(&r);
        assert!(t.contains("every region served at 120.2 s"), "{t}");
        r.finish_s = None;
        assert!(title(&r).contains("goal not reached"), "{}", title(&r));
        // The picture itself is written.
        let dir = std::env::temp_dir().join(format!("graph-png-{}", std::process::id()));
        let path = dir.join("g.png");
        let state = regions.validate().unwrap();
        let dock = regions.dock_node(&state.graph).unwrap();
        write_graph_png(&path, &state, &r, dock).unwrap();
        assert_eq!(&fs::read(&path).unwrap()[..4], b"\x89PNG");
        fs::remove_dir_all(&dir).unwrap();
    }
}
