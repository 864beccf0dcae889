//! The field's configuration and the tick engine: validate deposits, then compute the next frame
//! from the previous one (evaporation/diffusion pass, then deposits over their kernel extent).
//!
//! `Stepper` is storage-agnostic: the shared-memory service hands it the previous frame (a
//! received sample) and the next one (a loaned sample); `OwnedField` gives it two owned buffers
//! for tests and single-process runs.

use serde::{Deserialize, Serialize};

use crate::deposit::{
    prepare, DepositLimits, PreparedDeposit, RejectReason, Rejection, REJECT_REASONS,
};
use crate::error::ConfigError;
use crate::geometry::GridGeometry;
use crate::messages::{DepositMsg, FrameHeader, LAYOUT_VERSION};
use crate::models::{step_plane_threads, ChannelSpec, Evaporation, PlanePlan, Scratch};
use crate::sample::FrameView;

/// Largest frame accepted, in bytes (also bounded by the free space of /dev/shm at start).
pub const MAX_FRAME_BYTES: u64 = 4 << 30;

/// Everything that defines a field. Read from TOML (`--config`), unknown keys are errors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FieldConfig {
    /// Grid width in cells (default 512; see [`GridGeometry::width`]).
    #[serde(default = "defaults::width")]
    pub width: u32,
    /// Grid height in cells (default 512).
    #[serde(default = "defaults::width")]
    pub height: u32,
    /// Side of a square cell (m, default 0.05).
    #[serde(default = "defaults::cell_size_m")]
    pub cell_size_m: f32,
    /// World x of the grid's lower-left corner (m, default 0).
    #[serde(default)]
    pub origin_x_m: f32,
    /// World y of the grid's lower-left corner (m, default 0).
    #[serde(default)]
    pub origin_y_m: f32,
    /// Ticks per second; dt = 1 / tick_hz.
    #[serde(default = "defaults::tick_hz")]
    pub tick_hz: f32,
    /// Readers (subscribers) the frame service admits.
    #[serde(default = "defaults::max_readers")]
    pub max_readers: usize,
    /// Deposit publishers the deposit service admits.
    #[serde(default = "defaults::max_depositors")]
    pub max_depositors: usize,
    /// Deposits the field buffers between two ticks; a publisher whose deposit does not fit is told.
    #[serde(default = "defaults::deposit_buffer")]
    pub deposit_buffer: usize,
    /// Limits on what a single deposit may ask for (TOML table `[limits]`).
    #[serde(default)]
    pub limits: DepositLimits,
    /// The channels, in plane order (1 to 64, unique names; TOML `[[channel]]`). Default: one
    /// channel `trail` with the seed 000 ambient model.
    #[serde(default = "defaults::channels", rename = "channel")]
    pub channels: Vec<ChannelSpec>,
}

mod defaults {
    use super::*;
    pub fn width() -> u32 {
        512
    }
    pub fn cell_size_m() -> f32 {
        0.05
    }
    pub fn tick_hz() -> f32 {
        50.0
    }
    pub fn max_readers() -> usize {
        8
    }
    pub fn max_depositors() -> usize {
        64
    }
    pub fn deposit_buffer() -> usize {
        1024
    }
    pub fn channels() -> Vec<ChannelSpec> {
        vec![ChannelSpec::new(
            "trail",
            Evaporation::Ambient {
                decay_per_s: 0.0057,
                alpha: 0.5,
                radius_m: 0.5,
            },
        )]
    }
}

impl Default for FieldConfig {
    fn default() -> Self {
        Self {
            width: defaults::width(),
            height: defaults::width(),
            cell_size_m: defaults::cell_size_m(),
            origin_x_m: 0.0,
            origin_y_m: 0.0,
            tick_hz: defaults::tick_hz(),
            max_readers: defaults::max_readers(),
            max_depositors: defaults::max_depositors(),
            deposit_buffer: defaults::deposit_buffer(),
            limits: DepositLimits::default(),
            channels: defaults::channels(),
        }
    }
}

