//! The targets of issues 6, 14, 15 and 18: each goal with its limit, the value measured in the
//! run and whether it is met (`Report::targets`).

use serde::Serialize;

use crate::Report;

/// One target of issue 6, with what was measured.
#[derive(Debug, Clone, Serialize)]
pub struct Target {
    pub name: String,
    /// `"<="` or `">="`.
    pub op: &'static str,
    pub limit: f64,
    pub measured: f64,
    pub met: bool,
    /// Why nothing was measured (a peer of `--only peers` that could not run); `measured` is
    /// then NaN (null in JSON) and `met` false.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unavailable: Option<String>,
}

pub(crate) fn target(name: &str, op: &'static str, limit: f64, measured: f64) -> Target {
    // Two decimals, or three significant digits for a value under 1 (a ratio of 0.004 stays
    // 0.004, not 0).
    let round = |v: f64| {
        if v == 0.0 || !v.is_finite() {
            return v;
        }
        let decimals = (2 - v.abs().log10().floor() as i32).clamp(2, 12);
        let scale = 10f64.powi(decimals);
        (v * scale).round() / scale
    };
    Target {
        name: name.into(),
        op,
        limit: round(limit),
        measured: round(measured),
        met: if op == ">=" {
            measured >= limit
        } else {
            measured <= limit
        },
        unavailable: None,
    }
}

/// The targets of issues 6 and 18, each with the measured value and whether it is met.
pub fn targets(r: &Report) -> Vec<Target> {
    let mut t = Vec::new();
    tick_targets(r, &mut t);
    merge_targets(r, &mut t);
    hop_targets(r, &mut t);
    frame_targets(r, &mut t);
    visible_targets(r, &mut t);
    timing_targets(r, &mut t);
    gateway_targets(r, &mut t);
    mirror_targets(r, &mut t);
    c_abi_targets(r, &mut t);
    ros2_targets(r, &mut t);
    peer_targets(r, &mut t);
    t
}

/// Issue 53: ours at or below each peer's time (ours / peer ≤ 1), or why the peer did not run.
fn peer_targets(r: &Report, t: &mut Vec<Target>) {
    let Some(p) = &r.peers else { return };
    let mut push = |name: String, f: &crate::peers::PeerFigure| {
        t.push(match (f.ratio, &f.unavailable) {
            (Some(ratio), _) => target(&name, "<=", 1.0, ratio),
            (None, why) => Target {
                unavailable: Some(why.clone().unwrap_or_else(|| "no figure".into())),
                ..target(&name, "<=", 1.0, f64::NAN)
            },
        })
    };
    for a in &p.ambient {
        let at = format!("{0}x{0}, radius {1} cells", a.side, a.radius_cells);
        push(
            format!("ambient tick / OpenCV boxFilter at {at}"),
            &a.opencv_box,
        );
        push(
            format!("ambient tick / SciPy uniform_filter at {at}"),
            &a.scipy_uniform,
        );
    }
    for m in &p.merge {
        push(
            format!(
                "merge ({}) / OpenCV warpAffine + NumPy at {1}x{1}",
                m.rule, m.side
            ),
            &m.opencv_numpy,
        );
    }
}

/// One target over several runs: its measured value's min / median / max and how often it was
/// met.
#[derive(Debug, Clone, Serialize)]
pub struct Spread {
    pub name: String,
    pub op: &'static str,
    pub limit: f64,
    pub min: f64,
    pub median: f64,
    pub max: f64,
    pub met: usize,
    pub runs: usize,
}

/// Each target of the runs (by name, in the first run's order) over the runs that measured it.
pub fn spread(runs: &[Report]) -> Vec<Spread> {
    let Some(first) = runs.first() else {
        return Vec::new();
    };
    first
        .targets
        .iter()
        .map(|t0| {
            let all: Vec<&Target> = runs
                .iter()
                .filter_map(|r| r.targets.iter().find(|t| t.name == t0.name))
                .collect();
            let mut v: Vec<f64> = all.iter().map(|t| t.measured).collect();
            v.sort_by(f64::total_cmp);
            let median = match v.len() % 2 {
                1 => v[v.len() / 2],
                _ => 0.5 * (v[v.len() / 2 - 1] + v[v.len() / 2]),
            };
            Spread {
                name: t0.name.clone(),
                op: t0.op,
                limit: t0.limit,
                min: v[0],
                median,
                max: v[v.len() - 1],
                met: all.iter().filter(|t| t.met).count(),
                runs: all.len(),
            }
        })
        .collect()
}

