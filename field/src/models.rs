//! Per-channel evaporation / diffusion models and the fused per-plane update pass.
//!
//! One pass reads each cell of the previous plane once and writes each cell of the next plane
//! once (`step_plane`). The ambient mean of the seed 000 model uses running sums: a column-sum
//! vector updated by one row in and one row out, and a prefix sum along the row, so its cost per
//! cell does not depend on the radius.

use serde::{Deserialize, Serialize};

use crate::error::ConfigError;

/// How a channel loses pheromone between ticks.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Evaporation {
    /// Nothing evaporates.
    None,
    /// Plain exponential decay: P' = P·e^(−K·dt).
    Exponential { decay_per_sec: f32 },
    /// Seed 000 eq. 17–22 with the MODELS.md M1 decision:
    /// P' = P·e^(−K·dt) + (1 − e^(−K·dt))·min(P, α·Pa), Pa = mean over the square window of
    /// half-width `radius_m` centred on the cell (clipped at the grid's edge).
    Ambient {
        decay_per_sec: f32,
        #[serde(default = "default_alpha")]
        alpha: f32,
        radius_m: f32,
    },
    /// Seed 001 eqs. 6–7 / seed 004 eqs. 3–6: ξ' = ξ − ρ·ξ per tick; deposits saturate at ±1.
    Saturating { rho_per_tick: f32 },
    /// Seed 002 counter (MODELS.md M3 reading): every whole `tau_secs` of field time each cell
    /// loses `quantum`, never crossing zero.
    Quantum { quantum: f32, tau_secs: f32 },
}

fn default_alpha() -> f32 {
    0.5
}

impl Default for Evaporation {
    fn default() -> Self {
        Evaporation::Exponential {
            decay_per_sec: 0.0057,
        }
    }
}

/// One channel: a name, an evaporation model, optional diffusion, and whether values may be
/// negative (anti-pheromone).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelSpec {
    pub name: String,
    #[serde(default)]
    pub evaporation: Evaporation,
    /// Isotropic diffusion coefficient D (m²/s), explicit 5-point stencil, zero-flux edges.
    #[serde(default)]
    pub diffusion_m2_per_sec: f32,
    /// Signed channels hold pheromone (> 0) and anti-pheromone (< 0).
    #[serde(default)]
    pub signed: bool,
}

impl ChannelSpec {
    pub fn new(name: &str, evaporation: Evaporation) -> Self {
        Self {
            name: name.to_string(),
            evaporation,
            diffusion_m2_per_sec: 0.0,
            signed: false,
        }
    }

