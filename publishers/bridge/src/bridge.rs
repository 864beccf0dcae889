//! `Bridge`: the origin host's side. It reads the field's inputs and frames from shared memory
//! and publishes them on Zenoh; it forwards the deposits mirrors send to the field.

use std::time::{Duration, Instant};

use iceoryx2::node::Node;
use pheromone_field::shm::{DepositPublisher, FieldReader, InputsSubscriber, SendError, Svc};
use pheromone_field::DepositMsg;
use zenoh::qos::CongestionControl;
use zenoh::Wait;

use super::batches::Seen;
use super::codec::{self, frame_checksum};
use super::journal::{self, Journal};
use super::{zerr, BridgeError, Keys, REQUEST_TIMEOUT};

/// `--frames`: downsampled compressed frames for consumers without a mirror.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FramesOptions {
    pub rate_hz: f64,
    pub downsample: u32,
}

#[derive(Debug, Clone, PartialEq)]
pub struct BridgeOptions {
    pub field: String,
    /// Zenoh endpoints to listen on, e.g. `tcp/0.0.0.0:7447`.
    pub listen: Vec<String>,
    /// Publish a frame checksum every this many frames (sequence numbers divisible by it).
    pub checksum_every: u32,
    /// Publish a keyframe this often (and on request).
    pub keyframe_every: Duration,
    pub frames: Option<FramesOptions>,
    /// Turn on the session's read-only admin space, so [`Bridge::listen_locators`] can tell the
    /// ports it listens on (`--print-address`).
    pub admin_space: bool,
    /// TLS, credentials and access control of the session.
    pub security: super::Security,
}

/// What a bridge did, cumulative.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct BridgeStats {
    pub inputs_sent: u64,
    pub deposits_in_inputs: u64,
    pub checksums_sent: u64,
    pub keyframes_sent: u64,
    pub keyframe_requests: u64,
    pub frames_sent: u64,
    /// Bytes put on the wire (envelopes included), by kind.
    pub inputs_bytes: u64,
    pub keyframe_bytes: u64,
    pub other_bytes: u64,
    pub last_keyframe_bytes: u64,
    pub deposits_forwarded: u64,
    /// Mirrors' deposits the origin's deposit service did not take (its queue refused them).
    pub deposits_refused: u64,
    /// Deposit batches answered, and those of them that came again (a mirror that missed the
    /// answer): answered again, not handed to the field twice.
    pub deposit_batches: u64,
    pub deposit_batches_repeated: u64,
    /// Deposit messages from mirrors that failed their checks.
    pub bad_messages: u64,
    pub epoch: u64,
    pub last_sequence: u64,
}

pub struct Bridge {
    o: BridgeOptions,
    admits: super::owner::Admits,
    keys: Keys,
    session: zenoh::Session,
    inputs_pub: zenoh::pubsub::Publisher<'static>,
    checksum_pub: zenoh::pubsub::Publisher<'static>,
    keyframe_pub: zenoh::pubsub::Publisher<'static>,
    frames_pub: Option<zenoh::pubsub::Publisher<'static>>,
    keyframe_q: zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<zenoh::query::Query>>,
    config_q: zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<zenoh::query::Query>>,
    deposit_sub:
        zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    ack_pub: zenoh::pubsub::Publisher<'static>,
    /// The mirrors' batches handed to the field, and their record on disk (`journal`).
    seen: Seen,
    journal: Journal,
    reader: FieldReader,
    inputs: InputsSubscriber,
    depositor: DepositPublisher,
    /// The field's configuration and the run (epoch) it belongs to.
    config: Option<(u64, String)>,
    /// A configuration that came while the current run already had one: the next run's.
    next_config: Option<String>,
    /// Sequence of the last inputs received in the current epoch; `None` while the field's
    /// process is gone (its last frame is then no keyframe: no mirror may resync to a dead run).
    last_inputs: Option<u64>,
    /// Stamp of the first inputs of the current epoch: a frame stamped before it is older
    /// (another run's, or from before this bridge listened).
    epoch_since_ns: u64,
    last_new_frame: Instant,
    last_alive_check: Instant,
    /// Requests waiting for an answer (since when).
    held_keyframe_q: Vec<(Instant, zenoh::query::Query)>,
    held_config_q: Vec<(Instant, zenoh::query::Query)>,
    last_checksum: u64,
    last_keyframe: Instant,
    last_frame: Instant,
    /// The (epoch, sequence) of the last frame put on `pheromone/F/frames`.
    last_frame_sent: Option<(u64, u64)>,
    pub stats: BridgeStats,
}

