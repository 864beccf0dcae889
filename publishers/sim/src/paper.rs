//! Seed 004's own figures (`docs/paper/seed004.csv`, embedded), each citing its table, and
//! what a sweep measured beside each ([`beside`]). The paper's tables are images: the file holds
//! only the values its text states (a mean, a maximum, a t, a bound every t exceeds, the R_C
//! where exploration peaks).

use pheromone_roles::follower::StrategyKind;

use super::sweep::{Figure, PointKey, SweepResult};

/// The paper's values, as shipped.
pub const SEED004_CSV: &str = include_str!("../../../docs/paper/seed004.csv");

/// What a paper value is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PaperKind {
    /// Mean exploration per robot (%).
    MeanPct,
    /// Highest exploration reported (%).
    MaxPct,
    /// Welch's t, IAS-SS against uniform.
    WelchT,
    /// Every paired t (with against without integration) exceeds this.
    PairedTAbove,
    /// The R_C (m) where exploration peaks, decaying slowly beyond.
    PeakRcM,
}

impl PaperKind {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "mean_pct" => PaperKind::MeanPct,
            "max_pct" => PaperKind::MaxPct,
            "welch_t" => PaperKind::WelchT,
            "paired_t_above" => PaperKind::PairedTAbove,
            "peak_rc_m" => PaperKind::PeakRcM,
            _ => return None,
        })
    }
}

/// One row of the file.
#[derive(Debug, Clone, PartialEq)]
pub struct PaperValue {
    /// The paper's table the value belongs to (1–9).
    pub table: u32,
    pub kind: PaperKind,
    pub strategy: StrategyKind,
    pub integration: bool,
    pub robots: Option<usize>,
    pub rc_m: Option<f64>,
    pub value: f64,
    /// The paper's sentence that gives it.
    pub quote: String,
}

/// A row of the paper's file that does not parse.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{origin}:{line}: {reason}")]
pub struct PaperError {
    pub origin: String,
    pub line: usize,
    pub reason: String,
}

/// The header line the file must have.
pub const PAPER_HEADER: &str = "table,kind,strategy,integration,robots,rc_m,value,quote";

/// The shipped file's rows.
pub fn seed004() -> Result<Vec<PaperValue>, PaperError> {
    parse(SEED004_CSV, "docs/paper/seed004.csv")
}

/// Parses the file: `#` lines are comments, then the header, then one value a line; every row
/// cites a table from 1 to 9 and quotes the paper. `origin` names the file in errors.
pub fn parse(text: &str, origin: &str) -> Result<Vec<PaperValue>, PaperError> {
    let mut out = Vec::new();
    let mut header = false;
    for (i, line) in text.lines().enumerate() {
        let bad = |reason: String| PaperError {
            origin: origin.to_string(),
            line: i + 1,
            reason,
        };
        if line.trim().is_empty() || line.starts_with('#') {
            continue;
        }
        if !header {
            if line != PAPER_HEADER {
                return Err(bad(format!("expected the header {PAPER_HEADER:?}")));
            }
            header = true;
            continue;
        }
        out.push(row(line).map_err(bad)?);
    }
    if !header {
        return Err(PaperError {
            origin: origin.to_string(),
            line: text.lines().count(),
            reason: "no header, no rows".into(),
        });
    }
    Ok(out)
}

/// One row: seven plain fields and the quote (in double quotes, may hold commas).
fn row(line: &str) -> Result<PaperValue, String> {
    let fields: Vec<&str> = line.splitn(8, ',').collect();
    let [table, kind, strategy, integration, robots, rc_m, value, quote] = fields[..] else {
        return Err(format!("expected 8 fields, found {}", fields.len()));
    };
    let table = match table.parse::<u32>() {
        Ok(t) if (1..=9).contains(&t) => t,
        _ => return Err(format!("table {table:?}: not a table of the paper (1–9)")),
    };
    let kind = PaperKind::parse(kind).ok_or_else(|| {
        format!("kind {kind:?}: expected mean_pct, max_pct, welch_t, paired_t_above or peak_rc_m")
    })?;
    let strategy = match strategy.parse::<StrategyKind>() {
        Ok(k @ (StrategyKind::Inverse | StrategyKind::Uniform)) => k,
        _ => {
            return Err(format!(
                "strategy {strategy:?}: expected inverse or uniform"
            ))
        }
    };
    let integration = integration
        .parse::<bool>()
        .map_err(|_| format!("integration {integration:?}: expected true or false"))?;
    let robots = match robots {
        "" => None,
        r => Some(
            r.parse::<usize>()
                .ok()
                .filter(|n| *n >= 1)
                .ok_or_else(|| format!("robots {r:?}: expected a robot count ≥ 1 or nothing"))?,
        ),
    };
    let rc_m = match rc_m {
        "" => None,
        r => Some(
            r.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite() && *v > 0.0)
                .ok_or_else(|| format!("rc_m {r:?}: expected a radius > 0 (m) or nothing"))?,
        ),
    };
    let value = value
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| format!("value {value:?}: expected a finite number"))?;
    let quote = quote
        .strip_prefix('"')
        .and_then(|q| q.strip_suffix('"'))
        .filter(|q| !q.trim().is_empty())
        .ok_or_else(|| format!("quote {quote:?}: expected the paper's words in double quotes"))?;
    Ok(PaperValue {
        table,
        kind,
        strategy,
        integration,
        robots,
        rc_m,
        value,
        quote: quote.to_string(),
    })
}

