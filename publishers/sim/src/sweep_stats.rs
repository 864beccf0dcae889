//! The statistics of a sweep (`pheromone sweep`): mean and sample standard deviation of a
//! point's trials, Welch's unequal-variance t (the paper's IAS-SS vs uniform test, Table 2) and
//! the paired t over matching seeds (the paper's with vs without integration, Tables 5 and 8).
//! A test whose statistic is undefined (fewer than two trials on a side, or no variance at all)
//! is `None`, never NaN.

use serde::Serialize;

/// Mean and sample standard deviation (n − 1 in the denominator; 0 for a single value).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MeanSd {
    pub n: usize,
    pub mean: f64,
    pub sd: f64,
}

impl MeanSd {
    /// `None` for an empty sample.
    pub fn of(v: &[f64]) -> Option<MeanSd> {
        if v.is_empty() {
            return None;
        }
        let n = v.len();
        let mean = v.iter().sum::<f64>() / n as f64;
        let sd = if n < 2 {
            0.0
        } else {
            (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
        };
        Some(MeanSd { n, mean, sd })
    }
}

/// A t statistic and its degrees of freedom.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TTest {
    pub t: f64,
    pub df: f64,
}

/// Welch's t of `a` against `b` (positive when `a`'s mean is larger) with the
/// Welch–Satterthwaite degrees of freedom. `None` with fewer than two values on a side or when
/// both samples have no variance.
pub fn welch(a: &[f64], b: &[f64]) -> Option<TTest> {
    let (x, y) = (MeanSd::of(a)?, MeanSd::of(b)?);
    if x.n < 2 || y.n < 2 {
        return None;
    }
    let (v1, v2) = (x.sd * x.sd / x.n as f64, y.sd * y.sd / y.n as f64);
    let v = v1 + v2;
    if v <= 0.0 {
        return None;
    }
    let t = (x.mean - y.mean) / v.sqrt();
    let df = v * v / (v1 * v1 / (x.n - 1) as f64 + v2 * v2 / (y.n - 1) as f64);
    Some(TTest { t, df })
}

/// The paired t of `a` against `b` (value i of each from the same seed), df = n − 1. `None`
/// when the lengths differ, with fewer than two pairs, or when every difference is the same.
pub fn paired(a: &[f64], b: &[f64]) -> Option<TTest> {
    if a.len() != b.len() || a.len() < 2 {
        return None;
    }
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    let s = MeanSd::of(&d)?;
    if s.sd <= 0.0 {
        return None;
    }
    Some(TTest {
        t: s.mean / (s.sd / (s.n as f64).sqrt()),
        df: (s.n - 1) as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn welch_t_matches_a_hand_computed_value() {
        // a = 1..4: mean 2.5, s² = 5/3, s²/n = 5/12; b = 2, 4, …, 10: mean 6, s² = 10, s²/n = 2.
        // t = −3.5 / √(29/12) = −2.251 436; df = (29/12)² / ((5/12)²/3 + 2²/4) = 5.520 79.
        let r = welch(&[1.0, 2.0, 3.0, 4.0], &[2.0, 4.0, 6.0, 8.0, 10.0]).unwrap();
        assert!((r.t + 2.251_436).abs() < 1e-5, "{r:?}");
        assert!((r.df - 5.520_788).abs() < 1e-5, "{r:?}");
        // Swapping the samples flips the sign only.
        let s = welch(&[2.0, 4.0, 6.0, 8.0, 10.0], &[1.0, 2.0, 3.0, 4.0]).unwrap();
        assert_eq!((s.t, s.df), (-r.t, r.df));
    }

    #[test]
    fn paired_t_matches_a_hand_computed_value() {
        // d = −0.5, −0.5, 0, −1: mean −0.5, s² = 1/6, t = −0.5 / (√(1/6) / 2) = −2.449 490.
        let r = paired(&[1.0, 2.0, 3.0, 4.0], &[1.5, 2.5, 3.0, 5.0]).unwrap();
        assert!((r.t + 2.449_490).abs() < 1e-5, "{r:?}");
        assert_eq!(r.df, 3.0);
    }

    #[test]
    fn undefined_tests_are_none_and_mean_sd_is_the_sample_one() {
        assert_eq!(welch(&[1.0], &[2.0, 3.0]), None);
        assert_eq!(welch(&[1.0, 1.0], &[1.0, 1.0]), None);
        assert_eq!(paired(&[1.0, 2.0], &[0.0, 1.0]), None, "equal differences");
        assert_eq!(paired(&[1.0, 2.0], &[0.0]), None);
        let m = MeanSd::of(&[1.0, 2.0, 3.0, 4.0]).unwrap();
        assert!((m.mean - 2.5).abs() < 1e-12 && (m.sd - 1.290_994_448_735_805_6).abs() < 1e-12);
        assert_eq!(MeanSd::of(&[0.7]).unwrap().sd, 0.0);
        assert_eq!(MeanSd::of(&[]), None);
        // One side without variance: still defined.
        assert!(welch(&[1.0, 1.0, 1.0], &[0.5, 0.7, 0.6]).is_some());
    }
}
