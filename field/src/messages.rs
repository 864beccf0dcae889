//! The field's shared-memory message types: fixed-size `#[repr(C)]`, `ZeroCopySend`, no heap
//! pointers. Their iceoryx2 type names carry a layout version, so a client built against another
//! layout is refused when it opens the service instead of reading garbage.

use crate::reject::REJECT_REASONS;

pub use crate::wire::LAYOUT_VERSION;

/// Deposit kernel codes on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum KernelKind {
    /// Seed 000, project default: γ·exp(−½ dᵀΣxy⁻¹d), cut at z_rng.
    Ellipse = 0,
    /// Seed 000 eq. 14 as printed: γ·exp(−(u²/λ1² + v²/λ2²)), cut at z_rng.
    Paper = 1,
    /// Seeds 001/004 eq. 3: (1 − ξ)·ρt·exp(−d²/λ²), cut at z_rng, saturates at ±1.
    Saturating = 2,
    /// Seed 002 eq. 1: Q·μ(d), the Z-shape.
    ZShape = 3,
}

impl KernelKind {
    /// The kernel whose wire code (as in [`DepositMsg::kernel`]) is `code`; `None` for an
    /// unknown code.
    pub fn from_code(code: u32) -> Option<Self> {
        Some(match code {
            0 => KernelKind::Ellipse,
            1 => KernelKind::Paper,
            2 => KernelKind::Saturating,
            3 => KernelKind::ZShape,
            _ => return None,
        })
    }

    /// The kernel's name in configuration and on the command line (parsed back by `FromStr`).
    pub fn name(self) -> &'static str {
        match self {
            KernelKind::Ellipse => "ellipse",
            KernelKind::Paper => "paper",
            KernelKind::Saturating => "saturating",
            KernelKind::ZShape => "z-shape",
        }
    }
}

/// A kernel name that is none of `KernelKind`'s.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown kernel '{0}' (expected ellipse, paper, saturating or z-shape)")]
pub struct UnknownKernel(pub String);

impl std::str::FromStr for KernelKind {
    type Err = UnknownKernel;
    fn from_str(s: &str) -> Result<Self, UnknownKernel> {
        [
            KernelKind::Ellipse,
            KernelKind::Paper,
            KernelKind::Saturating,
            KernelKind::ZShape,
        ]
        .into_iter()
        .find(|k| k.name() == s)
        .ok_or_else(|| UnknownKernel(s.to_string()))
    }
}

/// One deposit request on the wire. Build it from a typed [`crate::Deposit`] (`deposit.into()`)
/// rather than field by field. Unused parameters of a kernel are ignored but must be finite.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct DepositMsg {
    /// Monotonic stamp (ns, CLOCK_MONOTONIC) when the deposit was made.
    pub stamp_ns: u64,
    /// The depositing robot (set by the publisher or client from its `attach` id); a tick
    /// applies its deposits ordered by robot, `u32::MAX` (scripted deposits) first.
    pub robot_id: u32,
    /// Channel index.
    pub channel: u32,
    /// `KernelKind` code.
    pub kernel: u32,
    /// Centre of the deposit, world metres.
    pub x_m: f32,
    /// y of the deposit's centre, world metres.
    pub y_m: f32,
    /// τ (ellipse, paper), ρt (saturating) or Q (z-shape); negative = anti-pheromone.
    pub amount: f32,
    /// Position covariance Σxy (m²), for ellipse and paper: the x variance.
    pub cov_xx: f32,
    /// The x–y covariance of Σxy (m²); Σxy must be positive semi-definite.
    pub cov_xy: f32,
    /// The y variance of Σxy (m²).
    pub cov_yy: f32,
    /// Cut-off radius z_rng (m), for ellipse, paper and saturating.
    pub range_m: f32,
    /// γmax, for ellipse and paper.
    pub gamma_max: f32,
    /// λ (m), for saturating.
    pub sigma_m: f32,
    /// c and σ (m), for z-shape: radius of the full-value plateau.
    pub plateau_m: f32,
    /// σ (m), for z-shape: width of the linear fall-off beyond the plateau.
    pub slope_m: f32,
}

// repr(C): numbers and arrays of numbers only.
crate::wire_type!(DepositMsg, "DepositMsg", size = 64, align = 8);

