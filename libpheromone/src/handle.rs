//! What a C handle is: a node, a `FieldReader`, an optional `DepositPublisher`, and whether the
//! caller has borrowed the frame the reader holds. Safe Rust; `ffi` turns C arguments into these
//! calls. Nothing here allocates after `attach`, except to format an error that a field error
//! already carries.

use std::time::Duration;

use iceoryx2::prelude::*;
use pheromone_field::messages::FrameHeader;
use pheromone_field::sample::FrameView;
use pheromone_field::sample::SamplePose;
use pheromone_field::shm::{DepositPublisher, FieldReader, Receipt, Svc, WaitPolicy};
use pheromone_field::{DepositMsg, KernelKind};

use crate::borrowed::Borrowed;
use crate::error::{bail, fail, from_shm, Failure};
use crate::types::{
    PheromoneAttachOptions, PheromoneDeposit, PheromoneEllipseParams, PheromoneFrameView,
    PheromoneLiveness, PheromonePose, PheromonePoseEstimate, PheromoneReceipt, PheromoneStatus,
    PheromoneWaitPolicy, PHEROMONE_LAYOUT_VERSION, PHEROMONE_MAX_CHANNELS,
    PHEROMONE_RECEIPT_APPLIED, PHEROMONE_RECEIPT_FORWARDED, PHEROMONE_RECEIPT_REJECTED,
    PHEROMONE_WAIT_BUSY_POLL, PHEROMONE_WAIT_EVENT, PHEROMONE_WAIT_SPIN,
};

const BAD: PheromoneStatus = PheromoneStatus::BadArgument;

/// One attachment to a field (opaque to C).
pub struct PheromoneField {
    name: String,
    /// The caller holds a view of the reader's newest frame: the reader is not updated (and so
    /// never drops that frame) until `release`.
    borrowed: Option<Borrowed>,
    // Dropped in this order: the ports before their node.
    deposit: Option<DepositPublisher>,
    reader: FieldReader,
    _node: Node<Svc>,
}

/// Attach options as Rust values (`ffi` reads them from C).
pub struct Options<'a> {
    pub c: PheromoneAttachOptions,
    pub iox_domain: Option<&'a str>,
}

impl PheromoneField {
    /// Attaches to field `name`; see `pheromone_field_attach`.
    pub fn attach(name: &str, o: &Options<'_>) -> Result<Box<Self>, Failure> {
        if o.c.layout_version != PHEROMONE_LAYOUT_VERSION {
            bail!(
                PheromoneStatus::Layout,
                "options.layout_version = {}: this program was compiled against the pheromone.h of \
                 layout v{} but the library speaks layout v{PHEROMONE_LAYOUT_VERSION}; rebuild it \
                 against the installed pheromone.h",
                o.c.layout_version,
                o.c.layout_version
            );
        }
        pheromone_field::shm::check_name(name).map_err(|e| from_shm("field name", &e))?;
        let domain = effective_domain(o.iox_domain);
        let node = create_node(domain.as_deref())?;
        let place = match &domain {
            Some(d) => format!("field '{name}' in iceoryx2 domain '{d}'"),
            None => format!("field '{name}' in iceoryx2's default domain"),
        };
        let timeout = Duration::from_nanos(o.c.attach_timeout_ns);
        let started = std::time::Instant::now();
        let reader = if timeout.is_zero() {
            FieldReader::attach(&node, name)
        } else {
            FieldReader::attach_within(&node, name, timeout)
        }
        .map_err(|e| from_shm(&format!("attach to {place}"), &e))?;
        wait_alive(&node, &reader, &place, started + timeout)?;
        if let Some(f) = reader.frame() {
            check_frame_layout(name, f.header)?;
        }
        // A field that is starting may have its frame service and not yet its deposit service.
        let left = timeout.saturating_sub(started.elapsed());
        let deposit = match (o.c.deposits != 0, left.is_zero()) {
            (false, _) => None,
            (true, true) => Some(DepositPublisher::attach(&node, name, o.c.robot_id)),
            (true, false) => Some(DepositPublisher::attach_within(
                &node,
                name,
                o.c.robot_id,
                left,
            )),
        }
        .transpose()
        .map_err(|e| from_shm(&format!("attach the deposit publisher of {place}"), &e))?;
        Ok(Box::new(Self {
            name: name.to_string(),
            borrowed: None,
            deposit,
            reader,
            _node: node,
        }))
    }

