//! The depositor role: turns a localizer's pose estimate (`PoseMsg`, mean + 3×3 covariance) into
//! deposit requests for the field (`pheromone_field::DepositMsg`). Pure library code; the iceoryx2 loop
//! lives elsewhere.
//!
//! Three modes (MODELS.md M1, M2/M4):
//! - [`DepositMode::UncertaintyAware`] — seed 000: the error-ellipse kernel (`ellipse`, or the
//!   `paper` form of eq. 14 as printed) with amount τ. The field computes γ = τ / det Σxy capped
//!   at γmax (eq. 12) from the position covariance Σxy this module passes on, and cuts the kernel
//!   at the sensor range z_rng (eq. 14). A well-localized robot deposits much in a small area, a
//!   lost one little over a wide area.
//! - [`DepositMode::Saturating`] — seeds 001/004 eq. 3: Δ = (1 − ξ)·ρt·exp(−d²/λ²) with a small
//!   λ. The strength ρt ∈ [0, ρmax] grows as the uncertainty shrinks (seed 001 eq. 4); this module
//!   uses ρt = ρmax·exp(−trace(Σxy)/σ0²) (see [`saturating_rho`]).
//! - [`DepositMode::Constant`] — the traditional scheme seed 000 argues against: the same
//!   ellipse deposit whatever the localization (a fixed, small, isotropic covariance).
//!
//! The leader deposits at intervals, not every step (seed 000, "intermittent time intervals"):
//! the first accepted pose deposits, later ones only once the robot has moved `interval_m` from
//! the last deposit or `interval_s` has elapsed since it.
//!
//! Bad poses (NaN/inf, a covariance that is not symmetric or not positive semi-definite, values
//! that do not fit the `f32` deposit message) are rejected with a [`PoseRejection`] and counted
//! by reason; no `DepositMsg` carrying a non-finite value is ever produced.

use pheromone_field::kernel::defaults;
use pheromone_field::kernel::pose::DepositAmount;
use pheromone_field::{Deposit, DepositMsg, EllipseRule, Kernel, KernelKind};
use serde::{Deserialize, Serialize};

use pheromone_messages::PoseMsg;

/// Which M1 kernel an ellipse deposit uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EllipseKernel {
    /// Project default: γ·exp(−½ dᵀΣxy⁻¹d) (MODELS.md M1).
    #[default]
    Ellipse,
    /// Seed 000 eq. 14 as printed: γ·exp(−(u²/λ1² + v²/λ2²)).
    Paper,
}

impl EllipseKernel {
    pub fn kind(self) -> KernelKind {
        match self {
            EllipseKernel::Ellipse => KernelKind::Ellipse,
            EllipseKernel::Paper => KernelKind::Paper,
        }
    }

    /// This kernel with amount τ, covariance Σxy (m²), cut-off and cap.
    pub fn with(self, tau: f32, cov_m2: [f32; 3], range_m: f32, gamma_max: f32) -> Kernel {
        match self {
            EllipseKernel::Ellipse => Kernel::Ellipse {
                tau,
                cov_m2,
                range_m,
                gamma_max,
            },
            EllipseKernel::Paper => Kernel::Paper {
                tau,
                cov_m2,
                range_m,
                gamma_max,
            },
        }
    }
}

/// How a pose becomes a deposit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DepositMode {
    /// Seed 000 eqs. 12–14: amount τ, γ = τ/det Σxy ≤ γmax, shape = the pose's error ellipse.
    #[default]
    UncertaintyAware,
    /// Seeds 001/004 eq. 3: saturating kernel of strength ρt(Σxy) and small width λ.
    Saturating,
    /// `--constant`: the ellipse kernel with a fixed covariance, independent of localization.
    Constant,
}

