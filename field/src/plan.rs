//! What one tick does to one plane ([`PlanePlan`]): the interface between the models, which
//! compute a plan from a channel's spec (`PlanePlan::for_tick` in `crate::models`), and the
//! plane pass that carries it out (`crate::ambient`). A leaf: it imports nothing of the crate.

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
