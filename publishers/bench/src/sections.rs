//! The measurements of `pheromone bench`, one function per section, and what they share
//! (`Ctx`: the options, the mode's plan, pinning, the progress log, unique service tags).

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use crate::*;

/// What every section of a run uses: the options, the mode's plan, whether this process is
/// pinned, the progress log and the unique tags of the peers' services.
pub(crate) struct Ctx<'a> {
    pub(crate) opts: &'a Options,
    pub(crate) plan: Plan,
    pub(crate) pin: bool,
    pub(crate) started: Instant,
    pub(crate) serial: u32,
}

impl Ctx<'_> {
    /// A progress line on stderr (`Options::progress`), stamped with the time since the start.
    pub(crate) fn say(&self, msg: &str) {
        if self.opts.progress {
            eprintln!("[{:>6.1}s] {msg}", self.started.elapsed().as_secs_f64());
        }
    }

    /// A tag no other measurement of this run (or process) uses.
    pub(crate) fn tag(&mut self) -> String {
        self.serial += 1;
        format!("{}-{}", std::process::id(), self.serial)
    }

    /// Whether section `s` runs: named by `--only`, or every one but `scale` (long) without it.
    pub(crate) fn runs(&self, s: Section) -> bool {
        (self.opts.only.is_empty() && s != Section::Scale) || self.opts.only.contains(&s)
    }
}

/// Rows keyed by a grid or map size (`"512x512"`).
pub(crate) type BySize<T> = BTreeMap<String, T>;

/// The sections measured in this process: `tick_vs_memcpy` and `merge_vs_memcpy`, keyed by size.
pub(crate) fn measure_in_process(
    cx: &Ctx,
) -> Result<(BySize<TickRow>, BySize<MergeRow>), BenchError> {
    let plan = cx.plan;
    let mut tick_vs_memcpy = BTreeMap::new();
    for &w in plan.tick_widths.iter().filter(|_| cx.runs(Section::Tick)) {
        cx.say(&format!("tick vs memcpy at {w}x{w}"));
        tick_vs_memcpy.insert(format!("{w}x{w}"), tick::measure(w, plan.tick_reps)?);
    }
    let mut merge_vs_memcpy = BTreeMap::new();
    for &n in plan.merge_sides.iter().filter(|_| cx.runs(Section::Merge)) {
        cx.say(&format!("merge vs memcpy at {n}x{n}"));
        merge_vs_memcpy.insert(format!("{n}x{n}"), merge::measure(n, plan.tick_reps)?);
    }
    Ok((tick_vs_memcpy, merge_vs_memcpy))
}

/// The `peers` section (issue 53), if the run measures it.
pub(crate) fn measure_peers(cx: &Ctx) -> Result<Option<peers::PeersReport>, BenchError> {
    if !cx.runs(Section::Peers) {
        return Ok(None);
    }
    let plan = cx.plan;
    cx.say(&format!(
        "peers: ambient tick at {:?} cells, radii {:?}, against OpenCV boxFilter and SciPy \
         uniform_filter; merge at {:?} against OpenCV warpAffine + NumPy ({})",
        plan.peer_sides, plan.peer_radii, plan.peer_merge_sides, cx.opts.peers_python
    ));
    peers::measure(&peers::PeersRun {
        python: &cx.opts.peers_python,
        ambient_sides: plan.peer_sides,
        radii_cells: plan.peer_radii,
        merge_sides: plan.peer_merge_sides,
        reps: plan.peer_reps,
    })
    .map(Some)
}

