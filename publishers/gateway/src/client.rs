//! The thin client's side of the gateway (MODELS.md M3, `docs/gateway-wire.md`): a
//! [`GatewayClient`] sends PIR, DEPOSIT and PING frames over a [`Transport`] (a UDP socket, one
//! frame per datagram, or a serial line, a byte stream) and waits for the matching reply.
//!
//! - **Timeout and retries.** Each request waits [`ClientConfig::timeout`] for its reply and is
//!   sent again up to [`ClientConfig::retries`] times on the same gateway. Replies to other
//!   client IDs (a shared radio channel carries every robot's frames), requests, and replies that
//!   do not answer this request (a late reply to an earlier one) are skipped.
//! - **Backup.** Given a backup ([`GatewayClient::with_backup`]), a request the active gateway
//!   does not answer within its attempts goes to the other gateway, which becomes the active one
//!   ([`GatewayClient::active`]) for the following requests. An error reply is an answer: it does
//!   not switch.
//! - **Deposits at most once.** [`GatewayClient::deposit`] takes the next 1-byte seq itself and
//!   resends the *same* seq until the gateway answers, so a gateway applies it at most once.
//!   The seq memory is the gateway process's: across a switch see [`DepositRetry`] and
//!   `docs/gateway-wire.md` ("The client's backup switch").

use std::collections::VecDeque;
use std::fs::File;
use std::io::{ErrorKind, Read};
use std::net::{SocketAddr, ToSocketAddrs, UdpSocket};
use std::os::fd::OwnedFd;
use std::time::{Duration, Instant};

use pheromone_gateway_codec::{
    decode, encode, DecodeError, DepositRequest, DepositStatus, EncodeError, ErrorReason, Frame,
    Message, PirRequest, StatusReply, MAX_ENCODED_BYTES, MAX_WIRE_BYTES,
};

use super::serial;

/// Deposit seqs remembered per gateway as sent to it (twice the gateway's [`super::SEQ_MEMORY`]:
/// a gateway remembers the seqs it applied, and some sent ones are rejected).
const SENT_MEMORY: usize = 2 * super::SEQ_MEMORY;

/// Why a request failed. Each names the gateway's address (or serial path) and the request.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error(
        "gateway {address}: no answer to {request} after {attempts} attempt(s) of {timeout:?}"
    )]
    Timeout {
        address: String,
        request: &'static str,
        attempts: u32,
        timeout: Duration,
    },
    #[error("gateway {address}: {request} refused by the host (nothing listens on the port)")]
    Unreachable {
        address: String,
        request: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error("gateway {address}: error reply to {request}: M3 reason {} ({reason:?})", reason.code())]
    ErrorReply {
        address: String,
        request: &'static str,
        reason: ErrorReason,
    },
    #[error("gateway {address}: no valid answer to {request}, only a bad frame: {error}")]
    BadFrame {
        address: String,
        request: &'static str,
        error: DecodeError,
    },
    #[error("gateway {address}: {action} failed")]
    Io {
        address: String,
        action: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error("{request} not sent: {source}")]
    Encode {
        request: &'static str,
        #[source]
        source: EncodeError,
    },
}

impl ClientError {
    /// Whether the gateway gave no usable answer (so another gateway may be asked).
    fn no_answer(&self) -> bool {
        !matches!(
            self,
            ClientError::ErrorReply { .. } | ClientError::Encode { .. }
        )
    }
}

/// The two antenna readings of a PIR.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PirReading {
    pub p_left: f32,
    pub p_right: f32,
    /// The field frame they were read from.
    pub frame_seq: u32,
}

/// Which of its gateways the client is using.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Which {
    Primary,
    Backup,
}

/// Where a deposit that its gateway did not answer may be sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DepositRetry {
    /// To the other gateway too, after the switch (with a seq that gateway has not seen from
    /// this client). It is applied unless both fail; it is applied twice if the first gateway
    /// applied it but its reply was lost (or it died between applying and answering).
    #[default]
    AcrossSwitch,
    /// Only to the gateway it was first sent to: a deposit is never applied twice, but one the
    /// first gateway did not answer fails ([`ClientError::Timeout`]; it may have been applied
    /// once). The client still switches for the following requests.
    SameGateway,
}

