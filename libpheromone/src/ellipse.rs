//! Seed 000's uncertainty-aware deposit from a pose estimate, from C: the C parameters checked
//! ([`check_params`]), then the field's one pose → deposit rule (`pheromone_field::kernel::pose`:
//! validation, tolerances, the ellipse), the same the Rust depositor (`pheromone_roles::depositor`, mode
//! `uncertainty-aware`) and the ROS 2 pose path use. A refusal is `BadArgument` with the rule's
//! message, naming the entry and its value.

use pheromone_field::kernel::pose::{EllipseRule, PoseEstimate, PoseRejection};
use pheromone_field::{DepositMsg, KernelKind};

use crate::error::{bail, Failure};
use crate::types::{PheromoneEllipseParams, PheromonePoseEstimate, PheromoneStatus};

const BAD: PheromoneStatus = PheromoneStatus::BadArgument;

/// Checks the settings: the depositor's ranges for τ, γmax, z_rng and the σ floor.
pub fn check_params(p: &PheromoneEllipseParams) -> Result<KernelKind, Failure> {
    for (name, v) in [
        ("tau", p.tau),
        ("gamma_max", p.gamma_max),
        ("range_m", p.range_m),
    ] {
        if !(v.is_finite() && v > 0.0) {
            bail!(BAD, "ellipse params: {name} = {v}: must be finite and > 0");
        }
    }
    if !(p.min_sigma_m.is_finite() && p.min_sigma_m >= 0.0 && p.min_sigma_m < 1e3) {
        bail!(
            BAD,
            "ellipse params: min_sigma_m = {}: must be finite, ≥ 0 and < 1000 (0 = off)",
            p.min_sigma_m
        );
    }
    match KernelKind::from_code(p.kernel) {
        Some(k @ (KernelKind::Ellipse | KernelKind::Paper)) => Ok(k),
        _ => bail!(
            BAD,
            "ellipse params: kernel = {}: expected PHEROMONE_KERNEL_ELLIPSE (0) or PHEROMONE_KERNEL_PAPER (1)",
            p.kernel
        ),
    }
}

/// The pose as the field's rule reads it.
fn estimate(pose: &PheromonePoseEstimate) -> PoseEstimate {
    PoseEstimate {
        x_m: pose.x_m,
        y_m: pose.y_m,
        theta_rad: pose.theta_rad,
        cov: pose.cov,
    }
}

/// The refusal as this library reports it: `BadArgument` with the rule's message.
fn refused(e: PoseRejection) -> Failure {
    crate::error::fail(BAD, format_args!("{e}"))
}

/// The deposit the Rust depositor makes for `pose` in mode `uncertainty-aware` with `amount =
/// "literal"` (stamp and robot id are filled in when it is sent).
pub fn deposit_for(
    pose: &PheromonePoseEstimate,
    p: &PheromoneEllipseParams,
) -> Result<DepositMsg, Failure> {
    let rule = EllipseRule {
        channel: p.channel,
        kernel: check_params(p)?,
        tau: p.tau,
        range_m: p.range_m,
        gamma_max: p.gamma_max,
        min_sigma_m: p.min_sigma_m,
        anti_pheromone: p.anti_pheromone != 0,
        // The C struct has no key for it: eqs. 12 and 14 as printed (issue 48 part 2).
        amount: pheromone_field::kernel::pose::DepositAmount::Literal,
    };
    Ok(rule.deposit(&estimate(pose)).map_err(refused)?.into())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(x: f64, y: f64, cov: [f64; 9]) -> PheromonePoseEstimate {
        PheromonePoseEstimate {
            x_m: x,
            y_m: y,
            theta_rad: 0.3,
            cov,
        }
    }

    #[test]
    fn the_xy_block_becomes_the_ellipse_and_theta_is_ignored() {
        let cov = [0.04, 0.01, 0.02, 0.01, 0.09, 0.03, 0.02, 0.03, 0.3];
        let m = deposit_for(&pose(1.5, -2.0, cov), &PheromoneEllipseParams::default()).unwrap();
        assert_eq!(m.kernel, KernelKind::Ellipse as u32);
        assert_eq!((m.x_m, m.y_m), (1.5, -2.0));
        assert_eq!((m.cov_xx, m.cov_xy, m.cov_yy), (0.04, 0.01, 0.09));
        assert_eq!((m.amount, m.range_m, m.gamma_max), (0.2, 1.0, 100.0));
    }

    #[test]
    fn the_sigma_floor_and_anti_pheromone_apply() {
        let p = PheromoneEllipseParams {
            min_sigma_m: 0.1,
            anti_pheromone: 1,
            ..Default::default()
        };
        let m = deposit_for(
            &pose(0.0, 0.0, [1e-6, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.1]),
            &p,
        )
        .unwrap();
        assert_eq!(m.cov_xx, (0.1f32 as f64).powi(2) as f32);
        assert_eq!(m.cov_yy, 0.5);
        assert_eq!(m.amount, -0.2);
    }

    #[test]
    fn bad_poses_are_refused_naming_the_entry() {
        let p = PheromoneEllipseParams::default();
        let mut cov = [0.04, 0.0, 0.0, 0.0, 0.04, 0.0, 0.0, 0.0, 0.1];
        cov[4] = f64::NAN;
        assert_eq!(
            deposit_for(&pose(0.0, 0.0, cov), &p),
            Err(Failure(PheromoneStatus::BadArgument))
        );
        assert!(crate::error::last_message().contains("cov_yy = NaN"));
        let asym = [0.04, 0.02, 0.0, 0.0, 0.04, 0.0, 0.0, 0.0, 0.1];
        assert!(deposit_for(&pose(0.0, 0.0, asym), &p).is_err());
        assert!(crate::error::last_message().contains("not_symmetric"));
        let not_psd = [0.01, 0.05, 0.0, 0.05, 0.01, 0.0, 0.0, 0.0, 0.1];
        assert!(deposit_for(&pose(0.0, 0.0, not_psd), &p).is_err());
        assert!(crate::error::last_message().contains("not_psd"));
        let far = pose(1e300, 0.0, [0.04, 0.0, 0.0, 0.0, 0.04, 0.0, 0.0, 0.0, 0.1]);
        assert!(deposit_for(&far, &p).is_err());
        assert!(crate::error::last_message().contains("(out_of_range): x_m = "));
        let bad_tau = PheromoneEllipseParams { tau: -1.0, ..p };
        assert!(deposit_for(&pose(0.0, 0.0, [0.0; 9]), &bad_tau).is_err());
        assert!(crate::error::last_message().contains("tau = -1"));
    }
}
