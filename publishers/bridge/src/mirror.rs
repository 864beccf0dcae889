//! `Mirror`: a field on another host fed by its origin's inputs over Zenoh. It starts from a
//! keyframe, replays each frame's deposit list with the same `Stepper`, publishes the frames with
//! the origin's sequence numbers in local shared memory, checks the origin's checksums, and asks
//! for a keyframe on a mismatch, a sequence gap, a new origin epoch or a silent origin (then it
//! is `stale` until live inputs come again). Deposits made on its host go to the origin in
//! numbered batches, each kept until the bridge answers it and sent again while unanswered
//! (`batches`); while the mirror is stale they are held (at most `HELD_MAX`) and sent once it is
//! live again.
//!
//! Requests never block a round: a keyframe (and, for a new origin run, its configuration) is
//! asked with a Zenoh `get` whose replies are polled each round, while the inputs keep being
//! drained into `pending`. The state (configuration, epoch) is taken only from a keyframe and
//! the configuration of the same epoch, never from an inputs list.

use std::collections::{BTreeMap, VecDeque};
use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use pheromone_field::messages::InputsHeader;
use pheromone_field::messages::MirrorState;
use pheromone_field::shm::{now_ns, FieldServer, MirrorStateWriter, Svc};
use pheromone_field::{DepositMsg, FieldConfig, FrameHeader};
use zenoh::handlers::FifoChannelHandler;
use zenoh::query::Reply;
use zenoh::sample::Sample;
use zenoh::Wait;

use super::batches::{self, Outbox};
use super::codec::{self, frame_checksum};
use super::{zerr, BridgeError, Keys, REQUEST_TIMEOUT};

#[derive(Debug, Clone, PartialEq)]
pub struct MirrorOptions {
    pub field: String,
    /// Zenoh endpoints of the bridge, e.g. `tcp/10.0.0.1:7447`.
    pub connect: Vec<String>,
    /// No inputs for this long: the mirror is stale (and asks for keyframes).
    pub stale_after: Duration,
    /// TLS, credentials and access control of the session.
    pub security: super::Security,
}

/// What a mirror did, cumulative.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct MirrorStats {
    pub frames_applied: u64,
    pub keyframes_applied: u64,
    pub keyframe_requests: u64,
    pub checksums_matched: u64,
    pub checksum_mismatches: u64,
    pub gaps: u64,
    pub epochs: u64,
    pub rejected_inputs: u64,
    pub rejected_keyframes: u64,
    pub rejected_other: u64,
    /// Local deposits sent to the origin (each once; resends are counted in
    /// `deposit_batches_resent`).
    pub deposits_forwarded: u64,
    /// Local deposits refused because more than `HELD_MAX` (100,000) waited for the origin (the oldest
    /// go).
    pub deposits_refused: u64,
    /// Deposits the bridge answered as handed to the origin's field, and as refused there.
    pub deposits_confirmed: u64,
    pub deposits_refused_by_origin: u64,
    /// Local deposits sent or held, not answered yet (now).
    pub deposits_unconfirmed: u64,
    /// Batches sent again because no answer came within `batches::RESEND_AFTER`.
    pub deposit_batches_resent: u64,
    /// Batches unanswered `batches::UNANSWERED_WARN_AFTER` after their first send (each said
    /// once on stderr).
    pub deposit_batches_overdue: u64,
    pub stale_periods: u64,
    pub last_sequence: u64,
    /// Wall time from the last keyframe request to the keyframe published locally (ms).
    pub last_catch_up_ms: f64,
    /// Keyframes (or configurations) refused because they do not fit the origin's
    /// configuration of their epoch (cells or grid of another size).
    pub mismatched_keyframes: u64,
    pub last_keyframe_bytes: u64,
}

type Sub = zenoh::pubsub::Subscriber<FifoChannelHandler<Sample>>;

