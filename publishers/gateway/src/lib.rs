//! Seed 002's pheromone server for thin clients (MODELS.md M3): robots with only a
//! microcontroller and a radio send DLE/CRC frames (`gateway_codec`, wire contract in
//! `docs/gateway-wire.md`) and get back what they would read from shared memory.
//!
//! [`Gateway`] holds the I/O-free logic: it answers one decoded frame at a time from the newest
//! frame of a field it reads ([`FieldReader`]) and forwards deposits to the field
//! ([`DepositPublisher`]). [`udp`] serves it on a UDP socket (one frame per datagram),
//! [`serial`] on a serial line (a byte stream, half duplex); [`client`] is the thin client's side
//! of both, with a backup gateway; [`line`](mod@line) is either place to serve on, as `pheromone gateway`
//! opens it.
//!
//! - **PIR:** the two antenna readings at the M3 antenna points, half a wheel base (as the client
//!   sends it) to each side of the pose ([`pheromone_field::FrameView::antennas`]), with the sequence of
//!   the frame they were read from.
//! - **DEPOSIT:** a Z-shape reinforcement (seed 002 eq. 1) at (x, y) with the gateway's plateau
//!   and slope, sent to the field with the client ID as robot ID. Its 1-byte `seq` makes a
//!   retried deposit apply at most once: the last [`SEQ_MEMORY`] seqs of each client are kept.
//! - **PING:** the newest frame's sequence, field time and channel count.
//! - **Errors:** a frame with a valid CRC that is malformed, names an unknown channel, a value out
//!   of range, comes from a client not on the allow-list or over its rate gets an error reply
//!   with M3's reason and is never applied; a frame with a bad CRC (or broken framing) is counted
//!   and dropped, since its client ID cannot be trusted.

pub mod client;
pub mod line;
pub mod peer;
pub mod radio;
pub mod serial;
pub mod udp;

use std::time::Duration;

use iceoryx2::node::Node;
use pheromone_field::shm::{
    ConfigSubscriber, DepositPublisher, FieldReader, SendError, ShmError, Svc,
};
use pheromone_field::sources::SourceSensing;
use pheromone_field::{Deposit, FieldConfig, Kernel, RejectReason, SamplePose};
use pheromone_gateway_codec::{
    DecodeError, DepositReply, DepositRequest, DepositStatus, ErrorReason, Frame, Message,
    PirReply, PirRequest, StatusReply,
};
use serde::Serialize;

/// How often a serving gateway calls its log with the counters.
pub const LOG_EVERY: Duration = Duration::from_secs(1);

/// Deposit seqs remembered per client (M3: the last 16).
pub const SEQ_MEMORY: usize = 16;
/// The widest half wheel base a PIR may name (m); a larger one is out of range (reason 3).
pub const MAX_HALF_WHEEL_BASE_M: f32 = 10.0;

/// What the gateway serves and to whom.
#[derive(Debug, Clone, PartialEq)]
pub struct GatewayConfig {
    /// Client IDs served; the others get reason 6. Default: 1–255 (ID 0 is left out: CRC-16/ARC
    /// does not protect a leading 0x00, see `docs/gateway-wire.md`).
    pub allow: Vec<u8>,
    /// Client IDs served only from these UDP sources (`--allow ID@ADDR`: an IP address, any
    /// port, or IP:PORT); a frame with such an ID from elsewhere, or on a serial line, gets
    /// reason 6. An ID may be bound to several sources.
    pub bound: Vec<(u8, Source)>,
    /// Requests per second each client ID may send from each source (a bucket of as many,
    /// refilled continuously; one per ID and UDP address, so another socket using the ID has
    /// its own); 0 = unlimited. Over it: reason 5.
    pub rate_per_s: f64,
    /// Which local users are served from loopback sources, by the owner of the source socket
    /// ([`peer`]); others get reason 6. Default: the gateway's own user and root.
    pub local_users: peer::LocalUsers,
    /// Plateau c of the Z-shape deposit (m).
    pub plateau_m: f32,
    /// Slope width σ of the Z-shape deposit (m).
    pub slope_m: f32,
}

/// Where a bound client ID may send from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// This IP address, any port.
    Ip(std::net::IpAddr),
    /// This IP address and port.
    Socket(std::net::SocketAddr),
}

impl Source {
    fn admits(self, from: std::net::SocketAddr) -> bool {
        match self {
            Source::Ip(ip) => from.ip() == ip,
            Source::Socket(s) => from == s,
        }
    }
}