/// How a client talks to its gateways.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClientConfig {
    /// The client ID in every frame (1–255; the gateway's default allow-list leaves out 0).
    pub client_id: u8,
    /// How long each attempt waits for the reply.
    pub timeout: Duration,
    /// Attempts after the first on the same gateway before switching (or failing).
    pub retries: u32,
    /// The seq of the first deposit. A restarted client should not start where its last run
    /// ended: the gateway remembers the last 16 applied seqs of each client and answers a
    /// remembered one as applied without applying it.
    pub first_seq: u8,
    pub deposit_retry: DepositRetry,
    /// How long a request may keep backing off while its gateway answers "over your rate"
    /// (M3 reason 5) before the request fails with that reply. The client waits 10 ms after the
    /// first such answer, doubling up to 320 ms, then sends the same request again (a deposit
    /// with the same seq); these waits use no attempt and cause no switch.
    pub rate_limited_wait: Duration,
}

impl Default for ClientConfig {
    fn default() -> Self {
        Self {
            client_id: 1,
            timeout: Duration::from_millis(100),
            retries: 2,
            first_seq: 0,
            deposit_retry: DepositRetry::AcrossSwitch,
            rate_limited_wait: Duration::from_secs(5),
        }
    }
}

/// The first wait after a rate-limited answer, and the longest.
const BACKOFF_FIRST: Duration = Duration::from_millis(10);
const BACKOFF_MAX: Duration = Duration::from_millis(320);

enum Link {
    Udp(UdpSocket),
    Serial {
        file: File,
        decoder: Box<pheromone_gateway_codec::Decoder>,
        buf: Box<[u8; 512]>,
        at: usize,
        len: usize,
    },
}

/// One way to a gateway: a UDP socket connected to it, or a serial line.
pub struct Transport {
    name: String,
    link: Link,
}

impl std::fmt::Debug for Transport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Transport")
            .field("name", &self.name)
            .finish()
    }
}

fn io<'a>(
    address: &'a str,
    action: &'static str,
) -> impl FnOnce(std::io::Error) -> ClientError + 'a {
    move |source| ClientError::Io {
        address: address.to_string(),
        action,
        source,
    }
}

impl Transport {
    /// A UDP socket on an ephemeral port, connected to the gateway at `address` (`HOST:PORT`).
    pub fn udp(address: &str) -> Result<Transport, ClientError> {
        let to: SocketAddr = address
            .to_socket_addrs()
            .map_err(io(address, "resolve"))?
            .next()
            .ok_or_else(|| {
                io(address, "resolve")(std::io::Error::new(ErrorKind::NotFound, "no address"))
            })?;
        let local = if to.is_ipv4() { "0.0.0.0:0" } else { "[::]:0" };
        let socket = UdpSocket::bind(local).map_err(io(address, "bind"))?;
        socket.connect(to).map_err(io(address, "connect"))?;
        Ok(Transport {
            name: format!("udp://{to}"),
            link: Link::Udp(socket),
        })
    }

    /// The serial line at `path`, opened raw at `baud`, 8N1 (as the gateway opens its own).
    pub fn serial(path: &str, baud: u32) -> Result<Transport, ClientError> {
        let file = serial::open(path, baud).map_err(|e| match e {
            super::GatewayError::Serial { action, source, .. } => io(path, action)(source),
            other => io(path, "open")(std::io::Error::new(
                ErrorKind::InvalidInput,
                other.to_string(),
            )),
        })?;
        Ok(Self::serial_file(file, path))
    }

    /// A byte stream that is already set up (e.g. the master side of a pseudo-terminal), named
    /// `name` in errors. It is made non-blocking.
    pub fn serial_fd(fd: OwnedFd, name: &str) -> Result<Transport, ClientError> {
        use nix::fcntl::{fcntl, FcntlArg, OFlag};
        let flags = fcntl(&fd, FcntlArg::F_GETFL).map_err(|e| io(name, "get flags")(e.into()))?;
        let flags = OFlag::from_bits_truncate(flags) | OFlag::O_NONBLOCK;
        fcntl(&fd, FcntlArg::F_SETFL(flags)).map_err(|e| io(name, "set O_NONBLOCK")(e.into()))?;
        Ok(Self::serial_file(File::from(fd), name))
    }

    fn serial_file(file: File, name: &str) -> Transport {
        Transport {
            name: name.to_string(),
            link: Link::Serial {
                file,
                decoder: Box::new(pheromone_gateway_codec::Decoder::new()),
                buf: Box::new([0; 512]),
                at: 0,
                len: 0,
            },
        }
    }