/// A keyframe or configuration request whose replies are polled each round.
struct Request {
    replies: FifoChannelHandler<Reply>,
    /// `None`: the keyframe is asked; `Some(keyframe)`: the configuration of its run is.
    keyframe: Option<Keyframe>,
    /// When the keyframe was asked (catch-up time).
    started: Instant,
}

pub struct Mirror {
    o: MirrorOptions,
    keys: Keys,
    session: zenoh::Session,
    inputs_sub: Sub,
    checksum_sub: Sub,
    keyframe_sub: Sub,
    deposit_pub: zenoh::pubsub::Publisher<'static>,
    ack_sub: Sub,
    /// Local deposits taken from the field's queue, kept until the bridge answers them.
    outbox: Outbox,
    server: Option<FieldServer>,
    config: Option<FieldConfig>,
    /// The origin run the local frames come from (set from a keyframe and its configuration).
    epoch: u64,
    /// The origin run of the newest inputs seen (`pending` holds only its lists).
    input_epoch: u64,
    request: Option<Request>,
    pending: BTreeMap<u64, (InputsHeader, Vec<DepositMsg>)>,
    own_sums: VecDeque<(u64, u64)>,
    origin_sums: BTreeMap<u64, u64>,
    every: Option<u64>,
    need_keyframe: bool,
    last_input_at: Instant,
    last_request: Option<Instant>,
    stale: bool,
    /// What readers on this host see of the mirror (created with the local field).
    state: Option<MirrorStateWriter>,
    /// CLOCK_MONOTONIC (ns) of the newest inputs, and of the last time it went stale.
    last_input_ns: u64,
    stale_since_ns: u64,
    /// Origin publish → mirror publish (ns, CLOCK_MONOTONIC: meaningful when both run on one
    /// host, as in `pheromone bench`), one per applied frame, the latest 100 000.
    pub lags_ns: VecDeque<u64>,
    pub stats: MirrorStats,
}

/// A keyframe of another run than the local field's, kept while its configuration is asked.
struct Keyframe {
    epoch: u64,
    header: FrameHeader,
    cells: Vec<f32>,
    /// Its size on the wire.
    bytes: usize,
}

/// Whether a keyframe's header and cells are a frame of `config`'s grid.
fn fits(config: &FieldConfig, h: &FrameHeader, cells: &[f32]) -> bool {
    h.width == config.width
        && h.height == config.height
        && h.channels as usize == config.channels.len()
        && cells.len() == config.frame_len()
}

const SUMS_KEPT: usize = 64;
/// Inputs lists kept while a keyframe is awaited.
const MAX_PENDING: usize = 4096;
/// A stale mirror holds at most this many local deposits for its origin.
pub const HELD_MAX: usize = 100_000;

/// A keyframe request that got no usable answer is sent again this long after.
const RETRY_AFTER: Duration = Duration::from_millis(200);

impl Mirror {
    /// Opens the session (it connects, and reconnects, in the background).
    pub fn start(o: MirrorOptions) -> Result<Self, BridgeError> {
        let keys = Keys::of(&o.field);
        let config = super::session_config_with(&o.security, "peer", &[], &o.connect)?;
        let session = zenoh::open(config)
            .wait()
            .map_err(|e| zerr(&format!("connect to {:?}", o.connect), e))?;
        let sub = |key: &str| {
            session
                .declare_subscriber(key.to_string())
                .wait()
                .map_err(|e| zerr(&format!("subscribe {key}"), e))
        };
        let inputs_sub = sub(&keys.inputs)?;
        let checksum_sub = sub(&keys.checksum)?;
        let keyframe_sub = sub(&keys.keyframe)?;
        let ack_sub = sub(&keys.deposit_ack)?;
        let deposit_pub = session
            .declare_publisher(keys.deposit.clone())
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .wait()
            .map_err(|e| zerr("declare the deposit publisher", e))?;
        Ok(Self {
            o,
            keys,
            session,
            inputs_sub,
            checksum_sub,
            keyframe_sub,
            deposit_pub,
            ack_sub,
            // One id per mirror run: the bridge tells its batches from another run's.
            outbox: Outbox::new((now_ns() ^ (u64::from(std::process::id()) << 40)) | 1),
            server: None,
            config: None,
            epoch: 0,
            input_epoch: 0,
            request: None,
            pending: BTreeMap::new(),
            own_sums: VecDeque::new(),
            origin_sums: BTreeMap::new(),
            every: None,
            need_keyframe: true,
            last_input_at: Instant::now(),
            last_request: None,
            stale: true,
            state: None,
            last_input_ns: 0,
            stale_since_ns: now_ns(),
            lags_ns: VecDeque::new(),
            stats: MirrorStats::default(),
        })
    }