/// The `c_abi` section: libpheromone's C reader against the Rust reader.
pub(crate) fn measure_c_abi(cx: &mut Ctx) -> Result<c_abi::CAbiReport, BenchError> {
    let plan = cx.plan;
    cx.say(&format!(
        "C ABI: 1 MiB frames to a Rust and a C reader ({} rounds of {} frames each), \
         sampling {} points x {}",
        plan.c_abi_rounds, plan.c_abi_frames.0, plan.c_abi_points.0, plan.c_abi_points.1
    ));
    let run = c_abi::CAbiRun {
        width: 512,
        count: plan.c_abi_frames.0,
        skip: plan.c_abi_frames.1,
        rounds: plan.c_abi_rounds,
        points: plan.c_abi_points.0,
        reps: plan.c_abi_points.1,
        pin: cx.pin,
    };
    let launcher = &cx.opts.launcher;
    let mut serial = cx.serial;
    let report = c_abi::measure(
        launcher,
        &mut || {
            serial += 1;
            format!("{}-{}", std::process::id(), serial)
        },
        run,
    );
    cx.serial = serial;
    report
}

/// The `hop_ns` section: ours and raw iceoryx2, waiting and busy-polling.
pub(crate) fn measure_hops(cx: &mut Ctx) -> Result<HopReport, BenchError> {
    let mut hop = |raw: bool, busy: bool| -> Result<Latency, BenchError> {
        cx.say(&format!(
            "hop: {} {} ({} ping-pongs)",
            if raw {
                "raw iceoryx2 u64"
            } else {
                "ours (PoseMsg link)"
            },
            if busy { "busy-poll" } else { "wait" },
            cx.plan.hop_count
        ));
        let s = hop::measure(
            &cx.opts.launcher,
            &cx.tag(),
            hop::HopRun {
                raw,
                busy,
                warmup: cx.plan.hop_warmup,
                count: cx.plan.hop_count,
                pin: cx.pin,
            },
        )?;
        latency(&s, "hop")
    };
    Ok(HopReport {
        ours: hop(false, false)?,
        raw_iceoryx2: hop(true, false)?,
        busy_poll: HopPair {
            ours: hop(false, true)?,
            raw_iceoryx2: hop(true, true)?,
        },
        message_bytes: HopBytes {
            ours: std::mem::size_of::<pheromone_messages::PoseMsg>(),
            raw_iceoryx2: std::mem::size_of::<u64>(),
        },
        method: "ping-pong between two processes, one-way = round trip / 2",
    })
}

/// One frame size of the `frame_ns` section.
pub(crate) struct FrameSize {
    pub(crate) key: &'static str,
    pub(crate) width: u32,
    /// Frames recorded and skipped.
    pub(crate) count: usize,
    pub(crate) skip: usize,
    pub(crate) period_ms: u64,
}

