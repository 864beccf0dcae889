//! Evaporation under the irregular steps of a field that publishes on deposit.
//!
//! A field that publishes on deposit steps by the real elapsed time (`Stepper::step_dt`): the
//! closed forms of the evaporation models must hold whatever the steps, and a step longer than
//! the tick period is clamped to it.

use pheromone_field::{ChannelSpec, DepositMsg, Evaporation, FieldConfig, Stepper};
use pheromone_field::{Deposit, Kernel};

fn config(evaporation: Evaporation, tick_hz: f32) -> FieldConfig {
    FieldConfig {
        width: 16,
        height: 16,
        cell_size_m: 0.1,
        tick_hz,
        channels: vec![ChannelSpec::new("trail", evaporation)],
        ..FieldConfig::default()
    }
}

/// Steps a uniform field of `start` through `dts`; returns the final value of a cell and the
/// field time.
fn run(config: FieldConfig, start: f32, dts: &[f32]) -> (f32, f64) {
    let mut stepper = Stepper::new(config.clone()).unwrap();
    let mut prev = vec![start; config.frame_len()];
    let mut next = vec![0.0; config.frame_len()];
    for &dt in dts {
        stepper.step_dt(&prev, &mut next, dt);
        std::mem::swap(&mut prev, &mut next);
        assert!(prev.iter().all(|v| v.is_finite()), "NaN after dt {dt}");
    }
    (prev[5 * 16 + 7], stepper.sim_time_s)
}

/// Irregular steps of 0.1–10 ms that add up to `total_s` (deterministic).
fn irregular(total_s: f64, period_s: f32) -> Vec<f32> {
    let mut dts = Vec::new();
    let mut t = 0.0f64;
    let mut i = 0u32;
    while t < total_s - 1e-9 {
        let dt = (0.0001 + (i.wrapping_mul(2654435761) % 1000) as f64 * 1e-5)
            .min(period_s as f64)
            .min(total_s - t);
        dts.push(dt as f32);
        t += dt as f32 as f64;
        i += 1;
    }
    dts
}

#[test]
fn exponential_decay_follows_its_closed_form_under_irregular_steps() {
    let k = 0.8f32;
    let dts = irregular(2.0, 0.01);
    assert!(dts.len() > 300, "{} steps", dts.len());
    let (v, t) = run(
        config(Evaporation::Exponential { decay_per_s: k }, 100.0),
        10.0,
        &dts,
    );
    let expected = 10.0 * (-(k as f64) * t).exp();
    assert!(
        ((v as f64) - expected).abs() <= 1e-4 * expected,
        "after {} steps (t = {t:.6} s): {v} vs closed form {expected}",
        dts.len()
    );
}

#[test]
fn ambient_decay_of_a_uniform_field_follows_its_closed_form_under_irregular_steps() {
    // On a uniform field the ambient mean equals the cell, so min(P, α·Pa) = α·P and
    // P(t) = P0 · (α + (1 − α)·e^(−K·t)) after one step; over many steps of total t the plane
    // follows P' = P·(e + (1 − e)·α) per step, whose product is the closed form to check.
    let (k, alpha) = (0.5f32, 0.5f32);
    let dts = irregular(1.0, 0.01);
    let (v, _) = run(
        config(
            Evaporation::Ambient {
                decay_per_s: k,
                alpha,
                radius_m: 0.2,
            },
            100.0,
        ),
        4.0,
        &dts,
    );
    let expected: f64 = dts.iter().fold(4.0f64, |p, &dt| {
        let e = (-(k as f64) * dt as f64).exp();
        p * (e + (1.0 - e) * alpha as f64)
    });
    assert!(
        ((v as f64) - expected).abs() <= 1e-4 * expected,
        "{v} vs {expected}"
    );
}

#[test]
fn saturating_decay_is_per_regular_tick_whatever_the_steps() {
    let rho = 0.05f32;
    // 50 ticks of 20 ms = 1 s, taken in irregular steps: (1 − ρ)^50.
    let dts = irregular(1.0, 0.02);
    let (v, t) = run(
        config(Evaporation::Saturating { rho_per_tick: rho }, 50.0),
        0.8,
        &dts,
    );
    let expected = 0.8 * (1.0 - rho as f64).powf(t / 0.02);
    assert!(
        ((v as f64) - expected).abs() <= 1e-4 * expected,
        "{v} vs {expected}"
    );
}

