//! What one tick does to one plane ([`PlanePlan`]): the interface between the models, which
//! compute a plan from a channel's spec (`PlanePlan::for_tick` in `crate::models`), and the
//! plane pass that carries it out (`crate::ambient`). A leaf: it imports nothing of the crate.

/// What one tick does to one plane, with every per-tick constant already computed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PlanePlan {
    /// P' = P·factor (exponential, saturating, or none with factor 1).
    Scale {
        /// Multiplier applied to every cell, in [0, 1].
        factor: f32,
    },
    /// P' = P·e + (1 − e)·min(P, α·Pa), Pa the mean over a (2r+1)² window.
    Ambient {
        /// e = e^(−K·dt), this tick's exponential decay factor, in [0, 1].
        factor: f32,
        /// α, in [0, 1]: a cell at or below α·Pa keeps its value.
        alpha: f32,
        /// r, the window's half-width in cells (the channel's `radius_m` over the cell size,
        /// rounded).
        radius_cells: u32,
    },
    /// P' = sign(P)·max(|P| − loss, 0).
    Subtract {
        /// Amount taken off every cell's magnitude this tick (≥ 0; a whole number of quanta).
        loss: f32,
    },
}
