//! A robot's messages and the deposits, written to CDR: a pose as
//! `geometry_msgs/msg/PoseWithCovarianceStamped` (x, y, yaw; the (x, y, yaw) covariance in rows
//! and columns 0, 1 and 5 of the 6×6 one, the rest 0), a trajectory as `nav_msgs/msg/Path`, a
//! deposit as this project's `pheromone_msgs/msg/Deposit` (types::DEPOSIT, docs/ros2.md).

use pheromone_field::{DepositMsg, KernelKind};

use crate::cdr::CdrWriter;
use crate::grid::{header, Stamp};

/// Position and heading: x (m), y (m), θ (rad).
pub type Pose2 = [f64; 3];

/// A `geometry_msgs/msg/Pose` at `(x, y, 0)` turned by `yaw` about z.
fn pose(w: &mut CdrWriter, p: Pose2) {
    let (s, c) = (0.5 * p[2]).sin_cos();
    for v in [p[0], p[1], 0.0, 0.0, 0.0, s, c] {
        w.f64(v);
    }
}

/// The 6×6 covariance (x, y, z, rot x, rot y, rot z) of a row-major (x, y, yaw) 3×3 one.
pub fn covariance_6x6(cov3: &[f64; 9]) -> [f64; 36] {
    let idx = [0, 1, 5];
    let mut out = [0.0; 36];
    for (i, &r) in idx.iter().enumerate() {
        for (j, &c) in idx.iter().enumerate() {
            out[r * 6 + c] = cov3[i * 3 + j];
        }
    }
    out
}

/// A CDR `geometry_msgs/msg/PoseWithCovarianceStamped`.
pub fn pose_with_covariance_cdr(
    stamp: Stamp,
    frame_id: &str,
    p: Pose2,
    covariance: &[f64; 36],
) -> Vec<u8> {
    let mut w = CdrWriter::with_capacity(64 + frame_id.len() + 8 * (7 + 36));
    header(&mut w, stamp, frame_id);
    pose(&mut w, p);
    for &v in covariance {
        w.f64(v);
    }
    w.finish()
}

/// A CDR `nav_msgs/msg/Path`: every pose a `geometry_msgs/msg/PoseStamped` with its own stamp.
pub fn path_cdr(stamp: Stamp, frame_id: &str, poses: &[(Stamp, Pose2)]) -> Vec<u8> {
    let mut w = CdrWriter::with_capacity(32 + frame_id.len() + poses.len() * (80 + frame_id.len()));
    header(&mut w, stamp, frame_id);
    w.seq_len(poses.len());
    for &(s, p) in poses {
        header(&mut w, s, frame_id);
        pose(&mut w, p);
    }
    w.finish()
}

/// A CDR `pheromone_msgs/msg/Deposit`; `peak` is the value the deposit adds at its centre.
pub fn deposit_cdr(stamp: Stamp, frame_id: &str, d: &DepositMsg, peak: f32) -> Vec<u8> {
    let mut w = CdrWriter::with_capacity(128 + frame_id.len());
    header(&mut w, stamp, frame_id);
    w.u32(d.robot_id);
    w.u32(d.channel);
    w.string(KernelKind::from_code(d.kernel).map_or("unknown", KernelKind::name));
    for v in [
        d.x_m,
        d.y_m,
        d.amount,
        peak,
        d.cov_xx,
        d.cov_xy,
        d.cov_yy,
        d.range_m,
        d.gamma_max,
        d.sigma_m,
        d.plateau_m,
        d.slope_m,
    ] {
        w.f32(v);
    }
    w.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cdr::CdrReader;
    use crate::pose::PoseWithCovarianceStamped;

    #[test]
    fn a_pose_reads_back_with_its_yaw_and_covariance() {
        let cov3 = [0.1, 0.02, 0.003, 0.02, 0.2, 0.004, 0.003, 0.004, 0.05];
        let cov = covariance_6x6(&cov3);
        let b =
            pose_with_covariance_cdr(Stamp { sec: 3, nanosec: 5 }, "map", [1.0, -2.0, 0.7], &cov);
        let p = PoseWithCovarianceStamped::from_cdr(&b).unwrap();
        assert_eq!((p.stamp_ns, p.frame_id.as_str()), (3_000_000_005, "map"));
        assert_eq!(&p.position[..2], &[1.0, -2.0]);
        assert!((p.yaw_rad() - 0.7).abs() < 1e-12);
        let back = p.to_pose_msg(4);
        assert_eq!(back.cov, cov3);
        assert_eq!(cov[2 * 6 + 2], 0.0);
    }

    #[test]
    fn a_path_lists_its_poses() {
        let s = |sec| Stamp { sec, nanosec: 0 };
        let b = path_cdr(
            s(9),
            "map",
            &[(s(1), [0.0, 1.0, 0.0]), (s(2), [2.0, 3.0, 0.0])],
        );
        let mut r = CdrReader::new(&b).unwrap();
        assert_eq!((r.i32("").unwrap(), r.u32("").unwrap()), (9, 0));
        assert_eq!(r.string("").unwrap(), "map");
        assert_eq!(r.u32("n").unwrap(), 2);
        for (sec, x) in [(1, 0.0), (2, 2.0)] {
            assert_eq!((r.i32("").unwrap(), r.u32("").unwrap()), (sec, 0));
            assert_eq!(r.string("").unwrap(), "map");
            assert_eq!(r.f64("x").unwrap(), x);
            for _ in 0..6 {
                r.f64("").unwrap();
            }
        }
    }
}