/// A tick costs little more than copying the frame.
fn tick_targets(r: &Report, t: &mut Vec<Target>) {
    for (size, row) in &r.tick_vs_memcpy {
        t.push(target(
            &format!("plain tick / memcpy at {size}"),
            "<=",
            1.1,
            row.exponential_ratio,
        ));
        t.push(target(
            &format!("ambient tick / memcpy at {size}"),
            "<=",
            1.5,
            row.ambient_ratio,
        ));
        for by in &row.ambient_by_radius {
            t.push(target(
                &format!(
                    "ambient tick / memcpy at {size}, radius {} cells",
                    by.radius_cells
                ),
                "<=",
                1.5,
                by.ambient_ratio,
            ));
        }
    }
}

/// A map merge costs at most a few memcpys of its planes (issue 33).
fn merge_targets(r: &Report, t: &mut Vec<Target>) {
    for (size, row) in &r.merge_vs_memcpy {
        t.push(target(
            &format!("merge / memcpy at {size}"),
            "<=",
            3.0,
            row.merge_ratio,
        ));
    }
}

/// A hop costs little more than raw iceoryx2's.
fn hop_targets(r: &Report, t: &mut Vec<Target>) {
    if let Some(h) = &r.hop_ns {
        t.push(target(
            "hop p50 ours / raw iceoryx2 (wait)",
            "<=",
            1.5,
            h.ours.p50 / h.raw_iceoryx2.p50,
        ));
        t.push(target(
            "hop p50 ours / raw iceoryx2 (busy-poll)",
            "<=",
            1.5,
            h.busy_poll.ours.p50 / h.busy_poll.raw_iceoryx2.p50,
        ));
    }
}

/// Frame delivery: independent of the frame size, near raw iceoryx2, far ahead of a copy.
fn frame_targets(r: &Report, t: &mut Vec<Target>) {
    if let (Some(small), Some(big)) = (r.frame_ns.get("1MiB"), r.frame_ns.get("16MiB")) {
        t.push(target(
            "frame p50 16 MiB / 1 MiB (ours, 1 reader)",
            "<=",
            2.0,
            big.ours.p50 / small.ours.p50,
        ));
        t.push(target(
            "frame p50 16 MiB / 1 MiB (ours, 8 readers)",
            "<=",
            2.0,
            big.readers_8.ours.p50 / small.readers_8.ours.p50,
        ));
        for (size, f) in [("1 MiB", small), ("16 MiB", big)] {
            t.push(target(
                &format!("frame p50 ours / raw iceoryx2 at {size} (wait)"),
                "<=",
                1.5,
                f.ours.p50 / f.raw_iceoryx2.p50,
            ));
            t.push(target(
                &format!("frame p50 ours / raw iceoryx2 at {size} (busy-poll)"),
                "<=",
                1.5,
                f.ours_busy_poll.p50 / f.raw_iceoryx2_busy_poll.p50,
            ));
            t.push(target(
                &format!("frame p50 ours / raw iceoryx2 at {size} (paced spin)"),
                "<=",
                1.5,
                f.ours_spin.p50 / f.raw_iceoryx2_spin.p50,
            ));
        }
        t.push(target(
            "frame p50 16 MiB / 1 MiB: ours / raw iceoryx2's (busy-poll)",
            "<=",
            1.0,
            (big.ours_busy_poll.p50 / small.ours_busy_poll.p50)
                / (big.raw_iceoryx2_busy_poll.p50 / small.raw_iceoryx2_busy_poll.p50),
        ));
        // Issue 18: ≥ 1000× both, in wait mode (every reader waits) and with ours busy-polling
        // (the socket and Zenoh readers block in their receive either way: their frame takes
        // milliseconds to copy and decode, so polling would not change them).
        t.push(target(
            "16 MiB frame p50: UDS+serde / ours (1 reader, wait)",
            ">=",
            1000.0,
            big.uds_serde.p50 / big.ours.p50,
        ));
        t.push(target(
            "16 MiB frame p50: UDS+serde / ours busy-polling (1 reader)",
            ">=",
            1000.0,
            big.uds_serde.p50 / big.ours_busy_poll.p50,
        ));
        if let Some(z) = big.zenoh {
            t.push(target(
                "16 MiB frame p50: Zenoh / ours (1 reader, wait)",
                ">=",
                1000.0,
                z.p50 / big.ours.p50,
            ));
            t.push(target(
                "16 MiB frame p50: Zenoh / ours busy-polling (1 reader)",
                ">=",
                1000.0,
                z.p50 / big.ours_busy_poll.p50,
            ));
        }
    }
}

/// A deposit is visible within a tick (or at once, publishing on deposit).
fn visible_targets(r: &Report, t: &mut Vec<Target>) {
    if let Some(v) = &r.deposit_to_visible_us {
        t.push(target(
            "deposit-to-visible p99 µs (limit: period + 1.2 x tick compute p99 + 50 µs)",
            "<=",
            v.target_p99_us,
            v.latency.p99,
        ));
    }
    if let Some(v) = &r.deposit_to_visible_on_deposit_us {
        t.push(target(
            "deposit-to-visible p99 µs, publishing on deposit (limit: tick compute p99 + 100 µs)",
            "<=",
            v.target_p99_us,
            v.latency.p99,
        ));
    }
    if let Some(v) = &r.deposit_to_visible_on_deposit_rt_us {
        t.push(target(
            "deposit-to-visible p99 µs, on deposit, SCHED_FIFO + spin + busy-poll (limit: tick compute p99 + 100 µs)",
            "<=",
            v.target_p99_us,
            v.latency.p99,
        ));
    }
}