/// One frame size of the `frame_ns` section: every transport and wait policy.
pub(crate) fn measure_frames(cx: &mut Ctx, size: FrameSize) -> Result<FrameReport, BenchError> {
    let FrameSize {
        key,
        width,
        count,
        skip,
        period_ms,
    } = size;
    let period = Duration::from_millis(period_ms);
    const EVENT: ReaderWait = ReaderWait::Event;
    const BUSY: ReaderWait = ReaderWait::BusyPoll;
    let spin = ReaderWait::Spin { spin_us: SPIN_US };
    let mut cpu: BTreeMap<(FrameTransport, ReaderWait), f64> = BTreeMap::new();
    let mut frames = |transport: FrameTransport,
                      readers: usize,
                      wait: ReaderWait|
     -> Result<Option<Latency>, BenchError> {
        if transport == FrameTransport::Zenoh && !ZENOH_BUILT {
            return Ok(None);
        }
        cx.say(&format!(
            "frames {key}: {transport:?} to {readers} reader(s), {} ({count} frames)",
            wait.label()
        ));
        let s = frames::measure(
            &cx.opts.launcher,
            &cx.tag(),
            frames::FrameRun {
                transport,
                width,
                readers,
                wait,
                count,
                skip,
                period,
                pin: cx.pin,
            },
        )?;
        if let (1, Some(share)) = (readers, s.reader_cpu_share) {
            cpu.insert((transport, wait), share);
        }
        latency(&s.samples_ns, "frames").map(Some)
    };
    let need = |l: Option<Latency>| l.ok_or(BenchError::NoZenoh);
    let ours = need(frames(FrameTransport::Ours, 1, EVENT)?)?;
    let uds_serde = need(frames(FrameTransport::UdsSerde, 1, EVENT)?)?;
    let zenoh = frames(FrameTransport::Zenoh, 1, EVENT)?;
    let readers_8 = FrameSet {
        ours: need(frames(FrameTransport::Ours, 8, EVENT)?)?,
        uds_serde: need(frames(FrameTransport::UdsSerde, 8, EVENT)?)?,
        zenoh: frames(FrameTransport::Zenoh, 8, EVENT)?,
    };
    let ours_busy_poll = need(frames(FrameTransport::Ours, 1, BUSY)?)?;
    let raw_iceoryx2 = need(frames(FrameTransport::RawIceoryx, 1, EVENT)?)?;
    let raw_iceoryx2_busy_poll = need(frames(FrameTransport::RawIceoryx, 1, BUSY)?)?;
    let ours_spin = need(frames(FrameTransport::Ours, 1, spin)?)?;
    let raw_iceoryx2_spin = need(frames(FrameTransport::RawIceoryx, 1, spin)?)?;
    let share = |t: FrameTransport, w: ReaderWait| cpu.get(&(t, w)).copied();
    Ok(FrameReport {
        width,
        frame_bytes: width as u64 * width as u64 * 4,
        ours,
        uds_serde,
        zenoh,
        readers_8,
        ours_busy_poll,
        raw_iceoryx2,
        raw_iceoryx2_busy_poll,
        ours_spin,
        raw_iceoryx2_spin,
        spin_us: SPIN_US,
        period_ms: period_ms as f64,
        reader_cpu_share: ReaderCpu {
            ours_wait: share(FrameTransport::Ours, EVENT),
            ours_spin: share(FrameTransport::Ours, spin),
            ours_busy_poll: share(FrameTransport::Ours, BUSY),
            raw_iceoryx2_wait: share(FrameTransport::RawIceoryx, EVENT),
            raw_iceoryx2_spin: share(FrameTransport::RawIceoryx, spin),
            raw_iceoryx2_busy_poll: share(FrameTransport::RawIceoryx, BUSY),
        },
    })
}

/// The three deposit-to-visible measurements.
pub(crate) struct Visible {
    pub(crate) on_tick: VisibleReport,
    pub(crate) on_deposit: VisibleReport,
    pub(crate) on_deposit_rt: VisibleReport,
}