/// `DepositMsg::kernel` of a flush request on the confirm service: it deposits nothing, and its
/// receipt (`RECEIPT_FLUSHED`) comes once the field has taken every deposit the same process
/// published before it.
pub const KERNEL_FLUSH: u32 = u32::MAX;

/// [`DepositReceipt::status`]: the deposit is in frame `sequence`.
pub const RECEIPT_APPLIED: u32 = 0;
/// The field refused the deposit; `reason` is the [`crate::RejectReason`] code (the index of
/// its counter in the frame header).
pub const RECEIPT_REJECTED: u32 = 1;
/// A flush request: every deposit published before it is in frame `sequence` or earlier (or was
/// refused and counted there).
pub const RECEIPT_FLUSHED: u32 = 2;
/// A mirror took the deposit and forwards it to its origin, which applies or refuses it there;
/// nothing more is known here.
pub const RECEIPT_FORWARDED: u32 = 3;

/// The field's answer to a deposit sent on `pheromone/F/deposit-confirm` (request-response): sent
/// after the frame that applied it is published, before readers are woken.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(C)]
pub struct DepositReceipt {
    /// The frame that applied (or refused) the deposit.
    pub sequence: u64,
    /// `RECEIPT_APPLIED`, `RECEIPT_REJECTED`, `RECEIPT_FLUSHED` or `RECEIPT_FORWARDED`.
    pub status: u32,
    /// With `RECEIPT_REJECTED`, the reason's code; 0 otherwise.
    pub reason: u32,
}

// repr(C): numbers only.
crate::wire_type!(DepositReceipt, "DepositReceipt", size = 16, align = 8);

/// Header of every published frame. Counters are cumulative since the field started (or was
/// restored).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct FrameHeader {
    /// [`LAYOUT_VERSION`] of the field that wrote the frame.
    pub layout_version: u32,
    /// Channel planes in the frame.
    pub channels: u32,
    /// Grid width in cells (see [`GridGeometry`](crate::geometry::GridGeometry)).
    pub width: u32,
    /// Grid height in cells.
    pub height: u32,
    /// Frame number, +1 per tick.
    pub sequence: u64,
    /// CLOCK_MONOTONIC (ns) when the frame was published.
    pub stamp_ns: u64,
    /// Field time at this frame (s).
    pub sim_time_s: f64,
    /// Side of a square cell (m).
    pub cell_size_m: f32,
    /// World x of the grid's lower-left corner (m).
    pub origin_x_m: f32,
    /// World y of the grid's lower-left corner (m).
    pub origin_y_m: f32,
    /// The regular tick period (s), part of the field's configuration. A field that publishes
    /// on deposit also publishes frames between ticks, each stepped by the real elapsed time:
    /// the step of a frame is the difference of `sim_time_s` to the previous one.
    pub dt_s: f32,
    /// Compute time of the tick that produced this frame (ns).
    pub tick_compute_ns: u64,
    /// Deposits applied so far.
    pub deposits_applied: u64,
    /// Rejected deposits, indexed by `RejectReason as usize`.
    pub deposits_rejected: [u64; REJECT_REASONS],
    /// Deposits this frame added (this tick only).
    pub deposits_this_tick: u32,
    /// Reserved for a later layout; 0.
    pub _reserved: u32,
}

// repr(C): numbers and arrays of numbers only.
crate::wire_type!(
    FrameHeader,
    "FrameHeader",
    size = 80 + 8 * REJECT_REASONS,
    align = 8
);

impl FrameHeader {
    /// Deposits refused so far, all reasons together.
    pub fn deposits_rejected_total(&self) -> u64 {
        self.deposits_rejected.iter().sum()
    }

    /// The grid the frame's planes are laid out on.
    pub fn geometry(&self) -> crate::geometry::GridGeometry {
        crate::geometry::GridGeometry {
            width: self.width,
            height: self.height,
            cell_size_m: self.cell_size_m,
            origin_x_m: self.origin_x_m,
            origin_y_m: self.origin_y_m,
        }
    }

    /// Number of `f32` cells in the frame.
    pub fn len(&self) -> usize {
        self.channels as usize * self.width as usize * self.height as usize
    }

