//! `geometry_msgs/msg/PoseWithCovarianceStamped` (what AMCL publishes on `/amcl_pose`, and
//! robot_localization on `/odometry/filtered`'s pose) read from CDR and turned into the
//! depositor's [`PoseMsg`]: position x, y; heading = the yaw of the orientation quaternion; the
//! 3×3 covariance of (x, y, yaw) taken from rows/columns 0, 1 and 5 of the 6×6 one.

use thiserror::Error;

use crate::cdr::{CdrError, CdrReader};
use crate::deps::depositor::{validate_pose, PoseRejection};
use crate::deps::PoseMsg;

/// A decoded `PoseWithCovarianceStamped`.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseWithCovarianceStamped {
    pub stamp_ns: i64,
    pub frame_id: String,
    /// x, y, z (m).
    pub position: [f64; 3],
    /// x, y, z, w.
    pub orientation: [f64; 4],
    /// Row-major 6×6 over (x, y, z, rot x, rot y, rot z).
    pub covariance: [f64; 36],
}

impl PoseWithCovarianceStamped {
    /// Reads a CDR message; a truncated or malformed one is an error naming where.
    pub fn from_cdr(msg: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(msg)?;
        let sec = r.i32("header.stamp.sec")?;
        let nanosec = r.u32("header.stamp.nanosec")?;
        let frame_id = r.string("header.frame_id")?;
        let mut position = [0.0; 3];
        for v in &mut position {
            *v = r.f64("pose.pose.position")?;
        }
        let mut orientation = [0.0; 4];
        for v in &mut orientation {
            *v = r.f64("pose.pose.orientation")?;
        }
        let mut covariance = [0.0; 36];
        for v in &mut covariance {
            *v = r.f64("pose.covariance")?;
        }
        Ok(Self {
            stamp_ns: sec as i64 * 1_000_000_000 + nanosec as i64,
            frame_id,
            position,
            orientation,
            covariance,
        })
    }

    /// Yaw (rad) of the orientation.
    pub fn yaw_rad(&self) -> f64 {
        let [x, y, z, w] = self.orientation;
        (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
    }

    /// The depositor's pose message for robot `robot_id`.
    pub fn to_pose_msg(&self, robot_id: u32) -> PoseMsg {
        let c = &self.covariance;
        let at = |r: usize, col: usize| c[r * 6 + col];
        let idx = [0, 1, 5];
        let mut cov = [0.0; 9];
        for (i, &r) in idx.iter().enumerate() {
            for (j, &col) in idx.iter().enumerate() {
                cov[i * 3 + j] = at(r, col);
            }
        }
        PoseMsg {
            stamp_ns: self.stamp_ns.max(0) as u64,
            robot_id,
            x_m: self.position[0],
            y_m: self.position[1],
            theta_rad: self.yaw_rad(),
            cov,
            ..PoseMsg::default()
        }
    }
}

/// Why a pose was refused before the depositor saw it.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum PoseRefusal {
    #[error(transparent)]
    Depositor(#[from] PoseRejection),
    #[error("pose refused (not_positive_definite): Σxy = [[{xx}, {xy}], [{xy}, {yy}]] has det {det} ≤ 0 (γ = τ/det Σ needs det > 0)")]
    NotPositiveDefinite { xx: f64, xy: f64, yy: f64, det: f64 },
}

impl PoseRefusal {
    /// A stable snake_case name, for counters.
    pub fn name(&self) -> &'static str {
        match self {
            PoseRefusal::Depositor(r) => r.reason().name(),
            PoseRefusal::NotPositiveDefinite { .. } => "not_positive_definite",
        }
    }
}

/// The depositor's checks (finite, symmetric, PSD), then Σxy positive definite: seed 000's
/// γ = τ/det Σxy is undefined for a singular position covariance.
pub fn check_pose(p: &PoseMsg) -> Result<(), PoseRefusal> {
    validate_pose(p)?;
    let [xx, xy, yy] = p.cov_xy();
    let det = xx * yy - xy * xy;
    if xx > 0.0 && det > 0.0 {
        Ok(())
    } else {
        Err(PoseRefusal::NotPositiveDefinite { xx, xy, yy, det })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cdr::CdrWriter;

    pub(crate) fn encode(p: &PoseWithCovarianceStamped) -> Vec<u8> {
        let mut w = CdrWriter::default();
        w.i32((p.stamp_ns / 1_000_000_000) as i32);
        w.u32((p.stamp_ns % 1_000_000_000) as u32);
        w.string(&p.frame_id);
        for v in p.position.iter().chain(&p.orientation).chain(&p.covariance) {
            w.f64(*v);
        }
        w.finish()
    }

    fn sample() -> PoseWithCovarianceStamped {
        let mut covariance = [0.0; 36];
        covariance[0] = 0.04;
        covariance[1] = 0.01;
        covariance[6] = 0.01;
        covariance[7] = 0.09;
        covariance[35] = 0.02;
        let half = 0.3f64;
        PoseWithCovarianceStamped {
            stamp_ns: 12_000_000_345,
            frame_id: "map".into(),
            position: [1.0, -2.0, 0.0],
            orientation: [0.0, 0.0, half.sin(), half.cos()],
            covariance,
        }
    }

    #[test]
    fn decodes_and_maps_to_the_depositor_pose() {
        let p = sample();
        let b = encode(&p);
        let d = PoseWithCovarianceStamped::from_cdr(&b).unwrap();
        assert_eq!(d, p);
        let m = d.to_pose_msg(4);
        assert_eq!((m.robot_id, m.x_m, m.y_m), (4, 1.0, -2.0));
        assert!((m.theta_rad - 0.6).abs() < 1e-12);
        assert_eq!(m.cov, [0.04, 0.01, 0.0, 0.01, 0.09, 0.0, 0.0, 0.0, 0.02]);
        assert_eq!(m.stamp_ns, 12_000_000_345);
        check_pose(&m).unwrap();
        for cut in [0, 3, 10, 20, b.len() - 1] {
            assert!(PoseWithCovarianceStamped::from_cdr(&b[..cut]).is_err());
        }
    }

    #[test]
    fn nan_and_singular_covariances_are_refused() {
        let mut p = sample();
        p.covariance[7] = f64::NAN;
        let e = check_pose(&p.to_pose_msg(1)).unwrap_err();
        assert_eq!(e.name(), "non_finite");
        let mut p = sample();
        p.covariance[7] = 0.0025; // xx·yy = xy²: singular
        let e = check_pose(&p.to_pose_msg(1)).unwrap_err();
        assert_eq!(e.name(), "not_positive_definite");
        let mut p = sample();
        p.covariance[0] = -1.0;
        assert_eq!(check_pose(&p.to_pose_msg(1)).unwrap_err().name(), "not_psd");
    }
}
