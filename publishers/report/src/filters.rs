//! Seed 000's comparison of localization filters (Figs. 13–18): the same robot on the same
//! scenario, once per filter (`pheromone sim --compare-filters`). From each run's time series
//! of that robot: the estimation error in x, y and φ at each step and the combined position
//! error (Figs. 13–16), the pheromone it deposited at each step (Fig. 17), and its position
//! uncertainty against its deposits (Fig. 18, log–log). Nothing here is made up: every value
//! is a difference of two recorded poses, or a recorded σ or deposit.

use pheromone_sim::recording::RobotSample;
use serde::Serialize;
use std::fmt::Write as _;

/// One step of one filter's run: the estimate's error and what the robot deposited.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FilterStep {
    pub t_s: f64,
    /// Estimate − truth (m).
    pub err_x_m: f64,
    pub err_y_m: f64,
    /// Estimate − truth, wrapped to (−π, π] (rad).
    pub err_phi_rad: f64,
    /// √(err_x² + err_y²) (m): seed 000 Fig. 16's combined error.
    pub err_xy_m: f64,
    /// √(largest eigenvalue of the estimate's position covariance) (m).
    pub sigma_m: Option<f64>,
    /// The peak of the deposit made at this step (γ, seed 000 eq. 12), if one was made.
    pub deposit: Option<f32>,
}

/// One filter's run of the compared robot.
#[derive(Debug, Clone, PartialEq)]
pub struct FilterRun {
    /// `ekf`, `ukf` or `pf`.
    pub filter: String,
    pub steps: Vec<FilterStep>,
}

/// Wraps an angle to (−π, π].
fn wrap_rad(a: f64) -> f64 {
    let w = a.rem_euclid(std::f64::consts::TAU);
    if w > std::f64::consts::PI {
        w - std::f64::consts::TAU
    } else {
        w
    }
}

impl FilterRun {
    /// The steps of `rows` (one robot's time series) that have an estimate.
    pub fn of(filter: &str, rows: &[RobotSample]) -> Self {
        let steps = rows
            .iter()
            .filter_map(|r| {
                let est = r.est_pose?;
                let (ex, ey) = (est[0] - r.true_pose[0], est[1] - r.true_pose[1]);
                Some(FilterStep {
                    t_s: r.t_s,
                    err_x_m: ex,
                    err_y_m: ey,
                    err_phi_rad: wrap_rad(est[2] - r.true_pose[2]),
                    err_xy_m: ex.hypot(ey),
                    sigma_m: r.est_sigma_m,
                    deposit: r.deposit_peak,
                })
            })
            .collect();
        Self {
            filter: filter.to_string(),
            steps,
        }
    }
}

/// One filter's figures over the run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FilterSummary {
    pub filter: String,
    pub steps: usize,
    pub rms_x_m: f64,
    pub rms_y_m: f64,
    pub rms_phi_rad: f64,
    pub rms_xy_m: f64,
    pub max_xy_m: f64,
    /// Mean and largest σ of the estimate (m), over the steps that report one.
    pub mean_sigma_m: Option<f64>,
    pub max_sigma_m: Option<f64>,
    pub deposits: usize,
    /// Sum of the deposits' peaks.
    pub deposited: f64,
    /// Pearson correlation of ln σ and ln deposit over the steps with both (Fig. 18: the
    /// paper's "peaks in uncertainty correspond to drops in the pheromones"); None with fewer
    /// than 3 such steps or no spread.
    pub log_sigma_log_deposit_r: Option<f64>,
}

fn rms(v: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x * x, n + 1));
    if n == 0 {
        0.0
    } else {
        (sum / n as f64).sqrt()
    }
}

