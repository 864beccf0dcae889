//! A mirror's replay of the origin's applied deposits gives bit-identical frames.
//!
//! A mirror replays the origin's applied deposits (`Stepper::applied` → `Stepper::replay`) and
//! computes bit-identical frames, whatever order the deposits arrived in at the origin.

use pheromone_field::{ChannelSpec, DepositMsg, Evaporation, FieldConfig, Stepper};
use pheromone_field::{Deposit, Kernel};

fn config() -> FieldConfig {
    FieldConfig {
        width: 32,
        height: 32,
        cell_size_m: 0.1,
        tick_hz: 50.0,
        channels: vec![
            ChannelSpec::new(
                "trail",
                Evaporation::Ambient {
                    decay_per_s: 0.3,
                    alpha: 0.5,
                    radius_m: 0.3,
                },
            ),
            ChannelSpec::new("quanta", Evaporation::Exponential { decay_per_s: 0.5 }),
        ],
        ..FieldConfig::default()
    }
}

fn deposit(robot: u32, i: u32) -> DepositMsg {
    let mut d = DepositMsg::from(Deposit {
        channel: i % 2,
        x_m: 0.3 + (i % 23) as f32 * 0.11,
        y_m: 0.4 + (i % 17) as f32 * 0.13,
        kernel: Kernel::Ellipse {
            tau: 1.0 + (i % 5) as f32,
            cov_m2: [0.01, 0.0, 0.01],
            range_m: 0.4,
            gamma_max: 0.2,
        },
    });
    d.robot_id = robot;
    d
}

#[test]
fn replayed_inputs_give_bit_identical_frames() {
    let c = config();
    let mut origin = Stepper::new(c.clone()).unwrap();
    let mut mirror = Stepper::new(c.clone()).unwrap();
    let (mut op, mut on) = (vec![0.0f32; c.frame_len()], vec![0.0f32; c.frame_len()]);
    let (mut mp, mut mn) = (op.clone(), on.clone());
    let mut rejected_seen = false;
    for tick in 0..200u32 {
        // Robots offer in an interleaved order; one deposit per tick is invalid (rejected).
        for k in 0..(tick % 7) {
            let robot = (tick + k) % 3;
            origin.offer(&deposit(robot, tick * 7 + k)).unwrap();
        }
        let mut bad = deposit(1, tick);
        bad.x_m = f32::NAN;
        rejected_seen |= origin.offer(&bad).is_err();
        let report = if tick % 5 == 4 {
            origin.step_dt(&op, &mut on, 0.0071)
        } else {
            origin.step(&op, &mut on)
        };
        let (before, dt_s, dt_time_s) = origin.last_step();
        assert_eq!(origin.applied().len(), report.deposits_applied as usize);
        let (_, refused) = mirror.replay(&mp, &mut mn, origin.applied(), before, dt_s, dt_time_s);
        assert_eq!(refused, 0);
        std::mem::swap(&mut op, &mut on);
        std::mem::swap(&mut mp, &mut mn);
        let same = op.iter().zip(&mp).all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(same, "frames differ at tick {tick}");
        assert_eq!(origin.sim_time_s.to_bits(), mirror.sim_time_s.to_bits());
    }
    assert!(rejected_seen);
    assert!(op.iter().any(|v| *v > 0.0), "the deposits left nothing");
}
