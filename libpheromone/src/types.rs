//! The types of the C ABI (`pheromone.h`): `#[repr(C)]`, plain numbers and pointers. Values that
//! come from C and select something (a wait kind, a kernel) are `u32` fields checked by the
//! library, never Rust enums (a C caller can pass any number).

/// The layout version of the field's shared-memory types this library speaks
/// (`pheromone_field::wire::LAYOUT_VERSION`). Pass it in `PheromoneAttachOptions::layout_version`: a program
/// compiled against another `pheromone.h` is refused at attach, and a field of another layout
/// refuses this library.
pub const PHEROMONE_LAYOUT_VERSION: u32 = 1;
const _: () = assert!(
    PHEROMONE_LAYOUT_VERSION == pheromone_field::wire::LAYOUT_VERSION,
    "PHEROMONE_LAYOUT_VERSION must follow pheromone_field::wire::LAYOUT_VERSION"
);

/// The version of this library and of the `pheromone.h` it ships with (the crate's version;
/// `libpheromone.so.MAJOR` is its SONAME).
pub const PHEROMONE_VERSION_MAJOR: u32 = 0;
pub const PHEROMONE_VERSION_MINOR: u32 = 1;
pub const PHEROMONE_VERSION_PATCH: u32 = 0;

/// A decimal number at compile time (the crate's version parts).
const fn decimal(s: &str) -> u32 {
    let b = s.as_bytes();
    let mut i = 0;
    let mut v = 0;
    while i < b.len() {
        v = v * 10 + (b[i] - b'0') as u32;
        i += 1;
    }
    v
}
const _: () = assert!(
    PHEROMONE_VERSION_MAJOR == decimal(env!("CARGO_PKG_VERSION_MAJOR"))
        && PHEROMONE_VERSION_MINOR == decimal(env!("CARGO_PKG_VERSION_MINOR"))
        && PHEROMONE_VERSION_PATCH == decimal(env!("CARGO_PKG_VERSION_PATCH")),
    "PHEROMONE_VERSION_* must follow the crate's version"
);

/// Most channels a field has (`FieldConfig`): the length of `PheromoneFrameView::planes`.
pub const PHEROMONE_MAX_CHANNELS: usize = 64;

/// Bytes of the per-thread last-error message, its terminating NUL included.
pub const PHEROMONE_ERROR_CAPACITY: usize = 512;

/// What every call returns.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PheromoneStatus {
    /// Done.
    Ok = 0,
    /// `pheromone_wait_frame`: no newer frame came within the timeout (not an error; the last
    /// error is not set).
    Timeout = 1,
    /// No field of that name is running.
    NoField = 2,
    /// An argument is invalid (a null pointer, a bad name, a non-finite number, a channel the
    /// field does not have, a covariance that is not symmetric positive semi-definite…); the
    /// last error names it and its value.
    BadArgument = 3,
    /// The field, or the program's `pheromone.h`, speaks another layout version.
    Layout = 4,
    /// No frame is held (borrow before the first frame came) or borrowed (sampling before
    /// `pheromone_frame_borrow`).
    NoFrame = 5,
    /// A frame is borrowed: release it before waiting for the next one or detaching.
    Borrowed = 6,
    /// A deposit was not delivered: no field took it (not running, or its queue is full).
    NotDelivered = 7,
    /// Shared memory (iceoryx2) failed; the last error says where.
    ShmError = 8,
    /// A bug in the library was caught at the boundary (a Rust panic); the handle should be
    /// detached.
    Internal = 9,
    /// `pheromone_deposit_confirmed`: the field refused the deposit (by its own checks, e.g.
    /// outside its grid); the receipt's `reason` and the last error say why. Nothing was applied.
    Rejected = 10,
    /// A signal the program handles cut a blocking call short: `pheromone_wait_frame` sleeping on
    /// the frame event, `pheromone_deposit_confirmed` waiting for its receipt (the deposit may
    /// still be applied, once), `pheromone_field_attach` between retries. The program's handler
    /// ran; the library installs, replaces and consumes no signal handler. Call again to go on
    /// waiting. Rarely, a signal the program ignores also cuts a wait short (a child's SIGCHLD
    /// queued while the thread that forked it blocked every signal): the same status, no handler
    /// ran.
    Interrupted = 11,
    /// `pheromone_field_attach`: the field's services exist (another process attached to them
    /// holds them) but no live process publishes its frames: its field process died (and no
    /// standby took over) within `attach_timeout_ns`. Restart the field; a handle attached before
    /// it died keeps its last frame and receives the frames of a field restarted under the name.
    FieldDead = 12,
}