impl Bridge {
    /// Attaches to the running field (waiting up to `attach_timeout`) and opens the session.
    pub fn start(
        node: &Node<Svc>,
        o: BridgeOptions,
        attach_timeout: Duration,
    ) -> Result<Self, BridgeError> {
        let reader = FieldReader::attach_within(node, &o.field, attach_timeout)?;
        let inputs = InputsSubscriber::attach(node, &o.field)?;
        let depositor = DepositPublisher::attach(node, &o.field, u32::MAX)?;
        let keys = Keys::of(&o.field);
        let mut seen = Seen::default();
        let journal = open_journal(node, &o.field, &mut seen)?;
        let mut config = super::session_config_with(&o.security, "peer", &o.listen, &[])?;
        if o.admin_space {
            config = super::with_admin_space(config)?;
        }
        let admits = super::owner::admits(&config);
        let session = zenoh::open(config)
            .wait()
            .map_err(|e| zerr(&format!("listen on {:?}", o.listen), e))?;
        let publisher = |key: &str, block: bool| {
            session
                .declare_publisher(key.to_string())
                .congestion_control(if block {
                    CongestionControl::Block
                } else {
                    CongestionControl::Drop
                })
                .wait()
                .map_err(|e| zerr(&format!("declare publisher {key}"), e))
        };
        // Inputs and keyframes must not be dropped (a mirror would only resync); frames may.
        let inputs_pub = publisher(&keys.inputs, true)?;
        let checksum_pub = publisher(&keys.checksum, true)?;
        let keyframe_pub = publisher(&keys.keyframe, true)?;
        let ack_pub = publisher(&keys.deposit_ack, true)?;
        let frames_pub = match o.frames {
            Some(_) => Some(publisher(&keys.frames, false)?),
            None => None,
        };
        let queryable = |key: &str| {
            session
                .declare_queryable(key.to_string())
                .wait()
                .map_err(|e| zerr(&format!("declare queryable {key}"), e))
        };
        let keyframe_q = queryable(&keys.keyframe)?;
        let config_q = queryable(&keys.config)?;
        let deposit_sub = session
            .declare_subscriber(keys.deposit.clone())
            .wait()
            .map_err(|e| zerr(&format!("subscribe {}", keys.deposit), e))?;
        Ok(Self {
            o,
            admits,
            keys,
            session,
            inputs_pub,
            checksum_pub,
            keyframe_pub,
            frames_pub,
            keyframe_q,
            config_q,
            deposit_sub,
            ack_pub,
            seen,
            journal,
            reader,
            inputs,
            depositor,
            config: None,
            next_config: None,
            last_inputs: None,
            epoch_since_ns: u64::MAX,
            last_new_frame: Instant::now(),
            last_alive_check: Instant::now(),
            held_keyframe_q: Vec::new(),
            held_config_q: Vec::new(),
            last_checksum: u64::MAX,
            last_keyframe: Instant::now(),
            last_frame: Instant::now() - Duration::from_secs(3600),
            last_frame_sent: None,
            stats: BridgeStats::default(),
        })
    }

