//! The deposit parameters a caller gets when it names none, in one place: `pheromone deposit`'s
//! flags, the depositor's `pheromone_roles::depositor::DepositorConfig`, the C ABI's `PheromoneEllipseParams` and the Python package's `DEPOSIT_DEFAULTS` take them
//! (`python/tests/test_defaults.py` compares Python's with `pheromone deposit --help`).

/// τ of the uncertainty-aware ellipse (pheromone·m⁴): its peak γ = τ / det Σxy.
pub const TAU: f32 = 0.2;
/// The cap γmax on an ellipse's (or the paper kernel's) peak.
pub const GAMMA_MAX: f32 = 100.0;
/// The kernel's cut-off radius z_rng (m).
pub const RANGE_M: f32 = 1.0;
/// The position covariance Σxy of a one-off deposit that names none, as xx, xy, yy (m²): σ = 0.1 m.
pub const COV_M2: [f32; 3] = [0.01, 0.0, 0.01];
/// λ of a one-off saturating deposit (m).
pub const SATURATING_SIGMA_M: f32 = 0.1;
/// The z-shape's plateau radius c (m).
pub const PLATEAU_M: f32 = 0.2;
/// The z-shape's slope length σ (m).
pub const SLOPE_M: f32 = 0.3;
