//! Seed 002's antenna robot with its two readings from anywhere (MODELS.md M3): an
//! [`AntennaSource`] answers "the readings P_L, P_R at the antennas either side of this pose, from
//! a frame at least this new", and [`AntennaRobot`] turns a pose into the command of the `antenna`
//! strategy ([`AntennaFollower`]) from them.
//!
//! - [`ShmSource`]: the newest frame in shared memory ([`FieldReader`], `FrameView::antennas`),
//!   waiting on the field's `frame-ready` event for a newer one.
//! - [`GatewaySource`]: a PIR to a `pheromone gateway` ([`GatewayClient`], with its backup),
//!   nothing of the field in shared memory. The client sends the antennas' centre
//!   ([`AntennaFollower::head`]) and half the wheel base; the gateway reads
//!   `FrameView::antennas` with twice that, so both sources give the same `f32` readings from
//!   the same frame.
//!
//! **Lockstep over a gateway.** In lockstep the follower must steer on frame `k + 1` for step `k`
//! (the frame the field computes after clock `k`). A PIR reply carries the sequence of the frame
//! it was read from (its low 32 bits); a reply from an older frame (the field has not ticked
//! yet) is counted as stale and the PIR is sent again, until a reply from frame `k + 1` or
//! later comes or the deadline passes. Each retry is one full round trip: the client blocks in
//! `recv` for the gateway's answer (no sleep), and the gateway answers from the newest frame it
//! holds, so the retries stop as soon as the field's tick lands. The cost is CPU while the field
//! ticks (see `docs/gateway-wire.md`, "Lockstep over a gateway").

use std::time::Instant;

use pheromone_field::shm::{FieldReader, ShmError};
use pheromone_field::SamplePose;
use serde::{Deserialize, Serialize};

use super::{AntennaFollower, FollowError, FollowOutput, FollowerStrategy};
use pheromone_gateway::client::{ClientError, GatewayClient};
use pheromone_messages::{CmdMsg, FollowerStatusMsg, PoseMsg};

/// Two antenna readings and the frame they were read from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AntennaReading {
    pub p_left: f32,
    pub p_right: f32,
    /// The frame's sequence (a gateway sends its low 32 bits).
    pub frame_seq: u64,
}

/// Why a source gave no readings.
#[derive(Debug, thiserror::Error)]
pub enum AntennaSourceError {
    #[error(transparent)]
    Gateway(#[from] ClientError),
    #[error(transparent)]
    Shm(#[from] ShmError),
    #[error(
        "{source_name}: the frame has {channels} channel(s); the follower reads channel {channel}"
    )]
    ChannelMissing {
        source_name: String,
        channel: u8,
        channels: usize,
    },
    #[error("{source_name}: deposits go through a gateway (--gateway), this source has none")]
    NoDeposits { source_name: String },
}

pheromone_field::from_shm_errors!(AntennaSourceError);

/// What a source did, for the role's summary.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SourceStats {
    /// `shm:FIELD` or the gateway's address (`udp://HOST:PORT`).
    pub source: String,
    /// Readings taken (PIRs answered, for a gateway).
    pub reads: u64,
    /// Replies from a frame older than the one asked for, asked again (lockstep).
    pub stale_replies: u64,
    /// Switches between the primary and the backup gateway.
    pub switches: u64,
    /// Answers "over your rate" (M3 reason 5) the client waited out before asking again.
    #[serde(default)]
    pub rate_limited_backoffs: u64,
    /// The gateway used at the end.
    pub active: String,
    /// Deposits the gateway answered as applied.
    pub deposits_applied: u64,
    /// Deposits that got no answer or were refused (applied at most once; see
    /// `DepositRetry::SameGateway`).
    pub deposits_failed: u64,
}

/// Where an antenna robot's two readings come from.
pub trait AntennaSource {
    /// `shm:FIELD`, `udp://HOST:PORT`: names the source in messages.
    fn name(&self) -> String;

