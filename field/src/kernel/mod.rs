//! A deposit as its sender thinks of it: where, on which channel, and a kernel with its own named
//! parameters. [`Deposit`] becomes the wire's flat [`DepositMsg`] with `into()`; the field reads
//! a message back with [`Deposit::from_msg`]. A pose estimate becomes a deposit by the one rule of
//! [`pose`] (validation, tolerances, seed 000's uncertainty-aware ellipse).
//!
//! ```
//! use pheromone_field::{Deposit, DepositMsg, Kernel, KernelKind};
//!
//! // Seed 000's ellipse on channel 0 at (2 m, 3 m): amount τ = 0.2, the pose covariance
//! // [xx, xy, yy] (m²), cut off at 1 m, γ capped at 100.
//! let deposit = Deposit {
//!     channel: 0,
//!     x_m: 2.0,
//!     y_m: 3.0,
//!     kernel: Kernel::Ellipse { tau: 0.2, cov_m2: [0.01, 0.0, 0.01], range_m: 1.0, gamma_max: 100.0 },
//! };
//! let msg: DepositMsg = deposit.into();
//! assert_eq!(msg.kernel, KernelKind::Ellipse as u32);
//! assert_eq!(Deposit::from_msg(&msg), Some(deposit));
//! ```

pub mod defaults;
pub mod pose;

pub use pose::{DepositAmount, EllipseRule, PoseEstimate, PoseRejectReason, PoseRejection};

use crate::messages::{DepositMsg, KernelKind};

/// A deposit kernel and the parameters it uses; a negative amount is anti-pheromone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Kernel {
    /// Seed 000, the project's default: γ·exp(−½ dᵀΣ⁻¹d) with γ = min(τ/det Σ, γmax), cut at
    /// `range_m`.
    Ellipse {
        /// τ, the deposited amount (negative = anti-pheromone); γ = τ / det Σ, capped at ±γmax.
        tau: f32,
        /// Position covariance Σxy as `[xx, xy, yy]` (m²).
        cov_m2: [f32; 3],
        /// Cut-off radius z_rng (m, > 0): cells farther from the centre get nothing.
        range_m: f32,
        /// γmax, the cap on the peak value γ (> 0).
        gamma_max: f32,
    },
    /// Seed 000 eq. 14 as printed: γ·exp(−(u²/λ1² + v²/λ2²)), cut at `range_m`.
    Paper {
        /// τ, the deposited amount (negative = anti-pheromone); γ = τ / det Σ, capped at ±γmax.
        tau: f32,
        /// Position covariance Σxy as `[xx, xy, yy]` (m²); λ1, λ2 are its eigenvalues.
        cov_m2: [f32; 3],
        /// Cut-off radius z_rng (m, > 0).
        range_m: f32,
        /// γmax, the cap on the peak value γ (> 0).
        gamma_max: f32,
    },
    /// Seeds 001/004 eq. 3: ρt·exp(−d²/λ²) with λ = `sigma_m`, cut at `range_m`; the cell
    /// saturates at ±1.
    Saturating {
        /// ρt, the signed strength, in [−1, 1].
        rho: f32,
        /// λ, the kernel's width (m, > 0).
        sigma_m: f32,
        /// Cut-off radius (m, > 0).
        range_m: f32,
    },
    /// Seed 002 eq. 1: Q·μ(d), full inside `plateau_m`, falling to zero over `slope_m`.
    ZShape {
        /// Q, the value added on the plateau (negative = anti-pheromone).
        amount: f32,
        /// c, radius of the full-value plateau (m, ≥ 0).
        plateau_m: f32,
        /// σ, width of the linear fall-off beyond the plateau (m, ≥ 0).
        slope_m: f32,
    },
}

/// Every kernel's shape parameters at once, as a command line or a scenario file gives them
/// (`pheromone deposit`, scripted deposits); [`Kernel::from_params`] keeps the ones its kind
/// uses.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct KernelParams {
    /// Position covariance Σxy as `[xx, xy, yy]` (m²), for ellipse and paper.
    pub cov_m2: [f32; 3],
    /// Cut-off radius z_rng (m), for ellipse, paper and saturating.
    pub range_m: f32,
    /// γmax, for ellipse and paper.
    pub gamma_max: f32,
    /// λ (m), for saturating.
    pub sigma_m: f32,
    /// c (m), for z-shape.
    pub plateau_m: f32,
    /// σ (m), for z-shape.
    pub slope_m: f32,
}

impl Kernel {
    /// The kernel of `kind` with signed `amount` (τ, ρt or Q) and the parameters it uses.
    pub fn from_params(kind: KernelKind, amount: f32, p: &KernelParams) -> Self {
        match kind {
            KernelKind::Ellipse => Kernel::Ellipse {
                tau: amount,
                cov_m2: p.cov_m2,
                range_m: p.range_m,
                gamma_max: p.gamma_max,
            },
            KernelKind::Paper => Kernel::Paper {
                tau: amount,
                cov_m2: p.cov_m2,
                range_m: p.range_m,
                gamma_max: p.gamma_max,
            },
            KernelKind::Saturating => Kernel::Saturating {
                rho: amount,
                sigma_m: p.sigma_m,
                range_m: p.range_m,
            },
            KernelKind::ZShape => Kernel::ZShape {
                amount,
                plateau_m: p.plateau_m,
                slope_m: p.slope_m,
            },
        }
    }