    /// The options it was started with.
    pub fn options(&self) -> &MirrorOptions {
        &self.o
    }

    pub fn is_stale(&self) -> bool {
        self.stale
    }

    /// The local field, once the first keyframe came.
    pub fn server(&self) -> Option<&FieldServer> {
        self.server.as_ref()
    }

    /// One round: waits up to `timeout` for the origin's inputs, applies what can be applied,
    /// checks checksums, forwards local deposits, and resyncs from a keyframe when needed
    /// (asking without waiting for the answer: it is taken in a later round).
    pub fn step(&mut self, node: &Node<Svc>, timeout: Duration) -> Result<(), BridgeError> {
        // Asked once inputs came: the keyframe must be of the run whose inputs arrive.
        if self.need_keyframe
            && self.input_epoch != 0
            && self.request.is_none()
            && self.last_request.is_none_or(|t| t.elapsed() >= RETRY_AFTER)
        {
            self.ask(None, Instant::now())?;
        }
        let first = self
            .inputs_sub
            .recv_timeout(timeout)
            .map_err(|e| zerr("receive inputs", e))?;
        let mut inputs: Vec<Sample> = first.into_iter().collect();
        while let Ok(Some(s)) = self.inputs_sub.try_recv() {
            inputs.push(s);
        }
        for s in inputs {
            self.take_inputs(&s.payload().to_bytes());
        }
        self.poll_request(node)?;
        while let Ok(Some(s)) = self.keyframe_sub.try_recv() {
            match codec::decode_keyframe(&s.payload().to_bytes()) {
                Ok((epoch, h, cells)) => {
                    // A periodic keyframe of the run the local field follows.
                    if self.need_keyframe
                        && epoch == self.epoch
                        && epoch == self.input_epoch
                        && self.server.is_some()
                    {
                        let started = self.request.as_ref().map(|r| r.started);
                        if self.apply_keyframe(&h, &cells, s.payload().len(), started)? {
                            self.request = None;
                        }
                    }
                }
                Err(e) => self.reject_keyframe(&e),
            }
        }
        self.apply_pending()?;
        while let Ok(Some(s)) = self.checksum_sub.try_recv() {
            match codec::decode_checksum(&s.payload().to_bytes()) {
                Ok((epoch, seq, sum, every)) if epoch == self.epoch => {
                    self.every = Some(every as u64);
                    self.origin_sums.insert(seq, sum);
                }
                Ok(_) => {}
                Err(e) => {
                    self.stats.rejected_other += 1;
                    eprintln!("mirror '{}': rejected a checksum: {e}", self.o.field);
                }
            }
        }
        self.compare_checksums();
        self.forward_deposits()?;
        let silent = self.last_input_at.elapsed() >= self.o.stale_after;
        if silent && !self.stale {
            self.stale = true;
            self.stale_since_ns = now_ns();
            self.need_keyframe = true;
            self.stats.stale_periods += 1;
            eprintln!(
                "mirror '{}': stale: no inputs from the origin for {:.1} s; frames stay at {}",
                self.o.field,
                self.last_input_at.elapsed().as_secs_f64(),
                self.stats.last_sequence
            );
        }
        self.publish_state(node)
    }