/// Pearson's r of the pairs, None with fewer than 3 or no spread in either.
fn pearson(pairs: &[(f64, f64)]) -> Option<f64> {
    let n = pairs.len() as f64;
    if pairs.len() < 3 {
        return None;
    }
    let (mx, my) = pairs
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (x, y) in pairs {
        sxy += (x - mx) * (y - my);
        sxx += (x - mx) * (x - mx);
        syy += (y - my) * (y - my);
    }
    // Values that are all equal (every deposit at γmax) have no spread, whatever the rounding
    // of the sums says.
    let spread = |f: fn(&(f64, f64)) -> f64| {
        let (lo, hi) = pairs
            .iter()
            .map(f)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                (l.min(v), h.max(v))
            });
        hi - lo > 1e-9 * hi.abs().max(1.0)
    };
    (spread(|p| p.0) && spread(|p| p.1)).then(|| sxy / (sxx * syy).sqrt())
}

impl FilterSummary {
    pub fn of(run: &FilterRun) -> Self {
        let s = &run.steps;
        let sigmas: Vec<f64> = s.iter().filter_map(|p| p.sigma_m).collect();
        let deposits: Vec<f64> = s.iter().filter_map(|p| p.deposit.map(f64::from)).collect();
        let logs: Vec<(f64, f64)> = s
            .iter()
            .filter_map(|p| Some((p.sigma_m?, f64::from(p.deposit?))))
            .filter(|(a, b)| *a > 0.0 && *b > 0.0)
            .map(|(a, b)| (a.ln(), b.ln()))
            .collect();
        Self {
            filter: run.filter.clone(),
            steps: s.len(),
            rms_x_m: rms(s.iter().map(|p| p.err_x_m)),
            rms_y_m: rms(s.iter().map(|p| p.err_y_m)),
            rms_phi_rad: rms(s.iter().map(|p| p.err_phi_rad)),
            rms_xy_m: rms(s.iter().map(|p| p.err_xy_m)),
            max_xy_m: s.iter().map(|p| p.err_xy_m).fold(0.0, f64::max),
            mean_sigma_m: (!sigmas.is_empty())
                .then(|| sigmas.iter().sum::<f64>() / sigmas.len() as f64),
            max_sigma_m: sigmas.iter().copied().reduce(f64::max),
            deposits: deposits.len(),
            deposited: deposits.iter().sum(),
            log_sigma_log_deposit_r: pearson(&logs),
        }
    }
}

impl FilterSummary {
    /// The summary's line on stderr (`sim --compare-filters`).
    pub fn line(&self) -> String {
        format!(
            "  {:>3}: {} steps, RMS error x {:.3} m, y {:.3} m, φ {:.4} rad, combined {:.3} m (max {:.3} m); \
             mean σ {:.3} m; {} deposits summing {:.1}; r(ln σ, ln γ) {}",
            self.filter,
            self.steps,
            self.rms_x_m,
            self.rms_y_m,
            self.rms_phi_rad,
            self.rms_xy_m,
            self.max_xy_m,
            self.mean_sigma_m.unwrap_or(f64::NAN),
            self.deposits,
            self.deposited,
            self.log_sigma_log_deposit_r
                .map_or("n/a".into(), |r| format!("{r:.3}")),
        )
    }
}

/// `filters.json` and the `--json` line of `sim --compare-filters`.
#[derive(Debug, Serialize)]
pub struct Comparison {
    pub scenario: String,
    pub seed: u64,
    pub robot: u32,
    /// Particles of the PF run.
    pub particles: Option<usize>,
    /// The largest distance between the robot's true positions at the same step in two of the
    /// runs (m): 0 when the filter changes nothing but the estimate.
    pub truth_spread_m: f64,
    pub filters: Vec<FilterSummary>,
}

/// The largest distance between the true positions at the same step of two of `series` (m).
pub fn truth_spread_m(series: &[Vec<RobotSample>]) -> f64 {
    let mut spread: f64 = 0.0;
    for a in series {
        for b in series {
            for (p, q) in a.iter().zip(b) {
                let d = (p.true_pose[0] - q.true_pose[0]).hypot(p.true_pose[1] - q.true_pose[1]);
                spread = spread.max(d);
            }
        }
    }
    spread
}