impl PheromoneStatus {
    /// Every status, in the order of their values.
    pub const ALL: [Self; 13] = [
        Self::Ok,
        Self::Timeout,
        Self::NoField,
        Self::BadArgument,
        Self::Layout,
        Self::NoFrame,
        Self::Borrowed,
        Self::NotDelivered,
        Self::ShmError,
        Self::Internal,
        Self::Rejected,
        Self::Interrupted,
        Self::FieldDead,
    ];

    /// What `pheromone_status_str` says of it.
    pub fn description(self) -> &'static core::ffi::CStr {
        match self {
            Self::Ok => c"ok",
            Self::Timeout => c"timeout: nothing came within the timeout",
            Self::NoField => c"no field of that name is running",
            Self::BadArgument => c"invalid argument",
            Self::Layout => c"another layout version",
            Self::NoFrame => c"no frame held or borrowed",
            Self::Borrowed => c"a frame is borrowed",
            Self::NotDelivered => c"deposit not delivered",
            Self::ShmError => c"shared memory (iceoryx2) failed",
            Self::Internal => c"internal error (a bug in libpheromone)",
            Self::Rejected => c"the field refused the deposit",
            Self::Interrupted => c"interrupted by a signal",
            Self::FieldDead => c"the field's process is gone",
        }
    }
}

/// `pheromone_set_log_level`: iceoryx2's log levels, most verbose first.
pub const PHEROMONE_LOG_TRACE: u32 = 0;
pub const PHEROMONE_LOG_DEBUG: u32 = 1;
pub const PHEROMONE_LOG_INFO: u32 = 2;
pub const PHEROMONE_LOG_WARN: u32 = 3;
pub const PHEROMONE_LOG_ERROR: u32 = 4;
pub const PHEROMONE_LOG_FATAL: u32 = 5;

/// `PheromoneReceipt::status`: the deposit is in frame `sequence`.
pub const PHEROMONE_RECEIPT_APPLIED: u32 = 0;
/// `PheromoneReceipt::status`: the field refused it in frame `sequence`, for `reason`.
pub const PHEROMONE_RECEIPT_REJECTED: u32 = 1;
/// `PheromoneReceipt::status`: the field is a mirror; it forwarded the deposit to its origin,
/// which applies or refuses it there.
pub const PHEROMONE_RECEIPT_FORWARDED: u32 = 3;

/// The field's answer to `pheromone_deposit_confirmed` (its `DepositReceipt`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PheromoneReceipt {
    /// The frame that applied (or refused) the deposit; 0 when forwarded.
    pub sequence: u64,
    /// `PHEROMONE_RECEIPT_APPLIED`, `_REJECTED` or `_FORWARDED`.
    pub status: u32,
    /// With `PHEROMONE_RECEIPT_REJECTED`, the field's reason code (the index of its counter in
    /// the frame header: 0 non-finite, 1 covariance not PSD, 2 unknown channel, 3 unknown
    /// kernel, 4 out of limits, 5 outside the grid, 6 negative on an unsigned channel); else 0.
    pub reason: u32,
}