impl std::str::FromStr for Source {
    type Err = std::net::AddrParseError;

    /// `IP` or `IP:PORT` (`[v6]:PORT` for IPv6).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.parse::<std::net::SocketAddr>() {
            Ok(a) => Ok(Source::Socket(a)),
            Err(_) => s.parse().map(Source::Ip),
        }
    }
}

impl Default for GatewayConfig {
    fn default() -> Self {
        Self {
            allow: (1..=255).collect(),
            bound: Vec::new(),
            rate_per_s: 100.0,
            local_users: peer::LocalUsers::owner(),
            plateau_m: 0.2,
            slope_m: 0.3,
        }
    }
}

/// Why a gateway could not start or serve.
#[derive(Debug, thiserror::Error)]
pub enum GatewayError {
    #[error(transparent)]
    Shm(#[from] ShmError),
    #[error("gateway setting {name} = {value}: {reason}")]
    Config {
        name: &'static str,
        value: String,
        reason: &'static str,
    },
    #[error("no frame from field '{field}' within {timeout_s} s")]
    NoFrame { field: String, timeout_s: f64 },
    #[error("serial line {path}: {action} failed")]
    Serial {
        path: String,
        action: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error("UDP socket {address}: {action} failed")]
    Socket {
        address: String,
        action: &'static str,
        #[source]
        source: std::io::Error,
    },
}

pheromone_field::from_shm_errors!(GatewayError);

/// Counters of one gateway, logged once a second and printed at the end.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct GatewayCounters {
    /// Frames decoded (valid CRC and framing).
    pub frames: u64,
    pub pirs: u64,
    /// Deposits forwarded to the field.
    pub deposits: u64,
    /// Retried deposits whose seq was already applied (answered, not applied again).
    pub deposits_repeated: u64,
    /// Deposits the field did not take (none subscribed or its buffer full): not answered, so
    /// the client retries.
    pub deposits_undelivered: u64,
    /// Deposits refused with the field's own checks (`pheromone_field::deposit::prepare`), by the
    /// field's reason (`out_of_limits`, `negative_on_unsigned`, …): answered, never sent.
    pub deposits_refused: std::collections::BTreeMap<&'static str, u64>,
    pub pings: u64,
    /// Error replies sent, by M3 reason code (index 1–6).
    pub errors_sent: [u64; 7],
    /// Frames dropped without a reply (bad CRC, broken framing), by the codec's reason.
    pub dropped: u64,
    /// Rejections by the codec's reason name (bad_crc, too_long, …).
    pub rejected: std::collections::BTreeMap<&'static str, u64>,
}

impl GatewayCounters {
    /// The status line `pheromone gateway` writes once a second and at the end.
    pub fn status_line(&self) -> String {
        format!(
            "gateway: frames {} pir {} deposits {} (repeated {}, undelivered {}) pings {} \
             errors sent {:?} dropped {} rejected {:?}",
            self.frames,
            self.pirs,
            self.deposits,
            self.deposits_repeated,
            self.deposits_undelivered,
            self.pings,
            &self.errors_sent[1..],
            self.dropped,
            self.rejected
        )
    }
}

/// What one client has used of its rate and which deposit seqs it has applied.
#[derive(Debug, Clone, Copy)]
struct Client {
    seqs: [u8; SEQ_MEMORY],
    seq_count: usize,
    seq_next: usize,
}

/// Rate buckets kept at most; past it, the bucket idle longest is dropped (it starts full again
/// when its sender comes back, as after a second of silence).
pub const MAX_RATE_BUCKETS: usize = 4096;

/// The request bucket of one client ID *from one source* (a UDP address, or the serial line):
/// a flood that borrows a real client's ID from another socket empties only its own bucket, so
/// it cannot starve that client (issue 54 item 5).
#[derive(Debug, Clone, Copy)]
struct Bucket {
    tokens: f64,
    last_ns: u64,
}

impl Bucket {
    const NEW: Bucket = Bucket {
        tokens: f64::NAN,
        last_ns: 0,
    };

