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
    Exponential {
        #[serde(alias = "decay_per_sec")]
        decay_per_s: f32,
    },
    /// Seed 000 eq. 17–22 with the MODELS.md M1 decision:
    /// P' = P·e^(−K·dt) + (1 − e^(−K·dt))·min(P, α·Pa), Pa = mean over the square window of
    /// half-width `radius_m` centred on the cell (clipped at the grid's edge).
    Ambient {
        #[serde(alias = "decay_per_sec")]
        decay_per_s: f32,
        #[serde(default = "default_alpha")]
        alpha: f32,
        radius_m: f32,
    },
    /// Seed 001 eqs. 6–7 / seed 004 eqs. 3–6: ξ' = ξ − ρ·ξ per tick; deposits saturate at ±1.
    Saturating { rho_per_tick: f32 },
    /// Seed 002 counter (MODELS.md M3 reading): every whole `tau_s` of field time each cell
    /// loses `quantum`, never crossing zero.
    Quantum {
        quantum: f32,
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
    pub name: String,
    #[serde(default)]
    pub evaporation: Evaporation,
    /// Isotropic diffusion coefficient D (m²/s), explicit 5-point stencil, zero-flux edges.
    #[serde(default)]
    #[serde(alias = "diffusion_m2_per_sec")]
    pub diffusion_m2_per_s: f32,
    /// Signed channels hold pheromone (> 0) and anti-pheromone (< 0).
    #[serde(default)]
    pub signed: bool,
}

