//! Every shared-memory contract in one place: the layout version (from which every wire type's
//! iceoryx2 type name is generated), the name of every service and of its `-ready` wake-up
//! companion, and every option that is part of a service's identity (two processes that disagree
//! on one of them cannot share the service).
//!
//! The wire types themselves live beside the code that gives them meaning — the field's in
//! [`crate::messages`] and [`crate::process::lockstep`], the robots' in `messages`, the graph's
//! in `pheromone_graph::shm` — and each is declared with [`wire_type!`](crate::wire_type),
//! which names it `pheromone::<Name>/v<LAYOUT_VERSION>` and pins its size and alignment at
//! compile time: a change to a wire type does not build until its size is restated here, and the
//! layout version bumped below. A client built with another layout is then refused by iceoryx2
//! when it opens the service (the type names differ), instead of reading garbage.
//!
//! Services of field `F`, world `W`, robot `r<ID>` and graph `G`:
//!
//! | service | type | who sends → who receives |
//! | --- | --- | --- |
//! | `pheromone/F/frame` (+ event `pheromone/F/frame-ready`) | `[f32]` + `FrameHeader` | field → readers |
//! | `pheromone/F/deposit` | `DepositMsg` | depositors → field |
//! | `pheromone/F/inputs` | `[DepositMsg]` + `InputsHeader` | field → bridge (mirrors) |
//! | `pheromone/F/config` | `[u8]` (TOML, history 1) | field → bridge (mirrors) |
//! | `sim/W/clock` (+ `-ready`) | `ClockMsg` | world → every role and the field |
//! | `sim/W/step-done` (+ `-ready`) | `StepAck` | every participant → world |
//! | `sim/W/attached` (event) | — | every participant → world |
//! | `sim/W/r<ID>/sensors`, `sim/W/r<ID>/truth` (+ `-ready`) | `SensorMsg`, `TruthMsg` | world → localizer, depositor |
//! | `pheromone/W/r<ID>/pose` (+ `-ready`) | `PoseMsg` | localizer → depositor, follower |
//! | `pheromone/W/r<ID>/cmd`, `…/status` (+ `-ready`) | `CmdMsg`, `FollowerStatusMsg` | follower → world, observers |
//! | `pheromone/G/graph`, `…/graph-update`, `…/contend` (+ `-ready`) | `GraphSnapshot`, `GraphUpdateMsg`, `ContendWire` | graph writer ↔ robots |

pub use iceoryx2::prelude::ZeroCopySend;

/// The layout version as a literal (for `concat!`): **the one place to bump** on any change to
/// any wire type. Everything else derives from it.
#[doc(hidden)]
#[macro_export]
macro_rules! __pheromone_layout_version {
    () => {
        "1"
    };
}

/// Layout version of every wire type; written into frames and checkpoints.
pub const LAYOUT_VERSION: u32 = parse_version(__pheromone_layout_version!());

const fn parse_version(s: &str) -> u32 {
    let b = s.as_bytes();
    assert!(!b.is_empty(), "the layout version is empty");
    let mut i = 0;
    let mut v = 0u32;
    while i < b.len() {
        assert!(b[i].is_ascii_digit(), "the layout version is not a number");
        v = v * 10 + (b[i] - b'0') as u32;
        i += 1;
    }
    v
}

/// The iceoryx2 type name of wire type `Name` in this build's layout:
/// `"pheromone::Name/v<LAYOUT_VERSION>"`.
#[macro_export]
macro_rules! wire_type_name {
    ($name:literal) => {
        concat!(
            "pheromone::",
            $name,
            "/v",
            $crate::__pheromone_layout_version!()
        )
    };
}

