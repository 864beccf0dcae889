//! Seed 000's uncertainty-aware deposit from a pose estimate: the rule of
//! `roles::depositor` (`validate_pose` and `Depositor::deposit_for` in
//! `publishers/src/roles/depositor/mod.rs`, mode `uncertainty-aware`), restated here because
//! this crate does not depend on `publishers`. The field then computes γ = τ / det Σxy capped at
//! γmax and cuts the kernel at z_rng (`field::deposit`), as for the Rust depositor's deposit.
//!
//! The pose is refused (with the entry and its value named) when a number is not finite, the
//! covariance is not symmetric (|Σij − Σji| > 1e-6·max|Σ|) or not positive semi-definite
//! (λmin < −1e-9·max|Σ|), or a value does not fit the `f32` message.

use field::{Deposit, Kernel, KernelParams};
use field::{DepositMsg, KernelKind};

use crate::error::{bail, Failure};
use crate::types::{PheromoneEllipseParams, PheromonePoseEstimate, PheromoneStatus};

/// `roles::depositor::SYMMETRY_REL_TOL`.
const SYMMETRY_REL_TOL: f64 = 1e-6;
/// `roles::depositor::PSD_REL_TOL`.
const PSD_REL_TOL: f64 = 1e-9;

const COV_NAMES: [&str; 9] = [
    "cov_xx",
    "cov_xy",
    "cov_xtheta",
    "cov_yx",
    "cov_yy",
    "cov_ytheta",
    "cov_thetax",
    "cov_thetay",
    "cov_thetatheta",
];

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

/// Checks a pose: finite, covariance symmetric and positive semi-definite.
pub fn validate_pose(pose: &PheromonePoseEstimate) -> Result<(), Failure> {
    for (name, v) in [
        ("x_m", pose.x_m),
        ("y_m", pose.y_m),
        ("theta_rad", pose.theta_rad),
    ] {
        if !v.is_finite() {
            bail!(BAD, "pose rejected (non_finite): {name} = {v}");
        }
    }
    if let Some(i) = pose.cov.iter().position(|v| !v.is_finite()) {
        bail!(
            BAD,
            "pose rejected (non_finite): {} = {}",
            COV_NAMES[i],
            pose.cov[i]
        );
    }
    let c = &pose.cov;
    let scale = c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (row, col) in [(0, 1), (0, 2), (1, 2)] {
        let (upper, lower) = (c[row * 3 + col], c[col * 3 + row]);
        if (upper - lower).abs() > SYMMETRY_REL_TOL * scale {
            bail!(
                BAD,
                "pose rejected (not_symmetric): cov[{row}][{col}] = {upper} but cov[{col}][{row}] = {lower}"
            );
        }
    }
    let m = nalgebra::Matrix3::from_row_slice(c);
    let sym = (m + m.transpose()) * 0.5;
    let min_eigenvalue = sym.symmetric_eigenvalues().min();
    if min_eigenvalue < -PSD_REL_TOL * scale {
        bail!(
            BAD,
            "pose rejected (not_psd): covariance has eigenvalue {min_eigenvalue} < 0"
        );
    }
    Ok(())
}

fn to_f32(name: &str, value: f64) -> Result<f32, Failure> {
    let v = value as f32;
    if !v.is_finite() {
        bail!(
            BAD,
            "pose rejected (out_of_range): {name} = {value} does not fit the f32 deposit message"
        );
    }
    Ok(v)
}

/// The deposit the Rust depositor makes for `pose` in mode `uncertainty-aware` (stamp and robot
/// id are filled in when it is sent).
pub fn deposit_for(
    pose: &PheromonePoseEstimate,
    p: &PheromoneEllipseParams,
) -> Result<DepositMsg, Failure> {
    let kernel = check_params(p)?;
    validate_pose(pose)?;
    let x = to_f32("x_m", pose.x_m)?;
    let y = to_f32("y_m", pose.y_m)?;
    let sign = if p.anti_pheromone != 0 { -1.0 } else { 1.0 };
    let (xx, xy, yy) = (pose.cov[0], pose.cov[1], pose.cov[4]);
    let floor = (p.min_sigma_m as f64).powi(2);
    let xx32 = to_f32("cov_xx", xx.max(floor))?;
    let yy32 = to_f32("cov_yy", yy.max(floor))?;
    // Keep Σxy PSD after rounding to f32: |xy| ≤ √(xx·yy).
    let bound = (xx32 as f64 * yy32 as f64).max(0.0).sqrt();
    let xy32 = xy.clamp(-bound, bound) as f32;
    let params = KernelParams {
        cov_m2: [xx32, xy32, yy32],
        range_m: p.range_m,
        gamma_max: p.gamma_max,
        ..KernelParams::default()
    };
    let deposit = Deposit {
        channel: p.channel,
        x_m: x,
        y_m: y,
        kernel: Kernel::from_params(kernel, sign * p.tau, &params),
    };
    Ok(deposit.into())
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
