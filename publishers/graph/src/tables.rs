//! The paper's tables of a graph run as text (Tables 2–4), each robot's line and, for a run
//! whose robots localize ([`super::localize`]), the localization lines (η1, η2).

use super::agent::Until;
use super::run::RunReport;

/// The paper's tables as text: captures in time order (Table 2), final link values (Table 3)
/// and the area capture matrix (Table 4).
pub fn tables_text(r: &RunReport) -> String {
    let mut s = String::new();
    headline(&mut s, r);
    captures_table(&mut s, r);
    links_table(&mut s, r);
    robots_lines(&mut s, r);
    areas_table(&mut s, r);
    localization_lines(&mut s, r);
    s
}

// Writing into a String cannot fail: each `let _ = writeln!` below drops an `Ok`.

/// The run in one line: scenario, strategy, robots, seed, the goal and when it was reached.
fn headline(s: &mut String, r: &RunReport) {
    use std::fmt::Write;
    let finish = r
        .finish_s
        .map_or("not finished".to_string(), |f| format!("{f:.1} s"));
    let _ = writeln!(
        s,
        "{} · {} · {} robot(s) · seed {} · {} when {}: {finish} · conflicts {}",
        r.scenario,
        r.strategy.name(),
        r.robots,
        r.seed,
        match r.until {
            Until::Served => "every region served",
            Until::Captured => "every region captured",
            Until::Time => "the end of max_time_s",
        },
        if r.finish_s.is_some() {
            "reached"
        } else {
            "not reached"
        },
        r.conflicts
    );
}

/// Table 2: captures in time order.
fn captures_table(s: &mut String, r: &RunReport) {
    use std::fmt::Write;
    let _ = writeln!(s, "\nCaptures (cf. Table 2):");
    let _ = writeln!(
        s,
        "  {:<8} {:>6} {:>11} {:>11}",
        "region", "robot", "captured s", "released s"
    );
    for c in &r.captures {
        let rel = c
            .released_s
            .map_or("held".to_string(), |t| format!("{t:.1}"));
        let _ = writeln!(
            s,
            "  {:<8} {:>6} {:>11.1} {:>11}",
            c.region,
            format!("R{}", c.robot),
            c.captured_s,
            rel
        );
    }
}

/// Table 3: the final link values of each node.
fn links_table(s: &mut String, r: &RunReport) {
    use std::fmt::Write;
    let _ = writeln!(s, "\nFinal link values (cf. Table 3):");
    let _ = writeln!(
        s,
        "  {:<8} {:>7} {:>7} {:>7} {:>7}",
        "node", "up", "down", "left", "right"
    );
    for l in &r.links {
        let _ = writeln!(
            s,
            "  {:<8} {:>7} {:>7} {:>7} {:>7}",
            l.node, l.up, l.down, l.left, l.right
        );
    }
}

/// Each robot's distance, captures, conflicts and path (when the run has robot reports).
fn robots_lines(s: &mut String, r: &RunReport) {
    use std::fmt::Write;
    if r.robot_reports.is_empty() {
        return;
    }
    let _ = writeln!(s, "\nRobots:");
    for rr in &r.robot_reports {
        let _ = writeln!(
            s,
            "  R{:<3} {:>6.1} m, {} capture(s), {} conflict(s), path {}",
            rr.robot,
            rr.distance_m,
            rr.capture_count,
            rr.conflicts,
            rr.path.join(" → ")
        );
    }
}

/// Table 4: the area capture matrix.
fn areas_table(s: &mut String, r: &RunReport) {
    use std::fmt::Write;
    let _ = writeln!(s, "\nArea capture matrix (cf. Table 4):");
    let _ = writeln!(
        s,
        "  {:<8} {:<16} {:>5}  captured during the run",
        "area", "held at end", "max-r"
    );
    let ids = |v: &[u32]| {
        if v.is_empty() {
            "N".to_string()
        } else {
            let robots: Vec<String> = v.iter().map(|i| format!("R{i}")).collect();
            format!("Y ({})", robots.join(", "))
        }
    };
    for a in &r.areas {
        let _ = writeln!(
            s,
            "  {:<8} {:<16} {:>5}  {}",
            a.region,
            ids(&a.held_by),
            a.max_r,
            ids(&a.captured_by)
        );
    }
}

/// A localized run: the landmark comparisons per class of steps, η1 and η2 (eq. 13 from the
/// landmark counts and from the comparisons), the step times (wall clock, labelled as such:
/// they move with the load), ρ_t and deposits.
fn localization_lines(s: &mut String, r: &RunReport) {
    use std::fmt::Write;
    let Some(l) = &r.localization else {
        return;
    };
    let a = &l.all;
    let f = |v: Option<f64>| v.map_or("—".to_string(), |v| format!("{v:.2}"));
    let us = |v: Option<f64>| v.map_or("—".to_string(), |v| format!("{:.1} µs", v / 1e3));
    let _ = writeln!(
        s,
        "\nLocalization (paper 001 Algorithm 1, deposits {}): {} landmarks, {} observations, {} used",
        l.config.deposit.name(),
        a.landmarks,
        a.observations,
        a.observations_used
    );
    let per_step = |c: u64, n: u64| if n > 0 { c as f64 / n as f64 } else { 0.0 };
    for (name, w) in [
        ("holding a region", &a.holding),
        ("free (others hold)", &a.free),
        ("nothing captured", &a.open),
    ] {
        let _ = writeln!(
            s,
            "  {name:<20} {:>6} steps: L_set {:>5.1} of {:>3} landmarks, {:>7.1} comparisons/step ({:.1} against the whole map)",
            w.steps,
            per_step(w.landmarks_considered, w.steps),
            a.landmarks,
            per_step(w.compared, w.steps),
            per_step(w.compared_whole_map, w.steps)
        );
    }
    let _ = writeln!(
        s,
        "  η1 = {} (eq. 13) · {} (comparisons)   η2 = {} (eq. 13) · {} (comparisons)",
        f(l.eta1_eq13),
        f(l.eta1_compared),
        f(l.eta2_eq13),
        f(l.eta2_compared)
    );
    let _ = writeln!(
        s,
        "  wall clock (varies with the machine's load, not η): holder step {} ({} whole map, ratio {}), free step {} ({} whole map, ratio {})",
        us(l.holding_step_ns),
        us(l.holding_step_whole_map_ns),
        f(l.eta1_wall_clock),
        us(l.free_step_ns),
        us(l.free_step_whole_map_ns),
        f(l.eta2_wall_clock)
    );
    let _ = writeln!(
        s,
        "  ρ_t {:.3}..{:.3} · deposits {} ({:.3}..{:.3}) · position error mean {:.3} m, max {:.3} m",
        a.rho_min, a.rho_max, a.deposits, a.deposit_min, a.deposit_max, a.position_error_mean_m, a.position_error_max_m
    );
}