/// Declares `$t` a wire type: implements iceoryx2's `ZeroCopySend` with the versioned type name
/// `pheromone::$name/v<LAYOUT_VERSION>`, and asserts at compile time that `$t` is plain data
/// (`Copy + Send + 'static`) of exactly `size` bytes with alignment `align`.
///
/// The caller guarantees that `$t` is `#[repr(C)]` and holds only numbers, arrays of numbers and
/// other wire types (no pointers, no references): every type in this crate and in `publishers`
/// that uses it does, and says so where it is defined.
#[macro_export]
macro_rules! wire_type {
    ($t:ty, $name:literal, size = $size:expr, align = $align:expr) => {
        // Implementing `ZeroCopySend` is `unsafe`: allowed here, where the contract is stated.
        #[allow(unsafe_code)]
        // SAFETY: the caller guarantees `$t` is `#[repr(C)]` plain data (numbers and arrays of
        // them, no pointers or references), so its bytes mean the same in every process that maps
        // them; the asserts below pin its size and alignment, and the type name carries the
        // layout version, so a process built with another layout is refused by iceoryx2.
        unsafe impl $crate::wire::ZeroCopySend for $t {
            unsafe fn type_name() -> &'static str {
                $crate::wire_type_name!($name)
            }
        }
        const _: () = {
            assert!(
                ::core::mem::size_of::<$t>() == $size,
                concat!(
                    "the size of ",
                    stringify!($t),
                    " changed: bump the layout version"
                )
            );
            assert!(
                ::core::mem::align_of::<$t>() == $align,
                concat!(
                    "the alignment of ",
                    stringify!($t),
                    " changed: bump the layout version"
                )
            );
        };
        const _: fn() = $crate::wire::assert_plain_data::<$t>;
    };
}

/// Compiles only for plain data (`Copy + Send + 'static`): [`wire_type!`] names it for each wire
/// type, so a type that holds a reference or a non-`Copy` field is refused at compile time.
#[doc(hidden)]
pub fn assert_plain_data<T: Copy + Send + 'static>() {
    // Nothing to do at run time: the bounds are the check.
}

/// The type name a wire type is registered under (for error messages).
#[allow(unsafe_code)] // iceoryx2's `type_name` is an `unsafe fn`
pub fn type_name_of<T: ZeroCopySend + ?Sized>() -> &'static str {
    // SAFETY: `type_name` only returns a constant string; iceoryx2 marks it unsafe because a
    // wrong name would let incompatible types share a service, which reading it cannot do.
    unsafe { <T as ZeroCopySend>::type_name() }
}

// ---- links (`crate::process::link`) -----------------------------------------------------------------

/// Limits every side of a link ([`crate::process::link`]) agrees on (they are part of the service's identity).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkOptions {
    /// Most senders the service admits at once.
    pub max_publishers: usize,
    /// Most receivers the service admits at once.
    pub max_subscribers: usize,
    /// Messages a subscriber buffers; with `keep_latest` the oldest is overwritten when full.
    pub buffer: usize,
    /// `true`: a full buffer drops its oldest message (state such as poses, where only the newest
    /// matters). `false`: the sender is told the message was not delivered.
    pub keep_latest: bool,
}

impl Default for LinkOptions {
    /// The options of every robot link ([`ROBOT_LINK`]).
    fn default() -> Self {
        ROBOT_LINK
    }
}

// ---- field `F` ------------------------------------------------------------------------------

/// Service names of one field.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldServices {
    /// The frames (`[f32]` + [`FrameHeader`](crate::messages::FrameHeader)), field → readers:
    /// `pheromone/F/frame`.
    pub frame: String,
    /// The event the field notifies after publishing each frame, which wakes readers:
    /// `pheromone/F/frame-ready`.
    pub frame_ready: String,
    /// Fire-and-forget deposits ([`DepositMsg`](crate::messages::DepositMsg)), depositors →
    /// field: `pheromone/F/deposit`.
    pub deposit: String,
    /// Deposits that want an answer (request-response, [`crate::messages::DepositReceipt`]).
    pub deposit_confirm: String,
    /// The event depositors notify after each deposit; created only by a field that publishes
    /// on deposit (`pheromone field --publish-on-deposit-ms`).
    pub deposit_ready: String,
    /// The deposits each frame applied (`[DepositMsg]` + `InputsHeader`), for a bridge.
    pub inputs: String,
    /// The field's configuration as TOML (`[u8]`, history 1), for a bridge.
    pub config: String,
    /// A mirror's state (blackboard, [`crate::messages::MirrorState`]); only mirrors have it.
    pub mirror: String,
    /// The field's tick timing (blackboard, [`crate::messages::FieldTiming`]).
    pub timing: String,
}