    /// One round: waits up to `timeout` for a frame, then publishes what came (inputs,
    /// checksum, keyframe, frames), answers requests and forwards mirrors' deposits.
    pub fn step(&mut self, timeout: Duration) -> Result<(), BridgeError> {
        if self.reader.wait_frame(timeout)? {
            self.last_new_frame = Instant::now();
        } else {
            self.check_field_alive();
        }
        if let Some(t) = self.inputs.config_toml()? {
            // The current run's, unless it has one already (then the next run's: a restarted
            // field publishes its configuration around its first inputs).
            match &self.config {
                Some((e, _)) if *e == self.stats.epoch => self.next_config = Some(t),
                _ if self.stats.epoch == 0 => self.next_config = Some(t),
                _ => self.config = Some((self.stats.epoch, t)),
            }
        }
        while let Some((h, deposits)) = self.inputs.receive()? {
            if h.epoch != self.stats.epoch {
                self.stats.epoch = h.epoch;
                self.last_checksum = u64::MAX;
                self.epoch_since_ns = h.stamp_ns;
                if let Some(t) = self.next_config.take() {
                    self.config = Some((h.epoch, t));
                }
            }
            let bytes = codec::encode_inputs(&h, &deposits);
            self.stats.inputs_bytes += bytes.len() as u64;
            self.inputs_pub
                .put(bytes)
                .wait()
                .map_err(|e| zerr("put inputs", e))?;
            self.stats.inputs_sent += 1;
            self.stats.deposits_in_inputs += deposits.len() as u64;
            self.stats.last_sequence = h.sequence;
            self.last_inputs = Some(h.sequence);
        }
        self.publish_frame_derived()?;
        self.answer_requests()?;
        self.forward_deposits()?;
        Ok(())
    }

    /// No new frame: once frames have stopped for `FIELD_SILENT`, checks (at most that often)
    /// whether the field's process is gone; then its last frame is no longer served.
    fn check_field_alive(&mut self) {
        if self.last_inputs.is_none()
            || self.last_new_frame.elapsed() < FIELD_SILENT
            || self.last_alive_check.elapsed() < FIELD_SILENT
        {
            return;
        }
        self.last_alive_check = Instant::now();
        if !self.reader.field_alive() {
            eprintln!(
                "bridge '{}': the field's process is gone after frame {}; no keyframes until it runs again",
                self.o.field, self.stats.last_sequence
            );
            self.last_inputs = None;
        }
    }

    fn publish_frame_derived(&mut self) -> Result<(), BridgeError> {
        let epoch = self.stats.epoch;
        let every = self.o.checksum_every.max(1) as u64;
        let mut puts: Vec<(u8, Vec<u8>)> = Vec::new();
        if let Some((h, cells)) =
            current(&self.reader, epoch, self.last_inputs, self.epoch_since_ns)
        {
            if h.sequence % every == 0 && h.sequence != self.last_checksum {
                self.last_checksum = h.sequence;
                let sum = frame_checksum(cells);
                puts.push((
                    0,
                    codec::encode_checksum(epoch, h.sequence, sum, every as u32),
                ));
            }
            if self.last_keyframe.elapsed() >= self.o.keyframe_every {
                self.last_keyframe = Instant::now();
                puts.push((1, codec::encode_keyframe(epoch, &h, cells)));
            }
            if let Some(f) = self.o.frames {
                // Each frame once: a round without a new frame sends nothing.
                let new = self.last_frame_sent != Some((epoch, h.sequence));
                if new && self.last_frame.elapsed().as_secs_f64() * f.rate_hz >= 1.0 {
                    self.last_frame = Instant::now();
                    self.last_frame_sent = Some((epoch, h.sequence));
                    puts.push((2, codec::encode_frame(epoch, &h, cells, f.downsample)));
                }
            }
        }
        for (what, bytes) in puts {
            let n = bytes.len() as u64;
            match what {
                0 => {
                    self.checksum_pub
                        .put(bytes)
                        .wait()
                        .map_err(|e| zerr("put checksum", e))?;
                    self.stats.checksums_sent += 1;
                    self.stats.other_bytes += n;
                }
                1 => {
                    self.keyframe_pub
                        .put(bytes)
                        .wait()
                        .map_err(|e| zerr("put keyframe", e))?;
                    self.stats.keyframes_sent += 1;
                    self.stats.keyframe_bytes += n;
                    self.stats.last_keyframe_bytes = n;
                }
                _ => {
                    if let Some(p) = &self.frames_pub {
                        p.put(bytes).wait().map_err(|e| zerr("put frame", e))?;
                        self.stats.frames_sent += 1;
                        self.stats.other_bytes += n;
                    }
                }
            }
        }
        Ok(())
    }