/// Issue 33: with real-time scheduling the field keeps its period beside busy loops.
fn timing_targets(r: &Report, t: &mut Vec<Target>) {
    for row in r.tick_timing.iter().filter(|row| row.realtime) {
        let what = format!(
            "{} Hz beside {} busy loops, SCHED_FIFO, spin {} µs",
            row.tick_hz, row.busy_loops, row.spin_us
        );
        t.push(target(
            &format!("longest tick gap in periods, {what}"),
            "<=",
            1.5,
            row.field.longest_gap_periods,
        ));
        t.push(target(
            &format!("tick-start lateness p99 µs, {what}"),
            "<=",
            100.0,
            row.field.lateness.p99_us as f64,
        ));
    }
}

/// The gateway (issue 14).
fn gateway_targets(r: &Report, t: &mut Vec<Target>) {
    // Issue 14: a PIR answered well inside a 10 Hz robot's step, and one gateway core serving
    // 1000 robots at 10 Hz (seed 002's server load grows with N² per axis; ours is O(1) per PIR).
    if let Some(g) = &r.gateway_pir {
        t.push(target(
            "PIR round trip p99 µs over UDP loopback",
            "<=",
            1000.0,
            g.pir_round_trip_ns.p99 / 1e3,
        ));
        t.push(target(
            "PIRs per second of gateway CPU (one core)",
            ">=",
            10_000.0,
            g.flood.pirs_per_cpu_s,
        ));
    }
    if let Some(l) = r.gateway_pir_loaded_rt.as_ref().filter(|l| l.realtime) {
        t.push(target(
            "PIR round trip p99 µs beside 2 busy loops, gateway and client SCHED_FIFO",
            "<=",
            1000.0,
            l.pir_round_trip_ns.p99 / 1e3,
        ));
    }
}

/// Issue 15: a mirror's wire traffic stays a small fraction of shipping the frames.
#[cfg(feature = "zenoh")]
fn mirror_targets(r: &Report, t: &mut Vec<Target>) {
    let Some(m) = &r.mirror else {
        return;
    };
    if let Some(w) = m.wire.iter().find(|w| w.deposits_per_s >= 1000.0) {
        // Rounded to 2 decimals: the ratio is reported in percent.
        t.push(target(
            &format!(
                "mirror wire bytes / raw frames at {0}x{0}, {1} Hz, 1000 deposits/s (%)",
                m.width, m.tick_hz
            ),
            "<=",
            1.0,
            w.ratio_to_raw * 100.0,
        ));
    }
}

#[cfg(not(feature = "zenoh"))]
fn mirror_targets(_r: &Report, _t: &mut [Target]) {}

/// libpheromone's C reader is as fast as the Rust reader it wraps.
fn c_abi_targets(r: &Report, t: &mut Vec<Target>) {
    if let Some(c) = &r.c_abi {
        t.push(target(
            "C reader frame latency p50 / Rust reader's",
            "<=",
            1.1,
            c.frame_ratio_p50,
        ));
        t.push(target(
            "C sampling (value + gradient) / Rust FrameView's",
            "<=",
            1.1,
            c.sample_ratio,
        ));
        t.push(target(
            "C batch sampling (pheromone_sample_many) / Rust FrameView's",
            "<=",
            1.1,
            c.sample_batch_ratio,
        ));
    }
}

/// Issue 46: `pheromone ros2` costs at most 1.5 x a plain Zenoh publisher per published MB.
fn ros2_targets(r: &Report, t: &mut Vec<Target>) {
    if let Some(x) = &r.ros2 {
        t.push(target(
            &format!(
                "pheromone ros2 CPU per published MB / plain Zenoh publisher's ({0}x{0}, {1} Hz)",
                x.width, x.rate_hz
            ),
            "<=",
            1.5,
            x.cpu_per_mb_ratio,
        ));
    }
}

#[cfg(test)]
mod tests {
    use super::target;

    #[test]
    fn a_target_keeps_the_significant_digits_of_a_small_ratio() {
        let t = target("small", "<=", 1.5, 0.002517);
        assert_eq!(t.measured, 0.00252);
        assert!(t.met);
        let t = target("large", ">=", 1000.0, 2704.9712);
        assert_eq!(t.measured, 2704.97);
        assert!(t.met);
        assert_eq!(target("zero", "<=", 1.0, 0.0).measured, 0.0);
    }
}