    /// Refuses to be dropped while a frame is borrowed.
    pub fn check_detach(&self) -> Result<(), Failure> {
        if self.borrowed.is_some() {
            bail!(
                PheromoneStatus::Borrowed,
                "field '{}': a frame is borrowed: call pheromone_frame_release before detaching",
                self.name
            );
        }
        Ok(())
    }

    /// Waits for a frame newer than the one held; `Ok(false)` on timeout.
    pub fn wait(&mut self, policy: PheromoneWaitPolicy, timeout_ns: u64) -> Result<bool, Failure> {
        let policy = wait_policy(policy)?;
        if self.borrowed.is_some() {
            bail!(
                PheromoneStatus::Borrowed,
                "field '{}': a frame is borrowed: call pheromone_frame_release before waiting for \
                 the next one",
                self.name
            );
        }
        // The notifications pending go first (a frame that comes after this is taken below or
        // wakes the caller's `poll` on `pheromone_field_fd` again), so a caller that waits in
        // its own event loop and calls this with a zero timeout is not woken for ever.
        self.reader
            .take_notifications()
            .map_err(|e| from_shm("wait for a frame", &e))?;
        let fresh = self
            .reader
            .wait_frame_with(policy, Duration::from_nanos(timeout_ns))
            .map_err(|e| from_shm("wait for a frame", &e))?;
        if let (true, Some(f)) = (fresh, self.reader.frame()) {
            check_frame_layout(&self.name, f.header)?;
        }
        Ok(fresh)
    }

    /// Lends the newest frame: its header's numbers and a pointer per channel into shared
    /// memory.
    pub fn borrow(&mut self, out: &mut PheromoneFrameView) -> Result<(), Failure> {
        let Some(f) = self.reader.frame() else {
            bail!(
                PheromoneStatus::NoFrame,
                "field '{}': no frame has arrived yet (call pheromone_wait_frame first)",
                self.name
            );
        };
        let h = f.header;
        if h.channels as usize > PHEROMONE_MAX_CHANNELS {
            bail!(
                PheromoneStatus::ShmError,
                "field '{}': the frame has {} channels, more than PHEROMONE_MAX_CHANNELS ({PHEROMONE_MAX_CHANNELS})",
                self.name,
                h.channels
            );
        }
        out.sequence = h.sequence;
        out.stamp_ns = h.stamp_ns;
        out.sim_time_s = h.sim_time_s;
        out.channels = h.channels;
        out.width = h.width;
        out.height = h.height;
        out.cell_size_m = h.cell_size_m;
        out.origin_x_m = h.origin_x_m;
        out.origin_y_m = h.origin_y_m;
        out.dt_s = h.dt_s;
        out.layout_version = h.layout_version;
        out.deposits_applied = h.deposits_applied;
        out.deposits_rejected = h.deposits_rejected_total();
        out.plane_len = f.view.geometry.cells();
        for (c, p) in out.planes.iter_mut().enumerate() {
            *p = if c < f.view.channels {
                f.view.plane(c).as_ptr()
            } else {
                std::ptr::null()
            };
        }
        self.borrowed = Some(Borrowed::of(&f));
        Ok(())
    }

    /// The frame-ready listener of the handle's reader (its file descriptor is
    /// `pheromone_field_fd`'s).
    pub fn frame_ready_listener(&self) -> &iceoryx2::port::listener::Listener<Svc> {
        self.reader.frame_ready_listener()
    }

    /// Whether the field's process is alive, which generation of it the handle reads, and the
    /// sequence of the newest frame held (`pheromone_field_liveness`).
    pub fn liveness(&self) -> PheromoneLiveness {
        PheromoneLiveness {
            alive: u32::from(self.reader.field_alive()),
            reserved: 0,
            generation: self.reader.generation(),
            sequence: self.reader.frame().map_or(0, |f| f.header.sequence),
        }
    }

    /// Ends the borrow (the view's pointers must not be used any more).
    pub fn release(&mut self) {
        self.borrowed = None;
    }

    /// The borrowed frame and a checked channel.
    fn sampled(&self, channel: u32) -> Result<(FrameView<'_>, usize), Failure> {
        let Some(b) = &self.borrowed else {
            bail!(
                PheromoneStatus::NoFrame,
                "field '{}': sampling needs a borrowed frame (call pheromone_frame_borrow first)",
                self.name
            );
        };
        let view = b.view();
        if channel as usize >= view.channels {
            bail!(
                BAD,
                "channel = {channel}: field '{}' has {} channel(s)",
                self.name,
                view.channels
            );
        }
        Ok((view, channel as usize))
    }

