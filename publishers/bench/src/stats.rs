//! Latency histograms (HdrHistogram) and their percentiles.

use hdrhistogram::Histogram;
use serde::Serialize;

/// Percentiles of one latency distribution, in the unit its field name gives.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Latency {
    pub p50: f64,
    pub p99: f64,
    pub p999: f64,
    pub max: f64,
    /// Samples behind the percentiles.
    pub samples: u64,
}

/// Builds a histogram of nanosecond samples (1 ns … 60 s, 3 significant digits).
pub fn histogram(samples_ns: &[u64]) -> Histogram<u64> {
    let mut h = Histogram::<u64>::new_with_bounds(1, 60_000_000_000, 3)
        .expect("static histogram bounds are valid");
    for &s in samples_ns {
        h.saturating_record(s.max(1));
    }
    h
}

impl Latency {
    /// Percentiles of `samples_ns` in nanoseconds; `None` without samples.
    pub fn from_ns(samples_ns: &[u64]) -> Option<Self> {
        Self::scaled(samples_ns, 1.0)
    }

    /// Percentiles of `samples_ns` in microseconds.
    pub fn from_ns_as_us(samples_ns: &[u64]) -> Option<Self> {
        Self::scaled(samples_ns, 1e-3)
    }

    fn scaled(samples_ns: &[u64], scale: f64) -> Option<Self> {
        if samples_ns.is_empty() {
            return None;
        }
        let h = histogram(samples_ns);
        let q = |q: f64| h.value_at_quantile(q) as f64 * scale;
        let round = |v: f64| (v * 10.0).round() / 10.0;
        Some(Self {
            p50: round(q(0.5)),
            p99: round(q(0.99)),
            p999: round(q(0.999)),
            max: round(h.max() as f64 * scale),
            samples: h.len(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_ordered_and_match_the_samples() {
        let samples: Vec<u64> = (1..=10_000).collect();
        let l = Latency::from_ns(&samples).unwrap();
        assert!(l.p50 <= l.p99 && l.p99 <= l.p999 && l.p999 <= l.max);
        assert!((l.p50 - 5000.0).abs() <= 5.0, "{l:?}");
        assert!((l.max - 10_000.0).abs() <= 10.0, "{l:?}");
        assert_eq!(l.samples, 10_000);
        assert!(Latency::from_ns(&[]).is_none());
        let us = Latency::from_ns_as_us(&[2_000, 4_000]).unwrap();
        assert!((us.max - 4.0).abs() < 0.01, "{us:?}");
    }
}
