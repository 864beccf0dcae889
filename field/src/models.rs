//! Per-channel evaporation / diffusion models and the fused per-plane update pass.
//!
//! One pass reads each cell of the previous plane once and writes each cell of the next plane
//! once (`step_plane`). The ambient mean of the seed 000 model uses separable running sums over
//! bands of rows (`crate::ambient`), so its cost per cell does not depend on the radius.

use serde::{Deserialize, Serialize};

use crate::ambient::{self, BandScratch, Output};
pub use crate::ambient::{band_rows, BAND_ROWS_MIN, DIRECT_RADIUS_MAX};
use crate::error::ConfigError;
pub use crate::plan::PlanePlan;
pub use crate::simd::Dispatch;

/// How a channel loses pheromone between ticks.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Evaporation {
    /// Nothing evaporates.
    None,
    /// Plain exponential decay: P' = P·e^(−K·dt).
    Exponential {
        /// Decay rate K (1/s, ≥ 0).
        #[serde(alias = "decay_per_sec")]
        decay_per_s: f32,
    },
    /// Seed 000 eq. 17–22 with the MODELS.md M1 decision:
    /// P' = P·e^(−K·dt) + (1 − e^(−K·dt))·min(P, α·Pa), Pa = mean over the square window of
    /// half-width `radius_m` centred on the cell (clipped at the grid's edge).
    Ambient {
        /// Decay rate K (1/s, ≥ 0).
        #[serde(alias = "decay_per_sec")]
        decay_per_s: f32,
        /// α, the fraction of the ambient mean Pa below which a cell stops decaying, in [0, 1]
        /// (default 0.5).
        #[serde(default = "default_alpha")]
        alpha: f32,
        /// Half-width of the ambient window (m, ≥ 0); rounded to whole cells.
        radius_m: f32,
    },
    /// Seed 001 eqs. 6–7 / seed 004 eqs. 3–6: ξ' = ξ − ρ·ξ per tick; deposits saturate at ±1.
    Saturating {
        /// ρ, the fraction of each cell lost per regular tick, in [0, 1].
        rho_per_tick: f32,
    },
    /// Seed 002 counter (MODELS.md M3 reading): every whole `tau_s` of field time each cell
    /// loses `quantum`, never crossing zero.
    Quantum {
        /// Amount each cell loses per period (≥ 0).
        quantum: f32,
        /// Period τ of field time between losses (s, > 0).
        #[serde(alias = "tau_secs")]
        tau_s: f32,
    },
}

fn default_alpha() -> f32 {
    0.5
}

impl Default for Evaporation {
    fn default() -> Self {
        Evaporation::Exponential {
            decay_per_s: 0.0057,
        }
    }
}

/// One channel: a name, an evaporation model, optional diffusion, and whether values may be
/// negative (anti-pheromone).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelSpec {
    /// The channel's name, by which deposits, readers and configuration address it.
    pub name: String,
    /// How the channel loses pheromone between ticks (default: exponential decay).
    #[serde(default)]
    pub evaporation: Evaporation,
    /// Isotropic diffusion coefficient D (m²/s), explicit 5-point stencil, zero-flux edges.
    #[serde(default)]
    #[serde(alias = "diffusion_m2_per_sec")]
    pub diffusion_m2_per_s: f32,
    /// Signed channels hold pheromone (> 0) and anti-pheromone (< 0).
    #[serde(default)]
    pub signed: bool,
    /// Seed 002's sources (MODELS.md M3): the plane holds one counter per grid node, read as
    /// eq. 4 with this Z-shape by directional antennas; a deposit adds to the nearest node's
    /// counter. Needs the `quantum` model and no diffusion. Unset: the plane holds values.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sources: Option<crate::sources::SourceSensing>,
}

impl ChannelSpec {
    /// An unsigned channel `name` with the given model and no diffusion.
    pub fn new(name: &str, evaporation: Evaporation) -> Self {
        Self {
            name: name.to_string(),
            evaporation,
            diffusion_m2_per_s: 0.0,
            signed: false,
            sources: None,
        }
    }

