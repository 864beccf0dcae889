//! Seed 000's pose → deposit rule, written once for every sender (the Rust depositor
//! `pheromone_roles::depositor`, the C ABI's `pheromone_deposit_pose`, the ROS 2 pose path): which pose
//! estimates are accepted ([`validate_pose`], with the tolerances [`SYMMETRY_REL_TOL`] and
//! [`PSD_REL_TOL`]), and the uncertainty-aware ellipse a pose deposits ([`EllipseRule`]). The
//! field then computes γ = τ / det Σxy capped at γmax and cuts the kernel at z_rng
//! (`pheromone_field::deposit`).
//!
//! A pose is refused, naming the entry and its value, when a number is not finite, the
//! covariance is not symmetric (|Σij − Σji| > 1e-6·max|Σ|) or not positive semi-definite
//! (λmin < −1e-9·max|Σ|), or a value does not fit the `f32` deposit message. Nothing non-finite
//! ever leaves this module.

use super::{Deposit, Kernel, KernelParams};
use crate::messages::KernelKind;

/// A pose estimate: the mean (m, rad) and its 3×3 covariance, row-major over x, y, θ.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PoseEstimate {
    /// Estimated x position in the world frame (m).
    pub x_m: f64,
    /// Estimated y position in the world frame (m).
    pub y_m: f64,
    /// Estimated heading (rad, counter-clockwise from +x); not used by the deposit.
    pub theta_rad: f64,
    /// Covariance of (x, y, θ), row-major 3×3 (m², m·rad, rad²); must be symmetric and
    /// positive semi-definite within [`SYMMETRY_REL_TOL`] and [`PSD_REL_TOL`].
    pub cov: [f64; 9],
}

/// Why a pose was refused. The discriminant indexes a depositor's counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum PoseRejectReason {
    /// A position, heading or covariance entry is NaN or infinite.
    NonFinite = 0,
    /// The 3×3 covariance is not symmetric.
    NotSymmetric = 1,
    /// The 3×3 covariance is not positive semi-definite.
    NotPsd = 2,
    /// A value is finite in `f64` but does not fit the `f32` deposit message.
    OutOfRange = 3,
}

/// Number of pose rejection reasons.
pub const POSE_REJECT_REASONS: usize = 4;

impl PoseRejectReason {
    /// Every reason, in discriminant order.
    pub const ALL: [PoseRejectReason; POSE_REJECT_REASONS] = [
        PoseRejectReason::NonFinite,
        PoseRejectReason::NotSymmetric,
        PoseRejectReason::NotPsd,
        PoseRejectReason::OutOfRange,
    ];

    /// Stable snake_case name, for logs and JSON.
    pub fn name(self) -> &'static str {
        match self {
            PoseRejectReason::NonFinite => "non_finite",
            PoseRejectReason::NotSymmetric => "not_symmetric",
            PoseRejectReason::NotPsd => "not_psd",
            PoseRejectReason::OutOfRange => "out_of_range",
        }
    }
}

/// A refused pose, naming the offending entry and value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PoseRejection {
    /// A number is NaN or infinite.
    #[error("pose rejected (non_finite): {name} = {value}")]
    NonFinite {
        /// The entry: `x_m`, `y_m`, `theta_rad` or `cov_<row><col>` (e.g. `cov_xtheta`).
        name: &'static str,
        /// Its value (NaN or ±∞).
        value: f64,
    },
    /// Σ is not symmetric.
    #[error("pose rejected (not_symmetric): cov[{row}][{col}] = {upper} but cov[{col}][{row}] = {lower}")]
    NotSymmetric {
        /// Row of the upper-triangle entry (0 = x, 1 = y, 2 = θ).
        row: usize,
        /// Column of the upper-triangle entry (> `row`).
        col: usize,
        /// Σ\[row\]\[col\].
        upper: f64,
        /// Σ\[col\]\[row\], which differs from `upper` by more than the tolerance.
        lower: f64,
    },
    /// Σ has a negative eigenvalue.
    #[error("pose rejected (not_psd): covariance has eigenvalue {min_eigenvalue} < 0")]
    NotPsd {
        /// The smallest eigenvalue of Σ's symmetric part, below −[`PSD_REL_TOL`]·max|Σ|.
        min_eigenvalue: f64,
    },
    /// A finite `f64` that does not fit the `f32` message.
    #[error("pose rejected (out_of_range): {name} = {value} does not fit the f32 deposit message")]
    OutOfRange {
        /// The value's name (`x_m`, `y_m`, `cov_xx`, `cov_yy`).
        name: &'static str,
        /// The value, beyond `f32`'s range.
        value: f64,
    },
}