impl FieldConfig {
    /// The grid these settings describe.
    pub fn geometry(&self) -> GridGeometry {
        GridGeometry {
            width: self.width,
            height: self.height,
            cell_size_m: self.cell_size_m,
            origin_x_m: self.origin_x_m,
            origin_y_m: self.origin_y_m,
        }
    }

    /// The regular tick period (s): `1 / tick_hz`.
    pub fn dt_s(&self) -> f32 {
        1.0 / self.tick_hz
    }

    /// `f32` cells in one frame.
    pub fn frame_len(&self) -> usize {
        self.channels.len() * self.geometry().cells()
    }

    /// Size of one frame's cells in bytes (4 per cell, header not included).
    pub fn frame_bytes(&self) -> u64 {
        self.frame_len() as u64 * 4
    }

    /// Index of the channel called `name`.
    pub fn channel_index(&self, name: &str) -> Option<usize> {
        self.channels.iter().position(|c| c.name == name)
    }

    /// Checks every value; the error names the setting and the value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.geometry().validate()?;
        if !(self.tick_hz.is_finite() && self.tick_hz > 0.0 && self.tick_hz <= 100_000.0) {
            return Err(ConfigError::invalid(
                "tick_hz",
                self.tick_hz,
                "must be within (0, 100000]",
            ));
        }
        if self.channels.is_empty() || self.channels.len() > 64 {
            return Err(ConfigError::invalid(
                "channels",
                self.channels.len(),
                "must be between 1 and 64",
            ));
        }
        for (i, c) in self.channels.iter().enumerate() {
            if c.name.is_empty() || self.channels[..i].iter().any(|o| o.name == c.name) {
                return Err(ConfigError::invalid(
                    "channel name",
                    format!("'{}'", c.name),
                    "must be non-empty and unique",
                ));
            }
            c.validate(self.dt_s(), self.cell_size_m)?;
        }
        for (name, v, max) in [
            ("max_readers", self.max_readers, 1024),
            ("max_depositors", self.max_depositors, 4096),
            ("deposit_buffer", self.deposit_buffer, 1 << 20),
        ] {
            if v == 0 || v > max {
                return Err(ConfigError::invalid(
                    name,
                    v,
                    format!("must be between 1 and {max}"),
                ));
            }
        }
        let l = &self.limits;
        for (name, v) in [
            ("limits.max_abs_amount", l.max_abs_amount),
            ("limits.max_radius_cells", l.max_radius_cells),
            ("limits.max_gamma", l.max_gamma),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(ConfigError::invalid(name, v, "must be finite and > 0"));
            }
        }
        if self.frame_bytes() > MAX_FRAME_BYTES {
            return Err(ConfigError::invalid(
                "frame size",
                format!(
                    "{} bytes ({}×{}×{} channels)",
                    self.frame_bytes(),
                    self.width,
                    self.height,
                    self.channels.len()
                ),
                format!("exceeds the {MAX_FRAME_BYTES}-byte limit"),
            ));
        }
        Ok(())
    }

    /// Parses TOML; errors carry the line/column and the offending key.
    pub fn from_toml(text: &str) -> Result<Self, toml::de::Error> {
        toml::from_str(text)
    }
}

/// Cumulative deposit counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DepositCounters {
    /// Deposits applied to a frame.
    pub applied: u64,
    /// Deposits refused, indexed by `RejectReason as usize`.
    pub rejected: [u64; REJECT_REASONS],
}

impl DepositCounters {
    /// Deposits refused, all reasons together.
    pub fn rejected_total(&self) -> u64 {
        self.rejected.iter().sum()
    }

    /// Counts one refusal for `reason`.
    pub fn count(&mut self, reason: RejectReason) {
        self.rejected[reason as usize] += 1;
    }
}

/// What one tick did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TickReport {
    /// Deposits the tick applied.
    pub deposits_applied: u32,
    /// Sum of the increments the deposits added (cells × value).
    pub mass_added: f64,
}

/// A deposit's place in its tick: deposits of robot id `u32::MAX` (a simulated world's scripted
/// ones) first, then each robot's by id, each robot's in the order offered. The key is unique,
/// so an unstable (allocation-free) sort keeps each robot's order.
fn deposit_order(robot_id: u32, arrival: usize) -> u64 {
    ((robot_id.wrapping_add(1) as u64) << 32) | (arrival as u64 & 0xffff_ffff)
}

