//! Region capture against the shortest-path baseline (paper 001 Fig. 4c): per robot count, the
//! time to the goal with each strategy, their conflicts and the ratio.

use serde::Serialize;

use super::agent::GraphStrategy;
use super::run::RunReport;

/// One robot count: the time to the goal with each strategy and their ratio; `None` where the
/// strategy was not run or did not reach the goal.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Comparison {
    pub robots: usize,
    pub pheromone_finish_s: Option<f32>,
    pub pheromone_conflicts: Option<u32>,
    pub shortest_path_finish_s: Option<f32>,
    pub shortest_path_conflicts: Option<u32>,
    pub shortest_path_over_pheromone: Option<f32>,
}

/// Per robot count: the time to the goal with each strategy and their ratio (Fig. 4c).
pub fn compare(runs: &[RunReport]) -> Vec<Comparison> {
    let mut counts: Vec<usize> = runs.iter().map(|r| r.robots).collect();
    counts.dedup();
    counts
        .into_iter()
        .map(|n| {
            let of = |s: GraphStrategy| runs.iter().find(|r| r.robots == n && r.strategy == s);
            let ph = of(GraphStrategy::Pheromone);
            let sp = of(GraphStrategy::ShortestPath);
            let ratio = match (ph.and_then(|r| r.finish_s), sp.and_then(|r| r.finish_s)) {
                (Some(a), Some(b)) if a > 0.0 => Some(b / a),
                _ => None,
            };
            Comparison {
                robots: n,
                pheromone_finish_s: ph.and_then(|r| r.finish_s),
                pheromone_conflicts: ph.map(|r| r.conflicts),
                shortest_path_finish_s: sp.and_then(|r| r.finish_s),
                shortest_path_conflicts: sp.map(|r| r.conflicts),
                shortest_path_over_pheromone: ratio,
            }
        })
        .collect()
}

/// The comparison as the table the paper's Fig. 4c reads off.
pub fn comparison_text(rows: &[Comparison]) -> String {
    use std::fmt::Write;
    // Writing into a String cannot fail: each `let _ = writeln!` below drops an `Ok`.
    let mut s = String::from(
        "Time to the goal (cf. Fig. 4c):\n  robots   pheromone (conflicts)   shortest-path (conflicts)   ratio\n",
    );
    let f = |v: Option<f32>| v.map_or("-".to_string(), |x| format!("{x:.1} s"));
    let c = |v: Option<u32>| v.map_or("-".to_string(), |x| x.to_string());
    for r in rows {
        let _ = writeln!(
            s,
            "  {:>6}   {:>9} ({:>3})         {:>9} ({:>3})             {}",
            r.robots,
            f(r.pheromone_finish_s),
            c(r.pheromone_conflicts),
            f(r.shortest_path_finish_s),
            c(r.shortest_path_conflicts),
            r.shortest_path_over_pheromone
                .map_or("-".to_string(), |x| format!("{x:.2}×")),
        );
    }
    s
}
