//! Why a deposit is refused ([`RejectReason`], [`Rejection`]): shared by the validation
//! (`crate::deposit`) and the frame header's counters (`crate::messages`). A leaf: it imports
//! nothing of the crate.

use std::fmt;

/// Why a deposit was refused. The discriminant is the index of its counter in the frame header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum RejectReason {
    /// A position, amount, covariance or parameter is NaN or infinite.
    NonFinite = 0,
    /// The position covariance is not symmetric positive semi-definite.
    NotPsd = 1,
    /// The channel index names no channel of this field.
    UnknownChannel = 2,
    /// The kernel code is not one this build knows.
    UnknownKernel = 3,
    /// An amount, range or shape parameter is out of the accepted limits.
    OutOfLimits = 4,
    /// The kernel's extent does not reach any cell of the grid.
    OutsideGrid = 5,
    /// A negative amount on a channel that is not signed.
    NegativeOnUnsigned = 6,
}

/// Number of rejection reasons (length of the counters array in the frame header).
pub const REJECT_REASONS: usize = 7;

impl RejectReason {
    /// Every reason, in discriminant order (the order of the frame header's counters).
    pub const ALL: [RejectReason; REJECT_REASONS] = [
        RejectReason::NonFinite,
        RejectReason::NotPsd,
        RejectReason::UnknownChannel,
        RejectReason::UnknownKernel,
        RejectReason::OutOfLimits,
        RejectReason::OutsideGrid,
        RejectReason::NegativeOnUnsigned,
    ];

    /// Stable snake_case name, used in logs and JSON.
    pub fn name(self) -> &'static str {
        match self {
            RejectReason::NonFinite => "non_finite",
            RejectReason::NotPsd => "not_psd",
            RejectReason::UnknownChannel => "unknown_channel",
            RejectReason::UnknownKernel => "unknown_kernel",
            RejectReason::OutOfLimits => "out_of_limits",
            RejectReason::OutsideGrid => "outside_grid",
            RejectReason::NegativeOnUnsigned => "negative_on_unsigned",
        }
    }
}

/// A refused deposit: the reason and what was wrong, naming the field and value.
#[derive(Debug, Clone, PartialEq)]
pub struct Rejection {
    /// Which rule the deposit broke; counted in the frame header under its code.
    pub reason: RejectReason,
    /// Human-readable specifics: the offending message field and value, and the limit.
    pub detail: String,
}

impl fmt::Display for Rejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "deposit rejected ({}): {}",
            self.reason.name(),
            self.detail
        )
    }
}

impl std::error::Error for Rejection {}