    pub fn value(&self, channel: u32, x_m: f32, y_m: f32) -> Result<f32, Failure> {
        finite(&[("x_m", x_m), ("y_m", y_m)])?;
        let (f, c) = self.sampled(channel)?;
        Ok(f.value(c, x_m, y_m))
    }

    pub fn gradient(&self, channel: u32, x_m: f32, y_m: f32) -> Result<(f32, f32), Failure> {
        finite(&[("x_m", x_m), ("y_m", y_m)])?;
        let (f, c) = self.sampled(channel)?;
        Ok(f.gradient(c, x_m, y_m))
    }

    /// Values and/or gradients of `channel` at every point (`FrameView::value`, `gradient`).
    pub fn sample_many(
        &self,
        channel: u32,
        points: &[[f32; 2]],
        values: Option<&mut [f32]>,
        gradients: Option<&mut [[f32; 2]]>,
    ) -> Result<(), Failure> {
        let (f, c) = self.sampled(channel)?;
        if let Some(i) = points
            .iter()
            .position(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            bail!(
                BAD,
                "point {i} = ({}, {}) (xy[{}], xy[{}]): must be finite",
                points[i][0],
                points[i][1],
                2 * i,
                2 * i + 1
            );
        }
        let done = match (values, gradients) {
            (Some(v), Some(g)) => {
                pheromone_field::shm::values_and_gradients_into(&f, c, points, v, g)
            }
            (Some(v), None) => pheromone_field::shm::values_into(&f, c, points, v),
            (None, Some(g)) => {
                for (p, g) in points.iter().zip(g.iter_mut()) {
                    let (gx, gy) = f.gradient(c, p[0], p[1]);
                    *g = [gx, gy];
                }
                Ok(())
            }
            (None, None) => bail!(BAD, "values and gradients are both NULL: nothing to write"),
        };
        done.map_err(|e| fail(BAD, format_args!("field '{}': {e}", self.name)))
    }

    pub fn antennas(
        &self,
        channel: u32,
        pose: PheromonePose,
        wheel_base_m: f32,
    ) -> Result<(f32, f32), Failure> {
        let pose = sample_pose(pose)?;
        if !(wheel_base_m.is_finite() && wheel_base_m >= 0.0) {
            bail!(BAD, "wheel_base_m = {wheel_base_m}: must be finite and ≥ 0");
        }
        let (f, c) = self.sampled(channel)?;
        Ok(f.antennas(c, pose, wheel_base_m))
    }

    pub fn sectors(
        &self,
        channel: u32,
        pose: PheromonePose,
        radius_m: f32,
        out: &mut [f32],
    ) -> Result<(), Failure> {
        let pose = sample_pose(pose)?;
        if !(radius_m.is_finite() && radius_m > 0.0) {
            bail!(BAD, "radius_m = {radius_m}: must be finite and > 0");
        }
        let (f, c) = self.sampled(channel)?;
        f.sector_means_into(c, pose, radius_m, out);
        Ok(())
    }

    /// Sends a deposit (checked here first, so a bad one is refused to the caller rather than
    /// counted as rejected by the field).
    pub fn deposit(&mut self, d: &PheromoneDeposit) -> Result<(), Failure> {
        let msg = deposit_msg(d)?;
        self.send(msg)
    }

    /// Sends seed 000's uncertainty-aware deposit for a pose estimate.
    pub fn deposit_pose(
        &mut self,
        pose: &PheromonePoseEstimate,
        params: &PheromoneEllipseParams,
    ) -> Result<(), Failure> {
        let msg = crate::ellipse::deposit_for(pose, params)?;
        self.send(msg)
    }

    /// Sends a deposit and waits at most `timeout_ns` for the field's receipt, written to
    /// `out` when one came (also when the field refused the deposit: `Rejected`).
    pub fn deposit_confirmed(
        &mut self,
        d: &PheromoneDeposit,
        timeout_ns: u64,
        out: &mut PheromoneReceipt,
    ) -> Result<(), Failure> {
        let msg = deposit_msg(d)?;
        self.check_channel(&msg)?;
        let p = self.publisher()?;
        let receipt = p
            .send_confirmed(msg, Duration::from_nanos(timeout_ns))
            .map_err(|e| from_shm("deposit", &e))?;
        let (sequence, status, reason) = match receipt {
            Receipt::Applied { sequence } => (sequence, PHEROMONE_RECEIPT_APPLIED, None),
            Receipt::Forwarded => (0, PHEROMONE_RECEIPT_FORWARDED, None),
            Receipt::Rejected { sequence, reason } => {
                (sequence, PHEROMONE_RECEIPT_REJECTED, Some(reason))
            }
            Receipt::Flushed { .. } => bail!(
                PheromoneStatus::Internal,
                "field '{}' answered a deposit as a flush",
                self.name
            ),
        };
        *out = PheromoneReceipt {
            sequence,
            status,
            reason: reason.map_or(0, |r| r as u32),
        };
        if let Some(r) = reason {
            bail!(
                PheromoneStatus::Rejected,
                "field '{}' refused the deposit in frame {sequence}: {} (reason {}); nothing was \
                 applied",
                self.name,
                r.name(),
                r as u32
            );
        }
        Ok(())
    }