    /// Takes one request from the bucket; false when the sender is over its rate.
    fn admit(&mut self, rate_per_s: f64, now_ns: u64) -> bool {
        if rate_per_s <= 0.0 {
            return true;
        }
        let burst = rate_per_s.max(1.0);
        if self.tokens.is_nan() {
            self.tokens = burst;
        } else {
            let dt_s = now_ns.saturating_sub(self.last_ns) as f64 * 1e-9;
            self.tokens = (self.tokens + dt_s * rate_per_s).min(burst);
        }
        self.last_ns = now_ns;
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

/// Every sender's [`Bucket`], by client ID and source, at most [`MAX_RATE_BUCKETS`].
#[derive(Default)]
struct Buckets(std::collections::HashMap<(u8, Option<std::net::SocketAddr>), Bucket>);

impl Buckets {
    fn admit(
        &mut self,
        id: u8,
        from: Option<std::net::SocketAddr>,
        rate_per_s: f64,
        now_ns: u64,
    ) -> bool {
        if rate_per_s <= 0.0 {
            return true;
        }
        if self.0.len() >= MAX_RATE_BUCKETS && !self.0.contains_key(&(id, from)) {
            let idlest = self
                .0
                .iter()
                .min_by_key(|(_, b)| b.last_ns)
                .map(|(k, _)| *k);
            if let Some(k) = idlest {
                self.0.remove(&k);
            }
        }
        self.0
            .entry((id, from))
            .or_insert(Bucket::NEW)
            .admit(rate_per_s, now_ns)
    }
}

impl Client {
    const NEW: Client = Client {
        seqs: [0; SEQ_MEMORY],
        seq_count: 0,
        seq_next: 0,
    };

    fn applied(&self, seq: u8) -> bool {
        self.seqs[..self.seq_count].contains(&seq)
    }

    fn remember(&mut self, seq: u8) {
        self.seqs[self.seq_next] = seq;
        self.seq_next = (self.seq_next + 1) % SEQ_MEMORY;
        self.seq_count = (self.seq_count + 1).min(SEQ_MEMORY);
    }
}

/// The pheromone server of seed 002 over one field.
pub struct Gateway {
    field: String,
    reader: FieldReader,
    depositor: DepositPublisher,
    config: GatewayConfig,
    allowed: [bool; 256],
    clients: Box<[Client; 256]>,
    buckets: Buckets,
    owners: peer::Owners,
    counters: GatewayCounters,
    /// The field's configuration once it has published it (with its next frame after the
    /// gateway attached): its channels and limits check each deposit as the field will.
    field_config: Option<FieldConfig>,
    config_sub: Option<ConfigSubscriber>,
    /// Each channel's sources, from `field_config`: a PIR on a source channel reads eq. 4 with
    /// directional antennas (M3).
    sources: Vec<Option<SourceSensing>>,
}

impl Gateway {
    /// Attaches to field `field` (waiting up to `timeout` for it and its first frame).
    pub fn attach(
        node: &Node<Svc>,
        field: &str,
        config: GatewayConfig,
        timeout: Duration,
    ) -> Result<Self, GatewayError> {
        check_config(&config)?;
        let mut reader = FieldReader::attach_within(node, field, timeout)?;
        // Checked every 100 ms, not only on frame-ready: a lockstep field waiting for its first
        // clock hands a new reader the current frame (its history) without a new frame event.
        if reader.frame().is_none() && reader.wait_until(timeout, |_| true)?.is_none() {
            return Err(GatewayError::NoFrame {
                field: field.to_string(),
                timeout_s: timeout.as_secs_f64(),
            });
        }
        // Robot IDs of the gateway's deposits are the client IDs; the publisher's own is unused.
        let depositor = DepositPublisher::attach_within(node, field, 0, timeout)?;
        let mut allowed = [false; 256];
        for &id in &config.allow {
            allowed[id as usize] = true;
        }
        let config_sub = ConfigSubscriber::attach(node, field)
            .map_err(|e| {
                eprintln!(
                    "gateway: cannot read field '{field}''s configuration ({e}); deposits are \
                     checked for their channel and reach only"
                )
            })
            .ok();
        Ok(Self {
            field: field.to_string(),
            reader,
            depositor,
            config,
            allowed,
            clients: Box::new([Client::NEW; 256]),
            buckets: Buckets::default(),
            owners: peer::Owners::default(),
            counters: GatewayCounters::default(),
            field_config: None,
            config_sub,
            sources: Vec::new(),
        })
    }

    /// The field's configuration, once it has arrived.
    fn field_config(&mut self) -> Result<Option<&FieldConfig>, GatewayError> {
        if let Some(sub) = &self.config_sub {
            if let Some(c) = sub.latest()? {
                self.field_config = Some(c);
            }
        }
        Ok(self.field_config.as_ref())
    }

    pub fn field(&self) -> &str {
        &self.field
    }

    pub fn counters(&self) -> &GatewayCounters {
        &self.counters
    }

    /// Counts a frame the codec rejected; returns the error reply it gets, if any.
    pub fn rejected(&mut self, e: &DecodeError) -> Option<Frame> {
        *self
            .counters
            .rejected
            .entry(e.rejection().name())
            .or_default() += 1;
        match e.reply() {
            Some((client_id, reason)) => Some(self.error(client_id, reason)),
            None => {
                self.counters.dropped += 1;
                None
            }
        }
    }

    /// Answers one decoded frame received at `now_ns` (CLOCK_MONOTONIC) from a source with no
    /// address (a serial line); `None` = no reply (a deposit the field did not take: the client
    /// retries).
    pub fn handle(&mut self, frame: Frame, now_ns: u64) -> Result<Option<Frame>, GatewayError> {
        self.handle_from(frame, now_ns, None)
    }

    /// [`Gateway::handle`] for a frame that came from `from` (UDP): a client ID bound to other
    /// sources (`GatewayConfig::bound`) is not allowed (reason 6).
    pub fn handle_from(
        &mut self,
        frame: Frame,
        now_ns: u64,
        from: Option<std::net::SocketAddr>,
    ) -> Result<Option<Frame>, GatewayError> {
        self.counters.frames += 1;
        let id = frame.client_id;
        if !self.allowed[id as usize]
            || !self.source_admitted(id, from)
            || !self.local_user_admitted(from, now_ns)
        {
            return Ok(Some(self.error(id, ErrorReason::ClientNotAllowed)));
        }
        if !self.buckets.admit(id, from, self.config.rate_per_s, now_ns) {
            return Ok(Some(self.error(id, ErrorReason::RateLimited)));
        }
        // Take whatever frame has arrived since the last request.
        self.reader.update()?;
        let reply = match frame.message {
            Message::Pir(p) => self.pir(id, p)?,
            Message::Deposit(d) => return self.deposit(id, d),
            Message::Ping => self.ping(id),
            // A reply sent to the server is no request.
            _ => self.error(id, ErrorReason::UnknownOpcode),
        };
        Ok(Some(reply))
    }

    /// Whether a loopback source's socket belongs to a user `local_users` admits (another
    /// host's source, or the serial line, has no local owner to check).
    fn local_user_admitted(&mut self, from: Option<std::net::SocketAddr>, now_ns: u64) -> bool {
        let (Some(from), peer::LocalUsers::Only(uids)) = (from, &self.config.local_users) else {
            return true;
        };
        if !from.ip().is_loopback() {
            return true;
        }
        self.owners
            .of(from, now_ns)
            .is_some_and(|uid| uids.contains(&uid))
    }

    /// Whether client `id` may send from `from`: any source unless it is bound.
    fn source_admitted(&self, id: u8, from: Option<std::net::SocketAddr>) -> bool {
        let mut bound = self
            .config
            .bound
            .iter()
            .filter(|(b, _)| *b == id)
            .peekable();
        if bound.peek().is_none() {
            return true;
        }
        from.is_some_and(|from| bound.any(|(_, s)| s.admits(from)))
    }

    fn pir(&mut self, id: u8, p: PirRequest) -> Result<Frame, GatewayError> {
        self.refresh_sources()?;
        Ok(self.pir_reply(id, p))
    }

    /// Each channel's sources (M3), from the field's configuration once it has arrived.
    fn refresh_sources(&mut self) -> Result<(), GatewayError> {
        if let Some(c) = self.field_config()? {
            self.sources = c.channels.iter().map(|c| c.sources).collect();
        }
        Ok(())
    }

    /// The quantum Q of channel `ch` when it is a source channel (M3), once the field's
    /// configuration has arrived.
    fn quantum_of(&mut self, ch: usize) -> Result<Option<f32>, GatewayError> {
        let spec = self.field_config()?.and_then(|c| c.channels.get(ch));
        Ok(spec
            .filter(|c| c.sources.is_some())
            .and_then(|c| match c.evaporation {
                pheromone_field::Evaporation::Quantum { quantum, .. } => Some(quantum),
                _ => None,
            }))
    }

    fn pir_reply(&mut self, id: u8, p: PirRequest) -> Frame {
        let Some(f) = self.reader.frame() else {
            return self.error(id, ErrorReason::BadValue);
        };
        if p.channel as usize >= f.view.channels {
            return self.error(id, ErrorReason::UnknownChannel);
        }
        if !(p.half_wheel_base_m > 0.0 && p.half_wheel_base_m <= MAX_HALF_WHEEL_BASE_M) {
            return self.error(id, ErrorReason::BadValue);
        }
        let pose = SamplePose::new(p.x_m, p.y_m, p.theta_rad);
        let (ch, b) = (p.channel as usize, 2.0 * p.half_wheel_base_m);
        let (p_left, p_right) = match self.sources.get(ch).copied().flatten() {
            Some(s) => pheromone_field::sources::antennas(&f.view, ch, pose, b, &s),
            None => f.view.antennas(ch, pose, b),
        };
        let frame_seq = f.header.sequence as u32;
        self.counters.pirs += 1;
        Frame {
            client_id: id,
            message: Message::PirReply(PirReply {
                p_left,
                p_right,
                frame_seq,
            }),
        }
    }

    fn deposit(&mut self, id: u8, d: DepositRequest) -> Result<Option<Frame>, GatewayError> {
        let reply = |status| Frame {
            client_id: id,
            message: Message::DepositReply(DepositReply { seq: d.seq, status }),
        };
        // On a source channel a DEPOSIT is one quantum Q to the nearest node's counter (M3).
        let amount = self.quantum_of(d.channel as usize)?.unwrap_or(d.amount);
        let deposit = Deposit {
            channel: d.channel as u32,
            x_m: d.x_m,
            y_m: d.y_m,
            kernel: Kernel::ZShape {
                amount,
                plateau_m: self.config.plateau_m,
                slope_m: self.config.slope_m,
            },
        };
        let msg = deposit.to_msg(id as u32, 0);
        // The field's own checks, with its channels and limits: what it would refuse is answered
        // here, never sent.
        let refused = match self.field_config()? {
            Some(c) => {
                pheromone_field::deposit::prepare(&msg, &c.geometry(), &c.channels, &c.limits).err()
            }
            None => None,
        };
        if let Some(r) = refused {
            *self
                .counters
                .deposits_refused
                .entry(r.reason.name())
                .or_default() += 1;
            let reason = deposit_status(r.reason);
            self.counters.errors_sent[reason as usize] += 1;
            return Ok(Some(reply(DepositStatus::Rejected(reason))));
        }
        let Some(f) = self.reader.frame() else {
            return Ok(Some(self.error(id, ErrorReason::BadValue)));
        };
        if d.channel as usize >= f.view.channels {
            self.counters.errors_sent[ErrorReason::UnknownChannel as usize] += 1;
            return Ok(Some(reply(DepositStatus::Rejected(
                ErrorReason::UnknownChannel,
            ))));
        }
        // The deposit's reach must touch the grid (the field would reject it otherwise).
        let g = f.header.geometry();
        let reach_m = self.config.plateau_m + self.config.slope_m;
        let (x0, y0) = (g.origin_x_m - reach_m, g.origin_y_m - reach_m);
        let x1 = g.origin_x_m + g.width as f32 * g.cell_size_m + reach_m;
        let y1 = g.origin_y_m + g.height as f32 * g.cell_size_m + reach_m;
        if !(d.x_m > x0 && d.x_m < x1 && d.y_m > y0 && d.y_m < y1) {
            self.counters.errors_sent[ErrorReason::BadValue as usize] += 1;
            return Ok(Some(reply(DepositStatus::Rejected(ErrorReason::BadValue))));
        }
        if self.clients[id as usize].applied(d.seq) {
            self.counters.deposits_repeated += 1;
            return Ok(Some(reply(DepositStatus::Applied)));
        }
        match self.depositor.send_as(msg) {
            Ok(()) => {
                self.clients[id as usize].remember(d.seq);
                self.counters.deposits += 1;
                Ok(Some(reply(DepositStatus::Applied)))
            }
            Err(SendError::NoSubscriber { .. }) => {
                self.counters.deposits_undelivered += 1;
                Ok(None)
            }
            Err(e) => Err(e.into()),
        }
    }

    fn ping(&mut self, id: u8) -> Frame {
        let Some(f) = self.reader.frame() else {
            return self.error(id, ErrorReason::BadValue);
        };
        let status = StatusReply {
            frame_seq: f.header.sequence as u32,
            field_time_s: f.header.sim_time_s as f32,
            channels: f.header.channels.min(255) as u8,
        };
        self.counters.pings += 1;
        Frame {
            client_id: id,
            message: Message::Status(status),
        }
    }

    fn error(&mut self, client_id: u8, reason: ErrorReason) -> Frame {
        self.counters.errors_sent[reason as usize] += 1;
        Frame {
            client_id,
            message: Message::Error(reason),
        }
    }
}

/// The deposit status (an M3 reason) for a deposit the field refuses: 4 for an unknown
/// channel, 3 (a bad value) for everything else (non-finite, beyond the limits, negative on an
/// unsigned channel, outside the grid).
pub fn deposit_status(r: RejectReason) -> ErrorReason {
    match r {
        RejectReason::UnknownChannel => ErrorReason::UnknownChannel,
        RejectReason::NonFinite
        | RejectReason::NotPsd
        | RejectReason::UnknownKernel
        | RejectReason::OutOfLimits
        | RejectReason::OutsideGrid
        | RejectReason::NegativeOnUnsigned => ErrorReason::BadValue,
    }
}

fn check_config(c: &GatewayConfig) -> Result<(), GatewayError> {
    let bad = |name, value: f64, reason| GatewayError::Config {
        name,
        value: value.to_string(),
        reason,
    };
    if !(c.rate_per_s.is_finite() && c.rate_per_s >= 0.0) {
        return Err(bad(
            "rate_per_s",
            c.rate_per_s,
            "must be a finite number ≥ 0",
        ));
    }
    if !(c.plateau_m.is_finite() && c.plateau_m >= 0.0) {
        return Err(bad(
            "plateau_m",
            c.plateau_m as f64,
            "must be finite and ≥ 0",
        ));
    }
    if !(c.slope_m.is_finite() && c.slope_m >= 0.0) {
        return Err(bad("slope_m", c.slope_m as f64, "must be finite and ≥ 0"));
    }
    if c.plateau_m + c.slope_m <= 0.0 {
        return Err(bad(
            "plateau_m + slope_m",
            (c.plateau_m + c.slope_m) as f64,
            "a deposit must reach somewhere",
        ));
    }
    if c.allow.is_empty() {
        return Err(GatewayError::Config {
            name: "allow",
            value: "[]".into(),
            reason: "no client would be served",
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rate_bucket_admits_its_burst_then_refills_at_the_rate() {
        let mut c = Bucket::NEW;
        let t0 = 1_000_000_000;
        let admitted = (0..15).filter(|_| c.admit(10.0, t0)).count();
        assert_eq!(admitted, 10, "a burst of one second's worth");
        assert!(!c.admit(10.0, t0 + 50_000_000), "half a token after 50 ms");
        assert!(c.admit(10.0, t0 + 100_000_000), "one token after 100 ms");
        let mut unlimited = Buckets::default();
        assert!(
            (0..1000).all(|_| unlimited.admit(1, None, 0.0, t0)),
            "0 = unlimited"
        );
    }

    #[test]
    fn a_flood_under_a_clients_id_from_another_source_empties_only_its_own_bucket() {
        let mut b = Buckets::default();
        let real: std::net::SocketAddr = "127.0.0.1:4000".parse().unwrap();
        let flood: std::net::SocketAddr = "127.0.0.1:4001".parse().unwrap();
        let t0 = 1_000_000_000;
        let through = (0..1000)
            .filter(|_| b.admit(7, Some(flood), 10.0, t0))
            .count();
        assert_eq!(through, 10);
        assert!((0..10).all(|_| b.admit(7, Some(real), 10.0, t0)));
        // Bounded: the idlest bucket goes when a new sender comes past the limit.
        for port in 0..MAX_RATE_BUCKETS as u16 + 10 {
            let from = std::net::SocketAddr::from(([127, 0, 0, 2], port));
            b.admit(9, Some(from), 10.0, t0 + 1 + u64::from(port));
        }
        assert_eq!(b.0.len(), MAX_RATE_BUCKETS);
    }

    #[test]
    fn the_last_sixteen_seqs_are_remembered() {
        let mut c = Client::NEW;
        for s in 0..20u8 {
            c.remember(s);
        }
        assert!((4..20).all(|s| c.applied(s)));
        assert!((0..4).all(|s| !c.applied(s)));
    }

    #[test]
    fn bad_settings_are_refused_naming_the_setting() {
        let e = check_config(&GatewayConfig {
            rate_per_s: f64::NAN,
            ..Default::default()
        })
        .unwrap_err();
        assert!(e.to_string().contains("rate_per_s"), "{e}");
        let e = check_config(&GatewayConfig {
            allow: vec![],
            ..Default::default()
        })
        .unwrap_err();
        assert!(e.to_string().contains("allow"), "{e}");
    }
}
