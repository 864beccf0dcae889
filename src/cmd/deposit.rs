//! `pheromone deposit`: one deposit into a running field, confirmed by the field's receipt
//! (applied in frame N, or refused with the reason), or sent without waiting (`--no-wait`).

use std::time::Duration;

use clap::Args;
use iceoryx2::prelude::Node;
use pheromone_field::kernel::defaults;
use pheromone_field::shm::{
    create_node, ConfigSubscriber, DepositClient, DepositPublisher, Receipt, Svc,
};
use pheromone_field::{DepositMsg, KernelKind};

use super::{bad, seconds, seconds_or_zero};

/// Send one deposit to a running field and wait for its receipt.
///
/// By default the command exits 0 only once the field has applied the deposit (it prints the
/// frame), exits 2 naming the value when the field refuses it (NaN, a covariance that is not
/// positive semi-definite, a channel the field lacks, outside the grid…), and exits 1 when no
/// receipt came within --receipt-timeout (the deposit may then still be applied, once: at most
/// once). --no-wait sends it without a receipt, as a loop would, and waits (at most
/// --receipt-timeout) only until the field has taken it from its queue: exit 0 once taken, exit 3
/// "queued, not confirmed" when the field did not take it in time (a stopped or very slow
/// field; the deposit may be lost when the command exits).
#[derive(Args, Debug)]
pub struct DepositArgs {
    /// Field name.
    #[arg(long, default_value = "main")]
    pub field: String,
    /// Robot id stamped on the deposit.
    #[arg(long, default_value_t = 0)]
    pub robot: u32,
    /// Channel index.
    #[arg(long, value_parser = super::int::<u32>(0, 63), default_value_t = 0)]
    pub channel: u32,
    /// Kernel: ellipse, paper, saturating or z-shape.
    #[arg(long, default_value = "ellipse")]
    pub kernel: KernelKind,
    /// World x of the centre (m).
    #[arg(long, value_parser = super::f32_any(), allow_negative_numbers = true)]
    pub x: f32,
    /// World y of the centre (m).
    #[arg(long, value_parser = super::f32_any(), allow_negative_numbers = true)]
    pub y: f32,
    /// The deposit's strength as its kernel takes it, negative for anti-pheromone: τ of the
    /// ellipse and paper kernels, the total before the kernel divides by det Σxy (the peak is
    /// γ = τ / det Σxy capped at --gamma-max: --tau 0.2 with the default --cov makes a peak near
    /// 94), ρt of saturating, Q (the plateau's level) of z-shape. `--amount`, its old name, is the
    /// same value (not the peak).
    #[arg(long = "tau", visible_alias = "amount", value_name = "TAU", value_parser = super::f32_any(), allow_negative_numbers = true)]
    pub tau: f32,
    /// Position covariance Σxy as xx,xy,yy (m²).
    #[arg(long, value_parser = super::f32_any(), value_delimiter = ',', default_values_t = defaults::COV_M2, allow_negative_numbers = true)]
    pub cov: Vec<f32>,
    /// Cut-off radius z_rng (m).
    #[arg(long, value_parser = super::f32_pos(1e6), default_value_t = defaults::RANGE_M)]
    pub range: f32,
    /// γ cap (ellipse, paper).
    #[arg(long, value_parser = super::f32_pos(1e9), default_value_t = defaults::GAMMA_MAX)]
    pub gamma_max: f32,
    /// λ (m), saturating kernel.
    #[arg(long, value_parser = super::f32_pos(1e6), default_value_t = defaults::SATURATING_SIGMA_M)]
    pub sigma: f32,
    /// Z-shape plateau c (m).
    #[arg(long, value_parser = super::f32_in(0.0, 1e6), default_value_t = defaults::PLATEAU_M)]
    pub plateau: f32,
    /// Z-shape slope length σ (m).
    #[arg(long, value_parser = super::f32_in(0.0, 1e6), default_value_t = defaults::SLOPE_M)]
    pub slope: f32,
    /// Seconds to wait for the field to exist.
    #[arg(long, value_parser = super::secs0(), default_value_t = 10.0)]
    pub timeout: f64,
    /// Seconds to wait for the field's receipt (the field answers at its next tick: a field
    /// slower than one tick a minute needs more).
    #[arg(long, value_parser = super::secs(), default_value_t = 60.0)]
    pub receipt_timeout: f64,
    /// Send without waiting for a receipt: wait only until the field has taken the deposit from
    /// its queue (no confirmation that it applied it); exit status 3 if it did not within
    /// --receipt-timeout.
    #[arg(long)]
    pub no_wait: bool,
}