/// Whether the field is alive and which of its processes the handle reads
/// (`pheromone_field_liveness`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PheromoneLiveness {
    /// 1 while a live process publishes the field's frames; 0 once that process died (a scan
    /// of the host's iceoryx2 nodes: ask when frames stop coming, not per frame).
    pub alive: u32,
    /// Reserved: 0.
    pub reserved: u32,
    /// How many field processes the handle has taken frames from: 1 after its first frame, one
    /// more each time a restarted field (or a standby that took over) publishes under the name.
    /// A change means the field's state may have been reset and its sequence numbers restarted.
    pub generation: u64,
    /// The sequence number of the newest frame the handle holds (a field's first frame is 0;
    /// 0 also while the handle holds none).
    pub sequence: u64,
}

/// `PheromoneWaitPolicy::kind`: sleep on the frame event until the field notifies.
pub const PHEROMONE_WAIT_EVENT: u32 = 0;
/// `PheromoneWaitPolicy::kind`: poll for `spin_ns`, then sleep on the event.
pub const PHEROMONE_WAIT_SPIN: u32 = 1;
/// `PheromoneWaitPolicy::kind`: poll until the frame comes (one core at 100 %).
pub const PHEROMONE_WAIT_BUSY_POLL: u32 = 2;

/// How `pheromone_wait_frame` waits (Rust's `pheromone_field::shm::WaitPolicy`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PheromoneWaitPolicy {
    /// `PHEROMONE_WAIT_EVENT`, `PHEROMONE_WAIT_SPIN` or `PHEROMONE_WAIT_BUSY_POLL`.
    pub kind: u32,
    /// `PHEROMONE_WAIT_SPIN`: how long to poll before sleeping (ns, 1 ns to 1 s).
    pub spin_ns: u64,
}

/// Options of `pheromone_field_attach`; start from `pheromone_attach_options_init`.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct PheromoneAttachOptions {
    /// `PHEROMONE_LAYOUT_VERSION` of the `pheromone.h` the program was compiled with.
    pub layout_version: u32,
    /// Robot id stamped on this handle's deposits.
    pub robot_id: u32,
    /// Non-zero: create a deposit publisher (the field counts it among its depositors); zero: a
    /// read-only handle, whose `pheromone_deposit` fails.
    pub deposits: u32,
    /// Keep retrying while the field does not exist yet, this long (ns); 0: try once.
    pub attach_timeout_ns: u64,
    /// The iceoryx2 domain (`pheromone --iox-domain`). NULL: the `PHEROMONE_IOX_DOMAIN`
    /// environment variable if it is set and not empty, else iceoryx2's default domain. `""`:
    /// iceoryx2's default domain, whatever the environment says. Otherwise 1–64 characters of
    /// `A–Z a–z 0–9 _ -`.
    pub iox_domain: *const core::ffi::c_char,
}

impl Default for PheromoneAttachOptions {
    fn default() -> Self {
        Self {
            layout_version: PHEROMONE_LAYOUT_VERSION,
            robot_id: 0,
            deposits: 1,
            attach_timeout_ns: 0,
            iox_domain: std::ptr::null(),
        }
    }
}

/// A borrowed frame: a copy of its header's numbers and a pointer per channel into the shared
/// memory the field published it in (no copy). Valid until `pheromone_frame_release`.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct PheromoneFrameView {
    /// Frame number, +1 per tick.
    pub sequence: u64,
    /// CLOCK_MONOTONIC (ns) when the field published the frame.
    pub stamp_ns: u64,
    /// Field time at this frame (s).
    pub sim_time_s: f64,
    pub channels: u32,
    pub width: u32,
    pub height: u32,
    pub cell_size_m: f32,
    /// World position of the grid's lower-left corner (m).
    pub origin_x_m: f32,
    pub origin_y_m: f32,
    /// The field's tick period (s).
    pub dt_s: f32,
    /// The layout version written in the frame.
    pub layout_version: u32,
    /// Deposits applied and rejected since the field started.
    pub deposits_applied: u64,
    pub deposits_rejected: u64,
    /// Cells per plane (`width * height`); cell `(x, y)` of channel `c` is
    /// `planes[c][y * width + x]`, row 0 at the grid's lower edge.
    pub plane_len: usize,
    /// One pointer per channel into shared memory (`channels` of them; the rest are NULL).
    pub planes: [*const f32; PHEROMONE_MAX_CHANNELS],
}

