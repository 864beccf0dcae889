//! Deposit kernels (MODELS.md M1–M4) and the validation every deposit passes before it may touch
//! a frame. A deposit costs O(kernel area): only the cells within its extent are visited.

use crate::geometry::{CellBox, GridGeometry};
use crate::messages::{DepositMsg, KernelKind};
use crate::models::ChannelSpec;
pub use crate::reject::{RejectReason, Rejection, REJECT_REASONS};
/// Seed 002 eq. 1 (defined beside the source channels that read with it).
pub use crate::sources::z_shape;

fn reject(reason: RejectReason, detail: impl Into<String>) -> Rejection {
    Rejection {
        reason,
        detail: detail.into(),
    }
}

/// Limits on what a single deposit may ask for.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DepositLimits {
    /// Largest |amount| (τ, ρt or Q) accepted.
    pub max_abs_amount: f32,
    /// Largest kernel radius, in cells (the kernel box is at most (2r+1)² cells).
    pub max_radius_cells: f32,
    /// Largest γmax accepted for the M1 kernels.
    pub max_gamma: f32,
}

impl Default for DepositLimits {
    fn default() -> Self {
        Self {
            max_abs_amount: 1.0e6,
            max_radius_cells: 512.0,
            max_gamma: 1.0e6,
        }
    }
}

/// A validated deposit, with every constant of its kernel computed once.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PreparedDeposit {
    /// Index of the target channel in the field's channel list (checked in range).
    pub channel: usize,
    /// The cells the kernel may reach (its cut-off box, clipped to the grid); only these are
    /// visited.
    pub cells: CellBox,
    /// x of the deposit's centre in the world frame (m).
    pub x_m: f32,
    /// y of the deposit's centre in the world frame (m).
    pub y_m: f32,
    /// Squared cut-off radius z_rng² (m²).
    pub range2_m2: f32,
    /// The kernel and its precomputed constants.
    pub shape: Shape,
}

/// The kernel, ready to evaluate at an offset `(dx, dy)` in metres from the deposit's centre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// value = gain·exp(−(a·dx² + 2b·dx·dy + c·dy²)) — both M1 kernels take this form.
    Quadratic {
        /// Peak value at the centre: γ (seed 000 eq. 12), signed like the amount.
        gain: f32,
        /// dx² coefficient of the quadratic form (1/m²).
        a: f32,
        /// Half the dx·dy coefficient of the quadratic form (1/m²).
        b: f32,
        /// dy² coefficient of the quadratic form (1/m²).
        c: f32,
    },
    /// Seed 001 eq. 3 / seed 004: Δ = (1 − s·ξprev)·s·ρt·exp(−d²/λ²), s = sign of the amount.
    Saturating {
        /// ρt, the signed deposit strength, in [−1, 1].
        rho: f32,
        /// 1/λ² (1/m²), λ the kernel's width (the message's `sigma_m`); capped at `f32::MAX`.
        inv_lambda2: f32,
    },
    /// Seed 002 eq. 1: amount·μ(d), μ = 1 to `plateau_m`, falling linearly to 0 over `slope_m`.
    ZShape {
        /// Value added on the plateau (Q, signed).
        amount: f32,
        /// Radius of the full-value plateau c (m, ≥ 0).
        plateau_m: f32,
        /// Width σ of the linear fall-off beyond the plateau (m, ≥ 0).
        slope_m: f32,
    },
    /// Seed 002 on a source channel: the whole amount to the one node in `cells`.
    Node {
        /// Added to the node's counter (signed).
        amount: f32,
    },
}

/// The 2×2 position covariance, its eigen-decomposition and the γ of seed 000 eq. 12.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorEllipse {
    /// Largest eigenvalue λ1 (variance along the major axis, m²), λ1 ≥ λ2.
    pub lambda1: f32,
    /// Smallest eigenvalue λ2 (variance along the minor axis, m²), clamped to ≥ 0.
    pub lambda2: f32,
    /// Unit eigenvector of λ1 (the major axis).
    pub major: (f32, f32),
}