/// Each paper value with what the sweep measured for it (`None`: the sweep has no such point
/// or comparison). Percentages and t values are on the sweep's figure.
pub fn beside(paper: &[PaperValue], r: &SweepResult) -> Vec<(PaperValue, Option<String>)> {
    paper
        .iter()
        .map(|p| (p.clone(), ours(p, r)))
        .collect::<Vec<_>>()
}

fn pct(x: f64) -> String {
    format!("{:.1}", 100.0 * x)
}

/// The sweep's figures for one paper value, one entry per steering mode and R_C, "; "-joined.
fn ours(p: &PaperValue, r: &SweepResult) -> Option<String> {
    let f: Figure = r.figure;
    let parts: Vec<String> = match p.kind {
        PaperKind::MeanPct | PaperKind::MaxPct => r
            .points
            .iter()
            .filter(|x| {
                x.key.strategy == p.strategy
                    && x.key.merge == p.integration
                    && p.robots.is_none_or(|n| n == x.key.robots)
            })
            .map(|x| {
                let m = x.figure(f);
                format!(
                    "{}: {} ± {} % ({} robot(s), R_C = {} m)",
                    setting(&x.key),
                    pct(m.mean),
                    pct(m.sd),
                    x.key.robots,
                    x.key.rc_m
                )
            })
            .collect(),
        PaperKind::WelchT | PaperKind::PairedTAbove => {
            let (kind, welch) = match p.kind {
                PaperKind::WelchT => ("strategy", true),
                _ => ("merge", false),
            };
            r.comparisons
                .iter()
                .filter(|c| {
                    c.kind == kind
                        && c.a.merge == p.integration
                        && (welch || c.a.strategy == p.strategy)
                        && p.robots.is_none_or(|n| n == c.a.robots)
                })
                .map(|c| {
                    let t = if welch { c.welch } else { c.paired };
                    let t = t.map_or("undefined".to_string(), |t| {
                        format!("t = {:.2} (df {:.1})", t.t, t.df)
                    });
                    format!(
                        "{}: {t} ({} robot(s), R_C = {} m)",
                        setting(&c.a),
                        c.a.robots,
                        c.a.rc_m
                    )
                })
                .collect()
        }
        PaperKind::PeakRcM => peaks(p, r),
    };
    (!parts.is_empty()).then(|| parts.join("; "))
}

/// A point's steering and, where they are not seed 004's own, its merge rule and cost.
fn setting(k: &PointKey) -> String {
    match k.integration.words() {
        w if w.is_empty() || !k.merge => k.steer_on.name().to_string(),
        w => format!("{}, merge {w}", k.steer_on.name()),
    }
}