    /// Whether the frame has no cells (no channels, or an empty grid).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// What a mirror says about itself (blackboard `pheromone/F/mirror`, key 0), so readers on its
/// host can tell a live copy from one whose origin went silent: the frames of a stale mirror
/// stay at `last_sequence` while the origin may have moved on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(C)]
pub struct MirrorState {
    /// 1 while the mirror has no live inputs from its origin (none for `--stale-after-s`, or
    /// none applied since its last keyframe); 0 while it follows the origin.
    pub stale: u32,
    /// Reserved for a later layout; 0.
    pub _reserved: u32,
    /// CLOCK_MONOTONIC (ns) when the newest inputs came from the origin; 0 before any.
    pub last_inputs_ns: u64,
    /// CLOCK_MONOTONIC (ns) when the mirror last went stale; 0 while live.
    pub stale_since_ns: u64,
    /// Times the mirror went stale after following its origin.
    pub stale_periods: u64,
    /// Sequence of the newest frame the mirror published.
    pub last_sequence: u64,
}

// repr(C): numbers only.
crate::wire_type!(MirrorState, "MirrorState", size = 40, align = 8);

/// How well the field keeps its period (blackboard `pheromone/F/timing`, written after every
/// frame), for `pheromone list` and monitors on its host: the run's totals so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(C)]
pub struct FieldTiming {
    /// Frames published by this run.
    pub ticks: u64,
    /// Wall-time ticks that started more than the slack after their deadline.
    pub missed_deadlines: u64,
    /// The latest tick start after its deadline (ns); `u64::MAX` while no tick had a deadline
    /// (a lockstep field, or none yet).
    pub max_lateness_ns: u64,
    /// The longest time between two published frames (ns).
    pub longest_gap_ns: u64,
    /// The longest tick compute (ns).
    pub max_compute_ns: u64,
    /// A tick later than this after its deadline is missed (ns).
    pub slack_ns: u64,
}

// repr(C): numbers only.
crate::wire_type!(FieldTiming, "FieldTiming", size = 48, align = 8);

/// A simulation clock tick: the world publishes one per step; a field run with `--clock` ticks
/// once per message instead of on wall time (lockstep simulation).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct ClockMsg {
    /// CLOCK_MONOTONIC (ns) when the tick was sent.
    pub stamp_ns: u64,
    /// The world step this tick starts (0, 1, …); with `finished`, the number of steps run.
    pub step: u64,
    /// Simulation time at the start of the step (s).
    pub sim_time_s: f64,
    /// Length of a simulation step (s).
    pub dt_s: f64,
    /// 1 when the simulation has ended and listeners should stop.
    pub finished: u32,
    /// Padding for the `#[repr(C)]` layout; 0.
    pub _pad: u32,
}

// repr(C): numbers and arrays of numbers only.
crate::wire_type!(ClockMsg, "ClockMsg", size = 40, align = 8);

/// The inputs of one published frame (service `pheromone/F/inputs`, user header of a
/// `[DepositMsg]` slice holding the deposits the tick applied, in the order applied): what a
/// mirror needs to compute the same frame from the previous one (`Stepper::replay`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct InputsHeader {
    /// Sequence number of the frame these inputs produced (the previous frame is `sequence - 1`).
    pub sequence: u64,
    /// An id of this run of the field process (its start time and pid): a restarted field has
    /// another one, so a mirror knows the sequence started again.
    pub epoch: u64,
    /// CLOCK_MONOTONIC (ns) when the frame was published.
    pub stamp_ns: u64,
    /// Field time before the tick (s).
    pub sim_time_before_s: f64,
    /// Field-time increment of the tick (s): `1 / tick_hz` as f64 for a regular tick.
    pub dt_time_s: f64,
    /// Cumulative counters after the tick (the frame header's).
    pub deposits_applied: u64,
    /// Cumulative refused deposits after the tick, all reasons together.
    pub deposits_rejected_total: u64,
    /// The step's dt (s, f32) as the evaporation and diffusion used it.
    pub dt_s: f32,
    /// Deposits in the slice.
    pub count: u32,
}

// repr(C): numbers only.
crate::wire_type!(InputsHeader, "InputsHeader", size = 64, align = 8);