impl ErrorEllipse {
    /// Closed-form eigen-decomposition of the symmetric matrix [[xx, xy], [xy, yy]].
    pub fn from_cov(xx: f32, xy: f32, yy: f32) -> Self {
        let (xx64, xy64, yy64) = (xx as f64, xy as f64, yy as f64);
        let mean = 0.5 * (xx64 + yy64);
        let half_diff = 0.5 * (xx64 - yy64);
        let root = (half_diff * half_diff + xy64 * xy64).sqrt();
        let l1 = mean + root;
        let l2 = (mean - root).max(0.0);
        // Eigenvector of l1: the angle θ with tan 2θ = 2xy / (xx − yy).
        let theta = 0.5 * (2.0 * xy64).atan2(xx64 - yy64);
        Self {
            lambda1: l1 as f32,
            lambda2: l2 as f32,
            major: (theta.cos() as f32, theta.sin() as f32),
        }
    }

    /// det Σxy = λ1·λ2.
    pub fn det(&self) -> f32 {
        self.lambda1 * self.lambda2
    }
}

/// γ = τ / det Σxy, capped at ±γmax (seed 000 eq. 12; a zero determinant gives the cap, and
/// τ = 0 gives 0 whatever the determinant: a deposit of nothing adds nothing).
pub fn gamma(tau: f32, det_m4: f32, gamma_max: f32) -> f32 {
    if tau == 0.0 {
        return 0.0;
    }
    let g = if det_m4 > 0.0 {
        tau as f64 / det_m4 as f64
    } else {
        f64::INFINITY.copysign(tau as f64)
    };
    (g.clamp(-(gamma_max as f64), gamma_max as f64)) as f32
}

/// Checks a deposit message against the field and turns it into a kernel.
pub fn prepare(
    msg: &DepositMsg,
    geometry: &GridGeometry,
    channels: &[ChannelSpec],
    limits: &DepositLimits,
) -> Result<PreparedDeposit, Rejection> {
    check_finite(msg)?;
    let (channel, kernel) = check_target(msg, channels, limits)?;
    let h = geometry.cell_size_m;
    let lengths = Lengths {
        max_m: limits.max_radius_cells * h,
    };
    let (shape, extent_m) = match kernel {
        KernelKind::Ellipse | KernelKind::Paper => {
            quadratic_shape(msg, kernel, h, limits, lengths)?
        }
        KernelKind::Saturating => saturating_shape(msg, lengths)?,
        KernelKind::ZShape => z_shape_kernel(msg, h, lengths)?,
    };
    if channels[channel].sources.is_some() {
        return node_deposit(msg, channel, geometry);
    }
    Ok(PreparedDeposit {
        channel,
        cells: cells_reached(msg, geometry, extent_m)?,
        x_m: msg.x_m,
        y_m: msg.y_m,
        range2_m2: extent_m * extent_m,
        shape,
    })
}

/// Every number of the message is finite.
fn check_finite(msg: &DepositMsg) -> Result<(), Rejection> {
    let named = [
        ("x_m", msg.x_m),
        ("y_m", msg.y_m),
        ("amount", msg.amount),
        ("cov_xx", msg.cov_xx),
        ("cov_xy", msg.cov_xy),
        ("cov_yy", msg.cov_yy),
        ("range_m", msg.range_m),
        ("gamma_max", msg.gamma_max),
        ("sigma_m", msg.sigma_m),
        ("plateau_m", msg.plateau_m),
        ("slope_m", msg.slope_m),
    ];
    match named.iter().find(|(_, v)| !v.is_finite()) {
        Some((name, v)) => Err(reject(RejectReason::NonFinite, format!("{name} = {v}"))),
        None => Ok(()),
    }
}