/// Header of `filters.csv`.
pub const FILTERS_CSV_HEADER: &str =
    "filter,t_s,err_x_m,err_y_m,err_phi_rad,err_xy_m,sigma_m,deposit";

/// Every step of every run, one row each; empty cells where a value is absent.
pub fn filters_csv(runs: &[FilterRun]) -> String {
    let mut text = String::from(FILTERS_CSV_HEADER);
    text.push('\n');
    let opt = |v: Option<f64>| v.map(|v| v.to_string()).unwrap_or_default();
    for r in runs {
        for p in &r.steps {
            // Writing into a String cannot fail.
            let _ = writeln!(
                text,
                "{},{},{},{},{},{},{},{}",
                r.filter,
                p.t_s,
                p.err_x_m,
                p.err_y_m,
                p.err_phi_rad,
                p.err_xy_m,
                opt(p.sigma_m),
                opt(p.deposit.map(f64::from)),
            );
        }
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t_s: f64, truth: [f64; 3], est: Option<[f64; 3]>, dep: Option<f32>) -> RobotSample {
        RobotSample {
            t_s,
            true_pose: truth,
            est_pose: est,
            est_sigma_m: est.map(|_| 0.1 * (1.0 + t_s)),
            v_m_per_s: 0.0,
            omega_rad_per_s: 0.0,
            state: None,
            sensed_level: None,
            deposit_peak: dep,
        }
    }

    #[test]
    fn errors_are_estimate_minus_truth_with_the_angle_wrapped() {
        let rows = [
            sample(0.0, [1.0, 2.0, 3.1], Some([1.3, 1.6, -3.1]), Some(100.0)),
            sample(0.1, [1.0, 2.0, 0.0], None, None),
            sample(0.2, [0.0, 0.0, -3.0], Some([0.0, 0.0, 3.0]), None),
        ];
        let run = FilterRun::of("pf", &rows);
        assert_eq!(run.steps.len(), 2, "a step without an estimate is skipped");
        let p = run.steps[0];
        assert!((p.err_x_m - 0.3).abs() < 1e-12 && (p.err_y_m + 0.4).abs() < 1e-12);
        assert!((p.err_xy_m - 0.5).abs() < 1e-12);
        let want = std::f64::consts::TAU - 6.2;
        assert!((p.err_phi_rad - want).abs() < 1e-12, "{}", p.err_phi_rad);
        let q = run.steps[1];
        assert!((q.err_phi_rad - (6.0 - std::f64::consts::TAU)).abs() < 1e-12);
        let s = FilterSummary::of(&run);
        assert_eq!((s.steps, s.deposits), (2, 1));
        assert!((s.rms_xy_m - (0.25f64 / 2.0).sqrt()).abs() < 1e-12);
        assert!((s.max_xy_m - 0.5).abs() < 1e-12, "{}", s.max_xy_m);
        assert_eq!(
            s.log_sigma_log_deposit_r, None,
            "one pair has no correlation"
        );
    }

    #[test]
    fn deposits_that_fall_as_sigma_grows_correlate_negatively() {
        let rows: Vec<RobotSample> = (0..20)
            .map(|k| {
                let t = k as f64;
                let s = sample(t, [0.0; 3], Some([0.0; 3]), None);
                let sigma = s.est_sigma_m.unwrap();
                RobotSample {
                    deposit_peak: Some((0.2 / (sigma * sigma)) as f32),
                    ..s
                }
            })
            .collect();
        let s = FilterSummary::of(&FilterRun::of("ekf", &rows));
        let r = s.log_sigma_log_deposit_r.unwrap();
        assert!(
            (r + 1.0).abs() < 1e-6,
            "γ = τ/σ² is exactly −1 in log–log: {r}"
        );
        let csv = filters_csv(&[FilterRun::of("ekf", &rows)]);
        assert_eq!(csv.lines().count(), 21);
        assert!(csv.starts_with(FILTERS_CSV_HEADER));
    }
}