    /// Checks the model against the tick length and cell size (e.g. the diffusion stability
    /// bound D·dt/h² ≤ ¼).
    pub fn validate(&self, dt_secs: f32, cell_size_m: f32) -> Result<(), ConfigError> {
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
            Evaporation::Exponential { decay_per_sec } => finite_nonneg("decay_per_sec", decay_per_sec)?,
            Evaporation::Ambient {
                decay_per_sec,
                alpha,
                radius_m,
            } => {
                finite_nonneg("decay_per_sec", decay_per_sec)?;
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
            Evaporation::Quantum { quantum, tau_secs } => {
                finite_nonneg("quantum", quantum)?;
                if !(tau_secs.is_finite() && tau_secs > 0.0) {
                    return Err(ConfigError::invalid(
                        format!("channel '{n}' tau_secs"),
                        tau_secs,
                        "must be finite and > 0",
                    ));
                }
            }
        }
        finite_nonneg("diffusion_m2_per_sec", self.diffusion_m2_per_sec)?;
        let kappa = self.diffusion_m2_per_sec * dt_secs / (cell_size_m * cell_size_m);
        if kappa > 0.25 {
            return Err(ConfigError::invalid(
                format!("channel '{n}' diffusion_m2_per_sec"),
                self.diffusion_m2_per_sec,
                format!(
                    "unstable: D·dt/h² = {kappa:.3} > 0.25 (dt = {dt_secs} s, h = {cell_size_m} m); \
                     lower D or dt, or raise the cell size"
                ),
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

/// What one tick does to one plane, with every per-tick constant already computed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlanePlan {
    /// P' = P·factor (exponential, saturating, or none with factor 1).
    Scale { factor: f32 },
    /// P' = P·e + (1 − e)·min(P, α·Pa), Pa the mean over a (2r+1)² window.
    Ambient { factor: f32, alpha: f32, radius_cells: u32 },
    /// P' = sign(P)·max(|P| − loss, 0).
    Subtract { loss: f32 },
}

impl PlanePlan {
    /// The plan for a tick of `dt_secs` that starts at field time `t_secs`.
    pub fn for_tick(spec: &ChannelSpec, t_secs: f64, dt_secs: f32, cell_size_m: f32) -> Self {
        match spec.evaporation {
            Evaporation::None => PlanePlan::Scale { factor: 1.0 },
            Evaporation::Exponential { decay_per_sec } => PlanePlan::Scale {
                factor: (-decay_per_sec * dt_secs).exp(),
            },
            Evaporation::Ambient {
                decay_per_sec,
                alpha,
                radius_m,
            } => PlanePlan::Ambient {
                factor: (-decay_per_sec * dt_secs).exp(),
                alpha,
                radius_cells: (radius_m / cell_size_m).round() as u32,
            },
            Evaporation::Saturating { rho_per_tick } => PlanePlan::Scale {
                factor: 1.0 - rho_per_tick,
            },
            Evaporation::Quantum { quantum, tau_secs } => {
                let tau = tau_secs as f64;
                let crossed = ((t_secs + dt_secs as f64) / tau).floor() - (t_secs / tau).floor();
                PlanePlan::Subtract {
                    loss: quantum * crossed.max(0.0) as f32,
                }
            }
        }
    }
}

/// Reusable scratch for the ambient mean (O(width), never O(grid)).
#[derive(Debug, Default, Clone)]
pub struct Scratch {
    col_sum: Vec<f64>,
    prefix: Vec<f64>,
    ambient: Vec<f32>,
    diffused: Vec<f32>,
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
    assert_eq!(prev.len(), next.len());
    assert!(width > 0 && prev.len() % width == 0);
    let height = prev.len() / width;
    if kappa == 0.0 {
        if let PlanePlan::Scale { factor } = plan {
            scale(prev, next, factor);
            return;
        }
        if let PlanePlan::Subtract { loss } = plan {
            for (o, &p) in next.iter_mut().zip(prev) {
                *o = subtract_toward_zero(p, loss);
            }
            return;
        }
    }
    let mut ambient = AmbientRows::new(plan, width, height, prev, scratch);
    let mut diffused = std::mem::take(&mut scratch.diffused);
    diffused.resize(width, 0.0);
    for y in 0..height {
        let row = &prev[y * width..(y + 1) * width];
        let src: &[f32] = if kappa > 0.0 {
            let up = if y > 0 { &prev[(y - 1) * width..y * width] } else { row };
            let down = if y + 1 < height {
                &prev[(y + 1) * width..(y + 2) * width]
            } else {
                row
            };
            diffuse_row(row, up, down, kappa, &mut diffused);
            &diffused
        } else {
            row
        };
        let out = &mut next[y * width..(y + 1) * width];
        match plan {
            PlanePlan::Scale { factor } => scale(src, out, factor),
            PlanePlan::Subtract { loss } => {
                for (o, &p) in out.iter_mut().zip(src) {
                    *o = subtract_toward_zero(p, loss);
                }
            }
            PlanePlan::Ambient { factor, alpha, .. } => {
                let amb = ambient.row(y, prev);
                ambient_row(src, amb, out, factor, alpha);
            }
        }
    }
    scratch.diffused = diffused;
    ambient.finish(scratch);
}

#[inline]
fn scale(src: &[f32], out: &mut [f32], factor: f32) {
    for (o, &p) in out.iter_mut().zip(src) {
        *o = p * factor;
    }
}

#[inline]
fn subtract_toward_zero(p: f32, loss: f32) -> f32 {
    let m = (p.abs() - loss).max(0.0);
    m.copysign(p)
}

#[inline]
fn ambient_row(src: &[f32], amb: &[f32], out: &mut [f32], factor: f32, alpha: f32) {
    let one_minus = 1.0 - factor;
    for ((o, &p), &a) in out.iter_mut().zip(src).zip(amb) {
        *o = p * factor + one_minus * p.min(alpha * a);
    }
}

fn diffuse_row(row: &[f32], up: &[f32], down: &[f32], kappa: f32, out: &mut [f32]) {
    let w = row.len();
    if w == 1 {
        out[0] = row[0] + kappa * (up[0] + down[0] - 2.0 * row[0]);
        return;
    }
    out[0] = row[0] + kappa * (row[1] + up[0] + down[0] - 3.0 * row[0]);
    for x in 1..w - 1 {
        out[x] = row[x] + kappa * (row[x - 1] + row[x + 1] + up[x] + down[x] - 4.0 * row[x]);
    }
    out[w - 1] = row[w - 1] + kappa * (row[w - 2] + up[w - 1] + down[w - 1] - 3.0 * row[w - 1]);
}

/// Streams the ambient mean row by row: `col_sum[x]` holds the sum of `prev` over the rows of the
/// window of the current row; each new row adds one row and drops one.
struct AmbientRows {
    radius: usize,
    width: usize,
    height: usize,
    col_sum: Vec<f64>,
    prefix: Vec<f64>,
    ambient: Vec<f32>,
    active: bool,
}

impl AmbientRows {
    fn new(plan: PlanePlan, width: usize, height: usize, prev: &[f32], scratch: &mut Scratch) -> Self {
        let (active, radius) = match plan {
            PlanePlan::Ambient {
                alpha, radius_cells, ..
            } => (alpha > 0.0, radius_cells as usize),
            _ => (false, 0),
        };
        let mut s = Self {
            radius,
            width,
            height,
            col_sum: std::mem::take(&mut scratch.col_sum),
            prefix: std::mem::take(&mut scratch.prefix),
            ambient: std::mem::take(&mut scratch.ambient),
            active,
        };
        s.ambient.clear();
        s.ambient.resize(width, 0.0);
        if active {
            s.col_sum.clear();
            s.col_sum.resize(width, 0.0);
            s.prefix.clear();
            s.prefix.resize(width + 1, 0.0);
            // Rows 0..=r-1 enter before row 0; row(y) adds row y+r.
            for y in 0..radius.min(height) {
                add_row(&mut s.col_sum, &prev[y * width..(y + 1) * width], 1.0);
            }
        }
        s
    }

    /// The ambient mean of every cell of row `y`; rows must be asked for in order 0, 1, 2, ….
    fn row(&mut self, y: usize, prev: &[f32]) -> &[f32] {
        if !self.active {
            return &self.ambient;
        }
        let (w, r) = (self.width, self.radius);
        if y + r < self.height {
            add_row(&mut self.col_sum, &prev[(y + r) * w..(y + r + 1) * w], 1.0);
        }
        if y > r {
            let out = y - r - 1;
            add_row(&mut self.col_sum, &prev[out * w..(out + 1) * w], -1.0);
        }
        let rows_in = (y + r).min(self.height - 1) - y.saturating_sub(r) + 1;
        prefix_sum(&self.col_sum, &mut self.prefix);
        for x in 0..w {
            let x0 = x.saturating_sub(r);
            let x1 = (x + r + 1).min(w);
            let n = ((x1 - x0) * rows_in) as f64;
            self.ambient[x] = ((self.prefix[x1] - self.prefix[x0]) / n) as f32;
        }
        &self.ambient
    }

    fn finish(self, scratch: &mut Scratch) {
        scratch.col_sum = self.col_sum;
        scratch.prefix = self.prefix;
        scratch.ambient = self.ambient;
    }
}

#[inline]
fn add_row(col_sum: &mut [f64], row: &[f32], sign: f64) {
    for (c, &v) in col_sum.iter_mut().zip(row) {
        *c += sign * v as f64;
    }
}

/// `prefix[i] = Σ col[..i]`, with four independent chains so the adds overlap.
fn prefix_sum(col: &[f64], prefix: &mut [f64]) {
    let n = col.len();
    prefix[0] = 0.0;
    let q = n / 4;
    if q == 0 {
        for i in 0..n {
            prefix[i + 1] = prefix[i] + col[i];
        }
        return;
    }
    let mut acc = [0.0f64; 4];
    // Local prefix sums of four quarters, interleaved.
    for i in 0..q {
        for (k, a) in acc.iter_mut().enumerate() {
            *a += col[k * q + i];
            prefix[k * q + i + 1] = *a;
        }
    }
    // Remainder belongs to the last quarter.
    for i in 4 * q..n {
        acc[3] += col[i];
        prefix[i + 1] = acc[3];
    }
    // Offset quarters 1..3 by the totals before them.
    let mut offset = acc[0];
    for k in 1..4 {
        let end = if k == 3 { n } else { (k + 1) * q };
        for p in &mut prefix[k * q + 1..=end] {
            *p += offset;
        }
        offset += acc[k];
    }
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