/// Most threads a tick may use (`Stepper::set_threads`).
pub const MAX_THREADS: usize = 256;

/// Validates deposits and advances frames. Holds no frame itself.
#[derive(Debug, Clone)]
pub struct Stepper {
    config: FieldConfig,
    geometry: GridGeometry,
    scratch: Scratch,
    /// Threads of the evaporation pass (1: the calling thread only).
    threads: usize,
    /// Validated deposits of the next tick, each with its place in the tick's canonical order.
    pending: Vec<(u64, PreparedDeposit, DepositMsg)>,
    /// The deposits the last step applied, in the order it applied them (`applied`).
    applied: Vec<DepositMsg>,
    /// The last step: field time before it (s), its `dt_s` and its `dt_time_s`.
    last_step: (f64, f32, f64),
    /// Deposits applied and refused since the field started (or resumed).
    pub counters: DepositCounters,
    /// Field time of the last computed frame (s).
    pub sim_time_s: f64,
    /// Sequence number of the last computed frame.
    pub sequence: u64,
}

impl Stepper {
    /// A stepper for `config` at sequence 0 and field time 0, on one thread; fails if the
    /// configuration does not validate ([`FieldConfig::validate`]).
    pub fn new(config: FieldConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        let pending = Vec::with_capacity(config.deposit_buffer);
        Ok(Self {
            geometry: config.geometry(),
            config,
            scratch: Scratch::default(),
            threads: 1,
            pending,
            applied: Vec::new(),
            last_step: (0.0, 0.0, 0.0),
            counters: DepositCounters::default(),
            sim_time_s: 0.0,
            sequence: 0,
        })
    }

    /// The configuration the stepper was made with.
    pub fn config(&self) -> &FieldConfig {
        &self.config
    }

    /// Splits each plane's rows across `threads` threads (the caller's plus `threads − 1` scoped
    /// ones) in every following step. Frames are bit-identical for every thread count. Errors
    /// for 0 or more than `MAX_THREADS`.
    pub fn set_threads(&mut self, threads: usize) -> Result<(), ConfigError> {
        if threads == 0 || threads > MAX_THREADS {
            return Err(ConfigError::invalid(
                "threads",
                threads,
                format!("the tick needs between 1 and {MAX_THREADS} threads"),
            ));
        }
        self.threads = threads;
        Ok(())
    }

    /// Threads of the evaporation pass.
    pub fn threads(&self) -> usize {
        self.threads
    }

    /// The grid of the configuration.
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// Resumes counters and clock from a frame header (restart / restore / takeover).
    pub fn resume_from(&mut self, header: &FrameHeader) {
        self.sequence = header.sequence;
        self.sim_time_s = header.sim_time_s;
        self.counters.applied = header.deposits_applied;
        self.counters.rejected = header.deposits_rejected;
    }

    /// Validates a deposit and queues it for the next tick; a rejection is counted and returned.
    pub fn offer(&mut self, msg: &DepositMsg) -> Result<(), Rejection> {
        match prepare(
            msg,
            &self.geometry,
            &self.config.channels,
            &self.config.limits,
        ) {
            Ok(d) => {
                let order = deposit_order(msg.robot_id, self.pending.len());
                self.pending.push((order, d, *msg));
                Ok(())
            }
            Err(r) => {
                self.counters.count(r.reason);
                Err(r)
            }
        }
    }

    /// Deposits waiting for the next tick.
    pub fn pending(&self) -> usize {
        self.pending.len()
    }

    /// Computes `next` from `prev` (both full frames, `channel, y, x`) and applies the queued
    /// deposits. Each cell of `prev` is read once and each cell of `next` written once by the
    /// evaporation pass; deposits then touch only their kernel's cells.
    pub fn step(&mut self, prev: &[f32], next: &mut [f32]) -> TickReport {
        let (dt, dt_time_s) = self.tick_step();
        self.step_by(prev, next, dt, dt_time_s)
    }

