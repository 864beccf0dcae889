use std::time::{Duration, Instant};

use pheromone_field::{FrameView, GridGeometry};

use super::*;
use crate::follower::test_support::{gaussian_ridge, synth};
use crate::follower::{AntennaConfig, Follower};

/// A source that reads an owned frame the way the gateway does (half the wheel base on the
/// wire, doubled by the server), and records what it was asked.
struct OwnedSource {
    geometry: GridGeometry,
    cells: Vec<f32>,
    seq: u64,
    asked: Vec<(u8, SamplePose, f32, u64)>,
}

impl AntennaSource for OwnedSource {
    fn name(&self) -> String {
        "owned".into()
    }

    fn read(
        &mut self,
        channel: u8,
        head: SamplePose,
        wheel_base_m: f32,
        min_seq: u64,
        _deadline: Instant,
    ) -> Result<Option<AntennaReading>, AntennaSourceError> {
        self.asked.push((channel, head, wheel_base_m, min_seq));
        if self.seq < min_seq {
            return Ok(None);
        }
        let half = 0.5 * wheel_base_m;
        let view = FrameView::new(self.geometry, 1, &self.cells);
        let (p_left, p_right) = view.antennas(channel as usize, head, 2.0 * half);
        Ok(Some(AntennaReading {
            p_left,
            p_right,
            frame_seq: self.seq,
        }))
    }

    fn stats(&self) -> SourceStats {
        SourceStats::default()
    }
}

#[test]
fn an_antenna_robot_decides_exactly_what_the_shared_memory_follower_decides() {
    let (g, cells) = synth(10.0, 10.0, 0.05, |_, y| gaussian_ridge(y - 5.0, 10.0, 0.25));
    let config = AntennaConfig {
        normalize_max: Some(10.0),
        ..AntennaConfig::default()
    };
    let mut shm = Follower::new(
        3,
        Box::new(AntennaFollower::new(0, config.clone()).unwrap()),
    );
    let source = OwnedSource {
        geometry: g,
        cells: cells.clone(),
        seq: 7,
        asked: Vec::new(),
    };
    let mut remote = AntennaRobot::new(3, AntennaFollower::new(0, config).unwrap(), source);
    let frame = FrameView::new(g, 1, &cells);
    let deadline = Instant::now() + Duration::from_secs(1);
    for (i, (x, y, th)) in [(2.0, 5.1, 0.0), (4.0, 4.8, 0.4), (6.0, 5.3, -0.7)]
        .into_iter()
        .enumerate()
    {
        let pose = PoseMsg {
            step: i as u64,
            x_m: x,
            y_m: y,
            theta_rad: th,
            ..PoseMsg::default()
        };
        let want = shm.step_pose(&frame, &pose, 0.1).unwrap();
        let (got, reading) = remote.step_pose(&pose, 0.1, 7, deadline).unwrap().unwrap();
        assert_eq!(got, want, "pose {i}");
        assert_eq!(reading.frame_seq, 7);
        // The antennas' centre is the pose moved antenna_ahead_m along the heading.
        let (_, head, base, min_seq) = remote.source().asked[i];
        let a = AntennaConfig::default().antenna_ahead_m;
        assert!((head.x_m - (x as f32 + a * (th as f32).cos())).abs() < 1e-6);
        assert!((head.y_m - (y as f32 + a * (th as f32).sin())).abs() < 1e-6);
        assert_eq!((base, min_seq), (0.3, 7));
    }
    assert!(
        remote
            .step_pose(&PoseMsg::default(), 0.1, 8, deadline)
            .unwrap()
            .is_none(),
        "no frame 8 yet: no command"
    );
}

#[test]
fn an_antenna_robot_refuses_a_non_finite_pose_before_asking() {
    let (g, cells) = synth(4.0, 4.0, 0.1, |_, _| 1.0);
    let source = OwnedSource {
        geometry: g,
        cells,
        seq: 1,
        asked: Vec::new(),
    };
    let mut remote = AntennaRobot::new(
        0,
        AntennaFollower::new(0, AntennaConfig::default()).unwrap(),
        source,
    );
    let pose = PoseMsg {
        x_m: f64::NAN,
        ..PoseMsg::default()
    };
    let e = remote
        .step_pose(&pose, 0.1, 0, Instant::now())
        .unwrap_err()
        .to_string();
    assert!(e.contains("x_m") && e.contains("NaN"), "{e}");
    assert!(remote.source().asked.is_empty());
}

#[test]
fn frame_sequences_compare_across_the_32_bit_wrap() {
    assert!(seq_reached(5, 5));
    assert!(seq_reached(6, 5));
    assert!(!seq_reached(4, 5));
    // Frame 2^32 + 1 is sent as 1: it is past frame 2^32 − 1.
    assert!(seq_reached(1, u32::MAX as u64));
    assert!(!seq_reached(u32::MAX, (1u64 << 32) + 1));
}

#[test]
fn deposits_need_a_gateway() {
    let (g, cells) = synth(4.0, 4.0, 0.1, |_, _| 1.0);
    let mut s = OwnedSource {
        geometry: g,
        cells,
        seq: 1,
        asked: Vec::new(),
    };
    let e = s.deposit(1.0, 1.0, 1.0, 0).unwrap_err().to_string();
    assert!(e.contains("owned") && e.contains("--gateway"), "{e}");
}