    /// Answers keyframe and configuration requests. A request that cannot be answered yet
    /// (the newest frame's inputs are not out yet, or the run's configuration has not come) is
    /// held for a later round, up to `REQUEST_TIMEOUT`; while the field is gone, keyframe
    /// requests are dropped unanswered (the mirror asks again).
    fn answer_requests(&mut self) -> Result<(), BridgeError> {
        while let Ok(Some(q)) = self.keyframe_q.try_recv() {
            self.stats.keyframe_requests += 1;
            self.held_keyframe_q.push((Instant::now(), q));
        }
        while let Ok(Some(q)) = self.config_q.try_recv() {
            self.held_config_q.push((Instant::now(), q));
        }
        if self.last_inputs.is_none() {
            self.held_keyframe_q.clear();
        }
        if !self.held_keyframe_q.is_empty() {
            let now = current(
                &self.reader,
                self.stats.epoch,
                self.last_inputs,
                self.epoch_since_ns,
            );
            if let Some((h, cells)) = now {
                let bytes = codec::encode_keyframe(self.stats.epoch, &h, cells);
                let n = bytes.len() as u64;
                for (_, q) in self.held_keyframe_q.drain(..) {
                    q.reply(self.keys.keyframe.clone(), bytes.clone())
                        .wait()
                        .map_err(|e| zerr("reply keyframe", e))?;
                    self.stats.keyframes_sent += 1;
                    self.stats.keyframe_bytes += n;
                    self.stats.last_keyframe_bytes = n;
                }
            }
        }
        // Only the current run's configuration.
        if let Some((epoch, t)) = self
            .config
            .as_ref()
            .filter(|(e, _)| *e == self.stats.epoch && *e != 0)
        {
            for (_, q) in self.held_config_q.drain(..) {
                let bytes = codec::encode_config(*epoch, t);
                self.stats.other_bytes += bytes.len() as u64;
                q.reply(self.keys.config.clone(), bytes)
                    .wait()
                    .map_err(|e| zerr("reply config", e))?;
            }
        }
        // Unanswered for too long: dropped (the requester has given up).
        self.held_keyframe_q
            .retain(|(t, _)| t.elapsed() < REQUEST_TIMEOUT);
        self.held_config_q
            .retain(|(t, _)| t.elapsed() < REQUEST_TIMEOUT);
        Ok(())
    }

    fn forward_deposits(&mut self) -> Result<(), BridgeError> {
        while let Ok(Some(s)) = self.deposit_sub.try_recv() {
            match codec::decode_deposits(&s.payload().to_bytes()) {
                Ok((mirror_id, batch, deposits)) => {
                    self.forward_batch(mirror_id, batch, deposits)?
                }
                Err(e) => {
                    self.stats.bad_messages += 1;
                    eprintln!("bridge '{}': rejected a deposit message: {e}", self.o.field);
                }
            }
        }
        Ok(())
    }

    /// Hands one mirror batch to the field, unless it did so before, and answers it. With no
    /// field to take it, it neither hands nor answers: the mirror sends it again.
    fn forward_batch(
        &mut self,
        mirror_id: u64,
        batch: u64,
        deposits: Vec<DepositMsg>,
    ) -> Result<(), BridgeError> {
        let answered = (mirror_id != 0)
            .then(|| self.seen.earlier(mirror_id, batch))
            .flatten();
        let (forwarded, refused) = match answered {
            Some(earlier) => {
                self.stats.deposit_batches_repeated += 1;
                earlier
            }
            None => {
                if mirror_id != 0 {
                    self.journal
                        .handing(mirror_id, batch)
                        .map_err(|e| self.journal_err(e))?;
                }
                let (mut forwarded, mut refused) = (0u32, 0u32);
                for d in deposits {
                    // Each keeps the robot id its mirror-host publisher stamped.
                    match self.depositor.send_as(d) {
                        Ok(()) => forwarded += 1,
                        Err(SendError::NoSubscriber { .. }) if forwarded == 0 => {
                            eprintln!(
                                "bridge '{}': no field takes deposits now; batch {batch} of \
                                 mirror {mirror_id:016x} waits for its resend",
                                self.o.field
                            );
                            if mirror_id != 0 {
                                self.journal
                                    .not_handed(mirror_id, batch)
                                    .map_err(|e| self.journal_err(e))?;
                            }
                            return Ok(());
                        }
                        Err(e) => {
                            refused += 1;
                            eprintln!("bridge '{}': deposit not forwarded: {e}", self.o.field)
                        }
                    }
                }
                self.stats.deposits_forwarded += u64::from(forwarded);
                self.stats.deposits_refused += u64::from(refused);
                if mirror_id != 0 {
                    self.seen.record(mirror_id, batch, forwarded, refused);
                    self.journal
                        .handed(mirror_id, batch, (forwarded, refused), &self.seen)
                        .map_err(|e| self.journal_err(e))?;
                }
                (forwarded, refused)
            }
        };
        if mirror_id == 0 {
            return Ok(());
        }
        self.stats.deposit_batches += 1;
        let ack = codec::encode_deposit_ack(&codec::DepositAck {
            mirror_id,
            batch,
            forwarded,
            refused,
        });
        self.stats.other_bytes += ack.len() as u64;
        self.ack_pub
            .put(ack)
            .wait()
            .map_err(|e| zerr("put a deposit answer", e))
    }

