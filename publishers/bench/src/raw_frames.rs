//! The raw iceoryx2 reference for frame delivery (issue 18): the same `[f32]` slice as the
//! field's frame, published by plain iceoryx2 with nothing of ours on the path. The publisher
//! writes the whole payload (a copy of a plane: one read and one write per cell, as a tick),
//! then stamps CLOCK_MONOTONIC into a `u64` user header and sends; in wait mode it also notifies
//! an event. The reader records (time it holds the sample − stamp), exactly as it does for ours.

use std::time::{Duration, Instant};

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use pheromone_field::shm::{now_ns, Svc, WaitPolicy};

use crate::frame_run::{
    drive, pause, record, spawn_readers, test_plane, FrameRun, FrameSamples, FRAME_TIMEOUT,
};
use crate::peer::{Launcher, ReaderWait};
use crate::BenchError;

fn raw_err(what: &str, e: impl std::fmt::Debug) -> BenchError {
    BenchError::Peer(format!("raw iceoryx2 frames, {what}: {e:?}"))
}

type Factory = iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, [f32], u64>;

fn services(
    node: &Node<Svc>,
    name: &str,
    readers: usize,
) -> Result<
    (
        Factory,
        iceoryx2::service::port_factory::event::PortFactory<Svc>,
    ),
    BenchError,
> {
    let frame = ServiceName::new(name).map_err(|e| raw_err(name, e))?;
    let ready = ServiceName::new(&format!("{name}-ready")).map_err(|e| raw_err(name, e))?;
    let pubsub = node
        .service_builder(&frame)
        .publish_subscribe::<[f32]>()
        .user_header::<u64>()
        .history_size(0)
        .subscriber_max_buffer_size(1)
        .subscriber_max_borrowed_samples(2)
        .max_subscribers(readers)
        .max_publishers(1)
        .open_or_create()
        .map_err(|e| raw_err("frame service", e))?;
    let event = node
        .service_builder(&ready)
        .event()
        .open_or_create()
        .map_err(|e| raw_err("ready event", e))?;
    Ok((pubsub, event))
}

/// The publishing side: one frame per period until every reader has its samples.
pub fn measure(
    node: &Node<Svc>,
    launcher: &Launcher,
    tag: &str,
    run: &FrameRun,
) -> Result<FrameSamples, BenchError> {
    let name = format!("pheromone-bench/raw-frames/{tag}");
    let (pubsub, event) = services(node, &name, run.readers)?;
    let cells = test_plane(run.width);
    let publisher: Publisher<Svc, [f32], u64> = pubsub
        .publisher_builder()
        .initial_max_slice_len(cells.len())
        .allocation_strategy(AllocationStrategy::Static)
        .max_loaned_samples(1)
        .create()
        .map_err(|e| raw_err("publisher", e))?;
    let notifier: Notifier<Svc> = event
        .notifier_builder()
        .create()
        .map_err(|e| raw_err("notifier", e))?;
    let mut peers = spawn_readers(launcher, run, &name)?;
    drive(node, &mut peers, run, || {
        let sample = publisher
            .loan_slice_uninit(cells.len())
            .map_err(|e| raw_err("loan", e))?;
        let mut sample = sample.write_from_slice(&cells);
        *sample.user_header_mut() = now_ns();
        sample.send().map_err(|e| raw_err("send", e))?;
        notifier.notify().map_err(|e| raw_err("notify", e))?;
        Ok(())
    })
}

/// The reader process: holds each new sample as soon as `policy` lets it see it.
pub fn read(source: &str, wait: ReaderWait, skip: usize, count: usize) -> Result<(), BenchError> {
    let policy = wait.policy();
    let node =
        pheromone_field::shm::create_node(&format!("bench-raw-reader-{}", std::process::id()))?;
    let frame = ServiceName::new(source).map_err(|e| raw_err(source, e))?;
    let ready = ServiceName::new(&format!("{source}-ready")).map_err(|e| raw_err(source, e))?;
    let subscriber: Subscriber<Svc, [f32], u64> = node
        .service_builder(&frame)
        .publish_subscribe::<[f32]>()
        .user_header::<u64>()
        .open()
        .map_err(|e| raw_err("open the frame service", e))?
        .subscriber_builder()
        .buffer_size(1)
        .create()
        .map_err(|e| raw_err("subscriber", e))?;
    let listener: Listener<Svc> = node
        .service_builder(&ready)
        .event()
        .open()
        .map_err(|e| raw_err("open the ready event", e))?
        .listener_builder()
        .create()
        .map_err(|e| raw_err("listener", e))?;
    crate::peer::say_ready();
    let spin = match policy {
        WaitPolicy::Event => Duration::ZERO,
        WaitPolicy::Spin(d) => d,
        WaitPolicy::BusyPoll => FRAME_TIMEOUT,
    };
    let (mut previous_ns, mut last_ns) = (0, 0);
    record(skip, count, || {
        pause(&node, wait.pause_after(previous_ns, last_ns, now_ns()))?;
        let start = Instant::now();
        loop {
            if let Some(s) = subscriber.receive().map_err(|e| raw_err("receive", e))? {
                let now = now_ns();
                std::hint::black_box(s.payload().len());
                (previous_ns, last_ns) = (last_ns, *s.user_header());
                return Ok(Some(now.saturating_sub(last_ns)));
            }
            let waited = start.elapsed();
            if waited >= FRAME_TIMEOUT {
                return Err(BenchError::Peer(format!(
                    "no raw frame on '{source}' within {FRAME_TIMEOUT:?}"
                )));
            }
            if waited < spin {
                std::hint::spin_loop();
            } else {
                pheromone_field::shm::listener_timed_wait(&listener, FRAME_TIMEOUT - waited)
                    .map_err(|e| raw_err("wait", e))?;
            }
        }
    })
}