/// Per steering mode, merge setting and robot count, where the sweep's merge line over R_C
/// peaks.
fn peaks(p: &PaperValue, r: &SweepResult) -> Vec<String> {
    let mut lines: Vec<PointKey> = Vec::new();
    for x in &r.points {
        let k = PointKey { rc_m: 0.0, ..x.key };
        if x.key.merge
            && x.key.strategy == p.strategy
            && p.robots.is_none_or(|n| n == x.key.robots)
            && !lines.contains(&k)
        {
            lines.push(k);
        }
    }
    lines
        .into_iter()
        .filter_map(|line| {
            let mut pts: Vec<(f64, f64)> = r
                .points
                .iter()
                .filter(|x| PointKey { rc_m: 0.0, ..x.key } == line)
                .map(|x| (x.key.rc_m, x.figure(r.figure).mean))
                .collect();
            if pts.len() < 2 {
                return None;
            }
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            let best = pts
                .iter()
                .copied()
                .fold(pts[0], |b, x| if x.1 > b.1 { x } else { b });
            let curve: Vec<String> = pts
                .iter()
                .map(|(rc, m)| format!("{rc} m {}", pct(*m)))
                .collect();
            Some(format!(
                "{}: peak at {} m ({} robot(s); {} %)",
                setting(&line),
                best.0,
                line.robots,
                curve.join(", ")
            ))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_file_parses_and_every_row_cites_a_table_and_quotes_the_paper() {
        let v = seed004().unwrap();
        assert!(v.len() >= 6, "{v:?}");
        for p in &v {
            assert!((1..=9).contains(&p.table), "{p:?}");
            assert!(!p.quote.is_empty());
        }
        // The figures the text gives: Table 6's 80 % for 5 robots, Table 2's t = 4.58.
        assert!(v
            .iter()
            .any(|p| p.table == 6 && p.kind == PaperKind::MeanPct && p.value == 80.0));
        assert!(v
            .iter()
            .any(|p| p.table == 2 && p.kind == PaperKind::WelchT));
        assert!(v
            .iter()
            .any(|p| p.table == 9 && p.kind == PaperKind::PeakRcM && p.rc_m == Some(24.0)));
    }

    /// A sweep of 5 robots over three radii, merged figure 0.7, 0.8, 0.75 (two seeds each).
    fn rc_sweep() -> SweepResult {
        use super::super::sweep::{comparisons, points, RunResult};
        let mut runs = Vec::new();
        for (rc_m, m) in [(16.0, 0.7), (24.0, 0.8), (40.0, 0.75)] {
            for (seed, d) in [(1, -0.05), (2, 0.05)] {
                runs.push(RunResult {
                    point: PointKey {
                        robots: 5,
                        rc_m,
                        merge: true,
                        strategy: StrategyKind::Inverse,
                        steer_on: pheromone_roles::mapper::SteerOn::OwnMap,
                        integration: Default::default(),
                    },
                    seed,
                    known_mean: 1.0,
                    known_team: 1.0,
                    merged_mean: m + d,
                    merged_team: 1.0,
                    visited_mean: 0.5,
                    visited_team: 0.9,
                    merges: 4,
                    alignment_error_m: Some(0.3),
                    wall_s: 1.0,
                });
            }
        }
        let pts = points(&runs);
        SweepResult {
            scenario: "ias-ss-open".into(),
            duration_s: 1000.0,
            trials: 2,
            sectors: 24,
            jobs: 1,
            figure: Figure::Merged,
            wall_s: 1.0,
            comparisons: comparisons(&runs, &pts, Figure::Merged),
            points: pts,
            runs,
        }
    }

    #[test]
    fn beside_finds_our_peak_and_our_means_on_the_sweeps_figure() {
        let r = rc_sweep();
        let v = seed004().unwrap();
        let got = beside(&v, &r);
        assert_eq!(got.len(), v.len());
        let peak = got
            .iter()
            .find(|(p, _)| p.kind == PaperKind::PeakRcM)
            .unwrap();
        assert_eq!(
            peak.1.as_deref(),
            Some("own-map: peak at 24 m (5 robot(s); 16 m 70.0, 24 m 80.0, 40 m 75.0 %)")
        );
        let mean = got.iter().find(|(p, _)| p.table == 6).unwrap();
        let text = mean.1.as_deref().unwrap();
        assert!(
            text.starts_with("own-map: 70.0 ± 7.1 % (5 robot(s), R_C = 16 m); "),
            "{text}"
        );
        // No uniform point, no no-merge point: no t of either kind.
        let welch = got
            .iter()
            .find(|(p, _)| p.kind == PaperKind::WelchT)
            .unwrap();
        assert_eq!(welch.1, None);
    }

    #[test]
    fn a_bad_row_is_refused_naming_the_file_line_and_field() {
        let ok = format!("# c\n{PAPER_HEADER}\n6,mean_pct,inverse,true,5,,80,\"q, with comma\"\n");
        assert_eq!(parse(&ok, "p.csv").unwrap()[0].quote, "q, with comma");
        for (row, what) in [
            ("12,mean_pct,inverse,true,5,,80,\"q\"", "table \"12\""),
            ("6,median,inverse,true,5,,80,\"q\"", "kind \"median\""),
            ("6,mean_pct,route,true,5,,80,\"q\"", "strategy \"route\""),
            ("6,mean_pct,inverse,yes,5,,80,\"q\"", "integration \"yes\""),
            ("6,mean_pct,inverse,true,0,,80,\"q\"", "robots \"0\""),
            ("6,mean_pct,inverse,true,5,-4,80,\"q\"", "rc_m \"-4\""),
            ("6,mean_pct,inverse,true,5,,NaN,\"q\"", "value \"NaN\""),
            ("6,mean_pct,inverse,true,5,,80,", "quote"),
            ("6,mean_pct,inverse", "8 fields"),
        ] {
            let e = parse(&format!("{PAPER_HEADER}\n{row}\n"), "p.csv")
                .unwrap_err()
                .to_string();
            assert!(e.starts_with("p.csv:2: ") && e.contains(what), "{e}");
        }
        let e = parse("a,b\n", "p.csv").unwrap_err().to_string();
        assert!(e.contains("p.csv:1") && e.contains("header"), "{e}");
    }
}