    /// The readings of two antennas `wheel_base_m` apart centred on `head` (MODELS.md M3), on
    /// `channel`, from a frame whose sequence is at least `min_seq` (0: any). `Ok(None)` when no
    /// such frame came before `deadline`.
    fn read(
        &mut self,
        channel: u8,
        head: SamplePose,
        wheel_base_m: f32,
        min_seq: u64,
        deadline: Instant,
    ) -> Result<Option<AntennaReading>, AntennaSourceError>;

    /// Adds `amount` at (x, y) on `channel` (a gateway's Z-shape deposit).
    fn deposit(
        &mut self,
        x_m: f32,
        y_m: f32,
        amount: f32,
        channel: u8,
    ) -> Result<(), AntennaSourceError> {
        let _ = (x_m, y_m, amount, channel);
        Err(AntennaSourceError::NoDeposits {
            source_name: self.name(),
        })
    }

    fn stats(&self) -> SourceStats;
}

/// The readings from the field's frames in shared memory.
pub struct ShmSource {
    field: String,
    reader: FieldReader,
    reads: u64,
}

impl ShmSource {
    pub fn new(field: &str, reader: FieldReader) -> Self {
        Self {
            field: field.to_string(),
            reader,
            reads: 0,
        }
    }
}

impl AntennaSource for ShmSource {
    fn name(&self) -> String {
        format!("shm:{}", self.field)
    }

    fn read(
        &mut self,
        channel: u8,
        head: SamplePose,
        wheel_base_m: f32,
        min_seq: u64,
        deadline: Instant,
    ) -> Result<Option<AntennaReading>, AntennaSourceError> {
        loop {
            self.reader.update()?;
            if let Some(f) = self.reader.frame() {
                if f.header.sequence >= min_seq {
                    if channel as usize >= f.view.channels {
                        return Err(AntennaSourceError::ChannelMissing {
                            source_name: self.name(),
                            channel,
                            channels: f.view.channels,
                        });
                    }
                    let (p_left, p_right) = f.view.antennas(channel as usize, head, wheel_base_m);
                    self.reads += 1;
                    return Ok(Some(AntennaReading {
                        p_left,
                        p_right,
                        frame_seq: f.header.sequence,
                    }));
                }
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            // Woken by the field's frame-ready event.
            self.reader.wait_frame(left)?;
        }
    }

    fn stats(&self) -> SourceStats {
        SourceStats {
            source: self.name(),
            reads: self.reads,
            active: self.name(),
            ..SourceStats::default()
        }
    }
}

/// The readings from PIRs to a gateway (and its backup): no shared memory of the field.
pub struct GatewaySource {
    client: GatewayClient,
    name: String,
    stats: SourceStats,
}

impl GatewaySource {
    pub fn new(client: GatewayClient) -> Self {
        let name = client.active_address().to_string();
        Self {
            client,
            stats: SourceStats {
                source: name.clone(),
                ..SourceStats::default()
            },
            name,
        }
    }

    pub fn client(&self) -> &GatewayClient {
        &self.client
    }
}

/// Whether the 32-bit frame sequence `got` is at or after the low 32 bits of `want` (serial
/// number arithmetic: right across a wrap of the 32 bits).
pub fn seq_reached(got: u32, want: u64) -> bool {
    (got.wrapping_sub(want as u32) as i32) >= 0
}

impl AntennaSource for GatewaySource {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn read(
        &mut self,
        channel: u8,
        head: SamplePose,
        wheel_base_m: f32,
        min_seq: u64,
        deadline: Instant,
    ) -> Result<Option<AntennaReading>, AntennaSourceError> {
        let half_wheel_base_m = 0.5 * wheel_base_m;
        loop {
            let r = self.client.pir(
                head.x_m,
                head.y_m,
                head.theta_rad,
                half_wheel_base_m,
                channel,
            )?;
            self.stats.reads += 1;
            if min_seq == 0 || seq_reached(r.frame_seq, min_seq) {
                // The full sequence: the one asked for plus how far the reply is past it.
                let frame_seq = if min_seq == 0 {
                    r.frame_seq as u64
                } else {
                    min_seq + r.frame_seq.wrapping_sub(min_seq as u32) as u64
                };
                return Ok(Some(AntennaReading {
                    p_left: r.p_left,
                    p_right: r.p_right,
                    frame_seq,
                }));
            }
            self.stats.stale_replies += 1;
            if Instant::now() >= deadline {
                return Ok(None);
            }
        }
    }