impl FieldServices {
    /// The names of field `field` (not checked: see `shm::FieldServices::new`).
    pub fn of(field: &str) -> Self {
        Self {
            frame: format!("pheromone/{field}/frame"),
            frame_ready: format!("pheromone/{field}/frame-ready"),
            deposit: format!("pheromone/{field}/deposit"),
            deposit_confirm: format!("pheromone/{field}/deposit-confirm"),
            deposit_ready: format!("pheromone/{field}/deposit-ready"),
            inputs: format!("pheromone/{field}/inputs"),
            config: format!("pheromone/{field}/config"),
            mirror: format!("pheromone/{field}/mirror"),
            timing: format!("pheromone/{field}/timing"),
        }
    }
}

/// The field `F` of a frame service name `pheromone/F/frame`, if `service` is one (how
/// `pheromone list` finds the fields on a host).
pub fn field_of_frame_service(service: &str) -> Option<&str> {
    let field = service.strip_prefix("pheromone/")?.strip_suffix("/frame")?;
    (!field.is_empty() && !field.contains('/')).then_some(field)
}

/// Inputs lists a subscriber (the bridge) buffers; older ones are dropped (the mirror sees a gap
/// and asks for a keyframe).
pub const INPUTS_SUBSCRIBER_BUFFER: usize = 256;
/// Subscribers (bridges) of the inputs service.
pub const INPUTS_SUBSCRIBERS: usize = 4;
/// Subscribers of the config service: bridges, gateways and every `deposit` command (which
/// checks its deposit against the channels while it waits for its receipt). With the inputs'
/// 4, five waiting deposits kept a bridge from starting (issue 54); one per default depositor
/// slot, readers and bridges, each a 1-sample buffer and history.
pub const CONFIG_SUBSCRIBERS: usize = 128;

/// Most confirmed deposits one client may have waiting for their receipts.
pub const CONFIRM_ACTIVE_REQUESTS: usize = 4;
/// Servers of the confirm service: the field, and a standby taking over.
pub const CONFIRM_SERVERS: usize = 2;

/// Frames each subscriber buffers (a reader only ever wants the newest).
pub const FRAME_SUBSCRIBER_BUFFER: usize = 1;
/// Frames a late subscriber receives on connect.
pub const FRAME_HISTORY: usize = 1;
/// Frames one reader may hold at once (the newest and the one it is still reading).
pub const READER_BORROWED_FRAMES: usize = 2;
/// Frame publishers: the field and a standby taking over.
pub const FRAME_PUBLISHERS: usize = 2;
/// Nodes of the frame service beyond the readers': the field, a standby and a spare, plus one
/// (iceoryx2's default admits 20 nodes whatever the readers).
pub const FRAME_EXTRA_NODES: usize = 4;
/// Listeners of `frame-ready`: every reader and every deposit publisher (which waits for frames
/// to flush).
pub const FRAME_READY_LISTENERS: usize = 1024;
/// Notifiers of `frame-ready`: the field and a standby, with spares.
pub const FRAME_READY_NOTIFIERS: usize = 4;
/// Deposit subscribers: the field and a standby.
pub const DEPOSIT_SUBSCRIBERS: usize = 2;
/// Deposits a subscriber (the field, a standby) receives from before it connected: none (a
/// deposit counts once).
pub const DEPOSIT_HISTORY: usize = 0;

/// Listeners of `deposit-ready`: the field and a standby.
pub const DEPOSIT_READY_LISTENERS: usize = 2;
/// Notifiers of `deposit-ready` beyond the field's `max_depositors` (a gateway, spares).
pub const DEPOSIT_READY_EXTRA_NOTIFIERS: usize = 4;

// ---- world `W` (lockstep runs) --------------------------------------------------------------