    /// Tells readers on this host the mirror's state, and hands readers that attached since the
    /// last frame the current one: a stale mirror publishes no frames, and iceoryx2 delivers a
    /// publisher's history only when it sends or updates its connections.
    fn publish_state(&mut self, node: &Node<Svc>) -> Result<(), BridgeError> {
        let Some(server) = &self.server else {
            return Ok(());
        };
        server.serve_new_readers()?;
        if self.state.is_none() {
            self.state = Some(MirrorStateWriter::create(node, &self.o.field)?);
        }
        if let Some(w) = &self.state {
            w.set(MirrorState {
                stale: u32::from(self.stale),
                _reserved: 0,
                last_inputs_ns: self.last_input_ns,
                stale_since_ns: if self.stale { self.stale_since_ns } else { 0 },
                stale_periods: self.stats.stale_periods,
                last_sequence: self.stats.last_sequence,
            });
        }
        Ok(())
    }

    fn take_inputs(&mut self, bytes: &[u8]) {
        match codec::decode_inputs(bytes) {
            Ok((h, deposits)) => {
                self.last_input_at = Instant::now();
                self.last_input_ns = now_ns();
                if h.epoch != self.input_epoch {
                    // A new origin run (restart): its sequence starts again. The local field
                    // changes run only with a keyframe and the configuration of that run.
                    if self.input_epoch != 0 {
                        eprintln!(
                            "mirror '{}': the origin restarted (epoch {:x} → {:x}); asking for a keyframe",
                            self.o.field, self.input_epoch, h.epoch
                        );
                    }
                    self.input_epoch = h.epoch;
                    self.pending.clear();
                    if h.epoch != self.epoch {
                        self.need_keyframe = true;
                        self.last_request = None;
                    }
                }
                self.pending.insert(h.sequence, (h, deposits));
                // Bounded while waiting for a keyframe: the oldest are the ones it will cover.
                while self.pending.len() > MAX_PENDING {
                    self.pending.pop_first();
                }
            }
            Err(e) => {
                self.stats.rejected_inputs += 1;
                eprintln!("mirror '{}': rejected an inputs list: {e}", self.o.field);
            }
        }
    }

    fn reject_keyframe(&mut self, e: &codec::CodecError) {
        self.stats.rejected_keyframes += 1;
        eprintln!("mirror '{}': rejected a keyframe: {e}", self.o.field);
    }

    /// Sends a `get` for a keyframe (`keyframe` = `None`) or for the configuration of the
    /// keyframe's run; `poll_request` takes the answer. `started`: when the resync began.
    fn ask(&mut self, keyframe: Option<Keyframe>, started: Instant) -> Result<(), BridgeError> {
        let key = match keyframe {
            None => {
                self.last_request = Some(Instant::now());
                self.stats.keyframe_requests += 1;
                self.keys.keyframe.clone()
            }
            Some(_) => self.keys.config.clone(),
        };
        let replies = self
            .session
            .get(key.clone())
            .timeout(REQUEST_TIMEOUT)
            .wait()
            .map_err(|e| zerr(&format!("get {key}"), e))?;
        self.request = Some(Request {
            replies,
            keyframe,
            started,
        });
        Ok(())
    }

    /// Takes the answer to the request in flight, if it came (never waits). A request that
    /// ended without a usable answer is asked again `RETRY_AFTER` after it was sent.
    fn poll_request(&mut self, node: &Node<Svc>) -> Result<(), BridgeError> {
        let Some(r) = self.request.as_ref() else {
            return Ok(());
        };
        let bytes = loop {
            match r.replies.try_recv() {
                Ok(Some(reply)) => {
                    if let Ok(sample) = reply.result() {
                        break sample.payload().to_bytes().into_owned();
                    }
                }
                Ok(None) => return Ok(()),
                // Every reply came (or the request timed out), none usable.
                Err(_) => {
                    self.request = None;
                    return Ok(());
                }
            }
        };
        let r = self.request.take().expect("looked at above");
        if !self.need_keyframe {
            // A periodic keyframe came first.
            return Ok(());
        }
        match r.keyframe {
            None => self.take_keyframe(&bytes, r.started),
            Some(k) => self.take_config(node, k, &bytes, r.started),
        }
    }