/// Depositor settings. Unknown keys are errors; every key has a default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DepositorConfig {
    pub mode: DepositMode,
    /// Kernel of the `uncertainty-aware` and `constant` modes.
    pub kernel: EllipseKernel,
    /// Field channel the deposits go to.
    pub channel: u32,
    /// Deposit anti-pheromone (a negative amount; the channel must be signed).
    pub anti_pheromone: bool,
    /// τ of seed 000 eq. 12 (pheromone·m⁴): γ = τ / det Σxy. Paper: 0.2.
    pub tau: f32,
    /// γmax, the cap on γ (seed 000; paper: 100).
    pub gamma_max: f32,
    /// Sensor range z_rng (m): no cell farther than this from the pose receives pheromone
    /// (seed 000 eq. 14, seed 001 eq. 3).
    pub range_m: f32,
    /// Deposit again once the pose has moved this far from the last deposit (m); 0 = off.
    pub interval_m: f64,
    /// Deposit again once this much time has elapsed since the last deposit (s); 0 = off.
    /// With both intervals off every pose deposits; with both on, either one triggers.
    pub interval_s: f64,
    /// `constant` mode: the fixed standard deviation (m) of the isotropic covariance used in
    /// place of the pose's Σxy (covariance = σ²·I).
    pub constant_sigma_m: f32,
    /// `saturating` mode: ρmax ∈ (0, 1], the strength of a perfectly localized deposit.
    pub rho_max: f32,
    /// `saturating` mode: σ0 (m) in ρt = ρmax·exp(−trace(Σxy)/σ0²).
    pub rho_sigma0_m: f32,
    /// `saturating` mode: kernel width λ (m) of seed 001 eq. 3 (small: mostly the robot's own
    /// cell and its neighbours, eq. 5).
    pub lambda_m: f32,
    /// `uncertainty-aware` mode: the variances of Σxy are raised to at least this σ² (m), so a
    /// trail is never narrower than the robot that lays it (a well-localized EKF can report
    /// σ of a few millimetres). 0 = off. While γ is capped at γmax this changes only the shape.
    pub min_sigma_m: f32,
    /// `uncertainty-aware` mode: γ is the kernel's peak (`literal`, eqs. 12 and 14 as printed)
    /// or the deposit's total (`intent`, eq. 11: the peak falls as the ellipse grows, also
    /// where γ is capped). See docs/localization.md.
    pub amount: AmountForm,
    /// `intent`: σ of the reference ellipse (m, > 0) whose peak is γ.
    pub amount_sigma_m: f32,
}

/// `amount` of a depositor (issue 48 part 2).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AmountForm {
    /// γ is the deposit's total: the peak falls as the uncertainty grows (eq. 11's intent).
    #[default]
    Intent,
    /// γ is the kernel's peak (eqs. 12 and 14 as printed).
    Literal,
}

impl Default for DepositorConfig {
    fn default() -> Self {
        Self {
            mode: DepositMode::UncertaintyAware,
            kernel: EllipseKernel::Ellipse,
            channel: 0,
            anti_pheromone: false,
            tau: defaults::TAU,
            gamma_max: defaults::GAMMA_MAX,
            range_m: defaults::RANGE_M,
            interval_m: 0.25,
            interval_s: 0.0,
            constant_sigma_m: 0.1,
            rho_max: 1.0,
            rho_sigma0_m: 0.5,
            lambda_m: 0.05,
            min_sigma_m: 0.0,
            amount: AmountForm::Intent,
            amount_sigma_m: 0.1,
        }
    }
}

/// A depositor setting that is out of range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("depositor setting {name} = {value}: {reason}")]
pub struct DepositorConfigError {
    pub name: &'static str,
    pub value: String,
    pub reason: &'static str,
}