/// The channel and kernel the message names, and its amount checked against them: the
/// channel's index and the kernel.
fn check_target(
    msg: &DepositMsg,
    channels: &[ChannelSpec],
    limits: &DepositLimits,
) -> Result<(usize, KernelKind), Rejection> {
    let channel = msg.channel as usize;
    let Some(spec) = channels.get(channel) else {
        return Err(reject(
            RejectReason::UnknownChannel,
            format!(
                "channel = {} (the field has {})",
                msg.channel,
                channels.len()
            ),
        ));
    };
    let Some(kernel) = KernelKind::from_code(msg.kernel) else {
        return Err(reject(
            RejectReason::UnknownKernel,
            format!("kernel = {}", msg.kernel),
        ));
    };
    if msg.amount.abs() > limits.max_abs_amount {
        return Err(reject(
            RejectReason::OutOfLimits,
            format!("amount = {} (limit ±{})", msg.amount, limits.max_abs_amount),
        ));
    }
    if msg.amount < 0.0 && !spec.signed {
        return Err(reject(
            RejectReason::NegativeOnUnsigned,
            format!(
                "amount = {} on unsigned channel '{}'",
                msg.amount, spec.name
            ),
        ));
    }
    Ok((channel, kernel))
}

/// The longest length (range, σ, plateau, slope) a deposit may ask for.
#[derive(Clone, Copy)]
struct Lengths {
    max_m: f32,
}

impl Lengths {
    /// `v` (metres, called `name` in the message) is within `[0, max]`, and not 0 unless
    /// `allow_zero`.
    fn check(self, name: &str, v: f32, allow_zero: bool) -> Result<(), Rejection> {
        let max_range_m = self.max_m;
        if v < 0.0 || (!allow_zero && v == 0.0) || v > max_range_m {
            Err(reject(
                RejectReason::OutOfLimits,
                format!(
                    "{name} = {v} m (must be {} and ≤ {max_range_m} m)",
                    if allow_zero { "≥ 0" } else { "> 0" }
                ),
            ))
        } else {
            Ok(())
        }
    }
}

/// Whether a deposit's Σxy `[[xx, xy], [xy, yy]]` is positive semi-definite, within the `f32`
/// message's rounding: xx ≥ 0, yy ≥ 0 and xx·yy − xy² ≥ −1e-6·max(|xx|, |yy|)². The field refuses
/// an ellipse or paper deposit that fails it (`not_psd`); senders that get no receipt (the C
/// ABI's `pheromone_deposit`) check it first with this same function.
pub fn cov_xy_is_psd(xx: f32, xy: f32, yy: f32) -> bool {
    let scale = xx.abs().max(yy.abs()).max(f32::MIN_POSITIVE);
    // Written as "not refused" so that a NaN (which the finiteness checks refuse first, by name)
    // is not reported as a PSD failure.
    !(xx < 0.0
        || yy < 0.0
        || (xx as f64 * yy as f64 - xy as f64 * xy as f64) < -1e-6 * (scale as f64).powi(2))
}