impl PoseRejection {
    /// The reason, for counting.
    pub fn reason(&self) -> PoseRejectReason {
        match self {
            PoseRejection::NonFinite { .. } => PoseRejectReason::NonFinite,
            PoseRejection::NotSymmetric { .. } => PoseRejectReason::NotSymmetric,
            PoseRejection::NotPsd { .. } => PoseRejectReason::NotPsd,
            PoseRejection::OutOfRange { .. } => PoseRejectReason::OutOfRange,
        }
    }
}

/// Relative tolerance of the symmetry check: |Σij − Σji| ≤ tol·max|Σ|.
pub const SYMMETRY_REL_TOL: f64 = 1e-6;
/// Relative tolerance of the PSD check: λmin ≥ −tol·max|Σ|.
pub const PSD_REL_TOL: f64 = 1e-9;

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

/// Checks a pose: finite mean and covariance, covariance symmetric and positive semi-definite
/// (MODELS.md M1: anything else is bad input, rejected with a reason, never deposited).
pub fn validate_pose(pose: &PoseEstimate) -> Result<(), PoseRejection> {
    for (name, value) in [
        ("x_m", pose.x_m),
        ("y_m", pose.y_m),
        ("theta_rad", pose.theta_rad),
    ] {
        if !value.is_finite() {
            return Err(PoseRejection::NonFinite { name, value });
        }
    }
    if let Some(i) = pose.cov.iter().position(|v| !v.is_finite()) {
        return Err(PoseRejection::NonFinite {
            name: COV_NAMES[i],
            value: pose.cov[i],
        });
    }
    let c = &pose.cov;
    let scale = c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (row, col) in [(0, 1), (0, 2), (1, 2)] {
        let (upper, lower) = (c[row * 3 + col], c[col * 3 + row]);
        if (upper - lower).abs() > SYMMETRY_REL_TOL * scale {
            return Err(PoseRejection::NotSymmetric {
                row,
                col,
                upper,
                lower,
            });
        }
    }
    let m = nalgebra::Matrix3::from_row_slice(c);
    let sym = (m + m.transpose()) * 0.5;
    let min_eigenvalue = sym.symmetric_eigenvalues().min();
    if min_eigenvalue < -PSD_REL_TOL * scale {
        return Err(PoseRejection::NotPsd { min_eigenvalue });
    }
    Ok(())
}

/// `value` as the `f32` of a deposit message, or [`PoseRejection::OutOfRange`] naming it.
pub fn fit_f32(name: &'static str, value: f64) -> Result<f32, PoseRejection> {
    let v = value as f32;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(PoseRejection::OutOfRange { name, value })
    }
}

/// The position block Σxy of `cov` as `[xx, xy, yy]` in `f32`, each variance floored at
/// `min_sigma_m²`, and |xy| ≤ √(xx·yy) so that it stays positive semi-definite after rounding.
pub fn ellipse_cov_m2(cov: &[f64; 9], min_sigma_m: f32) -> Result<[f32; 3], PoseRejection> {
    let (xx, xy, yy) = (cov[0], cov[1], cov[4]);
    let floor = (min_sigma_m as f64).powi(2);
    let xx32 = fit_f32("cov_xx", xx.max(floor))?;
    let yy32 = fit_f32("cov_yy", yy.max(floor))?;
    let bound = (xx32 as f64 * yy32 as f64).max(0.0).sqrt();
    Ok([xx32, xy.clamp(-bound, bound) as f32, yy32])
}

/// How much an uncertainty-aware deposit leaves (issue 48 part 2; docs/localization.md).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DepositAmount {
    /// Eqs. 12 and 14 as printed: the kernel's peak is γ = τ/det Σxy capped at γmax. While γ
    /// is capped a growing ellipse spreads the same peak wider, so the trail *brightens* as
    /// the robot gets lost.
    Literal,
    /// Eq. 11's intent, "amount of pheromones ∝ γ ∝ 1/uncertainty": γ (capped at γmax, "the
    /// maximum number of pheromones which could be deposited") is the deposit's total, as a
    /// count per reference ellipse of σ = `sigma_ref_m` on both axes. The peak is
    /// γ·min(1, A_ref/A), A the kernel's area (√det Σxy for `ellipse`, det Σxy for `paper`,
    /// A_ref the same at σ_ref), so it falls as the ellipse grows, capped or not, and the
    /// deposit's integral stays γ·(the reference kernel's integral).
    Intent {
        /// σ of the reference ellipse (m, > 0); at or below it nothing changes.
        sigma_ref_m: f32,
    },
}

impl Default for DepositAmount {
    /// The intent with σ_ref = 0.1 m.
    fn default() -> Self {
        DepositAmount::Intent { sigma_ref_m: 0.1 }
    }
}

