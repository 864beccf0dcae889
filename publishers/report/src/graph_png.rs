//! The picture of a node-graph run (paper 001 Figs. 4b, 5 and 7): regions, links coloured by
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
/// Node colours: the dock, terminal nodes, the others.
const DOCK_RGB: [u8; 3] = [245, 150, 30];
const TERMINAL_RGB: [u8; 3] = [210, 40, 40];
const NODE_RGB: [u8; 3] = [40, 160, 70];
/// Region fills: held, served (no longer held), never captured.
const HELD_RGB: [u8; 3] = [170, 220, 170];
const SERVED_RGB: [u8; 3] = [205, 205, 205];
const OPEN_RGB: [u8; 3] = [230, 240, 200];
/// Height (px) of a row of the legend under the graph.
const LEGEND_ROW_PX: i32 = 26;

/// One entry of the legend: what its swatch looks like, and what it means.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Swatch {
    Node([u8; 3]),
    Region([u8; 3]),
    Link([u8; 3]),
    DashedLink,
}

/// The legend of every graph picture, in order.
fn legend() -> Vec<(Swatch, &'static str)> {
    vec![
        (Swatch::Node(DOCK_RGB), "dock"),
        (Swatch::Node(TERMINAL_RGB), "terminal node"),
        (Swatch::Node(NODE_RGB), "node"),
        (Swatch::Region(HELD_RGB), "region held (by R<id>)"),
        (Swatch::Region(SERVED_RGB), "region served"),
        (Swatch::Region(OPEN_RGB), "region never captured"),
        (
            Swatch::Link(link_rgb(-1.0, 1.0)),
            "link < 0 (anti-pheromone)",
        ),
        (Swatch::Link(link_rgb(0.0, 1.0)), "link 0"),
        (Swatch::Link(link_rgb(1.0, 1.0)), "link > 0 (pheromone)"),
        (Swatch::DashedLink, "link −∞ (closed)"),
    ]
}

/// The legend's rows (entries wrapped to the picture's width `w`) as (x, row) per entry.
fn legend_layout(w: i32) -> Vec<(i32, i32)> {
    let mut at = Vec::new();
    let (mut x, mut row) = (8, 0);
    for (_, label) in legend() {
        let need = 34 + super::heatmap::text_width(label) + 18;
        if x > 8 && x + need > w {
            (x, row) = (8, row + 1);
        }
        at.push((x, row));
        x += need;
    }
    at
}

/// Draws the legend under the graph, from `top` (px): each entry's swatch and its meaning.
fn draw_legend(root: &Root<'_>, top: i32, w: i32) -> Result<(), String> {
    let text = (FONT, 14).into_font().color(&colour(GRAPH_TEXT_RGB));
    for ((swatch, label), (x, row)) in legend().into_iter().zip(legend_layout(w)) {
        let y = top + 14 + row * LEGEND_ROW_PX;
        match swatch {
            Swatch::Node(rgb) => root.draw(&Circle::new((x + 13, y), 7, colour(rgb).filled())),
            Swatch::Region(rgb) => root.draw(&Rectangle::new(
                [(x + 2, y - 8), (x + 26, y + 8)],
                colour(rgb).filled(),
            )),
            Swatch::Link(rgb) => root.draw(&PathElement::new(
                vec![(x, y), (x + 28, y)],
                colour(rgb).stroke_width(4),
            )),
            Swatch::DashedLink => root.draw(&DashedPathElement::new(
                vec![(x, y), (x + 28, y)],
                8,
                6,
                colour([0, 0, 0]).stroke_width(4),
            )),
        }
        .map_err(msg)?;
        root.draw_text(label, &text, (x + 34, y - 8)).map_err(msg)?;
    }
    Ok(())
}

/// Height (px) of the legend in a picture `w` px wide.
fn legend_h_px(w: i32) -> i32 {
    let rows = legend_layout(w).last().map_or(0, |&(_, r)| r) + 1;
    rows * LEGEND_ROW_PX + 8
}