    /// The endpoints the bridge listens on, with the ports the system chose (needs
    /// `admin_space`).
    pub fn listen_locators(&self) -> Result<Vec<String>, BridgeError> {
        super::listen_locators(&self.session)
    }

    /// Whom it admits: this user's sessions only (the owner key, on loopback endpoints without
    /// credentials), the users of a dictionary, or anyone who reaches it.
    pub fn admits(&self) -> &super::owner::Admits {
        &self.admits
    }

    /// The options it was started with.
    pub fn options(&self) -> &BridgeOptions {
        &self.o
    }

    /// Whether the field's process is alive.
    pub fn field_alive(&self) -> bool {
        self.reader.field_alive()
    }

    /// Stops: closes the session; dropping the journal removes its file (a successor needs it
    /// only after a crash).
    pub fn close(self) {
        // A session that fails to close ends with the process.
        let _ = self.session.close().wait();
    }

    fn journal_err(&self, e: std::io::Error) -> BridgeError {
        journal_err(self.journal.path(), e)
    }
}

/// Opens the journal of `field`'s bridges in `node`'s iceoryx2 domain and loads what a crashed
/// predecessor left into `seen`, saying what it recovered.
fn open_journal(node: &Node<Svc>, field: &str, seen: &mut Seen) -> Result<Journal, BridgeError> {
    let prefix = node.config().global.prefix.to_string();
    let path = journal::path_for(&prefix, field);
    let (j, r) = Journal::open(&path, seen).map_err(|e| journal_err(&path, e))?;
    if r.handed > 0 || !r.interrupted.is_empty() {
        eprintln!(
            "bridge '{field}': a bridge before this one stopped without closing; {} batch(es) it \
             handed to the field are answered again from {} without handing them over twice",
            r.handed,
            path.display()
        );
    }
    for (m, b) in &r.interrupted {
        eprintln!(
            "bridge '{field}': batch {b} of mirror {m:016x} was being handed to the field when \
             that bridge stopped; it is not handed over again, and some of its deposits may be \
             missing"
        );
    }
    Ok(j)
}

fn journal_err(path: &std::path::Path, e: std::io::Error) -> BridgeError {
    BridgeError::Journal {
        path: path.display().to_string(),
        detail: e.to_string(),
    }
}

/// A field that publishes no frame for this long is checked for a dead process.
const FIELD_SILENT: Duration = Duration::from_millis(200);

/// The current frame, if its inputs have gone out (so a mirror can continue from it) in the
/// run the bridge relays.
fn current(
    reader: &FieldReader,
    epoch: u64,
    last_inputs: Option<u64>,
    epoch_since_ns: u64,
) -> Option<(pheromone_field::FrameHeader, &[f32])> {
    let s = reader.sample()?;
    let h = *s.user_header();
    (epoch != 0 && last_inputs.is_some_and(|l| l >= h.sequence) && h.stamp_ns >= epoch_since_ns)
        .then_some((h, s.payload()))
}