#[test]
fn the_quantum_model_subtracts_one_quantum_per_whole_tau_whatever_the_steps() {
    let (quantum, tau_s) = (0.5f32, 0.25f32);
    let dts = irregular(1.0, 0.01);
    let (v, t) = run(
        config(Evaporation::Quantum { quantum, tau_s }, 100.0),
        10.0,
        &dts,
    );
    let periods = (t / tau_s as f64 * (1.0 + 2.5e-7)).floor();
    assert_eq!(periods, 4.0, "t = {t}");
    assert_eq!(v, 10.0 - 4.0 * quantum, "after t = {t} s");
}

#[test]
fn a_step_longer_than_the_period_or_not_a_number_is_one_period() {
    let c = config(Evaporation::Exponential { decay_per_s: 1.0 }, 10.0);
    let (v_long, t_long) = run(c.clone(), 1.0, &[5.0]);
    let (v_nan, t_nan) = run(c.clone(), 1.0, &[f32::NAN]);
    let (v_tick, t_tick) = run(c, 1.0, &[0.1]);
    assert_eq!((v_long, v_nan), (v_tick, v_tick));
    assert!(
        (t_long - 0.1).abs() < 1e-6 && (t_nan - 0.1).abs() < 1e-6 && (t_tick - 0.1).abs() < 1e-6
    );
}

#[test]
fn deposits_apply_in_a_short_step_as_in_a_tick() {
    let c = config(Evaporation::None, 100.0);
    let mut stepper = Stepper::new(c.clone()).unwrap();
    let prev = vec![0.0; c.frame_len()];
    let mut next = vec![0.0; c.frame_len()];
    stepper
        .offer(&DepositMsg::from(Deposit {
            channel: 0,
            x_m: 0.8,
            y_m: 0.8,
            kernel: Kernel::Ellipse {
                tau: 0.01,
                cov_m2: [0.01, 0.0, 0.01],
                range_m: 1.0,
                gamma_max: 10.0,
            },
        }))
        .unwrap();
    let report = stepper.step_dt(&prev, &mut next, 0.0002);
    assert_eq!(report.deposits_applied, 1);
    assert!(next.iter().any(|&v| v > 0.0));
    assert!((stepper.sim_time_s - 0.0002).abs() < 1e-9);
}

/// A deposit of robot `robot_id` at (x, y).
fn deposit_of(robot_id: u32, x_m: f32, y_m: f32, gamma_max: f32) -> DepositMsg {
    let mut msg = DepositMsg::from(Deposit {
        channel: 0,
        x_m,
        y_m,
        kernel: Kernel::Ellipse {
            tau: 0.01,
            cov_m2: [0.01, 0.0, 0.01],
            range_m: 0.5,
            gamma_max,
        },
    });
    msg.robot_id = robot_id;
    msg
}

#[test]
fn deposits_that_arrive_during_the_pass_land_in_that_frame_as_if_offered_before_it() {
    let c = config(Evaporation::Exponential { decay_per_s: 0.5 }, 100.0);
    let prev: Vec<f32> = (0..c.frame_len()).map(|i| (i % 7) as f32 * 0.3).collect();
    // Two robots on overlapping cells, where the order of deposits matters (saturation).
    let early = deposit_of(2, 0.8, 0.8, 10.0);
    let late = [deposit_of(1, 0.85, 0.8, 7.0), deposit_of(2, 0.9, 0.75, 3.0)];

    let mut before = Stepper::new(c.clone()).unwrap();
    let mut expected = vec![0.0; c.frame_len()];
    before.offer(&early).unwrap();
    for d in &late {
        before.offer(d).unwrap();
    }
    let expected_report = before.step_dt(&prev, &mut expected, 0.004);

    let mut during = Stepper::new(c.clone()).unwrap();
    let mut got = vec![0.0; c.frame_len()];
    during.offer(&early).unwrap();
    let mut offered_late = 0;
    let report = during.step_dt_then(&prev, &mut got, 0.004, |s| {
        // The pass is done: nothing has been applied yet, the early deposit still waits.
        assert_eq!(s.pending(), 1);
        for d in &late {
            s.offer(d).unwrap();
            offered_late += 1;
        }
    });
    assert_eq!(offered_late, 2);
    assert_eq!(report.deposits_applied, 3);
    assert_eq!(report, expected_report);
    assert_eq!(during.applied(), before.applied(), "the canonical order");
    assert_eq!(during.applied()[0].robot_id, 1, "robot 1 before robot 2");
    let same = got
        .iter()
        .zip(&expected)
        .all(|(a, b)| a.to_bits() == b.to_bits());
    assert!(same, "the frame must be bit-identical");
    assert!(
        got.iter().zip(&prev).any(|(g, p)| g > p),
        "the deposits show"
    );
    assert_eq!(during.pending(), 0);
    assert_eq!(during.sim_time_s, before.sim_time_s);
}