/// A planar pose for sampling: position (m), heading (rad, counter-clockwise from +x).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PheromonePose {
    pub x_m: f32,
    pub y_m: f32,
    pub theta_rad: f32,
}

/// `PheromoneDeposit::kernel`: seed 000's ellipse γ·exp(−½ dᵀΣ⁻¹d), cut at `range_m`.
pub const PHEROMONE_KERNEL_ELLIPSE: u32 = 0;
/// `PheromoneDeposit::kernel`: seed 000 eq. 14 as printed.
pub const PHEROMONE_KERNEL_PAPER: u32 = 1;
/// `PheromoneDeposit::kernel`: seeds 001/004 saturating (1 − ξ)·ρ·exp(−d²/λ²).
pub const PHEROMONE_KERNEL_SATURATING: u32 = 2;
/// `PheromoneDeposit::kernel`: seed 002's Z-shape.
pub const PHEROMONE_KERNEL_Z_SHAPE: u32 = 3;

/// One deposit, as `pheromone deposit` sends it (the field's `DepositMsg` without stamp and
/// robot id, which the library fills in). Parameters the kernel does not use must be finite.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PheromoneDeposit {
    pub channel: u32,
    /// `PHEROMONE_KERNEL_*`.
    pub kernel: u32,
    /// Centre (m).
    pub x_m: f32,
    pub y_m: f32,
    /// τ (ellipse, paper), ρ (saturating) or Q (z-shape); negative: anti-pheromone.
    pub amount: f32,
    /// Position covariance Σxy (m²), ellipse and paper.
    pub cov_xx: f32,
    pub cov_xy: f32,
    pub cov_yy: f32,
    /// Cut-off radius (m): ellipse, paper, saturating.
    pub range_m: f32,
    /// γmax: ellipse, paper.
    pub gamma_max: f32,
    /// λ (m): saturating.
    pub sigma_m: f32,
    /// Plateau c and slope σ (m): z-shape.
    pub plateau_m: f32,
    pub slope_m: f32,
}

/// A pose estimate for `pheromone_deposit_pose`: mean (m, rad) and its 3×3 covariance
/// (row-major, order x, y, θ), as a localizer publishes it.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PheromonePoseEstimate {
    pub x_m: f64,
    pub y_m: f64,
    pub theta_rad: f64,
    pub cov: [f64; 9],
}

/// Seed 000's uncertainty-aware deposit settings (the depositor's `[depositor]` keys of the
/// same names); start from `pheromone_ellipse_params_init`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PheromoneEllipseParams {
    pub channel: u32,
    /// Non-zero: deposit anti-pheromone (a negative amount).
    pub anti_pheromone: u32,
    /// `PHEROMONE_KERNEL_ELLIPSE` or `PHEROMONE_KERNEL_PAPER`.
    pub kernel: u32,
    /// τ (pheromone·m⁴): γ = τ / det Σxy, capped at `gamma_max`. Default 0.2.
    pub tau: f32,
    /// Default 100.
    pub gamma_max: f32,
    /// Sensor range z_rng (m). Default 1.
    pub range_m: f32,
    /// The variances of Σxy are raised to at least this σ² (m); 0 = off (the default).
    pub min_sigma_m: f32,
}

impl Default for PheromoneEllipseParams {
    fn default() -> Self {
        // pheromone_field::kernel::defaults, as pheromone_roles::depositor::DepositorConfig.
        Self {
            channel: 0,
            anti_pheromone: 0,
            kernel: PHEROMONE_KERNEL_ELLIPSE,
            tau: pheromone_field::kernel::defaults::TAU,
            gamma_max: pheromone_field::kernel::defaults::GAMMA_MAX,
            range_m: pheromone_field::kernel::defaults::RANGE_M,
            min_sigma_m: 0.0,
        }
    }
}