    /// A keyframe answered: applied at once when it is of the run the local field follows;
    /// for another run, that run's configuration is asked first.
    fn take_keyframe(&mut self, bytes: &[u8], started: Instant) -> Result<(), BridgeError> {
        let (epoch, header, cells) = match codec::decode_keyframe(bytes) {
            Ok(k) => k,
            Err(e) => {
                self.reject_keyframe(&e);
                return Ok(());
            }
        };
        if epoch != self.input_epoch {
            // Not the run whose inputs come now (one restarted meanwhile): asked again.
            return Ok(());
        }
        if epoch == self.epoch && self.server.is_some() {
            self.apply_keyframe(&header, &cells, bytes.len(), Some(started))?;
            return Ok(());
        }
        let k = Keyframe {
            epoch,
            header,
            cells,
            bytes: bytes.len(),
        };
        self.ask(Some(k), started)
    }

    /// The configuration of a keyframe's run answered: the local field follows that run from
    /// the keyframe, started again when the configuration differs (e.g. another grid).
    fn take_config(
        &mut self,
        node: &Node<Svc>,
        k: Keyframe,
        bytes: &[u8],
        started: Instant,
    ) -> Result<(), BridgeError> {
        let (cepoch, toml) = match codec::decode_config(bytes) {
            Ok(c) => c,
            Err(e) => {
                self.stats.rejected_other += 1;
                eprintln!("mirror '{}': rejected a configuration: {e}", self.o.field);
                return Ok(());
            }
        };
        if cepoch != k.epoch || k.epoch != self.input_epoch {
            // The origin restarted between the two answers: asked again.
            return Ok(());
        }
        let config =
            FieldConfig::from_toml(&toml).map_err(|e| BridgeError::Config(e.to_string()))?;
        config
            .validate()
            .map_err(|e| BridgeError::Config(e.to_string()))?;
        if !fits(&config, &k.header, &k.cells) {
            self.stats.mismatched_keyframes += 1;
            eprintln!(
                "mirror '{}': keyframe {} ({}x{}x{}, {} cells) does not fit its run's configuration ({}x{}x{}); asking again",
                self.o.field,
                k.header.sequence,
                k.header.width,
                k.header.height,
                k.header.channels,
                k.cells.len(),
                config.width,
                config.height,
                config.channels.len()
            );
            return Ok(());
        }
        if self.epoch != k.epoch {
            self.epoch = k.epoch;
            self.stats.epochs += 1;
            self.origin_sums.clear();
            self.own_sums.clear();
            self.every = None;
        }
        if self.config.as_ref() == Some(&config) && self.server.is_some() {
            self.apply_keyframe(&k.header, &k.cells, k.bytes, Some(started))?;
            return Ok(());
        }
        // First start, or an origin restarted with another configuration (another grid):
        // the local field starts again with it, from the keyframe.
        if let Some(old) = &self.config {
            eprintln!(
                "mirror '{}': the origin runs another configuration ({}x{}x{} → {}x{}x{}); following it",
                self.o.field,
                old.width,
                old.height,
                old.channels.len(),
                config.width,
                config.height,
                config.channels.len()
            );
        }
        self.server = None;
        let server = FieldServer::start(
            node,
            &self.o.field,
            config.clone(),
            Some((k.header, &k.cells)),
        )?;
        self.server = Some(server);
        self.config = Some(config);
        self.finish_keyframe(&k.header, k.bytes, Some(started));
        Ok(())
    }