    /// The kernel's wire code.
    pub fn kind(&self) -> KernelKind {
        match self {
            Kernel::Ellipse { .. } => KernelKind::Ellipse,
            Kernel::Paper { .. } => KernelKind::Paper,
            Kernel::Saturating { .. } => KernelKind::Saturating,
            Kernel::ZShape { .. } => KernelKind::ZShape,
        }
    }

    /// τ, ρt or Q: the kernel's signed amount.
    pub fn amount(&self) -> f32 {
        match *self {
            Kernel::Ellipse { tau, .. } | Kernel::Paper { tau, .. } => tau,
            Kernel::Saturating { rho, .. } => rho,
            Kernel::ZShape { amount, .. } => amount,
        }
    }
}

/// One deposit: a kernel placed at (`x_m`, `y_m`) world metres on `channel`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Deposit {
    /// Index of the target channel in the field's configuration.
    pub channel: u32,
    /// x of the kernel's centre in the world frame (m).
    pub x_m: f32,
    /// y of the kernel's centre in the world frame (m).
    pub y_m: f32,
    /// The kernel's shape and amount.
    pub kernel: Kernel,
}

impl Deposit {
    /// The typed view of a wire message; `None` for a kernel code no [`KernelKind`] has.
    /// Parameters the kernel does not use are dropped.
    pub fn from_msg(m: &DepositMsg) -> Option<Self> {
        let cov_m2 = [m.cov_xx, m.cov_xy, m.cov_yy];
        let kernel = match KernelKind::from_code(m.kernel)? {
            KernelKind::Ellipse => Kernel::Ellipse {
                tau: m.amount,
                cov_m2,
                range_m: m.range_m,
                gamma_max: m.gamma_max,
            },
            KernelKind::Paper => Kernel::Paper {
                tau: m.amount,
                cov_m2,
                range_m: m.range_m,
                gamma_max: m.gamma_max,
            },
            KernelKind::Saturating => Kernel::Saturating {
                rho: m.amount,
                sigma_m: m.sigma_m,
                range_m: m.range_m,
            },
            KernelKind::ZShape => Kernel::ZShape {
                amount: m.amount,
                plateau_m: m.plateau_m,
                slope_m: m.slope_m,
            },
        };
        Some(Self {
            channel: m.channel,
            x_m: m.x_m,
            y_m: m.y_m,
            kernel,
        })
    }

    /// The wire message, stamped with `robot_id` and `stamp_ns` (0: the publisher stamps it
    /// when it sends).
    pub fn to_msg(&self, robot_id: u32, stamp_ns: u64) -> DepositMsg {
        let mut m = DepositMsg {
            stamp_ns,
            robot_id,
            channel: self.channel,
            kernel: self.kernel.kind() as u32,
            x_m: self.x_m,
            y_m: self.y_m,
            amount: self.kernel.amount(),
            ..DepositMsg::default()
        };
        match self.kernel {
            Kernel::Ellipse {
                cov_m2,
                range_m,
                gamma_max,
                ..
            }
            | Kernel::Paper {
                cov_m2,
                range_m,
                gamma_max,
                ..
            } => {
                [m.cov_xx, m.cov_xy, m.cov_yy] = cov_m2;
                m.range_m = range_m;
                m.gamma_max = gamma_max;
            }
            Kernel::Saturating {
                sigma_m, range_m, ..
            } => {
                m.sigma_m = sigma_m;
                m.range_m = range_m;
            }
            Kernel::ZShape {
                plateau_m, slope_m, ..
            } => {
                m.plateau_m = plateau_m;
                m.slope_m = slope_m;
            }
        }
        m
    }
}

impl From<Deposit> for DepositMsg {
    fn from(d: Deposit) -> Self {
        d.to_msg(0, 0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kernel_round_trips_through_the_wire_message() {
        let kernels = [
            Kernel::Ellipse {
                tau: 0.2,
                cov_m2: [0.01, 0.002, 0.03],
                range_m: 1.0,
                gamma_max: 100.0,
            },
            Kernel::Paper {
                tau: -0.5,
                cov_m2: [0.02, 0.0, 0.02],
                range_m: 2.0,
                gamma_max: 50.0,
            },
            Kernel::Saturating {
                rho: -1.0,
                sigma_m: 0.3,
                range_m: 0.9,
            },
            Kernel::ZShape {
                amount: 3.0,
                plateau_m: 0.1,
                slope_m: 0.2,
            },
        ];
        for kernel in kernels {
            let d = Deposit {
                channel: 2,
                x_m: 1.5,
                y_m: -0.5,
                kernel,
            };
            let m = d.to_msg(7, 42);
            assert_eq!((m.robot_id, m.stamp_ns), (7, 42));
            assert_eq!(m.kernel, kernel.kind() as u32);
            assert_eq!(m.amount, kernel.amount());
            assert_eq!(Deposit::from_msg(&m), Some(d), "{kernel:?}");
        }
    }

    #[test]
    fn an_unknown_kernel_code_has_no_typed_view() {
        let m = DepositMsg {
            kernel: 9,
            ..DepositMsg::default()
        };
        assert_eq!(Deposit::from_msg(&m), None);
    }
}