    /// As `step`, over `dt_s` seconds instead of one tick period (a field that publishes as
    /// soon as deposits arrive): evaporation by its closed form in `dt_s`, diffusion by
    /// κ = D·dt/h². `dt_s` must lie in (0, tick period]: a shorter step keeps the diffusion
    /// stable (κ only shrinks), a longer one is clamped to the period.
    pub fn step_dt(&mut self, prev: &[f32], next: &mut [f32], dt_s: f32) -> TickReport {
        self.step_dt_then(prev, next, dt_s, |_| {})
    }

    /// As `step_dt`, calling `late` between the evaporation pass and the deposits: what it
    /// offers (deposits that arrived while the pass ran) lands in this frame, in the canonical
    /// order with the others. A field publishing on deposit uses it, so a deposit that comes
    /// during a tick waits for the rest of that tick only, not for one more.
    pub fn step_dt_then(
        &mut self,
        prev: &[f32],
        next: &mut [f32],
        dt_s: f32,
        late: impl FnOnce(&mut Self),
    ) -> TickReport {
        let period = self.config.dt_s();
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            dt_s.min(period)
        } else {
            period
        };
        self.evaporate(prev, next, dt);
        late(self);
        self.apply_pending(prev, next, dt, dt as f64)
    }

    /// The deposits the last step applied, in the order it applied them: what a mirror replays
    /// (`replay`) to compute the same frame.
    pub fn applied(&self) -> &[DepositMsg] {
        &self.applied
    }

    /// Recomputes a frame of another field (a mirror): `deposits` are the origin's applied list of
    /// that tick, in order, `sim_time_before_s` its field time before the tick, `dt_s` and
    /// `dt_time_s` the step it took (`InputsHeader`). The frame is bit-identical to the origin's
    /// on the same binary and architecture. Returns the report and how many deposits this
    /// stepper refused (0 unless the configurations differ).
    pub fn replay(
        &mut self,
        prev: &[f32],
        next: &mut [f32],
        deposits: &[DepositMsg],
        sim_time_before_s: f64,
        dt_s: f32,
        dt_time_s: f64,
    ) -> (TickReport, u32) {
        self.pending.clear();
        let mut refused = 0;
        for d in deposits {
            if self.offer(d).is_err() {
                refused += 1;
            }
        }
        self.sim_time_s = sim_time_before_s;
        (self.step_by(prev, next, dt_s, dt_time_s), refused)
    }

    /// The last step: field time before it (s), its `dt_s` and its field-time increment (s).
    pub fn last_step(&self) -> (f64, f32, f64) {
        self.last_step
    }

    /// The step (`dt_s`, `dt_time_s`) `step` takes: one tick period.
    pub fn tick_step(&self) -> (f32, f64) {
        (self.config.dt_s(), 1.0 / self.config.tick_hz as f64)
    }

    fn step_by(&mut self, prev: &[f32], next: &mut [f32], dt: f32, dt_time_s: f64) -> TickReport {
        self.evaporate(prev, next, dt);
        self.apply_pending(prev, next, dt, dt_time_s)
    }

    /// The plane pass of every channel (evaporation, diffusion) over `dt` seconds.
    fn evaporate(&mut self, prev: &[f32], next: &mut [f32], dt: f32) {
        let n = self.geometry.cells();
        assert_eq!(
            prev.len(),
            self.config.frame_len(),
            "previous frame has the wrong length"
        );
        assert_eq!(next.len(), prev.len(), "next frame has the wrong length");
        let h = self.geometry.cell_size_m;
        let tick_dt = self.config.dt_s();
        for (c, spec) in self.config.channels.iter().enumerate() {
            let plan = PlanePlan::for_dt(spec, self.sim_time_s, dt, tick_dt, h);
            let kappa = spec.diffusion_m2_per_s * dt / (h * h);
            step_plane_threads(
                plan,
                kappa,
                self.geometry.width as usize,
                &prev[c * n..(c + 1) * n],
                &mut next[c * n..(c + 1) * n],
                &mut self.scratch,
                self.threads,
            );
        }
    }

    /// Applies the pending deposits onto `next` in their canonical order and closes the step.
    fn apply_pending(
        &mut self,
        prev: &[f32],
        next: &mut [f32],
        dt: f32,
        dt_time_s: f64,
    ) -> TickReport {
        let n = self.geometry.cells();
        let mut report = TickReport::default();
        // Deposits onto one cell do not commute (saturation, rounding): apply them in one
        // canonical order, whatever order the publishers' messages arrived in.
        self.pending.sort_unstable_by_key(|(order, _, _)| *order);
        self.applied.clear();
        for (_, d, msg) in self.pending.drain(..) {
            self.applied.push(msg);
            let (lo, hi) = self.config.channels[d.channel].value_range();
            let range = d.channel * n..(d.channel + 1) * n;
            report.mass_added += d.apply(
                &self.geometry,
                &prev[range.clone()],
                &mut next[range],
                lo,
                hi,
            );
            report.deposits_applied += 1;
        }
        self.counters.applied += report.deposits_applied as u64;
        self.last_step = (self.sim_time_s, dt, dt_time_s);
        self.sim_time_s += dt_time_s;
        self.sequence += 1;
        report
    }

    /// The header describing the frame just computed.
    pub fn header(&self, stamp_ns: u64, tick_compute_ns: u64, report: &TickReport) -> FrameHeader {
        let g = &self.geometry;
        FrameHeader {
            layout_version: LAYOUT_VERSION,
            channels: self.config.channels.len() as u32,
            width: g.width,
            height: g.height,
            sequence: self.sequence,
            stamp_ns,
            sim_time_s: self.sim_time_s,
            cell_size_m: g.cell_size_m,
            origin_x_m: g.origin_x_m,
            origin_y_m: g.origin_y_m,
            dt_s: self.config.dt_s(),
            tick_compute_ns,
            deposits_applied: self.counters.applied,
            deposits_rejected: self.counters.rejected,
            deposits_this_tick: report.deposits_applied,
            _reserved: 0,
        }
    }
}