impl DepositAmount {
    /// σ_ref of the intent forms, `None` for the literal one.
    pub fn sigma_ref_m(self) -> Option<f32> {
        match self {
            DepositAmount::Literal => None,
            DepositAmount::Intent { sigma_ref_m } => Some(sigma_ref_m),
        }
    }

    /// The τ to send so that the field's min(γmax, τ'/det Σxy) is this form's peak, for the
    /// ellipse `cov_m2` (as sent) and `kind`.
    pub fn tau_to_send(self, kind: KernelKind, tau: f32, cov_m2: [f32; 3], gamma_max: f32) -> f32 {
        let Some(sigma_ref) = self.sigma_ref_m() else {
            return tau;
        };
        let [xx, xy, yy] = cov_m2.map(f64::from);
        let det = xx * yy - xy * xy;
        if det.is_nan() || det <= 0.0 || sigma_ref.is_nan() || sigma_ref <= 0.0 {
            return tau;
        }
        let r2 = f64::from(sigma_ref).powi(2);
        let shrink = match kind {
            KernelKind::Paper => (r2 * r2 / det).min(1.0),
            _ => (r2 / det.sqrt()).min(1.0),
        };
        let literal = (f64::from(tau) / det).clamp(-f64::from(gamma_max), f64::from(gamma_max));
        let peak = literal * shrink;
        if peak.abs() >= f64::from(gamma_max) {
            tau
        } else {
            (peak * det) as f32
        }
    }
}

/// Seed 000's uncertainty-aware deposit (MODELS.md M1): amount τ (negative with
/// `anti_pheromone`), the pose's error ellipse Σxy (floored at `min_sigma_m`), γ = τ/det Σxy
/// capped at `gamma_max` by the field, cut at `range_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EllipseRule {
    /// Index of the channel the deposits go to.
    pub channel: u32,
    /// [`KernelKind::Ellipse`] (the project's default) or [`KernelKind::Paper`] (eq. 14 as
    /// printed).
    pub kernel: KernelKind,
    /// τ, the amount of each deposit; its sign is flipped with `anti_pheromone`.
    pub tau: f32,
    /// Cut-off radius z_rng of the kernel (m, > 0).
    pub range_m: f32,
    /// γmax, the cap the field applies to γ = τ/det Σxy (> 0).
    pub gamma_max: f32,
    /// σ floor of each position variance (m; 0 = off).
    pub min_sigma_m: f32,
    /// Deposit −τ (anti-pheromone, on a signed channel) instead of τ.
    pub anti_pheromone: bool,
    /// What γ measures: the peak (eq. 14 as printed) or the deposit's total (eq. 11's intent).
    pub amount: DepositAmount,
}