    fn deposit(
        &mut self,
        x_m: f32,
        y_m: f32,
        amount: f32,
        channel: u8,
    ) -> Result<(), AntennaSourceError> {
        match self.client.deposit(x_m, y_m, amount, channel) {
            Ok(_) => {
                self.stats.deposits_applied += 1;
                Ok(())
            }
            Err(e) => {
                self.stats.deposits_failed += 1;
                Err(e.into())
            }
        }
    }

    fn stats(&self) -> SourceStats {
        SourceStats {
            switches: self.client.switches().0,
            rate_limited_backoffs: self.client.backoffs(),
            active: self.client.active_address().to_string(),
            ..self.stats.clone()
        }
    }
}

/// Why an antenna robot's step produced no command.
#[derive(Debug, thiserror::Error)]
pub enum AntennaStepError {
    #[error(transparent)]
    Input(#[from] FollowError),
    #[error(transparent)]
    Source(#[from] AntennaSourceError),
}

/// An antenna robot: the `antenna` strategy on readings from an [`AntennaSource`].
pub struct AntennaRobot<S: AntennaSource> {
    robot_id: u32,
    strategy: AntennaFollower,
    source: S,
}

impl<S: AntennaSource> AntennaRobot<S> {
    pub fn new(robot_id: u32, strategy: AntennaFollower, source: S) -> Self {
        Self {
            robot_id,
            strategy,
            source,
        }
    }

    pub fn robot_id(&self) -> u32 {
        self.robot_id
    }

    pub fn source(&self) -> &S {
        &self.source
    }

    pub fn source_mut(&mut self) -> &mut S {
        &mut self.source
    }

    pub fn channel(&self) -> u8 {
        self.strategy.channel() as u8
    }

    /// One step from a pose message: the readings from a frame at least `min_seq` new, then the
    /// command (its `step` is the pose's; stamps are left 0). `Ok(None)` when no such frame came
    /// before `deadline`. A pose that is not finite in `f32` is refused before anything is sent.
    pub fn step_pose(
        &mut self,
        pose: &PoseMsg,
        dt_s: f64,
        min_seq: u64,
        deadline: Instant,
    ) -> Result<Option<(FollowOutput, AntennaReading)>, AntennaStepError> {
        let mut p = SamplePose::default();
        for (name, v, out) in [
            ("x_m", pose.x_m, &mut p.x_m),
            ("y_m", pose.y_m, &mut p.y_m),
            ("theta_rad", pose.theta_rad, &mut p.theta_rad),
        ] {
            let f = v as f32;
            if !f.is_finite() {
                return Err(FollowError::BadPose { name, value: v }.into());
            }
            *out = f;
        }
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return Err(FollowError::BadDt(dt_s).into());
        }
        let head = self.strategy.head(p);
        let Some(reading) = self.source.read(
            self.channel(),
            head,
            self.strategy.config().wheel_base_m,
            min_seq,
            deadline,
        )?
        else {
            return Ok(None);
        };
        let mut d = self
            .strategy
            .decide_readings(reading.p_left, reading.p_right);
        let finite_or_zero = |v: f64| if v.is_finite() { v } else { 0.0 };
        d.v_m_per_s = finite_or_zero(d.v_m_per_s);
        d.omega_rad_per_s = finite_or_zero(d.omega_rad_per_s);
        if !d.sensed_level.is_finite() {
            d.sensed_level = 0.0;
        }
        let cmd = CmdMsg {
            stamp_ns: 0,
            step: pose.step,
            robot_id: self.robot_id,
            _pad: 0,
            v_m_per_s: d.v_m_per_s,
            omega_rad_per_s: d.omega_rad_per_s,
        };
        let status = FollowerStatusMsg {
            stamp_ns: 0,
            step: pose.step,
            robot_id: self.robot_id,
            state: d.state as u32,
            sensed_level: d.sensed_level,
            _pad: 0,
        };
        Ok(Some((
            FollowOutput {
                cmd,
                status,
                decision: d,
            },
            reading,
        )))
    }
}

#[cfg(test)]
mod tests;