/// The `deposit_to_visible_us` section: the field ticking, then publishing on deposit, then
/// publishing on deposit with real-time scheduling, a spin of a period and a busy-polling reader.
pub(crate) fn measure_visible(cx: &mut Ctx) -> Result<Visible, BenchError> {
    let opts = cx.opts;
    let w = opts.visible_width;
    cx.say(&format!(
        "deposit to visible: {w}x{w} field at {} Hz ({} deposits)",
        opts.tick_hz, cx.plan.visible_count,
    ));
    let visible_run = visible::VisibleRun {
        width: opts.visible_width,
        tick_hz: opts.tick_hz,
        warmup: (cx.plan.visible_count / 20).max(2),
        count: cx.plan.visible_count,
        pin: cx.pin,
        on_deposit: false,
        cpu_window: cx.plan.cpu_window,
        rt_priority: None,
        spin_us: 0,
        reader_wait: ReaderWait::Event,
    };
    let v = visible::measure(&opts.launcher, &cx.tag(), visible_run)?;
    let on_tick = visible_report(opts, v, |compute_p99_us| {
        1e6 / opts.tick_hz as f64 + 1.2 * compute_p99_us + 50.0
    })?;
    cx.say(&format!(
        "deposit to visible, publishing on deposit: {w}x{w} field ({} deposits), then its CPU \
         at 10, 100 and 1000 deposits/s",
        cx.plan.visible_count,
    ));
    let on_deposit_run = visible::VisibleRun {
        on_deposit: true,
        ..visible_run
    };
    let v = visible::measure(&opts.launcher, &cx.tag(), on_deposit_run)?;
    let on_deposit = visible_report(opts, v, |compute_p99_us| compute_p99_us + 100.0)?;
    // Four fifths of the period: a spin of the whole period keeps the field at 0.95 of a core,
    // where Linux's real-time throttling (`sched_rt_runtime_us`, 950 000 of every 1 000 000 µs
    // by default) stops every SCHED_FIFO task on the core for the rest of each second: 45 ms
    // stalls. Deposits that come while it sleeps wake it by their event.
    let spin_us = (0.8e6 / opts.tick_hz as f64).round() as u32;
    cx.say(&format!(
        "deposit to visible, publishing on deposit with SCHED_FIFO {RT_PRIORITY}, the field \
         spinning {spin_us} µs a period and the follower busy-polling at SCHED_FIFO {RT_PRIORITY}"
    ));
    let v = visible::measure(
        &opts.launcher,
        &cx.tag(),
        visible::VisibleRun {
            rt_priority: Some(RT_PRIORITY),
            spin_us,
            reader_wait: ReaderWait::BusyPoll,
            ..on_deposit_run
        },
    )?;
    let on_deposit_rt = visible_report(opts, v, |compute_p99_us| compute_p99_us + 100.0)?;
    Ok(Visible {
        on_tick,
        on_deposit,
        on_deposit_rt,
    })
}

/// The `SCHED_FIFO` priority of the bench's real-time runs.
pub(crate) const RT_PRIORITY: i32 = 80;

/// The `tick_timing` section: a 512² field at 100 Hz and 1 kHz beside two busy loops, with the
/// default scheduler, with `SCHED_FIFO`, and with `SCHED_FIFO` and a 200 µs spin.
pub(crate) fn measure_timing(cx: &mut Ctx) -> Result<Vec<timing::TimingRow>, BenchError> {
    let mut rows = Vec::new();
    for tick_hz in [100.0f32, 1000.0] {
        for (rt_priority, spin_us) in [(None, 0), (Some(RT_PRIORITY), 0), (Some(RT_PRIORITY), 200)]
        {
            let run = timing::TimingRun {
                tick_hz,
                width: 512,
                duration: cx.plan.timing_run,
                rt_priority,
                spin_us,
                busy_loops: 2,
            };
            cx.say(&format!(
                "tick timing: 512x512 at {tick_hz} Hz for {:.1} s beside 2 busy loops, {}, spin {spin_us} µs",
                run.duration.as_secs_f64(),
                rt_priority.map_or("default scheduler".into(), |p| format!("SCHED_FIFO {p}")),
            ));
            rows.push(timing::measure(&cx.opts.launcher, &cx.tag(), run)?);
        }
    }
    Ok(rows)
}

/// A deposit-to-visible report from its samples; `target_p99_us` of the tick compute's p99 (µs).
fn visible_report(
    opts: &Options,
    v: visible::VisibleResult,
    target_p99_us: impl Fn(f64) -> f64,
) -> Result<VisibleReport, BenchError> {
    let no_samples = || BenchError::Peer("deposit to visible: no samples".into());
    let compute = Latency::from_ns_as_us(&v.compute_ns).ok_or_else(no_samples)?;
    let latency = Latency::from_ns_as_us(&v.samples_ns).ok_or_else(no_samples)?;
    Ok(VisibleReport {
        tick_hz: opts.tick_hz,
        width: opts.visible_width,
        target_p99_us: target_p99_us(compute.p99),
        tick_compute_us: compute,
        to_field_us: Latency::from_ns_as_us(&v.to_field_ns).ok_or_else(no_samples)?,
        to_reader_us: Latency::from_ns_as_us(&v.to_reader_ns).ok_or_else(no_samples)?,
        send_us: Latency::from_ns_as_us(&v.send_ns).ok_or_else(no_samples)?,
        slowest_1pct_us: v.slowest_stages(latency.p99),
        latency,
        field_cpu: v.cpu,
    })
}