/// The M1 kernels (ellipse and paper, seed 000): the covariance's quadratic form and γ, and the
/// cut-off range. `h`: the cell size (m).
fn quadratic_shape(
    msg: &DepositMsg,
    kernel: KernelKind,
    h: f32,
    limits: &DepositLimits,
    lengths: Lengths,
) -> Result<(Shape, f32), Rejection> {
    lengths.check("range_m", msg.range_m, false)?;
    if !(msg.gamma_max > 0.0 && msg.gamma_max <= limits.max_gamma) {
        return Err(reject(
            RejectReason::OutOfLimits,
            format!(
                "gamma_max = {} (must be in (0, {}])",
                msg.gamma_max, limits.max_gamma
            ),
        ));
    }
    let (xx, xy, yy) = (msg.cov_xx, msg.cov_xy, msg.cov_yy);
    if !cov_xy_is_psd(xx, xy, yy) {
        return Err(reject(
            RejectReason::NotPsd,
            format!("covariance [[{xx}, {xy}], [{xy}, {yy}]] is not positive semi-definite"),
        ));
    }
    let ellipse = ErrorEllipse::from_cov(xx, xy, yy);
    let g = gamma(msg.amount, ellipse.det(), msg.gamma_max);
    // The shape uses variances floored at (h/2)²: a point-like ellipse still lands on
    // the cell under it instead of falling between cell centres.
    // Computed in f64 and saturated into f32: with tiny cells 1/λ² overflows f32, and
    // ∞·0 in the rotation below would be NaN.
    let floor = 0.25 * (h as f64) * (h as f64);
    let l1 = (ellipse.lambda1 as f64).max(floor);
    let l2 = (ellipse.lambda2 as f64).max(floor);
    let (c, s) = (ellipse.major.0 as f64, ellipse.major.1 as f64);
    // Weights along the axes: ellipse ½/λ (= ½ dᵀΣ⁻¹d), paper 1/λ² (eq. 14 as printed).
    let (w1, w2) = match kernel {
        KernelKind::Ellipse => (0.5 / l1, 0.5 / l2),
        _ => (1.0 / (l1 * l1), 1.0 / (l2 * l2)),
    };
    let to_f32 = |v: f64| v.clamp(-(f32::MAX as f64), f32::MAX as f64) as f32;
    // Quadratic form R diag(w1, w2) Rᵀ.
    let a = to_f32(w1 * c * c + w2 * s * s);
    let b = to_f32((w1 - w2) * c * s);
    let cc = to_f32(w1 * s * s + w2 * c * c);
    Ok((
        Shape::Quadratic {
            gain: g,
            a,
            b,
            c: cc,
        },
        msg.range_m,
    ))
}

/// The saturating kernel (seed 001 eq. 3 / seed 004) and its cut-off range.
fn saturating_shape(msg: &DepositMsg, lengths: Lengths) -> Result<(Shape, f32), Rejection> {
    lengths.check("range_m", msg.range_m, false)?;
    lengths.check("sigma_m", msg.sigma_m, false)?;
    if msg.amount.abs() > 1.0 {
        return Err(reject(
            RejectReason::OutOfLimits,
            format!(
                "amount = {} (ρt of a saturating deposit must be within [−1, 1])",
                msg.amount
            ),
        ));
    }
    Ok((
        Shape::Saturating {
            rho: msg.amount,
            // A vanishing λ (λ² underflows) must not give 1/λ² = ∞: at d = 0 that
            // would be 0·∞ = NaN. f32::MAX keeps it a point deposit.
            inv_lambda2: (1.0 / (msg.sigma_m * msg.sigma_m)).min(f32::MAX),
        },
        msg.range_m,
    ))
}

/// The z-shaped kernel (seed 002 eq. 1) and its extent, at least the cell under the centre
/// (`h`: the cell size, m).
fn z_shape_kernel(msg: &DepositMsg, h: f32, lengths: Lengths) -> Result<(Shape, f32), Rejection> {
    lengths.check("plateau_m", msg.plateau_m, true)?;
    lengths.check("slope_m", msg.slope_m, true)?;
    let extent = msg.plateau_m + msg.slope_m;
    lengths.check("plateau_m + slope_m", extent, true)?;
    Ok((
        Shape::ZShape {
            amount: msg.amount,
            plateau_m: msg.plateau_m,
            slope_m: msg.slope_m,
        },
        // Reach at least the cell under the centre.
        extent.max(0.5 * h),
    ))
}

/// The cells within `extent_m` of the deposit's centre; a deposit that reaches none is refused.
/// On a source channel (MODELS.md M3), a deposit, checked as its kernel, adds its amount to the
/// counter of the node nearest to (x, y) (`sources`: the node at a cell's corner).
fn node_deposit(
    msg: &DepositMsg,
    channel: usize,
    geometry: &GridGeometry,
) -> Result<PreparedDeposit, Rejection> {
    let Some((i, j)) = crate::sources::nearest_node(geometry, msg.x_m, msg.y_m) else {
        return Err(reject(
            RejectReason::OutsideGrid,
            format!(
                "({}, {}) m: its nearest node is not one of the grid's {} × {} source nodes",
                msg.x_m, msg.y_m, geometry.width, geometry.height
            ),
        ));
    };
    Ok(PreparedDeposit {
        channel,
        cells: CellBox {
            x0: i,
            y0: j,
            x1: i,
            y1: j,
        },
        x_m: msg.x_m,
        y_m: msg.y_m,
        range2_m2: f32::INFINITY,
        shape: Shape::Node { amount: msg.amount },
    })
}