    /// Checks the model against the tick length and cell size (e.g. the diffusion stability
    /// bound D·dt/h² ≤ ¼).
    pub fn validate(&self, dt_s: f32, cell_size_m: f32) -> Result<(), ConfigError> {
        let n = &self.name;
        let finite_nonneg = |what: &str, v: f32| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(ConfigError::invalid(
                    format!("channel '{n}' {what}"),
                    v,
                    "must be finite and ≥ 0",
                ))
            }
        };
        match self.evaporation {
            Evaporation::None => {}
            Evaporation::Exponential { decay_per_s } => finite_nonneg("decay_per_s", decay_per_s)?,
            Evaporation::Ambient {
                decay_per_s,
                alpha,
                radius_m,
            } => {
                finite_nonneg("decay_per_s", decay_per_s)?;
                if !(0.0..=1.0).contains(&alpha) {
                    return Err(ConfigError::invalid(
                        format!("channel '{n}' alpha"),
                        alpha,
                        "must be within [0, 1]",
                    ));
                }
                finite_nonneg("radius_m", radius_m)?;
                if self.signed {
                    return Err(ConfigError::invalid(
                        format!("channel '{n}' signed"),
                        true,
                        "the ambient model is defined for non-negative pheromone only",
                    ));
                }
            }
            Evaporation::Saturating { rho_per_tick } => {
                if !(0.0..=1.0).contains(&rho_per_tick) {
                    return Err(ConfigError::invalid(
                        format!("channel '{n}' rho_per_tick"),
                        rho_per_tick,
                        "must be within [0, 1]",
                    ));
                }
            }
            Evaporation::Quantum { quantum, tau_s } => {
                finite_nonneg("quantum", quantum)?;
                if !(tau_s.is_finite() && tau_s > 0.0) {
                    return Err(ConfigError::invalid(
                        format!("channel '{n}' tau_s"),
                        tau_s,
                        "must be finite and > 0",
                    ));
                }
            }
        }
        finite_nonneg("diffusion_m2_per_s", self.diffusion_m2_per_s)?;
        if let Some(s) = &self.sources {
            self.validate_sources(s)?;
        }
        let kappa = self.diffusion_m2_per_s * dt_s / (cell_size_m * cell_size_m);
        if kappa > 0.25 {
            return Err(ConfigError::invalid(
                format!("channel '{n}' diffusion_m2_per_s"),
                self.diffusion_m2_per_s,
                format!(
                    "unstable: D·dt/h² = {kappa:.3} > 0.25 (dt = {dt_s} s, h = {cell_size_m} m); \
                     lower D or dt, or raise the cell size"
                ),
            ));
        }
        Ok(())
    }

    /// A source channel's counters lose a quantum per τ (eqs. 2–3) and do not diffuse.
    fn validate_sources(&self, s: &crate::sources::SourceSensing) -> Result<(), ConfigError> {
        let n = &self.name;
        s.validate(n)?;
        if !matches!(self.evaporation, Evaporation::Quantum { .. }) {
            return Err(ConfigError::invalid(
                format!("channel '{n}' sources"),
                "set",
                "source counters need the quantum model (eqs. 2–3)",
            ));
        }
        if self.diffusion_m2_per_s != 0.0 {
            return Err(ConfigError::invalid(
                format!("channel '{n}' diffusion_m2_per_s"),
                self.diffusion_m2_per_s,
                "a source channel's counters do not diffuse (must be 0)",
            ));
        }
        Ok(())
    }

    /// Clamp range of a cell of this channel.
    pub fn value_range(&self) -> (f32, f32) {
        match (self.evaporation, self.signed) {
            (Evaporation::Saturating { .. }, true) => (-1.0, 1.0),
            (Evaporation::Saturating { .. }, false) => (0.0, 1.0),
            (_, true) => (-CELL_LIMIT, CELL_LIMIT),
            (_, false) => (0.0, CELL_LIMIT),
        }
    }
}

/// No cell ever exceeds this magnitude: deposits saturate here, so no sum of finite deposits can
/// reach infinity.
pub const CELL_LIMIT: f32 = 1.0e30;

impl PlanePlan {
    /// The plan for a tick of `dt_s` that starts at field time `t_s`.
    pub fn for_tick(spec: &ChannelSpec, t_s: f64, dt_s: f32, cell_size_m: f32) -> Self {
        Self::for_dt(spec, t_s, dt_s, dt_s, cell_size_m)
    }

    /// The plan for a step of any length `dt_s` from field time `t_s`, in a field whose regular
    /// tick is `tick_dt_s` (a field that publishes on deposit steps by the real elapsed time).
    /// Every model is closed-form in dt: exponential and ambient decay by e^(−λ·dt), the
    /// saturating model by (1 − ρ)^(dt / tick_dt) (ρ is per regular tick), the quantum model
    /// subtracts one quantum per whole τ crossed.
    pub fn for_dt(
        spec: &ChannelSpec,
        t_s: f64,
        dt_s: f32,
        tick_dt_s: f32,
        cell_size_m: f32,
    ) -> Self {
        match spec.evaporation {
            Evaporation::None => PlanePlan::Scale { factor: 1.0 },
            Evaporation::Exponential { decay_per_s } => PlanePlan::Scale {
                factor: (-decay_per_s * dt_s).exp(),
            },
            Evaporation::Ambient {
                decay_per_s,
                alpha,
                radius_m,
            } => PlanePlan::Ambient {
                factor: (-decay_per_s * dt_s).exp(),
                alpha,
                radius_cells: (radius_m / cell_size_m).round() as u32,
            },
            Evaporation::Saturating { rho_per_tick } => PlanePlan::Scale {
                factor: if dt_s == tick_dt_s {
                    1.0 - rho_per_tick
                } else {
                    ((1.0 - rho_per_tick as f64).powf(dt_s as f64 / tick_dt_s as f64)) as f32
                },
            },
            Evaporation::Quantum { quantum, tau_s } => {
                let tau = tau_s as f64;
                // The clock (a sum of f32 ticks) and τ are f32-precise: 50 ticks of 0.02f32 s
                // fall 2e-8 s short of 1 s. t/τ is off by at most ~1.2e-7 (relative) from the
                // intended ratio, so periods count as elapsed within 2.5e-7 of their end: "every
                // τ" means every τ, not one tick later.
                let periods = |t: f64| (t / tau * (1.0 + 2.5e-7)).floor();
                let crossed = periods(t_s + dt_s as f64) - periods(t_s);
                PlanePlan::Subtract {
                    loss: quantum * crossed.max(0.0) as f32,
                }
            }
        }
    }
}