/// A field in process memory: two buffers that swap each tick (no copy). Used by tests, the
/// single-process simulator and benchmarks; the shared-memory field runs the same `Stepper`.
#[derive(Debug, Clone)]
pub struct OwnedField {
    /// The engine: configuration, pending deposits, counters and clock.
    pub stepper: Stepper,
    current: Vec<f32>,
    spare: Vec<f32>,
}

impl OwnedField {
    /// A field of `config` with every cell 0; fails if the configuration does not validate.
    pub fn new(config: FieldConfig) -> Result<Self, ConfigError> {
        let stepper = Stepper::new(config)?;
        let len = stepper.config().frame_len();
        Ok(Self {
            stepper,
            current: vec![0.0; len],
            spare: vec![0.0; len],
        })
    }

    /// Starts from given cells (e.g. a checkpoint); the length must match the configuration.
    pub fn with_cells(config: FieldConfig, cells: Vec<f32>) -> Result<Self, ConfigError> {
        let mut f = Self::new(config)?;
        if cells.len() != f.current.len() {
            return Err(ConfigError::invalid(
                "cells",
                cells.len(),
                format!("expected {}", f.current.len()),
            ));
        }
        if let Some(i) = cells.iter().position(|v| !v.is_finite()) {
            return Err(ConfigError::invalid(
                format!("cell {i}"),
                cells[i],
                "must be finite",
            ));
        }
        f.current = cells;
        Ok(f)
    }

    /// Validates a deposit and queues it for the next tick (see [`Stepper::offer`]).
    pub fn offer(&mut self, msg: &DepositMsg) -> Result<(), Rejection> {
        self.stepper.offer(msg)
    }

    /// Advances one tick period: evaporation and diffusion, then the queued deposits.
    pub fn tick(&mut self) -> TickReport {
        let report = self.stepper.step(&self.current, &mut self.spare);
        std::mem::swap(&mut self.current, &mut self.spare);
        report
    }

    /// The current frame's cells, all planes (`channel, y, x`).
    pub fn cells(&self) -> &[f32] {
        &self.current
    }

    /// The current frame as a [`FrameView`], for sampling.
    pub fn view(&self) -> FrameView<'_> {
        FrameView::new(
            *self.stepper.geometry(),
            self.stepper.config().channels.len(),
            &self.current,
        )
    }
}