    /// Publishes a keyframe of the run the local field follows; false (and counted) when it
    /// does not fit the local configuration.
    fn apply_keyframe(
        &mut self,
        h: &FrameHeader,
        cells: &[f32],
        bytes: usize,
        started: Option<Instant>,
    ) -> Result<bool, BridgeError> {
        let (Some(server), Some(config)) = (self.server.as_mut(), self.config.as_ref()) else {
            return Ok(false);
        };
        if !fits(config, h, cells) {
            self.stats.mismatched_keyframes += 1;
            eprintln!(
                "mirror '{}': keyframe {} ({}x{}x{}) does not fit the configuration of its run; ignored",
                self.o.field, h.sequence, h.width, h.height, h.channels
            );
            return Ok(false);
        }
        // Every frame published first takes the local deposits queued so far (`apply_pending`).
        self.outbox.push(server.take_local_deposits()?);
        server.reset_to(h, cells)?;
        self.finish_keyframe(h, bytes, started);
        Ok(true)
    }

    /// After a keyframe is published: counters, and the frames since it come from the inputs.
    /// The mirror stays stale until live inputs are applied on top of it.
    fn finish_keyframe(&mut self, h: &FrameHeader, bytes: usize, started: Option<Instant>) {
        if let Some(t) = started {
            self.stats.last_catch_up_ms = t.elapsed().as_secs_f64() * 1e3;
        }
        self.stats.last_keyframe_bytes = bytes as u64;
        self.stats.keyframes_applied += 1;
        self.stats.last_sequence = h.sequence;
        self.need_keyframe = false;
        self.request = None;
        self.pending.retain(|_, (ih, _)| ih.epoch == self.epoch);
        eprintln!(
            "mirror '{}': keyframe {} published ({} bytes, {:.1} ms after the request)",
            self.o.field, h.sequence, bytes, self.stats.last_catch_up_ms
        );
        self.record_own_sum();
    }

    fn apply_pending(&mut self) -> Result<(), BridgeError> {
        if self.need_keyframe || self.server.is_none() {
            return Ok(());
        }
        while let Some((&seq, _)) = self.pending.first_key_value() {
            let current = self.stats.last_sequence;
            if seq <= current {
                self.pending.pop_first();
                continue;
            }
            if seq != current + 1 {
                self.stats.gaps += 1;
                eprintln!(
                    "mirror '{}': gap: frame {} follows {current}; asking for a keyframe",
                    self.o.field, seq
                );
                self.need_keyframe = true;
                self.last_request = None;
                return Ok(());
            }
            let (h, deposits) = self.pending.pop_first().expect("just looked").1;
            let server = self.server.as_mut().expect("checked above");
            // Every frame drains the local queue, as a field's tick does (also when one round
            // applies several): confirmed deposits are answered "forwarded", and a local
            // depositor's flush request "flushed", once they left the queue.
            self.outbox.push(server.take_local_deposits()?);
            let refused = server.apply_inputs(&h, &deposits)?;
            if refused > 0 {
                eprintln!(
                    "mirror '{}': {refused} deposit(s) of frame {seq} refused here: the configurations differ",
                    self.o.field
                );
            }
            self.lags_ns.push_back(now_ns().saturating_sub(h.stamp_ns));
            if self.lags_ns.len() > 100_000 {
                self.lags_ns.pop_front();
            }
            self.stats.frames_applied += 1;
            self.stats.last_sequence = seq;
            self.record_own_sum();
            if self.stale {
                // Live inputs on top of the keyframe: the origin is back.
                self.stale = false;
                eprintln!("mirror '{}': live at frame {seq}", self.o.field);
            }
        }
        Ok(())
    }

    fn record_own_sum(&mut self) {
        let (Some(every), Some(server)) = (self.every, self.server.as_ref()) else {
            return;
        };
        let seq = self.stats.last_sequence;
        if seq.is_multiple_of(every) || self.origin_sums.contains_key(&seq) {
            if let Some(cells) = server.latest_cells() {
                self.own_sums.push_back((seq, frame_checksum(cells)));
                if self.own_sums.len() > SUMS_KEPT {
                    self.own_sums.pop_front();
                }
            }
        }
        self.compare_checksums();
    }