    fn check_channel(&self, msg: &DepositMsg) -> Result<(), Failure> {
        if let Some(f) = self.reader.frame() {
            if msg.channel >= f.header.channels {
                bail!(
                    BAD,
                    "deposit channel = {}: field '{}' has {} channel(s)",
                    msg.channel,
                    self.name,
                    f.header.channels
                );
            }
        }
        Ok(())
    }

    fn publisher(&mut self) -> Result<&mut DepositPublisher, Failure> {
        match self.deposit.as_mut() {
            Some(p) => Ok(p),
            None => bail!(
                BAD,
                "field '{}' was attached without deposits (options.deposits = 0)",
                self.name
            ),
        }
    }

    fn send(&mut self, msg: DepositMsg) -> Result<(), Failure> {
        self.check_channel(&msg)?;
        let p = self.publisher()?;
        p.send(msg).map_err(|e| from_shm("deposit", &e))
    }
}

/// The iceoryx2 domain of `options.iox_domain`: NULL, the environment's
/// (`PHEROMONE_IOX_DOMAIN` if set and not empty); `""`, the default domain (`None`) whatever the
/// environment says; otherwise the name given.
fn effective_domain(option: Option<&str>) -> Option<String> {
    match option {
        Some(d) => Some(d.to_string()),
        None => std::env::var(pheromone_field::shm::IOX_DOMAIN_ENV).ok(),
    }
    .filter(|d| !d.is_empty())
}

/// Waits until a live process publishes the frames the reader opened, at most until
/// `deadline`: a field whose process died (its services held by another process) is
/// `FieldDead`, not a handle whose every wait times out.
fn wait_alive(
    node: &Node<Svc>,
    reader: &FieldReader,
    place: &str,
    deadline: std::time::Instant,
) -> Result<(), Failure> {
    use iceoryx2::node::NodeWaitFailure;
    loop {
        if reader.field_alive() {
            return Ok(());
        }
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        if left.is_zero() {
            bail!(
                PheromoneStatus::FieldDead,
                "attach to {place}: its services exist (another process holds them) but no live \
                 process publishes its frames: the field process died; restart it"
            );
        }
        match pheromone_field::shm::node_wait(node, left.min(Duration::from_millis(20))) {
            Ok(()) => {}
            Err(NodeWaitFailure::Interrupt | NodeWaitFailure::TerminationRequest) => bail!(
                PheromoneStatus::Interrupted,
                "attach to {place}: the wait for its field process was interrupted by a signal"
            ),
        }
    }
}

/// The iceoryx2 node of a handle: in `domain` (`None`: the default domain), without signal
/// handlers (the host program owns SIGINT and SIGTERM), after removing what dead nodes left.
fn create_node(domain: Option<&str>) -> Result<Node<Svc>, Failure> {
    use std::sync::atomic::{AtomicU32, Ordering};
    static SERIAL: AtomicU32 = AtomicU32::new(0);
    let config = pheromone_field::shm::domain_config_of(domain)
        .map_err(|e| from_shm("options.iox_domain", &e))?;
    let name = format!(
        "c-{}-{}",
        std::process::id(),
        SERIAL.fetch_add(1, Ordering::Relaxed)
    );
    let node_name =
        NodeName::new(&name).map_err(|e| fail(BAD, format_args!("node name '{name}': {e:?}")))?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .config(&config)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Svc>()
        .map_err(|e| {
            fail(
                PheromoneStatus::ShmError,
                format_args!("cannot create the iceoryx2 node '{name}': {e:?}"),
            )
        })?;
    pheromone_field::shm::cleanup_dead_nodes(&node);
    Ok(node)
}

fn check_frame_layout(name: &str, h: &FrameHeader) -> Result<(), Failure> {
    if h.layout_version != PHEROMONE_LAYOUT_VERSION {
        bail!(
            PheromoneStatus::Layout,
            "field '{name}' writes frames of layout v{} but this library reads layout \
             v{PHEROMONE_LAYOUT_VERSION}",
            h.layout_version
        );
    }
    Ok(())
}