impl DepositArgs {
    /// The deposit the flags describe; non-finite numbers are refused before anything is sent.
    fn msg(&self) -> anyhow::Result<DepositMsg> {
        if self.cov.len() != 3 {
            return Err(bad(format!(
                "--cov needs three values xx,xy,yy, got {}",
                self.cov.len()
            )));
        }
        let numbers = [
            ("--x", self.x),
            ("--y", self.y),
            ("--tau", self.tau),
            ("--cov xx", self.cov[0]),
            ("--cov xy", self.cov[1]),
            ("--cov yy", self.cov[2]),
            ("--range", self.range),
            ("--gamma-max", self.gamma_max),
            ("--sigma", self.sigma),
            ("--plateau", self.plateau),
            ("--slope", self.slope),
        ];
        if let Some((flag, v)) = numbers.iter().find(|(_, v)| !v.is_finite()) {
            return Err(bad(format!("{flag} {v}: must be a finite number")));
        }
        let params = pheromone_field::KernelParams {
            cov_m2: [self.cov[0], self.cov[1], self.cov[2]],
            range_m: self.range,
            gamma_max: self.gamma_max,
            sigma_m: self.sigma,
            plateau_m: self.plateau,
            slope_m: self.slope,
        };
        Ok(DepositMsg::from(pheromone_field::Deposit {
            channel: self.channel,
            x_m: self.x,
            y_m: self.y,
            kernel: pheromone_field::Kernel::from_params(self.kernel, self.tau, &params),
        }))
    }

    fn what(&self) -> String {
        format!(
            "{} at ({}, {}) τ {}",
            self.kernel.name(),
            self.x,
            self.y,
            self.tau
        )
    }
}

pub fn run_deposit(a: DepositArgs) -> anyhow::Result<()> {
    let attach_timeout = seconds_or_zero("timeout", a.timeout)?;
    let receipt_timeout = seconds("receipt-timeout", a.receipt_timeout)?;
    let msg = a.msg()?;
    let node = create_node(&format!("deposit-{}", std::process::id()))?;
    if a.no_wait {
        return send_unconfirmed(&node, &a, msg, attach_timeout, receipt_timeout);
    }
    let mut client = DepositClient::attach_within(&node, &a.field, a.robot, attach_timeout)?;
    // Subscribed before sending: the field hands its configuration over with the frame that
    // answers, so a refusal can be explained with the field's own rules.
    let config = ConfigSubscriber::attach(&node, &a.field).ok();
    match client.deposit(msg, receipt_timeout)? {
        Receipt::Applied { sequence } => {
            eprintln!(
                "deposit applied by field '{}' in frame {sequence}: {}",
                a.field,
                a.what()
            );
            Ok(())
        }
        Receipt::Forwarded => {
            eprintln!(
                "deposit taken by mirror '{}', forwarded to its origin: {}",
                a.field,
                a.what()
            );
            Ok(())
        }
        Receipt::Rejected { sequence, reason } => Err(bad(format!(
            "field '{}' refused the deposit (frame {sequence}): {}",
            a.field,
            refusal_detail(&node, config.as_ref(), &msg, reason)
        ))),
        Receipt::Flushed { .. } => Err(anyhow::anyhow!(
            "field '{}' answered a deposit as a flush",
            a.field
        )),
    }
}

/// `--no-wait`'s end when the field did not take the deposit from its queue in time: exit
/// status 3 ("queued, not confirmed").
#[derive(Debug)]
pub struct NotTaken(pub String);

impl std::fmt::Display for NotTaken {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for NotTaken {}

/// `--no-wait`: sends on publish-subscribe and waits (at most `timeout`) for the field to take
/// the deposit from its queue (a flush), since a deposit still queued when this process exits
/// is lost with its ports.
fn send_unconfirmed(
    node: &Node<Svc>,
    a: &DepositArgs,
    msg: DepositMsg,
    attach_timeout: Duration,
    timeout: Duration,
) -> anyhow::Result<()> {
    let mut publisher = DepositPublisher::attach_within(node, &a.field, a.robot, attach_timeout)?;
    publisher.send(msg)?;
    if publisher.flush(timeout) {
        eprintln!(
            "deposit taken by field '{}' from its queue (not confirmed: --no-wait): {}",
            a.field,
            a.what()
        );
        return Ok(());
    }
    // Already waited: dropping the publisher does not wait again.
    publisher.flush_timeout = Duration::ZERO;
    Err(NotTaken(format!(
        "deposit queued for field '{}', not confirmed: the field did not take it within \
         --receipt-timeout {} s (stopped or slower than that?); it may be lost now that this \
         command exits: {}",
        a.field,
        a.receipt_timeout,
        a.what()
    ))
    .into())
}

/// Why the field refused `msg`, naming the value: the field's own check with its configuration,
/// or the reason's name when the configuration did not arrive.
fn refusal_detail(
    node: &Node<Svc>,
    config: Option<&ConfigSubscriber>,
    msg: &DepositMsg,
    reason: pheromone_field::RejectReason,
) -> String {
    let deadline = std::time::Instant::now() + Duration::from_secs(1);
    while let Some(sub) = config {
        if let Ok(Some(c)) = sub.latest() {
            let g = c.geometry();
            if let Err(r) = pheromone_field::deposit::prepare(msg, &g, &c.channels, &c.limits) {
                return r.to_string();
            }
            break;
        }
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        if left.is_zero()
            || pheromone_field::shm::node_wait(node, left.min(Duration::from_millis(50))).is_err()
        {
            break;
        }
    }
    format!("deposit rejected ({})", reason.name())
}