fn cells_reached(
    msg: &DepositMsg,
    geometry: &GridGeometry,
    extent_m: f32,
) -> Result<CellBox, Rejection> {
    geometry
        .cell_box(msg.x_m, msg.y_m, extent_m)
        .ok_or_else(|| {
            reject(
                RejectReason::OutsideGrid,
                format!(
                    "({}, {}) m with extent {extent_m} m misses the grid [{}, {}] × [{}, {}] m",
                    msg.x_m,
                    msg.y_m,
                    geometry.origin_x_m,
                    geometry.origin_x_m + geometry.width_m(),
                    geometry.origin_y_m,
                    geometry.origin_y_m + geometry.height_m()
                ),
            )
        })
}

impl PreparedDeposit {
    /// Adds this deposit to `plane` (the next frame's plane of its channel), reading the previous
    /// frame's plane `prev` for the saturating factor. Values are clamped to `[lo, hi]`.
    /// Returns the mass actually added (sum of cell increments).
    pub fn apply(
        &self,
        geometry: &GridGeometry,
        prev: &[f32],
        plane: &mut [f32],
        lo: f32,
        hi: f32,
    ) -> f64 {
        let w = geometry.width as usize;
        let h = geometry.cell_size_m;
        let mut added = 0.0f64;
        for y in self.cells.y0..=self.cells.y1 {
            let dy = geometry.origin_y_m + (y as f32 + 0.5) * h - self.y_m;
            let row = y as usize * w;
            for x in self.cells.x0..=self.cells.x1 {
                let dx = geometry.origin_x_m + (x as f32 + 0.5) * h - self.x_m;
                let d2 = dx * dx + dy * dy;
                if d2 > self.range2_m2 {
                    continue;
                }
                let i = row + x as usize;
                let delta = match self.shape {
                    Shape::Quadratic { gain, a, b, c } => {
                        gain * (-(a * dx * dx + 2.0 * b * dx * dy + c * dy * dy)).exp()
                    }
                    Shape::Saturating { rho, inv_lambda2 } => {
                        let s = rho.signum();
                        let room = (1.0 - s * prev[i]).max(0.0);
                        room * rho * (-d2 * inv_lambda2).exp()
                    }
                    Shape::ZShape {
                        amount,
                        plateau_m,
                        slope_m,
                    } => amount * z_shape(d2.sqrt(), plateau_m, slope_m),
                    Shape::Node { amount } => amount,
                };
                // Last line of defence for absurd geometries (cells of 1e-20 m or 1e30 m make
                // f32 kernel arithmetic overflow into ∞ − ∞): a NaN never reaches the frame.
                if delta.is_nan() {
                    continue;
                }
                let before = plane[i];
                let after = (before + delta).clamp(lo, hi);
                plane[i] = after;
                // In f64: the f32 difference of two cells of different magnitude rounds.
                added += after as f64 - before as f64;
            }
        }
        added
    }
}

#[cfg(test)]
mod tests {
    use super::gamma;

    #[test]
    fn gamma_is_tau_over_det_capped_and_zero_for_no_amount() {
        assert_eq!(gamma(0.2, 0.01, 100.0), 20.0);
        assert_eq!(gamma(0.2, 0.0, 100.0), 100.0);
        assert_eq!(gamma(-0.2, 0.0, 100.0), -100.0);
        // Amount 0 (or -0) with a zero covariance deposited ±γmax before.
        assert_eq!(gamma(0.0, 0.0, 100.0), 0.0);
        assert_eq!(gamma(-0.0, 0.0, 100.0), 0.0);
        assert_eq!(gamma(0.0, 1e-4, 100.0), 0.0);
    }
}