impl DepositorConfig {
    /// Checks every value; the error names the setting and the value.
    pub fn validate(&self) -> Result<(), DepositorConfigError> {
        let bad = |name, value: &dyn std::fmt::Display, reason| DepositorConfigError {
            name,
            value: value.to_string(),
            reason,
        };
        let positive32 = [
            ("tau", self.tau),
            ("gamma_max", self.gamma_max),
            ("range_m", self.range_m),
            ("constant_sigma_m", self.constant_sigma_m),
            ("rho_sigma0_m", self.rho_sigma0_m),
            ("lambda_m", self.lambda_m),
            ("amount_sigma_m", self.amount_sigma_m),
        ];
        for (name, v) in positive32 {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(name, &v, "must be finite and > 0"));
            }
        }
        if !(self.rho_max.is_finite() && self.rho_max > 0.0 && self.rho_max <= 1.0) {
            return Err(bad("rho_max", &self.rho_max, "must be within (0, 1]"));
        }
        if !(self.min_sigma_m.is_finite() && self.min_sigma_m >= 0.0 && self.min_sigma_m < 1e3) {
            return Err(bad(
                "min_sigma_m",
                &self.min_sigma_m,
                "must be finite, ≥ 0 and < 1000 (0 = off)",
            ));
        }
        for (name, v) in [
            ("interval_m", self.interval_m),
            ("interval_s", self.interval_s),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(name, &v, "must be finite and ≥ 0 (0 = off)"));
            }
        }
        let sigma2 = self.constant_sigma_m * self.constant_sigma_m;
        if !(sigma2.is_finite() && sigma2 > 0.0) {
            return Err(bad(
                "constant_sigma_m",
                &self.constant_sigma_m,
                "its square must be a finite f32 > 0",
            ));
        }
        Ok(())
    }
}

pub use pheromone_field::kernel::pose::{
    fit_f32, PoseRejectReason, PoseRejection, POSE_REJECT_REASONS, PSD_REL_TOL, SYMMETRY_REL_TOL,
};

/// Checks a pose by the field's one rule (`pheromone_field::kernel::pose::validate_pose`): finite mean
/// and covariance, covariance symmetric and positive semi-definite (MODELS.md M1: anything else
/// is bad input, rejected with a reason, never deposited).
pub fn validate_pose(pose: &PoseMsg) -> Result<(), PoseRejection> {
    pheromone_field::kernel::pose::validate_pose(&pose.estimate())
}

/// ρt = ρmax·exp(−trace(Σxy)/σ0²) — the project's choice for the strength of seed 001 eq. 3 /
/// seed 004 eq. 4: 1 at perfect localization (times ρmax), falling smoothly as the summed
/// position variance grows past σ0², never negative and never above ρmax.
pub fn saturating_rho(rho_max: f32, sigma0_m: f32, cov_xx_m2: f64, cov_yy_m2: f64) -> f32 {
    let trace = (cov_xx_m2 + cov_yy_m2).max(0.0);
    let s02 = sigma0_m as f64 * sigma0_m as f64;
    (rho_max as f64 * (-trace / s02).exp()) as f32
}

/// Cumulative counters of a depositor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DepositorCounters {
    /// Poses offered (accepted or not).
    pub poses: u64,
    /// Deposit messages produced.
    pub deposits: u64,
    /// Valid poses that produced no deposit because no interval had elapsed.
    pub skipped_interval: u64,
    /// Rejected poses, indexed by `PoseRejectReason as usize`.
    pub rejected: [u64; POSE_REJECT_REASONS],
}

impl DepositorCounters {
    pub fn rejected_total(&self) -> u64 {
        self.rejected.iter().sum()
    }

    pub fn rejected_for(&self, reason: PoseRejectReason) -> u64 {
        self.rejected[reason as usize]
    }
}

/// Where and when the last deposit was made.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LastDeposit {
    x_m: f64,
    y_m: f64,
    stamp_ns: u64,
}

/// Turns poses into deposits (see the module documentation).
#[derive(Debug, Clone)]
pub struct Depositor {
    config: DepositorConfig,
    last: Option<LastDeposit>,
    counters: DepositorCounters,
}

impl Depositor {
    pub fn new(config: DepositorConfig) -> Result<Self, DepositorConfigError> {
        config.validate()?;
        Ok(Self {
            config,
            last: None,
            counters: DepositorCounters::default(),
        })
    }

    pub fn config(&self) -> &DepositorConfig {
        &self.config
    }

    pub fn counters(&self) -> &DepositorCounters {
        &self.counters
    }

    /// Forgets the last deposit: the next valid pose deposits.
    pub fn reset(&mut self) {
        self.last = None;
    }