impl EllipseRule {
    /// The deposit `pose` makes, or why it is refused.
    pub fn deposit(&self, pose: &PoseEstimate) -> Result<Deposit, PoseRejection> {
        validate_pose(pose)?;
        let x_m = fit_f32("x_m", pose.x_m)?;
        let y_m = fit_f32("y_m", pose.y_m)?;
        let cov_m2 = ellipse_cov_m2(&pose.cov, self.min_sigma_m)?;
        let sign = if self.anti_pheromone { -1.0 } else { 1.0 };
        let tau = self
            .amount
            .tau_to_send(self.kernel, self.tau, cov_m2, self.gamma_max);
        let params = KernelParams {
            cov_m2,
            range_m: self.range_m,
            gamma_max: self.gamma_max,
            ..KernelParams::default()
        };
        Ok(Deposit {
            channel: self.channel,
            x_m,
            y_m,
            kernel: Kernel::from_params(self.kernel, sign * tau, &params),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(x_m: f64, cov: [f64; 9]) -> PoseEstimate {
        PoseEstimate {
            x_m,
            y_m: -2.0,
            theta_rad: 0.3,
            cov,
        }
    }

    const RULE: EllipseRule = EllipseRule {
        channel: 0,
        kernel: KernelKind::Ellipse,
        tau: 0.2,
        range_m: 1.0,
        gamma_max: 100.0,
        min_sigma_m: 0.0,
        anti_pheromone: false,
        amount: DepositAmount::Literal,
    };

    /// The peak the field makes of a deposit (γ = τ/det Σxy capped), as it computes it.
    fn peak(d: &Deposit) -> f32 {
        let Kernel::Ellipse {
            tau,
            cov_m2,
            gamma_max,
            ..
        } = d.kernel
        else {
            panic!("not the ellipse kernel");
        };
        let e = crate::deposit::ErrorEllipse::from_cov(cov_m2[0], cov_m2[1], cov_m2[2]);
        crate::deposit::gamma(tau, e.det(), gamma_max)
    }

    #[test]
    fn the_intent_falls_as_the_ellipse_grows_while_the_literal_peak_stays_capped() {
        let intent = EllipseRule {
            amount: DepositAmount::Intent { sigma_ref_m: 0.1 },
            min_sigma_m: 0.1,
            ..RULE
        };
        let literal = EllipseRule {
            min_sigma_m: 0.1,
            ..RULE
        };
        let iso = |s: f64| [s * s, 0.0, 0.0, 0.0, s * s, 0.0, 0.0, 0.0, 0.01];
        let mut last = f32::INFINITY;
        for sigma in [0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.5, 1.0, 2.0] {
            let (i, l) = (
                peak(&intent.deposit(&pose(0.0, iso(sigma))).unwrap()),
                peak(&literal.deposit(&pose(0.0, iso(sigma))).unwrap()),
            );
            let s = sigma.max(0.1);
            // Literal: min(100, 0.2/σ⁴); intent: that times (0.1/σ)², so its total is fixed.
            let want_l = (0.2 / s.powi(4)).min(100.0);
            assert!(
                (f64::from(l) - want_l).abs() <= 1e-3 * want_l,
                "σ {sigma}: {l}"
            );
            let want_i = want_l * (0.01 / (s * s)).min(1.0);
            assert!(
                (f64::from(i) - want_i).abs() <= 1e-3 * want_i,
                "σ {sigma}: {i}"
            );
            assert!(i <= l && i <= last, "σ {sigma}: {i} after {last}");
            if sigma > 0.1 {
                assert!(
                    i < last,
                    "σ {sigma}: the intent must fall, {i} after {last}"
                );
            }
            last = i;
        }
        // Capped regime (0.1 < σ ≤ 0.21 m: 0.2/σ⁴ ≥ 100): the literal peak stays at 100.
        let l = peak(&literal.deposit(&pose(0.0, iso(0.2))).unwrap());
        assert_eq!(l, 100.0);
    }

    #[test]
    fn the_xy_block_becomes_the_ellipse_and_theta_is_ignored() {
        let cov = [0.04, 0.01, 0.02, 0.01, 0.09, 0.03, 0.02, 0.03, 0.3];
        let d = RULE.deposit(&pose(1.5, cov)).unwrap();
        assert_eq!((d.x_m, d.y_m), (1.5, -2.0));
        let expected = Kernel::Ellipse {
            tau: 0.2,
            cov_m2: [0.04, 0.01, 0.09],
            range_m: 1.0,
            gamma_max: 100.0,
        };
        assert_eq!(d.kernel, expected);
    }

    #[test]
    fn the_floor_keeps_the_ellipse_psd_and_anti_pheromone_is_negative() {
        let rule = EllipseRule {
            min_sigma_m: 0.1,
            anti_pheromone: true,
            kernel: KernelKind::Paper,
            ..RULE
        };
        let cov = [1e-6, 0.4, 0.0, 0.4, 0.5, 0.0, 0.0, 0.0, 0.1];
        // Not PSD before the floor: refused as such, never floored into shape.
        assert_eq!(
            rule.deposit(&pose(0.0, cov)).unwrap_err().reason(),
            PoseRejectReason::NotPsd
        );
        let cov = [1e-6, 1e-4, 0.0, 1e-4, 0.5, 0.0, 0.0, 0.0, 0.1];
        let Kernel::Paper { tau, cov_m2, .. } = rule.deposit(&pose(0.0, cov)).unwrap().kernel
        else {
            panic!("not the paper kernel");
        };
        assert_eq!(tau, -0.2);
        assert_eq!(cov_m2[0], (0.1f32 as f64).powi(2) as f32);
        assert!(cov_m2[1] * cov_m2[1] <= cov_m2[0] * cov_m2[2]);
    }

    #[test]
    fn bad_poses_are_refused_naming_the_entry_and_value() {
        let mut cov = [0.04, 0.0, 0.0, 0.0, 0.04, 0.0, 0.0, 0.0, 0.1];
        cov[4] = f64::NAN;
        let e = RULE.deposit(&pose(0.0, cov)).unwrap_err().to_string();
        assert!(e.contains("(non_finite): cov_yy = NaN"), "{e}");
        let asym = [0.04, 0.02, 0.0, 0.0, 0.04, 0.0, 0.0, 0.0, 0.1];
        let e = RULE.deposit(&pose(0.0, asym)).unwrap_err();
        assert_eq!(e.reason(), PoseRejectReason::NotSymmetric);
        let ok = [0.04, 0.0, 0.0, 0.0, 0.04, 0.0, 0.0, 0.0, 0.1];
        let e = RULE.deposit(&pose(1e300, ok)).unwrap_err().to_string();
        assert!(e.contains("(out_of_range): x_m = "), "{e}");
    }
}