/// The `gateway_pir` section.
pub(crate) fn measure_gateway(
    cx: &mut Ctx,
) -> Result<(gateway::GatewayReport, gateway::LoadedPirReport), BenchError> {
    let plan = cx.plan;
    cx.say(&format!(
        "gateway: {} PIR round trips over UDP loopback, {} direct reads, {:.1} s flood",
        plan.pir_count.0,
        plan.pir_count.0,
        plan.flood.as_secs_f64()
    ));
    let run = gateway::GatewayRun {
        warmup: plan.pir_count.1,
        count: plan.pir_count.0,
        flood: plan.flood,
        window: 32,
        pin: cx.pin,
    };
    let report = gateway::measure(&cx.opts.launcher, &cx.tag(), run)?;
    cx.say(&format!(
        "gateway: {} PIR round trips beside 2 busy loops, gateway and client at SCHED_FIFO {RT_PRIORITY}",
        plan.pir_count.0
    ));
    let loaded = gateway::measure_loaded(&cx.opts.launcher, &cx.tag(), run, (2, RT_PRIORITY))?;
    Ok((report, loaded))
}

/// The `mirror` section: an origin of `plan.mirror_width`² at 100 Hz, a bridge and a mirror.
#[cfg(feature = "zenoh")]
pub(crate) fn measure_mirror(cx: &mut Ctx) -> Result<Option<MirrorSection>, BenchError> {
    let w = cx.plan.mirror_width;
    cx.say(&format!(
        "mirror: {w}x{w} origin at 100 Hz, bridge and mirror over Zenoh on loopback, \
         {:.1} s at 10 and at 1000 deposits/s, then a mirror started afresh",
        cx.plan.mirror_window.as_secs_f64()
    ));
    mirror::measure(
        &cx.opts.launcher,
        &cx.tag(),
        mirror::MirrorRun {
            width: w,
            tick_hz: 100.0,
            window: cx.plan.mirror_window,
            keyframe_every: Duration::from_secs(5),
            pin: cx.pin,
        },
    )
    .map(Some)
}

#[cfg(not(feature = "zenoh"))]
pub(crate) fn measure_mirror(cx: &mut Ctx) -> Result<Option<MirrorSection>, BenchError> {
    cx.say(&format!(
        "mirror ({w}x{w}, {:.1} s per deposit rate): not built (--features zenoh)",
        cx.plan.mirror_window.as_secs_f64(),
        w = cx.plan.mirror_width
    ));
    Ok(None)
}

/// The `ros2` section (issue 46), if the run measures it: `pheromone ros2` against a plain
/// Zenoh publisher.
#[cfg(feature = "zenoh")]
pub(crate) fn measure_ros2(cx: &mut Ctx) -> Result<Option<ros2::Ros2Report>, BenchError> {
    if !cx.runs(Section::Ros2) {
        return Ok(None);
    }
    let run = ros2::Ros2Run::of(cx.opts.mode);
    cx.say(&format!(
        "ros2: a {w}x{w} field at {} Hz, `pheromone ros2` ({:.1} s with nobody subscribed, then \
         {:.1} s with one subscriber) and a plain Zenoh publisher of the same bytes, CPU per MB",
        run.rate_hz,
        run.idle.as_secs_f64(),
        run.window.as_secs_f64(),
        w = run.width
    ));
    ros2::measure(&cx.opts.launcher, &cx.tag(), run).map(Some)
}

#[cfg(not(feature = "zenoh"))]
pub(crate) fn measure_ros2(cx: &mut Ctx) -> Result<Option<ros2::Ros2Report>, BenchError> {
    if cx.runs(Section::Ros2) {
        cx.say("ros2: not built (--features zenoh)");
    }
    Ok(None)
}