/// Most processes one run may have: the limit of the clock, step-done and attach services.
/// A scenario's 256 robots (`MAX_ROBOTS`) with four roles each, the field, the world and the
/// observer fit (issue 52: 512 refused every run above ~170 robots).
pub const MAX_PARTICIPANTS: usize = 1040;

/// The clock: one sender (and a spare), every participant a receiver; nothing is overwritten.
/// In lockstep a receiver is a step or two behind at most; on wall time (`--realtime`) the buffer
/// holds 128 steps (12.8 s at 10 Hz) for a receiver that falls behind. Not more: iceoryx2 sizes
/// the sender's memory and every receiver's connection by `max_subscribers` × buffer samples
/// (with 1024, 1.07 M samples, which the world initialised for each of the N participants'
/// connections at start-up: issue 52).
pub const CLOCK_LINK: LinkOptions = LinkOptions {
    max_publishers: 2,
    max_subscribers: MAX_PARTICIPANTS,
    buffer: 128,
    keep_latest: false,
};

/// Step acknowledgements: every participant a sender, the conductor the receiver. One step's
/// acknowledgements of every participant fit in the buffer.
pub const ACK_LINK: LinkOptions = LinkOptions {
    max_publishers: MAX_PARTICIPANTS,
    max_subscribers: 2,
    buffer: MAX_PARTICIPANTS,
    keep_latest: false,
};

/// Service names of a simulation clock `W`: messages and their wake-up event.
pub fn clock_services(world: &str) -> (String, String) {
    (
        format!("sim/{world}/clock"),
        format!("sim/{world}/clock-ready"),
    )
}

/// Service names of world `W`'s step acknowledgements and their wake-up event.
pub fn step_done_services(world: &str) -> (String, String) {
    (
        format!("sim/{world}/step-done"),
        format!("sim/{world}/step-done-ready"),
    )
}

/// The event a participant notifies when it has joined world `W`.
pub fn attached_service(world: &str) -> String {
    format!("sim/{world}/attached")
}

// ---- robot `r<ID>` of world `W` -------------------------------------------------------------

/// Every robot link (sensors, truth, pose, command, status): a few senders, every role and
/// observer of the robot a receiver, the newest message wins.
pub const ROBOT_LINK: LinkOptions = LinkOptions {
    max_publishers: 8,
    // The world's clock is watched by the field and by every role of every robot (three
    // per robot): 16 admitted at most five robots.
    max_subscribers: 64,
    buffer: 64,
    keep_latest: true,
};

/// Service names of one robot. Robots are named `r<ID>` within their world, so several
/// simulations (or test runs) on one host never share a service.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RobotServices {
    /// Odometry and landmark observations (`SensorMsg`, world → localizer, depositor):
    /// `sim/W/r<ID>/sensors`.
    pub sensors: String,
    /// The true pose (`TruthMsg`, world → observers): `sim/W/r<ID>/truth`.
    pub truth: String,
    /// The pose estimate (`PoseMsg`, localizer → depositor, follower): `pheromone/W/r<ID>/pose`.
    pub pose: String,
    /// Motion commands (`CmdMsg`, follower → world): `pheromone/W/r<ID>/cmd`.
    pub cmd: String,
    /// Follower status (`FollowerStatusMsg`, follower → observers): `pheromone/W/r<ID>/status`.
    pub status: String,
    /// Seed 004's range scan (`ScanMsg`, world → observer), when the scenario maps:
    /// `sim/W/r<ID>/scan`.
    pub scan: String,
    /// Seed 004's rendezvous measurement (`RendezvousMsg`, world → observer), when the
    /// scenario maps: `sim/W/r<ID>/rendezvous`.
    pub rendezvous: String,
    /// Seed 000's laser range scan (world → localizer), when the world has a laser.
    pub laser: String,
}

impl RobotServices {
    /// The names of robot `robot` in world `world` (not checked).
    pub fn new(world: &str, robot: u32) -> Self {
        Self {
            sensors: format!("sim/{world}/r{robot}/sensors"),
            truth: format!("sim/{world}/r{robot}/truth"),
            pose: format!("pheromone/{world}/r{robot}/pose"),
            cmd: format!("pheromone/{world}/r{robot}/cmd"),
            status: format!("pheromone/{world}/r{robot}/status"),
            scan: format!("sim/{world}/r{robot}/scan"),
            rendezvous: format!("sim/{world}/r{robot}/rendezvous"),
            laser: format!("sim/{world}/r{robot}/laser"),
        }
    }
}