    /// The gateway's address (`udp://HOST:PORT`) or the serial line's path.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Drops whatever has arrived and not been read (late replies to earlier requests).
    fn drain(&mut self) {
        match &mut self.link {
            Link::Udp(socket) => {
                let mut buf = [0u8; MAX_WIRE_BYTES + 1];
                if socket.set_nonblocking(true).is_ok() {
                    // Until WouldBlock (or any error: a refusal is seen again on the next receive).
                    while socket.recv(&mut buf).is_ok() {}
                    let _ = socket.set_nonblocking(false);
                }
            }
            Link::Serial {
                file,
                decoder,
                buf,
                at,
                len,
            } => {
                while matches!(file.read(&mut buf[..]), Ok(n) if n > 0) {}
                decoder.reset();
                (*at, *len) = (0, 0);
            }
        }
    }

    fn send(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        match &mut self.link {
            Link::Udp(socket) => socket.send(bytes).map(|_| ()),
            Link::Serial { file, .. } => serial::write_all(file, bytes),
        }
    }

    /// The next frame (or rejected frame) to arrive before `deadline`; `None` if none does.
    fn recv(&mut self, deadline: Instant) -> std::io::Result<Option<Result<Frame, DecodeError>>> {
        match &mut self.link {
            Link::Udp(socket) => {
                let mut buf = [0u8; MAX_WIRE_BYTES + 1];
                loop {
                    let left = deadline.saturating_duration_since(Instant::now());
                    if left.is_zero() {
                        return Ok(None);
                    }
                    socket.set_read_timeout(Some(left.max(Duration::from_micros(100))))?;
                    match socket.recv(&mut buf) {
                        Ok(n) if n > MAX_WIRE_BYTES => return Ok(Some(Err(DecodeError::TooLong))),
                        Ok(n) => {
                            return Ok(Some(
                                decode(&buf[..n]).unwrap_or(Err(DecodeError::Truncated { len: n })),
                            ))
                        }
                        Err(e)
                            if matches!(
                                e.kind(),
                                ErrorKind::WouldBlock
                                    | ErrorKind::TimedOut
                                    | ErrorKind::Interrupted
                            ) => {}
                        Err(e) => return Err(e),
                    }
                }
            }
            Link::Serial {
                file,
                decoder,
                buf,
                at,
                len,
            } => loop {
                while *at < *len {
                    let byte = buf[*at];
                    *at += 1;
                    if let Some(outcome) = decoder.push(byte) {
                        return Ok(Some(outcome));
                    }
                }
                let left = deadline.saturating_duration_since(Instant::now());
                if left.is_zero() {
                    return Ok(None);
                }
                if !serial::wait_readable(&*file, left)? {
                    continue;
                }
                match file.read(&mut buf[..]) {
                    Ok(0) => std::thread::sleep(Duration::from_millis(1).min(left)),
                    Ok(n) => (*at, *len) = (0, n),
                    Err(e)
                        if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::Interrupted) => {}
                    Err(e) => return Err(e),
                }
            },
        }
    }
}

struct Endpoint {
    transport: Transport,
    /// Deposit seqs sent to this gateway, newest last.
    sent: VecDeque<u8>,
}

/// A thin client of one gateway, or of a primary and a backup.
pub struct GatewayClient {
    config: ClientConfig,
    endpoints: Vec<Endpoint>,
    active: usize,
    next_seq: u8,
    switches: u64,
    last_switch: Option<Instant>,
    /// Rate-limited answers the client backed off on.
    backoffs: u64,
}

impl GatewayClient {
    /// A client of the gateway at the other end of `primary`.
    pub fn new(primary: Transport, config: ClientConfig) -> GatewayClient {
        GatewayClient {
            next_seq: config.first_seq,
            config,
            endpoints: vec![Endpoint {
                transport: primary,
                sent: VecDeque::with_capacity(SENT_MEMORY),
            }],
            active: 0,
            switches: 0,
            last_switch: None,
            backoffs: 0,
        }
    }

    /// How many times the client backed off because its gateway answered "over your rate".
    pub fn backoffs(&self) -> u64 {
        self.backoffs
    }

    /// Adds the backup gateway, used when the primary does not answer (and the other way
    /// round).
    pub fn with_backup(mut self, backup: Transport) -> GatewayClient {
        self.endpoints.truncate(1);
        self.endpoints.push(Endpoint {
            transport: backup,
            sent: VecDeque::with_capacity(SENT_MEMORY),
        });
        self
    }

    pub fn config(&self) -> &ClientConfig {
        &self.config
    }

    /// The gateway requests go to now.
    pub fn active(&self) -> Which {
        if self.active == 0 {
            Which::Primary
        } else {
            Which::Backup
        }
    }

    /// The address (or serial path) of the gateway requests go to now.
    pub fn active_address(&self) -> &str {
        self.endpoints[self.active].transport.name()
    }