/// The Rust wait policy of a C one.
pub fn wait_policy(p: PheromoneWaitPolicy) -> Result<WaitPolicy, Failure> {
    Ok(match p.kind {
        PHEROMONE_WAIT_EVENT => WaitPolicy::Event,
        PHEROMONE_WAIT_BUSY_POLL => WaitPolicy::BusyPoll,
        PHEROMONE_WAIT_SPIN if (1..=1_000_000_000).contains(&p.spin_ns) => {
            WaitPolicy::Spin(Duration::from_nanos(p.spin_ns))
        }
        PHEROMONE_WAIT_SPIN => bail!(
            BAD,
            "wait policy spin_ns = {}: must be 1 ns to 1 s",
            p.spin_ns
        ),
        k => bail!(
            BAD,
            "wait policy kind = {k}: expected PHEROMONE_WAIT_EVENT (0), PHEROMONE_WAIT_SPIN (1) \
             or PHEROMONE_WAIT_BUSY_POLL (2)"
        ),
    })
}

fn finite(values: &[(&str, f32)]) -> Result<(), Failure> {
    for &(name, v) in values {
        if !v.is_finite() {
            bail!(BAD, "{name} = {v}: must be finite");
        }
    }
    Ok(())
}

fn sample_pose(p: PheromonePose) -> Result<SamplePose, Failure> {
    finite(&[
        ("pose.x_m", p.x_m),
        ("pose.y_m", p.y_m),
        ("pose.theta_rad", p.theta_rad),
    ])?;
    Ok(SamplePose::new(p.x_m, p.y_m, p.theta_rad))
}

/// The covariance of an ellipse or paper deposit must be positive semi-definite: the field's own
/// check (`pheromone_field::deposit::cov_xy_is_psd`, by which the field refuses it as `not_psd`), made here
/// so that `pheromone_deposit`, which gets no receipt, refuses it to the caller instead of the
/// field dropping it.
fn check_psd(xx: f32, xy: f32, yy: f32) -> Result<(), Failure> {
    if !pheromone_field::deposit::cov_xy_is_psd(xx, xy, yy) {
        bail!(
            BAD,
            "deposit covariance [[{xx}, {xy}], [{xy}, {yy}]] (cov_xx, cov_xy, cov_yy): not \
             positive semi-definite (needs cov_xx ≥ 0, cov_yy ≥ 0, cov_xx·cov_yy ≥ cov_xy²)"
        );
    }
    Ok(())
}

/// The wire message of a C deposit, every number checked finite, the kernel known and an
/// ellipse's or paper kernel's covariance positive semi-definite.
pub fn deposit_msg(d: &PheromoneDeposit) -> Result<DepositMsg, Failure> {
    let Some(kernel) = KernelKind::from_code(d.kernel) else {
        bail!(
            BAD,
            "deposit kernel = {}: expected PHEROMONE_KERNEL_ELLIPSE (0), _PAPER (1), \
             _SATURATING (2) or _Z_SHAPE (3)",
            d.kernel
        );
    };
    finite(&[
        ("deposit x_m", d.x_m),
        ("deposit y_m", d.y_m),
        ("deposit amount", d.amount),
        ("deposit cov_xx", d.cov_xx),
        ("deposit cov_xy", d.cov_xy),
        ("deposit cov_yy", d.cov_yy),
        ("deposit range_m", d.range_m),
        ("deposit gamma_max", d.gamma_max),
        ("deposit sigma_m", d.sigma_m),
        ("deposit plateau_m", d.plateau_m),
        ("deposit slope_m", d.slope_m),
    ])?;
    if matches!(kernel, KernelKind::Ellipse | KernelKind::Paper) {
        check_psd(d.cov_xx, d.cov_xy, d.cov_yy)?;
    }
    let params = pheromone_field::KernelParams {
        cov_m2: [d.cov_xx, d.cov_xy, d.cov_yy],
        range_m: d.range_m,
        gamma_max: d.gamma_max,
        sigma_m: d.sigma_m,
        plateau_m: d.plateau_m,
        slope_m: d.slope_m,
    };
    let deposit = pheromone_field::Deposit {
        channel: d.channel,
        x_m: d.x_m,
        y_m: d.y_m,
        kernel: pheromone_field::Kernel::from_params(kernel, d.amount, &params),
    };
    Ok(deposit.into())
}
