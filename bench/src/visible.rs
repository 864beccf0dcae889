//! Deposit-to-visible latency: a deposit is published (this process), the field (a separate
//! process ticking at a fixed rate) applies it in its next tick, and a follower (this process's
//! `FieldReader`) holds a frame that contains it.

use std::time::{Duration, Instant};

use field::shm::{create_node, now_ns, DepositPublisher, FieldReader, FieldServer};
use field::{ChannelSpec, DepositMsg, Evaporation, FieldConfig};

use crate::peer::{say_ready, say_result, Launcher, Peer, PeerResult, PeerSpec};
use crate::BenchError;

#[derive(Debug, Clone, Copy)]
pub struct VisibleRun {
    pub width: u32,
    pub tick_hz: f32,
    pub warmup: usize,
    pub count: usize,
    /// Pin the field process to core 1 (this process is on core 0).
    pub pin: bool,
}

#[derive(Debug, Clone, Default)]
pub struct VisibleResult {
    /// Deposit sent → frame holding it received, ns.
    pub samples_ns: Vec<u64>,
    /// The field's tick compute time of the frames that carried the deposits, ns.
    pub compute_ns: Vec<u64>,
}

fn config(width: u32, tick_hz: f32) -> FieldConfig {
    FieldConfig {
        width,
        height: width,
        tick_hz,
        max_readers: 2,
        channels: vec![ChannelSpec::new(
            "trail",
            Evaporation::Exponential {
                decay_per_s: 0.0057,
            },
        )],
        ..FieldConfig::default()
    }
}

pub fn measure(
    launcher: &Launcher,
    tag: &str,
    run: VisibleRun,
) -> Result<VisibleResult, BenchError> {
    let node = create_node(&format!("bench-visible-{tag}"))?;
    let name = format!("bench-{tag}");
    let mut field = Peer::spawn(
        launcher,
        &PeerSpec::Field {
            name: name.clone(),
            width: run.width,
            tick_hz: run.tick_hz,
            core: run.pin.then_some(1),
        },
    )?;
    field.wait_ready(Duration::from_secs(20))?;
    let mut reader = FieldReader::attach_within(&node, &name, Duration::from_secs(10))?;
    let mut depositor = DepositPublisher::attach_within(&node, &name, 1, Duration::from_secs(10))?;
    let period = Duration::from_secs_f32(1.0 / run.tick_hz);
    let timeout = period * 10 + Duration::from_secs(2);
    let c = config(run.width, run.tick_hz);
    let (x_m, y_m) = (
        c.width as f32 * c.cell_size_m / 2.0,
        c.height as f32 * c.cell_size_m / 2.0,
    );
    let mut result = VisibleResult::default();
    for i in 0..run.warmup + run.count {
        let last = reader.frame().map(|f| f.header.sequence).unwrap_or(0);
        if reader
            .wait_until(timeout, |f| f.header.sequence > last)?
            .is_none()
        {
            return Err(BenchError::Peer(format!(
                "field '{name}' sent no frame within {timeout:?}"
            )));
        }
        // Deposits land at every phase of the tick: spread them over the period.
        let phase = period.mul_f64(((i * 37) % 100) as f64 / 100.0);
        node.wait(phase).map_err(|_| BenchError::Interrupted)?;
        reader.update()?;
        let before = reader
            .frame()
            .map(|f| f.header.deposits_applied)
            .unwrap_or(0);
        let sent = now_ns();
        depositor.send(DepositMsg::ellipse(
            0,
            x_m,
            y_m,
            0.001,
            [0.01, 0.0, 0.01],
            0.5,
            100.0,
        ))?;
        let frame = reader
            .wait_until(timeout, |f| f.header.deposits_applied > before)?
            .ok_or_else(|| {
                BenchError::Peer(format!("the deposit did not show within {timeout:?}"))
            })?;
        let seen = now_ns();
        if i >= run.warmup {
            result.samples_ns.push(seen.saturating_sub(sent));
            result.compute_ns.push(frame.header.tick_compute_ns);
        }
    }
    drop(depositor);
    drop(field);
    Ok(result)
}

/// The field process: ticks at `tick_hz` until terminated.
pub fn field(name: &str, width: u32, tick_hz: f32) -> Result<(), BenchError> {
    let node = create_node(&format!("bench-field-{}", std::process::id()))?;
    let mut server = FieldServer::start(&node, name, config(width, tick_hz), None)?;
    say_ready();
    let period = Duration::from_secs_f32(1.0 / tick_hz);
    let mut next = Instant::now();
    loop {
        next += period;
        let now = Instant::now();
        if next < now {
            next = now;
        }
        if node.wait(next - now).is_err() {
            break;
        }
        server.tick()?;
    }
    say_result(&PeerResult::default());
    Ok(())
}