    /// How many times the client has switched gateways, and when it last did.
    pub fn switches(&self) -> (u64, Option<Instant>) {
        (self.switches, self.last_switch)
    }

    /// The seq the next new deposit takes (unless the active gateway was already sent it).
    pub fn next_seq(&self) -> u8 {
        self.next_seq
    }

    /// Reads the two antennas at `half_wheel_base_m` to each side of the pose on `channel`.
    pub fn pir(
        &mut self,
        x_m: f32,
        y_m: f32,
        theta_rad: f32,
        half_wheel_base_m: f32,
        channel: u8,
    ) -> Result<PirReading, ClientError> {
        let message = Message::Pir(PirRequest {
            x_m,
            y_m,
            theta_rad,
            half_wheel_base_m,
            channel,
        });
        match self.request(
            "PIR",
            true,
            |_| message,
            |m, _| matches!(m, Message::PirReply(_)),
        )? {
            Message::PirReply(r) => Ok(PirReading {
                p_left: r.p_left,
                p_right: r.p_right,
                frame_seq: r.frame_seq,
            }),
            _ => unreachable!("accepted only a PIR reply"),
        }
    }

    /// Deposits `amount` at (x, y) on `channel` (a Z-shape reinforcement); returns the seq the
    /// gateway applied it under. Retries resend the same seq, so the gateway applies it once;
    /// a refused deposit (status ≠ 0) is [`ClientError::ErrorReply`] and not applied.
    pub fn deposit(
        &mut self,
        x_m: f32,
        y_m: f32,
        amount: f32,
        channel: u8,
    ) -> Result<u8, ClientError> {
        let across = self.config.deposit_retry == DepositRetry::AcrossSwitch;
        // The seq each gateway was sent for this deposit; the first one chosen is kept on the
        // other gateway unless that one was sent it recently (it could take the deposit for a
        // retry of an earlier one and not apply it).
        let mut seqs: [Option<u8>; 2] = [None, None];
        let mut chosen: Option<u8> = None;
        let reply = self.request(
            "DEPOSIT",
            across,
            |client| {
                let active = client.active;
                let seq = match seqs[active] {
                    Some(seq) => seq,
                    None => {
                        let sent = &client.endpoints[active].sent;
                        let seq = match chosen {
                            Some(seq) if !sent.contains(&seq) => seq,
                            _ => {
                                let mut seq = client.next_seq;
                                while sent.contains(&seq) {
                                    seq = seq.wrapping_add(1);
                                }
                                client.next_seq = seq.wrapping_add(1);
                                seq
                            }
                        };
                        chosen.get_or_insert(seq);
                        let sent = &mut client.endpoints[active].sent;
                        if sent.len() == SENT_MEMORY {
                            sent.pop_front();
                        }
                        sent.push_back(seq);
                        seqs[active] = Some(seq);
                        seq
                    }
                };
                Message::Deposit(DepositRequest {
                    seq,
                    x_m,
                    y_m,
                    amount,
                    channel,
                })
            },
            |m, sent| match (m, sent) {
                (Message::DepositReply(r), Message::Deposit(d)) => r.seq == d.seq,
                _ => false,
            },
        )?;
        let Message::DepositReply(r) = reply else {
            unreachable!("accepted only a deposit reply")
        };
        match r.status {
            DepositStatus::Applied => Ok(r.seq),
            DepositStatus::Rejected(reason) => Err(ClientError::ErrorReply {
                address: self.active_address().to_string(),
                request: "DEPOSIT",
                reason,
            }),
        }
    }

    /// The gateway's status: newest frame, field time, channels.
    pub fn ping(&mut self) -> Result<StatusReply, ClientError> {
        match self.request(
            "PING",
            true,
            |_| Message::Ping,
            |m, _| matches!(m, Message::Status(_)),
        )? {
            Message::Status(s) => Ok(s),
            _ => unreachable!("accepted only a status reply"),
        }
    }

    /// Sends the request `build` makes for the active gateway until a reply `accept`s; if the
    /// active gateway gives no answer in its attempts, switches to the other and (if
    /// `resend_elsewhere`) asks it.
    fn request(
        &mut self,
        request: &'static str,
        resend_elsewhere: bool,
        mut build: impl FnMut(&mut GatewayClient) -> Message,
        accept: impl Fn(&Message, &Message) -> bool,
    ) -> Result<Message, ClientError> {
        let mut last = None;
        for round in 0..self.endpoints.len() {
            if round > 0 {
                self.switch();
                if !resend_elsewhere {
                    break;
                }
            }
            let message = build(self);
            match self.ask(request, &message, &accept) {
                Ok(reply) => return Ok(reply),
                Err(e) if e.no_answer() => last = Some(e),
                Err(e) => return Err(e),
            }
        }
        Err(last.expect("at least one gateway was asked"))
    }