/// Writes a picture of a node-graph run: regions (green while held, grey once served, labelled
/// with their holders), links coloured by their final value (red anti-pheromone, blue
/// pheromone, dashed black −∞), terminal nodes red, the others green, the dock orange; a
/// legend under the graph says so.
pub fn write_graph_png(
    path: &Path,
    state: &pheromone_graph::GraphState,
    report: &pheromone_graph::run::RunReport,
    dock: usize,
) -> Result<(), ReportError> {
    let pic = graph_picture(state, report, dock).map_err(|detail| ReportError::Draw {
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

/// The picture of [`write_graph_png`].
fn graph_picture(
    state: &pheromone_graph::GraphState,
    report: &pheromone_graph::run::RunReport,
    dock: usize,
) -> Result<Picture, String> {
    let nodes = state.graph.nodes();
    let regions = state.regions.regions();
    let frame = Frame::around(nodes, regions);
    let max_abs = max_abs_value(report);
    let (w, h) = (frame.w as i32, frame.h as i32);
    let mut pic = Picture::new(w as u32, (h + legend_h_px(w)) as u32, [250, 250, 250]);
    pic.draw(|root| {
        draw_legend(root, h, w)?;
        let text = (FONT, 16).into_font().color(&colour(GRAPH_TEXT_RGB));
        draw_regions(root, &frame, regions, report, &text)?;
        draw_links(root, &frame, nodes, report, max_abs)?;
        draw_nodes(root, &frame, nodes, dock, &text)?;
        let style = (FONT, 20).into_font().color(&colour(GRAPH_TEXT_RGB));
        root.draw_text(&title(report), &style, (8, 14)).map_err(msg)
    })?;
    Ok(pic)
}

/// Writes `summary.png` of a regions run (`runs`: by robot count then strategy) into `dir`:
/// its headline ([`graph_headline`]) over the first run's picture.
pub fn write_graph_summary(
    dir: &Path,
    state: &pheromone_graph::GraphState,
    runs: &[pheromone_graph::run::RunReport],
    dock: usize,
) -> Result<Option<std::path::PathBuf>, ReportError> {
    let Some(first) = runs.first() else {
        return Ok(None);
    };
    let pic = graph_picture(state, first, dock).map_err(|detail| ReportError::Draw {
        path: dir.join(super::summary::SUMMARY_PNG),
        detail,
    })?;
    super::summary::write_summary_of(dir, &graph_headline(runs), &pic).map(Some)
}

/// A regions run's headline: the first run's goal (every region served or captured, and when),
/// the conflicts; a line per further run, and the strategies' ratio where both ran.
pub fn graph_headline(runs: &[pheromone_graph::run::RunReport]) -> super::summary::Headline {
    let goal = |r: &pheromone_graph::run::RunReport| {
        use pheromone_graph::agent::Until;
        let done = match (r.until, r.finish_s) {
            (Until::Served, Some(t)) => format!("every region served at t = {t:.1} s"),
            (Until::Captured, Some(t)) => format!("every region captured at t = {t:.1} s"),
            (Until::Time, Some(t)) => format!("ran {t:.1} s, {} captures", r.captures.len()),
            (Until::Served | Until::Captured, None) => "goal not reached".to_string(),
            (Until::Time, None) => "stopped early".to_string(),
        };
        format!(
            "{}, {} robots: {done} ({} conflicts)",
            r.strategy.name(),
            r.robots,
            r.conflicts
        )
    };
    let mut details: Vec<String> = runs.iter().skip(1).map(goal).collect();
    for c in pheromone_graph::compare::compare(runs) {
        if let Some(ratio) = c.shortest_path_over_pheromone {
            details.push(format!(
                "{} robots: shortest-path takes {ratio:.2} × pheromone's time",
                c.robots
            ));
        }
    }
    let (scenario, seed) = runs
        .first()
        .map_or((String::new(), 0), |r| (r.scenario.clone(), r.seed));
    super::summary::Headline {
        title: format!("{scenario} · seed {seed} · {} run(s)", runs.len()),
        headline: runs.first().map_or("no run".to_string(), goal),
        details,
    }
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
            HELD_RGB
        } else if area.served {
            SERVED_RGB
        } else {
            OPEN_RGB
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
            DOCK_RGB
        } else if n.terminal {
            TERMINAL_RGB
        } else {
            NODE_RGB
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

    /// Issue 51: every graph picture has a legend under the graph: each colour the graph uses
    /// is drawn there, with what it means, inside the picture.
    #[test]
    fn the_legend_names_every_colour_inside_the_picture() {
        let regions = RegionsScenario::builtin("regions").unwrap();
        let state = regions.validate().unwrap();
        let frame = Frame::around(state.graph.nodes(), state.regions.regions());
        let (w, h) = (frame.w as i32, frame.h as i32);
        let legend_h = legend_h_px(w);
        let mut pic = Picture::new(w as u32, (h + legend_h) as u32, [250, 250, 250]);
        pic.draw(|root| draw_legend(root, h, w)).unwrap();
        let labels: Vec<&str> = legend().iter().map(|(_, l)| *l).collect();
        for word in ["dock", "terminal", "held", "served", "pheromone", "−∞"] {
            assert!(
                labels.iter().any(|l| l.contains(word)),
                "{word}: {labels:?}"
            );
        }
        for ((swatch, label), (x, row)) in legend().into_iter().zip(legend_layout(w)) {
            let y = h + 14 + row * LEGEND_ROW_PX;
            assert!(
                x >= 0 && y + 10 <= h + legend_h,
                "{label} outside the picture"
            );
            let (px, rgb) = match swatch {
                Swatch::Node(rgb) => ((x + 13, y), rgb),
                Swatch::Region(rgb) => ((x + 14, y), rgb),
                Swatch::Link(rgb) => ((x + 14, y), rgb),
                Swatch::DashedLink => ((x + 2, y), [0, 0, 0]),
            };
            assert_eq!(pic.get(px.0 as usize, px.1 as usize), rgb, "{label}");
        }
        // A narrow picture wraps the legend onto more rows.
        assert!(legend_h_px(300) > legend_h_px(1200));
    }
}