    /// Processes one pose: validates it (counting a rejection by reason), applies the interval
    /// rule and returns the deposit to send, if any. The message's `stamp_ns` and `robot_id` are
    /// the pose's.
    pub fn process(&mut self, pose: &PoseMsg) -> Result<Option<DepositMsg>, PoseRejection> {
        self.counters.poses += 1;
        let msg = match self.deposit_for(pose) {
            Ok(m) => m,
            Err(e) => {
                self.counters.rejected[e.reason() as usize] += 1;
                return Err(e);
            }
        };
        if !self.due(pose) {
            self.counters.skipped_interval += 1;
            return Ok(None);
        }
        self.last = Some(LastDeposit {
            x_m: pose.x_m,
            y_m: pose.y_m,
            stamp_ns: pose.stamp_ns,
        });
        self.counters.deposits += 1;
        Ok(Some(msg))
    }

    /// Whether the interval rule lets `pose` deposit (the first pose always does). A stamp
    /// earlier than the last deposit's counts as no time elapsed.
    fn due(&self, pose: &PoseMsg) -> bool {
        let Some(last) = self.last else {
            return true;
        };
        let (im, is) = (self.config.interval_m, self.config.interval_s);
        if im == 0.0 && is == 0.0 {
            return true;
        }
        let moved_m = (pose.x_m - last.x_m).hypot(pose.y_m - last.y_m);
        let elapsed_s = pose.stamp_ns.saturating_sub(last.stamp_ns) as f64 * 1e-9;
        (im > 0.0 && moved_m >= im) || (is > 0.0 && elapsed_s >= is)
    }

    /// The deposit this pose would make, ignoring the interval rule (pure: no counters, no
    /// state). Every field of the result is finite.
    pub fn deposit_for(&self, pose: &PoseMsg) -> Result<DepositMsg, PoseRejection> {
        let c = &self.config;
        let deposit = match c.mode {
            DepositMode::UncertaintyAware => self.ellipse_rule().deposit(&pose.estimate())?,
            DepositMode::Constant | DepositMode::Saturating => {
                validate_pose(pose)?;
                let sign = if c.anti_pheromone { -1.0 } else { 1.0 };
                let kernel = if c.mode == DepositMode::Constant {
                    let s2 = c.constant_sigma_m * c.constant_sigma_m;
                    c.kernel
                        .with(sign * c.tau, [s2, 0.0, s2], c.range_m, c.gamma_max)
                } else {
                    let [xx, _, yy] = pose.cov_xy();
                    Kernel::Saturating {
                        rho: sign * saturating_rho(c.rho_max, c.rho_sigma0_m, xx, yy),
                        sigma_m: c.lambda_m,
                        range_m: c.range_m,
                    }
                };
                Deposit {
                    channel: c.channel,
                    x_m: fit_f32("x_m", pose.x_m)?,
                    y_m: fit_f32("y_m", pose.y_m)?,
                    kernel,
                }
            }
        };
        let msg = deposit.to_msg(pose.robot_id, pose.stamp_ns);
        debug_assert!(msg_is_finite(&msg));
        Ok(msg)
    }

    /// Seed 000's uncertainty-aware rule with this depositor's settings.
    pub fn ellipse_rule(&self) -> EllipseRule {
        let c = &self.config;
        EllipseRule {
            channel: c.channel,
            kernel: c.kernel.kind(),
            tau: c.tau,
            range_m: c.range_m,
            gamma_max: c.gamma_max,
            min_sigma_m: c.min_sigma_m,
            anti_pheromone: c.anti_pheromone,
            amount: match c.amount {
                AmountForm::Intent => DepositAmount::Intent {
                    sigma_ref_m: c.amount_sigma_m,
                },
                AmountForm::Literal => DepositAmount::Literal,
            },
        }
    }
}

/// Every `f32` field of a deposit message is finite.
pub fn msg_is_finite(m: &DepositMsg) -> bool {
    [
        m.x_m,
        m.y_m,
        m.amount,
        m.cov_xx,
        m.cov_xy,
        m.cov_yy,
        m.range_m,
        m.gamma_max,
        m.sigma_m,
        m.plateau_m,
        m.slope_m,
    ]
    .iter()
    .all(|v| v.is_finite())
}

#[cfg(test)]
mod tests;