/// Reusable scratch of the plane pass: one `BandScratch` per thread (O(width) each, never
/// O(grid)).
#[derive(Debug, Default, Clone)]
pub struct Scratch {
    workers: Vec<BandScratch>,
}

/// Computes one plane of the next frame from the previous one: diffusion (if `kappa > 0`,
/// κ = D·dt/h²) then the evaporation plan, in one pass. `prev` and `next` are `width × height`
/// row-major planes.
pub fn step_plane(
    plan: PlanePlan,
    kappa: f32,
    width: usize,
    prev: &[f32],
    next: &mut [f32],
    scratch: &mut Scratch,
) {
    step_plane_threads(plan, kappa, width, prev, next, scratch, 1);
}

/// As `step_plane`, with the rows split across `threads` threads (the caller's and
/// `threads − 1` scoped ones). The result is bit-identical for every thread count.
pub fn step_plane_threads(
    plan: PlanePlan,
    kappa: f32,
    width: usize,
    prev: &[f32],
    next: &mut [f32],
    scratch: &mut Scratch,
    threads: usize,
) {
    step_plane_with(
        plan,
        kappa,
        width,
        prev,
        next,
        scratch,
        threads,
        Dispatch::detect(),
    );
}

/// As `step_plane_threads` with a chosen kernel instantiation (tests compare AVX2 and portable
/// bit for bit).
#[allow(clippy::too_many_arguments)]
pub fn step_plane_with(
    plan: PlanePlan,
    kappa: f32,
    width: usize,
    prev: &[f32],
    next: &mut [f32],
    scratch: &mut Scratch,
    threads: usize,
    dispatch: Dispatch,
) {
    assert_eq!(prev.len(), next.len());
    assert!(width > 0 && prev.len().is_multiple_of(width));
    ambient::plane(
        Output::Step { plan, kappa },
        width,
        prev,
        next,
        &mut scratch.workers,
        threads,
        dispatch,
    );
}

/// The running-sum ambient mean of every cell of a `width`-wide plane, over the `(2r+1)²` window
/// around each cell clipped to the grid — the same band code the tick uses (`crate::ambient`),
/// for tests and tools (compare with `ambient_mean_brute`).
pub fn ambient_mean_plane(prev: &[f32], width: usize, r: usize) -> Vec<f32> {
    ambient_mean_plane_with(prev, width, r, Dispatch::detect(), 1)
}

/// As `ambient_mean_plane` with a chosen kernel instantiation and thread count (tests compare
/// the AVX2 and portable paths and thread counts bit for bit).
pub fn ambient_mean_plane_with(
    prev: &[f32],
    width: usize,
    r: usize,
    dispatch: Dispatch,
    threads: usize,
) -> Vec<f32> {
    assert!(width > 0 && prev.len().is_multiple_of(width));
    let mut out = vec![0.0f32; prev.len()];
    let mut workers = Vec::new();
    ambient::plane(
        Output::Mean { radius_cells: r },
        width,
        prev,
        &mut out,
        &mut workers,
        threads,
        dispatch,
    );
    out
}

/// Brute-force ambient mean of one cell (for tests and reference): mean of `prev` over the
/// `(2r+1)²` window around `(x, y)`, clipped to the grid.
pub fn ambient_mean_brute(prev: &[f32], width: usize, x: usize, y: usize, r: usize) -> f32 {
    let height = prev.len() / width;
    let (x0, x1) = (x.saturating_sub(r), (x + r).min(width - 1));
    let (y0, y1) = (y.saturating_sub(r), (y + r).min(height - 1));
    let mut sum = 0.0f64;
    for yy in y0..=y1 {
        for xx in x0..=x1 {
            sum += prev[yy * width + xx] as f64;
        }
    }
    (sum / ((x1 - x0 + 1) * (y1 - y0 + 1)) as f64) as f32
}