/// The field under which robot `robot`'s mapper (`pheromone mapper`) publishes its local map in
/// world `world`: `<world>-map-r<ID>`, a field of two channels (occupancy log-odds, pheromone)
/// in the robot's own frame (origin = its start pose), one frame per world step (its sequence =
/// the step). Every field reader reads it (`pheromone probe --field <world>-map-r<ID>`).
pub fn map_field(world: &str, robot: u32) -> String {
    format!("{world}-map-r{robot}")
}

/// The wake-up event of the link `service`.
pub fn ready_service(service: &str) -> String {
    format!("{service}-ready")
}

// ---- graph `G` ------------------------------------------------------------------------------

/// Service names of graph `name`: (snapshots, updates, contention), each with its `-ready`.
pub fn graph_services(name: &str) -> [(String, String); 3] {
    ["graph", "graph-update", "contend"].map(|s| {
        let service = format!("pheromone/{name}/{s}");
        let ready = ready_service(&service);
        (service, ready)
    })
}

/// Graph snapshots: one writer, every robot a reader, the newest wins.
pub const GRAPH_SNAPSHOT_LINK: LinkOptions = LinkOptions {
    max_publishers: 1,
    max_subscribers: 32,
    buffer: 2,
    keep_latest: true,
};

/// Graph updates: every robot a sender, the writer the receiver; nothing is overwritten.
pub const GRAPH_UPDATE_LINK: LinkOptions = LinkOptions {
    max_publishers: 32,
    max_subscribers: 1,
    buffer: 256,
    keep_latest: false,
};

/// Contention messages between robots (seed 001, Listing 1): everyone to everyone.
pub const GRAPH_CONTEND_LINK: LinkOptions = LinkOptions {
    max_publishers: 32,
    max_subscribers: 32,
    buffer: 64,
    keep_latest: false,
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::{ClockMsg, DepositMsg, FrameHeader};

    #[test]
    fn type_names_carry_the_layout_version() {
        let v = format!("/v{LAYOUT_VERSION}");
        for name in [
            type_name_of::<DepositMsg>(),
            type_name_of::<FrameHeader>(),
            type_name_of::<ClockMsg>(),
            type_name_of::<crate::process::lockstep::StepAck>(),
        ] {
            assert!(name.starts_with("pheromone::"), "{name}");
            assert!(name.ends_with(&v), "{name} does not end with {v}");
        }
        assert_eq!(type_name_of::<DepositMsg>(), wire_type_name!("DepositMsg"));
    }

    #[test]
    fn every_service_has_its_ready_companion_and_names_differ_per_robot_and_world() {
        let a = RobotServices::new("w", 0);
        let b = RobotServices::new("w", 1);
        let c = RobotServices::new("v", 0);
        assert_ne!(a, b);
        assert_ne!(a, c);
        assert_eq!(ready_service(&a.pose), "pheromone/w/r0/pose-ready");
        assert_eq!(ready_service(&a.scan), "sim/w/r0/scan-ready");
        assert_ne!(a.rendezvous, b.rendezvous);
        let f = FieldServices::of("f");
        assert_eq!(f.frame_ready, ready_service(&f.frame));
        assert_eq!(field_of_frame_service(&f.frame), Some("f"));
        for other in [
            &f.frame_ready,
            &f.deposit,
            &a.pose,
            "pheromone//frame",
            "x/f/frame",
        ] {
            assert_eq!(field_of_frame_service(other), None, "{other}");
        }
        for (s, r) in graph_services("g") {
            assert_eq!(r, ready_service(&s));
        }
        assert_eq!(clock_services("w").1, ready_service(&clock_services("w").0));
        assert_eq!(
            step_done_services("w").1,
            ready_service(&step_done_services("w").0)
        );
    }
}