impl ChannelSpec {
    pub fn new(name: &str, evaporation: Evaporation) -> Self {
        Self {
            name: name.to_string(),
            evaporation,
            diffusion_m2_per_s: 0.0,
            signed: false,
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
    Ambient {
        factor: f32,
        alpha: f32,
        radius_cells: u32,
    },
    /// P' = sign(P)·max(|P| − loss, 0).
    Subtract { loss: f32 },
}

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

/// Reusable scratch for the ambient mean (O(width), never O(grid)).
#[derive(Debug, Default, Clone)]
pub struct Scratch {
    col_sum: Vec<f64>,
    prefix: Vec<f64>,
    inv_count_x: Vec<f64>,
    inv_count: Vec<f64>,
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
    assert!(width > 0 && prev.len().is_multiple_of(width));
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
            let up = if y > 0 {
                &prev[(y - 1) * width..y * width]
            } else {
                row
            };
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
        // = P·e + (1 − e)·min(P, α·Pa), written so that rounding can never raise the cell:
        // P − (1 − e)·(P − m) with 0 ≤ m ≤ P gives 0 ≤ P' ≤ P in floating point too. (A plain
        // compare-select, not f32::min: cells are finite, and it vectorizes to one minps.)
        let m = alpha * a;
        let m = if m < p { m } else { p };
        *o = p - one_minus * (p - m);
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
/// window of the current row; each new row adds one row and drops one. Along the row, window
/// sums are differences of a prefix sum padded by the radius on both sides, so every cell takes
/// the same branch-free, vectorizable path, edges included.
struct AmbientRows {
    /// Window half-height, capped at the height (a larger one clips to the same window).
    radius_y: usize,
    /// Window half-width, capped at the width.
    radius_x: usize,
    width: usize,
    height: usize,
    col_sum: Vec<f64>,
    /// `prefix[j] = Σ col_sum[..clamp(j − radius_x, 0, width)]`, `width + 2·radius_x + 1` long:
    /// the window sum of cell x is `prefix[x + 2·radius_x + 1] − prefix[x]`.
    prefix: Vec<f64>,
    /// 1 / (cells of the window of column x along the row) — no division per cell.
    inv_count_x: Vec<f64>,
    /// 1 / (cells of the window of column x) for windows of `inv_count_rows` rows: recomputed
    /// only when the row count changes (near the top and bottom edges).
    inv_count: Vec<f64>,
    inv_count_rows: usize,
    ambient: Vec<f32>,
    active: bool,
}

impl AmbientRows {
    fn new(
        plan: PlanePlan,
        width: usize,
        height: usize,
        prev: &[f32],
        scratch: &mut Scratch,
    ) -> Self {
        let (active, radius) = match plan {
            PlanePlan::Ambient {
                alpha,
                radius_cells,
                ..
            } => (alpha > 0.0, radius_cells as usize),
            _ => (false, 0),
        };
        let (radius_x, radius_y) = (radius.min(width), radius.min(height));
        let mut s = Self {
            radius_y,
            radius_x,
            width,
            height,
            col_sum: std::mem::take(&mut scratch.col_sum),
            prefix: std::mem::take(&mut scratch.prefix),
            inv_count_x: std::mem::take(&mut scratch.inv_count_x),
            inv_count: std::mem::take(&mut scratch.inv_count),
            inv_count_rows: 0,
            ambient: std::mem::take(&mut scratch.ambient),
            active,
        };
        s.ambient.clear();
        s.ambient.resize(width, 0.0);
        if active {
            s.col_sum.clear();
            s.col_sum.resize(width, 0.0);
            // The left pad stays 0 (= Σ of nothing); the rest is rewritten every row.
            s.prefix.clear();
            s.prefix.resize(width + 2 * radius_x + 1, 0.0);
            s.inv_count_x.clear();
            s.inv_count_x.extend((0..width).map(|x| {
                1.0 / ((x + radius_x + 1).min(width) - x.saturating_sub(radius_x)) as f64
            }));
            s.inv_count.clear();
            s.inv_count.resize(width, 0.0);
            // Rows 0..=r-1 enter before row 0; row(y) adds row y+r.
            for y in 0..radius_y {
                add_row(&mut s.col_sum, &prev[y * width..(y + 1) * width]);
            }
        }
        s
    }

    /// The ambient mean of every cell of row `y`; rows must be asked for in order 0, 1, 2, ….
    fn row(&mut self, y: usize, prev: &[f32]) -> &[f32] {
        if !self.active {
            return &self.ambient;
        }
        let (w, r, rx) = (self.width, self.radius_y, self.radius_x);
        let row = |i: usize| &prev[i * w..(i + 1) * w];
        match (y + r < self.height, y > r) {
            (true, true) => swap_row(&mut self.col_sum, row(y + r), row(y - r - 1)),
            (true, false) => add_row(&mut self.col_sum, row(y + r)),
            (false, true) => sub_row(&mut self.col_sum, row(y - r - 1)),
            (false, false) => {}
        }
        let rows_in = (y + r).min(self.height - 1) - y.saturating_sub(r) + 1;
        if rows_in != self.inv_count_rows {
            let inv_rows = 1.0 / rows_in as f64;
            for (c, &cx) in self.inv_count.iter_mut().zip(&self.inv_count_x) {
                *c = cx * inv_rows;
            }
            self.inv_count_rows = rows_in;
        }
        prefix_sum(&self.col_sum, &mut self.prefix[rx..=rx + w]);
        let total = self.prefix[rx + w];
        self.prefix[rx + w + 1..].fill(total);
        let span = 2 * rx + 1;
        for (((a, &hi), &lo), &inv) in self
            .ambient
            .iter_mut()
            .zip(&self.prefix[span..])
            .zip(&self.prefix[..w])
            .zip(&self.inv_count)
        {
            // Clamped at 0: the cells are non-negative (the ambient model is unsigned-only), but
            // running sums that add and later drop a large value can end a hair below 0.
            let sum = hi - lo;
            let sum = if sum > 0.0 { sum } else { 0.0 };
            *a = (sum * inv) as f32;
        }
        &self.ambient
    }

    fn finish(self, scratch: &mut Scratch) {
        scratch.col_sum = self.col_sum;
        scratch.prefix = self.prefix;
        scratch.inv_count_x = self.inv_count_x;
        scratch.inv_count = self.inv_count;
        scratch.ambient = self.ambient;
    }
}

#[inline]
fn add_row(col_sum: &mut [f64], row: &[f32]) {
    for (c, &v) in col_sum.iter_mut().zip(row) {
        *c += v as f64;
    }
}

#[inline]
fn sub_row(col_sum: &mut [f64], row: &[f32]) {
    for (c, &v) in col_sum.iter_mut().zip(row) {
        *c -= v as f64;
    }
}

/// One row enters the window and one leaves. The difference of two f32 is exact in f64, so this
/// is one rounding per column instead of two.
#[inline]
fn swap_row(col_sum: &mut [f64], row_in: &[f32], row_out: &[f32]) {
    for ((c, &i), &o) in col_sum.iter_mut().zip(row_in).zip(row_out) {
        *c += i as f64 - o as f64;
    }
}

/// `prefix[i] = Σ col[..i]` (`prefix` is one longer than `col`). The row is cut into four
/// blocks whose local sums run interleaved, so the adds overlap instead of waiting on each other;
/// a second, vectorized pass adds to each block the total of the blocks before it.
fn prefix_sum(col: &[f64], prefix: &mut [f64]) {
    let n = col.len();
    assert_eq!(prefix.len(), n + 1);
    prefix[0] = 0.0;
    let out = &mut prefix[1..];
    let q = n / 4;
    if q < 4 {
        let mut acc = 0.0;
        for (p, &c) in out.iter_mut().zip(col) {
            acc += c;
            *p = acc;
        }
        return;
    }
    // Blocks of q cells; the remainder joins the last block.
    let (c0, rest) = col.split_at(q);
    let (c1, rest) = rest.split_at(q);
    let (c2, c3) = rest.split_at(q);
    let (o0, rest) = out.split_at_mut(q);
    let (o1, rest) = rest.split_at_mut(q);
    let (o2, o3) = rest.split_at_mut(q);
    let (mut a0, mut a1, mut a2, mut a3) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (((((((&x0, &x1), &x2), &x3), p0), p1), p2), p3) in c0
        .iter()
        .zip(c1)
        .zip(c2)
        .zip(&c3[..q])
        .zip(o0.iter_mut())
        .zip(o1.iter_mut())
        .zip(o2.iter_mut())
        .zip(o3[..q].iter_mut())
    {
        a0 += x0;
        a1 += x1;
        a2 += x2;
        a3 += x3;
        *p0 = a0;
        *p1 = a1;
        *p2 = a2;
        *p3 = a3;
    }
    for (p, &c) in o3[q..].iter_mut().zip(&c3[q..]) {
        a3 += c;
        *p = a3;
    }
    for (block, offset) in [(o1, a0), (o2, a0 + a1), (o3, a0 + a1 + a2)] {
        for p in block.iter_mut() {
            *p += offset;
        }
    }
}

/// The running-sum ambient mean of every cell of a `width`-wide plane, over the `(2r+1)²` window
/// around each cell clipped to the grid — the same `AmbientRows` code the tick uses, for tests
/// and tools (compare with `ambient_mean_brute`).
pub fn ambient_mean_plane(prev: &[f32], width: usize, r: usize) -> Vec<f32> {
    assert!(width > 0 && prev.len().is_multiple_of(width));
    let height = prev.len() / width;
    let plan = PlanePlan::Ambient {
        factor: 1.0,
        alpha: 1.0,
        radius_cells: r.min(u32::MAX as usize) as u32,
    };
    let mut scratch = Scratch::default();
    let mut rows = AmbientRows::new(plan, width, height, prev, &mut scratch);
    let mut out = Vec::with_capacity(prev.len());
    for y in 0..height {
        out.extend_from_slice(rows.row(y, prev));
    }
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