    fn switch(&mut self) {
        self.active = (self.active + 1) % self.endpoints.len();
        self.switches += 1;
        self.last_switch = Some(Instant::now());
    }

    /// Asks the active gateway, `1 + retries` times at most; an answer "over your rate" (M3
    /// reason 5) is waited out with a growing backoff (`rate_limited_wait` in all) and the same
    /// request sent again, using no attempt.
    fn ask(
        &mut self,
        request: &'static str,
        message: &Message,
        accept: &impl Fn(&Message, &Message) -> bool,
    ) -> Result<Message, ClientError> {
        let id = self.config.client_id;
        let mut out = [0u8; MAX_ENCODED_BYTES];
        let n = encode(message, id, &mut out)
            .map_err(|source| ClientError::Encode { request, source })?;
        let (timeout, attempts) = (self.config.timeout, 1 + self.config.retries);
        let backoff_end = Instant::now() + self.config.rate_limited_wait;
        let mut backoff = BACKOFF_FIRST;
        let transport = &mut self.endpoints[self.active].transport;
        let address = transport.name.clone();
        let (mut bad, mut refused) = (None, None);
        let mut attempt = 0;
        while attempt < attempts {
            attempt += 1;
            transport.drain();
            match transport.send(&out[..n]) {
                Ok(()) => {}
                Err(e) if e.kind() == ErrorKind::ConnectionRefused => {
                    refused = Some(e);
                    continue;
                }
                Err(source) => return Err(io(&address, "send")(source)),
            }
            let answer = await_reply(transport, id, message, accept, Instant::now() + timeout);
            match answer {
                Ok(Answer::Reply(reply)) => return Ok(reply),
                Ok(Answer::Error(ErrorReason::RateLimited))
                    if Instant::now() + backoff <= backoff_end =>
                {
                    // Over the rate: wait (a late answer is read and dropped meanwhile), then
                    // send the same request again; not an attempt.
                    self.backoffs += 1;
                    wait_out(transport, Instant::now() + backoff);
                    backoff = (backoff * 2).min(BACKOFF_MAX);
                    attempt -= 1;
                }
                Ok(Answer::Error(reason)) => {
                    return Err(ClientError::ErrorReply {
                        address,
                        request,
                        reason,
                    })
                }
                Ok(Answer::None { bad_frame }) => bad = bad_frame.or(bad),
                Err(e) if e.kind() == ErrorKind::ConnectionRefused => refused = Some(e),
                Err(source) => return Err(io(&address, "receive")(source)),
            }
        }
        Err(if let Some(error) = bad {
            ClientError::BadFrame {
                address,
                request,
                error,
            }
        } else if let Some(source) = refused {
            ClientError::Unreachable {
                address,
                request,
                source,
            }
        } else {
            ClientError::Timeout {
                address,
                request,
                attempts,
                timeout,
            }
        })
    }
}

/// What one attempt got back.
enum Answer {
    /// The reply `accept` took.
    Reply(Message),
    /// An error reply (`0xFF`).
    Error(ErrorReason),
    /// Nothing usable before the deadline (the last bad frame, if one came).
    None { bad_frame: Option<DecodeError> },
}

/// Reads until the reply to `message` from client `id` (or an error reply) arrives, or
/// `deadline`.
fn await_reply(
    transport: &mut Transport,
    id: u8,
    message: &Message,
    accept: &impl Fn(&Message, &Message) -> bool,
    deadline: Instant,
) -> std::io::Result<Answer> {
    let mut bad_frame = None;
    loop {
        match transport.recv(deadline)? {
            None => return Ok(Answer::None { bad_frame }),
            Some(Ok(frame)) => {
                if frame.client_id != id || !frame.message.is_reply() {
                    continue;
                }
                if let Message::Error(reason) = frame.message {
                    return Ok(Answer::Error(reason));
                }
                if accept(&frame.message, message) {
                    return Ok(Answer::Reply(frame.message));
                }
            }
            Some(Err(e)) => bad_frame = Some(e),
        }
    }
}

/// Reads and drops whatever arrives until `until`: the backoff after a rate-limited answer.
fn wait_out(transport: &mut Transport, until: Instant) {
    while Instant::now() < until {
        if transport.recv(until).is_err() {
            break;
        }
    }
}

#[cfg(test)]
mod tests;
