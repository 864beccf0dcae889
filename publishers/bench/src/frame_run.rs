//! What every frame transport's measurement shares (`crate::frames`, `crate::raw_frames`): the
//! run's parameters, the reader processes and the publish and record loops. A leaf among the
//! frame modules: it imports neither.

use std::time::{Duration, Instant};

use iceoryx2::prelude::*;
use pheromone_field::shm::Svc;

use crate::peer::{say_result, FrameTransport, Launcher, Peer, PeerResult, PeerSpec, ReaderWait};
use crate::BenchError;

/// Longest a reader waits for the next frame before it gives up.
pub(crate) const FRAME_TIMEOUT: Duration = Duration::from_secs(20);

/// One frame-delivery measurement.
#[derive(Debug, Clone, Copy)]
pub struct FrameRun {
    pub transport: FrameTransport,
    /// Cells per side (one f32 channel): 512 = 1 MiB, 2048 = 16 MiB.
    pub width: u32,
    pub readers: usize,
    pub wait: ReaderWait,
    /// Frames each reader records (after `skip`).
    pub count: usize,
    pub skip: usize,
    /// Time between the end of one publish and the next.
    pub period: Duration,
    /// Pin the publisher to core 0 and a single reader to core 1.
    pub pin: bool,
}

/// A plane with something in it, so nothing can be compressed away.
pub(crate) fn test_plane(width: u32) -> Vec<f32> {
    (0..width as usize * width as usize)
        .map(|i| (i % 1013) as f32 * 0.001)
        .collect()
}

/// Waits `period` on the node (returns early with an error on Ctrl-C).
pub(crate) fn pause(node: &Node<Svc>, period: Duration) -> Result<(), BenchError> {
    pheromone_field::shm::node_wait(node, period).map_err(|_| BenchError::Interrupted)
}

/// What the readers of one frame-delivery measurement recorded.
#[derive(Debug, Clone, Default)]
pub struct FrameSamples {
    /// Every reader's latencies (ns), pooled.
    pub samples_ns: Vec<u64>,
    /// The readers' mean CPU share of one core while they recorded (their wait policy's cost),
    /// where they measured it.
    pub reader_cpu_share: Option<f64>,
}

/// Collects every reader's result; `publish` is called once per period until all are in.
pub(crate) fn drive(
    node: &Node<Svc>,
    peers: &mut [Peer],
    run: &FrameRun,
    mut publish: impl FnMut() -> Result<(), BenchError>,
) -> Result<FrameSamples, BenchError> {
    let frames = run.skip + run.count;
    // Generous: every frame may take a whole period plus a second of slack, and some are lost.
    let deadline = Instant::now()
        + (run.period + Duration::from_millis(200)) * (2 * frames as u32)
        + Duration::from_secs(30);
    let mut results: Vec<Option<PeerResult>> = vec![None; peers.len()];
    while results.iter().any(Option::is_none) {
        if Instant::now() > deadline {
            return Err(BenchError::Peer(format!(
                "{:?} readers did not receive {frames} frames in time",
                run.transport
            )));
        }
        publish()?;
        pause(node, run.period)?;
        for (peer, slot) in peers.iter_mut().zip(results.iter_mut()) {
            if slot.is_none() {
                *slot = peer.try_result()?;
            }
        }
    }
    let results: Vec<PeerResult> = results.into_iter().flatten().collect();
    let shares: Vec<f64> = results.iter().filter_map(|r| r.cpu_share).collect();
    Ok(FrameSamples {
        reader_cpu_share: (!shares.is_empty())
            .then(|| shares.iter().sum::<f64>() / shares.len() as f64),
        samples_ns: results.into_iter().flat_map(|r| r.samples_ns).collect(),
    })
}

pub(crate) fn spawn_readers(
    launcher: &Launcher,
    run: &FrameRun,
    source: &str,
) -> Result<Vec<Peer>, BenchError> {
    let mut peers = Vec::with_capacity(run.readers);
    for _ in 0..run.readers {
        peers.push(Peer::spawn(
            launcher,
            &PeerSpec::FrameReader {
                transport: run.transport,
                source: source.to_string(),
                wait: run.wait,
                skip: run.skip,
                count: run.count,
                core: (run.pin && run.readers == 1).then_some(1),
            },
        )?);
    }
    for p in &mut peers {
        p.wait_ready(Duration::from_secs(20))?;
    }
    Ok(peers)
}

/// Records frames until `count` are in; `next` waits for one frame and returns its latency
/// (or `None` for a frame that does not count, e.g. one already seen). Also measures this
/// process's CPU time (`/proc/PID/schedstat`) over the wall time from the first counted frame to
/// the last: the cost of the reader's wait policy, as a share of one core.
pub(crate) fn record(
    skip: usize,
    count: usize,
    mut next: impl FnMut() -> Result<Option<u64>, BenchError>,
) -> Result<(), BenchError> {
    let mut samples = Vec::with_capacity(count);
    let mut skipped = 0;
    let me = std::process::id();
    let mut since: Option<(Instant, u64)> = None;
    while samples.len() < count {
        if let Some(latency_ns) = next()? {
            if skipped < skip {
                skipped += 1;
            } else {
                if since.is_none() {
                    since = Some((Instant::now(), crate::machine::cpu_ns(me)?));
                }
                samples.push(latency_ns);
            }
        }
    }
    let cpu_share = match since {
        Some((t0, cpu0)) if samples.len() > 1 => {
            let wall_ns = t0.elapsed().as_nanos() as f64;
            let cpu = crate::machine::cpu_ns(me)?.saturating_sub(cpu0) as f64;
            (wall_ns > 0.0).then(|| ((cpu / wall_ns) * 1000.0).round() / 1000.0)
        }
        _ => None,
    };
    say_result(&PeerResult {
        samples_ns: samples,
        cpu_share,
        field_timing: None,
    });
    Ok(())
}