    fn compare_checksums(&mut self) {
        let mut mismatch = None;
        self.origin_sums.retain(|seq, sum| {
            match self.own_sums.iter().find(|(s, _)| s == seq) {
                Some((_, own)) => {
                    if own == sum {
                        self.stats.checksums_matched += 1;
                    } else {
                        self.stats.checksum_mismatches += 1;
                        mismatch = Some(*seq);
                    }
                    false
                }
                // Not computed here yet (the mirror is behind); drop those long past.
                None => *seq + 4 * SUMS_KEPT as u64 > self.stats.last_sequence,
            }
        });
        if let Some(seq) = mismatch {
            eprintln!(
                "mirror '{}': checksum mismatch at frame {seq}; asking for a keyframe",
                self.o.field
            );
            self.need_keyframe = true;
            self.last_request = None;
        }
    }

    fn forward_deposits(&mut self) -> Result<(), BridgeError> {
        self.take_answers();
        let Some(server) = self.server.as_mut() else {
            return Ok(());
        };
        self.outbox.push(server.take_local_deposits()?);
        let excess = self.outbox.trim_to(HELD_MAX);
        if excess > 0 {
            self.stats.deposits_refused += excess;
            eprintln!(
                "mirror '{}': {HELD_MAX} local deposits wait for the origin; {excess} older ones refused",
                self.o.field
            );
        }
        self.stats.deposits_unconfirmed = self.outbox.deposits() as u64;
        if self.stale {
            // No origin hears them now: a partition longer than Zenoh's lease closes the
            // session, and a put no subscriber matches is dropped without a word. Held until
            // live inputs come again, then sent.
            return Ok(());
        }
        let now = Instant::now();
        for (batch, deposits, resend) in self.outbox.due(now) {
            let bytes = codec::encode_deposits(self.outbox.mirror_id(), batch, &deposits);
            self.deposit_pub
                .put(bytes)
                .wait()
                .map_err(|e| zerr("put deposits", e))?;
            if resend {
                self.stats.deposit_batches_resent += 1;
            } else {
                self.stats.deposits_forwarded += deposits.len() as u64;
            }
        }
        for (batch, n, times) in self.outbox.overdue(now) {
            self.stats.deposit_batches_overdue += 1;
            eprintln!(
                "mirror '{}': batch {batch} ({n} deposits) unanswered by the origin's bridge \
                 after {times} sends in {:.0} s; still sending it (an access rule denying puts \
                 on {} would do this)",
                self.o.field,
                batches::UNANSWERED_WARN_AFTER.as_secs_f64(),
                self.keys.deposit
            );
        }
        Ok(())
    }

    /// The bridge's answers to this mirror's batches.
    fn take_answers(&mut self) {
        while let Ok(Some(s)) = self.ack_sub.try_recv() {
            match codec::decode_deposit_ack(&s.payload().to_bytes()) {
                Ok(ack) => {
                    let Some(a) = self.outbox.answer(&ack) else {
                        continue;
                    };
                    self.stats.deposits_confirmed += a.forwarded;
                    self.stats.deposits_refused_by_origin += a.refused;
                    if a.refused > 0 {
                        eprintln!(
                            "mirror '{}': the origin's field refused {} deposit(s) of batch {}",
                            self.o.field, a.refused, ack.batch
                        );
                    }
                }
                Err(e) => {
                    self.stats.rejected_other += 1;
                    eprintln!("mirror '{}': rejected a deposit answer: {e}", self.o.field);
                }
            }
        }
    }

    pub fn close(self) {
        let n = self.outbox.deposits();
        if n > 0 {
            eprintln!(
                "mirror '{}': closing with {n} local deposit(s) in {} batch(es) the origin has not \
                 confirmed (sent or held): they may be lost",
                self.o.field,
                self.outbox.batches()
            );
        }
        // A session that fails to close ends with the process.
        let _ = self.session.close().wait();
    }
}
